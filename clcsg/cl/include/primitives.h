/* Which primitive a surface point belongs to (for its color and primitive id).
 * Records: prim_rec, owner_rec (layout.h); the host side is clcsg/cl/records.py. */
#ifndef CLCSG_PRIMITIVES_H
#define CLCSG_PRIMITIVES_H
#include "quadric.h"

/* The primitive table as kernel / function parameters, and the same names as arguments
 * (clcsg/cl/records.py passes its buffers in this order). */
#define PRIMITIVE_TABLE                                                                       \
    __global const owner_rec *owners, __global const int *owner_list, __global const prim_rec *prims, \
        __global const int2 *prim_lits
#define PRIMITIVE_TABLE_ARGS owners, owner_list, prims, prim_lits

/* The first primitive instance, in tree order, whose own boundary holds p on quadric q: it
 * has q as a literal and all its other literals hold at p.  Where rounding leaves none, the
 * first owner of q; -1 if q has none. */
inline int primitive_at(PRIMITIVE_TABLE, __global const quadric_rec *qs, int q, real3 p)
{
    owner_rec o = owners[q];
    for (int k = 0; k < o.count; ++k) {
        int pi = owner_list[o.first + k];
        prim_rec pr = prims[pi];
        bool holds = true;
        for (int l = 0; l < pr.lit_count && holds; ++l) {
            int2 lit = prim_lits[pr.lit_first + l];
            if (lit.x != q) holds = lit.y * quadric_value(quadric_load(qs, lit.x), p) <= 0;
        }
        if (holds) return pi;
    }
    return o.count ? owner_list[o.first] : -1;
}

#endif
