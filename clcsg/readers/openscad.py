"""OpenSCAD's CSG export (``openscad -o model.csg model.scad``) read into a clcsg :class:`Scene`.

OpenSCAD evaluates a ``.scad`` program into a tree of built-in nodes and ``-o model.csg``
writes that tree out with every expression already evaluated::

    group() {
        difference() {
            cube(size = [10, 10, 10], center = false);
            multmatrix([[1, 0, 0, 5], [0, 1, 0, 5], [0, 0, 1, -1], [0, 0, 0, 1]]) {
                cylinder($fn = 0, $fa = 12, $fs = 2, h = 12, r1 = 3, r2 = 3, center = false);
            }
        }
    }

Every node of a quadric-only model maps onto clcsg exactly: ``cube`` is a box, ``sphere`` a
sphere, ``cylinder`` a finite cylinder or a cone frustum (``$fn``, ``$fa`` and ``$fs`` are
ignored: the surfaces are exact, not tessellated), ``multmatrix`` a transform and ``group``,
``union``, ``difference``, ``intersection`` the Booleans.  Nodes that build other geometry
(``polyhedron``, ``linear_extrude``, ``hull``, ...) are rejected with a one-line
:class:`~clcsg.errors.SceneError` naming file, line and column.

The text is tokenized and parsed by :mod:`clcsg.readers.openscad_tokens` (grammar there); this
module evaluates the nodes.  Semantics follow OpenSCAD's own evaluator (2021.01 and later), including its quirks:

* ``group``/``union``/``render`` are the union of their children, ``difference`` is the first
  child minus all others, ``intersection`` the common part; ``multmatrix(m)`` (row-major 4x4,
  translation in the last column; missing entries are taken from the identity, ``m`` is divided
  by ``m[3][3]`` and its projective part is ignored) transforms the union of its children.
* Empty results behave as in OpenSCAD: a zero, negative or non-finite size, radius or height
  gives nothing (with a :class:`OpenScadWarning` naming line and column), an empty group gives
  nothing, an empty first child of a difference gives nothing, an empty child of an
  intersection makes it empty, and a singular or non-finite ``multmatrix`` removes its
  children (OpenSCAD: "Scaling a 3D object with 0 - removing object").
* Modifiers: ``*`` disables a subtree, ``%`` (background) leaves it out of the model,
  ``#`` (highlight) renders it normally and ``!`` makes that subtree the whole model (without
  the transforms and colors of its ancestors, like OpenSCAD; the first ``!`` wins).
* ``color`` takes ``[r, g, b]``, ``[r, g, b, a]``, a CSS/SVG color name or ``"#rgb"``, ``"#rgba"``, ``"#rrggbb"``, ``"#rrggbbaa"`` (parsed by
  :mod:`clcsg.model.colors`), optionally with an ``alpha``.
  As in OpenSCAD the *outermost* color wins: ``color("red") color("blue") cube(1);`` is red
  (openscad/openscad#4057, #5446).  Colors OpenSCAD could not parse are exported as
  ``color([-1, -1, -1, a])``, which sets no color.
* Arguments that OpenSCAD ignores with a warning (a ``size`` that is not a number or a
  3-vector, a non-boolean ``center``, unknown names) are ignored here too, with a warning;
  ``undef`` means "not given".

The parser raises nothing but :class:`SceneError` for any input text: syntax errors read
``<file>:<line>:<col>: syntax error: expected ...``.

Streaming: the text is read a chunk at a time and the parser yields an event per node (open,
close, or a leaf); the evaluator builds the model from the events as they come and keeps only
the nodes still open, so memory holds the model, not the file or its syntax tree.  Two things
keep the meaning of a file read whole: a syntax error anywhere is the error reported (the
evaluation's warnings are collected and emitted once the file has parsed), and a file with a
root modifier (``!``, which makes one subtree the whole model) is parsed into a tree first.

Deep nesting: the parser and the evaluator keep pending nodes on explicit stacks instead of
recursing, so any nesting depth loads (1,000 nested ``difference()`` are an ordinary model;
:data:`MAX_NODE_DEPTH`, 100,000 levels, only bounds memory for absurd input).  Values are
parsed recursively; vectors nested deeper than :data:`MAX_DEPTH` (100) levels are refused
(CSG export nests them 2 deep).  Code that walks the resulting :class:`Shape` graph must not
recurse per level either.

``.scad`` programs are exported by the ``openscad`` binary first: :mod:`clcsg.readers.scad`.
"""
from __future__ import annotations

import codecs
import math
import os
from dataclasses import dataclass

import numpy as np

from ..errors import SceneError
from ..model.csg import Difference, Intersection, Shape, Transformed, Union
from ..model.scene import Scene
from ..model.colors import NAMED_COLORS, ColorError, from_string
from .budget import CSG_FACTOR, check_file, check_input
from .openscad_2d import PARAMS_2D, REFUSED, Constructions
from .openscad_tokens import (CLOSE, OPEN, SOURCE_HINT, UNDEF, Node, OpenScadWarning, Parser, Source, chunks_of, events_of,
                              fmt, is_num)
from ..model import solids

__all__ = [
    "load_csg", "parse_csg", "OpenScadWarning", "WEB_COLORS", "SUPPORTED_NODES", "MAX_DEPTH", "MAX_NODE_DEPTH",
]

#: Deepest nesting of values (vectors, signs) accepted.  CSG export never nests vectors deeper
#: than a matrix (2 levels); values are parsed recursively, so this stays far below Python's
#: recursion limit.
MAX_DEPTH = 100

#: Deepest nesting of nodes (blocks, single children) accepted.  Nodes are parsed and evaluated
#: with explicit stacks, not recursion; the limit only bounds memory for absurd input.
MAX_NODE_DEPTH = 100_000

#: CSS Color Module Level 4 named colors (0-255), as OpenSCAD's ColorNode.cc lists them, plus
#: OpenSCAD's own "transparent": Pillow's table, see :data:`clcsg.model.colors.NAMED_COLORS`.
WEB_COLORS = NAMED_COLORS

_PRIMITIVES = frozenset(("cube", "sphere", "cylinder"))

#: Nodes this reader understands.
SUPPORTED_NODES = (
    "group", "union", "difference", "intersection", "render", "multmatrix", "color",
    "cube", "sphere", "cylinder",
    "linear_extrude", "rotate_extrude", "hull", "minkowski", "square", "circle", "polygon", "offset",
)

_UNSUPPORTED_HINT = ("clcsg reads quadric solids only (cube, sphere, cylinder, their Booleans, extrusions, "
                     "hulls and Minkowski sums)")

# Module names that exist only in the .scad language: OpenSCAD's export turns them into
# multmatrix/group, so meeting one means the file is a .scad source, not a CSG export.
_SOURCE_MODULES = frozenset(
    "translate rotate scale mirror children echo assert intersection_for parent_module".split()
)


# -- evaluation -------------------------------------------------------------------------------
@dataclass
class _Ctx:
    color: tuple | None = None  # the outermost valid color() above, or None


_PARAMS: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    # name: (positional parameters, named-only parameters)
    "cube": (("size", "center"), ()),
    "sphere": (("r",), ("d",)),
    "cylinder": (("h", "r1", "r2", "center"), ("r", "d", "d1", "d2")),
    "multmatrix": (("m",), ()),
    "color": (("c", "alpha"), ("texture",)),
    "render": (("convexity",), ()),
    "group": ((), ()),
    "union": ((), ()),
    "difference": ((), ()),
    "intersection": ((), ()),
    **PARAMS_2D,
}


@dataclass
class _Evaluator(Constructions):
    src: Source
    #: the file that relative import() paths are relative to (the .csg or .scad file)
    base: str | None = None

    def warn(self, pos: int, message: str):
        self.src.warn(pos, message)

    # arguments
    def bind(self, node: Node) -> dict:
        """Arguments by parameter name, as OpenSCAD's Parameters::parse assigns them."""
        positional, named = _PARAMS[node.name]
        known = set(positional) | set(named)
        out: dict = {}
        k = 0
        for a in node.args:
            if a.name is None:
                if k >= len(positional):
                    self.warn(a.pos, f"{node.name}(): too many unnamed arguments: {fmt(a.value)} ignored")
                    continue
                name = positional[k]
                k += 1
            else:
                name = a.name
                if name.startswith("$"):
                    # $fn, $fa, $fs: tessellation settings, irrelevant for exact surfaces; but a
                    # small $fn is how OpenSCAD users ask for prisms (hex nuts) on purpose
                    fn = a.value
                    if name == "$fn" and node.name in ("sphere", "cylinder") and is_num(fn) and 0.0 < fn <= 8.0:
                        self.warn(
                            a.pos,
                            f"{node.name}(): $fn = {fn:g} makes OpenSCAD build a {max(int(fn), 3)}-sided "
                            "polygonal solid; clcsg renders the exact round surface",
                        )
                    continue
                if name not in known:
                    self.warn(a.pos, f"{node.name}(): unknown argument {name!r} ignored")
                    continue
            if a.value is UNDEF:
                continue
            if name in out:
                self.warn(a.pos, f"{node.name}(): argument {name!r} given twice; the last one is used")
            out[name] = a.value
        return out

    # tree
    def shape(self, nodes: list[Node]) -> Shape | None:
        """The model of a whole syntax tree: the first root (``!``) subtree if there is one,
        else the union of the top-level nodes."""
        roots = []
        self._find_roots(nodes, roots)
        if roots:
            root = roots[0]
            if len(roots) > 1:
                self.warn(
                    roots[1].pos,
                    f"more than one root modifier (!): the first one, at {self.src.where(root.pos)}, is used",
                )
            if root.background:
                return None
            return self.evaluate(events_of([root]))
        return self.evaluate(events_of(nodes))

    def _find_roots(self, nodes, out):
        stack = list(reversed(nodes))
        while stack:
            n = stack.pop()
            if n.disabled:
                continue
            if n.root:
                out.append(n)
            if n.name not in _PRIMITIVES:  # OpenSCAD does not instantiate a primitive's children
                stack.extend(reversed(n.children))

    def _method(self, node: Node):
        method = getattr(self, "n_" + node.name, None) if node.name in _PARAMS else None
        if method is None:
            if node.name in REFUSED:
                raise self.src.error(node.pos, f"{node.name}() is not supported: {REFUSED[node.name]}")
            if node.name in _SOURCE_MODULES:
                raise self.src.error(node.pos, f"{node.name}() is not supported: {SOURCE_HINT}")
            raise self.src.error(node.pos, f"{node.name}() is not supported: {_UNSUPPORTED_HINT}")
        return method

    # The model is evaluated from the parser's events as they come (streaming): a node with
    # children gets a frame on an explicit stack while its children are read.  The n_* methods
    # of the Booleans, transforms and colors are generators: they run up to ``kids = yield
    # ctx`` when the node opens (argument warnings come first, as OpenSCAD gives them) and get
    # their children's shapes (None for an empty child; disabled and background children are
    # left out) when it closes.  Other nodes with children (extrusions, whose 2-D children are
    # evaluated as a tree, and primitives, which ignore theirs) collect their subtree and are
    # evaluated when they close.  Disabled and background subtrees are read and skipped.
    def evaluate(self, events) -> Shape | None:
        """The union of the top-level nodes of an event stream."""
        top: list = []
        stack: list = []
        ctx0 = _Ctx()
        for kind, node in events:
            if stack:
                f = stack[-1]
                tf = type(f)
                if tf is _Skip:
                    if kind == OPEN:
                        f.depth += 1
                    elif kind == CLOSE:
                        f.depth -= 1
                        if f.depth == 0:
                            stack.pop()
                    continue
                if tf is _Collect:
                    if kind == CLOSE:
                        f.nodes.pop()
                        if f.nodes:
                            continue
                        stack.pop()
                        r = self._method(node)(node, f.ctx)
                    else:
                        f.nodes[-1].children.append(node)
                        if kind == OPEN:
                            node.children = []
                            f.nodes.append(node)
                        continue
                elif kind == CLOSE:
                    stack.pop()
                    r = _finish(f.gen, f.kids)
                else:
                    r = self._start(kind, node, f.ctx, stack)
                    if r is _PENDING:
                        continue
            else:
                r = self._start(kind, node, ctx0, stack)
                if r is _PENDING:
                    continue
            if stack:
                stack[-1].kids.append(r)
            else:
                top.append(r)
        return _union(top)

    def _start(self, kind, node: Node, ctx: _Ctx, stack: list):
        """A node that opens or is a leaf: its shape, or _PENDING when it opened a frame
        (skipped nodes give _PENDING too, and never a shape)."""
        if node.disabled or node.background:
            if kind == OPEN:
                stack.append(_Skip())
            return _PENDING
        method = self._method(node)
        if node.name in _STREAMED:
            gen = method(node, ctx)
            child_ctx = gen.send(None)  # runs up to the children
            if kind == OPEN:
                stack.append(_Frame(gen, child_ctx))
                return _PENDING
            return _finish(gen, [])
        if kind == OPEN:
            stack.append(_Collect(node, ctx))
            return _PENDING
        return method(node, ctx)

    # Booleans and groups
    def n_group(self, node, ctx):
        self.bind(node)
        return _union((yield ctx))

    n_union = n_group
    n_render = n_group

    def n_difference(self, node, ctx):
        self.bind(node)
        kids = yield ctx
        if not kids or kids[0] is None:
            return None
        rest = [k for k in kids[1:] if k is not None]
        return Difference([kids[0], *rest]) if rest else kids[0]

    def n_intersection(self, node, ctx):
        self.bind(node)
        kids = yield ctx
        if not kids or any(k is None for k in kids):
            return None
        return Intersection(kids) if len(kids) > 1 else kids[0]

    # transform
    def n_multmatrix(self, node, ctx):
        p = self.bind(node)
        child = _union((yield ctx))
        m = np.eye(4)
        raw = p.get("m")
        if isinstance(raw, list):
            for i, row in enumerate(raw[:4]):
                if isinstance(row, list):
                    for j, v in enumerate(row[:4]):
                        if is_num(v):
                            m[i, j] = v
        elif raw is not None:
            self.warn(node.pos, f"multmatrix(): m = {fmt(raw)} is not a matrix: the identity is used")
        with np.errstate(all="ignore"):
            if m[3, 3] != 1.0:
                m = m / m[3, 3]
        if child is None:
            return None
        if not np.all(np.isfinite(m)):
            self.warn(node.pos, "multmatrix(): the matrix contains NaN or infinity: its children are left out, as OpenSCAD does")
            return None
        if np.any(m[3, :3] != 0.0):
            self.warn(node.pos, f"multmatrix(): the projective last row {fmt(m[3].tolist())} is ignored, as OpenSCAD does")
            m[3] = (0.0, 0.0, 0.0, 1.0)
        if np.linalg.det(m[:3, :3]) == 0.0:
            self.warn(node.pos, "multmatrix(): the matrix is singular (scaling a 3D object by 0): its children are left out, as OpenSCAD does")
            return None
        if np.array_equal(m, np.eye(4)):
            return child
        try:
            return Transformed(child, m)
        except (SceneError, ValueError, ArithmeticError) as e:
            self.warn(node.pos, f"multmatrix(): {e}: its children are left out")
            return None

    # color
    def n_color(self, node, ctx):
        p = self.bind(node)
        rgba = [-1.0, -1.0, -1.0, 1.0]
        c = p.get("c")
        if isinstance(c, list):
            for i in range(4):
                v = c[i] if i < len(c) else 1.0
                rgba[i] = v if is_num(v) else 0.0
        elif isinstance(c, str):
            try:
                rgba = list(from_string(c))
            except ColorError:
                self.warn(node.pos, f"color(): unable to parse color {fmt(c)}: no color is set, as in OpenSCAD")
        elif c is not None:
            self.warn(node.pos, f"color(): {fmt(c)} is not a color: no color is set, as in OpenSCAD")
        alpha = p.get("alpha")
        if is_num(alpha):
            rgba[3] = alpha
        elif alpha is not None:
            self.warn(node.pos, f"color(): alpha = {fmt(alpha)} is not a number: ignored")
        color = None
        if rgba[0] >= 0.0 and rgba[1] >= 0.0 and rgba[2] >= 0.0:  # OpenSCAD's Color4f::isValid
            clean = []
            for v in rgba:
                if not (0.0 <= v <= 1.0):  # also NaN
                    self.warn(node.pos, f"color(): value {v:g} is out of range [0, 1]: clamped")
                    v = 0.0 if math.isnan(v) else min(max(v, 0.0), 1.0)
                clean.append(float(v))
            color = tuple(clean)
        elif isinstance(c, list) and not (rgba[0] == rgba[1] == rgba[2] == -1.0):
            self.warn(node.pos, f"color(): {fmt(c)} has negative components: no color is set, as in OpenSCAD")
        # OpenSCAD: the outermost color wins (a color node only colors what has none yet)
        if color is not None and ctx.color is None:
            ctx = _Ctx(color)
        return _union((yield ctx))

    # primitives
    def _no_children(self, node):
        if node.has_children_block and node.children:
            self.warn(node.pos, f"{node.name}() does not support child nodes: they are ignored, as in OpenSCAD")

    def _center(self, node, p) -> bool:
        c = p.get("center", False)
        if isinstance(c, bool):
            return c
        self.warn(node.pos, f"{node.name}(): center = {fmt(c)} is not true or false: treated as false, as in OpenSCAD")
        return False

    def _make(self, node, factory, ctx, **params):
        try:
            return getattr(solids, factory)(color=ctx.color, **params)
        except (SceneError, ValueError, ArithmeticError, TypeError) as e:
            raise self.src.error(node.pos, f"{node.name}(): {e}") from None

    def n_cube(self, node, ctx):
        self._no_children(node)
        p = self.bind(node)
        size = (1.0, 1.0, 1.0)
        s = p.get("size")
        if is_num(s):
            size = (s, s, s)
        elif isinstance(s, list) and len(s) == 3 and all(is_num(v) for v in s):
            size = tuple(s)
        elif s is not None:
            self.warn(node.pos, f"cube(): unable to convert size = {fmt(s)} to a number or a vector of 3 numbers: size 1 is used, as in OpenSCAD")
        center = self._center(node, p)
        if not all(math.isfinite(v) and v > 0.0 for v in size):
            self.warn(node.pos, f"cube(size = {fmt(list(size))}) is empty (a size is zero, negative or not finite): left out, as in OpenSCAD")
            return None
        c = (0.0, 0.0, 0.0) if center else tuple(v / 2.0 for v in size)
        return self._make(node, "box", ctx, size=size, center=c)

    def _radius(self, node, p, d_name, r_name):
        """OpenSCAD's lookup_radius: a diameter wins over a radius."""
        d, r = p.get(d_name), p.get(r_name)
        for name, v in ((d_name, d), (r_name, r)):
            if v is not None and not is_num(v):
                self.warn(node.pos, f"{node.name}(): {name} = {fmt(v)} is not a number: ignored")
        if is_num(d):
            if is_num(r):
                self.warn(node.pos, f"{node.name}(): ignoring radius {r_name!r} as diameter {d_name!r} is given too")
            return d / 2.0
        return r if is_num(r) else None

    def n_sphere(self, node, ctx):
        self._no_children(node)
        p = self.bind(node)
        r = self._radius(node, p, "d", "r")
        r = 1.0 if r is None else r
        if not (math.isfinite(r) and r > 0.0):
            self.warn(node.pos, f"sphere(r = {r:g}) is empty (radius zero, negative or not finite): left out, as in OpenSCAD")
            return None
        return self._make(node, "sphere", ctx, radius=r, center=(0.0, 0.0, 0.0))

    def n_cylinder(self, node, ctx):
        self._no_children(node)
        p = self.bind(node)
        h = p.get("h")
        if h is not None and not is_num(h):
            self.warn(node.pos, f"cylinder(): h = {fmt(h)} is not a number: ignored")
        h = h if is_num(h) else 1.0
        r = self._radius(node, p, "d", "r")
        r1 = self._radius(node, p, "d1", "r1")
        r2 = self._radius(node, p, "d2", "r2")
        if r is not None and (r1 is not None or r2 is not None):
            self.warn(node.pos, "cylinder(): parameters ambiguous (r together with r1 or r2)")
        a = b = 1.0
        if r is not None:
            a = b = r
        if r1 is not None:
            a = r1
        if r2 is not None:
            b = r2
        center = self._center(node, p)
        if not (math.isfinite(h) and h > 0.0):
            self.warn(node.pos, f"cylinder(h = {h:g}) is empty (height zero, negative or not finite): left out, as in OpenSCAD")
            return None
        if not (math.isfinite(a) and math.isfinite(b) and a >= 0.0 and b >= 0.0 and (a > 0.0 or b > 0.0)):
            self.warn(node.pos, f"cylinder(r1 = {a:g}, r2 = {b:g}) is empty (radii zero, negative or not finite): left out, as in OpenSCAD")
            return None
        c = (0.0, 0.0, 0.0) if center else (0.0, 0.0, h / 2.0)
        if a == b:
            return self._make(node, "cylinder", ctx, height=h, radius=a, center=c)
        return self._make(node, "cone", ctx, height=h, r1=a, r2=b, center=c)




_PENDING = object()

#: nodes whose n_* method is a generator that gets its children's shapes
_STREAMED = frozenset(("group", "union", "render", "difference", "intersection", "multmatrix", "color",
                       "hull", "minkowski"))


class _Frame:
    """A streamed node whose children are being read: its generator and their shapes."""

    __slots__ = ("gen", "ctx", "kids")

    def __init__(self, gen, ctx):
        self.gen = gen
        self.ctx = ctx
        self.kids: list = []


class _Collect:
    """A node evaluated from its subtree, which is being collected (``nodes``: the open ones)."""

    __slots__ = ("nodes", "ctx")

    def __init__(self, node, ctx):
        node.children = []  # rebuilt from the events (a tree's nodes come with theirs)
        self.nodes = [node]
        self.ctx = ctx


class _Skip:
    """A disabled or background subtree being read (``depth``: its nodes still open)."""

    __slots__ = ("depth",)

    def __init__(self):
        self.depth = 1


def _finish(gen, kids):
    try:
        gen.send(kids)
    except StopIteration as stop:
        return stop.value
    raise RuntimeError(f"{gen.__name__} asked for its children twice")  # pragma: no cover


def _union(shapes: list) -> Shape | None:
    kept = [s for s in shapes if s is not None]
    if not kept:
        return None
    return kept[0] if len(kept) == 1 else Union(kept)




# -- entry points -----------------------------------------------------------------------------
#: characters per chunk the reader decodes and tokenizes at a time
CHUNK = 1 << 16


def parse_csg(text: str, source: str = "<string>", base: str | None = None) -> Scene:
    """Parse OpenSCAD CSG export ``text`` into a :class:`Scene`.

    ``base``: the file relative ``import()`` paths are relative to (default ``source``).
    Raises :class:`SceneError` (one line: ``<source>:<line>:<col>: ...``) and nothing else for
    any text; emits :class:`OpenScadWarning` for what OpenSCAD also skips with a warning.  An
    empty model is an empty union (a scene with no DNF terms).
    """
    if not isinstance(text, str):
        raise SceneError(f"{source}: expected the text of a .csg file, got {type(text).__name__}")
    if text.startswith("\ufeff"):
        text = text[1:]
    check_input(str(source), len(text), CSG_FACTOR)
    return _read(chunks_of(text, CHUNK), str(source), source if base is None else base, "!" in text)


def _read(chunks, source: str, base, has_root: bool) -> Scene:
    """The scene of a text given in chunks.  Without a root modifier (``!``) anywhere the
    model is evaluated while the text streams by; with one, the file is parsed into a tree
    first (the first root decides what the rest of the file means)."""
    src = Source(chunks, source)
    try:
        parser = Parser(src, MAX_NODE_DEPTH, MAX_DEPTH)
        evaluator = _Evaluator(src, base)
        if has_root:
            nodes = parser.parse_file()
            shape = _evaluated(src, lambda: evaluator.shape(nodes))
        else:
            shape = _streamed(src, parser.events(), evaluator)
    except SceneError:
        raise
    except RecursionError:
        raise SceneError(f"{source}: the model is nested too deeply") from None
    except MemoryError:
        raise SceneError(f"{source}: the model is too large to load") from None
    if shape is None:
        src.warn(src.length, "the model is empty (nothing to render)")
        src.flush()
        shape = Union([])
    return Scene(shape, None, source)


def _evaluated(src: Source, evaluate):
    try:
        shape = evaluate()
    except SceneError:
        src.flush()  # the warnings before the error
        raise
    src.flush()
    return shape


def _streamed(src: Source, events, evaluator: _Evaluator):
    """Evaluate while parsing; a syntax error anywhere in the file is what is reported (and
    then no warnings), as when the whole file was parsed before it was evaluated."""
    syntax = []

    def checked():
        try:
            yield from events
        except SceneError:
            syntax.append(True)
            raise

    stream = checked()
    try:
        shape = evaluator.evaluate(stream)
    except SceneError as e:
        if syntax:
            src.pending.clear()
            raise
        try:
            for _ in stream:  # the rest of the file, for a syntax error that comes first
                pass
        except SceneError:
            src.pending.clear()
            raise
        src.flush()
        raise e from None
    src.flush()
    return shape


def _file_chunks(f, size: int):
    """The UTF-8 text of binary file ``f`` (undecodable bytes replaced, a BOM dropped) in
    chunks of about ``size`` characters."""
    decoder = codecs.getincrementaldecoder("utf-8")(errors="replace")
    first = True
    while True:
        data = f.read(size)
        text = decoder.decode(data, final=not data)
        if first and text:
            first = False
            if text.startswith("\ufeff"):
                text = text[1:]
        if text:
            yield text
        if not data:
            return


def _has_root(f, size: int) -> bool:
    """Whether binary file ``f`` holds a '!' (a root modifier, or one in a string or comment)."""
    while True:
        data = f.read(size)
        if not data:
            return False
        if b"!" in data:
            return True


def load_csg(path) -> Scene:
    """Load an OpenSCAD ``.csg`` file (``openscad -o model.csg model.scad``), a chunk at a time."""
    p = os.fspath(path)
    check_file(p, CSG_FACTOR)
    try:
        with open(p, "rb") as f:
            has_root = _has_root(f, CHUNK)
            f.seek(0)
            return _read(_file_chunks(f, CHUNK), p, p, has_root)
    except FileNotFoundError:
        raise SceneError(f"{p}: no such file") from None
    except OSError as e:
        raise SceneError(f"{p}: cannot read: {e.strerror or e}") from None
