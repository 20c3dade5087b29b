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

/* Eight pixels pix ... pix + 7 of a row written: depth, quadric and primitive ids, and the
 * colours as RGBA words (shade_pack_rgba8).  With CLCSG_STREAM_STORES (set by the host on
 * PoCL's CPU devices, whose compiler is clang) and all four rows 32-byte aligned (a row width
 * that is a multiple of 8), as non-temporal stores: the outputs are written once and read by
 * the host, so they need not pass through the cache, nor be read into it before the write. */
#if CLCSG_STREAM_STORES
#define PIXEL_STREAM(v, p) __builtin_nontemporal_store((v), (p))
#else
#define PIXEL_STREAM(v, p) (*(p) = (v))
#endif
inline void pixel_store8(pixel_out out, int pix, float8 depth, int8 qid, int8 prim, uint8 rgba)
{
    __global float *pd = out.depth + pix;
    __global int *pq = out.quadric + pix, *pp = out.primitive + pix;
    __global uint *pc = (__global uint *)(out.rgba + pix);
    if ((((size_t)pd | (size_t)pq | (size_t)pp | (size_t)pc) & 31) == 0) {
        PIXEL_STREAM(depth, (__global float8 *)pd);
        PIXEL_STREAM(qid, (__global int8 *)pq);
        PIXEL_STREAM(prim, (__global int8 *)pp);
        PIXEL_STREAM(rgba, (__global uint8 *)pc);
        return;
    }
    vstore8(depth, 0, pd);
    vstore8(qid, 0, pq);
    vstore8(prim, 0, pp);
    vstore8(rgba, 0, pc);
}
#undef PIXEL_STREAM

/* The display colour of primitive prim (-1: grey). */
inline float4 pixel_color(__global const prim_rec *prims, int prim)
{
    return prim >= 0 ? vload4(0, prims[prim].color) : (float4)(0.8f, 0.8f, 0.8f, 1.0f);
}

/* normalize() of eight vectors (x, y, z) in place, as one real8 computation where |p|^2 is a
 * normal number: p (1 / sqrt((x x + y y) + z z)), the products rounded on their own (not
 * fused), which is bit for bit what PoCL's normalize() does there; the other lanes (zero, tiny
 * or huge vectors, where normalize() rescales first) take normalize() itself. */
inline void pixel_normalize8(real8 *x, real8 *y, real8 *z)
{
#pragma OPENCL FP_CONTRACT OFF
    real8 xx = *x * *x, yy = *y * *y, zz = *z * *z;
    real8 l2 = (xx + yy) + zz;
    real8 inv = 1 / sqrt(l2);
    real8 nx = *x * inv, ny = *y * inv, nz = *z * inv;
    if (any(!(l2 >= REAL_MIN && l2 <= REAL_MAX))) {
        real s[8], px[8], py[8], pz[8], ox[8], oy[8], oz[8];
        vstore8(l2, 0, s);
        vstore8(*x, 0, px); vstore8(*y, 0, py); vstore8(*z, 0, pz);
        vstore8(nx, 0, ox); vstore8(ny, 0, oy); vstore8(nz, 0, oz);
        for (int l = 0; l < 8; ++l)
            if (!(s[l] >= REAL_MIN && s[l] <= REAL_MAX)) {
                real3 n = normalize((real3)(px[l], py[l], pz[l]));
                ox[l] = n.x; oy[l] = n.y; oz[l] = n.z;
            }
        nx = vload8(0, ox); ny = vload8(0, oy); nz = vload8(0, oz);
    }
    *x = nx; *y = ny; *z = nz;
}

/* Pixels pix ... pix + lanes - 1 (lanes <= 8) as background: depth +inf, no quadric or
 * primitive, the background colour. */
inline void pixel_store_background(pixel_out out, __global const view_rec *view, int pix, int lanes)
{
    uchar4 bg = shade_background(view);
    if (lanes == 8) {
        pixel_store8(out, pix, (float8)(INFINITY), (int8)(-1), (int8)(-1), (uint8)(as_uint(bg)));
        return;
    }
    for (int l = 0; l < lanes; ++l) {
        out.depth[pix + l] = INFINITY;
        out.quadric[pix + l] = out.primitive[pix + l] = -1;
        out.rgba[pix + l] = bg;
    }
}

/* The outputs of RAY_LANES consecutive pixels of a row, gathered lane by lane (pixel_lanes_set)
 * and shaded together (pixel_lanes_store): per lane the depth, quadric and primitive ids (a miss
 * keeps pixel_lanes_clear's +inf, -1, -1), the linear albedo (shade_albedo), the gradient of
 * the hit quadric at the hit (normalized in pixel_lanes_store) and the unit view ray, in float. */
#if RAY_LANES != 8
#error "the pixel lanes are shaded as one float8"
#endif
typedef struct {
    real gx[8], gy[8], gz[8];
    float depth[8], ax[8], ay[8], az[8], aw[8], vx[8], vy[8], vz[8];
    int quadric[8], primitive[8];
} pixel_lanes;

inline void pixel_lanes_clear(pixel_lanes *px)
{
    for (int l = 0; l < 8; ++l) {
        px->depth[l] = INFINITY;
        px->quadric[l] = px->primitive[l] = -1;
        px->ax[l] = px->ay[l] = px->az[l] = px->aw[l] = 0.0f;
        px->gx[l] = px->gy[l] = 0;
        px->gz[l] = 1; /* a lane without a hit keeps a harmless normal and ray */
        px->vx[l] = px->vy[l] = 0.0f;
        px->vz[l] = -1.0f;
    }
}

/* Lane l: a hit at depth on quadric qid (gradient g there) shown as primitive prim, whose
 * albedo is given, on the unit view ray v. */
inline void pixel_lanes_set(pixel_lanes *px, int l, float depth, int qid, int prim, float4 albedo, real3 g,
                            float3 v)
{
    px->depth[l] = depth;
    px->quadric[l] = qid;
    px->primitive[l] = prim;
    px->ax[l] = albedo.x; px->ay[l] = albedo.y; px->az[l] = albedo.z; px->aw[l] = albedo.w;
    px->gx[l] = g.x; px->gy[l] = g.y; px->gz[l] = g.z;
    px->vx[l] = v.x; px->vy[l] = v.y; px->vz[l] = v.z;
}

/* The lanes shaded (shade_light8 with the unit normals g / |g| in float, shade_encode8;
 * misses: shade_background) and written to pixels pix ... pix + lanes - 1.  Inlined, so that
 * a caller that fills px with vectors (trace_uniform_store) keeps them in registers. */
__attribute__((always_inline)) inline void pixel_lanes_store(pixel_out out, __global const view_rec *view, int pix,
                                                             int lanes, pixel_lanes *px)
{
    int8 qid = vload8(0, px->quadric);
    char8 hit = convert_char8(qid >= 0);
    uchar4 bg = shade_background(view);
    uchar8 rx = bg.x, ry = bg.y, rz = bg.z, ra = bg.w;
    if (any(hit)) {
        real8 gx = vload8(0, px->gx), gy = vload8(0, px->gy), gz = vload8(0, px->gz);
        pixel_normalize8(&gx, &gy, &gz);
        float8 cx, cy, cz;
        shade_light8(view, vload8(0, px->ax), vload8(0, px->ay), vload8(0, px->az), convert_float8(gx),
                     convert_float8(gy), convert_float8(gz), vload8(0, px->vx), vload8(0, px->vy),
                     vload8(0, px->vz), &cx, &cy, &cz);
        rx = select(rx, shade_encode8(view, cx), hit);
        ry = select(ry, shade_encode8(view, cy), hit);
        rz = select(rz, shade_encode8(view, cz), hit);
        ra = select(ra, convert_uchar8_sat(vload8(0, px->aw) * 255.0f + 0.5f), hit);
    }
    if (lanes == 8) {
        pixel_store8(out, pix, vload8(0, px->depth), qid, vload8(0, px->primitive),
                     shade_pack_rgba8(rx, ry, rz, ra));
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
