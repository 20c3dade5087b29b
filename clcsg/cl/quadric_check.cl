/* Evaluates the quadric.h functions at given points so tests can compare them with the
 * float64 reference in clcsg/quadric.py (and bench/ can time them). */
#include "quadric.h"

__kernel void eval(__global const quadric_rec *qs, int qi, __global const real *pts,
                   __global const real *dirs, int n, __global real *value, __global real *grad,
                   __global real *dist, __global real *roots)
{
    int i = get_global_id(0);
    if (i >= n) return;
    quadric q = quadric_load(qs, qi);
    real3 p = (real3)(pts[3 * i], pts[3 * i + 1], pts[3 * i + 2]);
    real3 v = (real3)(dirs[3 * i], dirs[3 * i + 1], dirs[3 * i + 2]);
    value[i] = quadric_value(q, p);
    real3 g = quadric_gradient(q, p);
    grad[3 * i] = g.x;
    grad[3 * i + 1] = g.y;
    grad[3 * i + 2] = g.z;
    dist[i] = quadric_distance(q, qs[qi].lam_min, qs[qi].lam_max, p);
    real t1 = NAN, t2 = NAN;
    int k = quadric_intersect(q, p, v, &t1, &t2);
    roots[2 * i] = k > 0 ? t1 : NAN;
    roots[2 * i + 1] = k > 1 ? t2 : NAN;
}

/* at_least[i] = quadric_distance_at_least(q, p_i, R_i) and dist[i] = quadric_distance(q, p_i):
 * the comparison without the quotient against the quotient */
__kernel void distance_at_least(__global const quadric_rec *qs, int qi, __global const real *pts,
                                __global const real *reach, int n, __global real *dist, __global int *at_least)
{
    int i = get_global_id(0);
    if (i >= n) return;
    quadric q = quadric_load(qs, qi);
    real3 p = (real3)(pts[3 * i], pts[3 * i + 1], pts[3 * i + 2]);
    real f;
    dist[i] = quadric_distance(q, qs[qi].lam_min, qs[qi].lam_max, p);
    at_least[i] = quadric_distance_at_least(q, qs[qi].lam_min, qs[qi].lam_max, p, reach[i], &f);
}
