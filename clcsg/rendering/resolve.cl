/* Resolve pass of the splat renderer, one work-item per pixel.  The framebuffer word holds
 * (float depth bits << 32 | sample index) of the nearest accepted fragment (splat.cl).  Outputs
 * the depth (distance along the unit view ray), the quadric and primitive ids and the colour of
 * the primitive whose boundary holds the hit (primitives.h), shaded with shade.h (the
 * primitives' albedos computed once per view by the albedo kernel, the encoding through the
 * table of the encoding kernel): the same shading as the ray tracer.
 *
 * Where the sample's splat_primitive is set (the colour rule gives one primitive over its whole
 * ball), the depth is the stored float z and the shaded point e + z v: the splat pass computed
 * z as (float)((s - e).v + tau) from the same ray, so this is its own depth output, and the
 * point is within half a float ulp of depth of the root, which the 8-bit shading does not
 * resolve (one pixel of the gear's 808,182 at 1080p moves by one level).  Elsewhere the hit is
 * recomputed from the winning sample's quadric, solved near the sample as in splat.cl
 * (o = e + ((s - e).v) v, Q(o + tau v) = 0, eqs. 5, 6) in `real` precision, taking the root
 * whose depth (s - e).v + tau is nearest the stored depth, for the colour rule at the exact
 * point.  EMPTY_KEY comes from clcsg/cl/constants.py. */
#include "pixel.h"

/* Per primitive k < n (and the grey of "none" at k = n): its albedo (shade_albedo) for this view. */
__kernel void albedo(__global const prim_rec *prims, int n, __global const view_rec *view, __global float4 *out)
{
    int k = get_global_id(0);
    if (k <= n) out[k] = shade_albedo(view, pixel_color(prims, k < n ? k : -1));
}

/* Entry b <= SHADE_BINS of the colour encoding's table for this view (shade_table_entry). */
__kernel void encoding(__global const view_rec *view, __global ushort *out)
{
    int b = get_global_id(0);
    if (b <= SHADE_BINS) out[b] = shade_table_entry(view, b);
}

__kernel void resolve(__global const quadric_rec *quadrics, __global const sample_rec *samples,
                      PRIMITIVE_TABLE, __global const view_rec *view, __global const ulong *framebuffer,
                      __global const float4 *albedo, int n_prims, __global const ushort *encoding,
                      PIXEL_OUTPUTS)
{
    int i, j;
    int pix = pixel_index(view, &i, &j);
    if (pix < 0) return;
    ulong key = framebuffer[pix];
    pixel_out out = PIXEL_OUT;
    if (key == EMPTY_KEY) {
        pixel_miss(out, view, pix);
        return;
    }
    uint idx = (uint)(key & 0xffffffffUL);
    real stored = (real)as_float((uint)(key >> 32));
    __global const sample_rec *sp = &samples[idx];
    real3 e = view_eye(view);
    real3 v = view_ray(view, i, j);
    int prim = sp->splat_primitive;
    real depth = stored;
    real3 p = e + stored * v;
    if (prim < 0) { /* the colour rule at the exact root */
        quadric q = quadric_load(quadrics, sp->quadric);
        real tc = dot(vload3(0, sp->pos) - e, v);
        real3 o;
        real tau[2];
        int nr = quadric_intersect_near(q, e, v, tc, &o, &tau[0], &tau[1]);
        real t = stored - tc; /* fallback: the stored depth (the roots vanished in rounding) */
        if (nr > 0) {
            t = tau[0];
            if (nr > 1 && fabs(tc + tau[1] - stored) < fabs(tc + tau[0] - stored)) t = tau[1];
        }
        p = o + t * v;
        depth = tc + t;
        prim = primitive_at(PRIMITIVE_TABLE_ARGS, quadrics, sp->quadric, p);
    }
    float4 alb = albedo[prim >= 0 ? prim : n_prims];
    float3 c = shade_light(view, alb, pixel_normal(quadrics, sp->quadric, p), convert_float3(v));
    pixel_write(out, pix, prim, sp->quadric, depth, shade_encode_table(view, encoding, c, alb.w));
}
