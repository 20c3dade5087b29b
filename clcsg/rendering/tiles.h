/* Tiles and depth slabs of the exact ray tracer, shared by its pruning kernels (tiles.cl) and
 * the ray kernel (raytrace.cl). */
#ifndef CLCSG_TILES_H
#define CLCSG_TILES_H
#include "tape.h"
#include "shade.h"

#ifndef TILE
#error "TILE (the tile size in pixels) is set by the driver, clcsg/rendering/raytracer.py"
#endif
#ifndef SLABS
#error "SLABS (depth slabs per tile) is set by the driver, clcsg/rendering/raytracer.py"
#endif
#if !defined(SLAB_LEVELS) || (1 << SLAB_LEVELS) != SLABS
#error "SLAB_LEVELS (log2 of SLABS) is set by the driver, clcsg/rendering/raytracer.py"
#endif

/* Depth range [za, zb] of slab s of a tile's range z = [z0, z1] (equal slabs; the last ends
 * at z1 exactly, so the slabs cover the range). */
inline real2 slab_range(real2 z, int s)
{
    real dz = (z.y - z.x) / SLABS;
    return (real2)(z.x + s * dz, s + 1 == SLABS ? z.y : z.x + (s + 1) * dz);
}

/* The depth range [z0, z1] (along the view's forward axis) narrowed to where the frustum of tile
 * (tx, ty) of span x span pixels can meet the box [blo, bhi].  A point e + z d of the frustum (d affine in the pixel, so
 * each component d_k between its least and greatest value dmin_k, dmax_k at the tile's corner
 * pixels) is in the box only if, per axis, e_k + z [dmin_k, dmax_k] meets [lo_k, hi_k]:
 * e_k + z dmax_k >= lo_k and e_k + z dmin_k <= hi_k, each a half-line of z.  A relaxation (d_k
 * taken per axis), so a superset of the true range, widened by a relative 2^-20 for the
 * rounding of the divisions; z1 < z0 when no depth is left. */
inline real2 tile_depths(__global const view_rec *view, int tx, int ty, int span, real z0, real z1, real3 blo,
                         real3 bhi)
{
    real3 e = view_eye(view);
    int i0 = ty * span, i1 = min(i0 + span, view->height) - 1;
    int j0 = tx * span, j1 = min(j0 + span, view->width) - 1;
    real3 dmin = (real3)(INFINITY), dmax = (real3)(-INFINITY);
    for (int m = 0; m < 4; ++m) {
        int i = (m & 1) ? i1 : i0, j = (m & 2) ? j1 : j0;
        real3 d = vload3(0, view->d00) + (real)j * vload3(0, view->dx) + (real)i * vload3(0, view->dy);
        dmin = fmin(dmin, d);
        dmax = fmax(dmax, d);
    }
    real za = z0, zb = z1;
    real lo[3] = {blo.x - e.x, blo.y - e.y, blo.z - e.z}, hi[3] = {bhi.x - e.x, bhi.y - e.y, bhi.z - e.z};
    real dl[3] = {dmin.x, dmin.y, dmin.z}, dh[3] = {dmax.x, dmax.y, dmax.z};
    for (int k = 0; k < 3; ++k) {
        /* z dh >= lo */
        if (dh[k] > 0) za = fmax(za, lo[k] / dh[k]);
        else if (dh[k] < 0) zb = fmin(zb, lo[k] / dh[k]);
        else if (lo[k] > 0) zb = -INFINITY;
        /* z dl <= hi */
        if (dl[k] > 0) zb = fmin(zb, hi[k] / dl[k]);
        else if (dl[k] < 0) za = fmax(za, hi[k] / dl[k]);
        else if (hi[k] < 0) zb = -INFINITY;
    }
    if (!(za <= zb)) return (real2)(z0, z0 - 1);
    real pad = ldexp(fabs(za) + fabs(zb), -20);
    return (real2)(fmax(z0, za - pad), fmin(z1, zb + pad));
}

/* The box around the frustum of tile (tx, ty) of span x span pixels between depths z0 and z1, cut by [blo, bhi];
 * false if they do not meet. */
inline bool tile_box(__global const view_rec *view, int tx, int ty, int span, real z0, real z1, real3 blo,
                     real3 bhi, prune_region *g)
{
    real3 e = view_eye(view);
    int i0 = ty * span, i1 = min(i0 + span, view->height) - 1;
    int j0 = tx * span, j1 = min(j0 + span, view->width) - 1;
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
    if (any(lo > hi)) return false;
    real3 h = (real)0.5 * (hi - lo);
    *g = (prune_region){(real)0.5 * (lo + hi), (real3)(h.x, 0, 0), (real3)(0, h.y, 0), (real3)(0, 0, h.z), 0};
    return true;
}

#endif
