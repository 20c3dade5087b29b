"""``clcsg.mesh``: a closed triangle mesh of a scene, its vertices on the exact surface.

Two methods.  *facets* (:mod:`.exact_facets`; the default wherever every primitive has a
closed-form faceting): the primitives faceted within the tolerance, combined by manifold3d's
exact Booleans, every vertex then solved onto its exact quadrics, curves and corners.
*contour* (any quadric; the stages below): the pruned tape contoured on a grid.

The contour stages, one module each:

1. :mod:`.octree`: the grid cells the surface may cross (octree descent over the pruned tape);
2. :mod:`.adapt`: their Kuhn tetrahedra, bisected (:mod:`.bisect`) where a feature is
   thinner than they are; :mod:`~clcsg.model.marching_tetrahedra`: marching tetrahedra on them: a closed, oriented
   2-manifold;
3. :mod:`.crossings`: every vertex moved onto the exact surface along its crossing edge;
4. :mod:`.refine`: edges split onto the intersection curves of the quadrics (sharp edges and
   corners, solved by Newton onto two or three quadrics, :mod:`.project`) and on curved patches
   until the chord error is under the tolerance;
5. :mod:`.collapse`: zero-length edges (a corner solved twice) collapsed;
   :mod:`.decimate`: half-edge collapses within the chord error bound that keep every vertex
   on its quadrics (curved patches coarsened to the tolerance, flat faces to their boundary);
   :mod:`.planar`: each planar patch re-triangulated from its boundary alone (few triangles);
6. :mod:`.colors`: per triangle its quadric, primitive and colour.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from functools import partial

import numpy as np

from ..errors import SceneError, UsageError
from ..readers.scenes import as_scene
from ..sampling.radius import Radius
from . import planar, refine
from .adapt import adapt
from .collapse import collapse_coincident
from .decimate import decimate
from .owners import triangle_owners
from .octree import surface_cells
from .exact_facets import contains_near, facetable, mesh_by_facets, timed
from .facets import KINDS as FACETED_KINDS
from .operand_booleans import mesh_by_booleans, needs_booleans
from .snap import repair_off_surface

#: default tolerance: 0.1% of the bound's diagonal
DEFAULT_TOLERANCE = "0.1%"
#: grid cells over the longest side of the bound (before refinement)
DEFAULT_CELLS = 32
#: the meshing methods of :func:`mesh`
METHODS = ("auto", "facets", "contour")


@dataclass
class Mesh:
    """A closed triangle mesh: ``vertices`` (V, 3) float64, ``triangles`` (T, 3) int64 with
    outward (counter-clockwise) orientation, per triangle its ``quadric`` (tape quadric index),
    ``primitive`` (instance index, -1 if none found) and ``colors`` (T, 4) RGBA in [0, 1]; per
    vertex the quadrics it lies on (``vertex_quadrics`` (V, k >= 3), -1 padded)."""

    vertices: np.ndarray
    triangles: np.ndarray
    quadric: np.ndarray
    primitive: np.ndarray
    colors: np.ndarray
    vertex_quadrics: np.ndarray
    tolerance: float
    stats: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.triangles)


def resolve_tolerance(tolerance, diagonal: float) -> float:
    """The tolerance in scene units: a number, ``"0.05"`` or ``"0.1%"`` of the diagonal."""
    return Radius.parse(tolerance, "tolerance").of(diagonal)


def mesh(scene, tolerance=DEFAULT_TOLERANCE, cells: int = DEFAULT_CELLS, bound=None, method: str = "auto") -> Mesh:
    """The mesh of ``scene`` (a Scene, Shape or scene file path) within ``tolerance`` of its
    surface (scene units, or ``"0.1%"`` of the bound's diagonal).  Raises SceneError for an
    empty solid.

    ``method``: ``"facets"`` (faceted primitives, manifold3d's Booleans, vertices onto the
    exact surface: :mod:`.exact_facets`), ``"contour"`` (the pruned tape contoured on a grid
    of ``cells``: the stages in this module's docstring) or ``"auto"`` (facets where every
    primitive has a closed-form faceting, else contour)."""
    t0 = time.process_time()
    sc = as_scene(scene, bound)
    spec = Radius.parse(tolerance, "tolerance")
    if not isinstance(cells, int) or cells < 4:
        raise UsageError(f"cells must be an integer >= 4, got {cells!r}")
    if method not in METHODS:
        raise UsageError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    tape = sc.compile()
    if tape.empty:
        raise SceneError(f"{sc.source}: the solid is empty: there is nothing to mesh")
    diag = float(np.linalg.norm(tape.bound[1] - tape.bound[0]))
    tol = spec.of(diag if diag > 0 and math.isfinite(diag) else 1.0)
    stats = {"tolerance": tol, "stage_cpu_s": {}}
    if needs_booleans(sc.shape):
        return _by_booleans(sc, tol, cells, stats, t0)
    if method == "facets" and not facetable(tape):
        kinds = sorted({i.node.kind for i in tape.instances} - set(FACETED_KINDS))
        raise UsageError(f"{sc.source}: method 'facets' has no faceting for {', '.join(kinds)}; use 'contour' or 'auto'")
    if method != "contour" and facetable(tape):
        got = mesh_by_facets(sc.shape, tape, tol, stats)
        if not len(got.triangles):
            raise SceneError(f"{sc.source}: the solid is empty: there is nothing to mesh")
        stats.update(triangles=int(len(got.triangles)), vertices=int(len(got.vertices)), cpu_s=time.process_time() - t0)
        return Mesh(got.vertices, got.triangles, got.quadric, got.primitive, got.colors, got.sets, tol, stats)
    stats["method"] = "contour"
    grid = timed(stats, "cells", surface_cells, tape, cells)
    stats.update(cells=int(len(grid.ijk)), boxes_tested=int(grid.visited), h=grid.h)

    marched = timed(stats, "adapt", adapt, tape, grid, tol, stats)
    tri = marched.triangles
    if not len(tri):
        raise SceneError(f"{sc.source}: the solid is empty (or thinner than the grid, "
                         f"{grid.h:.3g} units): there is nothing to mesh")
    verts, vq, fallbacks = marched.points, marched.quadric, marched.fallbacks
    stats.update(base_triangles=int(len(tri)), crossing_fallbacks=fallbacks)
    vsets = np.full((len(verts), 3), -1, dtype=np.int64)
    vsets[:, 0] = vq
    m = refine.Surface(tape, verts, vsets, tri)
    timed(stats, "refine", refine.refine, m, tol, stats)
    timed(stats, "collapse", collapse_coincident, m, stats)
    timed(stats, "decimate", decimate, m, tol, stats)
    timed(stats, "planar", planar.coarsen, m, stats)
    # curve points solved beyond a corner, off the solid: onto the corner (as the facets do)
    off, fixed = timed(stats, "repair", repair_off_surface, m.vertices, m.sets, m.triangles, tape.quadrics, tol,
                       partial(contains_near, tape))
    stats.update(off_surface=off, off_surface_repaired=fixed)
    quad, prim, colors = timed(stats, "owners", triangle_owners, tape, m, tol)
    stats["spanning_triangles"] = int(refine.spanning(m.sets, m.triangles).sum())  # of the final mesh
    stats.update(triangles=int(len(m.triangles)), vertices=int(len(m.vertices)),
                 cpu_s=time.process_time() - t0)
    return Mesh(m.vertices, m.triangles, quad, prim, colors, m.sets, tol, stats)


def _by_booleans(sc, tol: float, cells: int, stats: dict, t0: float) -> Mesh:
    """The mesh of a scene with point or large mesh operands (:mod:`.operand_booleans`)."""
    v, tri, colors = timed(stats, "booleans", mesh_by_booleans, sc, tol, cells,
                            lambda scene, t, c: mesh(scene, tolerance=t, cells=c))
    if not len(tri):
        raise SceneError(f"{sc.source}: the solid is empty: there is nothing to mesh")
    none = np.full(len(tri), -1, dtype=np.int64)
    stats.update(method="booleans", triangles=int(len(tri)), vertices=int(len(v)), spanning_triangles=0,
                 cpu_s=time.process_time() - t0)
    return Mesh(v, tri, none, none.copy(), colors, np.full((len(v), 3), -1, dtype=np.int64), tol, stats)
