/* Exact CSG ray tracer on the tape (the reference every render is tested against), with the
 * tape pruned per screen tile (driven by clcsg/rendering/raytracer.py).
 *
 * prune_tiles: one work-item per TILE x TILE pixel tile.  The tile's rays, between the depths
 * at which they can meet the scene bound, fill the frustum hull of 8 points (the tile's corner
 * directions d, whose forward component is 1, scaled to the depth range [z0, z1]); the tape
 * pruned over that box cut by the scene bound is written to the tile arena (overflow: the host
 * grows it and re-runs).
 *
 * raytrace: one work-item per pixel, ray e + t v (unit v).  Walk the roots of the tile tape's
 * leaves in increasing t > 0 inside the scene bound (where the tile's pruned tape is exact;
 * the solid lies in the bound) (the next root is the smallest one past the current; roots at
 * the same t are all tried): a root t on quadric q is a hit iff the tape's membership at
 * p = e + t v with q substituted differs between q's two sides, i.e. p is on the CSG
 * surface.  No 1-D interval CSG and no "outside view" assumption: views from inside the solid
 * are exact.  The winning depth is refined by one more solve from the hit point (accurate in
 * float as well).  Outputs depth (+inf on background), quadric and primitive ids and RGBA8
 * shaded with shade.h from the quadric's normal, in the hit primitive's colour.
 */
#include "tape.h"
#include "pixel.h"

#ifndef TILE
#error "TILE (the tile size in pixels) is set by the driver, clcsg/rendering/raytracer.py"
#endif

__kernel void prune_tiles(__global const quadric_rec *qs, __global const tape_op *tape, int n,
                          __global const view_rec *view, real3 blo, real3 bhi,
                          __global tape_op *arena, uint cap_arena, __global volatile uint *counters,
                          __global int2 *tiles)
{
    int tx = get_global_id(0), ty = get_global_id(1);
    int ntx = (view->width + TILE - 1) / TILE, nty = (view->height + TILE - 1) / TILE;
    if (tx >= ntx || ty >= nty) return;
    real3 e = view_eye(view), fw = vload3(0, view->forward);
    /* depth range of the bound along the forward axis */
    real z0 = INFINITY, z1 = -INFINITY;
    for (int m = 0; m < 8; ++m) {
        real3 c = (real3)((m & 1) ? bhi.x : blo.x, (m & 2) ? bhi.y : blo.y, (m & 4) ? bhi.z : blo.z);
        real z = dot(c - e, fw);
        z0 = fmin(z0, z);
        z1 = fmax(z1, z);
    }
    z0 = fmax(z0, (real)0);
    int tile = ty * ntx + tx;
    if (!(z1 > 0)) {
        tiles[tile] = (int2)(0, 0);
        return;
    }
    int i0 = ty * TILE, i1 = min(i0 + TILE, view->height) - 1;
    int j0 = tx * TILE, j1 = min(j0 + TILE, view->width) - 1;
    real3 lo = (real3)(INFINITY), hi = (real3)(-INFINITY);
    for (int m = 0; m < 4; ++m) {
        int i = (m & 1) ? i1 : i0, j = (m & 2) ? j1 : j0;
        real3 d = vload3(0, view->d00) + (real)j * vload3(0, view->dx) + (real)i * vload3(0, view->dy);
        real3 p0 = e + z0 * d, p1 = e + z1 * d;
        lo = fmin(lo, fmin(p0, p1));
        hi = fmax(hi, fmax(p0, p1));
    }
    lo = fmax(lo, blo);
    hi = fmin(hi, bhi);
    if (any(lo > hi)) {
        tiles[tile] = (int2)(0, 0);
        return;
    }
    real3 h = (real)0.5 * (hi - lo);
    prune_region g = {(real)0.5 * (lo + hi), (real3)(h.x, 0, 0), (real3)(0, h.y, 0), (real3)(0, 0, h.z), 0};
    uint evals = 0;
    uint base = atomic_add(&counters[0], (uint)(n + 1));
    if (base + (uint)(n + 1) > cap_arena) return;
    int first, count;
    tape_prune(tape, n, qs, &g, -1, arena + base, &first, &count, &evals);
    atomic_add(&counters[1], evals);
    atomic_add(&counters[2], (uint)count);
    tiles[tile] = (int2)((int)base + first, count);
}

/* [t0, t1] of the ray e + t v inside the box [lo, hi] (t0 > t1: it misses) */
inline real2 ray_box(real3 e, real3 v, real3 lo, real3 hi)
{
    real3 inv = 1 / v; /* +-inf for zero components: the slab test still works */
    real3 a = (lo - e) * inv, b = (hi - e) * inv;
    real3 tn = fmin(a, b), tf = fmax(a, b);
    return (real2)(fmax(fmax(tn.x, tn.y), tn.z), fmin(fmin(tf.x, tf.y), tf.z));
}

__kernel void raytrace(__global const quadric_rec *qs, __global const tape_op *arena, real3 blo, real3 bhi,
                       __global const int2 *tiles, PRIMITIVE_TABLE, __global const view_rec *view,
                       PIXEL_OUTPUTS)
{
    int i, j;
    int pix = pixel_index(view, &i, &j);
    if (pix < 0) return;
    int ntx = (view->width + TILE - 1) / TILE;
    int2 tt = tiles[(i / TILE) * ntx + j / TILE];
    __global const tape_op *tape = arena + tt.x;
    int n = tt.y;
    real3 e = view_eye(view);
    real3 v = view_ray(view, i, j);

    real best = INFINITY;
    int best_q = -1;
    /* the tile's tape is exact only inside the tile's region: the roots inside the bound */
    real slack = ROUNDING_ULPS * REAL_EPS * (length(blo) + length(bhi) + length(e));
    real2 seg = ray_box(e, v, blo - slack, bhi + slack);
    real t_cur = fmax(seg.x, (real)0);
    t_cur = t_cur > 0 ? t_cur * (1 - 4 * REAL_EPS) : 0; /* a root exactly at the entry is kept */
    bool searching = n > 0 && !(n == 1 && tape[0].op == OP_CONST) && seg.x <= seg.y;
    while (searching) {
        /* the smallest root past t_cur over the tape's leaves */
        real t_next = INFINITY;
        for (int k = 0; k < n; ++k) {
            tape_op o = tape[k];
            if (o.op != OP_LEAF) continue;
            real r[2];
            int nr = quadric_intersect(quadric_load(qs, o.a), e, v, &r[0], &r[1]);
            for (int m = 0; m < nr; ++m)
                if (r[m] > t_cur && r[m] < t_next) t_next = r[m];
        }
        if (!isfinite(t_next) || t_next > seg.y) break;
        real3 p = e + t_next * v;
        for (int k = 0; k < n && best_q < 0; ++k) {
            tape_op o = tape[k];
            if (o.op != OP_LEAF) continue;
            real r[2];
            int nr = quadric_intersect(quadric_load(qs, o.a), e, v, &r[0], &r[1]);
            bool at = (nr > 0 && r[0] == t_next) || (nr > 1 && r[1] == t_next);
            if (!at) continue;
            uint bits = tape_member(tape, n, qs, p, o.a);
            if (bits == 1 || bits == 2) {
                best = t_next;
                best_q = o.a;
            }
        }
        if (best_q >= 0) break;
        t_cur = t_next;
    }

    pixel_out out = PIXEL_OUT;
    if (best_q < 0) {
        pixel_miss(out, view, pix);
        return;
    }
    /* refine the depth by solving again from the hit, Q(p0 + tau v) = 0, p0 = e + best v, and
     * taking the root nearest 0: Q(p0) is then tiny and the roots are as accurate as the splat
     * renderer's near-sample solve (matters in float; a no-op up to rounding in double) */
    quadric q = quadric_load(qs, best_q);
    real3 p0 = e + best * v;
    real tau[2];
    int nr = quadric_intersect(q, p0, v, &tau[0], &tau[1]);
    if (nr > 0) {
        real d = (nr > 1 && fabs(tau[1]) < fabs(tau[0])) ? tau[1] : tau[0];
        if (fabs(d) < 1e-3 * best) best += d;
    }
    pixel_hit(out, view, pix, PRIMITIVE_TABLE_ARGS, qs, best_q, e + best * v, best, v);
}
