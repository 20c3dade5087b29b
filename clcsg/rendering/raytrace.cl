/* Exact global CSG ray tracing of a DNF (paper section 7.2's reference renderer), one work-item
 * per pixel.  For the pixel's ray eye + t v (unit v):
 *
 *   for every term a, every literal b of a, every root t of Q_ab(eye + t v) = 0 (eqs. 5, 6):
 *       t is a hit of term a if t > 0 and every other literal j != b of a holds at
 *       p = eye + t v:  s_aj Q_aj(p) <= 0
 *   depth = the nearest hit over all terms.
 *
 * For a viewer outside the solid the first boundary point of the union of the (closed) terms
 * is the nearest first boundary point of a term, so no 1-D interval CSG is needed.  The roots
 * of a literal come sorted, so the first valid one is that literal's nearest; roots beyond the
 * current best are skipped, and terms whose (padded) bound the ray misses are skipped.
 *
 * Outputs depth (distance along the unit ray, +inf on background), ids (quadric index, -1)
 * and RGBA8 shaded with shade.h from the solid's outward normal s * grad Q (eq. 4).  The winning
 * depth is refined by one more solve from the hit point (accurate in float as well).
 */
#include "quadric.h"
#include "shade.h"

/* Does every literal of the term except literal `skip` hold at p? */
inline bool term_holds_except(__global const quadric_rec *quadrics, __global const literal_rec *literals,
                              int first, int count, int skip, real3 p)
{
    for (int l = 0; l < count; ++l) {
        if (l == skip) continue;
        literal_rec lit = literals[first + l];
        if (lit.sign * quadric_value(quadric_load(quadrics, lit.quadric), p) > 0) return false;
    }
    return true;
}

/* Slab test of the ray against the term bound padded by `pad`: may the ray meet it before tmax? */
inline bool ray_meets_box(__global const term_rec *t, real3 e, real3 v, real tmax, real pad)
{
    real3 lo = vload3(0, t->lo) - pad, hi = vload3(0, t->hi) + pad;
    real3 inv = 1 / v; /* +-inf for zero components: the slab test still works */
    real3 a = (lo - e) * inv, b = (hi - e) * inv;
    real3 tn = fmin(a, b), tf = fmax(a, b);
    /* NaN (0 * inf: the ray lies in a slab plane) counts as "inside the slab" via fmin/fmax */
    real t0 = fmax(fmax(tn.x, tn.y), fmax(tn.z, (real)0));
    real t1 = fmin(fmin(tf.x, tf.y), tf.z);
    return t0 <= t1 && t0 <= tmax;
}

__kernel void raytrace(__global const quadric_rec *quadrics, __global const literal_rec *literals,
                       __global const term_rec *terms, int n_terms, real bound_pad,
                       __global const view_rec *view, __global float *depth_out,
                       __global int *id_out, __global uchar4 *rgba_out)
{
    int j = get_global_id(0), i = get_global_id(1);
    if (i >= view->height || j >= view->width) return;
    int pix = i * view->width + j;
    real3 e = view_eye(view);
    real3 v = view_ray(view, i, j);

    real best = INFINITY;
    int best_q = -1, best_s = 0;
    for (int a = 0; a < n_terms; ++a) {
        if (!ray_meets_box(&terms[a], e, v, best, bound_pad)) continue;
        int first = terms[a].first, count = terms[a].count;
        for (int b = 0; b < count; ++b) {
            literal_rec lit = literals[first + b];
            real r[2];
            int n = quadric_intersect(quadric_load(quadrics, lit.quadric), e, v, &r[0], &r[1]);
            for (int k = 0; k < n; ++k) {
                real t = r[k];
                if (!(t > 0) || !(t < best)) continue;
                if (term_holds_except(quadrics, literals, first, count, b, e + t * v)) {
                    best = t;
                    best_q = lit.quadric;
                    best_s = lit.sign;
                    break;
                }
            }
        }
    }

    if (best_q < 0) {
        depth_out[pix] = INFINITY;
        id_out[pix] = -1;
        rgba_out[pix] = shade_background(view);
        return;
    }
    /* refine the depth by solving again from the hit, Q(p0 + tau v) = 0, p0 = e + best v, and
     * taking the root nearest 0: Q(p0) is then tiny and the roots are as accurate as the splat
     * renderer's near-sample solve (matters in float; a no-op up to rounding in double) */
    quadric q = quadric_load(quadrics, best_q);
    real3 p0 = e + best * v;
    real tau[2];
    int nr = quadric_intersect(q, p0, v, &tau[0], &tau[1]);
    if (nr > 0) {
        real d = (nr > 1 && fabs(tau[1]) < fabs(tau[0])) ? tau[1] : tau[0];
        if (fabs(d) < 1e-3 * best) best += d;
    }
    real3 p = e + best * v;
    real3 g = best_s * quadric_gradient(q, p);
    depth_out[pix] = (float)best;
    id_out[pix] = best_q;
    rgba_out[pix] = shade(view, vload4(0, quadrics[best_q].color), convert_float3(normalize(g)),
                          convert_float3(v));
}
