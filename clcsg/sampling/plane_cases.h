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
 * - M the product of another live quadric's line (a plane's conic is linear) and a linear
 *   factor of one sign over the cell: a cylinder that a face plane cuts in two lines, one of
 *   them where the box face it rounds ends (the fillet strip's faces): over the cell the two
 *   have one sign, or opposite signs (plane_line_factor).
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

/* Is c the product of the line l (a linear conic: l(x, y) = 2 l.x1 x + 2 l.y1 y + l.11) and a
 * linear factor f with one sign over the rectangle [x0, x1] x [y0, y1]?  Returns that sign
 * (+1, -1), or 0.  c vanishes on l's line (its restriction there, a s^2 + 2 b s + c0 along
 * p + s d, is 0 up to CASE_TOLERANCE), and f's coefficients follow from c's quadratic terms
 * (f's x and y coefficients) and its linear ones (f's constant). */
inline int plane_line_factor(const plane_conic *c, const plane_conic *l, real x0, real x1, real y0, real y1)
{
    real nx = 2 * l->m[3], ny = 2 * l->m[4], n0 = l->m[5]; /* l = nx x + ny y + n0 */
    real nn = nx * nx + ny * ny;
    if (!(nn > 0)) return 0;
    real px = -n0 * nx / nn, py = -n0 * ny / nn; /* the line's point nearest the origin */
    real dn = sqrt(nn), dx = -ny / dn, dy = nx / dn;
    real axx = c->m[0], axy = c->m[1], ayy = c->m[2], gx = c->m[3], gy = c->m[4];
    real a = dx * (axx * dx + axy * dy) + dy * (axy * dx + ayy * dy);
    real b = dx * (axx * px + axy * py + gx) + dy * (axy * px + ayy * py + gy);
    real c0 = px * (axx * px + axy * py + 2 * gx) + py * (axy * px + ayy * py + 2 * gy) + c->m[5];
    real reach = 1 + fabs(px) + fabs(py);
    if (!(fabs(a) <= CASE_TOLERANCE && fabs(b) <= CASE_TOLERANCE * reach && fabs(c0) <= CASE_TOLERANCE * reach * reach))
        return 0;
    /* c's quadratic part (fx x + fy y)(nx x + ny y), its linear part fx n0 x + fy n0 y + f0 (nx x + ny y) */
    real fx, fy, f0;
    if (fabs(nx) >= fabs(ny)) {
        fx = axx / nx;
        fy = (2 * axy - fx * ny) / nx;
        f0 = (2 * gx - fx * n0) / nx;
    } else {
        fy = ayy / ny;
        fx = (2 * axy - fy * nx) / ny;
        f0 = (2 * gy - fy * n0) / ny;
    }
    real lo = f0 + fmin(fx * x0, fx * x1) + fmin(fy * y0, fy * y1);
    real hi = f0 + fmax(fx * x0, fx * x1) + fmax(fy * y0, fy * y1);
    real margin = CASE_TOLERANCE * (fabs(f0) + fabs(fx) * fmax(fabs(x0), fabs(x1)) + fabs(fy) * fmax(fabs(y0), fabs(y1)));
    return lo > margin ? 1 : hi < -margin ? -1 : 0;
}

/* The cases (tape.h, surface_cases: bit c, live quadric m positive in case c iff bit m of c)
 * that some point of a plane task (pf: its frame) in the cell [x0, x1] x [y0, y1] may have,
 * given its k live quadrics. */
inline uint plane_possible_cases(const plane_frame *pf, __global const quadric_rec *qs, const int *live, int k,
                                 real x0, real x1, real y0, real y1)
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
    for (int m = 0; m < k; ++m) { /* conics with a live plane's line as a factor */
        if (!(c[m].m[0] == 0 && c[m].m[1] == 0 && c[m].m[2] == 0)) continue;
        for (int j = 0; j < k; ++j) {
            if (j == m || (c[j].m[0] == 0 && c[j].m[1] == 0 && c[j].m[2] == 0)) continue;
            int f = plane_line_factor(&c[j], &c[m], x0, x1, y0, y1);
            if (f) possible &= f > 0 ? ~(CASE_TABLE(m) ^ CASE_TABLE(j)) : CASE_TABLE(m) ^ CASE_TABLE(j);
        }
    }
    return possible;
#endif
}

#endif
