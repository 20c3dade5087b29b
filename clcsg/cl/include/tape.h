/* Tape interpreters and tape pruning (the float64 reference is clcsg/compile/interpret.py;
 * the instruction set is documented in clcsg/compile/tape.py).
 *
 * A tape is `n` rows (op, out, a, b) in global memory; its result is register ops[n-1].out.
 * TAPE_REGS (a build option from the host's register allocation) sizes the private register
 * files.  Op codes OP_* come from clcsg/cl/constants.py.
 *
 * Substitution: the leaves on quadric `self_q` take, on the two sides of that quadric, the
 * constants they have just on its negative side (leaf (q, s) holds there iff s = +1) and just
 * on its positive side.  Pass self_q = -1 for plain evaluation.
 */
#ifndef CLCSG_TAPE_H
#define CLCSG_TAPE_H
#include "quadric.h"

#ifndef TAPE_REGS
#define TAPE_REGS 8
#endif

typedef struct {
    int op, out, a, b;
} tape_op;

/* A tape's rows other than OP_LEAF, on register file r of any type: AND and OR by the
 * interpreter's operators, COPY, and CONST (a != 0: TRUE) as its values of TRUE and FALSE.
 * Used as `if (o.op == OP_LEAF) { ... } else TAPE_BOOLEAN_ROW(...);`. */
#define TAPE_BOOLEAN_ROW(r, o, AND, OR, TRUE_VALUE, FALSE_VALUE)          \
    if ((o).op == OP_AND)                                                 \
        (r)[(o).out] = AND((r)[(o).a], (r)[(o).b]);                       \
    else if ((o).op == OP_OR)                                             \
        (r)[(o).out] = OR((r)[(o).a], (r)[(o).b]);                        \
    else if ((o).op == OP_COPY)                                           \
        (r)[(o).out] = (r)[(o).a];                                        \
    else                                                                  \
        (r)[(o).out] = (o).a ? (TRUE_VALUE) : (FALSE_VALUE)
#define BITS_AND(x, y) ((x) & (y))
#define BITS_OR(x, y) ((x) | (y))

/* Dead-row elimination on rows out[0..m) of any address space whose result is register root:
 * walking back from the last row, a row is kept only if a later kept row (or the result) reads
 * its output; a COPY r <- r keeps r read.  The kept rows are packed at the end, out[w..m). */
#define TAPE_KEEP_LIVE_ROWS(out, m, root, w)                              \
    do {                                                                  \
        uchar needed_[TAPE_REGS];                                         \
        for (int r_ = 0; r_ < TAPE_REGS; ++r_) needed_[r_] = 0;           \
        needed_[root] = 1;                                                \
        (w) = (m);                                                        \
        for (int k_ = (m) - 1; k_ >= 0; --k_) {                           \
            tape_op o_ = (out)[k_];                                       \
            if (!needed_[o_.out]) continue;                               \
            if (!(o_.op == OP_COPY && o_.a == o_.out)) needed_[o_.out] = 0; \
            if (o_.op == OP_AND || o_.op == OP_OR) {                      \
                needed_[o_.a] = 1;                                        \
                needed_[o_.b] = 1;                                        \
            } else if (o_.op == OP_COPY) {                                \
                needed_[o_.a] = 1;                                        \
            }                                                             \
            (out)[--(w)] = o_;                                            \
        }                                                                 \
    } while (0)

CLCSG_INLINE real literal_distance(__global const quadric_rec *qs, int q, int sign, real3 p)
{
    /* d(-Q, p) = -d(Q, p) */
    return sign * quadric_distance(quadric_load(qs, q), qs[q].lam_min, qs[q].lam_max, p);
}

/* (f-, f+) over reals: leaves are s d_q(p) (eqs. 10-12), TRUE = -inf, FALSE = +inf,
 * AND = max, OR = min.  *leaves counts the leaf distances evaluated. */
inline real2 tape_eval(__global const tape_op *t, int n, __global const quadric_rec *qs, real3 p, int self_q,
                       uint *leaves)
{
    real2 r[TAPE_REGS];
    for (int k = 0; k < n; ++k) {
        tape_op o = t[k];
        if (o.op == OP_LEAF) {
            if (o.a == self_q) {
                r[o.out] = o.b > 0 ? (real2)(-INFINITY, INFINITY) : (real2)(INFINITY, -INFINITY);
            } else {
                real d = literal_distance(qs, o.a, o.b, p);
                r[o.out] = (real2)(d, d);
                ++*leaves;
            }
        } else
            TAPE_BOOLEAN_ROW(r, o, fmax, fmin, (real2)(-INFINITY, -INFINITY), (real2)(INFINITY, INFINITY));
    }
    return r[t[n - 1].out];
}

/* d_q(p) = min(max(f-, -f+), max(-f-, f+)): negative iff p (on quadric q) is on the CSG
 * surface, |d_q| a radius on q within which that classification holds. */
CLCSG_INLINE real surface_distance(real2 f) { return fmin(fmax(f.x, -f.y), fmax(-f.x, f.y)); }

/* Membership, two bits: bit 0 on the negative side of self_q, bit 1 on the positive side
 * (both equal without substitution).  Closed solids: Q = 0 counts as inside. */
inline uint tape_member(__global const tape_op *t, int n, __global const quadric_rec *qs, real3 p, int self_q)
{
    uchar r[TAPE_REGS];
    for (int k = 0; k < n; ++k) {
        tape_op o = t[k];
        if (o.op == OP_LEAF) {
            if (o.a == self_q)
                r[o.out] = o.b > 0 ? 1 : 2;
            else
                r[o.out] = o.b * quadric_value(quadric_load(qs, o.a), p) <= 0 ? 3 : 0;
        } else
            TAPE_BOOLEAN_ROW(r, o, BITS_AND, BITS_OR, 3, 0);
    }
    return r[t[n - 1].out];
}

/* tape_member at eight points (px, py, pz) at once: per lane the membership bits of
 * tape_member, one vector per register (quadric_value's arithmetic per leaf). */
inline uchar8 tape_member8(__global const tape_op *t, int n, __global const quadric_rec *qs, real8 px, real8 py,
                           real8 pz, int self_q)
{
    uchar8 r[TAPE_REGS];
    for (int k = 0; k < n; ++k) {
        tape_op o = t[k];
        if (o.op == OP_LEAF) {
            if (o.a == self_q) {
                r[o.out] = (uchar8)(o.b > 0 ? 1 : 2);
            } else {
                quadric q = quadric_load(qs, o.a);
                real8 gx = q.xx * px + q.xy * py + q.xz * pz + 2 * q.xw;
                real8 gy = q.xy * px + q.yy * py + q.yz * pz + 2 * q.yw;
                real8 gz = q.xz * px + q.yz * py + q.zz * pz + 2 * q.zw;
                real8 v = px * gx + py * gy + pz * gz + q.ww;
                r[o.out] = convert_uchar8(o.b * v <= 0) & (uchar8)(3);
            }
        } else
            TAPE_BOOLEAN_ROW(r, o, BITS_AND, BITS_OR, (uchar8)(3), (uchar8)(0));
    }
    return r[t[n - 1].out];
}

/* The side the solid is on wherever the tape says "surface" on self_q: the tape is a monotone
 * Boolean function of its leaves, so if every leaf on self_q has polarity +1 the membership on
 * the negative side is never below the one on the positive side (the solid is on the negative
 * side: +1), if all have -1 the opposite (-1); mixed polarities give 0 (it may vary). */
inline int tape_self_polarity(__global const tape_op *t, int n, int self_q)
{
    int seen = 0;
    for (int k = 0; k < n; ++k) {
        if (t[k].op != OP_LEAF || t[k].a != self_q) continue;
        if (seen && seen != t[k].b) return 0;
        seen = t[k].b;
    }
    return seen;
}

/* ---- pruning ------------------------------------------------------------------------------ */

/* A region to prune over: the oriented box c + sum_m u_m a_m (|u_m| <= 1) grown by a ball of
 * radius rho.  Plane leaves are tested exactly on it (a linear function's range over the box
 * is its value at c +- sum_m |g.a_m|), other leaves by the conservative distance at c against
 * rho + the box's half-diagonal. */
typedef struct {
    real3 c, a0, a1, a2;
    real rho;
    /* optional (on_patch != 0; zero-initialized otherwise): the points of the sampled quadric
     * in the region are a heightfield patch p(x, y) = pc + x ui + y uj + (t(x, y) - t_c) uk,
     * |x| <= hx, |y| <= hy (cell coordinates from its center), slopes dt/dx in sx, dt/dy in sy
     * (intervals) and p in the box above; pruning for a decision over the patch may use it */
    int on_patch;
    real3 pc, ui, uj, uk;
    real hx, hy;
    real2 sx, sy;
} prune_region;

/* a state is two bits: bit 0 "can be TRUE", bit 1 "can be FALSE" (over the region), so AND
 * and OR of states are bitwise: an AND can be TRUE where both operands can, FALSE where either
 * can (st_and6); an OR the other way round (st_or6) */
#define ST_T 1
#define ST_F 2
#define ST_LIVE 3
/* register state: bits 0-1 the tape state, 2-3 side -, 4-5 side + (each ST_*) */
#define ST_PACK(t, m, p) ((uchar)((t) | ((m) << 2) | ((p) << 4)))
#define ST_CAN_T 0x15 /* the "can be TRUE" bits of the three fields */
#define ST_CAN_F 0x2A
#define ST_TAPE(s) ((s) & 3)
#define ST_MINUS(s) (((s) >> 2) & 3)
#define ST_PLUS(s) (((s) >> 4) & 3)
/* bit 6: the register's pruned value depends on a leaf of self_q; without it both sides agree
 * at every point of the region (no surface of self_q there), even where the value is live */
#define ST_SELF 64

/* the three fields of two packed states combined (bit 6 dropped) */
inline uchar st_and6(uchar a, uchar b) { return ((a & b) & ST_CAN_T) | ((a | b) & ST_CAN_F); }
inline uchar st_or6(uchar a, uchar b) { return ((a | b) & ST_CAN_T) | ((a & b) & ST_CAN_F); }

/* What the leaf tests need of a region that does not depend on the leaf, computed once per
 * pruning pass (prune_forward) instead of once per leaf, and only when a leaf is tested.  The
 * rounding scales take 1-norms, which bound the lengths from above: the slack only grows, and
 * no square root is taken for them. */
typedef struct {
    real slack;     /* rounding slack of the box and ball tests */
    real half_diag; /* |a0|^2 + |a1|^2 + |a2|^2, square-rooted */
    real pl;        /* 1 + |pc| + |a0| + |a1| + |a2| (on_patch regions; 1-norms) */
} prune_consts;

CLCSG_INLINE real norm1(real3 v) { return fabs(v.x) + fabs(v.y) + fabs(v.z); }

CLCSG_INLINE prune_consts prune_consts_of(const prune_region *g)
{
    prune_consts k;
    real axes = norm1(g->a0) + norm1(g->a1) + norm1(g->a2);
    k.slack = ROUNDING_ULPS * REAL_EPS * (fabs(g->rho) + norm1(g->c) + axes);
    k.half_diag = sqrt(dot(g->a0, g->a0) + dot(g->a1, g->a1) + dot(g->a2, g->a2));
    k.pl = g->on_patch ? 1 + norm1(g->pc) + axes : 0;
    return k;
}

/* The state of a leaf over the region: ST_T (holds everywhere), ST_F or ST_LIVE. */
inline int leaf_over_region(__global const quadric_rec *qs, int q, int sign, const prune_region *g,
                            const prune_consts *k)
{
    __global const real *c = qs[q].coef;
    real slack = k->slack;
    if (c[0] == 0 && c[1] == 0 && c[2] == 0 && c[4] == 0 && c[5] == 0 && c[7] == 0) {
        /* a plane: sign Q(x) = g.x + w, |grad| = |g| */
        real3 gr = 2 * sign * (real3)(c[3], c[6], c[8]);
        real v = dot(gr, g->c) + sign * c[9];
        real spread = fabs(dot(gr, g->a0)) + fabs(dot(gr, g->a1)) + fabs(dot(gr, g->a2)) + (g->rho + slack) * length(gr);
        return v > spread ? ST_F : v < -spread ? ST_T : ST_LIVE;
    }
    /* |d| >= reach decides the leaf; its sign is that of sign Q(c) */
    real f;
    if (!quadric_distance_at_least(quadric_load(qs, q), qs[q].lam_min, qs[q].lam_max, g->c,
                                   g->rho + k->half_diag + slack, &f))
        return ST_LIVE;
    return sign * f >= 0 ? ST_F : ST_T;
}

/* interval product and the interval of grad Q . u over the box (c + sum_m u_m a_m): the gradient
 * 2 (A p + w) is linear in p, so grad Q . u = 2 ((A u) . p + w . u) has the exact range
 * value(c) +- 2 sum_m |(A u) . a_m| */
CLCSG_INLINE real2 interval_mul(real2 a, real2 b)
{
    real p0 = a.x * b.x, p1 = a.x * b.y, p2 = a.y * b.x, p3 = a.y * b.y;
    return (real2)(fmin(fmin(p0, p1), fmin(p2, p3)), fmax(fmax(p0, p1), fmax(p2, p3)));
}

inline real2 gradient_along(quadric Q, real3 u, const prune_region *g)
{
    real3 Au = quadric_Ap(Q, u);
    real v = 2 * (dot(Au, g->c) + dot(quadric_minus_b(Q), u));
    real e = 2 * (fabs(dot(Au, g->a0)) + fabs(dot(Au, g->a1)) + fabs(dot(Au, g->a2)));
    return (real2)(v - e, v + e);
}

/* The state of leaf (q, sign) over a heightfield patch by the mean value form: f(x, y) =
 * sign Q(p(x, y)) has f(x, y) - f(0, 0) = grad f(xi) . (x, y) for a xi in the cell, and
 * df/dx = grad Q . ui + t_x grad Q . uk lies in G_i + S_x G_k (interval arithmetic with signs:
 * G_* from gradient_along, S_x the slope interval), likewise y.  So f lies in
 * f(pc) +- (max |df/dx| hx + max |df/dy| hy) over the patch: the bound is first-order exact in
 * the derivative, so a cell at distance D from the curve Q = 0 is decided once D exceeds
 * O(h^2), where the box and ball tests need D of the order of the cell's size h.  The rounding
 * slack covers Q(pc) and pc's own error. */
inline int leaf_over_patch(__global const quadric_rec *qs, int q, int sign, const prune_region *g,
                           const prune_consts *k)
{
    quadric Q = quadric_load(qs, q);
    real2 gk = gradient_along(Q, g->uk, g);
    real2 fx = gradient_along(Q, g->ui, g) + interval_mul(g->sx, gk);
    real2 fy = gradient_along(Q, g->uj, g) + interval_mul(g->sy, gk);
    real spread = fmax(fabs(fx.x), fabs(fx.y)) * g->hx + fmax(fabs(fy.x), fabs(fy.y)) * g->hy;
    real v = sign * quadric_value(Q, g->pc);
    __global const real *c = qs[q].coef;
    real cs = 0;
    for (int m = 0; m < 10; ++m) cs += fabs(c[m]);
    real pl = k->pl;
    spread += ROUNDING_ULPS * REAL_EPS * (4 * cs * pl * pl + length(quadric_gradient(Q, g->pc)) * pl);
    if (!isfinite(spread)) return ST_LIVE;
    return v > spread ? ST_F : v < -spread ? ST_T : ST_LIVE;
}

/* Leaf states of a forward pass kept for a second pass over the same tape and region (2 bits
 * a row, for rows below PRUNE_MEMO_ROWS): mode 1 records them, mode 2 replays them, so a split
 * that counts its children's rows and then writes them tests each leaf once.  Mode 3 records
 * them and what became of each row (`acts`, 2 bits a row: 0 dropped, 1 kept as it is, 2 and 3
 * kept as a COPY of its operand a or b), from which tape_pruned_private builds the pruned tape
 * without a second pass. */
#define PRUNE_MEMO_ROWS 256
typedef struct {
    uint bits[PRUNE_MEMO_ROWS / 16], acts[PRUNE_MEMO_ROWS / 16];
    int mode;
} prune_memo;

/* The forward pass of pruning t (n rows) over g with self_q substituted: leaves of one sign over
 * g become constants, constants are folded (TRUE absorbs OR, FALSE absorbs AND, the neutral
 * operand drops out and the result becomes a COPY of the other).  Rows that stay are written to
 * out[0..*m) when out is not null and counted in *m either way (each input row gives at most one
 * row, so *m <= n); *last is the output register of the last row kept (-1: none).  Returns the
 * root's packed state.  *evals counts the leaves tested against the region; `memo` (or null)
 * records or replays the leaves' states. */
inline uchar prune_forward(__global const tape_op *t, int n, __global const quadric_rec *qs,
                           const prune_region *g, int self_q, __global tape_op *out, int *m, int *last,
                           uint *evals, prune_memo *memo)
{
    uchar st[TAPE_REGS];
    bool write = out != 0;
    int memo_mode = memo ? memo->mode : 0;
    if (memo_mode & 1) /* the words of the rows there are: the states of no others are read */
        for (int w = 0; w < (min(n, PRUNE_MEMO_ROWS) + 15) >> 4; ++w) {
            memo->bits[w] = 0;
            if (memo_mode == 3) memo->acts[w] = 0;
        }
    int k_out = 0, lst = -1;
    prune_consts pk;
    bool have_pk = false;
    for (int k = 0; k < n; ++k) {
        tape_op o = t[k];
        tape_op keep = o;
        bool kept = false;
        uint act = 1;
        if (o.op == OP_LEAF) {
            if (o.a == self_q) {
                st[o.out] = (o.b > 0 ? ST_PACK(ST_LIVE, ST_T, ST_F) : ST_PACK(ST_LIVE, ST_F, ST_T)) | ST_SELF;
                kept = true;
            } else {
                int s;
                if (memo_mode == 2 && k < PRUNE_MEMO_ROWS) {
                    s = (memo->bits[k >> 4] >> (2 * (k & 15))) & 3;
                } else {
                    ++*evals;
                    if (!have_pk) {
                        pk = prune_consts_of(g);
                        have_pk = true;
                    }
                    s = leaf_over_region(qs, o.a, o.b, g, &pk);
                    if (s == ST_LIVE && g->on_patch) s = leaf_over_patch(qs, o.a, o.b, g, &pk);
                    if ((memo_mode & 1) && k < PRUNE_MEMO_ROWS) memo->bits[k >> 4] |= (uint)s << (2 * (k & 15));
                }
                st[o.out] = ST_PACK(s, s, s);
                kept = s == ST_LIVE;
            }
        } else if (o.op == OP_AND || o.op == OP_OR) {
            uchar sa = st[o.a], sb = st[o.b];
            bool is_and = o.op == OP_AND;
            int absorb = is_and ? ST_F : ST_T, neutral = is_and ? ST_T : ST_F;
            /* all three fields at once; the tape field is then absorb, the other operand's
             * (one operand neutral) or live, as the cases below need */
            uchar r = is_and ? st_and6(sa, sb) : st_or6(sa, sb);
            int ta = ST_TAPE(sa), tb = ST_TAPE(sb);
            if (ta == absorb || tb == absorb) {
                st[o.out] = r;
            } else if (ta == neutral || tb == neutral) {
                int src = ta == neutral ? o.b : o.a;
                kept = ST_TAPE(st[src]) == ST_LIVE && src != o.out;
                keep = (tape_op){OP_COPY, o.out, src, 0};
                act = ta == neutral ? 3 : 2;
                st[o.out] = r | (st[src] & ST_SELF);
            } else {
                kept = true;
                st[o.out] = r | ((sa | sb) & ST_SELF);
            }
        } else if (o.op == OP_COPY) {
            st[o.out] = st[o.a];
            kept = ST_TAPE(st[o.a]) == ST_LIVE && o.a != o.out;
        } else {
            st[o.out] = o.a ? ST_PACK(ST_T, ST_T, ST_T) : ST_PACK(ST_F, ST_F, ST_F);
        }
        if (kept) {
            if (write) out[k_out] = keep;
            if (memo_mode == 3 && k < PRUNE_MEMO_ROWS) memo->acts[k >> 4] |= act << (2 * (k & 15));
            ++k_out;
            lst = o.out;
        }
    }
    *m = k_out;
    *last = lst;
    return st[t[n - 1].out];
}

/* The decision of a root state: +1 both sides known and equal (no surface of self_q in the
 * region), -1 known and different (all of self_q in it is surface), 0 otherwise. */
CLCSG_INLINE int prune_decision(uchar s)
{
    return (ST_MINUS(s) == ST_LIVE || ST_PLUS(s) == ST_LIVE) ? 0 : ST_MINUS(s) == ST_PLUS(s) ? 1 : -1;
}

/* The constant of a root state: 0 FALSE, 1 TRUE, -1 not constant. */
inline int prune_constant(uchar s) { return ST_TAPE(s) == ST_LIVE ? -1 : ST_TAPE(s) == ST_T; }

/* Membership bits (as tape_member: bit 0 the negative side of self_q, bit 1 the positive
 * side) of a decided root state: they hold at every point of the region. */
inline uint prune_member_bits(uchar s) { return (ST_MINUS(s) == ST_T ? 1u : 0u) | (ST_PLUS(s) == ST_T ? 2u : 0u); }

/* Case analysis over the leaves pruning left live (the states `memo` recorded in mode 1 over
 * a region): where is there no surface of self_q in the region?  Three-valued pruning cannot
 * see that OR(L, NOT L) is TRUE: where two solids of a union meet in a face on quadric q (a
 * fillet strip glued into a corner, the removed corner of a plate), the tape over a cell across
 * that face keeps q live, though every point has the same membership on both sides of self_q.
 * So with k <= CASE_QUADRICS distinct live quadrics (listed in live[] as met), each point of the
 * region is in one of 2^k cases c (bit m of c: live quadric m positive there; its leaf (q, s)
 * holds iff s Q < 0), and one pass evaluates all cases at once: a register is a truth table,
 * one bit per case, per side of self_q (CASE_TABLE(m): the cases where live quadric m is
 * positive), the constant leaves come from the memo, self_q is substituted.  Returns the cases
 * whose two sides differ (0: no open piece of the region is surface), or ~0u if there are more
 * live quadrics or the memo does not cover the tape.
 * Left out are points where a live quadric is exactly 0 (both its leaves hold there): curves on
 * self_q's patch (quadrics are unique, so q is not self_q), and a surface point on such a curve
 * with no surface on either side of it bounds no area, so the surface (the closure of its 2-D
 * pieces, which the coverage guarantee is about) has none there.  Cases that no point has make
 * the answer conservative, never wrong; the caller may drop some it knows no point has. */
#define CASE_QUADRICS 5
/* the cases with bit m set: 0xAAAAAAAA, 0xCCCCCCCC, 0xF0F0F0F0, 0xFF00FF00, 0xFFFF0000 */
#define CASE_TABLE(m) (~(~0u / ((1u << (1u << (m))) + 1u)))
inline uint surface_cases(__global const tape_op *t, int n, int self_q, const prune_memo *memo, int live[CASE_QUADRICS],
                          int *k_out)
{
    if (n > PRUNE_MEMO_ROWS) return ~0u;
    uint2 reg[TAPE_REGS]; /* (negative side, positive side) of self_q, a bit per case */
    int k = 0;
    for (int r = 0; r < n; ++r) {
        tape_op o = t[r];
        if (o.op == OP_LEAF) {
            if (o.a == self_q) {
                reg[o.out] = o.b > 0 ? (uint2)(~0u, 0u) : (uint2)(0u, ~0u);
                continue;
            }
            int s = (memo->bits[r >> 4] >> (2 * (r & 15))) & 3;
            if (s != ST_LIVE) {
                reg[o.out] = (uint2)(s == ST_T ? ~0u : 0u);
                continue;
            }
            int m = 0;
            while (m < k && live[m] != o.a) ++m;
            if (m == k) {
                if (k == CASE_QUADRICS) return ~0u;
                live[k++] = o.a;
            }
            uint pos = CASE_TABLE(m);
            reg[o.out] = (uint2)(o.b < 0 ? pos : ~pos);
        } else
            TAPE_BOOLEAN_ROW(reg, o, BITS_AND, BITS_OR, (uint2)(~0u), (uint2)(0u));
    }
    *k_out = k;
    uint2 root = reg[t[n - 1].out];
    return root.x ^ root.y;
}

/* Rows that tape_prune_write writes for (t, g, self_q): the forward pass's rows plus a root
 * COPY if the last one does not define the root; 1 for a constant tape.  Reserving exactly
 * this many rows stores a pruned tape as what pruning keeps, never the parent's length.
 * *state is the root's packed state (prune_decision, prune_constant, prune_member_bits). */
inline int tape_prune_rows_memo(__global const tape_op *t, int n, __global const quadric_rec *qs,
                                const prune_region *g, int self_q, uchar *state, uint *evals, prune_memo *memo)
{
    int m, last;
    uchar s = prune_forward(t, n, qs, g, self_q, 0, &m, &last, evals, memo);
    *state = s;
    if (prune_constant(s) >= 0) return 1;
    return m + (last != t[n - 1].out);
}

inline int tape_prune_rows(__global const tape_op *t, int n, __global const quadric_rec *qs, const prune_region *g,
                           int self_q, uchar *state, uint *evals)
{
    return tape_prune_rows_memo(t, n, qs, g, self_q, state, evals, 0);
}

/* Prune tape t (n rows) over region g with self_q substituted; returns the decision
 * (prune_decision).  If `out` is not null the pruned tape is written there, within the first
 * tape_prune_rows(...) rows (at most n + 1): the forward pass writes rows from the front, a
 * backward pass (liveness over registers) keeps the rows whose result is read and packs them at
 * the end of that span; *first (offset in `out`) and *count give the result.  A constant tape
 * is one CONST row.  *evals counts the leaves tested against the region. */
inline int tape_prune_memo(__global const tape_op *t, int n, __global const quadric_rec *qs, const prune_region *g,
                           int self_q, __global tape_op *out, int *first, int *count, uint *evals, prune_memo *memo)
{
    int m, last;
    int root = t[n - 1].out;
    uchar s = prune_forward(t, n, qs, g, self_q, out, &m, &last, evals, memo);
    int decided = prune_decision(s);
    if (out == 0) return decided;
    if (ST_TAPE(s) != ST_LIVE) {
        out[0] = (tape_op){OP_CONST, root, ST_TAPE(s) == ST_T, 0};
        *first = 0;
        *count = 1;
        return decided;
    }
    if (last != root) out[m++] = (tape_op){OP_COPY, root, root, 0};
    int w; /* rows are packed downwards from the end of the forward rows (w > k always) */
    TAPE_KEEP_LIVE_ROWS(out, m, root, w);
    *first = w;
    *count = m - w;
    return decided;
}

inline int tape_prune(__global const tape_op *t, int n, __global const quadric_rec *qs, const prune_region *g,
                      int self_q, __global tape_op *out, int *first, int *count, uint *evals)
{
    return tape_prune_memo(t, n, qs, g, self_q, out, first, count, evals, 0);
}

/* The pruned tape into exactly the rows tape_prune_rows counted (`state` from it): a constant
 * tape is written as its CONST row without the forward pass (whose rows would not fit). */
inline void tape_prune_write_memo(__global const tape_op *t, int n, __global const quadric_rec *qs,
                                  const prune_region *g, int self_q, uchar state, __global tape_op *out, int *first,
                                  int *count, uint *evals, prune_memo *memo)
{
    int k = prune_constant(state);
    if (k >= 0) {
        out[0] = (tape_op){OP_CONST, t[n - 1].out, k, 0};
        *first = 0;
        *count = 1;
        return;
    }
    tape_prune_memo(t, n, qs, g, self_q, out, first, count, evals, memo);
}

/* tape_prune_write_memo after a count pass that gave `rows` (its leaf states in `memo`), or,
 * where the count is the tape's own length, the tape copied as it is without the second pass:
 * any tape that is exact over the region serves, the tape itself is, and pruning would save no
 * row (where it keeps every row it keeps them unchanged: an operation is only rewritten where a
 * leaf became constant). */
inline void tape_write_pruned(__global const tape_op *t, int n, int rows, __global const quadric_rec *qs,
                              const prune_region *g, int self_q, uchar state, __global tape_op *out, int *first,
                              int *count, uint *evals, prune_memo *memo)
{
    if (rows == n) {
        for (int m = 0; m < n; ++m) out[m] = t[m];
        *first = 0;
        *count = n;
        return;
    }
    memo->mode = 2;
    tape_prune_write_memo(t, n, qs, g, self_q, state, out, first, count, evals, memo);
}

/* The tape tape_write_pruned writes after a count pass over t (n <= PRUNE_MEMO_ROWS rows) that
 * gave `rows` and `state` and recorded its rows' fates in `memo` (mode 3), built in private
 * memory out[0..rows) from those fates, with no second pass: the same rows, *first and *count. */
inline void tape_pruned_private(__global const tape_op *t, int n, int rows, uchar state, const prune_memo *memo,
                                tape_op *out, int *first, int *count)
{
    int root = t[n - 1].out;
    *first = 0;
    if (rows == n) {
        for (int m = 0; m < n; ++m) out[m] = t[m];
        *count = n;
        return;
    }
    int k = prune_constant(state);
    if (k >= 0) {
        out[0] = (tape_op){OP_CONST, root, k, 0};
        *count = 1;
        return;
    }
    int m = 0, last = -1;
    for (int r = 0; r < n; ++r) {
        uint a = (memo->acts[r >> 4] >> (2 * (r & 15))) & 3;
        if (a == 0) continue;
        tape_op o = t[r];
        out[m++] = a == 1 ? o : (tape_op){OP_COPY, o.out, a == 2 ? o.a : o.b, 0};
        last = o.out;
    }
    if (last != root) out[m++] = (tape_op){OP_COPY, root, root, 0};
    int w;
    TAPE_KEEP_LIVE_ROWS(out, m, root, w);
    *first = w;
    *count = m - w;
}

inline void tape_prune_write(__global const tape_op *t, int n, __global const quadric_rec *qs,
                             const prune_region *g, int self_q, uchar state, __global tape_op *out, int *first,
                             int *count, uint *evals)
{
    tape_prune_write_memo(t, n, qs, g, self_q, state, out, first, count, evals, 0);
}

#endif
