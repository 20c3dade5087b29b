/* Sign relations of quadrics on a plane, for the sampler's case analysis (tape.h,
 * surface_cases; used by sampler.cl on tasks whose quadric is a plane).
 *
 * On a plane task the heightfield is linear, t = -(2 beta_i x + 2 beta_j y + gamma) / (2 beta_k),
 * so its points are p(x, y) = P0 + x Px + y Py, and a quadric Q(p) = p.A p + 2 w.p + w0 there is
 * the conic [x y 1] M [x y 1]^T with
 *     M = | Px.A Px   Px.A Py   Px.(A P0 + w) |
 *         |    .      Py.A Py   Py.(A P0 + w) |
 *         |    .         .         Q(P0)      |.
 * - M positive semidefinite: Q >= 0 all over the plane (a cylinder or cone touching it along a
 *   line, a sphere touching it at a point: a fillet tangent to a face), so no point of the plane
 *   has Q < 0, and the case "negative" is dropped; negative semidefinite likewise.
 * - M a multiple of another live quadric's M: the two have one sign (or opposite signs)
 *   everywhere on the plane (a chamfer cone and a counterbore cylinder that meet the plane in
 *   one circle), so the cases where they differ are dropped.
 * Only points where a quadric is exactly 0 are left out (see tape.h, surface_cases).
 *
 * M is normalized by its largest entry and compared with CASE_TOLERANCE: the relations hold
 * up to the rounding of the quadrics' coefficients (an intended tangency, written as one).
 * Without double precision the rounding is too coarse to tell: no relations. */
#ifndef CLCSG_PLANE_CASES_H
#define CLCSG_PLANE_CASES_H
#include "heightfield.h"
#include "tape.h"

#define CASE_TOLERANCE (256 * REAL_EPS)

/* M's entries xx, xy, yy, x1, y1, 11, divided by the largest in absolute value */
typedef struct {
    real m[6];
} plane_conic;

inline plane_conic plane_conic_of(quadric Q, real3 P0, real3 Px, real3 Py)
{
    real3 APx = quadric_Ap(Q, Px), APy = quadric_Ap(Q, Py);
    real3 g = quadric_Ap(Q, P0) + quadric_minus_b(Q);
    plane_conic c = {{dot(Px, APx), dot(Px, APy), dot(Py, APy), dot(Px, g), dot(Py, g), quadric_value(Q, P0)}};
    real s = 0;
    for (int m = 0; m < 6; ++m) s = fmax(s, fabs(c.m[m]));
    for (int m = 0; m < 6; ++m) c.m[m] = s > 0 ? c.m[m] / s : 0;
    return c;
}

/* Is s M (s = +-1) positive semidefinite, up to CASE_TOLERANCE?  Symmetric elimination with
 * the largest remaining diagonal entry as the pivot (stable on semidefinite matrices): a pivot
 * above the tolerance is eliminated; once none is, what is left must vanish (a semidefinite
 * matrix with a zero diagonal entry has a zero row there).  A tangent cylinder's conic has
 * rank 1, and this sees it exactly up to rounding, where an eigenvalue formula loses half the
 * digits at the double root. */
inline bool plane_conic_semidefinite(const plane_conic *c, real s)
{
    real a[3][3] = {{s * c->m[0], s * c->m[1], s * c->m[3]},
                    {s * c->m[1], s * c->m[2], s * c->m[4]},
                    {s * c->m[3], s * c->m[4], s * c->m[5]}};
    bool done[3] = {false, false, false};
    for (int step = 0; step < 3; ++step) {
        int p = -1;
        real best = -INFINITY;
        for (int i = 0; i < 3; ++i)
            if (!done[i] && a[i][i] > best) {
                best = a[i][i];
                p = i;
            }
        if (best <= CASE_TOLERANCE) {
            for (int i = 0; i < 3; ++i)
                for (int j = 0; j < 3; ++j)
                    if (!done[i] && !done[j] && fabs(a[i][j]) > CASE_TOLERANCE) return false;
            return true;
        }
        done[p] = true;
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j)
                if (!done[i] && !done[j]) a[i][j] -= a[i][p] * a[p][j] / best;
    }
    return true;
}

/* The cases (tape.h, surface_cases: bit c, live quadric m positive in case c iff bit m of c)
 * that some point of a plane task (pf: its frame) may have, given its k live quadrics. */
inline uint plane_possible_cases(const plane_frame *pf, __global const quadric_rec *qs, const int *live, int k)
{
#ifndef CLCSG_DOUBLE
    return ~0u;
#else
    if (!(pf->li == 0 && pf->lj == 0 && pf->lk == 0) || pf->bk == 0) return ~0u;
    real3 P0 = plane_point(pf, 0, 0, -pf->gamma / (2 * pf->bk));
    real3 Px = plane_axis(pf, pf->i) - (pf->bi / pf->bk) * plane_axis(pf, pf->k);
    real3 Py = plane_axis(pf, pf->j) - (pf->bj / pf->bk) * plane_axis(pf, pf->k);
    plane_conic c[CASE_QUADRICS];
    uint possible = ~0u;
    for (int m = 0; m < k; ++m) {
        c[m] = plane_conic_of(quadric_load(qs, live[m]), P0, Px, Py);
        uint pos = CASE_TABLE(m);
        if (plane_conic_semidefinite(&c[m], 1)) {
            possible &= pos;
            continue;
        }
        if (plane_conic_semidefinite(&c[m], -1)) {
            possible &= ~pos;
            continue;
        }
        for (int j = 0; j < m; ++j) {
            bool same = true, opposite = true;
            for (int e = 0; e < 6; ++e) {
                same = same && fabs(c[m].m[e] - c[j].m[e]) <= CASE_TOLERANCE;
                opposite = opposite && fabs(c[m].m[e] + c[j].m[e]) <= CASE_TOLERANCE;
            }
            if (same || opposite) {
                possible &= same ? ~(pos ^ CASE_TABLE(j)) : pos ^ CASE_TABLE(j);
                break;
            }
        }
    }
    return possible;
#endif
}

#endif
