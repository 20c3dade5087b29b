"""clcsg's JSON scene format (version 1): load, validate and save CSG graphs.

A scene file is one JSON object (full description in ``docs/scene-format.md``, JSON Schema in
``clcsg/schema/scene.schema.json``)::

    {"clcsg": 1,
     "bound": [[-2, -2, -2], [2, 2, 2]],                      (optional)
     "defs": {"hole": {"cylinder": {"radius": 0.2, "height": 3}}},   (optional)
     "root": {"difference": [{"box": {"size": 2}, "color": [0.9, 0.5, 0.1]},
                             {"ref": "hole"},
                             {"ref": "hole", "transform": [{"rotate": {"axis": [1, 0, 0], "degrees": 90}}]}]}}

Nodes map one to one onto :mod:`clcsg.csg`: a primitive kind from :data:`clcsg.solids.KINDS`
is a :class:`~clcsg.csg.Primitive`, ``union`` / ``intersection`` / ``difference`` /
``complement`` are the operation classes, every ``transform`` step is one
:class:`~clcsg.csg.Transformed` edge (built exactly as ``Shape.translate`` / ``rotate`` /
``scale`` / ``transform`` build it), and every ``{"ref": name}`` to the same definition is the
*same* Python object, so shared sub-graphs stay shared.  :func:`scene_to_dict` inverts this:
it finds nodes with more than one parent (by identity) and writes them once under ``defs``.
Floats are written with ``repr`` precision, so a saved graph loads back bit for bit.

Deep chains: loading and saving use explicit stacks, not recursion, so the depth of the graph
is not limited by Python's recursion limit.  JSON text is: Python's ``json`` module recurses
once per array and object and cannot read the ~2000 levels of 1,000 nested operations
(``$: nesting too deep``).  Write deep chains flat, one level per def::

    "defs": {"d0": {"box": {"size": 1}},
             "d1": {"difference": [{"ref": "d0"}, {"sphere": {"radius": 0.1}}]}, ...},
    "root": {"ref": "d1000"}

:func:`scene_to_dict` does this by itself: below :data:`SAVE_DEPTH` nested operations the
rest of a chain is written as a def (used once, so it loads back to the same graph).

Every problem is a :class:`~clcsg.errors.SceneError` (``TransformError`` for bad transforms)
with a one-line message ``<file>: <json path>: <reason>``, e.g.
``part.json: $.root.difference[1].cylinder.radius: must be positive, got -1``.
Syntax errors name ``line L, column C`` instead of a JSON path.
"""

from __future__ import annotations

import difflib
import inspect
import json
import math
import numbers
import os
import re
from types import GeneratorType
from typing import Any

import numpy as np

from ..model import solids
from ..model.csg import (
    DEFAULT_COLOR,
    Complement,
    Difference,
    Intersection,
    Primitive,
    Shape,
    Transformed,
    Union,
)
from ..errors import SceneError, TransformError
from ..model.scene import Scene

#: the format version this module reads and writes (``"clcsg": 1``)
FORMAT_VERSION = 1

#: variadic operations (JSON key -> class); ``complement`` takes a single node
OPERATIONS = {"union": Union, "intersection": Intersection, "difference": Difference}
UNARY = ("complement",)
#: transform step kinds, in the order the docs list them
TRANSFORM_STEPS = ("translate", "rotate", "scale", "matrix")

TOP_KEYS = ("clcsg", "bound", "defs", "root", "comment", "$schema")
NODE_EXTRA_KEYS = ("transform", "color", "comment")

#: line width of :func:`dumps`
WIDTH = 96

#: deepest nesting of operations that :func:`scene_to_dict` writes into one JSON object; a
#: deeper chain continues in a def (``{"ref": ...}``), so that saved files stay within the
#: nesting that Python's ``json`` module can read (about 1000 levels of arrays and objects,
#: two per operation)
SAVE_DEPTH = 100

_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
_HEX_COLOR = re.compile(r"#([0-9a-fA-F]{6}|[0-9a-fA-F]{8})\Z")


# -- public API ---------------------------------------------------------------------------------
def load_json(path) -> Scene:
    """Load and validate a ``.json`` scene file."""
    p = os.fspath(path)
    try:
        with open(p, encoding="utf-8-sig") as f:
            text = f.read()
    except FileNotFoundError:
        raise SceneError(f"{p}: no such file") from None
    except UnicodeDecodeError as e:
        raise SceneError(f"{p}: not UTF-8 text ({e.reason} at byte {e.start})") from None
    except OSError as e:
        raise SceneError(f"{p}: cannot read: {e.strerror or e}") from None
    return loads_json(text, p)


def loads_json(text: str, source: str = "<string>") -> Scene:
    """Parse and validate scene JSON text; ``source`` names it in error messages."""
    return scene_from_dict(parse_json(text, source), source)


def parse_json(text: str, source: str = "<string>") -> Any:
    """Strict JSON parsing: syntax errors with line and column; NaN, Infinity and duplicate
    keys are kept as markers that :func:`scene_from_dict` reports with their JSON path."""
    try:
        return json.loads(text, parse_constant=_BadConstant, object_pairs_hook=_object)
    except json.JSONDecodeError as e:
        raise SceneError(f"{source}: line {e.lineno}, column {e.colno}: invalid JSON: {e.msg}") from None
    except RecursionError:
        raise SceneError(f"{source}: $: nesting too deep") from None


def scene_from_dict(data, source: str = "scene") -> Scene:
    """Build a :class:`~clcsg.scene.Scene` from parsed JSON data (dicts, lists, numbers)."""
    try:
        return _Loader(source).scene(data)
    except RecursionError:
        raise SceneError(f"{source}: $.root: nesting too deep") from None


def scene_to_dict(scene) -> dict:
    """The JSON data of a Scene (or a bare Shape); shared nodes become ``defs`` + ``ref``."""
    if isinstance(scene, Shape):
        scene = Scene(scene)
    if not isinstance(scene, Scene):
        raise SceneError(f"expected a Scene or a Shape, got {type(scene).__name__}")
    return _Saver(scene.source).scene(scene)


def dumps(data) -> str:
    """Format scene data as readable JSON (short arrays and objects on one line)."""
    return _fmt(data, 0, 0) + "\n"


def save_json(scene, path) -> None:
    """Write a Scene (or a bare Shape) as a ``.json`` scene file."""
    p = os.fspath(path)
    text = dumps(scene_to_dict(scene))
    try:
        with open(p, "w", encoding="utf-8") as f:
            f.write(text)
    except OSError as e:
        raise SceneError(f"{p}: cannot write: {e.strerror or e}") from None


# -- JSON parsing helpers -----------------------------------------------------------------------
class _BadConstant:
    """Stands in for NaN / Infinity / -Infinity, which JSON does not have."""

    __slots__ = ("token",)

    def __init__(self, token):
        self.token = token


class _Object(dict):
    """A JSON object that remembers its first duplicate key."""

    duplicate = None


def _object(pairs):
    obj = _Object()
    for k, v in pairs:
        if k in obj and obj.duplicate is None:
            obj.duplicate = k
        obj[k] = v
    return obj


def _key(path: str, name) -> str:
    name = str(name)
    return f"{path}.{name}" if _IDENT.match(name) else f"{path}[{json.dumps(name)}]"


def _idx(path: str, i: int) -> str:
    return f"{path}[{i}]"


def _jtype(v) -> str:
    if v is None:
        return "null"
    if isinstance(v, bool):
        return "boolean"
    if isinstance(v, numbers.Real):
        return "number"
    if isinstance(v, str):
        return "string"
    if isinstance(v, (list, tuple)):
        return f"array of {len(v)}"
    if isinstance(v, dict):
        return "object"
    if isinstance(v, _BadConstant):
        return v.token
    return type(v).__name__


def _is_number(v) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, (bool, np.bool_))


def _suggest(word, choices) -> str:
    close = difflib.get_close_matches(str(word), list(choices), n=1, cutoff=0.7)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _one_line(msg: str) -> str:
    return " ".join(str(msg).split())


def _known_kinds() -> str:
    return (
        f"known primitives: {', '.join(sorted(solids.KINDS))}; "
        f"operations: {', '.join([*OPERATIONS, *UNARY])}; or \"ref\""
    )


# -- loading ------------------------------------------------------------------------------------
_BUILDING = object()


class _KeyCheck:
    """check_values' stack entry for an object key (checked before the key's value)."""

    __slots__ = ("key",)

    def __init__(self, key):
        self.key = key


def _run(gen):
    """Run a generator that yields sub-generators (``x = yield sub`` runs ``sub`` and sends
    back its return value) with an explicit stack instead of recursion; return its result."""
    stack = [gen]
    value = None
    while True:
        try:
            sub = stack[-1].send(value)
        except StopIteration as stop:
            stack.pop()
            if not stack:
                return stop.value
            value = stop.value
            continue
        assert type(sub) is GeneratorType
        stack.append(sub)
        value = None


class _Loader:
    def __init__(self, source: str):
        self.source = source
        self.defs: dict = {}
        self.built: dict = {}
        self.stack: list = []

    def fail(self, path: str, reason: str, cls=SceneError):
        raise cls(_one_line(f"{self.source}: {path}: {reason}"))

    # values that JSON cannot hold or that Python's json accepts anyway
    def check_values(self, v, path: str):
        """Depth-first, in document order, with an explicit stack (no recursion)."""
        todo = [(v, path)]
        while todo:
            v, path = todo.pop()
            if isinstance(v, _KeyCheck):  # an object key, checked just before its value
                if not isinstance(v.key, str):
                    self.fail(path, f"object keys must be strings, got {_jtype(v.key)}")
                continue
            self.check_value(v, path, todo)

    def check_value(self, v, path: str, todo: list):
        if isinstance(v, _BadConstant):
            self.fail(path, f"{v.token} is not allowed (JSON numbers must be finite)")
        if isinstance(v, dict):
            dup = getattr(v, "duplicate", None)
            if dup is not None:
                self.fail(_key(path, dup), f"duplicate key {dup!r}")
            for k, x in reversed(list(v.items())):
                todo.append((x, _key(path, k)))
                todo.append((_KeyCheck(k), path))
        elif isinstance(v, (list, tuple)):
            for i in range(len(v) - 1, -1, -1):
                todo.append((v[i], _idx(path, i)))
        elif _is_number(v):
            try:
                ok = math.isfinite(float(v))
            except OverflowError:
                ok = False
            if not ok:
                what = "NaN" if v != v else "out of range (it overflows a double to infinity)"
                self.fail(path, f"number {what} is not allowed (JSON numbers must be finite)")

    def scene(self, data) -> Scene:
        self.check_values(data, "$")
        if not isinstance(data, dict):
            self.fail("$", f"a scene file holds a JSON object, got {_jtype(data)}")
        if "clcsg" not in data:
            self.fail("$", f'missing key "clcsg" (the format version, {FORMAT_VERSION})')
        version = data["clcsg"]
        if not _is_number(version) or isinstance(version, float):
            self.fail("$.clcsg", f"the format version must be the integer {FORMAT_VERSION}, got {_jtype(version)}")
        if version != FORMAT_VERSION:
            self.fail("$.clcsg", f"unsupported format version {version} (this clcsg reads version {FORMAT_VERSION})")
        for k in data:
            if k not in TOP_KEYS:
                self.fail(_key("$", k), f"unknown key {k!r}{_suggest(k, TOP_KEYS)}; a scene has {', '.join(TOP_KEYS[:4])}")
        self.comment(data, "$")
        if "$schema" in data and not isinstance(data["$schema"], str):
            self.fail(_key("$", "$schema"), f"expected a string, got {_jtype(data['$schema'])}")
        if "root" not in data:
            self.fail("$", 'missing key "root" (the top node of the scene)')
        bound = self.bound(data["bound"], "$.bound") if "bound" in data else None
        defs = data.get("defs", {})
        if not isinstance(defs, dict):
            self.fail("$.defs", f"expected an object mapping names to nodes, got {_jtype(defs)}")
        for name in defs:
            if not name:
                self.fail(_key("$.defs", name), "a definition name must not be empty")
        self.defs = defs
        shape = self.node(data["root"], "$.root")
        for name in defs:  # unused definitions are validated as well
            self.ref(name, _key("$.defs", name))
        return Scene(shape, bound, self.source)

    def comment(self, obj, path):
        if "comment" in obj and not isinstance(obj["comment"], str):
            self.fail(_key(path, "comment"), f"a comment must be a string, got {_jtype(obj['comment'])}")

    # -- scalars and vectors
    def number(self, v, path, what="a number"):
        if not _is_number(v):
            self.fail(path, f"expected {what}, got {_jtype(v)}")
        return v

    def positive(self, v, path):
        self.number(v, path, "a positive number")
        if not v > 0:
            self.fail(path, f"must be positive, got {v}")
        return v

    def nonnegative(self, v, path):
        self.number(v, path, "a non-negative number")
        if v < 0:
            self.fail(path, f"must be non-negative, got {v}")
        return v

    def numbers(self, v, n, path, what=None, check=None):
        what = what or f"{n} numbers"
        if not isinstance(v, (list, tuple)):
            self.fail(path, f"expected {what}, got {_jtype(v)}")
        if len(v) != n:
            self.fail(path, f"expected {what}, got {_jtype(v)}")
        for i, x in enumerate(v):
            (check or self.number)(x, _idx(path, i))
        return list(v)

    def vec3(self, v, path):
        return self.numbers(v, 3, path, "3 numbers [x, y, z]")

    def direction(self, v, path):
        self.vec3(v, path)
        if all(x == 0 for x in v):
            self.fail(path, "a direction must not be the zero vector")
        return list(v)

    def bound(self, v, path):
        if not isinstance(v, (list, tuple)) or len(v) != 2:
            self.fail(path, f"expected two corners [[x0, y0, z0], [x1, y1, z1]], got {_jtype(v)}")
        lo = self.vec3(v[0], _idx(path, 0))
        hi = self.vec3(v[1], _idx(path, 1))
        if not all(a < b for a, b in zip(lo, hi)):
            self.fail(path, f"the lower corner {lo} must be below the upper corner {hi} on every axis")
        return np.array([lo, hi], dtype=np.float64)

    def color(self, v, path):
        if isinstance(v, str):
            m = _HEX_COLOR.match(v)
            if not m:
                self.fail(path, f"expected [r, g, b], [r, g, b, a] or \"#rrggbb[aa]\", got {v!r}")
            h = m.group(1)
            return [int(h[i : i + 2], 16) / 255.0 for i in range(0, len(h), 2)]
        if not isinstance(v, (list, tuple)) or len(v) not in (3, 4):
            self.fail(path, f"expected [r, g, b] or [r, g, b, a] with components in [0, 1], got {_jtype(v)}")
        for i, x in enumerate(v):
            self.number(x, _idx(path, i))
            if not 0 <= x <= 1:
                self.fail(_idx(path, i), f"color components must be in [0, 1], got {x}")
        return list(v)

    # -- nodes
    #
    # _node() and _ref() are recursive descent written as generators: ``x = yield gen`` runs
    # the sub-node ``gen`` and sends back its shape.  _run() keeps the pending nodes on an
    # explicit stack, so a deep chain (nested operations or a long chain of refs through
    # "defs") needs no Python recursion.
    def node(self, v, path) -> Shape:
        return _run(self._node(v, path))

    def ref(self, name, path) -> Shape:
        return _run(self._ref(name, path))

    def _node(self, v, path):
        if not isinstance(v, dict):
            self.fail(path, f"expected a node object, got {_jtype(v)}")
        kinds = [k for k in v if k in solids.KINDS or k in OPERATIONS or k in UNARY or k == "ref"]
        extras = [k for k in v if k not in kinds and k not in NODE_EXTRA_KEYS]
        if len(kinds) > 1:
            self.fail(path, f"a node has exactly one kind, this one has {kinds[0]!r} and {kinds[1]!r}"
                      " (combine them with an operation such as \"union\")")
        if not kinds:
            if extras:
                choices = [*solids.KINDS, *OPERATIONS, *UNARY, "ref"]
                self.fail(_key(path, extras[0]),
                          f"unknown node kind {extras[0]!r}{_suggest(extras[0], choices)}; {_known_kinds()}")
            self.fail(path, f"node has no kind; {_known_kinds()}")
        kind = kinds[0]
        allowed = ("color", "transform", "comment") if kind in solids.KINDS else ("transform", "comment")
        for k in extras:
            self.fail(_key(path, k), f"unknown key {k!r}{_suggest(k, allowed)} in a {kind} node; allowed next to "
                      f"{kind!r}: {', '.join(allowed)}")
        if "color" in v and kind not in solids.KINDS:
            self.fail(_key(path, "color"), f"color is only allowed on primitives, not on a {kind} node")
        self.comment(v, path)
        kpath = _key(path, kind)
        arg = v[kind]
        if kind in solids.KINDS:
            color = self.color(v["color"], _key(path, "color")) if "color" in v else None
            shape = self.primitive(kind, arg, color, kpath)
        elif kind in OPERATIONS:
            if not isinstance(arg, (list, tuple)):
                self.fail(kpath, f"expected a list of nodes, got {_jtype(arg)}")
            if not arg and kind != "union":
                self.fail(kpath, f"{kind} needs at least one operand")
            operands = []
            for i, c in enumerate(arg):
                operands.append((yield self._node(c, _idx(kpath, i))))
            shape = OPERATIONS[kind](operands)
        elif kind == "complement":
            shape = Complement((yield self._node(arg, kpath)))
        else:
            if not isinstance(arg, str):
                self.fail(kpath, f"expected the name of a definition, got {_jtype(arg)}")
            shape = yield self._ref(arg, kpath)
        if "transform" in v:
            shape = self.transform(shape, v["transform"], _key(path, "transform"))
        return shape

    def _ref(self, name, path):
        if name not in self.defs:
            known = f"defined: {', '.join(map(repr, self.defs))}" if self.defs else 'the scene has no "defs"'
            self.fail(path, f"undefined ref {name!r}{_suggest(name, self.defs)}; {known}")
        got = self.built.get(name)
        if got is _BUILDING:
            cycle = self.stack[self.stack.index(name):] + [name]
            self.fail(path, f"reference cycle: {' -> '.join(cycle)}")
        if got is not None:
            return got
        self.built[name] = _BUILDING
        self.stack.append(name)
        shape = yield self._node(self.defs[name], _key("$.defs", name))
        self.stack.pop()
        self.built[name] = shape
        return shape

    def primitive(self, kind, params, color, path) -> Primitive:
        known = solids.parameters(kind)
        if not isinstance(params, dict):
            self.fail(path, f"expected an object of {kind} parameters ({', '.join(known)}), got {_jtype(params)}")
        for name, value in params.items():
            if name not in known:
                self.fail(_key(path, name), f"unknown {kind} parameter {name!r}{_suggest(name, known)}; "
                          f"{kind} takes {', '.join(known)}")
            self.parameter(kind, name, value, known[name], _key(path, name))
        for name, default in known.items():
            if default is inspect.Parameter.empty and name not in params:
                self.fail(path, f"missing {kind} parameter {name!r}")
        try:
            return Primitive(kind, dict(params), color)
        except (ValueError, TypeError, ArithmeticError) as e:
            msg = str(e)
            named = [n for n in params if re.search(rf"(?<![A-Za-z0-9_]){re.escape(n)}(?![A-Za-z0-9_])", msg)]
            self.fail(_key(path, named[0]) if len(named) == 1 else path, msg)

    def parameter(self, kind, name, v, default, path):
        """JSON-shape checks of a primitive parameter; the solid checks the geometry."""
        if name in ("center", "apex"):
            self.vec3(v, path)
        elif name in ("axis", "normal"):
            self.direction(v, path)
        elif name in ("radius", "height", "slope"):
            self.positive(v, path)
        elif name in ("r1", "r2"):
            self.nonnegative(v, path)
        elif name == "size":
            if _is_number(v):
                self.positive(v, path)
            else:
                self.numbers(v, 3, path, "a positive number or 3 positive numbers", self.positive)
        elif name == "radii":
            n = len(default) if isinstance(default, (list, tuple)) else 3
            if _is_number(v) and kind == "ellipsoid":  # one radius for all three axes
                self.positive(v, path)
            else:
                self.numbers(v, n, path, f"{n} positive numbers", self.positive)
        elif name == "matrix":
            if isinstance(v, (list, tuple)) and len(v) == 10 and all(_is_number(x) for x in v):
                if not any(v):  # solids checks this for 4x4 matrices only
                    self.fail(path, "quadric matrix must not be zero")
                return
            if not isinstance(v, (list, tuple)) or len(v) != 4:
                self.fail(path, f"expected a symmetric 4x4 matrix (4 rows of 4 numbers) or 10 coefficients, got {_jtype(v)}")
            for i, row in enumerate(v):
                self.numbers(row, 4, _idx(path, i), "a row of 4 numbers")
        elif _is_number(default):
            self.number(v, path)
        elif isinstance(default, (list, tuple)) and all(_is_number(x) for x in default):
            self.numbers(v, len(default), path)

    # -- transforms
    def transform(self, shape: Shape, steps, path) -> Shape:
        if not isinstance(steps, (list, tuple)):
            self.fail(path, f"expected a list of transform steps ({', '.join(TRANSFORM_STEPS)}), got {_jtype(steps)}")
        for i, step in enumerate(steps):
            spath = _idx(path, i)
            if not isinstance(step, dict) or len(step) != 1:
                what = _jtype(step) if not isinstance(step, dict) else f"an object with {len(step)} keys"
                self.fail(spath, f"a transform step is an object with one key ({', '.join(TRANSFORM_STEPS)}), got {what}")
            (op, arg), = step.items()
            opath = _key(spath, op)
            if op not in TRANSFORM_STEPS:
                self.fail(opath, f"unknown transform step {op!r}{_suggest(op, TRANSFORM_STEPS)}; "
                          f"steps are {', '.join(TRANSFORM_STEPS)}")
            try:
                shape = self.step(shape, op, arg, opath)
            except TransformError as e:
                self.fail(opath, str(e), TransformError)
            except (ValueError, ArithmeticError) as e:
                self.fail(opath, str(e), TransformError)
        return shape

    def step(self, shape, op, arg, path) -> Shape:
        if op == "translate":
            return shape.translate(self.vec3(arg, path))
        if op == "scale":
            if _is_number(arg):
                return shape.scale(arg)
            return shape.scale(self.numbers(arg, 3, path, "a number or 3 numbers [sx, sy, sz]"))
        if op == "rotate":
            if not isinstance(arg, dict):
                self.fail(path, f'expected {{"axis": [x, y, z], "degrees": d}}, got {_jtype(arg)}')
            for k in arg:
                if k not in ("axis", "degrees"):
                    self.fail(_key(path, k), f"unknown rotate key {k!r}{_suggest(k, ('axis', 'degrees'))}; "
                              "rotate takes axis and degrees")
            for k in ("axis", "degrees"):
                if k not in arg:
                    self.fail(path, f"rotate needs {k!r}")
            axis = self.direction(arg["axis"], _key(path, "axis"))
            degrees = self.number(arg["degrees"], _key(path, "degrees"))
            return shape.rotate(axis, degrees)
        # matrix
        if not isinstance(arg, (list, tuple)) or len(arg) not in (3, 4):
            self.fail(path, f"expected a 4x4 matrix (4 rows of 4 numbers), got {_jtype(arg)}")
        for i, row in enumerate(arg):
            self.numbers(row, 4, _idx(path, i), "a row of 4 numbers")
        return shape.transform(np.array(arg, dtype=np.float64))


# -- saving -------------------------------------------------------------------------------------
class _Saver:
    def __init__(self, source: str):
        self.source = source
        self.shared: set[int] = set()
        self.names: dict[int, str] = {}
        self.defs: dict[str, Any] = {}
        self.counts: dict[str, int] = {}

    def fail(self, reason):
        raise SceneError(_one_line(f"{self.source}: cannot save: {reason}"))

    def scene(self, scene: Scene) -> dict:
        root = scene.shape
        if not isinstance(root, Shape):
            self.fail(f"the scene's shape is a {type(root).__name__}, not a CSG shape")
        parents: dict[int, int] = {}
        seen: set[int] = set()
        stack = [root]
        while stack:  # count incoming edges; a node with two or more is written once, as a def
            node = stack.pop()
            if id(node) in seen:
                continue
            seen.add(id(node))
            for c in node.children():
                parents[id(c)] = parents.get(id(c), 0) + 1
                stack.append(c)
        self.shared = {i for i, n in parents.items() if n > 1}
        out: dict[str, Any] = {"clcsg": FORMAT_VERSION}
        if scene.bound is not None:
            b = np.asarray(scene.bound, dtype=np.float64)
            out["bound"] = [[_jnum(x) for x in row] for row in b.reshape(2, 3)]
        body = self.node(root, top=True)
        if self.defs:
            out["defs"] = self.defs
        out["root"] = body
        return out

    def node(self, node: Shape, top=False) -> dict:
        return _run(self._node(node, top, 0))

    # a generator like _Loader._node (no recursion); ``depth`` counts the operations above
    # ``node`` in the object being written: at SAVE_DEPTH the subtree becomes a def
    def _node(self, node: Shape, top: bool, depth: int):
        if id(node) in self.shared and not top:
            name = self.names.get(id(node))
            if name is None:
                name = self.new_name(node)
                self.names[id(node)] = name
                self.defs[name] = None  # reserve the slot: defs keep first-use order
                self.defs[name] = yield self._node(node, True, 0)
            return {"ref": name}
        steps = []
        cur = node
        while isinstance(cur, Transformed) and (cur is node or id(cur) not in self.shared):
            steps.append(_step(cur.matrix))
            cur = cur.operand
        if steps:
            out = yield self._node(cur, False, depth)
            out["transform"] = steps[::-1]  # innermost edge is applied first
            return out
        if isinstance(node, Primitive):
            out = {node.kind: {k: _jvalue(v, self.fail) for k, v in node.params.items()}}
            if tuple(node.color) != tuple(DEFAULT_COLOR):
                c = [_jnum(x) for x in node.color]
                out["color"] = c[:3] if c[3] == 1.0 else c
            return out
        if depth >= SAVE_DEPTH and not top:
            # too deep for one JSON object (json.loads recurses per level): the rest of the
            # chain is written as a def, used once, which loads back to the same graph
            name = self.new_name(node)
            self.defs[name] = None
            self.defs[name] = yield self._node(node, True, 0)
            return {"ref": name}
        for name, cls in OPERATIONS.items():
            if type(node) is cls:
                operands = []
                for c in node.operands:
                    operands.append((yield self._node(c, False, depth + 1)))
                return {name: operands}
        if type(node) is Complement:
            return {"complement": (yield self._node(node.operand, False, depth + 1))}
        self.fail(f"unknown CSG node type {type(node).__name__}")

    def new_name(self, node) -> str:
        if isinstance(node, Primitive):
            label = node.kind
        elif isinstance(node, Transformed):
            label = "transformed"
        else:
            label = type(node).__name__.lower()
        while True:
            n = self.counts.get(label, 0) + 1
            self.counts[label] = n
            name = f"{label}{n}"
            if name not in self.defs:
                return name


def _jnum(x):
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, numbers.Integral):
        return int(x)
    f = float(x)
    if not math.isfinite(f):
        raise SceneError(f"cannot save the non-finite number {f}")
    return f


def _jvalue(v, fail):
    if isinstance(v, np.ndarray):
        v = v.tolist()
    if isinstance(v, (list, tuple)):
        return [_jvalue(x, fail) for x in v]
    if isinstance(v, dict):
        return {str(k): _jvalue(x, fail) for k, x in v.items()}
    if v is None or isinstance(v, str):
        return v
    if isinstance(v, (numbers.Real, np.generic)):
        return _jnum(v)
    fail(f"parameter value {v!r} has no JSON form")


def _step(m: np.ndarray) -> dict:
    """The shortest transform step that rebuilds ``m`` bit for bit."""
    lin, t = m[:3, :3], m[:3, 3]
    if np.array_equal(lin, np.eye(3)) and np.array_equal(m[3], [0, 0, 0, 1]):
        return {"translate": [_jnum(x) for x in t]}
    if np.array_equal(lin, np.diag(np.diag(lin))) and not t.any() and np.array_equal(m[3], [0, 0, 0, 1]):
        d = [_jnum(x) for x in np.diag(lin)]
        return {"scale": d[0] if d[0] == d[1] == d[2] else d}
    return {"matrix": [[_jnum(x) for x in row] for row in m]}


def _fmt(v, indent: int, col: int) -> str:
    flat = json.dumps(v, allow_nan=False, ensure_ascii=False, separators=(", ", ": "))
    if not isinstance(v, (dict, list)) or not v or col + len(flat) <= WIDTH:
        return flat
    inner = indent + 2
    pad = " " * inner
    if isinstance(v, dict):
        parts = []
        for k, x in v.items():
            ks = json.dumps(k, ensure_ascii=False) + ": "
            parts.append(pad + ks + _fmt(x, inner, inner + len(ks)))
        return "{\n" + ",\n".join(parts) + "\n" + " " * indent + "}"
    parts = [pad + _fmt(x, inner, inner) for x in v]
    return "[\n" + ",\n".join(parts) + "\n" + " " * indent + "]"
