/* The sampler's distance query on the CSG tape, timed at points on the quadrics of a real scene
 * (python -m bench micro): d_q(p) = surface_distance(tape_eval(tape, p, q)), exactly what
 * query() in clcsg/sampling/sampler.cl computes per cell corner.
 *
 * Build options: programs.build_options({"TAPE_REGS": tape.n_regs}, real) (precision, the op
 * codes and the tape's register count), include dirs cl/include and sampling.
 *
 * prune_points: per point i, the root tape pruned over the ball (p_i, rho) with the point's
 *   quadric substituted (tape_prune, as the sampler prunes a cell's tape for its children),
 *   written at arena + i (n + 1); first[i] / count[i] locate the result, evals[i] counts the
 *   leaves tested.
 * op_tape_query: K queries per work-item on point gid % m with the tape (first, count) of that
 *   point, nudged by k 1e-9 so the query cannot be hoisted out of the loop; the sum of the
 *   finite results is the only real store, leaves[gid] the leaf distances evaluated. */
#include "tape.h"

__kernel void prune_points(__global const quadric_rec *qs, __global const tape_op *tape, int n,
                           __global const real *pts, __global const int *self_q, int m, real rho,
                           __global tape_op *arena, __global int *first, __global int *count,
                           __global uint *evals)
{
    int i = get_global_id(0);
    if (i >= m) return;
    prune_region g;
    g.c = (real3)(pts[3 * i], pts[3 * i + 1], pts[3 * i + 2]);
    g.a0 = (real3)(0, 0, 0);
    g.a1 = (real3)(0, 0, 0);
    g.a2 = (real3)(0, 0, 0);
    g.rho = rho;
    int f = 0, c = 0;
    uint e = 0;
    tape_prune(tape, n, qs, &g, self_q[i], arena + (size_t)i * (size_t)(n + 1), &f, &c, &e);
    first[i] = i * (n + 1) + f;
    count[i] = c;
    evals[i] = e;
}

__kernel void op_tape_query(__global const quadric_rec *qs, __global const tape_op *tapes,
                            __global const int *first, __global const int *count,
                            __global const real *pts, __global const int *self_q, int m, int K,
                            __global real *out, __global uint *leaves)
{
    int gid = get_global_id(0);
    int i = gid % m;
    __global const tape_op *t = tapes + first[i];
    int n = count[i];
    int q = self_q[i];
    real3 p = (real3)(pts[3 * i], pts[3 * i + 1], pts[3 * i + 2]);
    real acc = 0;
    uint lv = 0;
    /* a trip count that depends on the id (it is K): PoCL keeps the loop per work-item */
    int kmax = K + (int)(gid >> 30);
    for (int k = 0; k < kmax; ++k) {
        real v = surface_distance(tape_eval(t, n, qs, p + (real)k * (real)1e-9, q, &lv));
        acc += isfinite(v) ? v : 0;
    }
    out[gid] = acc;
    leaves[gid] = lv;
}
