/* Covering a patch that lies on the CSG surface with samples (paper section 4.2's fill with
 * an anisotropic slope bound in place of the isotropic sqrt 3 distortion bound).
 *
 * Build options: FILL_DELTA_RATIO (a block is split while its distortion bounds differ by
 * more than this factor).  1.4, not 1.1: every block rounds its rows and columns up, and on
 * the curved zoo models the smaller blocks of 1.1 cost more samples than their tighter slopes
 * saved (lens 18,416 -> 17,382 samples, Steinmetz 21,517 -> 20,870; the rows get longer, so
 * the lens's calls take about a tenth less).
 */
#ifndef CLCSG_FILL_H
#define CLCSG_FILL_H
#include "heightfield.h"
#include "finish.h"

#ifndef FILL_DELTA_RATIO
#define FILL_DELTA_RATIO 1.4
#endif

/* The local box [x0,x1] x [y0,y1] x [t_lo,t_hi] of a plane, grown by `grow`, as a prune region. */
inline prune_region box_region(const plane_frame *pf, real x0, real x1, real y0, real y1, real t_lo, real t_hi,
                               real grow)
{
    prune_region g;
    g.c = plane_point(pf, 0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.5 * (t_lo + t_hi));
    g.a0 = (real)(0.5 * (x1 - x0)) * plane_axis(pf, pf->i);
    g.a1 = (real)(0.5 * (y1 - y0)) * plane_axis(pf, pf->j);
    g.a2 = (real)(0.5 * (t_hi - t_lo)) * plane_axis(pf, pf->k);
    g.rho = grow;
    g.on_patch = 0;
    return g;
}

/* samples a row of a fill decides at once: the cell's tape is pruned over the box of up to
 * this many of them grown by their splat radius (which holds all their balls); a chunk of two
 * or more samples whose sides this pruning decides is emitted in the eight lanes of emit_row8 */
#define FILL_CHUNK 8
#if FILL_CHUNK > 8
#error "FILL_CHUNK: a chunk is emitted in at most eight lanes"
#endif

/* Positions of a row's samples at x = x0 + (a + 1/2) sx, a = a0..a0+n-1 (n <= 8), and y
 * (plane_point of plane_height_clamped in lanes), then emit_known8; false: nothing written. */
inline bool emit_row8(const plane_frame *pf, sample_sink *out, uint slot, int n, real x0, int a0, real sx, real y,
                      real need, sample_src src)
{
    real8 x = x0 + (convert_real8((int8)(a0) + (int8)(0, 1, 2, 3, 4, 5, 6, 7)) + (real)0.5) * sx;
    real8 R = pf->li * x * x + 2 * pf->bi * x + (pf->lj * y * y + 2 * pf->bj * y + pf->gamma);
    real8 t = pf->lk != 0 ? pf->sheet * sqrt(fmax(R * pf->ik, (real8)0)) : R * pf->ik;
    real8 yv = (real8)(y);
    real8 z0 = pf->k == 0 ? t : x, z1 = pf->k == 0 ? x : pf->k == 1 ? t : yv, z2 = pf->k == 2 ? t : yv;
    return emit_known8(out, slot, n, pf->center.x + (pf->U[0] * z0 + pf->U[1] * z1 + pf->U[2] * z2),
                       pf->center.y + (pf->U[3] * z0 + pf->U[4] * z1 + pf->U[5] * z2),
                       pf->center.z + (pf->U[6] * z0 + pf->U[7] * z1 + pf->U[8] * z2), need, src);
}

/* The source of a row's samples in [xa, xb] x [y, yb] with splat radius `need`: with their
 * sides where the tape is decided over the chunk's box grown by `need`, so that none of them
 * prunes alone (a large filled cell is rarely decided as a whole, its chunks mostly are). */
inline sample_src chunk_source(const plane_frame *pf, real xa, real xb, real y, real yb, real need, sample_src src,
                               sample_sink *out)
{
    if (src.sides & SIDES_KNOWN) return src;
    real2 Px = quad_range(pf->li, pf->bi, pf->vi, pf->fvi, xa, xb);
    real2 Sy = quad_range(pf->lj, pf->bj, pf->vj, pf->fvj, y, yb);
    real2 t;
    bool whole;
    if (!rect_heights(pf, (real2)(Px.x + Sy.x + pf->gamma, Px.y + Sy.y + pf->gamma), &t, &whole)) return src;
    prune_region g = box_region(pf, xa, xb, y, yb, t.x, t.y, need);
    uchar state;
    tape_prune_rows(src.tape, src.tape_count, out->qs, &g, src.quadric, &state, &out->evals);
    if (prune_decision(state) < 0) src.sides = SIDES_KNOWN | (int)prune_member_bits(state);
    return src;
}

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
                sample_sink *out)
{
    real2 ni = abs_linear_range(pf->li, pf->bi, x0, x1);
    real2 nj = abs_linear_range(pf->lj, pf->bj, y0, y1);
    real2 Px = quad_range(pf->li, pf->bi, pf->vi, pf->fvi, x0, x1); /* the rows' own x range */
    real y = y0;
    real hy = y1 - y0;
    while (y < y1) {
        hy = fmin(y1 - y, 2 * hy);
        real3 m = row_slopes(pf, Px, ni, y, y + hy);
        /* the best aspect for these slopes: with t = tan(angle) the area rho^2 cs sn,
         * rho = r / sqrt(1 + e^2), e = mx cs + my sn, is r^2 t / (A + 2 mx my t + C t^2) with
         * A = 1 + mx^2, C = 1 + my^2, whose maximum is at A = C t^2: cs = sqrt(C / (A + C)),
         * sn = sqrt(A / (A + C)) */
        real A = 1 + m.x * m.x, C = 1 + m.y * m.y;
        real cs = sqrt(C / (A + C)), sn = sqrt(A / (A + C));
        real e_best = m.x * cs + m.y * sn;
        real best_b = fmax(radius * sn / sqrt(1 + e_best * e_best), (real)0);
        if (hy > 2 * best_b) {
            hy = 2 * best_b;
            m = row_slopes(pf, Px, ni, y, y + hy);
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
            uint base = sink_slots(out, (uint)nx);
            for (int a0 = 0; a0 < nx; a0 += FILL_CHUNK) {
                int a1 = min(nx, a0 + FILL_CHUNK);
                sample_src chunk = a1 - a0 > 1 ? chunk_source(pf, x0 + a0 * sx, x0 + a1 * sx, y, yb, need, src, out)
                                               : src;
                if (a1 - a0 > 1 && (chunk.sides & SIDES_KNOWN) && base + a1 <= out->cap
                    && emit_row8(pf, out, base + a0, a1 - a0, x0, a0, sx, cy, need, chunk))
                    continue;
                for (int a = a0; a < a1; ++a) {
                    real cx = x0 + (a + (real)0.5) * sx;
                    emit_sample(out, base + a, plane_point(pf, cx, cy, plane_height_clamped(pf, cx, cy)), need, chunk);
                }
            }
        } else {
            for (int a = 0; a < nx; ++a) {
                real xa = x0 + a * sx;
                if (!sub_rect_owned(pf, xa, xa + sx, y, yb)) continue;
                real cx = xa + (real)0.5 * sx;
                emit_sample(out, sink_slots(out, 1),
                            plane_point(pf, cx, cy, plane_height_clamped(pf, cx, cy)), need, src);
            }
        }
        y = yb;
    }
}

/* Cover a cell that lies on the CSG surface: split it (no distance queries needed) into
 * blocks over which the distortion varies little, and fill each block. */
void fill_cell(const plane_frame *pf, cell_rec c, real radius, sample_src src, sample_sink *out)
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
        fill_block(pf, b.x, b.y, b.z, b.w, radius, src, out);
    }
}

#endif
