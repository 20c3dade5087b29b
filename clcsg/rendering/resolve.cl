/* Resolve pass of the splat renderer, one work-item per RESOLVE_LANES pixels of a row.  The framebuffer word holds
 * (float bits of the ray parameter t << 32 | sample index) of the nearest accepted fragment (splat.cl).  Outputs
 * the depth (distance along the unit view ray), the quadric and primitive ids and the colour of
 * the primitive whose boundary holds the hit (primitives.h), shaded with shade.h (the
 * primitives' albedos computed once per view by the albedo kernel; the view rays, normals,
 * lighting and encoding as float8 over the lanes, one body with the ray tracer's scalar
 * shade_light): the same shading as the ray tracer, whose normals are double where the device
 * has fp64 (the normal's float rounding is far below the 8-bit output's).
 *
 * The word's depth is the root's parameter t on the ray e + t d of the pixel, d = d00 + j dx
 * + i dy not normalized (splat.cl), rounded to float; the depth output is t |d| (resolve_depth8,
 * in `real`: within a float ulp of the root's distance).  Where the sample's splat_primitive is
 * set (the colour rule gives one primitive over its whole ball), the shaded point is e + t d,
 * within half a float ulp of t of the root, which the 8-bit shading does not resolve.
 * Elsewhere the hit is
 * recomputed from the winning sample's quadric, solved near the sample as in splat.cl
 * (o = e + ((s - e).v) v, Q(o + tau v) = 0, eqs. 5, 6) in `real` precision, taking the root
 * whose depth (s - e).v + tau is nearest the stored t |d|, for the colour rule at the exact
 * point.  The winning sample's quadric and splat_primitive are read from sample_ids, an int2 per
 * sample, not from its whole record.  EMPTY_KEY comes from clcsg/cl/constants.py. */
#include "pixel.h"
#if RESOLVE_LANES != 8
#error "the resolve pass shades RESOLVE_LANES pixels as one float8"
#endif

/* Per primitive k < n (and the grey of "none" at k = n): its albedo (shade_albedo) for this view. */
__kernel void albedo(__global const prim_rec *prims, int n, __global const view_rec *view, __global float4 *out)
{
    int k = get_global_id(0);
    if (k <= n) out[k] = shade_albedo(view, pixel_color(prims, k < n ? k : -1));
}

/* The hit of framebuffer word key (not EMPTY_KEY) on the view ray e + t d (d not normalized):
 * its depth (along the unit ray), point p, quadric and primitive (see the file's comment). */
inline int resolve_hit(__global const quadric_rec *quadrics, __global const sample_rec *samples, PRIMITIVE_TABLE,
                       ulong key, real3 e, real3 d, real *depth, real3 *p, int *qid)
{
    uint idx = (uint)(key & 0xffffffffUL);
    real t = (real)as_float((uint)(key >> 32)), len = length(d);
    real3 v = d / len;
    real stored = t * len;
    __global const sample_rec *sp = &samples[idx];
    int prim = sp->splat_primitive;
    *qid = sp->quadric;
    *depth = stored;
    *p = e + t * d;
    if (prim < 0) { /* the colour rule at the exact root */
        quadric q = quadric_load(quadrics, sp->quadric);
        real tc = dot(vload3(0, sp->pos) - e, v);
        real3 o;
        real tau[2];
        int nr = quadric_intersect_near(q, e, v, tc, &o, &tau[0], &tau[1]);
        real u = stored - tc; /* fallback: the stored depth (the roots vanished in rounding) */
        if (nr > 0) {
            u = tau[0];
            if (nr > 1 && fabs(tc + tau[1] - stored) < fabs(tc + tau[0] - stored)) u = tau[1];
        }
        *p = o + u * v;
        *depth = tc + u;
        prim = primitive_at(PRIMITIVE_TABLE_ARGS, quadrics, sp->quadric, *p);
    }
    return prim;
}

/* Lane l (vector component c) of the resolve pass's gather: the framebuffer word and, unless
 * it is a miss, the winning sample's t, quadric and primitive, coefficients and albedo (and,
 * where the colour rule needs the exact root, resolve_hit's point and depth).  A macro over constant
 * components keeps the vectors in registers (OpenCL has no dynamic component index). */
#define RESOLVE_GATHER(l, c)                                                                        \
    if ((l) < lanes) {                                                                              \
        ulong key = K.c;                                                                            \
        if (key != EMPTY_KEY) {                                                                     \
            int2 sid = sample_ids[(uint)(key & 0xffffffffUL)];                                     \
            int qid = sid.x, prim = sid.y;                                                          \
            if (prim < 0) {                                                                         \
                real3 p;                                                                            \
                real depth;                                                                         \
                prim = resolve_hit(quadrics, samples, PRIMITIVE_TABLE_ARGS, key, e,                 \
                                   view_dir(view, i, j0 + (l)), &depth, &p, &qid);                  \
                PX.c = p.x; PY.c = p.y; PZ.c = p.z;                                                 \
                DEPTH.c = (float)depth;                                                             \
                exact |= 1 << (l);                                                                  \
            }                                                                                       \
            Z.c = as_float((uint)(key >> 32));                                                      \
            __global const real *q = quadrics[qid].coef;                                            \
            XX.c = q[0]; XY.c = q[1]; XZ.c = q[2]; BX.c = q[3];                                     \
            YY.c = q[4]; YZ.c = q[5]; BY.c = q[6]; ZZ.c = q[7]; BZ.c = q[8];                        \
            QID.c = qid; PRIM.c = prim;                                                             \
            float4 alb = albedo[prim >= 0 ? prim : n_prims];                                        \
            AX.c = alb.x; AY.c = alb.y; AZ.c = alb.z; AW.c = alb.w;                                 \
            hits |= 1 << (l);                                                                       \
        }                                                                                           \
    }

/* The depth outputs t |d| of the eight pixels j0 ... j0 + 7 of row i, from their words' t
 * (the splat pass's rays d = d00 + j dx + i dy, view_dirs8), in `real`. */
inline float8 resolve_depth8(__global const view_rec *view, int i, int j0, float8 t)
{
    real8 dX, dY, dZ;
    view_dirs8(view, i, j0, &dX, &dY, &dZ);
    return convert_float8(convert_real8(t) * sqrt(dX * dX + dY * dY + dZ * dZ));
}

/* The colours of the lanes in `hits` (the others keep the background), in float (shading
 * needs no more): the view rays of the lanes (view_ray), the points e + t d or, in the lanes
 * of `exact`, (PX, PY, PZ), the normals grad Q / |grad Q| (eq. 4), the lighting (shade_light8)
 * and the encoding (shade_encode8).  Inlined twice: for eight hits on one quadric and
 * primitive the coefficients and albedo are broadcast scalars, which leaves the vector
 * registers to the per-pixel values. */
__attribute__((always_inline)) inline void resolve_colours8(__global const view_rec *view, int i, int j0, real3 e,
    float8 Z, float8 PX, float8 PY, float8 PZ, int exact, int hits, float8 XX, float8 XY, float8 XZ, float8 BX,
    float8 YY, float8 YZ, float8 BY, float8 ZZ, float8 BZ, float8 AX, float8 AY, float8 AZ, float8 AW,
    uchar8 *rx, uchar8 *ry, uchar8 *rz, uchar8 *ra)
{
    uchar4 bg = shade_background(view);
    *rx = bg.x; *ry = bg.y; *rz = bg.z; *ra = bg.w;
    if (!hits) return;
    float8 jj = (float8)(j0) + (float8)(0, 1, 2, 3, 4, 5, 6, 7), ii = (float8)((float)i);
    float8 dX = (float)view->d00[0] + jj * (float)view->dx[0] + ii * (float)view->dy[0];
    float8 dY = (float)view->d00[1] + jj * (float)view->dx[1] + ii * (float)view->dy[1];
    float8 dZ = (float)view->d00[2] + jj * (float)view->dx[2] + ii * (float)view->dy[2];
    float8 il = 1.0f / sqrt(dX * dX + dY * dY + dZ * dZ);
    float8 vX = dX * il, vY = dY * il, vZ = dZ * il;
    int8 use = (((int8)(exact) >> (int8)(0, 1, 2, 3, 4, 5, 6, 7)) & 1) != 0;
    float8 pX = select((float)e.x + Z * dX, PX, use);
    float8 pY = select((float)e.y + Z * dY, PY, use);
    float8 pZ = select((float)e.z + Z * dZ, PZ, use);
    /* grad Q / 2 = A p - b (layout.h: the w column holds -b) */
    float8 gX = XX * pX + XY * pY + XZ * pZ + BX;
    float8 gY = XY * pX + YY * pY + YZ * pZ + BY;
    float8 gZ = XZ * pX + YZ * pY + ZZ * pZ + BZ;
    float8 gl = 1.0f / sqrt(gX * gX + gY * gY + gZ * gZ);
    float8 cx, cy, cz;
    shade_light8(view, AX, AY, AZ, gX * gl, gY * gl, gZ * gl, vX, vY, vZ, &cx, &cy, &cz);
    char8 hit = (((char8)((char)hits) >> (char8)(0, 1, 2, 3, 4, 5, 6, 7)) & (char8)(1)) != (char8)(0);
    *rx = select(*rx, shade_encode8(view, cx), hit);
    *ry = select(*ry, shade_encode8(view, cy), hit);
    *rz = select(*rz, shade_encode8(view, cz), hit);
    *ra = select(*ra, convert_uchar8_sat(AW * 255.0f + 0.5f), hit);
}

/* One work-item per RESOLVE_LANES pixels of a row: RESOLVE_GATHER per pixel (or, for eight
 * hits on one quadric and primitive, its coefficients and albedo read once), then
 * resolve_colours8 on the lanes as float8 vectors. */
__kernel void resolve(__global const quadric_rec *quadrics, __global const sample_rec *samples,
                      __global const int2 *sample_ids, PRIMITIVE_TABLE, __global const view_rec *view,
                      __global const ulong *framebuffer, __global const float4 *albedo, int n_prims,
                      PIXEL_OUTPUTS)
{
    int i = get_global_id(1), j0 = get_global_id(0) * RESOLVE_LANES;
    int W = view->width;
    if (i >= view->height || j0 >= W) return;
    int lanes = min(RESOLVE_LANES, W - j0);
    pixel_out out = PIXEL_OUT;
    real3 e = view_eye(view);
    /* the lanes not shown keep a unit sphere at the origin: harmless */
    float8 Z = 0, PX = 0, PY = 0, PZ = 0, XX = 1, XY = 0, XZ = 0, YY = 1, YZ = 0, ZZ = 1, BX = 0, BY = 0, BZ = 0;
    float8 AX = 0, AY = 0, AZ = 0, AW = 0;
    float8 DEPTH = INFINITY; /* the outputs, as pixel_miss where no fragment reached */
    int8 QID = -1, PRIM = -1;
    int hits = 0, exact = 0;
    int pix = i * W + j0;
    ulong8 K = (ulong8)(EMPTY_KEY); /* the words */
    if (lanes == RESOLVE_LANES) {
        K = vload8(0, framebuffer + pix);
    } else {
        for (int l = 0; l < lanes; ++l) ((ulong *)&K)[l] = framebuffer[pix + l];
    }
    if (all(K == (ulong8)(EMPTY_KEY)) && lanes == RESOLVE_LANES) { /* the background only */
        pixel_store_background(out, view, pix, lanes);
        return;
    }
    /* eight hits of samples on one quadric with one fixed primitive (most of a surface's
     * inside): the coefficients and the albedo are read once; else lane by lane */
    bool uniform = lanes == RESOLVE_LANES && all(K != (ulong8)(EMPTY_KEY));
    int q0 = -1, p0 = -1;
    if (uniform) {
        uint8 sidx = convert_uint8(K & (ulong8)(0xffffffffUL));
        int2 s0 = sample_ids[sidx.s0];
        q0 = s0.x;
        p0 = s0.y;
#define RESOLVE_SAME(c) uniform &= all(sample_ids[sidx.c] == s0);
        RESOLVE_SAME(s1) RESOLVE_SAME(s2) RESOLVE_SAME(s3) RESOLVE_SAME(s4) RESOLVE_SAME(s5) RESOLVE_SAME(s6)
        RESOLVE_SAME(s7)
#undef RESOLVE_SAME
        uniform &= p0 >= 0;
    }
    uchar8 rx, ry, rz, ra;
    if (uniform) { /* all eight lanes hit: stored at once */
        Z = convert_float8(as_float8(convert_uint8(K >> 32)));
        __global const real *q = quadrics[q0].coef;
        float4 alb = albedo[p0];
        resolve_colours8(view, i, j0, e, Z, PX, PY, PZ, 0, 0xff, (float8)((float)q[0]), (float8)((float)q[1]),
                         (float8)((float)q[2]), (float8)((float)q[3]), (float8)((float)q[4]), (float8)((float)q[5]),
                         (float8)((float)q[6]), (float8)((float)q[7]), (float8)((float)q[8]), (float8)(alb.x),
                         (float8)(alb.y), (float8)(alb.z), (float8)(alb.w), &rx, &ry, &rz, &ra);
        pixel_store8(out, pix, resolve_depth8(view, i, j0, Z), (int8)(q0), (int8)(p0),
                     shade_pack_rgba8(rx, ry, rz, ra));
        return;
    }
    RESOLVE_GATHER(0, s0) RESOLVE_GATHER(1, s1) RESOLVE_GATHER(2, s2) RESOLVE_GATHER(3, s3)
    RESOLVE_GATHER(4, s4) RESOLVE_GATHER(5, s5) RESOLVE_GATHER(6, s6) RESOLVE_GATHER(7, s7)
    resolve_colours8(view, i, j0, e, Z, PX, PY, PZ, exact, hits, XX, XY, XZ, BX, YY, YZ, BY, ZZ, BZ, AX, AY, AZ, AW,
                     &rx, &ry, &rz, &ra);
    int8 from_t = (((int8)(hits & ~exact) >> (int8)(0, 1, 2, 3, 4, 5, 6, 7)) & 1) != 0;
    if (hits & ~exact) DEPTH = select(DEPTH, resolve_depth8(view, i, j0, Z), from_t);
    /* the row's eight pixels at once, or the lanes one by one at the row's end */
    if (lanes == RESOLVE_LANES) {
        pixel_store8(out, pix, DEPTH, QID, PRIM, shade_pack_rgba8(rx, ry, rz, ra));
        return;
    }
#define RESOLVE_STORE(l, c)                                                                         \
    if ((l) < lanes) {                                                                              \
        out.depth[pix + (l)] = DEPTH.c;                                                             \
        out.quadric[pix + (l)] = QID.c;                                                             \
        out.primitive[pix + (l)] = PRIM.c;                                                          \
        out.rgba[pix + (l)] = (uchar4)(rx.c, ry.c, rz.c, ra.c);                                     \
    }
    RESOLVE_STORE(0, s0) RESOLVE_STORE(1, s1) RESOLVE_STORE(2, s2) RESOLVE_STORE(3, s3)
    RESOLVE_STORE(4, s4) RESOLVE_STORE(5, s5) RESOLVE_STORE(6, s6) RESOLVE_STORE(7, s7)
#undef RESOLVE_STORE
}
