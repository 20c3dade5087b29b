/* Adaptive subdivision sampler on the CSG tape (paper section 4.2 with eq. 22 generalized to
 * the tree; the driver is clcsg/sampling/sampler.py, which states the guarantee).
 *
 * One launch per level (levels run in chains: see the kernel), one cell per work-item, which
 * also classifies the halves of the small cells it splits in place (split_cell).  The
 * cell's tape is pruned over the cell's patch with the task's quadric substituted; if both
 * sides come out constant the patch is decided without a distance query (equal: no surface,
 * discard; different: all surface, fill).  Otherwise d_q(p) at the corners decides: discard, fill,
 * single sample, or split (the children get the tape pruned over the patch grown by the
 * radius, written once, with exactly the rows pruning keeps, into the level's output arena).
 * Arenas ping-pong: a level reads its cells' tapes from `arena_in` and writes its children's
 * into `arena_out`, so an arena holds the tapes of one level's live cells only.  A sample is
 * finished as it is emitted (finish.h: its clip program from the cell's tape, sign, normal,
 * primitive).  Children, samples, tapes and clip programs are appended with atomics and
 * written only below the capacity; the counters keep counting, so the host sees an overflow,
 * grows the buffer and re-runs the level.
 *
 * Build options: -DCLCSG_DOUBLE, TAPE_REGS, WORST_CASE_DISTORTION, SPLIT_AT(_Y), QUAD_SPLIT_DIAG,
 * HERE_DEPTH, WORK_GROUP, MAX_FILL (largest grid a cell may emit at once; larger cells are split
 * instead).  Counter slots SC_* come from clcsg/cl/constants.py.
 */
#include "tape.h"
#include "fill.h"
#include "plane_cases.h"

#ifndef MAX_FILL
#define MAX_FILL 65536
#endif

/* Where a split cuts the longest edge, as a fraction of it (SPLIT_AT across x, SPLIT_AT_Y
 * across y).  Not one half: models are full of features at the middle (or a quarter...) of
 * their boxes, and a cell edge lying exactly on a trimming curve can never be decided (its
 * corners there have d_q = 0, and no bound separates it from the curve), so it would split
 * down to the floor.  Not one fraction for both axes: a cell's corners would then lie on the
 * diagonal x = y of its root cell, where curves of symmetric models run (the tricylinder's
 * edges), and each such corner starts a chain of cells down to the floor (Steinmetz: a third
 * of its cells).  Any fractions keep the guarantee. */
#if !defined(SPLIT_AT) || !defined(SPLIT_AT_Y)
#error "SPLIT_AT, SPLIT_AT_Y: the split fractions come from the driver (sampler.py)"
#endif
#ifndef QUAD_SPLIT_DIAG
#error "QUAD_SPLIT_DIAG: from the driver (sampler.py)"
#endif

typedef struct {
    uint queries, leaves, evals, tapes_written;
} cell_work;

/* d_q at a point of the task's quadric, with the cell's tape */
CLCSG_INLINE real query(__global const tape_op *tape, int n, __global const quadric_rec *qs, int q, real3 p,
                  cell_work *w)
{
    ++w->queries;
    return surface_distance(tape_eval(tape, n, qs, p, q, &w->leaves));
}

/* The patch over the cell (local box [x0,x1] x [y0,y1] x [t_lo,t_hi]) as a prune region. */
CLCSG_INLINE prune_region patch_region(const plane_frame *pf, cell_rec c, real t_lo, real t_hi, real grow)
{
    return box_region(pf, c.x0, c.x1, c.y0, c.y1, t_lo, t_hi, grow);
}

#define OUT_DISCARDED 0
#define OUT_FILLED 1
#define OUT_SINGLE 2
#define OUT_SPLIT 3
#define OUT_UNRESOLVED 4
#define OUT_DECIDED_DISCARD 5
#define OUT_DECIDED_FILL 6
#define OUT_SPLIT_HERE 7 /* split in place (split_cell) */

/* What the exact interval bounds say about a cell's patch: its height range [t_lo, t_hi],
 * the distortion bound delta (|dp| <= delta |d(x, y)| over the cell) and what it needs, as
 * squares (delta2, diag2 and enough2 = (delta diag)^2: no square root or division per cell for
 * the corner discs; fill_fits takes the one root a fill needs). */
typedef struct {
    plane_frame pf;
    real t_lo, t_hi, delta2, enough2, wx, wy, et, diag2;
    bool whole_domain;
} cell_geom;

/* Slope interval of the heightfield along one in-plane axis over [a, b]: from R + lam_k t^2 = 0
 * (two sheets) dt/dx = -(lam x + beta) / (lam_k t), t in [t_lo, t_hi] of one sign; from
 * R + 2 beta_k t = 0 (one sheet) dt/dx = -(lam x + beta) / beta_k.  lam x + beta is linear, so
 * its range is its values at a and b; `inv` is the range of 1 / (lam_k t) (or 1 / beta_k),
 * which both axes share. */
CLCSG_INLINE real2 slope_range(real2 inv, real lam, real beta, real a, real b)
{
    real u = lam * a + beta, v = lam * b + beta;
    return interval_mul((real2)(-fmax(u, v), -fmin(u, v)), inv);
}

/* Where the heightfield is defined with a finite slope over the whole cell, give the prune
 * region the patch itself (the mean value test of leaf_over_patch); otherwise leave it off. */
CLCSG_INLINE void patch_on_surface(const cell_geom *g, cell_rec c, prune_region *r)
{
    real xm = 0.5 * (c.x0 + c.x1), ym = 0.5 * (c.y0 + c.y1);
    if (!g->whole_domain || !isfinite(g->delta2)) return;
    if (g->pf.lk != 0 && !(g->t_lo > 0 || g->t_hi < 0)) return;
    r->on_patch = 1;
    r->pc = plane_point(&g->pf, xm, ym, plane_height_clamped(&g->pf, xm, ym));
    r->ui = plane_axis(&g->pf, g->pf.i);
    r->uj = plane_axis(&g->pf, g->pf.j);
    r->uk = plane_axis(&g->pf, g->pf.k);
    r->hx = 0.5 * g->wx;
    r->hy = 0.5 * g->wy;
    real2 inv;
    if (g->pf.lk == 0) {
        inv = (real2)(1 / g->pf.bk, 1 / g->pf.bk);
    } else {
        real d0 = g->pf.lk * g->t_lo, d1 = g->pf.lk * g->t_hi;
        inv = (real2)(1 / fmax(d0, d1), 1 / fmin(d0, d1));
    }
    r->sx = slope_range(inv, g->pf.li, g->pf.bi, c.x0, c.x1);
    r->sy = slope_range(inv, g->pf.lj, g->pf.bj, c.y0, c.y1);
}

/* Fill g from the interval bounds over the cell; false: the cell holds no point of the task
 * (the heightfield is undefined over it, plane k owns none of it, or it lies outside the
 * task's box). */
CLCSG_INLINE bool cell_geometry(const task_rec *t, __global const frame_rec *frames, cell_rec c, real radius, cell_geom *g)
{
    plane_load(&g->pf, frames + t->quadric, t->plane, t->sheet);
    const plane_frame *pf = &g->pf;
    rect_bounds rb = rect_bounds_of(pf, c.x0, c.x1, c.y0, c.y1);
    real2 t_range;
    if (!rect_heights(pf, rb.R, &t_range, &g->whole_domain)) return false;
    g->t_lo = t_range.x;
    g->t_hi = t_range.y;
    if (!rect_may_be_owned(rb)) return false;
    if (g->t_hi < t->zlo[pf->k] || g->t_lo > t->zhi[pf->k]) return false;
    real ni_hi = rb.ni.y, nj_hi = rb.nj.y, nk_lo = rb.nk.x, nk_hi = rb.nk.y;
    g->delta2 = nk_lo > 0 ? (ni_hi * ni_hi + nj_hi * nj_hi + nk_hi * nk_hi) / (nk_lo * nk_lo) : INFINITY;
#if WORST_CASE_DISTORTION
    g->delta2 = fmax(g->delta2, (real)3);
#endif
    g->wx = c.x1 - c.x0;
    g->wy = c.y1 - c.y0;
    g->et = g->t_hi - g->t_lo;
    g->diag2 = g->wx * g->wx + g->wy * g->wy;
    g->enough2 = g->delta2 * g->diag2;
    return true;
}

/* May the cell be filled at once: the heightfield is defined over all of it with a finite
 * distortion bound, and (wx / s + 1) (wy / s + 1) <= MAX_FILL for the grid spacing
 * s = sqrt 2 r / delta of fill_cell (multiplied out by s delta). */
CLCSG_INLINE bool fill_fits(const cell_geom *g, real radius)
{
    if (!g->whole_domain || !isfinite(g->delta2)) return false;
    real delta = sqrt(g->delta2), s0 = sqrt((real)2) * radius;
    return (g->wx * delta + s0) * (g->wy * delta + s0) <= MAX_FILL * s0 * s0;
}

/* d_q at the four corners (x0,y0), (x1,y0), (x0,y1), (x1,y1); NaN where the heightfield is
 * undefined.  Values inherited from the parent were evaluated with the parent's tape over a
 * larger cell: still conservative.  An inherited value was taken at the same point of the
 * same heightfield, so the height is defined there and is not computed again (try_single
 * computes the one point it emits). */
CLCSG_INLINE void corner_distances(const cell_geom *g, cell_rec c, __global const tape_op *tape, int n,
                             __global const quadric_rec *qs, int q, real d[4], cell_work *w)
{
    real cx[4] = {c.x0, c.x1, c.x0, c.x1};
    real cy[4] = {c.y0, c.y0, c.y1, c.y1};
    for (int m = 0; m < 4; ++m) {
        real h;
        if (c.level > 0 && !isnan(c.d[m]))
            d[m] = c.d[m];
        else
            d[m] = plane_height(&g->pf, cx[m], cy[m], &h) ? query(tape, n, qs, q, plane_point(&g->pf, cx[m], cy[m], h), w)
                                                          : NAN;
    }
}

/* +1: the discs of positive distance cover the cell (one disc of radius |d| / delta reaching
 * the far corner, or four each reaching its quarter): no surface; -1: the same with negative
 * distances: all surface; 0: undecided. */
CLCSG_INLINE int corner_cover(const cell_geom *g, const real d[4])
{
    bool all_pos = true, all_neg = true, one_neg = false;
    real min_sq = INFINITY; /* the least d^2: the discs compare squares (cell_geom) */
    for (int m = 0; m < 4; ++m) {
        if (isnan(d[m])) {
            all_pos = all_neg = false;
            continue;
        }
        all_pos = all_pos && d[m] > 0;
        all_neg = all_neg && d[m] < 0;
        real sq = d[m] * d[m];
        min_sq = fmin(min_sq, sq);
        if (d[m] > 0 && sq >= g->enough2) return 1;
        if (d[m] < 0 && sq >= g->enough2) one_neg = true;
    }
    /* min |d| >= enough / 2 */
    if (all_pos && 4 * min_sq >= g->enough2) return 1;
    if (one_neg || (all_neg && 4 * min_sq >= g->enough2)) return -1;
    return 0;
}

/* Single sample (paper 4.2 special case): a point on the CSG surface whose splat covers the
 * patch's whole 3-D box; a corner with d < 0 first, then the cell's center (which reaches a
 * box twice as large, at the cost of one query).  The splat radius shrinks to what is needed. */
inline bool try_single(const cell_geom *g, cell_rec c, const real d[4],
                       __global const tape_op *tape, int n, __global const quadric_rec *qs, int q, real radius,
                       sample_src src, sample_sink *out, cell_work *w)
{
    real cx[4] = {c.x0, c.x1, c.x0, c.x1};
    real cy[4] = {c.y0, c.y0, c.y1, c.y1};
    /* a corner's splat reaches the far side of the cell, sqrt(diag^2 + ft^2) >= diag, the
     * centre's half of it: most cells are too large for either, and need no height */
    real r2 = radius * radius;
    if (0.25 * g->diag2 > r2) return false;
    bool corners = g->diag2 <= r2 * (1 + (real)1e-9);
    int best = -1;
    real best_r = INFINITY, best_h = 0; /* squared, then the radius */
    for (int m = 0; m < 4; ++m) {
        if (!corners || !(d[m] < 0)) continue;
        real h = plane_height_clamped(&g->pf, cx[m], cy[m]);
        real fx = fmax(cx[m] - c.x0, c.x1 - cx[m]);
        real fy = fmax(cy[m] - c.y0, c.y1 - cy[m]);
        real ft = fmax(h - g->t_lo, g->t_hi - h);
        real m2 = fx * fx + fy * fy + ft * ft;
        if (m2 < best_r) {
            best_r = m2;
            best = m;
            best_h = h;
        }
    }
    best_r = sqrt(best_r);
    if (best >= 0 && best_r <= radius) {
        emit_sample(out, sink_slots(out, 1), plane_point(&g->pf, cx[best], cy[best], best_h),
                    fmax(best_r, radius * (real)1e-3), src);
        return true;
    }
    real center_r2 = 0.25 * g->diag2, h; /* squared */
    real mx = 0.5 * (c.x0 + c.x1), my = 0.5 * (c.y0 + c.y1);
    if (!plane_height(&g->pf, mx, my, &h)) return false;
    real ft = fmax(h - g->t_lo, g->t_hi - h);
    real r = sqrt(center_r2 + ft * ft);
    if (r > radius) return false;
    real3 pc = plane_point(&g->pf, mx, my, h);
    if (!(query(tape, n, qs, q, pc, w) < 0)) return false;
    emit_sample(out, sink_slots(out, 1), pc, fmax(r, radius * (real)1e-3), src);
    return true;
}

/* d_q at the point (x, y) of the plane, NaN where the heightfield is undefined */
CLCSG_INLINE real query_at(const cell_geom *g, real x, real y, __global const tape_op *tape, int n,
                     __global const quadric_rec *qs, int q, cell_work *w)
{
    real h;
    if (!plane_height(&g->pf, x, y, &h)) return NAN;
    return query(tape, n, qs, q, plane_point(&g->pf, x, y, h), w);
}

/* A split hands a short tape (COPY_TAPE_ROWS rows at most) of a small cell (diagonal^2 below
 * COPY_TAPE_DIAG2 radii^2) to its children as it is: their patches grown by the radius are
 * hardly smaller than the cell's, so pruning it again shortened few tapes (none of the zoo's
 * cells or samples changed) and cost 2% of the lens's and the Steinmetz solid's time.  Long
 * tapes (a cell among thousands of primitives) are still pruned: the arena holds what pruning
 * keeps. */
#define COPY_TAPE_ROWS 16
#define COPY_TAPE_DIAG2 8
/* HERE_DEPTH: the cells a work-item holds for the cells it splits in place (split_cell; from
 * the driver, sampler.py); a split with no room left writes its halves out as any other */
#ifndef HERE_DEPTH
#error "HERE_DEPTH: from the driver (sampler.py)"
#endif

/* The two halves of cell c across its longer edge (at SPLIT_AT / SPLIT_AT_Y of it) into *a
 * and *b: *a comes with the halves' level and tape set, and *b starts as a copy of it.  The two
 * new corners, which both halves share, are evaluated with the halves' tape `tape`; the other
 * corners are the cell's. */
CLCSG_INLINE void split_halves(const cell_geom *g, cell_rec c, const real d[4], __global const tape_op *tape, int n,
                               __global const quadric_rec *qs, int q, cell_rec *a, cell_rec *b, cell_work *w)
{
    *b = *a;
    real e0, e1;
    if (g->wx >= g->wy) {
        real mid = c.x0 + (real)SPLIT_AT * g->wx;
        a->x1 = b->x0 = mid;
        e0 = query_at(g, mid, c.y0, tape, n, qs, q, w);
        e1 = query_at(g, mid, c.y1, tape, n, qs, q, w);
        a->d[1] = e0; a->d[3] = e1; /* a = [x0, mid]: new right corners */
        b->d[0] = e0; b->d[2] = e1; /* b = [mid, x1]: new left corners */
        a->d[0] = d[0]; a->d[2] = d[2];
        b->d[1] = d[1]; b->d[3] = d[3];
    } else {
        real mid = c.y0 + (real)SPLIT_AT_Y * g->wy;
        a->y1 = b->y0 = mid;
        e0 = query_at(g, c.x0, mid, tape, n, qs, q, w);
        e1 = query_at(g, c.x1, mid, tape, n, qs, q, w);
        a->d[2] = e0; a->d[3] = e1; /* a = [y0, mid]: new top corners */
        b->d[0] = e0; b->d[1] = e1; /* b = [mid, y1]: new bottom corners */
        a->d[0] = d[0]; a->d[1] = d[1];
        b->d[2] = d[2]; b->d[3] = d[3];
    }
}

/* Split along the longest edge, or along both edges (four children) while the cell is
 * roughly square and large against the radius (QUAD_SPLIT_DIAG radii): such a cell's children
 * would be split across the other edge at the next level anyway, and a level costs a launch
 * and a counter read whatever its size.  The children's tape (one copy per two children) is
 * this tape pruned over the patch grown by the radius (so it stays valid over every splat ball their samples get),
 * counted first and written with exactly that many rows into arena_out (the write replays the
 * count's leaf states).  The new corners, shared by the children, are evaluated here once
 * with the children's tape, just written: exact over the whole patch as the cell's tape is,
 * and shorter.
 *
 * A cell whose tape is handed on as it is (COPY_TAPE_ROWS, COPY_TAPE_DIAG2) is split in place
 * where `room` allows: its two halves go to `here` with the cell's own tape in arena_in, and
 * the caller classifies them in this launch.  They are the cells the next level would get
 * (the same corners, the same tape), so the samples are the same; what is saved is writing
 * them and their tape copy, two atomics, reading them back, and the launches of the levels
 * that only such cells reach (the cells along edges and contacts that go down towards the
 * floor).  True: split in place. */
inline bool split_cell(const cell_geom *g, cell_rec c, const real d[4], __global const tape_op *tape, int n,
                       __global const quadric_rec *qs, int q, real radius, __global cell_rec *cells_out,
                       uint cap_cells, __global tape_op *arena_out, uint cap_arena,
                       __global volatile uint *counters, bool room, cell_rec *here, cell_work *w)
{
    bool quad = g->diag2 > (real)(QUAD_SPLIT_DIAG * QUAD_SPLIT_DIAG) * radius * radius
             && fmin(g->wx, g->wy) >= (real)0.5 * fmax(g->wx, g->wy);
    bool copy = n <= COPY_TAPE_ROWS && g->diag2 < (real)COPY_TAPE_DIAG2 * radius * radius;
    cell_rec a = c;
    a.level = c.level + 1;
    if (copy && !quad && room) {
        split_halves(g, c, d, tape, n, qs, q, &a, &here[1], w);
        here[0] = a;
        return true;
    }
    uint k = quad ? 4u : 2u;
    uint slot = atomic_add(&counters[SC_CELLS], k);
    prune_region grown;
    uchar state;
    int first, count, rows = n;
    prune_memo memo; /* the count's leaf states, replayed by the write */
    memo.mode = 1;
    if (!copy) {
        grown = patch_region(&g->pf, c, g->t_lo, g->t_hi, radius);
        rows = tape_prune_rows_memo(tape, n, qs, &grown, q, &state, &w->evals, &memo);
    }
    /* four children get the tape twice, a copy per pair: a tape serves at most two cells */
    uint copies = quad ? 2u : 1u;
    uint base = atomic_add(&counters[SC_ARENA], copies * (uint)rows);
    if (slot + k > cap_cells || base + copies * (uint)rows > cap_arena) return false; /* overflow: the level re-runs */
    if (copy) {
        for (int m = 0; m < n; ++m) arena_out[base + m] = tape[m];
        first = 0;
        count = n;
    } else {
        tape_write_pruned(tape, n, rows, qs, &grown, q, state, arena_out + base, &first, &count, &w->evals, &memo);
    }
    w->tapes_written += copies;
    a.tape_first = (int)base + first;
    a.tape_count = count;
    tape = arena_out + a.tape_first;
    n = count;
    if (quad) {
        for (int m = 0; m < count; ++m) arena_out[base + rows + first + m] = arena_out[base + first + m];
        /* corners (x0|xm|x1) x (y0|ym|y1), row-major: e[3 * j + i] */
        real xs[3] = {c.x0, c.x0 + (real)SPLIT_AT * g->wx, c.x1};
        real ys[3] = {c.y0, c.y0 + (real)SPLIT_AT_Y * g->wy, c.y1};
        real e[9];
        e[0] = d[0]; e[2] = d[1]; e[6] = d[2]; e[8] = d[3];
        e[1] = query_at(g, xs[1], ys[0], tape, n, qs, q, w);
        e[3] = query_at(g, xs[0], ys[1], tape, n, qs, q, w);
        e[4] = query_at(g, xs[1], ys[1], tape, n, qs, q, w);
        e[5] = query_at(g, xs[2], ys[1], tape, n, qs, q, w);
        e[7] = query_at(g, xs[1], ys[2], tape, n, qs, q, w);
        for (int j = 0; j < 2; ++j)
            for (int i = 0; i < 2; ++i) {
                cell_rec b = a;
                b.x0 = xs[i]; b.x1 = xs[i + 1];
                b.y0 = ys[j]; b.y1 = ys[j + 1];
                b.d[0] = e[3 * j + i]; b.d[1] = e[3 * j + i + 1];
                b.d[2] = e[3 * (j + 1) + i]; b.d[3] = e[3 * (j + 1) + i + 1];
                b.tape_first = (int)base + j * rows + first;
                cells_out[slot + 2 * j + i] = b;
            }
        return false;
    }
    cell_rec b;
    split_halves(g, c, d, tape, n, qs, q, &a, &b, w);
    cells_out[slot] = a;
    cells_out[slot + 1] = b;
    return false;
}

/* A cell with no corner on the surface: its live leaves may only be faces where solids meet,
 * or quadrics that touch a plane task without crossing it (tape.h surface_cases, and on a plane
 * task plane_cases.h for the cases no point has). */
inline bool no_surface_in_cases(const cell_geom *g, cell_rec c, const prune_region *patch,
                                __global const tape_op *tape, int n, __global const quadric_rec *qs, int self_q,
                                const prune_memo *leaves)
{
    int live[CASE_QUADRICS], k = 0;
    uint cases = surface_cases(tape, n, self_q, leaves, live, &k);
    if (cases == 0) return true;
    if (cases == ~0u) return false;
    cases &= plane_possible_cases(&g->pf, qs, live, k, c.x0, c.x1, c.y0, c.y1);
    return cases == 0 || (cases & task_possible_cases(qs, self_q, live, k, patch)) == 0;
}

/* The source of a filled cell's samples: its tape pruned over the patch grown by the radius,
 * which holds every splat ball of the cell's samples (finish.h).  Decided there, the samples
 * get their sides (SIDES_KNOWN | membership bits) and no pruning; otherwise the pruned tape is
 * written to the clip buffer as the samples' tape (left as it was if the buffer is full: the
 * level runs again).  One pruning pass per cell, and per sample only the leaves still live. */
inline sample_src fill_source(const cell_geom *g, cell_rec c, sample_src src, real radius, sample_sink *out,
                              cell_work *w)
{
    prune_region grown = patch_region(&g->pf, c, g->t_lo, g->t_hi, radius);
    uchar state;
    prune_memo memo; /* the count's leaf states and rows' fates, for the write */
    memo.mode = 3;
    int rows = tape_prune_rows_memo(src.tape, src.tape_count, out->qs, &grown, src.quadric, &state, &w->evals, &memo);
    if (prune_decision(state) < 0) {
        src.sides = SIDES_KNOWN | (int)prune_member_bits(state);
        return src;
    }
    int count;
    int at = sink_clip_program(out, src.tape, src.tape_count, rows, &grown, src.quadric, state, &memo, &w->evals,
                               &count);
    if (at < 0) return src;
    src.clip_at = at;
    src.tape = out->clip + at;
    src.tape_count = count;
    return src;
}

/* One cell: geometry, the pruned tape's decision, the corner discs, single sample, fill,
 * floor, split (in that order; see the module docstring of sampler.py for the guarantee). */
int classify_cell(cell_rec c, __global const quadric_rec *qs, __global const frame_rec *frames,
                  __global const task_rec *tasks, __global cell_rec *cells_out, uint cap_cells,
                  __global const tape_op *arena_in, __global tape_op *arena_out, uint cap_arena,
                  __global volatile uint *counters, real radius, real floor_size, sample_sink *out, bool room,
                  cell_rec *here, cell_work *w)
{
    task_rec t = tasks[c.task];
    cell_geom g;
    if (!cell_geometry(&t, frames, c, radius, &g)) return OUT_DISCARDED;
    __global const tape_op *tape = arena_in + c.tape_first;
    int n = c.tape_count;
    sample_src src = {c.task, t.quadric, t.plane, t.sheet, tape, n, 0, -1};
    /* the discs of the corners the cell has from its parent first (a split gives both
     * children all four corners; NaN, unknown, gives no disc): where they prove the patch off
     * the surface, pruning it would only say the same */
    if (corner_cover(&g, c.d) > 0) return OUT_DISCARDED;

    /* the tape over the patch: both sides constant decides the whole patch; a value that no
     * longer depends on the task's quadric is the same on both sides: no surface.  Not where
     * the inherited corners straddle the surface (one with d_q < 0, on it, one with d_q > 0,
     * off it): pruning cannot decide such a patch, and its leaf states are only needed where
     * no corner is on the surface */
    prune_region patch;
    prune_memo leaves; /* the leaves' states over the patch, for surface_cases */
    bool straddles = (c.d[0] < 0 || c.d[1] < 0 || c.d[2] < 0 || c.d[3] < 0)
                  && (c.d[0] > 0 || c.d[1] > 0 || c.d[2] > 0 || c.d[3] > 0);
    if (!straddles) {
        patch = patch_region(&g.pf, c, g.t_lo, g.t_hi, 0);
        patch_on_surface(&g, c, &patch);
        uchar state;
        leaves.mode = 1;
        tape_prune_rows_memo(tape, n, qs, &patch, t.quadric, &state, &w->evals, &leaves);
        int decided = prune_decision(state);
        if (decided > 0 || !(state & ST_SELF)) return OUT_DECIDED_DISCARD;
        if (decided < 0 && fill_fits(&g, radius)) {
            fill_cell(&g.pf, c, radius, fill_source(&g, c, src, radius, out, w), out);
            return OUT_DECIDED_FILL;
        }
    }
    real d[4];
    corner_distances(&g, c, tape, n, qs, t.quadric, d, w);
    int cover = corner_cover(&g, d);
    if (cover > 0) return OUT_DISCARDED;
    if (!(d[0] < 0 || d[1] < 0 || d[2] < 0 || d[3] < 0) && no_surface_in_cases(&g, c, &patch, tape, n, qs, t.quadric, &leaves))
        return OUT_DECIDED_DISCARD;
    if (try_single(&g, c, d, tape, n, qs, t.quadric, radius, src, out, w))
        return OUT_SINGLE;
    /* fill: the corner discs of negative distance cover the cell and the heightfield is
     * defined everywhere: a grid with spacing s <= sqrt 2 r / delta puts every point of the
     * cell within r / delta (2-D), hence within r (3-D), of a sample */
    if (cover < 0 && fill_fits(&g, radius)) {
        fill_cell(&g.pf, c, radius, fill_source(&g, c, src, radius, out, w), out);
        return OUT_FILLED;
    }
    if (g.diag2 + g.et * g.et < floor_size * floor_size) return OUT_UNRESOLVED;
    return split_cell(&g, c, d, tape, n, qs, t.quadric, radius, cells_out, cap_cells, arena_out, cap_arena, counters,
                      room, here, w)
               ? OUT_SPLIT_HERE
               : OUT_SPLIT;
}

#ifndef WORK_GROUP
#error "WORK_GROUP: the work-group size comes from the driver (sampler.py)"
#endif

/* the per-cell statistics summed over a work-group before one atomic per counter (an atomic
 * per cell and counter contends between the compute units) */
#define WG_SUMS 15
constant int WG_SLOT[WG_SUMS] = {SC_DISCARDED, SC_FILLED, SC_SINGLE, SC_SPLIT, SC_SPLIT_IN_PLACE, SC_UNRESOLVED,
                                 SC_PRUNED_DECIDED, SC_DISTANCE_QUERIES, SC_LEAF_DISTANCES, SC_PRUNE_EVALUATIONS,
                                 SC_TAPES_WRITTEN, SC_TAPE_ROWS, SC_FINISH_PRUNE_EVALUATIONS, SC_SAMPLES, SC_CLIP_ROWS};

/* One level: a cell per work-item (classify_cell); its samples are finished as they are
 * emitted (finish.h), into the sample columns, while its tape is at hand.
 *
 * Levels run in chains, launched one after another with no read in between: the host reads
 * the counters once per chain.  `counters` holds a row of N_SAMPLER_COUNTERS per level of the
 * chain: row 0 is the host's seed (SC_CELLS: the first level's cells; SC_SAMPLES and
 * SC_CLIP_ROWS: the running totals every level appends at), row `row` this level's own counts.
 * A level's cells are the ones the level before wrote (its row's SC_CELLS), so a launch is
 * sized to what that could be at most, and its work-groups loop over the cells in strides.  A
 * level after one that overran a buffer does nothing and says so (SC_STATUS): its inputs stay
 * as they were, and the host runs the overrun level again with larger buffers. */
__kernel __attribute__((reqd_work_group_size(WORK_GROUP, 1, 1)))
void classify(__global const quadric_rec *qs, __global const frame_rec *frames,
              __global const task_rec *tasks, __global const cell_rec *cells_in, uint cap_cells_in,
              __global cell_rec *cells_out, uint cap_cells,
              __global real *sample_reals, __global int *sample_ints, uint cap_samples,
              __global const tape_op *arena_in, uint cap_arena_in, __global tape_op *arena_out, uint cap_arena,
              __global volatile uint *counters, int row, real radius, real floor_size,
              __global tape_op *clip, uint cap_clip, __global uint *clip_table, uint clip_table_mask,
              uint launch, PRIMITIVE_TABLE)
{
    __local uint sums[WG_SUMS][WORK_GROUP];
    __local uint tape_max[WORK_GROUP];
    __global volatile uint *running = counters;
    __global volatile uint *prev = counters + (row - 1) * N_SAMPLER_COUNTERS;
    __global volatile uint *mine = counters + row * N_SAMPLER_COUNTERS;
    int lid = get_local_id(0);
    __local uint skip;
    /* a buffer overrun before this level (or by another work-group of it, which the host sees
     * in this level's counts): nothing to do.  The running totals are read atomically: other
     * work-groups may be adding to them */
    if (lid == 0) {
        skip = prev[SC_STATUS] || prev[SC_CELLS] > cap_cells_in || prev[SC_ARENA] > cap_arena_in
            || atomic_or(&running[SC_SAMPLES], 0u) > cap_samples || atomic_or(&running[SC_CLIP_ROWS], 0u) > cap_clip;
        if (skip) atomic_or(&mine[SC_STATUS], 1u);
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    uint n_cells = skip ? 0 : prev[SC_CELLS];
    sample_sink out = {sample_reals, sample_ints, cap_samples, running, clip, cap_clip, qs, frames,
                       PRIMITIVE_TABLE_ARGS, 0, 0, 0, clip_table, clip_table_mask, launch};
    /* the work-item's sums over its cells, in registers until the work-group adds them up.
     * Each cell counts its work in a cell_work of its own, added to the sums here.  A single
     * cell_work for all of a work-item's cells, whose address went down the calls, kept about
     * 1 in WORK_GROUP of its counts under PoCL 3.0's loop vectorizer on an AVX-512 CPU (the
     * drilled block: 152 distance queries of 10,080; the samples were right) */
    uint queries = 0, leaves = 0, evals = 0, tapes_written = 0;
    uint discarded = 0, filled = 0, single = 0, split = 0, split_here = 0, unresolved = 0, decided = 0, rows = 0, rows_max = 0;
    for (uint start = get_group_id(0) * WORK_GROUP; start < n_cells; start += get_num_groups(0) * WORK_GROUP) {
        uint gid = start + lid;
        if (gid >= n_cells) continue;
        /* the cell, then the halves of the cells split in place, depth first */
        cell_rec stack[HERE_DEPTH];
        int top = 0;
        stack[top++] = cells_in[gid];
        rows += (uint)stack[0].tape_count; /* the level's own cells: the host divides by them */
        rows_max = max(rows_max, (uint)stack[0].tape_count);
        while (top > 0) {
            cell_rec c = stack[--top];
            cell_work w = {0, 0, 0, 0};
            int o = classify_cell(c, qs, frames, tasks, cells_out, cap_cells, arena_in, arena_out, cap_arena, mine,
                                  radius, floor_size, &out, top + 2 <= HERE_DEPTH, stack + top, &w);
            top += o == OUT_SPLIT_HERE ? 2 : 0;
            queries += w.queries;
            leaves += w.leaves;
            evals += w.evals;
            tapes_written += w.tapes_written;
            discarded += o == OUT_DISCARDED || o == OUT_DECIDED_DISCARD;
            filled += o == OUT_FILLED || o == OUT_DECIDED_FILL;
            single += o == OUT_SINGLE;
            split += o == OUT_SPLIT || o == OUT_SPLIT_HERE;
            split_here += o == OUT_SPLIT_HERE;
            unresolved += o == OUT_UNRESOLVED;
            decided += o == OUT_DECIDED_DISCARD || o == OUT_DECIDED_FILL;
        }
    }
    uint mine_sums[WG_SUMS] = {discarded, filled, single, split, split_here, unresolved, decided, queries, leaves,
                               evals, tapes_written, rows, out.evals, out.emitted, out.clip_rows};
    for (int k = 0; k < WG_SUMS; ++k) sums[k][lid] = mine_sums[k];
    tape_max[lid] = rows_max;
    barrier(CLK_LOCAL_MEM_FENCE);
    if (lid < WG_SUMS) {
        uint t = 0;
        for (int m = 0; m < WORK_GROUP; ++m) t += sums[lid][m];
        if (t) atomic_add(&mine[WG_SLOT[lid]], t);
    } else if (lid == WG_SUMS) {
        uint t = 0;
        for (int m = 0; m < WORK_GROUP; ++m) t = max(t, tape_max[m]);
        atomic_max(&mine[SC_TAPE_MAX], t);
    }
}
