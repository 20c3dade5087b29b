/* The per-pixel outputs shared by the exact ray tracer (raytrace.cl) and the splat resolve pass
 * (resolve.cl): depth along the unit view ray (+inf on background), quadric id, primitive id
 * and RGBA8.  A hit at p on quadric q takes the colour of the primitive whose boundary holds p
 * (primitives.h; grey if none does) and is shaded by shade.h with the unit normal
 * grad Q(p) / |grad Q(p)| (eq. 4; shade() makes it two-sided). */
#ifndef CLCSG_PIXEL_H
#define CLCSG_PIXEL_H
#include "primitives.h"
#include "shade.h"

typedef struct {
    __global float *depth;
    __global int *quadric;
    __global int *primitive;
    __global uchar4 *rgba;
} pixel_out;

/* The kernels' output parameters, in this order (the drivers pass the buffers so). */
#define PIXEL_OUTPUTS \
    __global float *depth_out, __global int *id_out, __global int *prim_out, __global uchar4 *rgba_out
#define PIXEL_OUT ((pixel_out){depth_out, id_out, prim_out, rgba_out})

/* Row-major index of pixel (i, j) = (get_global_id(1), get_global_id(0)); -1 outside the view. */
inline int pixel_index(__global const view_rec *view, int *i, int *j)
{
    *j = get_global_id(0);
    *i = get_global_id(1);
    return (*i < view->height && *j < view->width) ? *i * view->width + *j : -1;
}

inline void pixel_miss(pixel_out out, __global const view_rec *view, int pix)
{
    out.depth[pix] = INFINITY;
    out.quadric[pix] = -1;
    out.primitive[pix] = -1;
    out.rgba[pix] = shade_background(view);
}

/* The display colour of primitive prim (-1: grey). */
inline float4 pixel_color(__global const prim_rec *prims, int prim)
{
    return prim >= 0 ? vload4(0, prims[prim].color) : (float4)(0.8f, 0.8f, 0.8f, 1.0f);
}

/* The unit normal grad Q(p) / |grad Q(p)| of the shading, in float. */
inline float3 pixel_normal(__global const quadric_rec *qs, int qid, real3 p)
{
    return convert_float3(normalize(quadric_gradient(quadric_load(qs, qid), p)));
}

inline void pixel_write(pixel_out out, int pix, int prim, int qid, real depth, uchar4 rgba)
{
    out.depth[pix] = (float)depth;
    out.quadric[pix] = qid;
    out.primitive[pix] = prim;
    out.rgba[pix] = rgba;
}

/* A hit at p on quadric qid shown as primitive prim, whose albedo (shade_albedo) is given. */
inline void pixel_hit_lit(pixel_out out, __global const view_rec *view, int pix, float4 albedo, int prim,
                          __global const quadric_rec *qs, int qid, real3 p, real depth, real3 v)
{
    pixel_write(out, pix, prim, qid, depth, shade_lit(view, albedo, pixel_normal(qs, qid, p), convert_float3(v)));
}

/* A hit at p on quadric qid shown as primitive prim. */
inline void pixel_hit_as(pixel_out out, __global const view_rec *view, int pix, __global const prim_rec *prims,
                         int prim, __global const quadric_rec *qs, int qid, real3 p, real depth, real3 v)
{
    pixel_hit_lit(out, view, pix, shade_albedo(view, pixel_color(prims, prim)), prim, qs, qid, p, depth, v);
}

inline void pixel_hit(pixel_out out, __global const view_rec *view, int pix, PRIMITIVE_TABLE,
                      __global const quadric_rec *qs, int qid, real3 p,
                      real depth, real3 v)
{
    pixel_hit_as(out, view, pix, prims, primitive_at(PRIMITIVE_TABLE_ARGS, qs, qid, p), qs, qid, p, depth, v);
}
#endif
