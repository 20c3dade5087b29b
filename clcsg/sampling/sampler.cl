/* Adaptive subdivision sampler (paper section 4.2 with eq. 22; design note sections 2-4).
 *
 * One launch per level: every work-item takes one cell of the current queue, evaluates the
 * quadric-relative conservative distance d_Q(S, p) at its corners, and discards it, covers it
 * with samples, covers it with a single sample, or splits it; children and samples are
 * appended with atomics.  Writes happen only below the capacity; the counters keep counting,
 * so the host sees an overflow, grows the buffer and re-runs the level.
 *
 * Build options: -DCLCSG_DOUBLE (real = double), -DWORST_CASE_DISTORTION=1 replaces the
 * interval distortion bound by max(sqrt 3, bound) (for the paper's Fig. 14 comparison),
 * -DMAX_FILL: largest grid a cell may emit at once (larger cells are split instead).
 */
#include "quadric.h"

#ifndef MAX_FILL
#define MAX_FILL 65536
#endif
#ifndef BOX_TEST
#define BOX_TEST 1
#endif
#ifndef FILL_DELTA_RATIO
#define FILL_DELTA_RATIO 1.1
#endif
#ifndef WORST_CASE_DISTORTION
#define WORST_CASE_DISTORTION 0
#endif

/* counters */
#define C_CELLS 0
#define C_SAMPLES 1
#define C_QUERIES 2
#define C_UNRESOLVED 3
#define C_DISCARDED 4
#define C_FILLED 5
#define C_SINGLE 6
#define C_SPLIT 7
#define C_BOX_TESTS 8
#define C_BOX_RESOLVED 9
#define N_COUNTERS 10

inline real literal_distance(__global const quadric_rec *quadrics, literal_rec l, real3 p)
{
    __global const quadric_rec *r = quadrics + l.quadric;
    /* d(-Q, p) = -d(Q, p): the negated literal swaps lam_min / lam_max and the sign of f */
    return l.sign * quadric_distance(quadric_load(quadrics, l.quadric), r->lam_min, r->lam_max, p);
}

/* Distance from p to the term's bound box (0 inside). */
inline real box_distance(__global const term_rec *t, real3 p)
{
    real3 lo = (real3)(t->lo[0], t->lo[1], t->lo[2]);
    real3 hi = (real3)(t->hi[0], t->hi[1], t->hi[2]);
    real3 e = fmax(lo - p, (real3)(0)) + fmax(p - hi, (real3)(0));
    return length(e);
}

/* Quadric-relative conservative signed distance d_Q(S, p), eq. 22, for a point p on the
 * task's quadric q, generalized to the literal's group (the design note's rules for shared
 * surfaces, taken one step further):
 *   own   = min over terms holding (q, sign) of max over their other literals of d   (eq. 21)
 *   other = min over the remaining terms of max over their literals of d               (eq. 20)
 * where a term holding q with the opposite polarity enters without that literal, and
 * d_Q = max(own, -other).  Eq. 22 is the case of a single term holding the literal; taking the
 * union of the terms that share it removes the seams that distributing A - (B | C) over a
 * union leaves across A's faces (each term there is A minus one literal of B and C) and
 * samples a shared face once instead of once per term.
 * `enough`: a |d| this large already classifies the cell, so a term whose bound box is at
 * least that far away is not evaluated literal by literal (its box distance is a valid
 * conservative distance to it too). */
real csg_distance(__global const quadric_rec *quadrics, __global const literal_rec *literals,
                  __global const term_rec *terms, __global const int *task_terms, task_rec t, real3 p,
                  real enough)
{
    /* Branch and bound: the task lists the group's own terms first.  A term's max over its
     * literals only grows, so its scan stops once it can no longer lower the running min; and
     * once |d_Q| is known to be at least `enough` with its sign settled, the rest is skipped
     * (a smaller |d| of the right sign is still conservative). */
    real own = INFINITY, other = t.far_other;
    for (int n = 0; n < t.terms_count; ++n) {
        int code = task_terms[t.terms_first + n];
        bool member = code < 0; /* the term holds (q, sign) */
        if (!member && own >= enough) return own; /* outside every own term by enough */
        __global const term_rec *ti = terms + (member ? ~code : code);
        real box = member ? 0 : box_distance(ti, p);
        if (!member && (box >= enough || box >= other)) {
            other = fmin(other, box);
            continue;
        }
        real bound = member ? own : other;
        real v = member ? -INFINITY : box;
        for (int j = ti->first; j < ti->first + ti->count && v < bound; ++j) {
            literal_rec l = literals[j];
            if (l.quadric == t.quadric) continue;
            v = fmax(v, literal_distance(quadrics, l, p));
        }
        if (member) {
            own = fmin(own, v);
        } else {
            other = fmin(other, v);
            if (-other >= enough) return -other; /* inside another term by enough */
        }
    }
    return fmax(own, -other);
}

/* exact range of lam z^2 + 2 beta z over [a, b] */
inline real2 quad_range(real lam, real beta, real a, real b)
{
    real fa = lam * a * a + 2 * beta * a;
    real fb = lam * b * b + 2 * beta * b;
    real lo = fmin(fa, fb), hi = fmax(fa, fb);
    if (lam != 0) {
        real v = -beta / lam;
        if (v > a && v < b) {
            real fv = lam * v * v + 2 * beta * v;
            lo = fmin(lo, fv);
            hi = fmax(hi, fv);
        }
    }
    return (real2)(lo, hi);
}

/* range of |lam z + beta| over [a, b] */
inline real2 abs_linear_range(real lam, real beta, real a, real b)
{
    real fa = lam * a + beta, fb = lam * b + beta;
    real hi = fmax(fabs(fa), fabs(fb));
    real lo = (fa <= 0 && fb >= 0) || (fa >= 0 && fb <= 0) ? 0 : fmin(fabs(fa), fabs(fb));
    return (real2)(lo, hi);
}

typedef struct {
    real U[9];
    real3 center;
    real li, lj, lk, bi, bj, bk, gamma;
    int i, j, k;
    int sheet;
} plane_frame;

inline plane_frame plane_load(__global const frame_rec *f, int k, int sheet)
{
    plane_frame pf;
    for (int m = 0; m < 9; ++m) pf.U[m] = f->U[m];
    pf.center = (real3)(f->center[0], f->center[1], f->center[2]);
    pf.k = k;
    pf.i = k == 0 ? 1 : 0;
    pf.j = k == 2 ? 1 : 2;
    pf.li = f->lam[pf.i];
    pf.lj = f->lam[pf.j];
    pf.lk = f->lam[pf.k];
    pf.bi = f->beta[pf.i];
    pf.bj = f->beta[pf.j];
    pf.bk = f->beta[pf.k];
    pf.gamma = f->gamma;
    pf.sheet = sheet;
    return pf;
}

/* R(x, y) = lam_i x^2 + 2 beta_i x + lam_j y^2 + 2 beta_j y + gamma */
inline real plane_R(const plane_frame *pf, real x, real y)
{
    return pf->li * x * x + 2 * pf->bi * x + pf->lj * y * y + 2 * pf->bj * y + pf->gamma;
}

/* Height t of the heightfield at (x, y); false where it is undefined. */
inline bool plane_height(const plane_frame *pf, real x, real y, real *t)
{
    real R = plane_R(pf, x, y);
    if (pf->lk != 0) {
        real H = -R / pf->lk;
        if (H < 0) return false;
        *t = pf->sheet * sqrt(H);
    } else {
        *t = -R / (2 * pf->bk);
    }
    return true;
}

/* Height where the heightfield is known to be defined (rounding may make H slightly < 0). */
inline real plane_height_clamped(const plane_frame *pf, real x, real y)
{
    real R = plane_R(pf, x, y);
    if (pf->lk != 0) return pf->sheet * sqrt(fmax(-R / pf->lk, (real)0));
    return -R / (2 * pf->bk);
}

/* Exact ranges over a rectangle [x0,x1] x [y0,y1] of a plane (design note section 2): R is
 * separable, so its range is exact; |n_i| = |lam_i x + beta_i| and |n_j| are linear in one
 * coordinate each; |n_k| = sqrt(-lam_k R) on a two-sheet heightfield (lam_k t^2 = -R),
 * |beta_k| on a one-sheet one.  Ranges are (min, max). */
typedef struct {
    real2 R, ni, nj, nk;
} rect_bounds;

inline rect_bounds rect_bounds_of(const plane_frame *pf, real x0, real x1, real y0, real y1)
{
    rect_bounds b;
    real2 Px = quad_range(pf->li, pf->bi, x0, x1);
    real2 Sy = quad_range(pf->lj, pf->bj, y0, y1);
    b.R = (real2)(Px.x + Sy.x + pf->gamma, Px.y + Sy.y + pf->gamma);
    b.ni = abs_linear_range(pf->li, pf->bi, x0, x1);
    b.nj = abs_linear_range(pf->lj, pf->bj, y0, y1);
    if (pf->lk != 0) {
        real a = -pf->lk * b.R.x, c = -pf->lk * b.R.y; /* -lam_k R = (lam_k t)^2 */
        b.nk = (real2)(sqrt(fmax(fmin(a, c), (real)0)), sqrt(fmax(fmax(a, c), (real)0)));
    } else {
        b.nk = (real2)(fabs(pf->bk), fabs(pf->bk));
    }
    return b;
}

/* Can plane k own a point of the rectangle?  (no: an in-plane normal component exceeds |n_k|
 * everywhere there) */
inline bool rect_may_be_owned(rect_bounds b) { return !(b.ni.x > b.nk.y || b.nj.x > b.nk.y); }

inline bool sub_rect_owned(const plane_frame *pf, real x0, real x1, real y0, real y1)
{
    return rect_may_be_owned(rect_bounds_of(pf, x0, x1, y0, y1));
}

/* device coordinates of local (x, y, t) */
inline real3 plane_point(const plane_frame *pf, real x, real y, real t)
{
    real z[3];
    z[pf->i] = x;
    z[pf->j] = y;
    z[pf->k] = t;
    return pf->center + (real3)(pf->U[0] * z[0] + pf->U[1] * z[1] + pf->U[2] * z[2],
                                pf->U[3] * z[0] + pf->U[4] * z[1] + pf->U[5] * z[2],
                                pf->U[6] * z[0] + pf->U[7] * z[1] + pf->U[8] * z[2]);
}

inline void emit_sample(__global raw_sample_rec *out, int slot, int cap, real3 p, real radius, int task)
{
    if (slot >= cap) return;
    out[slot].pos[0] = p.x;
    out[slot].pos[1] = p.y;
    out[slot].pos[2] = p.z;
    out[slot].radius = radius;
    out[slot].task = task;
    out[slot].pad = 0;
}

/* Distortion bounds over a rectangle: (delta_hi, delta_lo) with delta_hi = inf where the
 * heightfield may be vertical; also whether plane k may own a point of it. */
inline real2 rect_distortion(const plane_frame *pf, real x0, real x1, real y0, real y1, bool *owned)
{
    rect_bounds b = rect_bounds_of(pf, x0, x1, y0, y1);
    *owned = rect_may_be_owned(b);
    real hi = b.nk.x > 0 ? sqrt(b.ni.y * b.ni.y + b.nj.y * b.nj.y + b.nk.y * b.nk.y) / b.nk.x : INFINITY;
    real lo = b.nk.y > 0 ? sqrt(b.ni.x * b.ni.x + b.nj.x * b.nj.x + b.nk.x * b.nk.x) / b.nk.y : INFINITY;
#if WORST_CASE_DISTORTION
    hi = fmax(hi, sqrt((real)3));
    lo = hi;
#endif
    return (real2)(hi, lo);
}

/* Slope bounds of the heightfield over a rectangle: (max |dt/dx|, max |dt/dy|) =
 * (max |n_i|, max |n_j|) / min |n_k|, and min |n_k| itself. */
inline real3 rect_slopes(const plane_frame *pf, real x0, real x1, real y0, real y1)
{
    rect_bounds b = rect_bounds_of(pf, x0, x1, y0, y1);
    real mx = b.ni.y / b.nk.x, my = b.nj.y / b.nk.x;
#if WORST_CASE_DISTORTION
    /* the paper's isotropic bound |dp| <= delta |d| with delta >= sqrt 3: equal slopes
     * m = sqrt((delta^2 - 1) / 2) give (m a + m b)^2 <= (delta^2 - 1)(a^2 + b^2) */
    real dl = fmax(sqrt(1 + mx * mx + my * my), sqrt((real)3));
    mx = my = sqrt((dl * dl - 1) / 2);
#endif
    return (real3)(mx, my, b.nk.x);
}

/* Largest half-width a with a^2 + b^2 + (mx a + my b)^2 <= r^2 (0 if none). */
inline real half_width(real mx, real my, real b, real r)
{
    real A = 1 + mx * mx, B = mx * my * b, C = b * b * (1 + my * my) - r * r;
    real disc = B * B - A * C;
    return disc > 0 ? fmax((-B + sqrt(disc)) / A, (real)0) : 0;
}

/* Cover a block [x0,x1] x [y0,y1] known to lie on the CSG surface with samples at the
 * centers of sub-rectangles of half-sizes (a, b).  Anisotropic bound (beyond the paper's
 * isotropic distortion): for two points of a sub-rectangle, p2 - p1 = (dx, dy, t2 - t1) and
 * by the mean value theorem |t2 - t1| <= mx |dx| + my |dy| with mx, my the slope bounds over
 * the sub-rectangle, so every point is within sqrt(a^2 + b^2 + (mx a + my b)^2) <= r of the
 * center.  On a steep patch only the steep direction shrinks.  Rows are marched in y, each
 * with the slopes over the whole row (shrinking a rectangle never raises them); (a, b)
 * maximize the area a b on the constraint.  Sub-rectangles that plane k owns nowhere are
 * left to the other planes; a row owned everywhere reserves its output with one atomic. */
void fill_block(const plane_frame *pf, real x0, real x1, real y0, real y1, real radius, int task,
                __global volatile uint *counters, __global raw_sample_rec *samples, int cap_samples)
{
    real2 ni = abs_linear_range(pf->li, pf->bi, x0, x1);
    real2 nj = abs_linear_range(pf->lj, pf->bj, y0, y1);
    real y = y0;
    real hy = y1 - y0;
    while (y < y1) {
        hy = fmin(y1 - y, 2 * hy);
        real3 m = rect_slopes(pf, x0, x1, y, y + hy);
        /* best aspect for these slopes: a few angles suffice (the area is flat at its max) */
        real best_b = 0, best_area = -1;
        for (int k = 1; k < 16; ++k) {
            real th = (real)(M_PI / 32) * k, cs = cos(th), sn = sin(th);
            real e = m.x * cs + m.y * sn;
            real rho = radius / sqrt(1 + e * e);
            if (rho * rho * cs * sn > best_area) {
                best_area = rho * rho * cs * sn;
                best_b = rho * sn;
            }
        }
        if (hy > 2 * best_b) {
            hy = 2 * best_b;
            m = rect_slopes(pf, x0, x1, y, y + hy);
        }
        real yb = y + hy >= y1 ? y1 : y + hy;
        real sx = 2 * half_width(m.x, m.y, 0.5 * hy, radius);
        sx = fmax(sx, (real)1e-12 * radius);
        int nx = max(1, (int)ceil((x1 - x0) / sx));
        sx = (x1 - x0) / nx;
        real cy = 0.5 * (y + yb);
        /* the radius this row's samples need (paper 6.1: smaller splats, less overdraw) */
        real ha = 0.5 * sx, hb = 0.5 * (yb - y), e = m.x * ha + m.y * hb;
        real need = fmin(radius, sqrt(ha * ha + hb * hb + e * e) * (1 + (real)1e-6));
        if (ni.y <= m.z && nj.y <= m.z) { /* owned everywhere */
            uint base = atomic_add(&counters[C_SAMPLES], (uint)nx);
            for (int a = 0; a < nx; ++a) {
                real cx = x0 + (a + (real)0.5) * sx;
                emit_sample(samples, base + a, cap_samples,
                            plane_point(pf, cx, cy, plane_height_clamped(pf, cx, cy)), need, task);
            }
        } else {
            for (int a = 0; a < nx; ++a) {
                real xa = x0 + a * sx;
                if (!sub_rect_owned(pf, xa, xa + sx, y, yb)) continue;
                real cx = xa + (real)0.5 * sx;
                uint slot = atomic_inc(&counters[C_SAMPLES]);
                emit_sample(samples, slot, cap_samples,
                            plane_point(pf, cx, cy, plane_height_clamped(pf, cx, cy)), need, task);
            }
        }
        y = yb;
    }
}

/* Cover a cell that lies on the CSG surface: split it (no distance queries needed) into
 * blocks over which the distortion varies little, and fill each block. */
void fill_cell(const plane_frame *pf, cell_rec c, real radius, __global volatile uint *counters,
               __global raw_sample_rec *samples, int cap_samples)
{
    real4 stack[40];
    int top = 0;
    stack[top++] = (real4)(c.x0, c.x1, c.y0, c.y1);
    while (top > 0) {
        real4 b = stack[--top];
        bool owned;
        real2 dl = rect_distortion(pf, b.x, b.y, b.z, b.w, &owned);
        if (!owned) continue;
        real wx = b.y - b.x, wy = b.w - b.z;
        real s = sqrt((real)2) * radius / dl.x;
        if (top + 2 <= 40 && wx * wy > 16 * s * s && dl.x > FILL_DELTA_RATIO * dl.y) {
            if (wx >= wy) {
                real mid = 0.5 * (b.x + b.y);
                stack[top++] = (real4)(b.x, mid, b.z, b.w);
                stack[top++] = (real4)(mid, b.y, b.z, b.w);
            } else {
                real mid = 0.5 * (b.z + b.w);
                stack[top++] = (real4)(b.x, b.y, b.z, mid);
                stack[top++] = (real4)(b.x, b.y, mid, b.w);
            }
            continue;
        }
        fill_block(pf, b.x, b.y, b.z, b.w, radius, c.task, counters, samples, cap_samples);
    }
}

/* ---- classifying a whole patch box at once ------------------------------------------------
 * The corner discs of eq. 22 need cells no larger than the distance to the nearest decision
 * border, so a face lying a hair inside another solid (an interior face 0.01 below a plate's
 * top) would need cells of that size everywhere.  The patch's 3-D box decides such cells at
 * once: a plane literal is linear, so it holds (fails) on the whole box iff it holds (fails)
 * at its 8 corners; any other literal holds (fails) on the box if its conservative distance at
 * the box center exceeds the half-diagonal. */
typedef struct {
    real3 corner[8];
    real3 center;
    real hdiag; /* half the diagonal */
} patch_box;

inline bool literal_is_plane(__global const quadric_rec *quadrics, int q)
{
    __global const real *c = quadrics[q].coef;
    return c[0] == 0 && c[1] == 0 && c[2] == 0 && c[4] == 0 && c[5] == 0 && c[7] == 0;
}

/* +1: the literal fails on the whole box; -1: it holds on the whole box; 0: unknown */
inline int literal_on_box(__global const quadric_rec *quadrics, literal_rec l, const patch_box *b)
{
    if (literal_is_plane(quadrics, l.quadric)) {
        quadric q = quadric_load(quadrics, l.quadric);
        int in = 0, out = 0;
        for (int m = 0; m < 8; ++m) {
            real v = l.sign * quadric_value(q, b->corner[m]);
            if (v <= 0) ++in;
            if (v > 0) ++out;
        }
        return in == 8 ? -1 : out == 8 ? 1 : 0;
    }
    real d = literal_distance(quadrics, l, b->center);
    return d <= -b->hdiag ? -1 : d >= b->hdiag ? 1 : 0;
}

/* -1: the whole patch is on the CSG surface, +1: none of it is, 0: unknown (same rules as
 * csg_distance: the union of the terms holding the literal, against all other terms). */
int box_classify(__global const quadric_rec *quadrics, __global const literal_rec *literals,
                 __global const term_rec *terms, __global const int *task_terms, task_rec t,
                 const patch_box *b)
{
    /* terms left out of the task miss the group's bound, hence the patch: they fail */
    bool some_member_holds = false, all_members_fail = true, others_all_fail = true;
    for (int n = 0; n < t.terms_count; ++n) {
        int code = task_terms[t.terms_first + n];
        bool member = code < 0;
        __global const term_rec *ti = terms + (member ? ~code : code);
        if (!member) {
            /* quick reject: the box misses the term's bound */
            real3 lo = (real3)(ti->lo[0], ti->lo[1], ti->lo[2]), hi = (real3)(ti->hi[0], ti->hi[1], ti->hi[2]);
            real3 e = fmax(lo - b->center, (real3)(0)) + fmax(b->center - hi, (real3)(0));
            if (length(e) > b->hdiag) continue;
        }
        bool holds = true, fails = false;
        for (int j = ti->first; j < ti->first + ti->count && !fails; ++j) {
            literal_rec l = literals[j];
            if (l.quadric == t.quadric) continue;
            int k = literal_on_box(quadrics, l, b);
            if (k > 0) fails = true;
            if (k >= 0) holds = false;
        }
        if (member) {
            if (holds) some_member_holds = true;
            if (!fails) all_members_fail = false;
        } else {
            if (holds) return 1; /* the patch lies inside another term: interior */
            if (!fails) others_all_fail = false;
        }
    }
    if (all_members_fail) return 1;
    if (some_member_holds && others_all_fail) return -1;
    return 0;
}

__kernel void classify(__global const quadric_rec *quadrics, __global const literal_rec *literals,
                       __global const term_rec *terms, __global const int *task_terms,
                       __global const frame_rec *frames, __global const task_rec *tasks,
                       __global const cell_rec *cells_in, int n_cells,
                       __global cell_rec *cells_out, int cap_cells,
                       __global raw_sample_rec *samples, int cap_samples,
                       __global volatile uint *counters, real radius, real floor_size)
{
    int gid = get_global_id(0);
    if (gid >= n_cells) return;
    cell_rec c = cells_in[gid];
    task_rec t = tasks[c.task];
    plane_frame pf = plane_load(frames + t.quadric, t.plane, t.sheet);

    /* exact interval bounds over the cell (design note section 2) */
    rect_bounds rb = rect_bounds_of(&pf, c.x0, c.x1, c.y0, c.y1);
    real t_lo, t_hi;
    bool whole_domain = true;
    if (pf.lk != 0) {
        real Hlo = -(pf.lk > 0 ? rb.R.y : rb.R.x) / pf.lk;
        real Hhi = -(pf.lk > 0 ? rb.R.x : rb.R.y) / pf.lk;
        if (Hhi < 0) { /* no surface over this cell */
            atomic_inc(&counters[C_DISCARDED]);
            return;
        }
        whole_domain = Hlo >= 0;
        real a = sqrt(fmax(Hlo, (real)0)), b = sqrt(Hhi);
        t_lo = pf.sheet > 0 ? a : -b;
        t_hi = pf.sheet > 0 ? b : -a;
    } else {
        t_lo = fmin(-rb.R.y / (2 * pf.bk), -rb.R.x / (2 * pf.bk));
        t_hi = fmax(-rb.R.y / (2 * pf.bk), -rb.R.x / (2 * pf.bk));
    }
    real2 ni = rb.ni, nj = rb.nj;
    real nk_lo = rb.nk.x, nk_hi = rb.nk.y;
    /* plane k owns no point of the cell: an in-plane normal component dominates everywhere */
    if (!rect_may_be_owned(rb)) {
        atomic_inc(&counters[C_DISCARDED]);
        return;
    }
    /* the patch lies outside the term's bound */
    if (t_hi < t.zlo[pf.k] || t_lo > t.zhi[pf.k]) {
        atomic_inc(&counters[C_DISCARDED]);
        return;
    }

    /* distortion bound: |dp| <= delta |d(x, y)| over the cell (design note section 2) */
    real delta = nk_lo > 0 ? sqrt(ni.y * ni.y + nj.y * nj.y + nk_hi * nk_hi) / nk_lo : INFINITY;
#if WORST_CASE_DISTORTION
    delta = fmax(delta, sqrt((real)3));
#endif
    real wx = c.x1 - c.x0, wy = c.y1 - c.y0;
    real diag = sqrt(wx * wx + wy * wy);
    real enough = delta * diag;

    /* corners: 3-D point and d_Q(S, p) */
    real cx[4] = {c.x0, c.x1, c.x0, c.x1};
    real cy[4] = {c.y0, c.y0, c.y1, c.y1};
    real d[4];
    bool defined[4];
    real3 p[4];
    int queries = 0;
    for (int m = 0; m < 4; ++m) {
        real h;
        defined[m] = plane_height(&pf, cx[m], cy[m], &h);
        if (defined[m]) {
            p[m] = plane_point(&pf, cx[m], cy[m], h);
            if (c.level > 0 && !isnan(c.d[m])) {
                d[m] = c.d[m]; /* inherited: evaluated for a larger cell, still conservative */
            } else {
                d[m] = csg_distance(quadrics, literals, terms, task_terms, t, p[m], enough);
                ++queries;
            }
        } else {
            d[m] = NAN;
        }
    }
    atomic_add(&counters[C_QUERIES], (uint)queries);

    /* discard: the corner discs of positive distance cover the cell */
    bool all_pos = true, all_neg = true;
    real min_abs = INFINITY;
    for (int m = 0; m < 4; ++m) {
        if (!defined[m]) {
            all_pos = all_neg = false;
            continue;
        }
        all_pos = all_pos && d[m] > 0;
        all_neg = all_neg && d[m] < 0;
        min_abs = fmin(min_abs, fabs(d[m]));
        if (d[m] > 0 && d[m] >= enough) { /* one disc covers the whole cell */
            atomic_inc(&counters[C_DISCARDED]);
            return;
        }
    }
    if (all_pos && min_abs >= 0.5 * enough) { /* each disc covers its quarter */
        atomic_inc(&counters[C_DISCARDED]);
        return;
    }

    /* single sample (paper 4.2 special case): a corner on the CSG surface whose splat of
     * radius r covers the patch's whole 3-D box; the splat radius shrinks to what is needed */
    real ex = fmax(wx, (real)0), ey = fmax(wy, (real)0), et = t_hi - t_lo;
    int best = -1;
    real best_r = INFINITY;
    for (int m = 0; m < 4; ++m) {
        if (!defined[m] || !(d[m] < 0)) continue;
        /* farthest point of the local box [x0,x1]x[y0,y1]x[t_lo,t_hi] from the corner */
        real h;
        plane_height(&pf, cx[m], cy[m], &h);
        real fx = fmax(cx[m] - c.x0, c.x1 - cx[m]);
        real fy = fmax(cy[m] - c.y0, c.y1 - cy[m]);
        real ft = fmax(h - t_lo, t_hi - h);
        real r = sqrt(fx * fx + fy * fy + ft * ft);
        if (r < best_r) {
            best_r = r;
            best = m;
        }
    }
    if (best >= 0 && best_r <= radius) {
        uint slot = atomic_inc(&counters[C_SAMPLES]);
        emit_sample(samples, slot, cap_samples, p[best], fmax(best_r, radius * (real)1e-3), c.task);
        atomic_inc(&counters[C_SINGLE]);
        return;
    }
    /* the same from the cell's center, which reaches a box twice as large: one more query */
    real center_r = 0.5 * sqrt(ex * ex + ey * ey) ;
    if (center_r <= radius) {
        real mx = 0.5 * (c.x0 + c.x1), my = 0.5 * (c.y0 + c.y1), h;
        if (plane_height(&pf, mx, my, &h)) {
            real ft = fmax(h - t_lo, t_hi - h);
            real r = sqrt(center_r * center_r + ft * ft);
            if (r <= radius) {
                real3 pc = plane_point(&pf, mx, my, h);
                atomic_inc(&counters[C_QUERIES]);
                if (csg_distance(quadrics, literals, terms, task_terms, t, pc, INFINITY) < 0) {
                    uint slot = atomic_inc(&counters[C_SAMPLES]);
                    emit_sample(samples, slot, cap_samples, pc, fmax(r, radius * (real)1e-3), c.task);
                    atomic_inc(&counters[C_SINGLE]);
                    return;
                }
            }
        }
    }

    /* fill: the corner discs of negative distance cover the cell and the heightfield is
     * defined everywhere: a grid with spacing s <= sqrt 2 r / delta puts every point of the
     * cell within r / delta (2-D), hence within r (3-D), of a sample */
    bool covered = false;
    if (whole_domain && isfinite(delta)) {
        for (int m = 0; m < 4; ++m)
            if (defined[m] && d[m] < 0 && -d[m] >= enough) covered = true;
        if (all_neg && min_abs >= 0.5 * enough) covered = true;
    }
    if (covered) {
        real s = sqrt((real)2) * radius / delta;
        if ((wx / s + 1) * (wy / s + 1) <= MAX_FILL) {
            fill_cell(&pf, c, radius, counters, samples, cap_samples);
            atomic_inc(&counters[C_FILLED]);
            return;
        }
    }

    /* the discs could not decide: try the patch's box as a whole */
    if (BOX_TEST) {
        patch_box b;
        real lx[2] = {c.x0, c.x1}, ly[2] = {c.y0, c.y1}, lt[2] = {t_lo, t_hi};
        for (int m = 0; m < 8; ++m) b.corner[m] = plane_point(&pf, lx[m & 1], ly[(m >> 1) & 1], lt[m >> 2]);
        b.center = plane_point(&pf, 0.5 * (c.x0 + c.x1), 0.5 * (c.y0 + c.y1), 0.5 * (t_lo + t_hi));
        b.hdiag = 0.5 * sqrt(ex * ex + ey * ey + et * et);
        atomic_inc(&counters[C_BOX_TESTS]);
        int k = box_classify(quadrics, literals, terms, task_terms, t, &b);
        if (k > 0) {
            atomic_inc(&counters[C_BOX_RESOLVED]);
            atomic_inc(&counters[C_DISCARDED]);
            return;
        }
        if (k < 0 && whole_domain && isfinite(delta)) {
            real s = sqrt((real)2) * radius / delta;
            if ((wx / s + 1) * (wy / s + 1) <= MAX_FILL) {
                fill_cell(&pf, c, radius, counters, samples, cap_samples);
                atomic_inc(&counters[C_BOX_RESOLVED]);
                atomic_inc(&counters[C_FILLED]);
                return;
            }
        }
    }

    /* floor: the patch is smaller than the floor and still unresolved */
    if (sqrt(ex * ex + ey * ey + et * et) < floor_size) {
        atomic_inc(&counters[C_UNRESOLVED]);
        return;
    }

    /* split along the longest edge */
    uint slot = atomic_add(&counters[C_CELLS], 2u);
    atomic_inc(&counters[C_SPLIT]);
    if (slot + 1 >= (uint)cap_cells) return;
    cell_rec a = c, b = c;
    a.level = b.level = c.level + 1;
    /* the two new corners, shared by both children, are evaluated here once */
    real e0 = NAN, e1 = NAN, h;
    int queries2 = 0;
    if (wx >= wy) {
        real mid = 0.5 * (c.x0 + c.x1);
        a.x1 = mid;
        b.x0 = mid;
        if (plane_height(&pf, mid, c.y0, &h)) {
            e0 = csg_distance(quadrics, literals, terms, task_terms, t, plane_point(&pf, mid, c.y0, h), 0.5 * enough);
            ++queries2;
        }
        if (plane_height(&pf, mid, c.y1, &h)) {
            e1 = csg_distance(quadrics, literals, terms, task_terms, t, plane_point(&pf, mid, c.y1, h), 0.5 * enough);
            ++queries2;
        }
        a.d[1] = e0; a.d[3] = e1; /* a = [x0, mid]: new right corners */
        b.d[0] = e0; b.d[2] = e1; /* b = [mid, x1]: new left corners */
        a.d[0] = d[0]; a.d[2] = d[2];
        b.d[1] = d[1]; b.d[3] = d[3];
    } else {
        real mid = 0.5 * (c.y0 + c.y1);
        a.y1 = mid;
        b.y0 = mid;
        if (plane_height(&pf, c.x0, mid, &h)) {
            e0 = csg_distance(quadrics, literals, terms, task_terms, t, plane_point(&pf, c.x0, mid, h), 0.5 * enough);
            ++queries2;
        }
        if (plane_height(&pf, c.x1, mid, &h)) {
            e1 = csg_distance(quadrics, literals, terms, task_terms, t, plane_point(&pf, c.x1, mid, h), 0.5 * enough);
            ++queries2;
        }
        a.d[2] = e0; a.d[3] = e1; /* a = [y0, mid]: new top corners */
        b.d[0] = e0; b.d[1] = e1; /* b = [mid, y1]: new bottom corners */
        a.d[0] = d[0]; a.d[1] = d[1];
        b.d[2] = d[2]; b.d[3] = d[3];
    }
    atomic_add(&counters[C_QUERIES], (uint)queries2);
    cells_out[slot] = a;
    cells_out[slot + 1] = b;
}

/* Per sample: the solid's outward normal, its term (the group term it lies deepest in), and
 * its clip set as a bit mask over the group's literals (bit j: group literal group_first + j
 * with |d| < the splat radius, in a term that is neither false nor true over the whole splat
 * ball), plus bit 0 of the flags word: some group term holds over the whole ball (no clipping).
 * A term is false over the ball if one of its literals has d >= r, true if all have d <= -r. */
__kernel void finish(__global const quadric_rec *quadrics, __global const literal_rec *literals,
                     __global const term_rec *terms, __global const frame_rec *frames,
                     __global const task_rec *tasks, __global const group_literal_rec *glits,
                     __global const raw_sample_rec *raw, int n,
                     __global real *normals, __global int *sample_terms, __global uint *masks)
{
    int gid = get_global_id(0);
    if (gid >= n) return;
    raw_sample_rec s = raw[gid];
    task_rec t = tasks[s.task];
    real3 p = (real3)(s.pos[0], s.pos[1], s.pos[2]);
    real3 g = t.sign * quadric_gradient(quadric_load(quadrics, t.quadric), p);
    real gl = length(g);
    if (gl > 0) {
        g = g / gl;
    } else { /* a singular point (cone apex): the sampling direction stands in */
        __global const frame_rec *f = frames + t.quadric;
        real sh = t.sheet != 0 ? (real)t.sheet : (real)1;
        g = sh * (real3)(f->U[t.plane], f->U[3 + t.plane], f->U[6 + t.plane]);
    }
    normals[3 * gid] = g.x;
    normals[3 * gid + 1] = g.y;
    normals[3 * gid + 2] = g.z;
    uint mask[MASK_WORDS + 1]; /* built privately, stored once */
    for (int w = 0; w <= MASK_WORDS; ++w) mask[w] = 0;
    int best_term = -1;
    real best = INFINITY;
    bool always = false;
    int j = 0;
    while (j < t.group_count) {
        int term = glits[t.group_first + j].term;
        int j0 = j;
        real vmax = -INFINITY;
        bool is_false = false, is_true = true;
        for (; j < t.group_count && glits[t.group_first + j].term == term; ++j) {
            int l = glits[t.group_first + j].literal;
            real d = l < 0 ? -INFINITY : literal_distance(quadrics, literals[l], p);
            vmax = fmax(vmax, d);
            if (d >= s.radius) is_false = true;
            if (d > -s.radius) is_true = false;
        }
        if (vmax < best) {
            best = vmax;
            best_term = term;
        }
        if (is_true) always = true;
        if (is_false || is_true) continue;
        for (int k = j0; k < j; ++k) {
            int l = glits[t.group_first + k].literal;
            real d = l < 0 ? -INFINITY : literal_distance(quadrics, literals[l], p);
            if (fabs(d) < s.radius) mask[1 + k / 32] |= 1u << (k % 32);
        }
    }
    if (always) mask[0] = 1;
    for (int w = 0; w <= MASK_WORDS; ++w) masks[(MASK_WORDS + 1) * gid + w] = mask[w];
    sample_terms[gid] = best_term;
}
