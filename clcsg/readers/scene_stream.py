"""A ``.json`` scene file read as a stream of JSON events (``ijson``), node by node.

The whole document is never held: :class:`StreamLoader` builds JSON values from ``ijson``'s
events and, as each node object of ``root`` ends, validates it against the node schema
(one node at a time, as :mod:`clcsg.readers.scene_schema` does) and replaces it by its
:class:`~clcsg.model.csg.Shape`, so memory holds the model, the objects still open on the
path to the current event, and ``defs`` (kept as JSON: a def may use a def written after it).
Refs resolve against ``defs`` written before ``root``, which is how :func:`clcsg.save` writes
them.

The stream only reads valid files.  At the first problem of any kind (invalid JSON, a
duplicate key, a number that is not finite, a ref to a def that comes later, a schema or
solid error) it raises :class:`Restart`, and the caller reads the file whole with the
document loader, which reports the first problem in document order with its JSON path
exactly as before (or, for a file too large to read whole, the problem met here).
"""

from __future__ import annotations

import math
import os
import sys

import ijson

from ..errors import LimitError, SceneError
from ..model.csg import Shape
from ..model.scene import Scene
from .budget import JSON_FACTOR, WHOLE_JSON_FACTOR, check_file
from .scene_schema import CONSTRUCTIONS, key
from .scenefile import OPERATIONS, _Loader, _Object, _one_line, loads_json
from .trampoline import run

#: node keys whose value is a list of nodes, and the one whose value is a node
_NODE_LISTS = frozenset((*OPERATIONS, *(c for c in CONSTRUCTIONS if c in ("hull", "minkowski"))))
_NODE_ONE = "complement"

#: deepest nesting of arrays and objects streamed: about what Python's ``json`` (which the
#: document loader uses) reads, so that both read the same files
_DEPTH = sys.getrecursionlimit() - 100

#: what the children of a container are
_RAW, _NODE, _TOP, _NODES = 0, 1, 2, 3


class Restart(Exception):
    """The stream met something the document loader must report (``reason`` says what)."""

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason


class _Open:
    """A container being built: the value, what it is (a node, the document, ...), its JSON
    path and the key whose value comes next."""

    __slots__ = ("value", "role", "path", "key")

    def __init__(self, value, role, path):
        self.value = value
        self.role = role
        self.path = path
        self.key = None


class StreamLoader(_Loader):
    """``StreamLoader(source).load(binary_file)``: the Scene of a valid scene file."""

    def load(self, f) -> Scene:
        try:
            top = self._document(ijson.basic_parse(f, use_float=True))
        except ijson.JSONError as e:
            raise Restart(f"invalid JSON: {' '.join(str(e).split()[:8])}") from None
        except SceneError as e:
            raise Restart(str(e)) from None
        try:
            return self._finish(top)
        except SceneError as e:
            raise Restart(str(e)) from None

    def _finish(self, top) -> Scene:
        self.validate(self.schema.document_errors(top), "$")
        if isinstance(top["clcsg"], float):
            raise Restart("the format version is not an integer")
        bound = self.bound(top["bound"], "$.bound") if "bound" in top else None
        self.defs = top.get("defs", {})
        shape = top["root"]
        if not isinstance(shape, Shape):  # pragma: no cover - the schema requires an object
            raise Restart("the root is not a node")
        for name in self.defs:  # unused definitions are validated as well
            run(self._ref(name, key("$.defs", name)))
        return Scene(shape, bound, self.source)

    def _document(self, events):
        stack: list[_Open] = []
        result = None
        for event, value in events:
            if event == "map_key":
                stack[-1].key = value
                continue
            if event == "start_map" or event == "start_array":
                role, path = self._child(stack)
                if event == "start_map":
                    new = _Open(_Object(), _TOP if not stack else (_NODE if role == _NODE else _RAW), path)
                else:
                    new = _Open([], _NODES if role == _NODES else _RAW, path)
                stack.append(new)
                if len(stack) > _DEPTH:
                    raise Restart("nesting too deep")
                continue
            if event == "end_map" or event == "end_array":
                done = stack.pop()
                value = done.value
                if done.role == _NODE:
                    value = self.node(value, done.path)
                elif done.role == _TOP:
                    for _ in events:  # anything after the document is an error: ijson raises it
                        raise Restart("data after the document")
                    return value
            elif event == "number" and type(value) is int:
                try:
                    math.isfinite(float(value))
                except OverflowError:
                    raise Restart("an integer overflows a double") from None
            if not stack:
                result = value
                break
            self._put(stack[-1], value)
        return result  # a document that is not an object: the document loader says so

    def _child(self, stack):
        """(role, JSON path) of the value that starts next."""
        if not stack:
            return _TOP, "$"
        parent = stack[-1]
        if parent.role == _NODES:
            return _NODE, f"{parent.path}[{len(parent.value)}]"
        k = parent.key
        if isinstance(parent.value, list):
            return _RAW, ""
        if parent.role == _TOP:
            if k == "root":
                if "defs" in parent.value:
                    self.defs = parent.value["defs"]
                return _NODE, "$.root"
            return _RAW, ""
        if parent.role == _NODE:
            if k in _NODE_LISTS:
                return _NODES, key(parent.path, k)
            if k == _NODE_ONE:
                return _NODE, key(parent.path, k)
        return _RAW, ""

    @staticmethod
    def _put(parent: _Open, value) -> None:
        c = parent.value
        if type(c) is list:
            c.append(value)
            return
        k = parent.key
        if k in c:
            raise Restart(f"duplicate key {k!r}")
        c[k] = value


def load_json(path) -> Scene:
    """Load and validate a ``.json`` scene file.

    A valid file is read as a stream, node by node (:class:`StreamLoader`: memory
    holds the model, not the document); a file with a problem is then read whole, so
    that the first problem in document order is the one reported."""
    p = os.fspath(path)
    check_file(p, JSON_FACTOR)
    try:
        with open(p, "rb") as f:
            if f.read(3) != b"\xef\xbb\xbf":
                f.seek(0)
            return StreamLoader(p).load(f)
    except Restart as e:
        restart = e.reason
    except FileNotFoundError:
        raise SceneError(f"{p}: no such file") from None
    except OSError as e:
        raise SceneError(f"{p}: cannot read: {e.strerror or e}") from None
    try:
        check_file(p, WHOLE_JSON_FACTOR)
    except LimitError:  # too large to read whole: what the stream met is the message
        raise SceneError(_one_line(restart if restart.startswith(p) else f"{p}: {restart}")) from None
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
