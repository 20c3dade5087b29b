/* Checks of plane_cases.h against the host (tests/test_plane_cases.py): which conics, given by
 * their six entries, plane_conic_semidefinite takes as positive (bit 0) and as negative (bit 1)
 * semidefinite. */
#include "plane_cases.h"

__kernel void semidefinite(__global const real *entries, int n, __global int *out)
{
    int i = get_global_id(0);
    if (i >= n) return;
    plane_conic c;
    for (int e = 0; e < 6; ++e) c.m[e] = entries[6 * i + e];
    out[i] = (plane_conic_semidefinite(&c, 1) ? 1 : 0) | (plane_conic_semidefinite(&c, -1) ? 2 : 0);
}
