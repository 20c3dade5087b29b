/* Exact CSG ray tracer on the tape (the reference every render is tested against), over the
 * tile and depth-slab tapes of tiles.cl (driven by clcsg/rendering/raytracer.py).
 *
 * One work-item per pixel, ray e + t v (unit v, forward component c = v.f > 0).  The slabs of
 * the pixel's tile are walked front to back; in slab s (depths [za, zb], rays t in
 * [za / c, zb / c] inside the scene bound, where the slab's tape is exact) each listed quadric
 * is solved against the ray once, Q(e + t v) = a t^2 + 2 h t + c with roots r1 <= r2, which
 * classifies the whole ray: the sign of Q at any t is sign(a) outside [r1, r2] and -sign(a)
 * inside (a double root: sign(a) but 0 at it), sign(h) (t - r) for a line (a = 0), sign(c)
 * without roots, 0 exactly at a root.  The roots in the slab are then visited in increasing t
 * (all roots at one t are tried): a root t on quadric q is a hit iff the slab tape's
 * membership with q substituted differs between q's two sides, the other leaves being their
 * signs at t from the classification (no quadric is evaluated again), i.e. e + t v is on the
 * CSG surface.  No 1-D interval CSG beyond that and no "outside view" assumption: views from
 * inside the solid are exact.  In float the winning depth is refined by one more solve from
 * the hit point; in double the root from the eye is already far below the float depth
 * output's rounding (ray_depth).  Outputs depth (+inf on background), quadric and
 * primitive ids and RGBA8 shaded with shade.h, in the hit primitive's colour.
 *
 * Culling (ray_culling.py): quadric q has a box B_q (the hull of the boxes of the primitive
 * instances that have q as a literal) and, where all those literals have one sign s_q, that
 * sign.  A primitive is the AND of its literals, so outside its box it is FALSE, and it stays
 * FALSE with its literal on q replaced by FALSE, i.e. with K_q taken as s_q; a negated
 * instance (an OR of the complements) stays TRUE the same way.  So where the ray's stretch in
 * the slab misses B_q, every primitive on q has the value it has with q's sign taken as s_q
 * all along the stretch: q is not solved (no roots, constant sign s_q), and every membership
 * and substitution test on the stretch is unchanged.  A ray that walks past a few roots
 * searches the rest of its stretch by bisection (window_hit): the slab tape pruned over a
 * window of it (ray_prune: a quadric without a root there keeps one sign on it) is constant
 * where the window holds no surface, which is then skipped whole; a window of a few roots has
 * them tested on its pruned rows.  The per-ray work is a box test per listed quadric, a solve
 * per quadric whose box the ray meets, a pass over the slab tape per visited root for the
 * first few, and then one per window, about log2 of the roots it passes.
 *
 * Lanes: a work-item traces RAY_LANES (8) neighbouring pixels of a row, which share a tile.
 * Each lane walks the slabs as a ray of its own, but the per-ray arithmetic that does not branch
 * runs on real8 vectors over the lanes with each lane's bits of the scalar code (the view rays,
 * the stretch in the bound and in each slab, the culling-box tests, and ray_classify of each
 * quadric of a slab of up to LANE_QUADRICS, shared by the lanes that walk it); the root walk
 * and the membership tests stay per lane.  The hits are shaded together as float8
 * (pixel_lanes_store).  So the image is the per-pixel kernel's, bit for bit, at a fraction of
 * its cost: the double square roots and divisions of the set-up and of the solves, latency
 * bound in a scalar work-item, fill vector units instead.
 *
 * LOCAL_QUADRICS (set by the driver) bounds the quadrics listed by any slab.
 */
#include "tiles.h"
#include "pixel.h"

/* rows of a slab tape pruned over one ray's stretch (longer ones: the slab's tape is used) */
#define RAY_ROWS 64
/* 0: no per-ray pruning (the driver's comparison run) */
#ifndef RAY_PRUNE
#define RAY_PRUNE 1
#endif
#define RAY_PRUNE_AFTER 2

#if TILE % RAY_LANES != 0
#error "a work-item's RAY_LANES pixels lie in one tile"
#endif
#ifndef LOCAL_QUADRICS
#error "LOCAL_QUADRICS is set by the driver, clcsg/rendering/raytracer.py"
#endif

/* One quadric along the ray: roots r1 <= r2 and how its sign follows (bits 0-1: 0 constant,
 * 1 line, 2 parabola, 3 zero along the whole ray; bit 2: the leading sign is negative). */
typedef struct {
    real r1[LOCAL_QUADRICS], r2[LOCAL_QUADRICS];
    uchar kind[LOCAL_QUADRICS];
    /* the listed quadrics solved against the ray with a root before the stretch's end */
    short solved[LOCAL_QUADRICS];
} ray_roots;

/* A slab's quadrics (up to LANE_QUADRICS) classified on all eight lanes' rays at once
 * (ray_classify8), for slab_hit to take instead of solving them lane by lane. */
#define LANE_QUADRICS 16
typedef struct {
    real r1[LANE_QUADRICS][8], r2[LANE_QUADRICS][8];
    uchar kind[LANE_QUADRICS][8];
} lane_roots;

inline uchar ray_classify(quadric q, real3 e, real3 v, real *r1, real *r2)
{
    real a = dot(v, quadric_Ap(q, v));
    real h = dot(v, quadric_Ap(q, e) + quadric_minus_b(q));
    real c = quadric_value(q, e);
    int nr = quadric_intersect(q, e, v, r1, r2);
    if (nr == 0) {
        *r1 = *r2 = INFINITY;
        return c != 0 ? (c < 0 ? 4 : 0) : (a != 0 ? (a < 0 ? 4 : 0) : 3);
    }
    if (a == 0) return h != 0 ? (h < 0 ? 5 : 1) : 3;
    return a < 0 ? 6 : 2;
}

/* dot() of eight pairs of vectors as PoCL computes it: (ax bx + ay by) + az bz, each product
 * rounded on its own (not fused). */
inline real8 ray_dot8(real8 ax, real8 ay, real8 az, real8 bx, real8 by, real8 bz)
{
#pragma OPENCL FP_CONTRACT OFF
    real8 x = ax * bx, y = ay * by, z = az * bz;
    return (x + y) + z;
}

/* ray_classify of one quadric on the eight rays e + t (vx, vy, vz) of a work-item's lanes:
 * per lane the arithmetic of quadric_Ap, dot and quadric_intersect, expression for expression,
 * with selects for their branches, so each lane gets ray_classify's bits
 * (tests/test_ray_lanes.py).  Q(e) and A e - b are the same for all lanes. */
inline int8 ray_classify8(quadric q, real3 e, real8 vx, real8 vy, real8 vz, real8 *r1, real8 *r2)
{
    real3 w = quadric_Ap(q, e) + quadric_minus_b(q);
    real c = quadric_value(q, e);
    real8 ax = q.xx * vx + q.xy * vy + q.xz * vz, ay = q.xy * vx + q.yy * vy + q.yz * vz,
          az = q.xz * vx + q.yz * vy + q.zz * vz;
    real8 a = ray_dot8(vx, vy, vz, ax, ay, az);
    real8 h = ray_dot8(vx, vy, vz, (real8)w.x, (real8)w.y, (real8)w.z);
    real8 disc = h * h - a * c;
    real8 sq = sqrt(disc);
    real8 qq = -(h + select(-sq, sq, h >= 0));
    real8 t1 = select((real8)INFINITY, qq / a, a != 0);
    real8 t2 = select((real8)INFINITY, c / qq, qq != 0);
    realmask8 go = !(disc < 0);
    realmask8 ok1 = go & isfinite(t1), ok2 = go & isfinite(t2), both = ok1 & ok2, none = !(ok1 | ok2);
    real8 lo = select(select(t2, t1, ok1), fmin(t1, t2), both);
    real8 hi = select(lo, fmax(t1, t2), both);
    *r1 = select(lo, (real8)INFINITY, none);
    *r2 = select(hi, (real8)INFINITY, none);
    int8 ia = convert_int8(a != 0), na = convert_int8(a < 0), ih = convert_int8(h != 0), nh = convert_int8(h < 0);
    int8 k0 = c != 0 ? (int8)(c < 0 ? 4 : 0) : select((int8)3, select((int8)0, (int8)4, na), ia);
    int8 k1 = select((int8)3, select((int8)1, (int8)5, nh), ih);
    int8 k2 = select((int8)2, (int8)6, na);
    return select(select(k1, k2, ia), k0, convert_int8(none));
}

/* The classifications (ray_classify8) of the last RAY_CACHE quadrics a work-item's lanes
 * were classified against, by quadric id: a quadric listed by several slabs of the tile (a
 * sphere's cap spanning their depths) is solved once per ray, not once per slab.  The roots
 * of a quadric along a ray do not depend on the slab, so the reuse is exact. */
#define RAY_CACHE 8
typedef struct {
    int q[RAY_CACHE];
    real r1[RAY_CACHE][8], r2[RAY_CACHE][8];
    int kind[RAY_CACHE][8];
    int n;
} roots_cache;

inline int8 cached_classify8(roots_cache *c, __global const quadric_rec *qs, int q, real3 e, real8 vx, real8 vy,
                             real8 vz, real8 *r1, real8 *r2)
{
    for (int k = 0; k < min(c->n, RAY_CACHE); ++k)
        if (c->q[k] == q) {
            *r1 = vload8(0, c->r1[k]);
            *r2 = vload8(0, c->r2[k]);
            return vload8(0, c->kind[k]);
        }
    int8 kind = ray_classify8(quadric_load(qs, q), e, vx, vy, vz, r1, r2);
    int slot = c->n++ % RAY_CACHE;
    c->q[slot] = q;
    vstore8(*r1, 0, c->r1[slot]);
    vstore8(*r2, 0, c->r2[slot]);
    vstore8(kind, 0, c->kind[slot]);
    return kind;
}

/* sign of Q_m(e + t v) from the classification */
inline int ray_sign(const ray_roots *rr, int m, real t)
{
    uchar k = rr->kind[m];
    int s = (k & 4) ? -1 : 1;
    real r1 = rr->r1[m], r2 = rr->r2[m];
    switch (k & 3) {
    case 0: return s;
    case 3: return 0;
    case 1: return t == r1 ? 0 : t > r1 ? s : -s;
    default: return (t == r1 || t == r2) ? 0 : ((t > r1) == (t > r2)) ? s : -s;
    }
}

/* Membership bits of a slab tape (leaves renumbered: a = listed quadric) at ray depth t with
 * listed quadric self substituted (tape_member's convention); for a tape in global memory
 * (slab_member) or in the ray's own rows (ray_member).  The registers' two bits each are kept
 * packed in one 64-bit integer where they fit (TAPE_REGS <= 32): the interpreter then reads and
 * writes a machine register, not a private array, whose byte stores and reloads were most of
 * its time. */
#if TAPE_REGS <= 32
#define SLAB_MEMBER_BODY                                                              \
    ulong r = 0;                                                                     \
    for (int k = 0; k < n; ++k) {                                                    \
        tape_op o = t[k];                                                            \
        ulong v;                                                                     \
        if (o.op == OP_LEAF) {                                                       \
            if (o.a == self)                                                         \
                v = o.b > 0 ? 1 : 2;                                                 \
            else                                                                     \
                v = o.b * ray_sign(rr, o.a, tt) <= 0 ? 3 : 0;                        \
        } else if (o.op == OP_AND) {                                                 \
            v = (r >> (2 * o.a)) & (r >> (2 * o.b)) & 3;                             \
        } else if (o.op == OP_OR) {                                                  \
            v = ((r >> (2 * o.a)) | (r >> (2 * o.b))) & 3;                           \
        } else if (o.op == OP_COPY) {                                                \
            v = (r >> (2 * o.a)) & 3;                                                \
        } else {                                                                     \
            v = o.a ? 3 : 0;                                                         \
        }                                                                            \
        r = (r & ~((ulong)3 << (2 * o.out))) | (v << (2 * o.out));                   \
    }                                                                                \
    return (uint)(r >> (2 * t[n - 1].out)) & 3;
#else
#define SLAB_MEMBER_BODY                                                     \
    uchar r[TAPE_REGS];                                                     \
    for (int k = 0; k < n; ++k) {                                           \
        tape_op o = t[k];                                                   \
        if (o.op == OP_LEAF) {                                              \
            if (o.a == self)                                                \
                r[o.out] = o.b > 0 ? 1 : 2;                                 \
            else                                                            \
                r[o.out] = o.b * ray_sign(rr, o.a, tt) <= 0 ? 3 : 0;        \
        } else                                                              \
            TAPE_BOOLEAN_ROW(r, o, BITS_AND, BITS_OR, 3, 0);                \
    }                                                                       \
    return r[t[n - 1].out];
#endif

inline uint slab_member(__global const tape_op *t, int n, const ray_roots *rr, real tt, int self)
{
    SLAB_MEMBER_BODY
}

inline uint ray_member(const tape_op *t, int n, const ray_roots *rr, real tt, int self) { SLAB_MEMBER_BODY }

/* The slab tape t (n rows) pruned over the ray's stretch [a, b]: a listed quadric without a
 * root in [a, b] has one sign all along it, so its leaves become constants and are folded
 * (tape.h's pruning rules, then the rows whose result is not read are dropped).  Writes the
 * rows to out (at most RAY_ROWS) and returns their count and first row; returns 0 if the
 * stretch has no surface (the tape is one constant on it) and -1 if the rows do not fit. */
inline int ray_prune(__global const tape_op *t, int n, const ray_roots *rr, real a, real b, tape_op *out,
                     int *first)
{
    uchar st[TAPE_REGS]; /* ST_F, ST_T or ST_LIVE */
    int m = 0, last = -1;
    for (int k = 0; k < n; ++k) {
        tape_op o = t[k];
        tape_op keep = o;
        bool kept = false;
        if (o.op == OP_LEAF) {
            real r1 = rr->r1[o.a], r2 = rr->r2[o.a];
            if ((r1 >= a && r1 <= b) || (r2 >= a && r2 <= b)) {
                st[o.out] = ST_LIVE;
                kept = true;
            } else
                st[o.out] = o.b * ray_sign(rr, o.a, a) <= 0 ? ST_T : ST_F;
        } else if (o.op == OP_AND || o.op == OP_OR) {
            int sa = st[o.a], sb = st[o.b];
            int absorb = o.op == OP_AND ? ST_F : ST_T, neutral = o.op == OP_AND ? ST_T : ST_F;
            if (sa == absorb || sb == absorb) {
                st[o.out] = absorb;
            } else if (sa == neutral || sb == neutral) {
                int src = sa == neutral ? o.b : o.a;
                st[o.out] = st[src];
                kept = st[src] == ST_LIVE && src != o.out;
                keep = (tape_op){OP_COPY, o.out, src, 0};
            } else {
                st[o.out] = ST_LIVE;
                kept = true;
            }
        } else if (o.op == OP_COPY) {
            st[o.out] = st[o.a];
            kept = st[o.a] == ST_LIVE && o.a != o.out;
        } else {
            st[o.out] = o.a ? ST_T : ST_F;
        }
        if (kept) {
            if (m == RAY_ROWS) return -1;
            out[m++] = keep;
            last = o.out;
        }
    }
    int root = t[n - 1].out;
    if (st[root] != ST_LIVE) return 0;
    if (last != root) {
        if (m == RAY_ROWS) return -1;
        out[m++] = (tape_op){OP_COPY, root, root, 0};
    }
    int w;
    TAPE_KEEP_LIVE_ROWS(out, m, root, w);
    *first = w;
    return m - w;
}

/* [t0, t1] of the ray e + t v inside the box [lo, hi] (t0 > t1: it misses), inv = 1 / v (+-inf
 * for zero components, or ray_inverse8's huge finite ends: the slab test still works) */
inline real2 ray_box_inv(real3 e, real3 inv, real3 lo, real3 hi)
{
    real3 a = (lo - e) * inv, b = (hi - e) * inv;
    real3 tn = fmin(a, b), tf = fmax(a, b);
    return (real2)(fmax(fmax(tn.x, tn.y), tn.z), fmin(fmin(tf.x, tf.y), tf.z));
}


/* 1 / v on eight lanes, clamped to +-REAL_MAX / 2 where a component of v is zero: finite and
 * not zero, so ray_box8's products are never 0 * inf (NaN).  A ray parallel to a slab then
 * gets huge (or infinite) ends of the sign the infinite inverse gives: the same intervals,
 * and one that lies in a face plane of the box counts as inside (conservative). */
inline real8 ray_inverse8(real8 v)
{
    return clamp(1 / v, (real8)(-0.5 * REAL_MAX), (real8)(0.5 * REAL_MAX));
}

/* The least and the greatest of eight numbers (none NaN). */
inline real min_of8(real8 a)
{
    real4 m = fmin(a.lo, a.hi);
    real2 k = fmin(m.lo, m.hi);
    return fmin(k.x, k.y);
}

inline real max_of8(real8 a)
{
    real4 m = fmax(a.lo, a.hi);
    real2 k = fmax(m.lo, m.hi);
    return fmax(k.x, k.y);
}

/* a < b ? a : b and a > b ? a : b, one instruction each on CPUs (fmin and fmax also order NaNs) */
inline real8 ray_min8(real8 a, real8 b) { return select(b, a, a < b); }
inline real8 ray_max8(real8 a, real8 b) { return select(b, a, a > b); }

/* ray_box_inv on the eight lanes' rays (inverse directions ix, iy, iz from ray_inverse8, so no
 * product is NaN and plain minima and maxima do): [t0, t1] per lane. */
inline void ray_box8(real3 e, real8 ix, real8 iy, real8 iz, real3 lo, real3 hi, real8 *t0, real8 *t1)
{
    real3 a = lo - e, b = hi - e;
    real8 ax = a.x * ix, ay = a.y * iy, az = a.z * iz, bx = b.x * ix, by = b.y * iy, bz = b.z * iz;
    *t0 = ray_max8(ray_max8(ray_min8(ax, bx), ray_min8(ay, by)), ray_min8(az, bz));
    *t1 = ray_min8(ray_min8(ray_max8(ax, bx), ray_max8(ay, by)), ray_max8(az, bz));
}

/* The lanes where mask m (a real8 comparison) holds, as bits. */
inline int lane_bits(realmask8 m)
{
    int8 b = convert_int8(m) & (int8)(1, 2, 4, 8, 16, 32, 64, 128);
    int4 h = b.lo | b.hi;
    int2 q = h.lo | h.hi;
    return q.x | q.y;
}

/* The least root of the solved quadrics after t_cur (at t_cur too if `first`), +inf past tb. */
inline real next_root(const ray_roots *rr, int ns, real t_cur, bool first, real tb)
{
    real t_next = INFINITY;
    for (int k = 0; k < ns; ++k) {
        int m = rr->solved[k];
        real a = rr->r1[m], b = rr->r2[m];
        if ((a > t_cur || (first && a == t_cur)) && a < t_next) t_next = a;
        if ((b > t_cur || (first && b == t_cur)) && b < t_next) t_next = b;
    }
    return t_next <= tb ? t_next : INFINITY;
}

/* The listed quadric with a root at t on the CSG surface (-1: none), by the membership of the
 * slab tape t (n rows) or, where nrows > 0, of the rows pruned over a stretch holding t. */
inline int root_hit(const ray_roots *rr, int ns, real tt, __global const tape_op *t, int n, const tape_op *rows,
                    int nrows)
{
    for (int k = 0; k < ns; ++k) {
        int m = rr->solved[k];
        if (rr->r1[m] != tt && rr->r2[m] != tt) continue;
        uint bits = nrows > 0 ? ray_member(rows, nrows, rr, tt, m) : slab_member(t, n, rr, tt, m);
        if (bits == 1 || bits == 2) return m;
    }
    return -1;
}

/* The first hit after t_cur (whose roots were visited) up to tb, by bisection of the stretch
 * in t: a window [lo, hi] whose pruned tape (ray_prune) is constant has no surface and is
 * skipped whole; one with at most RAY_WALK roots (or that cannot be split further) has its
 * roots visited in order on its pruned rows; any other is split at its midpoint, the nearer
 * half first.  So a ray that passes many roots before its hit (the face planes of a mesh
 * operand, whose extensions cross it everywhere) costs a pass over the slab tape per window,
 * about log2 of its roots of them, not one per root; the windows are taken in increasing t
 * and each one's roots in order, so the hit is the first one, as visiting every root finds. */
#define RAY_WALK 4
#define RAY_DEPTH 32
inline int window_hit(const ray_roots *rr, int ns, __global const tape_op *t, int n, real lo, real tb, real *depth)
{
    tape_op rows[RAY_ROWS];
    real ends[RAY_DEPTH];
    int sp = 0;
    ends[sp++] = tb;
    while (sp > 0) {
        real hi = ends[sp - 1];
        int r0 = 0, nrows = ray_prune(t, n, rr, lo, hi, rows, &r0);
        if (nrows != 0) {
            int roots = 0;
            for (int k = 0; k < ns && roots <= RAY_WALK; ++k) {
                int m = rr->solved[k];
                real a = rr->r1[m], b = rr->r2[m];
                roots += (a > lo && a <= hi) + (b > lo && b <= hi && b != a);
            }
            real mid = lo + (real)0.5 * (hi - lo);
            if (roots > RAY_WALK && sp < RAY_DEPTH && mid > lo && mid < hi) {
                ends[sp++] = mid;
                continue;
            }
            for (real t_cur = lo;;) {
                real t_next = next_root(rr, ns, t_cur, false, hi);
                if (!(t_next <= hi)) break;
                int m = root_hit(rr, ns, t_next, t, n, rows + r0, nrows);
                if (m >= 0) {
                    *depth = t_next;
                    return m;
                }
                t_cur = t_next;
            }
        }
        lo = hi;
        --sp;
    }
    return -1;
}

/* The first root in [ta, tb] on the CSG surface of slab tape t (quadrics ql, nq of them):
 * returns the listed index of its quadric (-1: none) and writes its depth.  Inlined into
 * trace_lanes, which calls it per lane and slab: the call cost about 4% of a compact model's
 * trace. */
__attribute__((always_inline)) inline int slab_hit(__global const quadric_rec *qs, __global const tape_op *t, int n,
                                                   __global const int *ql, int nq, __global const real *cull, real3 e,
                                                   real3 v, real3 inv, real slack, real ta, real tb,
                                                   const lane_roots *lr, int lane, ray_roots *rr, real *depth)
{
    int ns = 0; /* the solved quadrics, listed first in rr->solved */
    for (int m = 0; m < nq; ++m) {
        if (lr) { /* classified and culled for all lanes at once (bit 3: culled) */
            uchar k = lr->kind[m][lane];
            rr->r1[m] = lr->r1[m][lane];
            rr->r2[m] = lr->r2[m][lane];
            rr->kind[m] = k & 7;
            if (k & 8) continue;
        } else {
            int q = ql[m];
            real4 lo = vload4(0, cull + 8 * q), hi = vload4(1, cull + 8 * q);
            if (lo.w != 0) {
                real2 tt = ray_box_inv(e, inv, lo.xyz - slack, hi.xyz + slack);
                if (!(fmax(tt.x, ta) <= fmin(tt.y, tb))) {
                    rr->r1[m] = rr->r2[m] = INFINITY;
                    rr->kind[m] = lo.w < 0 ? 4 : 0;
                    continue;
                }
            }
            rr->kind[m] = ray_classify(quadric_load(qs, q), e, v, &rr->r1[m], &rr->r2[m]);
        }
        if (rr->r1[m] <= tb) rr->solved[ns++] = m;
    }
    if (ns == 0) return -1;
    /* the first RAY_PRUNE_AFTER roots on the slab's tape (most rays hit at their first root) */
    real t_cur = ta;
    bool first = ta > 0; /* a root exactly at ta is visited (not one at the eye) */
    for (int visited = 0; !RAY_PRUNE || visited < RAY_PRUNE_AFTER; ++visited) {
        real t_next = next_root(rr, ns, t_cur, first, tb);
        if (!(t_next <= tb)) return -1;
        int m = root_hit(rr, ns, t_next, t, n, 0, 0);
        if (m >= 0) {
            *depth = t_next;
            return m;
        }
        t_cur = t_next;
        first = false;
    }
    return window_hit(rr, ns, t, n, t_cur, tb, depth);
}

/* ray_sign on the eight lanes of a shared slab's classification (lane_roots) at depths tt:
 * per lane ray_sign's cases, expression for expression, as selects. */
inline int8 ray_sign8(const lane_roots *lr, int m, real8 tt)
{
    int8 k = convert_int8(vload8(0, lr->kind[m])) & 7;
    real8 r1 = vload8(0, lr->r1[m]), r2 = vload8(0, lr->r2[m]);
    int8 s = select((int8)1, (int8)-1, (k & 4) != 0);
    int8 kind = k & 3;
    int8 at1 = convert_int8(tt == r1), past1 = convert_int8(tt > r1), past2 = convert_int8(tt > r2);
    int8 line = select(select(-s, s, past1), (int8)0, at1);
    int8 parabola = select(select(-s, s, past1 == past2), (int8)0, at1 | convert_int8(tt == r2));
    return select(select(select(parabola, line, kind == 1), (int8)0, kind == 3), s, kind == 0);
}

/* slab_member on the eight lanes (listed quadric self substituted): the membership bits per
 * lane at its depth tt. */
inline int8 slab_member8(__global const tape_op *t, int n, const lane_roots *lr, real8 tt, int self)
{
    int8 r[TAPE_REGS];
    for (int k = 0; k < n; ++k) {
        tape_op o = t[k];
        if (o.op == OP_LEAF) {
            if (o.a == self)
                r[o.out] = (int8)(o.b > 0 ? 1 : 2);
            else
                r[o.out] = select((int8)0, (int8)3, o.b * ray_sign8(lr, o.a, tt) <= 0);
        } else
            TAPE_BOOLEAN_ROW(r, o, BITS_AND, BITS_OR, (int8)3, (int8)0);
    }
    return r[t[n - 1].out];
}

/* What slab_hit's first RAY_PRUNE_AFTER visits find, on all lanes of a shared slab at once:
 * each lane's roots in its stretch [ta, tb] in depth order (next_root, a root at ta counted
 * where ta > 0), and the listed quadric, in list order, on whose CSG surface one lies
 * (root_hit).  Returns the lanes of `in` decided here: those whose stretch runs out of roots
 * (no hit in the slab) and those with a hit among the visited roots (hit[l], depth[l]); the
 * others are left to slab_hit, which walks the rest.  Most rays hit at their first or second
 * root (the second where the solid is an intersection), so most lanes skip slab_hit's per-lane
 * walk. */
inline int first_root_hits8(__global const tape_op *t, int n, int nq, const lane_roots *lr, real8 ta, real8 tb,
                            int in, int *hit, real *depth)
{
    realmask8 first = ta > 0;
    real8 t_cur = ta;
    int open = in, decided = 0;
    for (int visited = 0; visited < RAY_PRUNE_AFTER && open; ++visited) {
        real8 tn = INFINITY;
        for (int m = 0; m < nq; ++m) {
            real8 r1 = vload8(0, lr->r1[m]), r2 = vload8(0, lr->r2[m]);
            realmask8 solved = convert_realmask8((convert_int8(vload8(0, lr->kind[m])) & 8) == 0) & (r1 <= tb);
            realmask8 c1 = solved & ((r1 > t_cur) | (first & (r1 == t_cur))) & (r1 < tn);
            tn = select(tn, r1, c1);
            realmask8 c2 = solved & ((r2 > t_cur) | (first & (r2 == t_cur))) & (r2 < tn);
            tn = select(tn, r2, c2);
        }
        int out = open & ~lane_bits(tn <= tb); /* no root left: no hit in the slab */
        decided |= out;
        open &= ~out;
        for (int m = 0; m < nq && open; ++m) {
            real8 r1 = vload8(0, lr->r1[m]), r2 = vload8(0, lr->r2[m]);
            realmask8 solved = convert_realmask8((convert_int8(vload8(0, lr->kind[m])) & 8) == 0) & (r1 <= tb);
            int at = open & lane_bits(solved & ((r1 == tn) | (r2 == tn)));
            if (!at) continue;
            int8 bits = slab_member8(t, n, lr, tn, m);
            int won = at & lane_bits(convert_realmask8((bits == 1) | (bits == 2)));
            real tns[8];
            vstore8(tn, 0, tns);
            for (int l = 0; l < 8; ++l)
                if (won >> l & 1) {
                    hit[l] = m;
                    depth[l] = tns[l];
                }
            open &= ~won;
            decided |= won;
        }
        t_cur = tn;
        first = 0;
    }
    return decided;
}

/* The refined depth: solve again from the hit, Q(p0 + tau v) = 0 with p0 = e + t v, and take
 * the root nearest 0 (Q(p0) is tiny there: as accurate as the splats' near-sample solve). */
inline real refine_depth(quadric q, real3 e, real3 v, real t)
{
    real tau[2];
    int nr = quadric_intersect(q, e + t * v, v, &tau[0], &tau[1]);
    if (nr > 0) {
        real d = (nr > 1 && fabs(tau[1]) < fabs(tau[0])) ? tau[1] : tau[0];
        if (fabs(d) < 1e-3 * t) t += d;
    }
    return t;
}

/* The depth output of a hit at root t on quadric q: in double the root from the eye (its
 * relative error, a few units of double's rounding, is far below the float depth's); in float
 * refine_depth's. */
inline real ray_depth(__global const quadric_rec *qs, int q, real3 e, real3 v, real t)
{
#ifdef CLCSG_DOUBLE
    return t;
#else
    return refine_depth(quadric_load(qs, q), e, v, t);
#endif
}

/* The hits of a work-item's lanes (rays e + t v, v = (vx, vy, vz)[l], lanes l < n) through
 * tile `tile`: per lane the tile's slabs are walked front to back until one holds a hit (a lane
 * walks them as if alone; the lanes only share the slabs' classifications, ray_classify8).
 * Writes each lane's quadric id (-1: none) and refined depth. */
inline void trace_lanes(__global const quadric_rec *qs, __global const tape_op *arena, __global const int *qlist,
                        __global const real *cull, real3 blo, real3 bhi, __global const real2 *tile_z,
                        __global const int4 *slabs, int tile, real3 e, real3 forward, real slack, int n, real8 vx8,
                        real8 vy8, real8 vz8, int *qid, real *depth)
{
    /* per lane as in a ray of its own: c = v.forward, inv = 1 / v, the stretch in the bound */
    real8 c8 = ray_dot8(vx8, vy8, vz8, (real8)forward.x, (real8)forward.y, (real8)forward.z);
    real8 ix8 = ray_inverse8(vx8), iy8 = ray_inverse8(vy8), iz8 = ray_inverse8(vz8);
    real8 s0, s1;
    ray_box8(e, ix8, iy8, iz8, blo - slack, bhi + slack, &s0, &s1);
    s0 = fmax(s0, (real8)0);
    /* lanes whose ray is in the bound and has no hit yet */
    int walking = lane_bits(s0 <= s1) & ((1 << n) - 1);
    real vx[8], vy[8], vz[8], ix[8], iy[8], iz[8], best[8];
    vstore8(vx8, 0, vx); vstore8(vy8, 0, vy); vstore8(vz8, 0, vz);
    vstore8(ix8, 0, ix); vstore8(iy8, 0, iy); vstore8(iz8, 0, iz);
    for (int l = 0; l < 8; ++l) {
        qid[l] = -1;
        best[l] = INFINITY;
    }
    ray_roots rr; /* filled by slab_hit anew per slab and lane */
    lane_roots lr;
    roots_cache cache;
    cache.n = 0;
    for (int s = 0; s < SLABS && walking; ++s) {
        int4 sl = slabs[tile * SLABS + s];
        if (sl.y == 0) continue;
        real2 zs = slab_range(tile_z[tile], s);
        real8 ta8 = fmax(s0, zs.x / c8), tb8 = fmin(s1, zs.y / c8);
        if (s == 0) ta8 = s0; /* the end slabs reach the eye or the bound's entry and exit */
        if (s == SLABS - 1) tb8 = s1;
        int in = walking & lane_bits(ta8 <= tb8); /* the walking lanes whose stretch meets the slab */
        if (!in) continue;
        /* the slab's quadrics classified and culled on all lanes at once, or (a longer list or
         * a single lane) by slab_hit per lane */
        bool shared = sl.w <= LANE_QUADRICS && popcount(in) > 1;
        if (shared)
            for (int m = 0; m < sl.w; ++m) {
                int q = qlist[sl.z + m];
                real4 lo = vload4(0, cull + 8 * q), hi = vload4(1, cull + 8 * q);
                realmask8 missed = 0;
                if (lo.w != 0) {
                    real8 b0, b1;
                    ray_box8(e, ix8, iy8, iz8, lo.xyz - slack, hi.xyz + slack, &b0, &b1);
                    missed = !(ray_max8(b0, ta8) <= ray_min8(b1, tb8));
                }
                real8 r1 = INFINITY, r2 = INFINITY;
                int8 k = lo.w < 0 ? 4 : 0;
                if ((lane_bits(missed) & in) != in)
                    k = cached_classify8(&cache, qs, q, e, vx8, vy8, vz8, &r1, &r2);
                int8 gone = convert_int8(missed);
                vstore8(select(r1, (real8)INFINITY, missed), 0, lr.r1[m]);
                vstore8(select(r2, (real8)INFINITY, missed), 0, lr.r2[m]);
                vstore8(convert_uchar8(select(k, (int8)(lo.w < 0 ? 4 | 8 : 8), gone)), 0, lr.kind[m]);
            }
        if (shared) { /* lanes without a root of a listed quadric in their stretch of the slab have no hit in it */
            realmask8 has = 0;
            for (int m = 0; m < sl.w; ++m) {
                real8 r1 = vload8(0, lr.r1[m]), r2 = vload8(0, lr.r2[m]);
                has |= (r1 >= ta8 & r1 <= tb8) | (r2 >= ta8 & r2 <= tb8);
            }
            in &= lane_bits(has);
            if (!in) continue;
            int hit[8];
            real t_hit[8];
            for (int l = 0; l < 8; ++l) hit[l] = -1;
            int decided = first_root_hits8(arena + sl.x, sl.y, sl.w, &lr, ta8, tb8, in, hit, t_hit);
            for (int l = 0; l < n; ++l)
                if ((decided >> l & 1) && hit[l] >= 0) {
                    qid[l] = qlist[sl.z + hit[l]];
                    best[l] = t_hit[l];
                    walking &= ~(1 << l);
                }
            in &= ~decided;
            if (!in) continue;
        }
        real ta[8], tb[8];
        vstore8(ta8, 0, ta);
        vstore8(tb8, 0, tb);
        for (int l = 0; l < n; ++l) {
            if (!(in >> l & 1)) continue;
            int m = slab_hit(qs, arena + sl.x, sl.y, qlist + sl.z, sl.w, cull, e, (real3)(vx[l], vy[l], vz[l]),
                             (real3)(ix[l], iy[l], iz[l]), slack, ta[l], tb[l], shared ? &lr : 0, l, &rr, &best[l]);
            if (m >= 0) {
                qid[l] = qlist[sl.z + m];
                walking &= ~(1 << l);
            }
        }
    }
    for (int l = 0; l < n; ++l)
        if (qid[l] >= 0) depth[l] = ray_depth(qs, qid[l], e, (real3)(vx[l], vy[l], vz[l]), best[l]);
}

/* The primitive of lane l's hit p on a quadric with several owners (primitive_at), and of the
 * later lanes that hit the same quadric where primitive_over_box gives one for the box of
 * their hits (neighbouring pixels mostly show one primitive): those get it in prim_of, the
 * others PRIMITIVE_POINT, where primitive_at is taken at once.  Not inlined: the kernel's
 * common path (a quadric of one owner) stays as lean as without it. */
#define PRIMITIVE_UNKNOWN (-3)
#define PRIMITIVE_POINT (-4)
__attribute__((noinline)) int lanes_primitive(PRIMITIVE_TABLE, __global const quadric_rec *qs, const int *qid,
                                              const real *depth, const real *vx, const real *vy, const real *vz,
                                              real3 e, real3 p, int *prim_of, int l, int lanes)
{
    int q = qid[l], same = 0;
    real3 lo = p, hi = p;
    for (int m = l + 1; m < lanes; ++m) {
        if (qid[m] != q) continue;
        real3 pm = e + depth[m] * (real3)(vx[m], vy[m], vz[m]);
        lo = fmin(lo, pm);
        hi = fmax(hi, pm);
        same |= 1 << m;
    }
    if (same) {
        int fixed = primitive_over_box(PRIMITIVE_TABLE_ARGS, qs, q, lo, hi);
        for (int m = l + 1; m < lanes; ++m)
            if (same & (1 << m)) prim_of[m] = fixed == PRIMITIVE_VARIES ? PRIMITIVE_POINT : fixed;
        if (fixed != PRIMITIVE_VARIES) return fixed;
    }
    return primitive_at(PRIMITIVE_TABLE_ARGS, qs, q, p);
}

/* The common case of a work-item's lanes, shaded and stored as vectors: all eight hit one
 * quadric, and one primitive holds over their hits: the quadric's only owner, or (several
 * owners) primitive_over_box's answer for the box of the eight hits, as lanes_primitive finds
 * it.  The points e + t v, the gradients (quadric_gradient's arithmetic on real8) and the
 * albedo are computed once for the eight; false (nothing written) otherwise. */
inline bool trace_uniform_store(pixel_out out, __global const quadric_rec *qs, PRIMITIVE_TABLE,
                                __global const view_rec *view, real3 e, const int *qid, const real *depth, real8 vx,
                                real8 vy, real8 vz, int pix)
{
    int q = qid[0];
    if (q < 0) return false;
    for (int l = 1; l < RAY_LANES; ++l)
        if (qid[l] != q) return false;
    owner_rec o = owners[q];
    real8 t = vload8(0, depth);
    real8 px = e.x + t * vx, py = e.y + t * vy, pz = e.z + t * vz;
    int prim;
    if (o.count == 1) {
        prim = owner_list[o.first];
    } else {
        real3 lo = (real3)(min_of8(px), min_of8(py), min_of8(pz));
        real3 hi = (real3)(max_of8(px), max_of8(py), max_of8(pz));
        prim = primitive_over_box(PRIMITIVE_TABLE_ARGS, qs, q, lo, hi);
        if (prim == PRIMITIVE_VARIES) return false;
    }
    float4 albedo = shade_albedo(view, pixel_color(prims, prim));
    quadric Q = quadric_load(qs, q);
    pixel_lanes L;
    vstore8(2 * ((Q.xx * px + Q.xy * py + Q.xz * pz) + Q.xw), 0, L.gx);
    vstore8(2 * ((Q.xy * px + Q.yy * py + Q.yz * pz) + Q.yw), 0, L.gy);
    vstore8(2 * ((Q.xz * px + Q.yz * py + Q.zz * pz) + Q.zw), 0, L.gz);
    vstore8(convert_float8(t), 0, L.depth);
    vstore8(convert_float8(vx), 0, L.vx);
    vstore8(convert_float8(vy), 0, L.vy);
    vstore8(convert_float8(vz), 0, L.vz);
    vstore8((float8)(albedo.x), 0, L.ax);
    vstore8((float8)(albedo.y), 0, L.ay);
    vstore8((float8)(albedo.z), 0, L.az);
    vstore8((float8)(albedo.w), 0, L.aw);
    vstore8((int8)(q), 0, L.quadric);
    vstore8((int8)(prim), 0, L.primitive);
    pixel_lanes_store(out, view, pix, RAY_LANES, &L);
    return true;
}

/* One work-item per RAY_LANES pixels of a row (all in one tile: TILE is a multiple of RAY_LANES):
 * the lanes' rays are traced (trace_lanes), then their hits are shaded as float8 vectors
 * (pixel_lanes_store: shade_light8 and shade_encode8, the resolve pass's lighting and encoding). */
__kernel void raytrace(__global const quadric_rec *qs, __global const tape_op *arena, __global const int *qlist,
                       __global const real *cull, real3 blo, real3 bhi, __global const real2 *tile_z, __global const int4 *slabs,
                       PRIMITIVE_TABLE, __global const view_rec *view, PIXEL_OUTPUTS)
{
    int i = get_global_id(1), j0 = get_global_id(0) * RAY_LANES;
    int W = view->width;
    if (i >= view->height || j0 >= W) return;
    int lanes = min(RAY_LANES, W - j0);
    int tile = (i / TILE) * ((W + TILE - 1) / TILE) + j0 / TILE;
    /* a tile whose slabs hold no tape has no surface: its pixels are background (most of a
     * frame round a compact model), without the rays' set-up */
    int listed = 0;
#if SLABS == 8 /* the eight int4 records as two int16 loads: their .y are components 1, 5, 9, 13 */
    int16 sa = vload16(0, (__global const int *)(slabs + tile * SLABS)),
          sb = vload16(1, (__global const int *)(slabs + tile * SLABS));
    int16 so = sa | sb;
    listed = so.s1 | so.s5 | so.s9 | so.sd;
#else
    for (int s = 0; s < SLABS; ++s) listed |= slabs[tile * SLABS + s].y;
#endif
    if (!listed) {
        pixel_store_background(PIXEL_OUT, view, i * W + j0, lanes);
        return;
    }
    real3 e = view_eye(view), forward = vload3(0, view->forward);
    real slack = ROUNDING_ULPS * REAL_EPS * (length(blo) + length(bhi) + length(e));
    pixel_lanes px;
    pixel_lanes_clear(&px);
    int last_prim = -2;
    float4 albedo = 0;
    /* the lanes' view rays: view_ray's arithmetic (d00 + j dx + i dy, then normalize) on real8;
     * lanes past the row's end get +z */
    real8 dx, dy, dz;
    view_dirs8(view, i, j0, &dx, &dy, &dz);
    realmask8 shown = convert_realmask8((int8)(0, 1, 2, 3, 4, 5, 6, 7) < (int8)(lanes));
    dx = select((real8)0, dx, shown);
    dy = select((real8)0, dy, shown);
    dz = select((real8)1, dz, shown);
    pixel_normalize8(&dx, &dy, &dz);
    int qid[8];
    real depth[8];
    trace_lanes(qs, arena, qlist, cull, blo, bhi, tile_z, slabs, tile, e, forward, slack, lanes, dx, dy, dz, qid, depth);
    if (lanes == RAY_LANES && trace_uniform_store(PIXEL_OUT, qs, PRIMITIVE_TABLE_ARGS, view, e, qid,
                                                  depth, dx, dy, dz, i * W + j0))
        return;
    real vx[8], vy[8], vz[8];
    vstore8(dx, 0, vx); vstore8(dy, 0, vy); vstore8(dz, 0, vz);
    int prim_of[8] = {PRIMITIVE_UNKNOWN, PRIMITIVE_UNKNOWN, PRIMITIVE_UNKNOWN, PRIMITIVE_UNKNOWN,
                      PRIMITIVE_UNKNOWN, PRIMITIVE_UNKNOWN, PRIMITIVE_UNKNOWN, PRIMITIVE_UNKNOWN};
    int last_q = -1;
    quadric Q;
    for (int l = 0; l < lanes; ++l) {
        int q = qid[l];
        if (q < 0) continue;
        real3 v = (real3)(vx[l], vy[l], vz[l]);
        real t = depth[l];
        real3 p = e + t * v;
        int prim = prim_of[l];
        owner_rec o = owners[q];
        if (prim == PRIMITIVE_UNKNOWN && o.count > 1)
            prim = lanes_primitive(PRIMITIVE_TABLE_ARGS, qs, qid, depth, vx, vy, vz, e, p, prim_of, l, lanes);
        else if (prim < 0) /* one owner: primitive_at's answer without the call */
            prim = o.count == 1 ? owner_list[o.first] : primitive_at(PRIMITIVE_TABLE_ARGS, qs, q, p);
        if (prim != last_prim) { /* neighbours mostly show one primitive */
            albedo = shade_albedo(view, pixel_color(prims, prim));
            last_prim = prim;
        }
        if (q != last_q) { /* and mostly one quadric */
            Q = quadric_load(qs, q);
            last_q = q;
        }
        pixel_lanes_set(&px, l, (float)t, q, prim, albedo, quadric_gradient(Q, p), convert_float3(v));
    }
    pixel_lanes_store(PIXEL_OUT, view, i * W + j0, lanes, &px);
}
