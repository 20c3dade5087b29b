/* Sign relations between live quadrics that drop the cases of the sampler's case analysis
 * (tape.h, surface_cases; used by sampler.cl) that no point of a cell has: on plane tasks
 * through the quadrics' conics on the plane (plane_possible_cases), on any task through a live
 * plane (task_possible_cases: parallel planes, and a quadric meeting a plane in the task
 * quadric's conic).
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
 * - M another live quadric's M times mu > 0 plus a semidefinite term (concentric circles: a
 *   cone's cap moved by an eps overlap against the cylinder it continues): one sign implies the
 *   other's (plane_conics_nested).
 * - M the product of another live quadric's line (a plane's conic is linear) and a linear
 *   factor of one sign over the cell: a cylinder that a face plane cuts in two lines, one of
 *   them where the box face it rounds ends (the fillet strip's faces): over the cell the two
 *   have one sign, or opposite signs (plane_line_factor).
 * Only points where a quadric is exactly 0 are left out (see tape.h, surface_cases).
 *
 * Entries are compared relative to the largest, with CASE_TOLERANCE (256 ulps; the offsets of
 * parallel planes and of nested conics must be far above it): the relations hold up to the
 * rounding of the quadrics' coefficients (an intended tangency, written as one).  Without
 * double precision the rounding is too coarse to tell: no relations. */
#ifndef CLCSG_PLANE_CASES_H
#define CLCSG_PLANE_CASES_H
#include "heightfield.h"
#include "tape.h"

#define CASE_TOLERANCE (256 * REAL_EPS)

/* M's entries xx, xy, yy, x1, y1, 11, divided by the largest in absolute value (scale) */
typedef struct {
    real m[6];
    real scale;
} plane_conic;

inline plane_conic plane_conic_of(quadric Q, real3 P0, real3 Px, real3 Py)
{
    real3 APx = quadric_Ap(Q, Px), APy = quadric_Ap(Q, Py);
    real3 g = quadric_Ap(Q, P0) + quadric_minus_b(Q);
    plane_conic c = {{dot(Px, APx), dot(Px, APy), dot(Py, APy), dot(Px, g), dot(Py, g), quadric_value(Q, P0)}, 0};
    real s = 0;
    for (int m = 0; m < 6; ++m) s = fmax(s, fabs(c.m[m]));
    for (int m = 0; m < 6; ++m) c.m[m] = s > 0 ? c.m[m] / s : 0;
    c.scale = s;
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

/* +1 (-1) if conics a and b are positive (negative) multiples of each other, up to
 * CASE_TOLERANCE, else 0 */
inline int plane_conics_proportional(const plane_conic *a, const plane_conic *b)
{
    bool same = a->scale > 0 && b->scale > 0, opposite = same;
    for (int e = 0; e < 6; ++e) {
        same = same && fabs(a->m[e] - b->m[e]) <= CASE_TOLERANCE;
        opposite = opposite && fabs(a->m[e] + b->m[e]) <= CASE_TOLERANCE;
    }
    return same ? 1 : opposite ? -1 : 0;
}

/* Quadric Q as its symmetric 4x4 matrix (x, 1)^T H (x, 1): rows of A and w = -b, then (w, w0) */
inline void quadric_matrix4(quadric Q, real h[4][4])
{
    real v[4][4] = {{Q.xx, Q.xy, Q.xz, Q.xw}, {Q.xy, Q.yy, Q.yz, Q.yw}, {Q.xz, Q.yz, Q.zz, Q.zw}, {Q.xw, Q.yw, Q.zw, Q.ww}};
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) h[i][j] = v[i][j];
}

/* Over the surface of the task's quadric S, in the cell's box g: is quadric Qj the live plane
 * P's value times a linear factor of one sign there?  If Qj and S meet P in one conic (Qj = mu S
 * on P: a flare cone and the turret cylinder it widens to meet the plane of their common
 * circle), Qj - mu S vanishes on P, so it is P L for a linear L (from its matrix D = (p l^T +
 * l p^T) / 2: l = 2 D u - (u^T D u) p with p.u = 1), and on S, Qj = P L.  Returns L's sign over
 * the box (+1, -1), or 0. */
inline int task_plane_factor(quadric S, quadric P, quadric Qj, const prune_region *g)
{
    real4 p = (real4)(2 * P.xw, 2 * P.yw, 2 * P.zw, P.ww); /* P(x) = p.(x, 1) */
    real3 n = p.xyz;
    real nn = dot(n, n);
    if (!(nn > 0)) return 0;
    real3 nh = n / sqrt(nn);
    real3 Px = normalize(cross(nh, fabs(nh.x) < 0.6 ? (real3)(1, 0, 0) : (real3)(0, 1, 0)));
    real3 Py = cross(nh, Px);
    real3 P0 = -(p.w / nn) * n;
    plane_conic cj = plane_conic_of(Qj, P0, Px, Py), cs = plane_conic_of(S, P0, Px, Py);
    int k = plane_conics_proportional(&cj, &cs);
    if (!k) return 0;
    real mu = k * cj.scale / cs.scale;
    real hj[4][4], hs[4][4], d[4][4];
    quadric_matrix4(Qj, hj);
    quadric_matrix4(S, hs);
    real big = 0;
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) {
            d[i][j] = hj[i][j] - mu * hs[i][j];
            big = fmax(big, fabs(hj[i][j]) + fabs(mu * hs[i][j]));
        }
    real pv[4] = {p.x, p.y, p.z, p.w}, pp = dot(p, p), u[4], du[4], udu = 0;
    for (int i = 0; i < 4; ++i) u[i] = pv[i] / pp;
    for (int i = 0; i < 4; ++i) {
        du[i] = 0;
        for (int j = 0; j < 4; ++j) du[i] += d[i][j] * u[j];
        udu += u[i] * du[i];
    }
    real l[4];
    for (int i = 0; i < 4; ++i) l[i] = 2 * du[i] - udu * pv[i];
    for (int i = 0; i < 4; ++i) /* D must be that product */
        for (int j = 0; j < 4; ++j)
            if (fabs(d[i][j] - 0.5 * (pv[i] * l[j] + l[i] * pv[j])) > CASE_TOLERANCE * big) return 0;
    real3 l3 = (real3)(l[0], l[1], l[2]);
    real mid = dot(l3, g->c) + l[3];
    real spread = fabs(dot(l3, g->a0)) + fabs(dot(l3, g->a1)) + fabs(dot(l3, g->a2));
    real margin = CASE_TOLERANCE * (fabs(l[3]) + length(l3) * (length(g->c) + spread + 1));
    return mid - spread > margin ? 1 : mid + spread < -margin ? -1 : 0;
}

/* The cases two parallel planes cannot have together anywhere (CASE_TABLE bits), 0 if the
 * planes are not parallel: offset planes n.x = d1 and n.x = d2 (OpenSCAD's eps overlaps: a
 * cap 0.01 below the face it joins) split space in three slabs, not four, so one of the four
 * sign pairs has no point.  Parallel up to CASE_TOLERANCE and offset by much more, so that
 * where they would cross is far outside any scene. */
inline uint parallel_planes_impossible(quadric A, quadric B, int ma, int mb)
{
    real3 na = (real3)(A.xw, A.yw, A.zw), nb = (real3)(B.xw, B.yw, B.zw);
    real la = length(na), lb = length(nb);
    if (!(la > 0 && lb > 0)) return 0;
    real3 ua = na / la, ub = nb / lb;
    if (length(cross(ua, ub)) > CASE_TOLERANCE) return 0;
    /* A = 2 la (ua.x + A.ww / (2 la)), B likewise: the planes are ua.x = da, ub.x = db */
    real da = -A.ww / (2 * la), db = -B.ww / (2 * lb);
    bool same = dot(ua, ub) > 0;
    if (!same) db = -db; /* B's plane as ua.x = db, B positive where ua.x < db */
    if (!(fabs(da - db) > 1e6 * CASE_TOLERANCE * (1 + fabs(da) + fabs(db)))) return 0;
    uint pa = CASE_TABLE(ma), pb = CASE_TABLE(mb); /* A positive where ua.x > da */
    if (same) return da < db ? pb & ~pa : pa & ~pb; /* ua.x > db implies ua.x > da, or the reverse */
    return da < db ? ~pa & ~pb : pa & pb;
}

/* The cases that points of any task in box g may have, given its k live quadrics: not two
 * parallel planes' impossible pair (parallel_planes_impossible); where one is a plane and
 * another meets it in the task quadric's conic, signs tied (task_plane_factor). */
inline uint task_possible_cases(__global const quadric_rec *qs, int self_q, const int *live, int k,
                                const prune_region *g)
{
#ifndef CLCSG_DOUBLE
    return ~0u;
#else
    uint possible = ~0u;
    quadric S = quadric_load(qs, self_q);
    for (int m = 0; m < k; ++m) {
        quadric P = quadric_load(qs, live[m]);
        if (!(P.xx == 0 && P.xy == 0 && P.xz == 0 && P.yy == 0 && P.yz == 0 && P.zz == 0)) continue;
        for (int j = 0; j < k; ++j) {
            if (j == m) continue;
            quadric Qj = quadric_load(qs, live[j]);
            if (Qj.xx == 0 && Qj.xy == 0 && Qj.xz == 0 && Qj.yy == 0 && Qj.yz == 0 && Qj.zz == 0) {
                if (j > m) possible &= ~parallel_planes_impossible(P, Qj, m, j);
                continue;
            }
            int f = task_plane_factor(S, P, Qj, g);
            if (f) possible &= f > 0 ? ~(CASE_TABLE(m) ^ CASE_TABLE(j)) : CASE_TABLE(m) ^ CASE_TABLE(j);
        }
    }
    return possible;
#endif
}

/* The cases two nested conics cannot have together (CASE_TABLE bits of live quadrics ma, mb),
 * 0 if they are not nested: where a - mu b (mu > 0, from their quadratic parts) is semidefinite,
 * one conic is the other plus a term of one sign, so b > 0 implies a > 0 (or a > 0 implies
 * b > 0). Concentric circles 0.01 apart: a cone's cap and the cylinder it continues, where
 * OpenSCAD's eps overlap moves the cap. */
inline uint plane_conics_nested(const plane_conic *a, const plane_conic *b, int ma, int mb)
{
    real qa = fmax(fabs(a->m[0]), fmax(fabs(a->m[1]), fabs(a->m[2])));
    real qb = fmax(fabs(b->m[0]), fmax(fabs(b->m[1]), fabs(b->m[2])));
    if (!(qa > CASE_TOLERANCE && qb > CASE_TOLERANCE)) return 0;
    int p = fabs(b->m[0]) == qb ? 0 : fabs(b->m[1]) == qb ? 1 : 2;
    real mu = a->m[p] / b->m[p];
    if (!(mu > 0)) return 0;
    plane_conic d;
    real big = 0;
    for (int e = 0; e < 6; ++e) {
        d.m[e] = a->m[e] - mu * b->m[e];
        big = fmax(big, fabs(d.m[e]));
    }
    d.scale = 1;
    if (!(fabs(d.m[0]) <= CASE_TOLERANCE && fabs(d.m[1]) <= CASE_TOLERANCE && fabs(d.m[2]) <= CASE_TOLERANCE) ||
        !(big > 1e6 * CASE_TOLERANCE))
        return 0; /* quadratic parts not proportional, or the same conic (plane_conics_proportional) */
    uint pa = CASE_TABLE(ma), pb = CASE_TABLE(mb);
    if (plane_conic_semidefinite(&d, 1)) return pb & ~pa; /* a >= mu b: b positive implies a positive */
    if (plane_conic_semidefinite(&d, -1)) return pa & ~pb;
    return 0;
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
            int r = plane_conics_proportional(&c[m], &c[j]);
            if (r) {
                possible &= r > 0 ? ~(pos ^ CASE_TABLE(j)) : pos ^ CASE_TABLE(j);
                break;
            }
        }
    }
    for (int m = 0; m < k; ++m) /* nested conics */
        for (int j = 0; j < m; ++j) possible &= ~plane_conics_nested(&c[m], &c[j], m, j);
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
