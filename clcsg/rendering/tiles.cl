/* The exact ray tracer's spatial structure (driven by clcsg/rendering/raytracer.py): the tape
 * pruned per screen tile, then per depth slab of each tile, so a ray meets only the leaves near
 * the part of it being walked (far parts of the solid do not ride along with near ones).
 *
 * prune_supertiles, prune_tiles: the tape pruned per super-tile of SUPER_TILE x SUPER_TILE
 * tiles (as below, from the full tape), then per tile from its super-tile's tape, within the
 * super-tile's depth range (so each tile prune reads a tape already cut to its neighbourhood).
 *
 * prune_tiles: one work-item per TILE x TILE pixel tile.  The tile's rays, between the depths
 * z0, z1 (along the view's forward axis) at which they can meet the scene bound (the bound's
 * corner depths narrowed per axis to the tile's frustum, tile_depths), fill the
 * frustum hull of 8 points (the tile's corner directions d, whose forward component is 1,
 * scaled to z0 and z1); the tape pruned over that box cut by the scene bound is written to the
 * tile arena, and [z0, z1] to the tile's depth range.
 *
 * prune_slabs: one work-item per tile: the tile's range split into SLABS equal depth slabs, each
 * slab's tape pruned over its frustum box from the tape of the slab pair (quad, ...) holding it,
 * down a binary tree from the tile's tape (in scratch blocks), and copied compactly to the slab
 * arena; its leaves are renumbered to the slab's own quadric list (leaf row a = index
 * into that list), so the ray kernel can keep one ray-quadric solve per listed quadric in
 * private memory.  Below a node whose tape is short (SLAB_DIRECT_ROWS) the slabs are pruned
 * from its tape directly.
 *
 * Both follow the sampler's overflow protocol: rows reserved with an atomic add and written
 * only below the capacity; the host grows the buffers and re-runs.
 */
#include "tiles.h"
/* a node of the slab tree whose tape has at most this many rows skips the levels below it: its
 * slabs are pruned from its tape directly (an intermediate prune of a tape this short costs
 * more than the rows it would save the slabs' prunes) */
#define SLAB_DIRECT_ROWS 8
#ifndef SUPER_TILE
#error "SUPER_TILE (tiles per super-tile side) is set by the driver, clcsg/rendering/raytracer.py"
#endif

/* The tape t (n rows) pruned over region g into rows reserved in the arena: the record (first
 * row, rows) in the arena, or (0, 0) where the arena is full (the host sees it in counters[0]
 * and re-runs); counters[1] counts the prune's evaluations. */
inline int2 prune_to_arena(__global const quadric_rec *qs, __global const tape_op *t, int n, const prune_region *g,
                           __global tape_op *arena, uint cap_arena, __global volatile uint *counters)
{
    uint evals = 0;
    uint base = atomic_add(&counters[0], (uint)(n + 1));
    if (base + (uint)(n + 1) > cap_arena) return (int2)(0, 0);
    int first, count;
    tape_prune(t, n, qs, g, -1, arena + base, &first, &count, &evals);
    atomic_add(&counters[1], evals);
    return (int2)((int)base + first, count);
}

/* Super-tile (sx, sy) of SUPER_TILE x SUPER_TILE tiles: its depth range (the bound's corner
 * depths narrowed to its frustum) and the full tape pruned over its frustum box, into the
 * super-tile arena. */
__kernel void prune_supertiles(__global const quadric_rec *qs, __global const tape_op *tape, int n,
                               __global const view_rec *view, real3 blo, real3 bhi,
                               __global tape_op *arena, uint cap_arena, __global volatile uint *counters,
                               __global int2 *sup, __global real2 *sup_z)
{
    int sx = get_global_id(0), sy = get_global_id(1), span = TILE * SUPER_TILE;
    int nsx = (view->width + span - 1) / span, nsy = (view->height + span - 1) / span;
    if (sx >= nsx || sy >= nsy) return;
    real3 e = view_eye(view), fw = vload3(0, view->forward);
    real z0 = INFINITY, z1 = -INFINITY; /* depth range of the bound along the forward axis */
    for (int m = 0; m < 8; ++m) {
        real3 c = (real3)((m & 1) ? bhi.x : blo.x, (m & 2) ? bhi.y : blo.y, (m & 4) ? bhi.z : blo.z);
        real z = dot(c - e, fw);
        z0 = fmin(z0, z);
        z1 = fmax(z1, z);
    }
    z0 = fmax(z0, (real)0);
    int st = sy * nsx + sx;
    sup[st] = (int2)(0, 0);
    sup_z[st] = (real2)(z0, z0 - 1);
    if (!(z1 > 0)) return;
    real2 zt = tile_depths(view, sx, sy, span, z0, z1, blo, bhi);
    prune_region g;
    if (!(zt.x <= zt.y) || !tile_box(view, sx, sy, span, zt.x, zt.y, blo, bhi, &g)) return;
    sup_z[st] = zt;
    sup[st] = prune_to_arena(qs, tape, n, &g, arena, cap_arena, counters);
}

__kernel void prune_tiles(__global const quadric_rec *qs, __global const tape_op *sup_arena,
                          __global const int2 *sup, __global const real2 *sup_z,
                          __global const view_rec *view, real3 blo, real3 bhi,
                          __global tape_op *arena, uint cap_arena, __global volatile uint *counters,
                          __global int2 *tiles, __global real2 *tile_z)
{
    int tx = get_global_id(0), ty = get_global_id(1);
    int ntx = (view->width + TILE - 1) / TILE, nty = (view->height + TILE - 1) / TILE;
    if (tx >= ntx || ty >= nty) return;
    int span = TILE * SUPER_TILE, nsx = (view->width + span - 1) / span;
    int st = (ty / SUPER_TILE) * nsx + tx / SUPER_TILE;
    int tile = ty * ntx + tx;
    real2 zs = sup_z[st];
    tiles[tile] = (int2)(0, 0);
    tile_z[tile] = zs;
    int2 rec = sup[st];
    __global const tape_op *tape = sup_arena + rec.x;
    int n = rec.y;
    if (n == 0 || (n == 1 && tape[0].op == OP_CONST)) return;
    /* within the super-tile's range, so the tile's box lies in the super-tile's */
    real2 zt = tile_depths(view, tx, ty, TILE, zs.x, zs.y, blo, bhi);
    prune_region g;
    if (!(zt.x <= zt.y) || !tile_box(view, tx, ty, TILE, zt.x, zt.y, blo, bhi, &g)) return;
    tile_z[tile] = zt;
    int2 got = prune_to_arena(qs, tape, n, &g, arena, cap_arena, counters);
    if (got.y == 0) return;
    atomic_add(&counters[2], (uint)got.y);
    uint leaves = 0;
    for (int k = 0; k < got.y; ++k) leaves += arena[got.x + k].op == OP_LEAF;
    atomic_max(&counters[3], leaves);
    tiles[tile] = got;
}

/* Renumber the leaves of rows [0, n) to an own list of quadrics (written to qlist, at most n);
 * returns the list's length. */
inline int slab_quadrics(__global tape_op *rows, int n, __global int *qlist)
{
    int nq = 0;
    for (int k = 0; k < n; ++k) {
        if (rows[k].op != OP_LEAF) continue;
        int q = rows[k].a, m = 0;
        while (m < nq && qlist[m] != q) ++m;
        if (m == nq) qlist[nq++] = q;
        rows[k].a = m;
    }
    return nq;
}

/* A tile's statistics, added to the counters once per tile instead of by three atomics per
 * prune on a cache line every work-item shares: prune evaluations, slab rows, the longest
 * slab quadric list. */
typedef struct {
    uint evals, rows, nq_max;
} slab_tally;

/* Slab s of a tile: its tape pruned from the tile's tape t (n rows) into scratch (n + 1 rows),
 * then copied compactly to the slab arena with its own quadric list.  Returns the record
 * (first row, rows, first listed quadric, quadrics); rows = 0 where the slab misses the bound
 * or the solid has no surface in it (or the arena is full: the host sees it in the counters). */
inline int4 prune_slab(__global const quadric_rec *qs, __global const tape_op *t, int n, const prune_region *g,
                       __global tape_op *scratch, __global tape_op *arena, uint cap_arena, __global int *qlist,
                       uint cap_qlist, __global volatile uint *counters, slab_tally *tally)
{
    int first, count;
    tape_prune(t, n, qs, g, -1, scratch, &first, &count, &tally->evals);
    if (count == 1 && scratch[first].op == OP_CONST) return (int4)(0);
    uint base = atomic_add(&counters[0], (uint)count);
    uint qbase = atomic_add(&counters[1], (uint)count);
    if (base + (uint)count > cap_arena || qbase + (uint)count > cap_qlist) return (int4)(0);
    for (int k = 0; k < count; ++k) arena[base + k] = scratch[first + k];
    int nq = slab_quadrics(arena + base, count, qlist + qbase);
    tally->rows += (uint)count;
    tally->nq_max = max(tally->nq_max, (uint)nq);
    return (int4)((int)base, count, (int)qbase, nq);
}

/* Depth range of node k of level l of a tile's slab tree (level SLAB_LEVELS: the slabs): the
 * union of the slab ranges below it, so a node's frustum box holds its children's. */
inline real2 slab_node_range(real2 z, int l, int k)
{
    int span = SLABS >> l;
    return (real2)(slab_range(z, k * span).x, slab_range(z, (k + 1) * span - 1).y);
}

/* One work-item per tile: slabs[tile * SLABS + s] for its SLABS slabs.  The slabs are the leaves
 * of a binary tree over the tile's depth range: each node's tape is pruned from its parent's
 * (the root: the tile tape) over the node's frustum box, which lies in the parent's, so each
 * prune reads a tape already cut to about twice its own region instead of the whole tile's.
 * The tree is walked depth first; level l >= 1 keeps its current node's tape in block l - 1 of
 * SLAB_LEVELS scratch blocks of the tile tape's length + SLAB_LEVELS rows reserved in `scratch` (a
 * pruned tape is at most its parent's rows + 1), the slabs go through the last block (prune_slab). */
__kernel void prune_slabs(__global const quadric_rec *qs, __global const tape_op *tile_arena,
                          __global const int2 *tiles, __global const real2 *tile_z,
                          __global const view_rec *view, real3 blo, real3 bhi, int n_tiles,
                          __global tape_op *scratch, uint cap_scratch, __global tape_op *arena, uint cap_arena,
                          __global int *qlist, uint cap_qlist, __global volatile uint *counters,
                          __global int4 *slabs)
{
    int tile = get_global_id(0);
    if (tile >= n_tiles) return;
    for (int s = 0; s < SLABS; ++s) slabs[tile * SLABS + s] = (int4)(0);
    int ntx = (view->width + TILE - 1) / TILE;
    int2 tt = tiles[tile];
    int n = tt.y;
    if (n == 0 || (n == 1 && tile_arena[tt.x].op == OP_CONST)) return;
    uint block = (uint)(n + SLAB_LEVELS); /* each level's prune adds at most a root COPY */
    uint sbase = atomic_add(&counters[5], SLAB_LEVELS * block);
    if (sbase + SLAB_LEVELS * block > cap_scratch) return;
    __global tape_op *work = scratch + sbase;
    /* the current node's tape per level (level 0: the tile's); rows = 0: nothing below it */
    __global const tape_op *node[SLAB_LEVELS];
    int rows[SLAB_LEVELS];
    node[0] = tile_arena + tt.x;
    rows[0] = n;
    real2 z = tile_z[tile];
    int tx = tile % ntx, ty = tile / ntx;
    slab_tally tally = {0, 0, 0};
    for (int s = 0; s < SLABS; ++s) {
        /* levels whose node changes from slab s - 1 to s: below the highest flipped bit */
        int l0 = s == 0 ? 1 : SLAB_LEVELS - (31 - clz(s & -s));
        for (int l = l0; l < SLAB_LEVELS; ++l) {
            rows[l] = 0;
            int np = rows[l - 1];
            if (np == 0) continue;
            if (np <= SLAB_DIRECT_ROWS) { /* its slabs are pruned from this tape directly */
                node[l] = node[l - 1];
                rows[l] = np;
                continue;
            }
            real2 zn = slab_node_range(z, l, s >> (SLAB_LEVELS - l));
            prune_region g;
            if (!tile_box(view, tx, ty, TILE, zn.x, zn.y, blo, bhi, &g)) continue;
            int first, count;
            __global tape_op *out = work + (l - 1) * block;
            tape_prune(node[l - 1], np, qs, &g, -1, out, &first, &count, &tally.evals);
            if (count == 1 && out[first].op == OP_CONST) continue;
            node[l] = out + first;
            rows[l] = count;
        }
        int np = rows[SLAB_LEVELS - 1];
        if (np == 0) continue;
        real2 zs = slab_range(z, s);
        prune_region g;
        if (!tile_box(view, tx, ty, TILE, zs.x, zs.y, blo, bhi, &g)) continue;
        slabs[tile * SLABS + s] = prune_slab(qs, node[SLAB_LEVELS - 1], np, &g, work + (SLAB_LEVELS - 1) * block,
                                             arena, cap_arena, qlist, cap_qlist, counters, &tally);
    }
    if (tally.evals) atomic_add(&counters[2], tally.evals);
    if (tally.rows) atomic_add(&counters[3], tally.rows);
    if (tally.nq_max) atomic_max(&counters[4], tally.nq_max);
}
