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

inline void pixel_miss(pixel_out out, __global const view_rec *view, int pix)
{
    out.depth[pix] = INFINITY;
    out.quadric[pix] = -1;
    out.primitive[pix] = -1;
    out.rgba[pix] = shade_background(view);
}

inline void pixel_hit(pixel_out out, __global const view_rec *view, int pix, __global const owner_rec *owners,
                      __global const int *owner_list, __global const prim_rec *prims,
                      __global const int2 *prim_lits, __global const quadric_rec *qs, int qid, real3 p,
                      real depth, real3 v)
{
    int prim = primitive_at(owners, owner_list, prims, prim_lits, qs, qid, p);
    float4 color = prim >= 0 ? vload4(0, prims[prim].color) : (float4)(0.8f, 0.8f, 0.8f, 1.0f);
    quadric q = quadric_load(qs, qid);
    out.depth[pix] = (float)depth;
    out.quadric[pix] = qid;
    out.primitive[pix] = prim;
    out.rgba[pix] = shade(view, color, convert_float3(normalize(quadric_gradient(q, p))), convert_float3(v));
}
#endif
