/* The sampler's distance query (eq. 22, csg_distance in clcsg/kernels/sampler.cl) timed at
 * sample positions of a real scene (python -m bench micro): K iterations per work-item on point
 * gid % n, nudged by k * 1e-9 so the query cannot be hoisted.
 *
 * csg_distance's signature follows the sampler: QUERY_API=1 is (quadrics, literals, terms,
 * n_terms, task, p, enough); QUERY_API=2 adds the per-task term lists (quadrics, literals,
 * terms, task_terms, task, p, enough).  bench/micro.py picks it from the source. */
#include "sampler.cl"

__kernel void op_csg_distance(__global const quadric_rec *qs, __global const literal_rec *lits,
                              __global const term_rec *terms, int n_terms,
                              __global const int *task_terms, __global const task_rec *tasks,
                              __global const real *pts, int n, int K, real enough,
                              __global real *out)
{
    int gid = get_global_id(0);
    int i = gid % n;
    task_rec t = tasks[i];
    real3 p = (real3)(pts[3 * i], pts[3 * i + 1], pts[3 * i + 2]);
    real acc = 0;
    int kmax = K + (int)(gid >> 30);
    for (int k = 0; k < kmax; ++k) {
#if QUERY_API == 2
        real v = csg_distance(qs, lits, terms, task_terms, t, p + (real)(k * 1e-9), enough);
#else
        real v = csg_distance(qs, lits, terms, n_terms, t, p + (real)(k * 1e-9), enough);
#endif
        acc += isfinite(v) ? v : 0;
    }
    out[gid] = acc;
}
