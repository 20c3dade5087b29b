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

/* region i: 13 reals (center, three half-axes, rho); output rows [i * (n + 1), (i + 1) * (n + 1)) */
__kernel void prune(__global const quadric_rec *qs, __global const tape_op *tape, int n, int self_q,
                    __global const real *regions, int m, __global tape_op *out, __global int *res)
{
    int i = get_global_id(0);
    if (i >= m) return;
    __global const real *r = regions + 13 * i;
    prune_region g = {(real3)(r[0], r[1], r[2]), (real3)(r[3], r[4], r[5]), (real3)(r[6], r[7], r[8]),
                      (real3)(r[9], r[10], r[11]), r[12]};
    uint evals = 0;
    int first, count;
    int decided_only = tape_prune(tape, n, qs, &g, self_q, 0, &first, &count, &evals);
    int decided = tape_prune(tape, n, qs, &g, self_q, out + i * (n + 1), &first, &count, &evals);
    res[4 * i] = decided;
    res[4 * i + 1] = first;
    res[4 * i + 2] = count;
    res[4 * i + 3] = decided_only == decided;
}
