/* Splat rasterizer with local quadric ray tracing and clipping by tape (paper section 6 on the
 * CSG tree).  One work-item per sample s (radius r, quadric Q, clip program C):
 *
 * 1. screen bound: the projection of the ball B(s, r) (exact tangent bound, screen_ball);
 *    with SURFACE_ALIGNED also the projection of a flat cylinder aligned with the normal that
 *    holds the quadric patch inside the ball (splat_slab; paper section 6.1), intersected;
 * 2. per row of the bound, the span of pixels whose ray meets the ball (with SURFACE_ALIGNED:
 *    whose chord through the ball meets the slab), both grown by a margin, found with
 *    un-normalized rays d (without square roots, divisions or branches); then the span eight
 *    rays at a time, as vectors: skip rays that miss the ball; solve Q(e + t d) = 0 (eqs. 5, 6)
 *    with d not normalized, whose coefficients are polynomials in the pixel's column (the
 *    paper solves near the sample to keep float's precision; in double the roots from the
 *    eye are far more precise than the float of the key).  The depth of the key is t itself,
 *    not the distance t |d|: on one pixel's ray |d| is a constant, so both order the fragments
 *    alike, and the resolve pass multiplies by |d| once per pixel.  All tests are scaled by
 *    |d|^2, so a ray costs no square root for |d|, only the roots' square root and divisions.
 *    The root nearer the eye is tried
 *    first, the other one if it fails: |p - s| <= r, t > 0, and the clip program: C is the
 *    sample's tape pruned over B(s, r) with Q substituted, and p (on Q) is on the CSG surface
 *    iff C's membership differs between Q's two sides (tape_member8).  This is exact from any
 *    eye position, inside the solid included.  An empty C means the whole ball is surface on
 *    Q: no clipping.  A ray whose chord through the ball starts behind the pixel's stored
 *    t is dropped (splat_occluded8), and before the clip program a root whose key already
 *    loses to the stored one ends the pixel (early depth rejection: no fragment there can win);
 * 3. depth test: atom_min of ((ulong)as_uint((float)t) << 32 | sample index) into the
 *    64-bit framebuffer (positive floats order like their bit patterns), only for keys below
 *    the word read before the solve (a plain read: atomics that cannot win are skipped).
 *
 * BACKFACE_CULLING (outside views only; the host turns it off when the eye is inside the
 * solid) skips splats whose patch faces away from the eye everywhere (splat_backfacing; for
 * splats with one orientation over the ball, tape_self_polarity) and fragments whose outward normal faces
 * away from the view ray: a back-facing point is where a ray leaves the solid, so a
 * front-facing surface point is nearer on the same ray.
 *
 * Build options: SURFACE_ALIGNED, BACKFACE_CULLING, CLCSG_STATS (0 or 1), TAPE_REGS,
 * CLCSG_PREFETCH (splat_prefetch_row).  With
 * CLCSG_STATS the PC_* counters (clcsg/cl/constants.py) are accumulated per work-item and
 * added with one atomic each at the end.
 */
#pragma OPENCL EXTENSION cl_khr_int64_base_atomics : enable
#pragma OPENCL EXTENSION cl_khr_int64_extended_atomics : enable
#include "tape.h"
#include "shade.h"

#ifndef SURFACE_ALIGNED
#define SURFACE_ALIGNED 1
#endif
#ifndef BACKFACE_CULLING
#define BACKFACE_CULLING 1
#endif
#ifndef CLCSG_PREFETCH
#define CLCSG_PREFETCH 0
#endif
#ifndef CLCSG_STATS
#define CLCSG_STATS 1
#endif

/* rounding slack for conservative tests, relative to the magnitudes involved */
#define SLACK (ROUNDING_ULPS * REAL_EPS)

typedef struct {
    int x0, y0, x1, y1; /* inclusive pixel range; empty if x0 > x1 or y0 > y1 */
} rect;

inline rect rect_full(__global const view_rec *vw) { return (rect){0, 0, vw->width - 1, vw->height - 1}; }

inline rect rect_meet(rect a, rect b)
{
    return (rect){max(a.x0, b.x0), max(a.y0, b.y0), min(a.x1, b.x1), min(a.y1, b.y1)};
}

/* floor(x) and ceil(x) as ints, for |x| < 2^30: the int conversion truncates towards zero,
 * then one step where it rounded the wrong way (the library's floor() and ceil() are a
 * software routine of dozens of instructions on PoCL's CPU devices). */
inline int floor_int(real x)
{
    int t = (int)x;
    return t - (x < (real)t);
}

inline int ceil_int(real x)
{
    int t = (int)x;
    return t + (x > (real)t);
}

/* x clamped to [-lim, lim], a NaN to -lim (a lower end) or lim (an upper end): fmin and fmax
 * return the number of a number and a NaN, so a bound that went NaN widens the range. */
inline real clamp_low(real x, real lim) { return fmin(fmax(x, -lim), lim); }
inline real clamp_high(real x, real lim) { return fmax(fmin(x, lim), -lim); }

/* Pixels whose center ray may pass through continuous image range [xmin, xmax] x [ymin, ymax]:
 * centers are at j + 0.5, so j in [xmin - 0.5, xmax - 0.5]; one extra pixel each side absorbs
 * rounding (the per-pixel tests are exact, so slack costs only time). */
inline rect rect_from_range(__global const view_rec *vw, real xmin, real xmax, real ymin, real ymax)
{
    real lim = 4 * (real)max(vw->width, vw->height) + 4; /* keeps the int conversion sane */
    rect r = {floor_int(clamp_low(xmin, lim) - (real)0.5), floor_int(clamp_low(ymin, lim) - (real)0.5),
              ceil_int(clamp_high(xmax, lim) - (real)0.5), ceil_int(clamp_high(ymax, lim) - (real)0.5)};
    return rect_meet(r, rect_full(vw));
}

/* 1-D tangent bound of a disc: the slopes u = X / Z of the two lines through the origin that
 * touch the disc of radius r around (cx, cz), cz > r:
 * (cx - u cz)^2 = r^2 (1 + u^2)  =>  u = (cx cz -+ r sqrt(cx^2 + cz^2 - r^2)) / (cz^2 - r^2). */
inline real2 tangent_slopes(real cx, real cz, real r)
{
    real den = cz * cz - r * r;
    real w = r * sqrt(fmax(cx * cx + cz * cz - r * r, (real)0));
    return (real2)((cx * cz - w) / den, (cx * cz + w) / den);
}

/* Screen bound of the ball B(s, r): exact (the image x of a point only depends on its X and
 * Z camera coordinates, so the ball's x range is the tangent bound of its XZ disc; same for
 * y).  Returns an empty rect if the ball is behind the eye and the full screen if it reaches
 * the eye plane. */
inline rect screen_ball(__global const view_rec *vw, real3 a /* s - e */, real r)
{
    real cz = dot(a, vload3(0, vw->forward));
    if (cz + r <= 0) return (rect){0, 0, -1, -1};
    real rr = r * (1 + SLACK) + SLACK * length(a);
    if (cz <= rr * 1.0001) return rect_full(vw);
    real cx = dot(a, vload3(0, vw->right)), cy = dot(a, vload3(0, vw->up));
    real2 ux = tangent_slopes(cx, cz, rr), uy = tangent_slopes(cy, cz, rr);
    real f = vw->focal;
    real hw = 0.5 * vw->width, hh = 0.5 * vw->height;
    return rect_from_range(vw, hw + f * ux.x, hw + f * ux.y, hh - f * uy.y, hh - f * uy.x);
}

/* Surface-aligned splat bound (paper section 6.1; an eigenvalue bound in place of eq. 23).
 * Frame: n = grad Q(s) / |grad Q(s)| and two tangents t1, t2.  A patch point p = s + w with
 * |w| <= r and Q(p) = 0 satisfies (eq. 8) 0 = Q(s) + g.w + w^T A w, g = grad Q(s), so its
 * height h = n.w = -(Q(s) + w^T A w) / |g|.  Since lam_min |w|^2 <= w^T A w <= lam_max |w|^2
 * and 0 <= |w|^2 <= r^2:
 *     h in [-(Q(s) + max(lam_max, 0) r^2) / |g|,  -(Q(s) + min(lam_min, 0) r^2) / |g|],
 * and |h| <= r.  Both follow from Q(p) = 0 and |w| <= r alone, so every point a fragment can
 * accept lies in the slab h_lo <= n.(x - s) <= h_hi and in the cylinder of radius r around
 * the normal axis: conservative.  A plane (A = 0) gives a flat disc; the bound is never taller
 * than the ball.  (The paper bounds with a box; the cylinder is the box minus its corners.) */
typedef struct {
    real3 t1, t2, n;
    real h_lo, h_hi, r;
} splat_slab;

inline bool make_slab(quadric q, real lam_min, real lam_max, real3 s, real r, splat_slab *b)
{
    real3 g = quadric_gradient(q, s);
    real gl = length(g);
    if (!(gl > 0)) return false;
    real3 n = g / gl;
    real3 h = fabs(n.x) < 0.7 ? (real3)(1, 0, 0) : (real3)(0, 1, 0);
    real3 t1 = normalize(cross(n, h));
    real3 t2 = cross(n, t1);
    real qs = quadric_value(q, s);
    real pad = SLACK * (r + length(s)) + 1e-6 * r;
    b->t1 = t1; b->t2 = t2; b->n = n;
    b->h_lo = fmax(-(qs + fmax(lam_max, (real)0) * r * r) / gl, -r) - pad;
    b->h_hi = fmin(-(qs + fmin(lam_min, (real)0) * r * r) / gl, r) + pad;
    b->r = r + pad;
    return true;
}

/* Range of X / Z over the circle c + r (cos(phi) u + sin(phi) w) (camera coordinates X, Z;
 * the circle in front of the eye).  d/dphi (X / Z) = 0 gives  A sin(phi) + B cos(phi) + C = 0
 * with A = u_z c_X - u_X c_z, B = w_X c_z - w_z c_X, C = r (w_X u_z - u_X w_z); with
 * k = |(A, B)|, al = -C / k and be = +-sqrt(1 - al^2), the two extremes are
 * (sin(phi), cos(phi)) = (al A + be B, al B - be A) / k (no trigonometry). */
inline real2 circle_slopes(real cx, real cz, real ux, real uz, real wx, real wz, real r)
{
    real A = uz * cx - ux * cz, B = wx * cz - wz * cx, C = r * (wx * uz - ux * wz);
    real ab = sqrt(A * A + B * B);
    real al = ab > 0 ? clamp(-C / ab, (real)-1, (real)1) : 0;
    real be = sqrt(1 - al * al);
    real ka = ab > 0 ? A / ab : 1, kb = ab > 0 ? B / ab : 0;
    real lo = INFINITY, hi = -INFINITY;
    for (int k = 0; k < 2; ++k) {
        real bk = k ? be : -be;
        real sn = al * ka + bk * kb, c = al * kb - bk * ka;
        real u = (cx + r * (c * ux + sn * wx)) / (cz + r * (c * uz + sn * wz));
        lo = fmin(lo, u);
        hi = fmax(hi, u);
    }
    return (real2)(lo, hi);
}

/* Screen bound of the cylinder {|x - s - h n| <= r in the tangent plane, h_lo <= h <= h_hi}:
 * it is the convex hull of its two end discs, so its projection is the hull of the two
 * projected discs (ellipses) and its bounding rect is the union of theirs (circle_slopes per
 * axis; a little slack absorbs the rounding).  Full screen if a disc
 * is not entirely in front of the eye. */
inline rect screen_slab(__global const view_rec *vw, real3 a /* s - e */, splat_slab *b)
{
    real3 fw = vload3(0, vw->forward), rt = vload3(0, vw->right), up = vload3(0, vw->up);
    real f = vw->focal, hw = 0.5 * vw->width, hh = 0.5 * vw->height;
    real3 u = (real3)(dot(b->t1, rt), dot(b->t1, up), dot(b->t1, fw));
    real3 w = (real3)(dot(b->t2, rt), dot(b->t2, up), dot(b->t2, fw));
    real xmin = INFINITY, xmax = -INFINITY, ymin = INFINITY, ymax = -INFINITY;
    for (int k = 0; k < 2; ++k) {
        real3 c = a + (k ? b->h_hi : b->h_lo) * b->n;
        real3 cc = (real3)(dot(c, rt), dot(c, up), dot(c, fw));
        if (!(cc.z - b->r * sqrt(u.z * u.z + w.z * w.z) > SLACK * length(c) + b->r * 1e-6)) return rect_full(vw);
        real2 sx = circle_slopes(cc.x, cc.z, u.x, u.z, w.x, w.z, b->r);
        real2 sy = circle_slopes(cc.y, cc.z, u.y, u.z, w.y, w.z, b->r);
        xmin = fmin(xmin, hw + f * sx.x); xmax = fmax(xmax, hw + f * sx.y);
        ymin = fmin(ymin, hh - f * sy.y); ymax = fmax(ymax, hh - f * sy.x);
    }
    real slack = 1e-3 + 1e3 * REAL_EPS * (fabs(xmax - hw) + fabs(ymax - hh) + fabs(xmin - hw) + fabs(ymin - hh));
    return rect_from_range(vw, xmin - slack, xmax + slack, ymin - slack, ymax + slack);
}

/* Back-facing test for a whole splat (outside views).  For a patch point p = s + w
 * (|w| <= r, Q(p) = 0) the solid's outward normal is sign grad Q(p) = sign (g + 2 A w) and
 *     grad Q(p).(p - e) = g.a + g.w + 2 (A w).a + 2 w^T A w        (a = s - e)
 *                       = g.a - Q(s) + 2 (A w).a + w^T A w          (g.w = -Q(s) - w^T A w)
 * with |2 (A w).a| <= 2 L r |a| and |w^T A w| <= L r^2, L = max(|lam_min|, |lam_max|).  If
 * sign (g.a - Q(s)) exceeds 2 L r |a| + L r^2, every patch point faces away from the eye
 * (its normal has a positive component along the ray from the eye): the splat is culled. */
inline bool splat_backfacing(quadric q, real lam_min, real lam_max, int sign, real3 s, real3 a, real r)
{
    real3 g = quadric_gradient(q, s);
    real qs = quadric_value(q, s);
    real L = fmax(fabs(lam_min), fabs(lam_max));
    real al = length(a);
    real lhs = sign * (dot(g, a) - qs);
    real slack = SLACK * (length(g) * al + fabs(qs)) * 4;
    return lhs > 2 * L * r * al + L * r * r + slack;
}

inline bool rect_empty(rect b) { return b.x0 > b.x1 || b.y0 > b.y1; }

/* Step 1 and the whole-splat back-face test: the pixels the fragments of the splat (s, r) on
 * Q can reach, empty if it is culled or off screen (a = s - e; clip program clip[0, nc)). */
inline rect splat_bound(__global const view_rec *view, quadric q, real lam_min, real lam_max, int sign, int qid,
                        __global const tape_op *clip, int nc, real3 s, real3 a, real r, splat_slab *slab,
                        bool *has_slab, ulong *cnt)
{
    *has_slab = false;
#if BACKFACE_CULLING
    /* the whole-splat test needs one orientation over the ball (asked last: a loop over C);
     * before the screen bound, which costs more: about half the samples face away */
    if (splat_backfacing(q, lam_min, lam_max, sign, s, a, r) && (nc == 0 || tape_self_polarity(clip, nc, qid) != 0)) {
        cnt[PC_SPLATS_CULLED] = 1;
        return (rect){0, 0, -1, -1};
    }
#endif
    rect bound = screen_ball(view, a, r);
#if SURFACE_ALIGNED
    *has_slab = make_slab(q, lam_min, lam_max, s, r, slab);
    if (*has_slab && !rect_empty(bound)) bound = rect_meet(bound, screen_slab(view, a, slab));
#endif
    cnt[rect_empty(bound) ? PC_SPLATS_OFFSCREEN : PC_SPLATS_DRAWN] = 1;
    return bound;
}

/* The plain reads of framebuffer slots before any atomic on them (early depth rejection and
 * the skipped atomics): a slot only decreases, so a stale word costs at most an extra solve
 * or atomic.  All such reads go through splat_peek and splat_peek8, on lines of their own. */
inline ulong splat_peek(__global const ulong *slot)
{
    return *slot;
}

/* The eight slots from row (all in the framebuffer), as splat_peek. */
inline ulong8 splat_peek8(__global const ulong *row)
{
    return vload8(0, row);
}

/* Early depth rejection on eight rays e + t d (a lane mask): can no fragment of parameter
 * t >= tc - m (tc = (s - e).d / |d|^2, m = sqrt(M) / |d|^2: the ball's chord starts there) beat
 * the pixel's word?  float rounding is monotone, so such a fragment's key is at least
 * as_uint((float)(tc - m)) << 32, above the word if tc - m exceeds the next float z after the
 * stored parameter.  Scaled by |d|^2, without a square root or a division: tc - m > z  <=>
 * u = ad - z dd > 0 and u^2 > M (ad = (s - e).d, lowered by the rounding's slack; dd = |d|^2).
 * An empty word (EMPTY_KEY) never occludes. */
inline int8 splat_occluded8(real8 ad, real8 dd, real8 M, ulong8 word)
{
    uint8 hi = convert_uint8(word >> 32);
    real8 u = ad - convert_real8(as_float8(hi + 1)) * dd;
    return (hi < 0x7f800000u) & convert_int8(u > 0) & convert_int8(u * u > M);
}

/* The 64-bit keys (float bits << 32 | idx) of eight ray parameters t (splat_roots8's te). */
inline ulong8 splat_keys8(real8 t, int idx)
{
    return (convert_ulong8(as_uint8(convert_float8(t))) << 32) | (ulong8)((ulong)(uint)idx);
}

/* The lanes of a mask (-1 / 0 per lane) as the bits of an int. */
inline int splat_lane_bits(int8 m)
{
    int8 b = m & (int8)(1, 2, 4, 8, 16, 32, 64, 128);
    int4 h = b.lo | b.hi;
    int2 k = h.lo | h.hi;
    return k.x | k.y;
}

/* The roots of Q on eight rays e + t d of a row (d not normalized) and what the tests need of
 * them.  Root k: te[k] = t, its parameter from the eye (the key's value), the point b + u[k] d on the ray, rad[k] <= 0 iff
 * |p - s| <= r, slope[k] = grad Q(p).d / 2 (the outward normal's component along the ray is
 * sign slope).  With fp64 the roots are solved from the eye: Q(e + t d) = qa t^2 + 2 qh t + qe
 * has coefficients that are polynomials in the column x (qa = a0 + 2 a1 x + a2 x^2,
 * qh = b0 + b1 x), and double keeps the roots far below the float depth's rounding; the radius
 * test is t^2 |d|^2 - 2 t (a.d) + |a|^2 - r^2 <= 0 (a = s - e, k = |a|^2 - r^2).  In float
 * they are solved near the sample (the paper's local solve, eqs. 5, 6): from o = e + tc d,
 * the ray's point nearest s (tc = a.d / |d|^2), Q(o + u d) = qa u^2 + 2 h u + Q(o), and the radius
 * test is u^2 |d|^2 <= r^2 - |o - s|^2. */
typedef struct {
    real8 te[2], u[2], rad[2], slope[2];
    real8 bX, bY, bZ;
} splat_roots;

inline int8 splat_roots8(quadric q, bool plane, real3 e, real3 a, real r, real k, real qe, real8 xs, real8 dX,
                         real8 dY, real8 dZ, real8 dd, real8 ad, real a0, real a1, real a2, real b0,
                         real b1, splat_roots *R)
{
    real8 qa = a0 + xs * (2 * a1 + xs * a2), t[2];
#ifdef CLCSG_DOUBLE
    real8 qh = b0 + xs * b1;
    int8 nr;
    if (plane) { /* 2 qh t + qe = 0: quadratic_roots8's single root c / q, q = -2 h */
        t[0] = t[1] = qe / (-2 * qh);
        nr = convert_int8(isfinite(t[0])) & 1;
    } else {
        nr = quadratic_roots8(qa, qh, (real8)(qe), &t[0], &t[1]);
    }
    R->bX = (real8)(e.x); R->bY = (real8)(e.y); R->bZ = (real8)(e.z);
    for (int j = 0; j < (plane ? 1 : 2); ++j) {
        R->u[j] = t[j];
        R->rad[j] = t[j] * (t[j] * dd - 2 * ad) + k;
        R->slope[j] = qa * t[j] + qh;
    }
#else
    real8 tc = ad / dd;
    real8 oX = e.x + tc * dX, oY = e.y + tc * dY, oZ = e.z + tc * dZ;
    real8 wX = tc * dX - a.x, wY = tc * dY - a.y, wZ = tc * dZ - a.z; /* o - s */
    real8 m2 = r * r - (wX * wX + wY * wY + wZ * wZ);
    real8 gX = q.xx * oX + q.xy * oY + q.xz * oZ + q.xw, gY = q.xy * oX + q.yy * oY + q.yz * oZ + q.yw,
          gZ = q.xz * oX + q.yz * oY + q.zz * oZ + q.zw; /* A o - b */
    real8 qh = dX * gX + dY * gY + dZ * gZ;
    real8 qc = oX * (gX + q.xw) + oY * (gY + q.yw) + oZ * (gZ + q.zw) + q.ww;
    int8 nr = quadratic_roots8(qa, qh, qc, &t[0], &t[1]);
    R->bX = oX; R->bY = oY; R->bZ = oZ;
    for (int j = 0; j < 2; ++j) {
        R->u[j] = t[j];
        R->rad[j] = t[j] * t[j] * dd - m2;
        R->slope[j] = qa * t[j] + qh;
        t[j] += tc;
    }
#endif
    R->te[0] = t[0];
    R->te[1] = t[1];
    return nr;
}

/* The clip program at the points b + u d of the lanes in `wins` (those still in the running):
 * clears the lanes whose point is not on the CSG surface (membership equal on both sides of Q)
 * and returns the side the solid is on at each point (+1: the negative side). */
inline real8 splat_clip8(int qid, __global const tape_op *clip, int nc, __global const quadric_rec *quadrics,
                         const splat_roots *R, real8 dX, real8 dY, real8 dZ, real8 u, int8 *wins, ulong *cnt)
{
    cnt[PC_CLIP_EVALUATIONS] += popcount((uint)splat_lane_bits(*wins));
    uchar8 bits = tape_member8(clip, nc, quadrics, R->bX + u * dX, R->bY + u * dY, R->bZ + u * dZ, qid);
    *wins &= convert_int8((bits != (uchar8)(0)) & (bits != (uchar8)(3)));
    return select((real8)(-1), (real8)(1), convert_realmask8((bits & (uchar8)(1)) != (uchar8)(0)));
}

/* Step 2 on eight rays of a splat (lanes `live`) with nr roots R (splat_roots8): per lane the
 * parameter t of the splat's fragment from the eye (the key's depth), 0 if none.  Root k (the
 * nearer first) is a candidate if it passes the radius and t > 0 tests; a candidate whose key (with sample index idx) is not below
 * the pixel's word as read loses, and the nearer one losing ends the lane (the farther root
 * cannot win either); a candidate wins if it is on the CSG surface (the clip program at the
 * point, splat_clip8; without one it is, on side sign) and faces the eye.  The farther root is
 * tried where the nearer is no candidate or does not win for the clip or the facing. */
__attribute__((always_inline)) inline real8 splat_fragment8(int sign, int qid, __global const tape_op *clip, int nc,
                                                            __global const quadric_rec *quadrics, const splat_roots *R,
                                                            real8 dX, real8 dY, real8 dZ, int8 nr, bool one_root,
                                                            ulong8 word, int idx, int8 live, ulong *cnt)
{
    int8 ok0 = live & convert_int8(R->rad[0] <= 0) & convert_int8(R->te[0] > 0);
    int8 loses0 = convert_int8(splat_keys8(R->te[0], idx) >= word);
    int8 wins0 = ok0 & ~loses0;
    real8 side0 = (real8)(sign), side1 = side0;
    if (nc > 0 && any(wins0)) side0 = splat_clip8(qid, clip, nc, quadrics, R, dX, dY, dZ, R->u[0], &wins0, cnt);
#if BACKFACE_CULLING
    wins0 &= convert_int8(side0 * R->slope[0] <= 0);
#endif
    if (one_root) return select((real8)(0), R->te[0], convert_realmask8(wins0)); /* a plane */
    int8 ok1 = live & (nr > 1) & convert_int8(R->rad[1] <= 0) & convert_int8(R->te[1] > 0);
    int8 wins1 = ok1 & convert_int8(splat_keys8(R->te[1], idx) < word);
    wins1 &= ~ok0 | (~loses0 & ~wins0);
    if (nc > 0 && any(wins1)) side1 = splat_clip8(qid, clip, nc, quadrics, R, dX, dY, dZ, R->u[1], &wins1, cnt);
#if BACKFACE_CULLING
    wins1 &= convert_int8(side1 * R->slope[1] <= 0);
#endif
    return select(select((real8)(0), R->te[1], convert_realmask8(wins1)), R->te[0], convert_realmask8(wins0));
}

/* The span [*first, *last] of row y's pixels in the bound whose rays meet the ball grown to R
 * and, with a slab, whose chord through it meets the slab (see the kernel), eight pixels per step
 * as vectors; empty (first > last) if none.  dy: the row's ray at column 0, d = dy + x ddx;
 * cy, cx: a x dy, a x ddx; ndy, ndx: n x dy, n x ddx.  Along the row every term of the tests is
 * a polynomial in the column x of degree <= 2 (d, c = a x d and n x d are linear): |d|^2,
 * E = R^2 |d|^2 - |c|^2, P = -c.(n x d) - mid |d|^2 and n.d, whose coefficients are set up once
 * per row (the x^2 ones, rc.s0 ... rc.s3, once per splat: E2, P2, |ddx|^2, n.ddx), so a pixel
 * costs a few multiply-adds.  The expansion's rounding, relative to |a|^2 |d|^2 and |a| |d|^2,
 * is far below the margin R - r. */
inline void splat_row_span(rect bound, real3 dy, real3 cy, real3 ndy, real3 ddx, real3 cx, real3 ndx, real3 n,
                           real R, real mid, real width, real4 rc, bool has_slab, int *first_out, int *last_out)
{
    real D0 = dot(dy, dy), D1 = dot(dy, ddx);
    real E0 = R * R * D0 - dot(cy, cy), E1 = R * R * D1 - dot(cy, cx);
    real P0 = -dot(cy, ndy) - mid * D0, P1 = -(dot(cy, ndx) + dot(cx, ndy)) - 2 * mid * D1;
    real N0 = dot(n, dy);
    int first = bound.x1 + 1, last = bound.x0 - 1;
    for (int x = bound.x0; x <= bound.x1; x += 8) { /* eight pixels per step, as vectors */
        real8 xs = (real)x + (real8)(0, 1, 2, 3, 4, 5, 6, 7);
        real8 dd = D0 + xs * (2 * D1 + xs * rc.s2);
        real8 E = E0 + xs * (2 * E1 + xs * rc.s0); /* |d|^2 m^2, the grown ball */
        real8 Y = fabs(P0 + xs * (P1 + xs * rc.s1)) - width * dd; /* |d|^2 (|n.w0 - mid| - width) */
        real8 nd = N0 + xs * rc.s3;
        int8 hit = convert_int8(E >= 0) & (x + (int8)(0, 1, 2, 3, 4, 5, 6, 7) <= bound.x1);
        if (has_slab) hit &= convert_int8((Y <= 0) | (Y * Y <= E * nd * nd));
        int bits = splat_lane_bits(hit);
        if (bits) {
            first = min(first, x + popcount(~bits & (bits - 1))); /* the lowest set lane */
            last = x + 31 - clz(bits);
        }
    }
    *first_out = first;
    *last_out = last;
}

/* The span [*first, *last] of a row's pixels in the bound for a plane's splat, whose slab is
 * the disc of radius R on the plane (dy: the row's ray at column 0): the rays through the disc
 * are, per row, a quadratic's span.  With a' = a + mid n (the disc's center from the eye),
 * the ray meets the plane at t = (n.a') / (n.d), |t d - a'|^2 <= R^2 reads
 * |(n.a') d - (n.d) a'|^2 <= R^2 (n.d)^2, and u = (n.a') d - (n.d) a' = u0 + x u1 is linear
 * in x: pa x^2 + 2 pb x + pc <= 0.  Where pa <= 0 (the disc seen edge-on, or reaching the
 * eye's plane) the rows are scanned as for other splats. */
inline void splat_disc_span(rect bound, real3 dy, real3 n, real3 ap, real alpha, real3 u1, real nu1, real pa, real R,
                            int W, int *first, int *last)
{
    real nu0 = dot(n, dy);
    real3 u0 = alpha * dy - nu0 * ap;
    real pb = dot(u0, u1) - R * R * nu0 * nu1, pc = dot(u0, u0) - R * R * nu0 * nu0;
    real disc = pb * pb - pa * pc;
    *first = bound.x1 + 1;
    *last = bound.x0 - 1;
    if (disc >= 0) { /* the pixels within the roots, and 1e-3 of one: the rounding */
        real sq = sqrt(disc), lim = 2 + (real)W;
        *first = max(bound.x0, ceil_int(clamp_low((-pb - sq) / pa, lim) - (real)1e-3));
        *last = min(bound.x1, floor_int(clamp_high((-pb + sq) / pa, lim) + (real)1e-3));
    }
}

/* Step 3: the 64-bit depth test of a fragment whose key was below the slot's word as read. */
inline void splat_depth_test(__global ulong *slot, ulong key, ulong *cnt)
{
    cnt[PC_ATOMICS]++;
    atom_min(slot, key);
}

/* Asks for the framebuffer words of row y, columns x0 ... x1, ahead of their use (the kernel
 * asks SPLAT_PREFETCH_ROWS rows ahead): a splat's rows are far apart in memory, and a CPU waits
 * on each otherwise (a fifth of the pass at 1080p).  The host sets CLCSG_PREFETCH on PoCL's CPU
 * devices, whose prefetch() does nothing: there clang's __builtin_prefetch asks the cache. */
#define SPLAT_PREFETCH_ROWS 4
#if CLCSG_PREFETCH
#define SPLAT_PREFETCH(p) __builtin_prefetch(p)
#else
#define SPLAT_PREFETCH(p) prefetch(p, 1)
#endif
inline void splat_prefetch_row(__global const ulong *framebuffer, int W, int y, int x0, int x1)
{
    for (int x = x0; x < x1; x += 8) SPLAT_PREFETCH(framebuffer + y * W + x);
    SPLAT_PREFETCH(framebuffer + y * W + x1);
}

__kernel void splat(__global const quadric_rec *quadrics, __global const sample_rec *samples, int n_samples,
                    __global const tape_op *clip, __global const view_rec *view,
                    __global ulong *framebuffer, __global ulong *counters)
{
    int idx = get_global_id(0);
    if (idx >= n_samples) return;
    ulong cnt[N_SPLAT_COUNTERS];
    for (int k = 0; k < N_SPLAT_COUNTERS; ++k) cnt[k] = 0;
    __global const sample_rec *sp = &samples[idx];
    real3 s = vload3(0, sp->pos);
    real r = sp->radius;
    int qid = sp->quadric, sign = sp->sign, nc = sp->clip_count;
    __global const tape_op *cp = clip + sp->clip_first;
    quadric q = quadric_load(quadrics, qid);
    real3 e = view_eye(view);
    real3 a = s - e;
    splat_slab slab;
    bool has_slab;
    rect bound = splat_bound(view, q, quadrics[qid].lam_min, quadrics[qid].lam_max, sign, qid, cp, nc, s, a, r,
                             &slab, &has_slab, cnt);
    int W = view->width;
    /* the camera in private memory: the compiler cannot keep it in registers across the
     * framebuffer writes otherwise (they might alias the view); same expression as view_ray */
    real3 d00 = vload3(0, view->d00), ddx = vload3(0, view->dx), ddy = vload3(0, view->dy);
    /* the row span: with c = a x d and the slab's normal n, |c|^2 <= R^2 |d|^2 is the ray meeting
     * the ball grown to R; its point nearest s is o - s = w0 = -(d x c) / |d|^2, so
     * |d|^2 n.w0 = -c.(n x d), and the chord [tc -+ m] meets the slab iff
     * |n.w0 - mid| <= width + m |n.v|, with |d|^2 m |n.v| = sqrt(E) |n.d|, E = R^2 |d|^2 - |c|^2.
     * c, n x d and d are linear along the row; the margin (pad) covers the rounding. */
    real al = length(a);
    real pad = 1e-4 * r + 16 * SLACK * al;
    real R = r + pad;
    real3 n = has_slab ? slab.n : (real3)(0, 0, 1);
    real mid = has_slab ? 0.5 * (slab.h_lo + slab.h_hi) : 0, width = has_slab ? 0.5 * (slab.h_hi - slab.h_lo) + pad : 0;
    real3 cx = cross(a, ddx), ndx = cross(n, ddx);
    /* splat_row_span's x^2 coefficients (E2, P2, |ddx|^2) and n.ddx */
    real ddx2 = dot(ddx, ddx);
    real4 rc = (real4)(R * R * ddx2 - dot(cx, cx), -dot(cx, ndx) - mid * ddx2, ddx2, dot(n, ddx));
    /* Q along the rays from the eye (splat_roots8): Q(e + t d) = (d^T A d) t^2 + 2 (g.d) t + Q(e)
     * with g = A e - b; d^T A d = a0 + 2 a1 x + a2 x^2 and g.d = b0 + b1 x along a row */
    real3 ge = quadric_Ap(q, e) + quadric_minus_b(q), Addx = quadric_Ap(q, ddx);
    real qe = quadric_value(q, e), a2 = dot(ddx, Addx), b1 = dot(ge, ddx);
    real k = dot(a, a) - r * r;
    bool plane = q.xx == 0 && q.xy == 0 && q.xz == 0 && q.yy == 0 && q.yz == 0 && q.zz == 0;
    /* a plane's splat: its row spans in closed form (splat_disc_span) */
    real3 ap = a + mid * n;
    real alpha = dot(n, ap), nu1 = dot(n, ddx);
    real3 u1 = alpha * ddx - nu1 * ap;
    real pa = dot(u1, u1) - R * R * nu1 * nu1;
#ifdef CLCSG_DOUBLE
    bool disc_span = plane && has_slab && pa > 0;
#else
    bool disc_span = false; /* float's rounding of the roots can reach a pixel: the scan */
#endif
    for (int y = bound.y0; y < min(bound.y0 + SPLAT_PREFETCH_ROWS, bound.y1 + 1); ++y)
        splat_prefetch_row(framebuffer, W, y, bound.x0, bound.x1);
    for (int y = bound.y0; y <= bound.y1; ++y) {
        /* the rays through the ball and slab (convex) are a span of the row (splat_row_span),
         * found without branches, square roots or divisions, then walked with the tests below */
        int first, last;
        real3 dy = d00 + (real)y * ddy;
        real3 cy = cross(a, dy), ndy = cross(n, dy);
        real a0 = dot(dy, quadric_Ap(q, dy)), a1 = dot(dy, Addx), b0 = dot(ge, dy);
        if (y + SPLAT_PREFETCH_ROWS <= bound.y1)
            splat_prefetch_row(framebuffer, W, y + SPLAT_PREFETCH_ROWS, bound.x0, bound.x1);
        if (disc_span) {
            splat_disc_span(bound, dy, n, ap, alpha, u1, nu1, pa, R, W, &first, &last);
        } else {
            splat_row_span(bound, dy, cy, ndy, ddx, cx, ndx, n, R, mid, width, rc, has_slab, &first, &last);
        }
        cnt[PC_BOUND_PIXELS] += bound.x1 - bound.x0 + 1;
        /* the span eight pixels per step: the rays, the ball test, the quadric's roots
         * (quadratic_roots8, eqs. 5, 6 from e), the depth tests, the clip and the facing
         * (splat_fragment8) as vectors, then the atomics per pixel */
        for (int x = first; x <= last; x += 8) {
            real8 xs = (real)x + (real8)(0, 1, 2, 3, 4, 5, 6, 7);
            real8 dX = dy.x + xs * ddx.x, dY = dy.y + xs * ddx.y, dZ = dy.z + xs * ddx.z;
            /* the ray e + t d, d not normalized (the key's depth is t): it meets the ball iff
             * M = |d|^2 (r^2 - |o - s|^2) = (a.d)^2 - |d|^2 k >= 0 (o: its point nearest s) */
            real8 dd = dX * dX + dY * dY + dZ * dZ;
            real8 ad = a.x * dX + a.y * dY + a.z * dZ;
            real8 M = ad * ad - dd * k;
            int8 meet = convert_int8(M >= 0) & (x + (int8)(0, 1, 2, 3, 4, 5, 6, 7) <= last);
            if (!any(meet)) continue; /* the rays miss the ball */
            __global ulong *row = &framebuffer[y * W + x];
            /* the pixels' words (a slot only decreases: a stale word costs an extra solve) */
            ulong8 word = (ulong8)(EMPTY_KEY);
            if (x + 8 <= W) {
                word = select(word, splat_peek8(row), convert_long8(meet) != 0);
            } else {
#define SPLAT_PEEK(l, c) if (meet.c) word.c = splat_peek(row + (l));
                SPLAT_PEEK(0, s0) SPLAT_PEEK(1, s1) SPLAT_PEEK(2, s2) SPLAT_PEEK(3, s3)
                SPLAT_PEEK(4, s4) SPLAT_PEEK(5, s5) SPLAT_PEEK(6, s6) SPLAT_PEEK(7, s7)
            }
#undef SPLAT_PEEK
            real8 ad_low = ad - 16 * SLACK * (fabs(ad) + r * (real)0.5 * (1 + dd)); /* |d| <= (1 + |d|^2) / 2 */
            int8 occluded = meet & splat_occluded8(ad_low, dd, M, word);
            int8 live = meet & ~occluded;
#if CLCSG_STATS
            cnt[PC_FRAGMENTS] += popcount((uint)splat_lane_bits(meet));
            cnt[PC_FRAGMENTS_OCCLUDED] += popcount((uint)splat_lane_bits(occluded));
#endif
            if (!any(live)) continue;
            splat_roots R;
            int8 nr = splat_roots8(q, plane, e, a, r, k, qe, xs, dX, dY, dZ, dd, ad, a0, a1, a2, b0, b1, &R);
            live &= nr > 0;
            if (!any(live)) continue;
            real8 te = splat_fragment8(sign, qid, cp, nc, quadrics, &R, dX, dY, dZ, nr, plane, word, idx, live, cnt);
            int8 pass = live & convert_int8(te > 0);
#if CLCSG_STATS
            cnt[PC_FRAGMENTS_PASSED] += popcount((uint)splat_lane_bits(pass));
#endif
            ulong8 key = splat_keys8(te, idx);
#define SPLAT_TEST(l, c) if (pass.c) splat_depth_test(row + (l), key.c, cnt);
            SPLAT_TEST(0, s0) SPLAT_TEST(1, s1) SPLAT_TEST(2, s2) SPLAT_TEST(3, s3)
            SPLAT_TEST(4, s4) SPLAT_TEST(5, s5) SPLAT_TEST(6, s6) SPLAT_TEST(7, s7)
#undef SPLAT_TEST
        }
    }
#if CLCSG_STATS
    for (int k = 0; k < N_SPLAT_COUNTERS; ++k)
        if (cnt[k]) atom_add(&counters[k], cnt[k]);
#endif
}
