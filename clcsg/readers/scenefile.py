"""clcsg's JSON scene format (version 1): load, validate and save CSG graphs.

A scene file is one JSON object (full description in ``docs/scene-format.md``, JSON Schema in
``clcsg/readers/schema/scene.schema.json``)::

    {"clcsg": 1,
     "bound": [[-2, -2, -2], [2, 2, 2]],                      (optional)
     "defs": {"hole": {"cylinder": {"radius": 0.2, "height": 3}}},   (optional)
     "root": {"difference": [{"box": {"size": 2}, "color": [0.9, 0.5, 0.1]},
                             {"ref": "hole"},
                             {"ref": "hole", "transform": [{"rotate": {"axis": [1, 0, 0], "degrees": 90}}]}]}}

Nodes map one to one onto :mod:`clcsg.model.csg`: a primitive kind from
:data:`clcsg.model.solids.KINDS` is a :class:`~clcsg.model.csg.Primitive`, ``union`` /
``intersection`` / ``difference`` / ``complement`` are the operation classes, every
``transform`` step is one :class:`~clcsg.model.csg.Transformed` edge (built exactly as
``Shape.translate`` / ``rotate`` / ``scale`` / ``transform`` build it), and every
``{"ref": name}`` to the same definition is the *same* Python object, so shared sub-graphs
stay shared.  :func:`scene_to_dict` inverts this: it finds nodes with more than one parent (by
identity) and writes them once under ``defs``.  Floats are written with ``repr`` precision, so
a saved graph loads back bit for bit.

Validation: the structure (keys, types, ranges, transform steps, colors) is checked by
``jsonschema`` against the shipped schema (:mod:`clcsg.readers.scene_schema`, one node at a time);
this module checks what a schema cannot say: finite numbers and unique keys (Python's ``json``
accepts NaN, Infinity and duplicates), the integer version, ``lo < hi`` in the bound, defined
and acyclic refs, color names (:mod:`clcsg.model.colors`), the solids' own rules (a cone needs
r1 > 0 or r2 > 0, a slab lo < hi, a quadric matrix symmetric and non-zero) and non-singular
affine transforms.

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

import json
import math
import numbers
import re
from typing import Any

import numpy as np

from ..atomic import atomic_open
from ..errors import SceneError, TransformError
from ..model import solids
from ..model.csg import DEFAULT_COLOR, Complement, Difference, Intersection, Primitive, Shape, Transformed, Union
from ..model.construction import Construction, first_color
from ..model.extrude import extrude
from ..model.hull import hull, minkowski
from ..model.polyhedron import polyhedron
from ..model.revolve import revolve
from ..model.scene import Scene
from ..model.colors import ColorError, parse_color
from .budget import WHOLE_JSON_FACTOR, check_input
from .mesh_files import load_mesh, resolve
from ..model.surfels import Surfels
from .profile_json import profile_from_json
from .scene_schema import CONSTRUCTIONS, FORMAT_VERSION, TOP_KEYS, TRANSFORM_STEPS, UNARY, join, jtype, key, scene_schema, suggest
from .trampoline import run

#: variadic operations (JSON key -> class); ``complement`` takes a single node
OPERATIONS = {"union": Union, "intersection": Intersection, "difference": Difference}
NODE_EXTRA_KEYS = ("transform", "color", "comment")

__all__ = ["FORMAT_VERSION", "OPERATIONS", "CONSTRUCTIONS", "UNARY", "TRANSFORM_STEPS", "TOP_KEYS", "NODE_EXTRA_KEYS", "WIDTH",
           "SAVE_DEPTH", "loads_json", "parse_json", "scene_from_dict", "scene_to_dict", "dumps",
           "save_json"]

#: line width of :func:`dumps`
WIDTH = 96

#: deepest nesting of operations that :func:`scene_to_dict` writes into one JSON object; a
#: deeper chain continues in a def (``{"ref": ...}``), so that saved files stay within the
#: nesting that Python's ``json`` module can read (about 1000 levels of arrays and objects,
#: two per operation)
SAVE_DEPTH = 100


# -- public API ---------------------------------------------------------------------------------
def loads_json(text: str, source: str = "<string>") -> Scene:
    """Parse and validate scene JSON text; ``source`` names it in error messages."""
    return scene_from_dict(parse_json(text, source), source)


def parse_json(text: str, source: str = "<string>") -> Any:
    """Strict JSON parsing: syntax errors with line and column; NaN, Infinity and duplicate
    keys are kept as markers that :func:`scene_from_dict` reports with their JSON path."""
    if isinstance(text, str):
        check_input(source, len(text), WHOLE_JSON_FACTOR)
    try:
        return json.loads(text, parse_constant=_BadConstant, object_pairs_hook=_object)
    except json.JSONDecodeError as e:
        raise SceneError(f"{source}: line {e.lineno}, column {e.colno}: invalid JSON: {e.msg}") from None
    except RecursionError:
        raise SceneError(f"{source}: $: nesting too deep") from None


def scene_from_dict(data, source: str = "scene") -> Scene:
    """Build a :class:`~clcsg.model.scene.Scene` from parsed JSON data (dicts, lists, numbers)."""
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
    text = dumps(scene_to_dict(scene))
    with atomic_open(path, "w", "scene") as f:
        f.write(text)


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


def _is_number(v) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, (bool, np.bool_))


def _one_line(msg: str) -> str:
    return " ".join(str(msg).split())


# -- loading ------------------------------------------------------------------------------------
_BUILDING = object()


class _KeyCheck:
    """check_values' stack entry for an object key (checked before the key's value)."""

    __slots__ = ("key",)

    def __init__(self, key):
        self.key = key


class _Loader:
    def __init__(self, source: str):
        self.source = source
        self.defs: dict = {}
        self.built: dict = {}
        self.stack: list = []
        self.schema = scene_schema()

    def fail(self, path: str, reason: str, cls=SceneError):
        raise cls(_one_line(f"{self.source}: {path}: {reason}"))

    def validate(self, problem, path: str):
        """Report the schema's first error (``(parts, reason)`` or None) under ``path``."""
        if problem is not None:
            parts, reason = problem
            self.fail(join(path, parts), reason)

    # values that JSON cannot hold or that Python's json accepts anyway
    def check_values(self, v, path: str):
        """Depth-first, in document order, with an explicit stack (no recursion)."""
        todo = [(v, path)]
        while todo:
            v, path = todo.pop()
            if isinstance(v, _KeyCheck):  # an object key, checked just before its value
                if not isinstance(v.key, str):
                    self.fail(path, f"object keys must be strings, got {jtype(v.key)}")
                continue
            if isinstance(v, _BadConstant):
                self.fail(path, f"{v.token} is not allowed (JSON numbers must be finite)")
            if isinstance(v, dict):
                dup = getattr(v, "duplicate", None)
                if dup is not None:
                    self.fail(key(path, dup), f"duplicate key {dup!r}")
                for k, x in reversed(list(v.items())):
                    todo.append((x, key(path, k)))
                    todo.append((_KeyCheck(k), path))
            elif isinstance(v, (list, tuple)):
                todo.extend((v[i], f"{path}[{i}]") for i in range(len(v) - 1, -1, -1))
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
        self.validate(self.schema.document_errors(data), "$")
        if isinstance(data["clcsg"], float):  # 1.0: JSON Schema cannot tell it from 1
            self.fail("$.clcsg", f"the format version must be the integer {FORMAT_VERSION}, got {data['clcsg']!r}")
        bound = self.bound(data["bound"], "$.bound") if "bound" in data else None
        self.defs = data.get("defs", {})
        shape = self.node(data["root"], "$.root")
        for name in self.defs:  # unused definitions are validated as well
            run(self._ref(name, key("$.defs", name)))
        return Scene(shape, bound, self.source)

    def bound(self, v, path):
        lo, hi = list(v[0]), list(v[1])
        if not all(a < b for a, b in zip(lo, hi)):
            self.fail(path, f"the lower corner {lo} must be below the upper corner {hi} on every axis")
        return np.array([lo, hi], dtype=np.float64)

    def color(self, v, path):
        try:
            return parse_color(v)
        except ColorError as e:
            self.fail(path, str(e))

    # -- nodes
    #
    # _node() and _ref() are recursive descent written as generators: ``x = yield gen`` runs
    # the sub-node ``gen`` and sends back its shape.  run() keeps the pending nodes on an
    # explicit stack, so a deep chain (nested operations or a long chain of refs through
    # "defs") needs no Python recursion.  Each node is validated against the schema when it is
    # met (its operands are validated when they are met in turn).
    def node(self, v, path) -> Shape:
        return run(self._node(v, path))

    def _node(self, v, path):
        if isinstance(v, Shape):  # built already (the streaming loader builds nodes as they end)
            return v
        self.validate(self.schema.node_errors(v), path)
        kind = next(k for k in v if k not in NODE_EXTRA_KEYS)
        kpath = key(path, kind)
        arg = v[kind]
        if kind in solids.KINDS:
            color = self.color(v["color"], key(path, "color")) if "color" in v else None
            shape = self.primitive(kind, arg, color, kpath)
        elif kind in OPERATIONS:
            operands = []
            for i, c in enumerate(arg):
                operands.append((yield self._node(c, f"{kpath}[{i}]")))
            shape = OPERATIONS[kind](operands)
        elif kind == "complement":
            shape = Complement((yield self._node(arg, kpath)))
        elif kind in ("hull", "minkowski"):
            color = self.color(v["color"], key(path, "color")) if "color" in v else None
            operands = []
            for i, c in enumerate(arg):
                operands.append((yield self._node(c, f"{kpath}[{i}]")))
            shape = self.construction(kind, operands, color, kpath)
        elif kind in ("extrude", "revolve", "mesh", "surfels"):
            color = self.color(v["color"], key(path, "color")) if "color" in v else None
            shape = self.construction(kind, arg, color, kpath)
        else:
            shape = yield self._ref(arg, kpath)
        if "transform" in v:
            shape = self.transform(shape, v["transform"], key(path, "transform"))
        return shape

    def _ref(self, name, path):
        if name not in self.defs:
            known = f"defined: {', '.join(map(repr, self.defs))}" if self.defs else 'the scene has no "defs"'
            self.fail(path, f"undefined ref {name!r}{suggest(name, self.defs)}; {known}")
        got = self.built.get(name)
        if got is _BUILDING:
            cycle = self.stack[self.stack.index(name):] + [name]
            self.fail(path, f"reference cycle: {' -> '.join(cycle)}")
        if got is not None:
            return got
        self.built[name] = _BUILDING
        self.stack.append(name)
        shape = yield self._node(self.defs[name], key("$.defs", name))
        self.stack.pop()
        self.built[name] = shape
        return shape

    def construction(self, kind, arg, color, path) -> Shape:
        try:
            if kind == "hull":
                return hull(*arg, color=color)
            if kind == "minkowski":
                return minkowski(*arg, color=color)
            if kind == "mesh":
                return self.mesh(arg, color, path)
            if kind == "surfels":
                return self.surfels(arg, color, path)
            prof = profile_from_json(arg["profile"], key(path, "profile"), self.fail)
            if kind == "extrude":
                return extrude(prof, arg.get("height", 1.0), center=arg.get("center", False),
                               scale=arg.get("scale", 1.0), color=color)
            return revolve(prof, arg.get("angle", 360.0), color=color)
        except SceneError as e:
            if str(e).startswith(self.source):
                raise
            self.fail(path, str(e))

    def mesh(self, arg, color, path) -> Shape:
        """A ``mesh`` node: a file relative to the scene file, or points and faces."""
        if "file" in arg:
            return load_mesh(resolve(arg["file"], None if self.source.startswith("<") else self.source), color,
                             source=f"{self.source}: {key(path, 'file')}")
        return polyhedron(arg["points"], arg["faces"], color, source=f"{self.source}: {path}")

    def surfels(self, arg, color, path) -> Shape:
        """A ``surfels`` node: a PLY point cloud relative to the scene file, or points, normals
        and radii."""
        if "file" in arg:
            return load_mesh(resolve(arg["file"], None if self.source.startswith("<") else self.source), color,
                             source=f"{self.source}: {key(path, 'file')}")
        return Surfels(arg["points"], arg["normals"], arg["radii"], color, source=f"{self.source}: {path}")

    def primitive(self, kind, params, color, path) -> Primitive:
        m = params.get("matrix") if kind == "quadric" else None
        if m is not None and len(m) == 10 and not any(m):  # solids checks this for 4x4 matrices only
            self.fail(key(path, "matrix"), "quadric matrix must not be zero")
        try:
            return Primitive(kind, dict(params), color)
        except (ValueError, TypeError, ArithmeticError) as e:
            msg = str(e)
            named = [n for n in params if re.search(rf"(?<![A-Za-z0-9_]){re.escape(n)}(?![A-Za-z0-9_])", msg)]
            self.fail(key(path, named[0]) if len(named) == 1 else path, msg)

    # -- transforms (the steps' structure is the schema's)
    def transform(self, shape: Shape, steps, path) -> Shape:
        for i, step in enumerate(steps):
            (op, arg), = step.items()
            opath = key(f"{path}[{i}]", op)
            try:
                shape = self.step(shape, op, arg)
            except (TransformError, ValueError, ArithmeticError) as e:
                self.fail(opath, str(e), TransformError)
        return shape

    @staticmethod
    def step(shape, op, arg) -> Shape:
        if op == "translate":
            return shape.translate(list(arg))
        if op == "scale":
            return shape.scale(arg if _is_number(arg) else list(arg))
        if op == "rotate":
            return shape.rotate(list(arg["axis"]), arg["degrees"])
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
        return run(self._node(node, top, 0))

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
        if isinstance(node, Surfels):
            out = {"surfels": {"points": node.points.tolist(), "normals": node.normals.tolist(),
                               "radii": node.radii.tolist()}}
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
        if isinstance(node, Construction) and node.spec is not None:
            return (yield self._construction(node, depth))
        for name, cls in OPERATIONS.items():
            if isinstance(node, cls):  # also a construction without a spec: its expansion
                operands = []
                for c in node.operands:
                    operands.append((yield self._node(c, False, depth + 1)))
                return {name: operands}
        if type(node) is Complement:
            return {"complement": (yield self._node(node.operand, False, depth + 1))}
        self.fail(f"unknown CSG node type {type(node).__name__}")

    def _construction(self, node, depth):
        color = first_color([node.operands[0]])
        if isinstance(node.spec, dict):
            out = dict(node.spec)
            implied = DEFAULT_COLOR
        else:
            kind, operands = node.spec
            out = {kind: []}
            for c in operands:
                out[kind].append((yield self._node(c, False, depth + 1)))
            implied = first_color(operands)
        if color is not None and tuple(color) != tuple(implied or DEFAULT_COLOR):
            c = [_jnum(x) for x in color]
            out["color"] = c[:3] if c[3] == 1.0 else c
        return out

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
