/* Quadric math shared by all kernels (paper section 3).  The float64 numpy reference is
 * clcsg/quadric.py; tests compare the two. */
#ifndef CLCSG_QUADRIC_H
#define CLCSG_QUADRIC_H
#include "layout.h"

/* Private copy of a quadric's coefficients (see layout.h for the order). */
typedef struct {
    real xx, xy, xz, xw, yy, yz, yw, zz, zw, ww;
} quadric;

inline quadric quadric_load(__global const quadric_rec *qs, int i)
{
    __global const real *c = qs[i].coef;
    quadric q = {c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7], c[8], c[9]};
    return q;
}

inline quadric quadric_scaled(quadric q, real s)
{
    quadric r = {s * q.xx, s * q.xy, s * q.xz, s * q.xw, s * q.yy,
                 s * q.yz, s * q.yw, s * q.zz, s * q.zw, s * q.ww};
    return r;
}

/* A p (the 3x3 part times p) */
inline real3 quadric_Ap(quadric q, real3 p)
{
    return (real3)(q.xx * p.x + q.xy * p.y + q.xz * p.z,
                   q.xy * p.x + q.yy * p.y + q.yz * p.z,
                   q.xz * p.x + q.yz * p.y + q.zz * p.z);
}

/* -b: the linear column of the matrix */
inline real3 quadric_minus_b(quadric q) { return (real3)(q.xw, q.yw, q.zw); }

/* Q(p) = p^T A p - 2 b^T p + c  (eq. 3) */
inline real quadric_value(quadric q, real3 p)
{
    real3 g = quadric_Ap(q, p) + 2 * quadric_minus_b(q);
    return dot(p, g) + q.ww;
}

/* grad Q(p) = 2 (A p - b)  (eq. 4) */
inline real3 quadric_gradient(quadric q, real3 p)
{
    return 2 * (quadric_Ap(q, p) + quadric_minus_b(q));
}

/* Roots t1 <= t2 of Q(o + t v) = a t^2 + 2 h t + c (eqs. 5, 6); returns how many (0, 1, 2).
 * q = -(h + sign(h) sqrt(h^2 - a c)), roots q / a and c / q: no cancellation, and for
 * a -> 0 c / q is the single root of eq. 6. */
inline int quadric_intersect(quadric q, real3 o, real3 v, real *t1, real *t2)
{
    real a = dot(v, quadric_Ap(q, v));
    real h = dot(v, quadric_Ap(q, o) + quadric_minus_b(q));
    real c = quadric_value(q, o);
    real disc = h * h - a * c;
    if (disc < 0) return 0;
    real sq = sqrt(disc);
    real qq = -(h + (h >= 0 ? sq : -sq));
    real r1 = a != 0 ? qq / a : INFINITY;
    real r2 = qq != 0 ? c / qq : INFINITY;
    bool ok1 = isfinite(r1), ok2 = isfinite(r2);
    if (ok1 && ok2) {
        *t1 = fmin(r1, r2);
        *t2 = fmax(r1, r2);
        return 2;
    }
    if (ok1 || ok2) {
        *t1 = ok1 ? r1 : r2;
        *t2 = *t1;
        return 1;
    }
    return 0;
}

/* The real roots of a t^2 + 2 h t + c = 0 in eight lanes at once, with quadric_intersect's
 * arithmetic (selects for its branches): per lane how many (0, 1, 2); t1 <= t2 where there are
 * two, t1 = t2 where one. */
inline int8 quadratic_roots8(real8 a, real8 h, real8 c, real8 *t1, real8 *t2)
{
    real8 disc = h * h - a * c;
    real8 sq = sqrt(fmax(disc, (real8)(0)));
    real8 qq = -(h + select(-sq, sq, h >= 0));
    real8 r1 = select((real8)(INFINITY), qq / a, a != 0);
    real8 r2 = select((real8)(INFINITY), c / qq, qq != 0);
    realmask8 ok1 = isfinite(r1) & (disc >= 0), ok2 = isfinite(r2) & (disc >= 0);
    realmask8 both = ok1 & ok2;
    *t1 = select(select(r2, r1, ok1), fmin(r1, r2), both);
    *t2 = select(*t1, fmax(r1, r2), both);
    return convert_int8(-ok1) + convert_int8(-ok2);
}

/* The roots tau of Q(o + tau v) = 0 solved from o = e + tc v, the point of the ray e + t v
 * nearest a sample s (tc = (s - e).v): the quadric's value is small there, so the roots are
 * accurate even in float (the local ray-quadric solve of the splats).  Writes o. */
inline int quadric_intersect_near(quadric q, real3 e, real3 v, real tc, real3 *o, real *t1, real *t2)
{
    *o = e + tc * v;
    return quadric_intersect(q, *o, v, t1, t2);
}

/* Conservative signed distance d(p) (eqs. 10-12): no surface point within |d| of p,
 * d < 0 inside.  lam_min/lam_max are the extreme eigenvalues of A. */
inline real quadric_distance(quadric q, real lam_min, real lam_max, real3 p)
{
    real f = quadric_value(q, p);
    if (f == 0) return 0;
    real g = 2 * length(quadric_Ap(q, p) + quadric_minus_b(q));
    bool inside = f < 0;
    real lam = inside ? lam_max : -lam_min;
    real af = fabs(f);
    /* lam = 0 (a plane; a cylinder or cone from outside): disc = g^2, sqrt(g^2) = g, so
     * 2 |f| / (g + g) = |f| / g, the same number without the square root */
    real disc = g * g + 4 * lam * af;
    real t = lam == 0 ? af / g : disc >= 0 ? 2 * af / (g + sqrt(disc)) : INFINITY;
    return inside ? -t : t;
}

/* Is |quadric_distance(q, p)| >= R?  The same bound without its square root and division:
 * with a = |f|, t = 2 a / (g + sqrt(D)), D = g^2 + 4 lam a, t >= R iff
 * u = 2 a - R g >= R sqrt(D), i.e. u >= 0 and u^2 >= R^2 D (a / g >= R where lam = 0; any R
 * where D < 0, t infinite).  R is a region's reach with its rounding slack, which covers the
 * rounding of either form; an overflow (u not finite) answers no, as the quotient's NaN did. */
inline bool quadric_distance_at_least(quadric q, real lam_min, real lam_max, real3 p, real R, real *f)
{
    *f = quadric_value(q, p);
    if (R <= 0) return true;
    if (*f == 0) return false;
    real g = 2 * length(quadric_Ap(q, p) + quadric_minus_b(q));
    real lam = *f < 0 ? lam_max : -lam_min;
    real a = fabs(*f);
    if (lam == 0) return a >= R * g;
    real disc = g * g + 4 * lam * a;
    if (disc < 0) return true;
    real u = 2 * a - R * g;
    return u >= 0 && isfinite(u * u) && u * u >= R * R * disc;
}

#endif
