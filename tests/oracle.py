"""A float64 numpy reference ray caster for DNF scenes (the oracle the kernels are tested against).

Scene input (``scene`` below) is anything :func:`parts` understands: a
:class:`~clcsg.host.dnf.Dnf`, a ``(quadrics, terms)`` pair (quadric matrices (U, 4, 4) and a
list of terms, each a tuple of ``(quadric index, sign)`` literals meaning ``sign * Q(x) <= 0``),
a :class:`~clcsg.csg.Shape` or a :class:`~clcsg.scene.Scene` (normalized first).

The algorithm is the one of the paper's comparison ray tracer, written literally:

* per ray and per DNF term, every root of every literal's quadric along the ray
  (:meth:`Quadric.intersect_line`, paper eqs. 5 and 6);
* a root t > 0 is a hit of the term if every *other* literal of the term holds at
  p = o + t v (``sign * Q(p) <= tol * |grad Q(p)|``; with the default ``tol = 0`` this is the
  exact float64 test ``sign * Q(p) <= 0``; the literal itself is excluded, it is 0 up to
  rounding);
* the nearest hit over all terms wins (for a viewer outside the solid the first boundary point
  of a union of closed terms is the nearest first boundary point of a term).

Public API::

    cast(scene, origins, directions, tol=0.0) -> Hits       # any leading shape
    cast_camera(scene, camera, tol=0.0) -> Hits             # shape (H, W)
    fragile(scene, origins, directions, rel=1e-9) -> bool   # pixels a tie can decide
    surface_points(scene, n_dirs=32, res=96) -> SurfacePoints
    fibonacci_sphere(n) -> (n, 3)

Directions are normalized by ``cast``; depth is the distance along the unit ray.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from clcsg.model.quadric import Quadric

CHUNK = 1 << 17


# -- scene input ----------------------------------------------------------------------------------


def parts(scene):
    """(quadrics (U, 4, 4) float64, terms: list of tuples of (quadric index, sign))."""
    from clcsg.model.csg import Shape
    from clcsg.compile.dnf import Dnf
    from clcsg.model.scene import Scene

    if isinstance(scene, (Shape, Scene)):
        from clcsg.model.scene import as_scene

        scene = as_scene(scene).normalize()
    if isinstance(scene, Dnf):
        return np.asarray(scene.quadrics, dtype=np.float64), [tuple(t) for t in scene.terms]
    quadrics, terms = scene
    q = np.asarray(quadrics, dtype=np.float64).reshape(-1, 4, 4)
    return q, [tuple((int(i), int(s)) for i, s in t) for t in terms]


def _value(m, p):
    """Q(p) for one matrix m (4, 4) and points (N, 3) (eq. 3)."""
    A = m[:3, :3]
    b = -m[:3, 3]
    return np.einsum("ni,ij,nj->n", p, A, p) - 2.0 * p @ b + m[3, 3]


def _grad_norm(m, p):
    return np.linalg.norm(2.0 * (p @ m[:3, :3] + m[:3, 3]), axis=-1)


def _holds(m, s, p, tol):
    """sign * Q(p) <= tol * |grad Q(p)| (exact sign test for tol == 0)."""
    v = s * _value(m, p)
    if tol == 0.0:
        return v <= 0.0
    return v <= tol * _grad_norm(m, p)


# -- the ray caster -------------------------------------------------------------------------------


@dataclass
class Hits:
    """Nearest CSG surface hit per ray; every array has the rays' leading shape.

    depth: distance along the unit ray (+inf: miss); quadric / term: indices (-1: miss);
    sign: polarity of the hit literal (0: miss); point, normal: hit point and the solid's
    outward unit normal ``sign * grad Q / |grad Q|`` (NaN: miss); second: depth of the nearest
    hit on a *different* quadric (+inf if none), to find pixels where two surfaces tie.
    """

    depth: np.ndarray
    quadric: np.ndarray
    term: np.ndarray
    sign: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    second: np.ndarray

    @property
    def mask(self) -> np.ndarray:
        return np.isfinite(self.depth)

    def ties(self, rel=1e-9) -> np.ndarray:
        """Rays whose winning surface is within ``rel`` (relative depth) of another quadric's."""
        with np.errstate(invalid="ignore"):
            return self.mask & (self.second - self.depth <= rel * self.depth)


def _cast_flat(Q, terms, o, d, tol):
    n = len(o)
    best = np.full(n, np.inf)
    second = np.full(n, np.inf)
    bq = np.full(n, -1, dtype=np.int64)
    bt = np.full(n, -1, dtype=np.int64)
    bs = np.zeros(n, dtype=np.int64)
    for ti, lits in enumerate(terms):
        for li, (qi, s) in enumerate(lits):
            t1, t2 = Quadric(Q[qi]).intersect_line(o, d)
            for t in (t1, t2):
                ok = np.isfinite(t) & (t > 0.0)
                # skip rays that cannot improve either the best or the second-best depth
                ok &= t < second
                idx = np.flatnonzero(ok)
                if not len(idx):
                    continue
                tt = t[idx]
                p = o[idx] + tt[:, None] * d[idx]
                good = np.ones(len(idx), dtype=bool)
                for lj, (qj, sj) in enumerate(lits):
                    if lj != li:
                        good &= _holds(Q[qj], sj, p, tol)
                idx, tt = idx[good], tt[good]
                if not len(idx):
                    continue
                same = bq[idx] == qi
                better = tt < best[idx]
                # same quadric: only the best depth can improve
                upd_same = same & better
                best[idx[upd_same]] = tt[upd_same]
                bt[idx[upd_same]] = ti
                bs[idx[upd_same]] = s
                # another quadric in front: the old best becomes the second
                upd_new = ~same & better
                j = idx[upd_new]
                second[j] = best[j]
                best[j] = tt[upd_new]
                bq[j] = qi
                bt[j] = ti
                bs[j] = s
                # another quadric behind the best: maybe the second
                upd_sec = ~same & ~better
                j = idx[upd_sec]
                second[j] = np.minimum(second[j], tt[upd_sec])
    hit = np.isfinite(best)
    point = np.full((n, 3), np.nan)
    normal = np.full((n, 3), np.nan)
    point[hit] = o[hit] + best[hit, None] * d[hit]
    for qi in np.unique(bq[hit]):
        sel = np.flatnonzero(bq == qi)
        g = 2.0 * (point[sel] @ Q[qi][:3, :3] + Q[qi][:3, 3])
        g *= bs[sel, None]
        with np.errstate(invalid="ignore", divide="ignore"):
            normal[sel] = g / np.linalg.norm(g, axis=-1, keepdims=True)
    return best, bq, bt, bs, point, normal, second


def cast(scene, origins, directions, tol=0.0) -> Hits:
    """Cast rays ``origins + t * directions`` (t > 0) against ``scene``; shapes (..., 3)."""
    Q, terms = parts(scene)
    o = np.asarray(origins, dtype=np.float64)
    d = np.asarray(directions, dtype=np.float64)
    o, d = np.broadcast_arrays(o, d)
    shape = o.shape[:-1]
    o = o.reshape(-1, 3)
    d = d.reshape(-1, 3)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    outs = [_cast_flat(Q, terms, o[k : k + CHUNK], d[k : k + CHUNK], float(tol)) for k in range(0, len(o), CHUNK)]
    if not outs:
        outs = [_cast_flat(Q, terms, o, d, float(tol))]
    cat = [np.concatenate([x[i] for x in outs]) for i in range(7)]
    best, bq, bt, bs, point, normal, second = cat
    return Hits(
        best.reshape(shape),
        bq.reshape(shape),
        bt.reshape(shape),
        bs.reshape(shape),
        point.reshape(shape + (3,)),
        normal.reshape(shape + (3,)),
        second.reshape(shape),
    )


def cast_camera(scene, camera, tol=0.0) -> Hits:
    """:func:`cast` for every pixel of a :class:`~clcsg.camera.Camera`: arrays of shape (H, W)."""
    o, d = camera.rays()
    return cast(scene, o, d, tol)


def scene_scale(scene) -> float:
    """A length scale of the scene: the largest |coordinate| of the term bounds, else 1."""
    from clcsg.compile.dnf import Dnf

    if isinstance(scene, Dnf) and scene.n_terms:
        return float(max(np.abs(scene.bound).max(), 1e-300))
    return 1.0


def fragile(scene, origins, directions, rel=1e-9, scale=None) -> np.ndarray:
    """Rays whose result a rounding-level change can flip: a literal test within
    ``rel * scale`` (a distance) of its boundary decides the hit (casting with
    ``tol = +-rel * scale`` gives another mask, depth or quadric), or two different quadrics
    tie within ``rel`` relative depth.  Exclude these when comparing an implementation with
    the oracle pixel by pixel."""
    if not (isinstance(scene, tuple)):
        from clcsg.model.csg import Shape
        from clcsg.model.scene import Scene

        if isinstance(scene, (Shape, Scene)):
            from clcsg.model.scene import as_scene

            scene = as_scene(scene).normalize()
    s = scene_scale(scene) if scale is None else float(scale)
    lo = cast(scene, origins, directions, tol=-rel * s)
    hi = cast(scene, origins, directions, tol=+rel * s)
    ex = cast(scene, origins, directions)
    out = ex.ties(rel)
    for h in (lo, hi):
        out |= h.mask != ex.mask
        both = h.mask & ex.mask
        with np.errstate(invalid="ignore"):
            out |= both & (np.abs(h.depth - ex.depth) > rel * ex.depth)
        out |= both & (h.quadric != ex.quadric)
    return out


# -- dense surface points -------------------------------------------------------------------------


def fibonacci_sphere(n: int) -> np.ndarray:
    """``n`` nearly uniform unit vectors (golden-angle spiral), shape (n, 3)."""
    k = np.arange(n, dtype=np.float64) + 0.5
    z = 1.0 - 2.0 * k / n
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = k * math.pi * (3.0 - math.sqrt(5.0))
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


@dataclass
class SurfacePoints:
    """Exact points of the CSG surface (world coordinates): ``points`` (M, 3), the solid's
    outward unit ``normals`` (M, 3), and for each the ``quadrics`` index, literal ``signs``
    and DNF ``terms`` it lies on."""

    points: np.ndarray
    normals: np.ndarray
    quadrics: np.ndarray
    signs: np.ndarray
    terms: np.ndarray

    def __len__(self):
        return len(self.points)


def _contains(Q, terms, p, strict_of=None):
    """Points in the closed union of the terms."""
    inside = np.zeros(len(p), dtype=bool)
    vals = {}
    for lits in terms:
        t_in = ~inside
        for qi, s in lits:
            if qi not in vals:
                vals[qi] = _value(Q[qi], p)
            t_in &= s * vals[qi] <= 0.0
        inside |= t_in
    return inside


def surface_points(scene, n_dirs=32, res=96, first_only=False, eps=1e-7, bound=None) -> SurfacePoints:
    """Dense exact points of the CSG surface, found by casting orthographic ray grids.

    For each of ``n_dirs`` directions u of a Fibonacci sphere, a ``res`` x ``res`` grid of
    parallel lines along u covers the scene's bounding sphere (center c, radius R of the
    bound; grid spacing 2R / res, so about ``n_dirs * res**2`` lines).  On every line, for
    every term and literal, each root of the literal's quadric at which all other literals of
    the term hold is a point p of the term's boundary; it is kept if it is on the boundary of
    the *union*: p + eps * diag * n is outside every term, n the literal's outward normal
    (this rejects points inside other terms and faces shared by two terms, like two boxes
    touching face to face, and keeps coincident outer faces such as flush tops).  With
    ``first_only`` only the first surface point along each line (t from the grid plane behind
    the scene) is kept, i.e. what an orthographic view sees.

    Every surface patch is crossed by lines of many directions, so with spacing ``h`` the
    points are roughly ``h / cos`` apart on it; regions narrower than ``h`` may be missed.
    Vectorized per term and literal; a few seconds for a million lines.
    """
    Q, terms = parts(scene)
    if bound is None:
        from clcsg.compile.dnf import Dnf

        if isinstance(scene, Dnf):
            bound = scene.bound
        else:
            from clcsg.model.scene import Scene
            from clcsg.model.csg import Shape

            if isinstance(scene, (Shape, Scene)):
                from clcsg.model.scene import as_scene

                bound = as_scene(scene).normalize().bound
            else:
                raise ValueError("surface_points needs a bound for a (quadrics, terms) scene")
    bound = np.asarray(bound, dtype=np.float64)
    c = 0.5 * (bound[0] + bound[1])
    R = 0.5 * float(np.linalg.norm(bound[1] - bound[0])) * 1.001 + 1e-12
    diag = 2.0 * R
    g = (np.arange(res) + 0.5) / res * 2.0 - 1.0
    gx, gy = np.meshgrid(g * R, g * R, indexing="ij")
    gx, gy = gx.ravel(), gy.ravel()
    outs = {k: [] for k in ("p", "n", "q", "s", "t")}
    for u in fibonacci_sphere(n_dirs):
        h = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        a = np.cross(u, h)
        a /= np.linalg.norm(a)
        b = np.cross(u, a)
        o = c + gx[:, None] * a + gy[:, None] * b - 1.5 * R * u
        d = np.broadcast_to(u, o.shape)
        cand = {k: [] for k in ("p", "n", "q", "s", "t", "ray", "dep")}
        for ti, lits in enumerate(terms):
            for li, (qi, s) in enumerate(lits):
                t1, t2 = Quadric(Q[qi]).intersect_line(o, d)
                for t in (t1, t2):
                    idx = np.flatnonzero(np.isfinite(t))
                    if not len(idx):
                        continue
                    p = o[idx] + t[idx, None] * u
                    good = np.ones(len(idx), dtype=bool)
                    for lj, (qj, sj) in enumerate(lits):
                        if lj != li:
                            good &= sj * _value(Q[qj], p) <= 0.0
                    idx, p = idx[good], p[good]
                    if not len(idx):
                        continue
                    gr = s * 2.0 * (p @ Q[qi][:3, :3] + Q[qi][:3, 3])
                    gn = np.linalg.norm(gr, axis=-1)
                    ok = gn > 0
                    idx, p, gr, gn = idx[ok], p[ok], gr[ok], gn[ok]
                    n = gr / gn[:, None]
                    cand["p"].append(p)
                    cand["n"].append(n)
                    cand["q"].append(np.full(len(p), qi))
                    cand["s"].append(np.full(len(p), s))
                    cand["t"].append(np.full(len(p), ti))
                    cand["ray"].append(idx)
                    cand["dep"].append(t[idx])
        if not cand["p"]:
            continue
        cat = {k: np.concatenate(v) for k, v in cand.items()}
        keep = ~_contains(Q, terms, cat["p"] + eps * diag * cat["n"])
        cat = {k: v[keep] for k, v in cat.items()}
        if first_only and len(cat["p"]):
            order = np.lexsort((cat["dep"], cat["ray"]))
            first = np.ones(len(order), dtype=bool)
            first[1:] = cat["ray"][order][1:] != cat["ray"][order][:-1]
            sel = order[first]
            cat = {k: v[sel] for k, v in cat.items()}
        for k in outs:
            outs[k].append(cat[k])
    if not outs["p"]:
        z = np.zeros((0, 3))
        e = np.zeros(0, dtype=np.int64)
        return SurfacePoints(z, z.copy(), e, e.copy(), e.copy())
    return SurfacePoints(
        np.concatenate(outs["p"]),
        np.concatenate(outs["n"]),
        np.concatenate(outs["q"]).astype(np.int64),
        np.concatenate(outs["s"]).astype(np.int64),
        np.concatenate(outs["t"]).astype(np.int64),
    )
