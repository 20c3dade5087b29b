/* Heightfields of a quadric's sampling planes and exact interval bounds over rectangles
 * (paper sections 3.2 and 3.4 with the degenerate cases; the host side is
 * clcsg/compile/frames.py).  A frame_rec gives x = center + U z and
 * Q = sum_m (lam_m z_m^2 + 2 beta_m z_m) + gamma; plane k has in-plane coordinates
 * (x, y) = (z_i, z_j) and height t = z_k:
 *     lam_k t^2 + 2 beta_k t + R(x, y) = 0,   R = lam_i x^2 + 2 beta_i x + lam_j y^2 + 2 beta_j y + gamma
 * two sheets t = +-sqrt(-R / lam_k) if lam_k != 0, one sheet t = -R / (2 beta_k) otherwise.
 *
 * Build option WORST_CASE_DISTORTION=1 replaces the interval distortion bound by
 * max(sqrt 3, bound) (the paper's isotropic bound, for its Fig. 14 comparison).
 */
#ifndef CLCSG_HEIGHTFIELD_H
#define CLCSG_HEIGHTFIELD_H
#include "layout.h"

#ifndef WORST_CASE_DISTORTION
#define WORST_CASE_DISTORTION 0
#endif

/* exact range of lam z^2 + 2 beta z over [a, b], whose extremum (lam != 0) is fv at z = v */
CLCSG_INLINE real2 quad_range(real lam, real beta, real v, real fv, real a, real b)
{
    real fa = lam * a * a + 2 * beta * a;
    real fb = lam * b * b + 2 * beta * b;
    real lo = fmin(fa, fb), hi = fmax(fa, fb);
    if (lam != 0 && v > a && v < b) {
        lo = fmin(lo, fv);
        hi = fmax(hi, fv);
    }
    return (real2)(lo, hi);
}

/* range of |lam z + beta| over [a, b] */
CLCSG_INLINE real2 abs_linear_range(real lam, real beta, real a, real b)
{
    real fa = lam * a + beta, fb = lam * b + beta;
    real hi = fmax(fabs(fa), fabs(fb));
    real lo = (fa <= 0 && fb >= 0) || (fa >= 0 && fb <= 0) ? 0 : fmin(fabs(fa), fabs(fb));
    return (real2)(lo, hi);
}

/* A quadric's frame as plane k sees it: ik the height factor of axis k (t^2 = R ik on two
 * sheets, t = R ik on one), (vi, fvi) and (vj, fvj) the vertices of axes i and j (frame_rec). */
typedef struct {
    real U[9];
    real3 center;
    real li, lj, lk, bi, bj, bk, gamma;
    real ik, vi, fvi, vj, fvj;
    int i, j, k;
    int sheet;
} plane_frame;

/* Fill *pf in place (returned by value, the copy into cell_geom's frame made the compiler store
 * it in 8-byte pieces and read them back 32 bytes at a time: a stalled store forwarding per cell) */
CLCSG_INLINE void plane_load(plane_frame *pf, __global const frame_rec *f, int k, int sheet)
{
    for (int m = 0; m < 9; ++m) pf->U[m] = f->U[m];
    pf->center = (real3)(f->center[0], f->center[1], f->center[2]);
    pf->k = k;
    pf->i = k == 0 ? 1 : 0;
    pf->j = k == 2 ? 1 : 2;
    pf->li = f->lam[pf->i];
    pf->lj = f->lam[pf->j];
    pf->lk = f->lam[pf->k];
    pf->bi = f->beta[pf->i];
    pf->bj = f->beta[pf->j];
    pf->bk = f->beta[pf->k];
    pf->gamma = f->gamma;
    pf->ik = f->height_factor[pf->k];
    pf->vi = f->vertex[pf->i];
    pf->fvi = f->vertex_value[pf->i];
    pf->vj = f->vertex[pf->j];
    pf->fvj = f->vertex_value[pf->j];
    pf->sheet = sheet;
}

/* R(x, y) = lam_i x^2 + 2 beta_i x + lam_j y^2 + 2 beta_j y + gamma */
CLCSG_INLINE real plane_R(const plane_frame *pf, real x, real y)
{
    return pf->li * x * x + 2 * pf->bi * x + pf->lj * y * y + 2 * pf->bj * y + pf->gamma;
}

/* Height t of the heightfield at (x, y); false where it is undefined. */
CLCSG_INLINE bool plane_height(const plane_frame *pf, real x, real y, real *t)
{
    real R = plane_R(pf, x, y);
    if (pf->lk != 0) {
        real H = R * pf->ik;
        if (H < 0) return false;
        *t = pf->sheet * sqrt(H);
    } else {
        *t = R * pf->ik;
    }
    return true;
}

/* Height where the heightfield is known to be defined (rounding may make H slightly < 0). */
CLCSG_INLINE real plane_height_clamped(const plane_frame *pf, real x, real y)
{
    real R = plane_R(pf, x, y);
    if (pf->lk != 0) return pf->sheet * sqrt(fmax(R * pf->ik, (real)0));
    return R * pf->ik;
}

/* Exact ranges over a rectangle [x0,x1] x [y0,y1] of a plane: R is
 * separable, so its range is exact; |n_i| = |lam_i x + beta_i| and |n_j| are linear in one
 * coordinate each; |n_k| = sqrt(-lam_k R) on a two-sheet heightfield (lam_k t^2 = -R),
 * |beta_k| on a one-sheet one.  Ranges are (min, max). */
typedef struct {
    real2 R, ni, nj, nk;
} rect_bounds;

/* rect_bounds_of over [x0,x1] x [y0,y1] from its x parts over [x0,x1] (Px: quad_range, ni:
 * abs_linear_range), which the rows of a fill share */
CLCSG_INLINE rect_bounds row_bounds_of(const plane_frame *pf, real2 Px, real2 ni, real y0, real y1)
{
    rect_bounds b;
    real2 Sy = quad_range(pf->lj, pf->bj, pf->vj, pf->fvj, y0, y1);
    b.R = (real2)(Px.x + Sy.x + pf->gamma, Px.y + Sy.y + pf->gamma);
    b.ni = ni;
    b.nj = abs_linear_range(pf->lj, pf->bj, y0, y1);
    if (pf->lk != 0) {
        real a = -pf->lk * b.R.x, c = -pf->lk * b.R.y; /* -lam_k R = (lam_k t)^2 */
        b.nk = (real2)(sqrt(fmax(fmin(a, c), (real)0)), sqrt(fmax(fmax(a, c), (real)0)));
    } else {
        b.nk = (real2)(fabs(pf->bk), fabs(pf->bk));
    }
    return b;
}

CLCSG_INLINE rect_bounds rect_bounds_of(const plane_frame *pf, real x0, real x1, real y0, real y1)
{
    return row_bounds_of(pf, quad_range(pf->li, pf->bi, pf->vi, pf->fvi, x0, x1),
                         abs_linear_range(pf->li, pf->bi, x0, x1), y0, y1);
}

/* The height range (t_lo, t_hi) of the task's sheet over a rectangle whose R range is R (from
 * quad_range or rect_bounds_of); false where the heightfield is defined nowhere on it, and
 * *whole: defined everywhere on it.  Two sheets: lam_k t^2 = -R, so t^2 lies in the range of
 * -R / lam_k cut at 0; one sheet: t = -R / (2 beta_k). */
CLCSG_INLINE bool rect_heights(const plane_frame *pf, real2 R, real2 *t, bool *whole)
{
    *whole = true;
    if (pf->lk != 0) {
        real Hlo = (pf->lk > 0 ? R.y : R.x) * pf->ik;
        real Hhi = (pf->lk > 0 ? R.x : R.y) * pf->ik;
        if (Hhi < 0) return false;
        *whole = Hlo >= 0;
        real a = sqrt(fmax(Hlo, (real)0)), b = sqrt(Hhi);
        *t = pf->sheet > 0 ? (real2)(a, b) : (real2)(-b, -a);
    } else {
        real a = R.x * pf->ik, b = R.y * pf->ik;
        *t = (real2)(fmin(a, b), fmax(a, b));
    }
    return true;
}

/* Can plane k own a point of the rectangle?  (no: an in-plane normal component exceeds |n_k|
 * everywhere there) */
CLCSG_INLINE bool rect_may_be_owned(rect_bounds b) { return !(b.ni.x > b.nk.y || b.nj.x > b.nk.y); }

CLCSG_INLINE bool sub_rect_owned(const plane_frame *pf, real x0, real x1, real y0, real y1)
{
    return rect_may_be_owned(rect_bounds_of(pf, x0, x1, y0, y1));
}

/* device coordinates of local (x, y, t) */
CLCSG_INLINE real3 plane_point(const plane_frame *pf, real x, real y, real t)
{
    /* z[i] = x, z[j] = y, z[k] = t with (i, j) = (1, 2), (0, 2), (0, 1) for k = 0, 1, 2 */
    real z[3] = {pf->k == 0 ? t : x, pf->k == 0 ? x : pf->k == 1 ? t : y, pf->k == 2 ? t : y};
    return pf->center + (real3)(pf->U[0] * z[0] + pf->U[1] * z[1] + pf->U[2] * z[2],
                                pf->U[3] * z[0] + pf->U[4] * z[1] + pf->U[5] * z[2],
                                pf->U[6] * z[0] + pf->U[7] * z[1] + pf->U[8] * z[2]);
}

/* column m of U (unit principal axis u_m) */
CLCSG_INLINE real3 plane_axis(const plane_frame *pf, int m) { return (real3)(pf->U[m], pf->U[3 + m], pf->U[6 + m]); }

/* Distortion bounds over a rectangle: (delta_hi, delta_lo) with delta_hi = inf where the
 * heightfield may be vertical; also whether plane k may own a point of it. */
CLCSG_INLINE real2 rect_distortion(const plane_frame *pf, real x0, real x1, real y0, real y1, bool *owned)
{
    rect_bounds b = rect_bounds_of(pf, x0, x1, y0, y1);
    *owned = rect_may_be_owned(b);
    real hi = b.nk.x > 0 ? sqrt(b.ni.y * b.ni.y + b.nj.y * b.nj.y + b.nk.y * b.nk.y) / b.nk.x : INFINITY;
    real lo = b.nk.y > 0 ? sqrt(b.ni.x * b.ni.x + b.nj.x * b.nj.x + b.nk.x * b.nk.x) / b.nk.y : INFINITY;
#if WORST_CASE_DISTORTION
    hi = fmax(hi, sqrt((real)3));
    lo = hi;
#endif
    return (real2)(hi, lo);
}

/* Slope bounds of the heightfield over a row [x0,x1] x [y0,y1] of a fill, from its x parts
 * (row_bounds_of): (max |dt/dx|, max |dt/dy|) = (max |n_i|, max |n_j|) / min |n_k|, and
 * min |n_k| itself. */
CLCSG_INLINE real3 row_slopes(const plane_frame *pf, real2 Px, real2 ni, real y0, real y1)
{
    rect_bounds b = row_bounds_of(pf, Px, ni, y0, y1);
    real mx = b.ni.y / b.nk.x, my = b.nj.y / b.nk.x;
#if WORST_CASE_DISTORTION
    /* the paper's isotropic bound |dp| <= delta |d| with delta >= sqrt 3: equal slopes
     * m = sqrt((delta^2 - 1) / 2) give (m a + m b)^2 <= (delta^2 - 1)(a^2 + b^2) */
    real dl = fmax(sqrt(1 + mx * mx + my * my), sqrt((real)3));
    mx = my = sqrt((dl * dl - 1) / 2);
#endif
    return (real3)(mx, my, b.nk.x);
}

/* Largest half-width a with a^2 + b^2 + (mx a + my b)^2 <= r^2 (0 if none). */
CLCSG_INLINE real half_width(real mx, real my, real b, real r)
{
    real A = 1 + mx * mx, B = mx * my * b, C = b * b * (1 + my * my) - r * r;
    real disc = B * B - A * C;
    return disc > 0 ? fmax((-B + sqrt(disc)) / A, (real)0) : 0;
}

#endif
