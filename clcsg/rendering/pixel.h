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

/* The outputs of RAY_LANES consecutive pixels of a row, gathered lane by lane (pixel_lanes_set)
 * and shaded together (pixel_lanes_store): per lane the depth, quadric and primitive ids (a miss
 * keeps pixel_lanes_clear's +inf, -1, -1), the linear albedo (shade_albedo), the unit normal
 * and the unit view ray, in float. */
#if RAY_LANES != 8
#error "the pixel lanes are shaded as one float8"
#endif
typedef struct {
    float depth[8], ax[8], ay[8], az[8], aw[8], nx[8], ny[8], nz[8], vx[8], vy[8], vz[8];
    int quadric[8], primitive[8];
} pixel_lanes;

inline void pixel_lanes_clear(pixel_lanes *px)
{
    for (int l = 0; l < 8; ++l) {
        px->depth[l] = INFINITY;
        px->quadric[l] = px->primitive[l] = -1;
        px->ax[l] = px->ay[l] = px->az[l] = px->aw[l] = 0.0f;
        px->nx[l] = px->ny[l] = 0.0f;
        px->nz[l] = 1.0f; /* a lane without a hit keeps a harmless normal and ray */
        px->vx[l] = px->vy[l] = 0.0f;
        px->vz[l] = -1.0f;
    }
}

inline void pixel_lanes_set(pixel_lanes *px, int l, float depth, int qid, int prim, float4 albedo, float3 n,
                            float3 v)
{
    px->depth[l] = depth;
    px->quadric[l] = qid;
    px->primitive[l] = prim;
    px->ax[l] = albedo.x; px->ay[l] = albedo.y; px->az[l] = albedo.z; px->aw[l] = albedo.w;
    px->nx[l] = n.x; px->ny[l] = n.y; px->nz[l] = n.z;
    px->vx[l] = v.x; px->vy[l] = v.y; px->vz[l] = v.z;
}

/* The lanes shaded (shade_light8, shade_encode8; misses: shade_background) and written to
 * pixels pix ... pix + lanes - 1. */
inline void pixel_lanes_store(pixel_out out, __global const view_rec *view, int pix, int lanes, const pixel_lanes *px)
{
    float8 cx, cy, cz;
    shade_light8(view, vload8(0, px->ax), vload8(0, px->ay), vload8(0, px->az), vload8(0, px->nx),
                 vload8(0, px->ny), vload8(0, px->nz), vload8(0, px->vx), vload8(0, px->vy), vload8(0, px->vz), &cx,
                 &cy, &cz);
    int8 qid = vload8(0, px->quadric);
    char8 hit = convert_char8(qid >= 0);
    uchar4 bg = shade_background(view);
    uchar8 rx = select((uchar8)bg.x, shade_encode8(view, cx), hit);
    uchar8 ry = select((uchar8)bg.y, shade_encode8(view, cy), hit);
    uchar8 rz = select((uchar8)bg.z, shade_encode8(view, cz), hit);
    uchar8 ra = select((uchar8)bg.w, convert_uchar8_sat(vload8(0, px->aw) * 255.0f + 0.5f), hit);
    if (lanes == 8) {
        vstore8(vload8(0, px->depth), 0, out.depth + pix);
        vstore8(qid, 0, out.quadric + pix);
        vstore8(vload8(0, px->primitive), 0, out.primitive + pix);
        __global uchar *rgba = (__global uchar *)(out.rgba + pix);
        vstore16((uchar16)(rx.s0, ry.s0, rz.s0, ra.s0, rx.s1, ry.s1, rz.s1, ra.s1,
                           rx.s2, ry.s2, rz.s2, ra.s2, rx.s3, ry.s3, rz.s3, ra.s3), 0, rgba);
        vstore16((uchar16)(rx.s4, ry.s4, rz.s4, ra.s4, rx.s5, ry.s5, rz.s5, ra.s5,
                           rx.s6, ry.s6, rz.s6, ra.s6, rx.s7, ry.s7, rz.s7, ra.s7), 0, rgba + 16);
        return;
    }
    uchar r[8], g[8], b[8], a[8];
    vstore8(rx, 0, r); vstore8(ry, 0, g); vstore8(rz, 0, b); vstore8(ra, 0, a);
    for (int l = 0; l < lanes; ++l) {
        out.depth[pix + l] = px->depth[l];
        out.quadric[pix + l] = px->quadric[l];
        out.primitive[pix + l] = px->primitive[l];
        out.rgba[pix + l] = (uchar4)(r[l], g[l], b[l], a[l]);
    }
}
#endif
