/* Microbenchmarks of the paper's Table 1 operations (python -m bench micro).
 *
 * The operations are the package's own device functions: this file includes
 * cl/include/quadric.h and sampling/heightfield.h, so what is timed is exactly what the
 * sampler and the renderers run.  Only the pointwise heightfield distortion, which the
 * package never needs by itself (it bounds distortion over rectangles), is written here.
 *
 * Method: each work-item loads one quadric (and its principal frame) into registers and
 * derives a point from its global id, then runs K iterations and sums the results; the sum is
 * the only store.  Two modes (build option DEPENDENT):
 *   0 (throughput): iteration k evaluates at p.x = x0 + k * eps; the iterations are
 *     independent, as in a loop over an array, but the input changes with k, so the
 *     compiler can neither hoist the operation out of the loop nor drop it;
 *   1 (latency): the result perturbs the next input, p.x += eps * v: one dependent chain
 *     per work-item.
 * eps is a kernel argument.  Memory traffic is one load of the quadric and one store per K
 * operations.  The `baseline` kernel runs the same loop with a trivial operation; its time is
 * subtracted.  Non-finite results (an undefined heightfield, a distortion of infinity) count
 * as 0 so the sums stay finite; the baseline does the same test.
 *
 * Build options: programs.build_options({"DEPENDENT": 0 or 1}, real) (-DCLCSG_DOUBLE for
 * double and the shared constants); include dirs cl/include and sampling.
 */
#include "quadric.h"
#include "heightfield.h"

#ifndef DEPENDENT
#define DEPENDENT 0
#endif
#if DEPENDENT
#define NEXT_INPUT(k, v) p += eps * (v)
#else
#define NEXT_INPUT(k, v) p = p0 + (real)(k + 1) * step
#endif

/* a point in [-1, 1]^3 from an integer (a cheap integer hash) */
inline real3 seed_point(uint g)
{
    uint a = g * 747796405u + 2891336453u;
    uint b = (a ^ (a >> 16)) * 2654435769u;
    uint c = (b ^ (b >> 13)) * 2246822519u;
    return (real3)((real)(a & 0xffff), (real)(b & 0xffff), (real)(c & 0xffff)) / (real)32767.5 - (real)1;
}

/* pointwise distortion of the heightfield of plane k at (x, y): |n| / |n_k| with
 * n = (lam_i x + beta_i, lam_j y + beta_j, lam_k t + beta_k), the surface's gradient / 2 */
inline real point_distortion(const plane_frame *pf, real x, real y)
{
    real ni = pf->li * x + pf->bi, nj = pf->lj * y + pf->bj;
    real nk2;
    if (pf->lk != 0) {
        nk2 = -pf->lk * plane_R(pf, x, y); /* lam_k^2 t^2 with t^2 = -R / lam_k */
        if (nk2 <= 0) return INFINITY;
    } else {
        nk2 = pf->bk * pf->bk;
    }
    return sqrt(1 + (ni * ni + nj * nj) / nk2);
}

#define MICRO(NAME, ...)                                                                       \
    __kernel void NAME(__global const quadric_rec *qs, __global const frame_rec *frames, int nq, \
                       int K, real eps, real width, __global real *out)                       \
    {                                                                                          \
        int gid = get_global_id(0);                                                            \
        int qi = gid % nq;                                                                     \
        quadric q = quadric_load(qs, qi);                                                      \
        real lam_min = qs[qi].lam_min, lam_max = qs[qi].lam_max;                               \
        plane_frame pf;                                                                        \
        plane_load(&pf, frames + qi, (gid / nq) % 3, (gid & 1) ? 1 : -1);                      \
        real3 p = seed_point((uint)gid);                                                       \
        real3 dir = normalize(seed_point((uint)gid + 0x9e3779b9u) + (real3)(0, 0, 1e-3));     \
        real3 p0 = p, step = eps * dir.zxy;                                                    \
        real acc = 0;                                                                          \
        /* a trip count that depends on the id (it is K): PoCL then keeps the loop inside  */ \
        /* each work-item instead of spilling the registers to per-work-group arrays at    */ \
        /* an implicit barrier in every iteration                                           */ \
        int kmax = K + (int)(gid >> 30);                                                       \
        for (int k = 0; k < kmax; ++k) {                                                       \
            real v;                                                                            \
            __VA_ARGS__;                                                                       \
            v = isfinite(v) ? v : 0;                                                           \
            acc += v;                                                                          \
            NEXT_INPUT(k, v);                                                                  \
        }                                                                                      \
        out[gid] = acc + lam_min + lam_max + pf.gamma + dir.x + q.ww;                          \
    }

/* the loop alone: the trivial "operation" is a sum of the inputs */
MICRO(baseline, v = p.x + p.y)

/* Q(x), eq. 3 */
MICRO(op_value, v = quadric_value(q, p))

/* N(x) = grad Q / |grad Q| (eq. 4, normalized) */
MICRO(op_normal, {
    real3 n = normalize(quadric_gradient(q, p));
    v = n.x + n.y + n.z;
})

/* heightfield value h(x, y) of a sampling plane (eq. 7) */
MICRO(op_height, {
    real t;
    v = plane_height(&pf, p.x, p.y, &t) ? t : 0;
})

/* heightfield distortion delta(x, y) at a point (section 3.4) */
MICRO(op_distortion, v = point_distortion(&pf, p.x, p.y))

/* min (and max) distortion over a region R = [x, x + w] x [y, y + w] (section 3.4) */
MICRO(op_min_distortion, {
    bool owned;
    real2 d = rect_distortion(&pf, p.x, p.x + width, p.y, p.y + width, &owned);
    v = owned ? d.y : d.x;
})

/* quadric-line intersection (eqs. 5, 6) */
MICRO(op_intersect, {
    real t1 = 0, t2 = 0;
    int n = quadric_intersect(q, p, dir, &t1, &t2);
    v = n > 0 ? t1 + t2 : 0;
})

/* conservative signed distance d(x0) (eqs. 10-12) */
MICRO(op_distance, v = quadric_distance(q, lam_min, lam_max, p))

/* Clock estimate: one chain of n dependent fused multiply-adds per work-item (4 cycles each on
 * current Intel and AMD cores), so ns per FMA per core / 4 = ns per cycle. */
__kernel void fma_chain(int n, real a, real b, __global real *out)
{
    int gid = get_global_id(0);
    real x = (real)gid * (real)1e-6;
    int m = n + (int)(gid >> 30);
    for (int i = 0; i < m; ++i) x = fma(x, a, b);
    out[gid] = x;
}

