"""OpenSCAD's constructions read exactly: 2-D shapes, extrusions, hulls and Minkowski sums.

The evaluator of :mod:`clcsg.readers.openscad` mixes :class:`Constructions` in.  A
``linear_extrude`` or ``rotate_extrude`` evaluates its children as a 2-D :class:`Profile`
(``square``, ``circle``, ``polygon`` with ``paths``, ``offset``, 2-D ``hull``, and ``group`` /
``union`` / ``difference`` / ``intersection`` / ``multmatrix`` / ``color`` / ``render`` over
them), then builds the exact solid (:mod:`clcsg.model.extrude`, :mod:`clcsg.model.revolve`).
``hull()`` and ``minkowski()`` of 3-D children go to :mod:`clcsg.model.hull`.

What has no quadric form is refused in one line naming the node and the reason, with the
nearest exact alternative where there is one (:data:`REFUSED`).
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import SceneError
from ..model.extrude import extrude
from ..model.hull import hull, minkowski
from ..model.profile import Profile, circle, difference2d, intersection2d, polygon, square, union2d
from ..model.profile_ops import hull2d_of, minkowski2d, offset
from ..model.polyhedron import polyhedron
from ..model.revolve import revolve
from .openscad_tokens import fmt, is_num
from .mesh_files import load_mesh, resolve

#: positional and named-only parameters of the nodes read here
PARAMS_2D = {
    "square": (("size", "center"), ()),
    "circle": (("r",), ("d",)),
    "polygon": (("points", "paths", "convexity"), ()),
    "offset": (("r",), ("delta", "chamfer")),
    "linear_extrude": (("height", "center", "convexity", "twist", "slices", "scale"), ("v", "file", "layer", "origin", "segments")),
    "rotate_extrude": (("angle",), ("convexity", "file", "layer", "origin", "scale")),
    "hull": ((), ()),
    "minkowski": (("convexity",), ()),
    "polyhedron": (("points", "faces", "convexity"), ("triangles",)),
    "import": (("file", "layer", "convexity", "origin", "scale"), ("timestamp", "dpi", "center", "id")),
}

#: nodes that have no exact quadric form: the reason, and the nearest exact alternative
REFUSED = {
    "text": "text() outlines glyphs with Bezier curves, not lines and arcs; nearest exact alternative: none "
            "(model lettering with polygons)",
    "surface": "surface() is a height-map mesh",
    "projection": "projection() of a 3-D solid to 2-D has curved outlines of higher degree",
    "resize": "resize() depends on the child's mesh bounding box; nearest exact alternative: scale()",
    "roof": "roof() builds a straight skeleton of a polygon, which is not covered",
}

_PASS_2D = ("group", "union", "render", "color")


class Constructions:
    """Node handlers (``n_<name>``) for the constructions; mixed into the evaluator."""

    def _fail(self, node, e):
        raise self.src.error(node.pos, f"{node.name}(): {e}") from None

    # -- 3-D nodes with a 2-D child ---------------------------------------------------------
    def n_linear_extrude(self, node, ctx):
        p = self.bind(node)
        h = p.get("height", p.get("v", 100.0))
        if isinstance(h, list):  # v = [x, y, z]: OpenSCAD extrudes along the vector
            self._fail(node, "extrusion along a vector v is not covered; nearest exact alternative: height = ... and multmatrix")
        if not is_num(h) or not (math.isfinite(h) and h > 0):
            self.warn(node.pos, f"linear_extrude(height = {fmt(h)}) is empty: left out, as in OpenSCAD")
            return None
        twist = p.get("twist", 0.0)
        if is_num(twist) and twist != 0:
            self._fail(node, f"twist = {twist:g} sweeps helicoids, which are not quadric surfaces; "
                             "nearest exact alternative: twist = 0 (rotate the whole extrusion instead)")
        scale = p.get("scale", 1.0)
        if isinstance(scale, list) and len(scale) == 2 and all(is_num(v) for v in scale):
            scale = tuple(scale)
        elif not is_num(scale):
            scale = 1.0
        center = p.get("center", False) is True
        prof = self.profile_of(node)
        if prof is None:
            return None
        try:
            return extrude(prof, h, center=center, scale=scale, color=ctx.color)
        except SceneError as e:
            self._fail(node, e)

    def n_rotate_extrude(self, node, ctx):
        p = self.bind(node)
        angle = p.get("angle", 360.0)
        if not is_num(angle):
            angle = 360.0
        prof = self.profile_of(node)
        if prof is None:
            return None
        try:
            return revolve(prof, angle, color=ctx.color)
        except SceneError as e:
            self._fail(node, e)

    # -- 3-D hull and Minkowski sum -----------------------------------------------------------
    def n_hull(self, node, ctx):
        self.bind(node)
        kids = [k for k in (yield ctx) if k is not None]
        if not kids:
            return None
        try:
            return hull(*kids, color=ctx.color)
        except SceneError as e:
            self._fail(node, e)

    def n_minkowski(self, node, ctx):
        self.bind(node)
        kids = [k for k in (yield ctx) if k is not None]
        if not kids:
            return None
        try:
            return minkowski(*kids, color=ctx.color)
        except SceneError as e:
            self._fail(node, e)

    def n_polyhedron(self, node, ctx):
        self._no_children(node)
        p = self.bind(node)
        pts, faces = p.get("points"), p.get("faces", p.get("triangles"))
        if not (isinstance(pts, list) and all(isinstance(q, list) and len(q) == 3 and all(is_num(v) for v in q) for q in pts)):
            raise self.src.error(node.pos, f"polyhedron(): points = {fmt(pts)} is not a list of [x, y, z] points")
        if not (isinstance(faces, list) and all(isinstance(f, list) and all(is_num(v) and 0 <= v < len(pts) for v in f) for f in faces)):
            raise self.src.error(node.pos, f"polyhedron(): faces = {fmt(faces)} is not a list of point index lists")
        try:
            return polyhedron(np.array(pts, dtype=float), [[int(v) for v in f] for f in faces], ctx.color,
                              source=f"{self.src.where(node.pos)}: polyhedron()")
        except SceneError as e:
            raise SceneError(str(e)) from None

    def n_import(self, node, ctx):
        self._no_children(node)
        p = self.bind(node)
        name = p.get("file")
        if not isinstance(name, str) or not name:
            raise self.src.error(node.pos, f"import(): file = {fmt(name)} is not a file name")
        scale = p.get("scale", 1.0)
        try:
            shape = load_mesh(resolve(name, self.base), ctx.color, source=f"{self.src.where(node.pos)}: import()")
        except SceneError as e:
            raise SceneError(str(e)) from None
        if is_num(scale) and scale != 1.0 and scale > 0:
            shape = shape.scale(float(scale))
        return shape

    # -- 2-D nodes where a solid is expected, and refused nodes ---------------------------------
    def _flat(self, node, ctx):
        raise self.src.error(node.pos, f"{node.name}() is a 2-D shape outside linear_extrude() or rotate_extrude(): "
                                       "it has no volume; nearest exact alternative: linear_extrude() it")

    n_square = n_circle = n_polygon = n_offset = _flat

    # -- 2-D evaluation -----------------------------------------------------------------------
    def profile_of(self, node) -> Profile | None:
        """The union of a node's 2-D children, or None (empty)."""
        return self._union2d([self.profile(c) for c in node.children if not (c.disabled or c.background)])

    @staticmethod
    def _union2d(ps):
        ps = [p for p in ps if p is not None]
        return union2d(*ps) if ps else None

    def profile(self, node) -> Profile | None:
        name = node.name
        if name in REFUSED:
            raise self.src.error(node.pos, f"{name}() is not supported: {REFUSED[name]}")
        if name not in PARAMS_2D and name not in _PASS_2D + ("difference", "intersection", "multmatrix"):
            raise self.src.error(node.pos, f"{name}() inside a 2-D profile is not supported: a profile is built from "
                                           "square, circle, polygon, offset, hull and 2-D Booleans and transforms")
        try:
            return getattr(self, "p_" + name)(node)
        except SceneError as e:
            if str(e).startswith(self.src.name):
                raise
            self._fail(node, e)

    def p_group(self, node):
        if node.name != "color":
            self.bind(node)
        return self.profile_of(node)

    p_union = p_render = p_color = p_group

    def p_difference(self, node):
        self.bind(node)
        kids = [self.profile(c) for c in node.children if not (c.disabled or c.background)]
        if not kids or kids[0] is None:
            return None
        return difference2d(kids[0], *[k for k in kids[1:] if k is not None])

    def p_intersection(self, node):
        self.bind(node)
        kids = [self.profile(c) for c in node.children if not (c.disabled or c.background)]
        if not kids or any(k is None for k in kids):
            return None
        return intersection2d(*kids)

    def p_multmatrix(self, node):
        p = self.bind(node)
        child = self.profile_of(node)
        if child is None:
            return None
        m = np.eye(4)
        raw = p.get("m")
        if isinstance(raw, list):
            for i, row in enumerate(raw[:4]):
                if isinstance(row, list):
                    for j, v in enumerate(row[:4]):
                        if is_num(v):
                            m[i, j] = v
        m2 = np.array([[m[0, 0], m[0, 1], m[0, 3]], [m[1, 0], m[1, 1], m[1, 3]], [0, 0, 1.0]])
        if not np.all(np.isfinite(m2)) or np.linalg.det(m2[:2, :2]) == 0:
            self.warn(node.pos, "multmatrix(): singular or not finite in 2-D: its children are left out, as in OpenSCAD")
            return None
        if np.array_equal(m2, np.eye(3)):
            return child
        return child.transform(m2)

    def p_square(self, node):
        p = self.bind(node)
        s = p.get("size", 1.0)
        if is_num(s):
            s = (s, s)
        if not (isinstance(s, (list, tuple)) and len(s) == 2 and all(is_num(v) and math.isfinite(v) and v > 0 for v in s)):
            self.warn(node.pos, f"square(size = {fmt(s)}) is empty: left out, as in OpenSCAD")
            return None
        return square(tuple(s), center=p.get("center", False) is True)

    def p_circle(self, node):
        p = self.bind(node)
        r = self._radius(node, p, "d", "r")
        r = 1.0 if r is None else r
        if not (math.isfinite(r) and r > 0):
            self.warn(node.pos, f"circle(r = {r:g}) is empty: left out, as in OpenSCAD")
            return None
        return circle(r)

    def p_polygon(self, node):
        p = self.bind(node)
        pts = p.get("points")
        if not (isinstance(pts, list) and all(isinstance(q, list) and len(q) >= 2 and all(is_num(v) for v in q[:2]) for q in pts)):
            raise self.src.error(node.pos, f"polygon(): points = {fmt(pts)} is not a list of [x, y] points")
        paths = p.get("paths")
        if paths is not None and not (isinstance(paths, list) and all(isinstance(q, list) and all(is_num(v) for v in q) for q in paths)):
            raise self.src.error(node.pos, f"polygon(): paths = {fmt(paths)} is not a list of index lists")
        return polygon([q[:2] for q in pts], None if paths is None else [[int(v) for v in q] for q in paths])

    def p_offset(self, node):
        p = self.bind(node)
        child = self.profile_of(node)
        if child is None:
            return None
        if is_num(p.get("r")):
            return offset(child, r=p["r"])
        delta = p.get("delta", 1.0)
        return offset(child, delta=delta if is_num(delta) else 1.0, chamfer=p.get("chamfer", False) is True)

    def p_hull(self, node):
        self.bind(node)
        kids = [self.profile(c) for c in node.children if not (c.disabled or c.background)]
        kids = [k for k in kids if k is not None]
        if not kids:
            return None
        return hull2d_of(*kids)

    def p_minkowski(self, node):
        self.bind(node)
        kids = [k for k in (self.profile(c) for c in node.children if not (c.disabled or c.background)) if k is not None]
        return minkowski2d(*kids) if kids else None
