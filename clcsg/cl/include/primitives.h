/* Which primitive a surface point belongs to (for its color and primitive id).
 * Records: prim_rec, owner_rec (layout.h), the instance program as tape_op rows (tape.h); the
 * host side is clcsg/cl/records.py and clcsg/compile/instance_program.py.
 *
 * The rule: a point p on the CSG surface, carried by quadric q, takes the first primitive
 * instance, in tree order, that *bounds the solid* at p: its own boundary holds p (q is one of
 * its literals and its other literals hold at p) and switching its membership on one side of
 * q changes the solid's membership on that side.  Memberships on the two sides of q are the
 * substitution of tape.h (bit 0: just on q's negative side, bit 1: its positive side); the
 * solid over the instances is the instance program.  An instance whose boundary holds p is the
 * only one whose membership differs between the sides, so where only one holds p it bounds the
 * solid (p being surface) and the program is not run; where several do, one pass evaluates the
 * program for the unswitched memberships and up to INSTANCE_LANES - 1 switched candidates at
 * once, two bits per lane.  Where rounding leaves none, the first owner of q; -1 if q has none.
 */
#ifndef CLCSG_PRIMITIVES_H
#define CLCSG_PRIMITIVES_H
#include "tape.h"

#ifndef INSTANCE_REGS
#error "INSTANCE_REGS comes from clcsg/cl/constants.py"
#endif
#define INSTANCE_LANES 16

/* The primitive table as kernel / function parameters, and the same names as arguments
 * (clcsg/cl/records.py passes its buffers in this order). */
#define PRIMITIVE_TABLE                                                                       \
    __global const owner_rec *owners, __global const int *owner_list, __global const prim_rec *prims, \
        __global const int2 *prim_lits, __global const real4 *prim_box, __global const tape_op *inst_tape, \
        int inst_rows
#define PRIMITIVE_TABLE_ARGS owners, owner_list, prims, prim_lits, prim_box, inst_tape, inst_rows

/* Instance pi's membership at p on quadric q, two bits as tape_member (closed: Q = 0 inside).
 * Outside the instance's padded box (prim_box: lo, hi) it is 0 without evaluating a literal. */
inline uint instance_sides(PRIMITIVE_TABLE, __global const quadric_rec *qs, int pi, int q, real3 p)
{
    real4 lo = prim_box[2 * pi], hi = prim_box[2 * pi + 1];
    if (any(p < lo.xyz) || any(p > hi.xyz)) return 0;
    prim_rec pr = prims[pi];
    uint m = 3;
    for (int l = 0; l < pr.lit_count && m; ++l) {
        int2 lit = prim_lits[pr.lit_first + l];
        if (lit.x == q)
            m &= lit.y > 0 ? 1u : 2u;
        else if (lit.y * quadric_value(quadric_load(qs, lit.x), p) > 0)
            m = 0;
    }
    return m;
}

/* The instance program at p on q, lane 0 plain and lane c (1 <= c < nc) with instance cand[c]
 * switched (its two bits complemented); returns the lanes packed two bits each. */
inline uint instance_lanes(PRIMITIVE_TABLE, __global const quadric_rec *qs, int q, real3 p,
                           const int *cand, int nc)
{
    uint r[INSTANCE_REGS];
    const uint all = nc >= INSTANCE_LANES ? 0xffffffffu : (1u << (2 * nc)) - 1u;
    for (int k = 0; k < inst_rows; ++k) {
        tape_op o = inst_tape[k];
        if (o.op == OP_LEAF) {
            uint m = instance_sides(PRIMITIVE_TABLE_ARGS, qs, o.a, q, p);
            uint w = m * 0x55555555u & all; /* m in every lane */
            for (int c = 1; c < nc; ++c)
                if (cand[c] == o.a) w ^= 3u << (2 * c);
            r[o.out] = o.b > 0 ? w : ~w & all;
        } else
            TAPE_BOOLEAN_ROW(r, o, BITS_AND, BITS_OR, all, 0);
    }
    return r[inst_tape[inst_rows - 1].out];
}

/* Does instance pi's own boundary hold p on q (q a literal, its other literals hold)? */
inline bool instance_holds(PRIMITIVE_TABLE, __global const quadric_rec *qs, int pi, int q, real3 p)
{
    uint m = instance_sides(PRIMITIVE_TABLE_ARGS, qs, pi, q, p);
    return m == 1 || m == 2;
}

/* The first of candidates cand[1..nc) whose switching changes the program's value; -1 if none. */
inline int instance_bounding(PRIMITIVE_TABLE, __global const quadric_rec *qs, int q, real3 p,
                             const int *cand, int nc)
{
    uint lanes = instance_lanes(PRIMITIVE_TABLE_ARGS, qs, q, p, cand, nc);
    for (int c = 1; c < nc; ++c)
        if (((lanes >> (2 * c)) & 3u) != (lanes & 3u)) return cand[c];
    return -1;
}

inline int primitive_at(PRIMITIVE_TABLE, __global const quadric_rec *qs, int q, real3 p)
{
    owner_rec o = owners[q];
    if (o.count == 1) return owner_list[o.first]; /* the loop below gives it, held or not */
    int cand[INSTANCE_LANES];
    int nc = 1, first = -1, holding = 0;
    for (int k = 0; k < o.count; ++k) {
        int pi = owner_list[o.first + k];
        if (!instance_holds(PRIMITIVE_TABLE_ARGS, qs, pi, q, p)) continue;
        if (inst_rows == 0) return pi;
        if (first < 0) first = pi;
        ++holding;
        cand[nc++] = pi;
        if (nc == INSTANCE_LANES) {
            int b = instance_bounding(PRIMITIVE_TABLE_ARGS, qs, q, p, cand, nc);
            if (b >= 0) return b;
            nc = 1;
        }
    }
    if (holding == 1) return first; /* the only instance whose membership changes across q */
    if (nc > 1) {
        int b = instance_bounding(PRIMITIVE_TABLE_ARGS, qs, q, p, cand, nc);
        if (b >= 0) return b;
    }
    return first >= 0 ? first : o.count ? owner_list[o.first] : -1;
}

/* primitive_at's answer at every point of the box [lo, hi] on quadric q (points on q), or
 * PRIMITIVE_VARIES where it may differ between them.  Per owner of q, over the box: it never
 * holds (the box misses its padded box, or one of its literals other than q fails everywhere,
 * leaf_over_region), surely holds (the box is inside its padded box and every such literal
 * holds everywhere), or either.  The answer is fixed if no owner can hold (the first owner), or
 * exactly one can and it surely holds or is the first owner (held, it is the only one; not
 * held, none is, and the first owner is the answer).  The tests are the tile pruning's, so the
 * box's points get what primitive_at gives each of them. */
#define PRIMITIVE_VARIES (-2)
inline int primitive_over_box(PRIMITIVE_TABLE, __global const quadric_rec *qs, int q, real3 lo, real3 hi)
{
    owner_rec o = owners[q];
    if (o.count <= 1) return o.count ? owner_list[o.first] : -1;
    real3 h = (real)0.5 * (hi - lo);
    prune_region g = {(real)0.5 * (lo + hi), (real3)(h.x, 0, 0), (real3)(0, h.y, 0), (real3)(0, 0, h.z), 0};
    prune_consts k = prune_consts_of(&g);
    int possible = -1, n_possible = 0;
    bool sure = false, first = false;
    for (int m = 0; m < o.count; ++m) {
        int pi = owner_list[o.first + m];
        real4 blo = prim_box[2 * pi], bhi = prim_box[2 * pi + 1];
        if (any(hi < blo.xyz) || any(lo > bhi.xyz)) continue;
        bool never = false, always = all(lo >= blo.xyz) && all(hi <= bhi.xyz);
        prim_rec pr = prims[pi];
        for (int l = 0; l < pr.lit_count && !never; ++l) {
            int2 lit = prim_lits[pr.lit_first + l];
            if (lit.x == q) continue;
            int st = leaf_over_region(qs, lit.x, lit.y, &g, &k);
            never = st == ST_F;
            always &= st == ST_T;
        }
        if (never) continue;
        if (++n_possible > 1) return PRIMITIVE_VARIES;
        possible = pi;
        sure = always;
        first = m == 0;
    }
    if (n_possible == 0) return owner_list[o.first];
    return sure || first ? possible : PRIMITIVE_VARIES;
}

#endif
