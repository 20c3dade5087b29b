/* Reads every field of the packed scene buffers into flat arrays, so a test can check that
 * the kernels see exactly what the host packed (clcsg/host/buffers.py). */
#include "layout.h"

__kernel void read_quadrics(__global const quadric_rec *q, __global real *coef_out,
                            __global real *lam_out, __global float *color_out)
{
    int i = get_global_id(0);
    for (int k = 0; k < 10; ++k) coef_out[10 * i + k] = q[i].coef[k];
    lam_out[2 * i] = q[i].lam_min;
    lam_out[2 * i + 1] = q[i].lam_max;
    for (int k = 0; k < 4; ++k) color_out[4 * i + k] = q[i].color[k];
}

__kernel void read_literals(__global const literal_rec *l, __global int *out)
{
    int i = get_global_id(0);
    out[2 * i] = l[i].quadric;
    out[2 * i + 1] = l[i].sign;
}

__kernel void read_terms(__global const term_rec *t, __global int *ranges, __global real *bounds)
{
    int i = get_global_id(0);
    ranges[2 * i] = t[i].first;
    ranges[2 * i + 1] = t[i].count;
    for (int k = 0; k < 3; ++k) {
        bounds[6 * i + k] = t[i].lo[k];
        bounds[6 * i + 3 + k] = t[i].hi[k];
    }
}
