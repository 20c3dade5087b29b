/* Covering a patch that lies on the CSG surface with samples (paper section 4.2's fill with
 * an anisotropic slope bound in place of the isotropic sqrt 3 distortion bound).
 *
 * Build options: FILL_DELTA_RATIO (a block is split while its distortion bounds differ by
 * more than this factor).
 */
#ifndef CLCSG_FILL_H
#define CLCSG_FILL_H
#include "heightfield.h"

#ifndef FILL_DELTA_RATIO
#define FILL_DELTA_RATIO 1.1
#endif

/* where a sample comes from: its task and the tape of its cell (valid over every splat ball
 * of radius <= r around the cell's patch) */
typedef struct {
    int task, tape_first, tape_count;
} sample_src;

inline void emit_sample(__global raw_sample_rec *out, uint slot, uint cap, real3 p, real radius, sample_src src)
{
    if (slot >= cap) return;
    out[slot].pos[0] = p.x;
    out[slot].pos[1] = p.y;
    out[slot].pos[2] = p.z;
    out[slot].radius = radius;
    out[slot].task = src.task;
    out[slot].tape_first = src.tape_first;
    out[slot].tape_count = src.tape_count;
    out[slot].pad = 0;
}

/* cos and sin of k pi / 32, k = 1..15: the aspect angles fill_block tries (a table, not
 * cos / sin per row: rows are many and short near trimming curves) */
__constant real FILL_COS[15] = {0.9951847266721969, 0.9807852804032304, 0.9569403357322088, 0.9238795325112867, 0.881921264348355, 0.8314696123025452, 0.773010453362737, 0.7071067811865476, 0.6343932841636455, 0.5555702330196023, 0.4713967368259978, 0.38268343236508984, 0.29028467725446233, 0.19509032201612833, 0.09801714032956077};
__constant real FILL_SIN[15] = {0.0980171403295606, 0.19509032201612825, 0.29028467725446233, 0.3826834323650898, 0.47139673682599764, 0.5555702330196022, 0.6343932841636455, 0.7071067811865475, 0.773010453362737, 0.8314696123025452, 0.8819212643483549, 0.9238795325112867, 0.9569403357322089, 0.9807852804032304, 0.9951847266721968};

/* Cover a block [x0,x1] x [y0,y1] known to lie on the CSG surface with samples at the
 * centers of sub-rectangles of half-sizes (a, b).  Anisotropic bound (beyond the paper's
 * isotropic distortion): for two points of a sub-rectangle, p2 - p1 = (dx, dy, t2 - t1) and
 * by the mean value theorem |t2 - t1| <= mx |dx| + my |dy| with mx, my the slope bounds over
 * the sub-rectangle, so every point is within sqrt(a^2 + b^2 + (mx a + my b)^2) <= r of the
 * center.  On a steep patch only the steep direction shrinks.  Rows are marched in y, each
 * with the slopes over the whole row (shrinking a rectangle never raises them); (a, b)
 * maximize the area a b on the constraint.  Sub-rectangles that plane k owns nowhere are
 * left to the other planes; a row owned everywhere reserves its output with one atomic. */
void fill_block(const plane_frame *pf, real x0, real x1, real y0, real y1, real radius, sample_src src,
                __global volatile uint *counters, __global raw_sample_rec *samples, uint cap_samples)
{
    real2 ni = abs_linear_range(pf->li, pf->bi, x0, x1);
    real2 nj = abs_linear_range(pf->lj, pf->bj, y0, y1);
    real y = y0;
    real hy = y1 - y0;
    while (y < y1) {
        hy = fmin(y1 - y, 2 * hy);
        real3 m = rect_slopes(pf, x0, x1, y, y + hy);
        /* best aspect for these slopes: a few angles suffice (the area is flat at its max).
         * The area rho^2 cs sn with rho = r / sqrt(1 + e^2) is compared as the fraction
         * cs sn / (1 + e^2), crosswise: no square root or division per angle (they were
         * most of this function's time on rows near trimming curves, which are many) */
        real best_num = 0, best_den = 1, best_sn = 0;
        for (int k = 0; k < 15; ++k) {
            real cs = FILL_COS[k], sn = FILL_SIN[k];
            real e = m.x * cs + m.y * sn;
            real num = cs * sn, den = 1 + e * e;
            if (num * best_den > best_num * den) {
                best_num = num;
                best_den = den;
                best_sn = sn;
            }
        }
        real best_b = radius / sqrt(best_den) * best_sn;
        if (hy > 2 * best_b) {
            hy = 2 * best_b;
            m = rect_slopes(pf, x0, x1, y, y + hy);
        }
        real yb = y + hy >= y1 ? y1 : y + hy;
        real sx = 2 * half_width(m.x, m.y, 0.5 * hy, radius);
        sx = fmax(sx, (real)1e-12 * radius);
        int nx = max(1, (int)ceil((x1 - x0) / sx));
        sx = (x1 - x0) / nx;
        real cy = 0.5 * (y + yb);
        /* the radius this row's samples need (paper 6.1: smaller splats, less overdraw) */
        real ha = 0.5 * sx, hb = 0.5 * (yb - y), e = m.x * ha + m.y * hb;
        real need = fmin(radius, sqrt(ha * ha + hb * hb + e * e) * (1 + (real)1e-6));
        if (ni.y <= m.z && nj.y <= m.z) { /* owned everywhere */
            uint base = atomic_add(&counters[SC_SAMPLES], (uint)nx);
            for (int a = 0; a < nx; ++a) {
                real cx = x0 + (a + (real)0.5) * sx;
                emit_sample(samples, base + a, cap_samples,
                            plane_point(pf, cx, cy, plane_height_clamped(pf, cx, cy)), need, src);
            }
        } else {
            for (int a = 0; a < nx; ++a) {
                real xa = x0 + a * sx;
                if (!sub_rect_owned(pf, xa, xa + sx, y, yb)) continue;
                real cx = xa + (real)0.5 * sx;
                uint slot = atomic_inc(&counters[SC_SAMPLES]);
                emit_sample(samples, slot, cap_samples,
                            plane_point(pf, cx, cy, plane_height_clamped(pf, cx, cy)), need, src);
            }
        }
        y = yb;
    }
}

/* Cover a cell that lies on the CSG surface: split it (no distance queries needed) into
 * blocks over which the distortion varies little, and fill each block. */
void fill_cell(const plane_frame *pf, cell_rec c, real radius, sample_src src, __global volatile uint *counters,
               __global raw_sample_rec *samples, uint cap_samples)
{
    real4 stack[40];
    int top = 0;
    stack[top++] = (real4)(c.x0, c.x1, c.y0, c.y1);
    while (top > 0) {
        real4 b = stack[--top];
        bool owned;
        real2 dl = rect_distortion(pf, b.x, b.y, b.z, b.w, &owned);
        if (!owned) continue;
        real wx = b.y - b.x, wy = b.w - b.z;
        real s = sqrt((real)2) * radius / dl.x;
        if (top + 2 <= 40 && wx * wy > 16 * s * s && dl.x > FILL_DELTA_RATIO * dl.y) {
            if (wx >= wy) {
                real mid = 0.5 * (b.x + b.y);
                stack[top++] = (real4)(b.x, mid, b.z, b.w);
                stack[top++] = (real4)(mid, b.y, b.z, b.w);
            } else {
                real mid = 0.5 * (b.z + b.w);
                stack[top++] = (real4)(b.x, b.y, b.z, mid);
                stack[top++] = (real4)(b.x, b.y, mid, b.w);
            }
            continue;
        }
        fill_block(pf, b.x, b.y, b.z, b.w, radius, src, counters, samples, cap_samples);
    }
}

#endif
