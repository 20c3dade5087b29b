/* Runs the tape.h interpreters and pruning on given points and regions, so tests can compare
 * them with the float64 reference in clcsg/compile/interpret.py. */
#include "tape.h"

__kernel void eval(__global const quadric_rec *qs, __global const tape_op *tape, int n, int self_q,
                   __global const real *pts, int m, __global real *f, __global uint *bits)
{
    int i = get_global_id(0);
    if (i >= m) return;
    real3 p = (real3)(pts[3 * i], pts[3 * i + 1], pts[3 * i + 2]);
    uint leaves = 0;
    real2 v = tape_eval(tape, n, qs, p, self_q, &leaves);
    f[2 * i] = v.x;
    f[2 * i + 1] = v.y;
    bits[i] = tape_member(tape, n, qs, p, self_q);
}

/* region i: 13 reals (center, three half-axes, rho) */
inline prune_region check_region(__global const real *regions, int i)
{
    __global const real *r = regions + 13 * i;
    prune_region g = {(real3)(r[0], r[1], r[2]), (real3)(r[3], r[4], r[5]), (real3)(r[6], r[7], r[8]),
                      (real3)(r[9], r[10], r[11]), r[12]};
    return g;
}

/* output rows [i * (n + 1), (i + 1) * (n + 1)) for region i (check_region) */
__kernel void prune(__global const quadric_rec *qs, __global const tape_op *tape, int n, int self_q,
                    __global const real *regions, int m, __global tape_op *out, __global int *res)
{
    int i = get_global_id(0);
    if (i >= m) return;
    prune_region g = check_region(regions, i);
    uint evals = 0;
    int first, count;
    int decided_only = tape_prune(tape, n, qs, &g, self_q, 0, &first, &count, &evals);
    int decided = tape_prune(tape, n, qs, &g, self_q, out + i * (n + 1), &first, &count, &evals);
    res[4 * i] = decided;
    res[4 * i + 1] = first;
    res[4 * i + 2] = count;
    res[4 * i + 3] = decided_only == decided;
}

/* The two ways the sampler stores a pruned tape, per region i: written by tape_write_pruned
 * after a count pass (into out rows [i * (n + 1), (i + 1) * (n + 1))), and built in private
 * memory by tape_pruned_private from the count pass's record.  res[i]: 1 if they are the same
 * rows, 0 if not, -1 if the tape is too long to build (more than 64 rows kept). */
__kernel void prune_private(__global const quadric_rec *qs, __global const tape_op *tape, int n, int self_q,
                            __global const real *regions, int m, __global tape_op *out, __global int *res)
{
    int i = get_global_id(0);
    if (i >= m) return;
    prune_region g = check_region(regions, i);
    uint evals = 0;
    uchar state;
    prune_memo memo;
    memo.mode = 3;
    int rows = tape_prune_rows_memo(tape, n, qs, &g, self_q, &state, &evals, &memo);
    if (rows > 64 || n > PRUNE_MEMO_ROWS) {
        res[i] = -1;
        return;
    }
    tape_op buf[64];
    int pf, pc, wf, wc;
    tape_pruned_private(tape, n, rows, state, &memo, buf, &pf, &pc);
    tape_write_pruned(tape, n, rows, qs, &g, self_q, state, out + i * (n + 1), &wf, &wc, &evals, &memo);
    int same = pc == wc;
    for (int k = 0; k < pc && same; ++k) {
        tape_op a = buf[pf + k], b = out[i * (n + 1) + wf + k];
        same = a.op == b.op && a.out == b.out && a.a == b.a && a.b == b.b;
    }
    res[i] = same;
}
