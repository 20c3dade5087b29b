/* Checks of plane_cases.h against the host (tests/test_plane_cases.py): which conics, given by
 * their six entries, plane_conic_semidefinite takes as positive (bit 0) and as negative (bit 1)
 * semidefinite; which plane_line_factor finds to be a line times a factor of one sign. */
#include "plane_cases.h"

__kernel void semidefinite(__global const real *entries, int n, __global int *out)
{
    int i = get_global_id(0);
    if (i >= n) return;
    plane_conic c;
    for (int e = 0; e < 6; ++e) c.m[e] = entries[6 * i + e];
    out[i] = (plane_conic_semidefinite(&c, 1) ? 1 : 0) | (plane_conic_semidefinite(&c, -1) ? 2 : 0);
}

/* plane_line_factor of conic i (six entries) by line i (a linear conic: entries 3-5 used) over
 * rectangle i (x0, x1, y0, y1): +1, -1 or 0 */
__kernel void line_factor(__global const real *conics, __global const real *lines, __global const real *rects, int n,
                          __global int *out)
{
    int i = get_global_id(0);
    if (i >= n) return;
    plane_conic c, l;
    for (int e = 0; e < 6; ++e) {
        c.m[e] = conics[6 * i + e];
        l.m[e] = lines[6 * i + e];
    }
    out[i] = plane_line_factor(&c, &l, rects[4 * i], rects[4 * i + 1], rects[4 * i + 2], rects[4 * i + 3]);
}
