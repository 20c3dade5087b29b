/* Point queries on the root tape (clcsg/queries/queries.py drives them; the interpreters are
 * cl/include/tape.h).  Points are in device coordinates (world - origin), three reals each. */
#include "tape.h"

/* query_inside: out[i] = 1 iff point i is in the closed solid: the tape's membership
 * (Q = 0 counts as inside), with no quadric substituted. */
__kernel void query_inside(__global const quadric_rec *qs, __global const tape_op *tape, int n,
                           __global const real *pts, int m, __global uchar *out)
{
    int i = get_global_id(0);
    if (i >= m) return;
    real3 p = (real3)(pts[3 * i], pts[3 * i + 1], pts[3 * i + 2]);
    out[i] = tape_member(tape, n, qs, p, -1) & 1;
}

/* query_distance: out[i] = the tape over reals at point i: leaves are the conservative
 * signed distances of their literals, AND = max, OR = min, so the result is negative inside,
 * positive outside, and its absolute value is at most the distance to the surface. */
__kernel void query_distance(__global const quadric_rec *qs, __global const tape_op *tape, int n,
                             __global const real *pts, int m, __global real *out)
{
    int i = get_global_id(0);
    if (i >= m) return;
    real3 p = (real3)(pts[3 * i], pts[3 * i + 1], pts[3 * i + 2]);
    uint leaves = 0;
    out[i] = tape_eval(tape, n, qs, p, -1, &leaves).x;
}
