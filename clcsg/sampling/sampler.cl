/* Adaptive subdivision sampler on the CSG tape (paper section 4.2 with eq. 22 generalized to
 * the tree; the driver is clcsg/sampling/sampler.py, which states the guarantee).
 *
 * One launch per level: every work-item takes one cell of the current queue.  The cell's tape
 * is pruned over the cell's patch with the task's quadric substituted; if both sides come out
 * constant the patch is decided without a distance query (equal: no surface, discard;
 * different: all surface, fill).  Otherwise d_q(p) at the corners decides: discard, fill,
 * single sample, or split (the children get the tape pruned over the patch grown by the
 * radius, written once into the tape arena).  Children, samples and tapes are appended with
 * atomics and written only below the capacity; the counters keep counting, so the host sees
 * an overflow, grows the buffer and re-runs the level.
 *
 * Build options: -DCLCSG_DOUBLE, TAPE_REGS, WORST_CASE_DISTORTION, MAX_FILL (largest grid a
 * cell may emit at once; larger cells are split instead).  Counter slots SC_* come from
 * clcsg/cl/constants.py.
 */
#include "tape.h"
#include "fill.h"

#ifndef MAX_FILL
#define MAX_FILL 65536
#endif

typedef struct {
    uint queries, leaves, evals, tapes_written;
} cell_work;

/* d_q at a point of the task's quadric, with the cell's tape */
inline real query(__global const tape_op *tape, int n, __global const quadric_rec *qs, int q, real3 p,
                  cell_work *w)
{
    ++w->queries;
    return surface_distance(tape_eval(tape, n, qs, p, q, &w->leaves));
}

/* The patch over the cell (local box [x0,x1] x [y0,y1] x [t_lo,t_hi]) as a prune region. */
inline prune_region patch_region(const plane_frame *pf, cell_rec c, real t_lo, real t_hi, real grow)
{
    prune_region g;
    g.c = plane_point(pf, 0.5 * (c.x0 + c.x1), 0.5 * (c.y0 + c.y1), 0.5 * (t_lo + t_hi));
    g.a0 = (real)(0.5 * (c.x1 - c.x0)) * plane_axis(pf, pf->i);
    g.a1 = (real)(0.5 * (c.y1 - c.y0)) * plane_axis(pf, pf->j);
    g.a2 = (real)(0.5 * (t_hi - t_lo)) * plane_axis(pf, pf->k);
    g.rho = grow;
    return g;
}

#define OUT_DISCARDED 0
#define OUT_FILLED 1
#define OUT_SINGLE 2
#define OUT_SPLIT 3
#define OUT_UNRESOLVED 4
#define OUT_DECIDED_DISCARD 5
#define OUT_DECIDED_FILL 6

int classify_cell(cell_rec c, __global const quadric_rec *qs, __global const frame_rec *frames,
                  __global const task_rec *tasks, __global cell_rec *cells_out, uint cap_cells,
                  __global raw_sample_rec *samples, uint cap_samples, __global tape_op *arena, uint cap_arena,
                  __global volatile uint *counters, real radius, real floor_size, cell_work *w)
{
    task_rec t = tasks[c.task];
    plane_frame pf = plane_load(frames + t.quadric, t.plane, t.sheet);
    __global const tape_op *tape = arena + c.tape_first;
    int n = c.tape_count;
    sample_src src = {c.task, c.tape_first, c.tape_count};

    /* exact interval bounds over the cell */
    rect_bounds rb = rect_bounds_of(&pf, c.x0, c.x1, c.y0, c.y1);
    real t_lo, t_hi;
    bool whole_domain = true;
    if (pf.lk != 0) {
        real Hlo = -(pf.lk > 0 ? rb.R.y : rb.R.x) / pf.lk;
        real Hhi = -(pf.lk > 0 ? rb.R.x : rb.R.y) / pf.lk;
        if (Hhi < 0) return OUT_DISCARDED; /* no surface over this cell */
        whole_domain = Hlo >= 0;
        real a = sqrt(fmax(Hlo, (real)0)), b = sqrt(Hhi);
        t_lo = pf.sheet > 0 ? a : -b;
        t_hi = pf.sheet > 0 ? b : -a;
    } else {
        t_lo = fmin(-rb.R.y / (2 * pf.bk), -rb.R.x / (2 * pf.bk));
        t_hi = fmax(-rb.R.y / (2 * pf.bk), -rb.R.x / (2 * pf.bk));
    }
    /* plane k owns no point of the cell: an in-plane normal component dominates everywhere */
    if (!rect_may_be_owned(rb)) return OUT_DISCARDED;
    /* the patch lies outside the task's box */
    if (t_hi < t.zlo[pf.k] || t_lo > t.zhi[pf.k]) return OUT_DISCARDED;

    real ni_hi = rb.ni.y, nj_hi = rb.nj.y, nk_lo = rb.nk.x, nk_hi = rb.nk.y;
    /* distortion bound: |dp| <= delta |d(x, y)| over the cell */
    real delta = nk_lo > 0 ? sqrt(ni_hi * ni_hi + nj_hi * nj_hi + nk_hi * nk_hi) / nk_lo : INFINITY;
#if WORST_CASE_DISTORTION
    delta = fmax(delta, sqrt((real)3));
#endif
    real wx = c.x1 - c.x0, wy = c.y1 - c.y0, et = t_hi - t_lo;
    real diag = sqrt(wx * wx + wy * wy);
    real enough = delta * diag;
    real s_fill = sqrt((real)2) * radius / delta;
    bool fill_fits = whole_domain && isfinite(delta) && (wx / s_fill + 1) * (wy / s_fill + 1) <= MAX_FILL;

    /* the tape over the patch: both sides constant decides the whole patch */
    prune_region patch = patch_region(&pf, c, t_lo, t_hi, 0);
    int unused0, unused1;
    int decided = tape_prune(tape, n, qs, &patch, t.quadric, 0, &unused0, &unused1, &w->evals);
    if (decided > 0) return OUT_DECIDED_DISCARD;
    if (decided < 0 && fill_fits) {
        fill_cell(&pf, c, radius, src, counters, samples, cap_samples);
        return OUT_DECIDED_FILL;
    }

    /* corners: 3-D point and d_q(p) */
    real cx[4] = {c.x0, c.x1, c.x0, c.x1};
    real cy[4] = {c.y0, c.y0, c.y1, c.y1};
    real d[4];
    bool defined[4];
    real3 p[4];
    for (int m = 0; m < 4; ++m) {
        real h;
        defined[m] = plane_height(&pf, cx[m], cy[m], &h);
        d[m] = NAN;
        if (defined[m]) {
            p[m] = plane_point(&pf, cx[m], cy[m], h);
            /* inherited values were evaluated for a larger cell: still conservative */
            d[m] = (c.level > 0 && !isnan(c.d[m])) ? c.d[m] : query(tape, n, qs, t.quadric, p[m], w);
        }
    }

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
        if (d[m] > 0 && d[m] >= enough) return OUT_DISCARDED; /* one disc covers the cell */
    }
    if (all_pos && min_abs >= 0.5 * enough) return OUT_DISCARDED; /* each disc covers its quarter */

    /* single sample (paper 4.2 special case): a corner on the CSG surface whose splat of
     * radius r covers the patch's whole 3-D box; the splat radius shrinks to what is needed */
    int best = -1;
    real best_r = INFINITY;
    for (int m = 0; m < 4; ++m) {
        if (!defined[m] || !(d[m] < 0)) continue;
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
        emit_sample(samples, atomic_inc(&counters[SC_SAMPLES]), cap_samples, p[best],
                    fmax(best_r, radius * (real)1e-3), src);
        return OUT_SINGLE;
    }
    /* the same from the cell's center, which reaches a box twice as large: one more query */
    real center_r = 0.5 * diag;
    if (center_r <= radius) {
        real mx = 0.5 * (c.x0 + c.x1), my = 0.5 * (c.y0 + c.y1), h;
        if (plane_height(&pf, mx, my, &h)) {
            real ft = fmax(h - t_lo, t_hi - h);
            real r = sqrt(center_r * center_r + ft * ft);
            if (r <= radius) {
                real3 pc = plane_point(&pf, mx, my, h);
                if (query(tape, n, qs, t.quadric, pc, w) < 0) {
                    emit_sample(samples, atomic_inc(&counters[SC_SAMPLES]), cap_samples, pc,
                                fmax(r, radius * (real)1e-3), src);
                    return OUT_SINGLE;
                }
            }
        }
    }

    /* fill: the corner discs of negative distance cover the cell and the heightfield is
     * defined everywhere: a grid with spacing s <= sqrt 2 r / delta puts every point of the
     * cell within r / delta (2-D), hence within r (3-D), of a sample */
    bool covered = false;
    for (int m = 0; m < 4; ++m)
        if (defined[m] && d[m] < 0 && -d[m] >= enough) covered = true;
    if (all_neg && min_abs >= 0.5 * enough) covered = true;
    if (covered && fill_fits) {
        fill_cell(&pf, c, radius, src, counters, samples, cap_samples);
        return OUT_FILLED;
    }

    /* floor: the patch is smaller than the floor and still unresolved */
    if (sqrt(wx * wx + wy * wy + et * et) < floor_size) return OUT_UNRESOLVED;

    /* split along the longest edge */
    uint slot = atomic_add(&counters[SC_CELLS], 2u);
    /* the children's tape: pruned over this patch grown by the radius (so it stays valid over
     * every splat ball their samples get), written only if that drops a row */
    int child_first = c.tape_first, child_count = n;
    prune_region grown = patch_region(&pf, c, t_lo, t_hi, radius);
    if (n > 1 && tape_prune_shrinks(tape, n, qs, &grown, t.quadric, &w->evals)) {
        uint base = atomic_add(&counters[SC_ARENA], (uint)(n + 1));
        if (base + (uint)(n + 1) <= cap_arena) {
            int first, count;
            tape_prune(tape, n, qs, &grown, t.quadric, arena + base, &first, &count, &w->evals);
            child_first = (int)base + first;
            child_count = count;
            w->tapes_written = 1;
        }
    }
    if (slot + 1 >= cap_cells) return OUT_SPLIT;
    cell_rec a = c, b = c;
    a.level = b.level = c.level + 1;
    a.tape_first = b.tape_first = child_first;
    a.tape_count = b.tape_count = child_count;
    /* the two new corners, shared by both children, are evaluated here once (with the
     * parent's tape, valid over the whole patch) */
    real e0 = NAN, e1 = NAN, h;
    if (wx >= wy) {
        real mid = 0.5 * (c.x0 + c.x1);
        a.x1 = mid;
        b.x0 = mid;
        if (plane_height(&pf, mid, c.y0, &h)) e0 = query(tape, n, qs, t.quadric, plane_point(&pf, mid, c.y0, h), w);
        if (plane_height(&pf, mid, c.y1, &h)) e1 = query(tape, n, qs, t.quadric, plane_point(&pf, mid, c.y1, h), w);
        a.d[1] = e0; a.d[3] = e1; /* a = [x0, mid]: new right corners */
        b.d[0] = e0; b.d[2] = e1; /* b = [mid, x1]: new left corners */
        a.d[0] = d[0]; a.d[2] = d[2];
        b.d[1] = d[1]; b.d[3] = d[3];
    } else {
        real mid = 0.5 * (c.y0 + c.y1);
        a.y1 = mid;
        b.y0 = mid;
        if (plane_height(&pf, c.x0, mid, &h)) e0 = query(tape, n, qs, t.quadric, plane_point(&pf, c.x0, mid, h), w);
        if (plane_height(&pf, c.x1, mid, &h)) e1 = query(tape, n, qs, t.quadric, plane_point(&pf, c.x1, mid, h), w);
        a.d[2] = e0; a.d[3] = e1; /* a = [y0, mid]: new top corners */
        b.d[0] = e0; b.d[1] = e1; /* b = [mid, y1]: new bottom corners */
        a.d[0] = d[0]; a.d[1] = d[1];
        b.d[2] = d[2]; b.d[3] = d[3];
    }
    cells_out[slot] = a;
    cells_out[slot + 1] = b;
    return OUT_SPLIT;
}

__kernel void classify(__global const quadric_rec *qs, __global const frame_rec *frames,
                       __global const task_rec *tasks, __global const cell_rec *cells_in, int n_cells,
                       __global cell_rec *cells_out, uint cap_cells,
                       __global raw_sample_rec *samples, uint cap_samples,
                       __global tape_op *arena, uint cap_arena,
                       __global volatile uint *counters, real radius, real floor_size)
{
    int gid = get_global_id(0);
    if (gid >= n_cells) return;
    cell_work w = {0, 0, 0, 0};
    int out = classify_cell(cells_in[gid], qs, frames, tasks, cells_out, cap_cells, samples, cap_samples, arena,
                            cap_arena, counters, radius, floor_size, &w);
    int slot = out == OUT_DISCARDED || out == OUT_DECIDED_DISCARD ? SC_DISCARDED
             : out == OUT_FILLED || out == OUT_DECIDED_FILL ? SC_FILLED
             : out == OUT_SINGLE ? SC_SINGLE
             : out == OUT_SPLIT ? SC_SPLIT : SC_UNRESOLVED;
    atomic_inc(&counters[slot]);
    if (out == OUT_DECIDED_DISCARD || out == OUT_DECIDED_FILL) atomic_inc(&counters[SC_PRUNED_DECIDED]);
    if (w.queries) atomic_add(&counters[SC_DISTANCE_QUERIES], w.queries);
    if (w.leaves) atomic_add(&counters[SC_LEAF_DISTANCES], w.leaves);
    if (w.evals) atomic_add(&counters[SC_PRUNE_EVALUATIONS], w.evals);
    if (w.tapes_written) atomic_inc(&counters[SC_TAPES_WRITTEN]);
    atomic_add(&counters[SC_TAPE_ROWS], (uint)cells_in[gid].tape_count);
    atomic_max(&counters[SC_TAPE_MAX], (uint)cells_in[gid].tape_count);
}
