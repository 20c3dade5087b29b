/* Checks of plane_cases.h against the host (tests/test_plane_cases.py): which conics, given by
 * their six entries, plane_conic_semidefinite takes as positive (bit 0) and as negative (bit 1)
 * semidefinite; which plane_line_factor finds to be a line times a factor of one sign; the
 * impossible sign pairs of parallel planes and of nested conics; task_plane_factor's factors. */
#include "plane_cases.h"

/* a conic from its six (normalized) entries */
inline plane_conic check_conic(__global const real *entries)
{
    plane_conic c;
    for (int e = 0; e < 6; ++e) c.m[e] = entries[e];
    c.scale = 1;
    return c;
}

__kernel void semidefinite(__global const real *entries, int n, __global int *out)
{
    int i = get_global_id(0);
    if (i >= n) return;
    plane_conic c = check_conic(entries + 6 * i);
    out[i] = (plane_conic_semidefinite(&c, 1) ? 1 : 0) | (plane_conic_semidefinite(&c, -1) ? 2 : 0);
}

/* plane_line_factor of conic i (six entries) by line i (a linear conic: entries 3-5 used) over
 * rectangle i (x0, x1, y0, y1): +1, -1 or 0 */
__kernel void line_factor(__global const real *conics, __global const real *lines, __global const real *rects, int n,
                          __global int *out)
{
    int i = get_global_id(0);
    if (i >= n) return;
    plane_conic c = check_conic(conics + 6 * i), l = check_conic(lines + 6 * i);
    out[i] = plane_line_factor(&c, &l, rects[4 * i], rects[4 * i + 1], rects[4 * i + 2], rects[4 * i + 3]);
}

inline quadric check_quadric(__global const real *c)
{
    quadric q = {c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7], c[8], c[9]};
    return q;
}

/* parallel_planes_impossible of planes a[i], b[i] (10 coefficients each) as live quadrics 0, 1 */
__kernel void parallel(__global const real *a, __global const real *b, int n, __global uint *out)
{
    int i = get_global_id(0);
    if (i >= n) return;
    out[i] = parallel_planes_impossible(check_quadric(a + 10 * i), check_quadric(b + 10 * i), 0, 1);
}

/* task_plane_factor of task quadric s[i], plane p[i], quadric q[i] over box i (center, three
 * half-axes: 12 values) */
__kernel void plane_factor(__global const real *s, __global const real *p, __global const real *q,
                           __global const real *box, int n, __global int *out)
{
    int i = get_global_id(0);
    if (i >= n) return;
    __global const real *b = box + 12 * i;
    prune_region g;
    g.c = (real3)(b[0], b[1], b[2]);
    g.a0 = (real3)(b[3], b[4], b[5]);
    g.a1 = (real3)(b[6], b[7], b[8]);
    g.a2 = (real3)(b[9], b[10], b[11]);
    g.rho = 0;
    g.on_patch = 0;
    out[i] = task_plane_factor(check_quadric(s + 10 * i), check_quadric(p + 10 * i), check_quadric(q + 10 * i), &g);
}

/* plane_conics_nested of conics a[i], b[i] (six entries each, normalized) as live quadrics 0, 1 */
__kernel void nested(__global const real *a, __global const real *b, int n, __global uint *out)
{
    int i = get_global_id(0);
    if (i >= n) return;
    plane_conic ca = check_conic(a + 6 * i), cb = check_conic(b + 6 * i);
    out[i] = plane_conics_nested(&ca, &cb, 0, 1);
}
