"""Validation of scene files against the shipped JSON Schema (``schema/scene.schema.json``) with
the ``jsonschema`` package, and the translation of its errors into clcsg's one-line messages
(``<json path>: <reason>``, e.g. ``$.root.box.size[1]: must be positive, got -2``).

The schema is the whole structural contract of the format: which keys a node has, the types
and ranges of every parameter, transform steps, colors.  Nodes are validated one at a time
(:meth:`SceneSchema.node_errors`) with a *shallow* copy of the schema in which every nested
node is ``true``: the loader walks the graph with an explicit stack and validates each node
where it meets it, so a deep chain needs no deep recursion in ``jsonschema`` (which needs
about 20 Python frames per level) and a shared definition is validated once.

:func:`explain` turns a ``jsonschema.ValidationError`` into (path, reason).  The reasons come
from the failing keyword and the schema's ``title`` of the value (``expected 3 numbers [x, y,
z], got array of 2``); unions (``oneOf``) report the alternative that the value's type
selects, or the union's title when none or several fit.
"""

from __future__ import annotations

import json
import numbers
import re
from importlib import resources

import numpy as np

from ..model import solids

#: variadic operations, then the unary one and ``ref``: the node kinds besides primitives
OPERATIONS = ("union", "intersection", "difference")
UNARY = ("complement",)
#: constructions: solids built exactly from a 2-D profile, from other nodes or from a closed mesh
CONSTRUCTIONS = ("extrude", "revolve", "hull", "minkowski", "mesh", "surfels")
TOP_KEYS = ("clcsg", "bound", "defs", "root", "comment", "$schema")
TRANSFORM_STEPS = ("translate", "rotate", "scale", "matrix")
FORMAT_VERSION = 1

_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")


def key(path: str, name) -> str:
    """``path`` extended by object key ``name`` (``$.a.b`` or ``$.a["my key"]``)."""
    name = str(name)
    return f"{path}.{name}" if _IDENT.match(name) else f"{path}[{json.dumps(name)}]"


def join(path: str, parts) -> str:
    for p in parts:
        path = f"{path}[{p}]" if isinstance(p, int) else key(path, p)
    return path


def jtype(v) -> str:
    """The JSON type of a value as messages name it (``array of 3``, ``number``, ...)."""
    if v is None:
        return "null"
    if isinstance(v, (bool, np.bool_)):
        return "boolean"
    if isinstance(v, numbers.Real):
        return "number"
    if isinstance(v, str):
        return "string"
    if isinstance(v, (list, tuple)):
        return f"array of {len(v)}"
    if isinstance(v, dict):
        return "object"
    return getattr(v, "token", None) or type(v).__name__


def suggest(word, choices) -> str:
    import difflib  # only for the error message

    close = difflib.get_close_matches(str(word), list(choices), n=1, cutoff=0.7)
    return f" (did you mean {close[0]!r}?)" if close else ""


def known_kinds() -> str:
    return (f"known primitives: {', '.join(sorted(solids.KINDS))}; "
            f"constructions: {', '.join(CONSTRUCTIONS)}; operations: {', '.join([*OPERATIONS, *UNARY])}; or \"ref\"")


def node_kinds(obj) -> list:
    return [k for k in obj if k in solids.KINDS or k in CONSTRUCTIONS or k in OPERATIONS or k in UNARY or k == "ref"]


def _num(v) -> str:
    return str(v)


def load_schema() -> dict:
    """The shipped scene schema (draft 2020-12)."""
    text = resources.files("clcsg").joinpath("readers", "schema", "scene.schema.json").read_text(encoding="utf-8")
    return json.loads(text)


def _shallow(schema: dict) -> dict:
    """The schema with every reference to ``#/$defs/node`` below a node made ``true`` and every
    other ``$ref`` replaced by the referenced object itself (the same object wherever it is
    used, so errors can be named by identity; no reference lookups while validating)."""
    defs = schema["$defs"]
    done: dict = {}

    def inline(node):
        if isinstance(node, list):
            return [inline(v) for v in node]
        if not isinstance(node, dict):
            return node
        ref = node.get("$ref")
        if ref == "#/$defs/node":
            return True
        if ref is not None and len(node) == 1:
            return definition(ref.rsplit("/", 1)[1])
        out = {k: inline(v) for k, v in node.items() if k != "$ref"}
        if ref is not None:  # "$ref" next to other keywords
            out["allOf"] = [definition(ref.rsplit("/", 1)[1])]
        return out

    def definition(name):
        if name not in done:
            done[name] = {}
            done[name].update(inline(defs[name]))
        return done[name]

    top = {k: inline(v) for k, v in schema.items() if k != "$defs"}
    node = {k: inline(v) for k, v in defs["node"].items()}
    for name in defs:
        definition(name)
    return {"top": top, "node": node, "defs": done}


class SceneSchema:
    """The document and node validators of the shallow schema, and the name of every named
    sub-schema (``$defs`` entry or top-level property) by identity, for :func:`explain`."""

    def __init__(self):
        import jsonschema

        def is_array(checker, v):
            return isinstance(v, (list, tuple))

        def is_number(checker, v):
            return isinstance(v, numbers.Real) and not isinstance(v, (bool, np.bool_))

        def is_integer(checker, v):
            return is_number(checker, v) and float(v).is_integer()

        base = jsonschema.Draft202012Validator
        checker = base.TYPE_CHECKER.redefine_many({"array": is_array, "number": is_number, "integer": is_integer})
        validator = jsonschema.validators.extend(base, type_checker=checker)
        shallow = _shallow(load_schema())
        self.document = validator(shallow["top"])
        self.node = validator(shallow["node"])
        self.names = {id(s): name for name, s in shallow["defs"].items()}
        self.names.update({id(s): "top:" + k for k, s in shallow["top"]["properties"].items() if isinstance(s, dict)
                           and id(s) not in self.names})
        self.names[id(shallow["top"])] = "top"
        self.names[id(shallow["node"])] = "node"

    def first_error(self, validator, instance):
        """(path parts, reason) of the first error of ``instance``, or None."""
        err = next(iter(validator.iter_errors(instance)), None)
        return None if err is None else explain(err, instance, self.names)

    def document_errors(self, data):
        return self.first_error(self.document, data)

    def node_errors(self, node):
        return self.first_error(self.node, node)


_SCHEMA = None


def scene_schema() -> SceneSchema:
    """The validators, built once."""
    global _SCHEMA
    if _SCHEMA is None:
        _SCHEMA = SceneSchema()
    return _SCHEMA


def _at(instance, parts):
    for p in parts:
        instance = instance[p]
    return instance


def _union_choice(err):
    """The error to report for a failed ``oneOf``: the first error of the only alternative the
    value's type fits, unless that fails on the array's length (then None: the union's title
    is the better message), or None when no or several alternatives fit."""
    branches: dict = {}
    for c in err.context:
        branches.setdefault(c.relative_schema_path[0], []).append(c)
    fits = [errs for _, errs in sorted(branches.items())
            if not any(c.validator == "type" and not c.relative_path for c in errs)]
    if len(fits) != 1:
        return None
    errs = fits[0]
    if any(c.validator in ("minItems", "maxItems") and not c.relative_path for c in errs):
        return None
    return errs[0]


def explain(err, instance, names) -> tuple[list, str]:
    """(path parts relative to ``instance``, reason) of a ``jsonschema`` error."""
    kw, value, schema = err.validator, err.instance, err.schema
    name = names.get(id(schema), "")
    path = list(err.absolute_path)
    title = schema.get("title") or f"a {schema.get('type', 'value')}"
    if kw in ("oneOf", "anyOf"):
        sub = _union_choice(err)
        if sub is not None:
            return explain(sub, instance, names)
        return path, f"expected {title}, got {jtype(value)}"
    if kw == "type":
        if name == "top":
            return path, f"a scene file holds a JSON object, got {jtype(value)}"
        if name == "top:clcsg":
            return path, f"the format version must be the integer {FORMAT_VERSION}, got {jtype(value)}"
        if name == "comment":
            return path, f"a comment must be a string, got {jtype(value)}"
        if name == "step":
            return path, _step_shape(value)
        return path, f"expected {title}, got {jtype(value)}"
    if kw in ("minProperties", "maxProperties") and name == "step":
        return path, _step_shape(value)
    if kw in ("minItems", "maxItems"):
        if name == "operands" and kw == "minItems" and path:
            return path, f"{path[-1]} needs at least one operand"
        return path, f"expected {title}, got {jtype(value)}"
    if kw == "exclusiveMinimum":
        return path, f"must be positive, got {_num(value)}" if err.validator_value == 0 else \
            f"must be greater than {err.validator_value}, got {_num(value)}"
    if kw in ("minimum", "maximum"):
        if name == "color_component":
            return path, f"color components must be in [0, 1], got {_num(value)}"
        if kw == "minimum" and err.validator_value == 0:
            return path, f"must be non-negative, got {_num(value)}"
        return path, f"must be {'at least' if kw == 'minimum' else 'at most'} {err.validator_value}, got {_num(value)}"
    if kw == "const" and name == "top:clcsg":
        return path, f"unsupported format version {_num(value)} (this clcsg reads version {FORMAT_VERSION})"
    if kw == "required":
        return path, _missing(name, value, err.validator_value)
    if kw == "additionalProperties":
        return _extra_key(name, value, path, schema)
    if kw == "enum" and name == "node_key":
        return _unknown_node_key(_at(instance, path), value, path)
    if kw == "enum" and name == "step_key":
        return path + [value], (f"unknown transform step {value!r}{suggest(value, TRANSFORM_STEPS)}; "
                                f"steps are {', '.join(TRANSFORM_STEPS)}")
    if kw == "minLength" and name == "def_name":
        return path + [value], "a definition name must not be empty"
    if kw == "not" and name == "direction":
        return path, "a direction must not be the zero vector"
    if kw == "not" and name == "node":
        return path, f"node has no kind; {known_kinds()}"
    if kw == "pattern":
        return path, f"expected {title}, got {value!r}"
    return path, " ".join(str(err.message).split())


def _step_shape(value) -> str:
    what = f"an object with {len(value)} keys" if isinstance(value, dict) else jtype(value)
    return f"a transform step is an object with one key ({', '.join(TRANSFORM_STEPS)}), got {what}"


def _missing(name, obj, required) -> str:
    missing = next(k for k in required if k not in obj)
    if name == "top":
        what = f"the format version, {FORMAT_VERSION}" if missing == "clcsg" else "the top node of the scene"
        return f'missing key "{missing}" ({what})'
    if name.startswith("params_"):
        return f"missing {name[len('params_'):]} parameter {missing!r}"
    if name == "rotation":
        return f"rotate needs {missing!r}"
    return f"missing key {missing!r}"


def _extra_key(name, obj, path, schema):
    allowed = list(schema.get("properties", {}))
    extra = next(k for k in obj if k not in allowed)
    if name == "top":
        return path + [extra], (f"unknown key {extra!r}{suggest(extra, TOP_KEYS)}; a scene has "
                                f"{', '.join(TOP_KEYS[:4])}")
    if name.startswith("params_"):
        kind = name[len("params_"):]
        return path + [extra], (f"unknown {kind} parameter {extra!r}{suggest(extra, allowed)}; "
                                f"{kind} takes {', '.join(allowed)}")
    if name == "rotation":
        return path + [extra], (f"unknown rotate key {extra!r}{suggest(extra, allowed)}; "
                                "rotate takes axis and degrees")
    kinds = node_kinds(obj)
    if len(kinds) > 1:
        return path, (f"a node has exactly one kind, this one has {kinds[0]!r} and {kinds[1]!r}"
                      " (combine them with an operation such as \"union\")")
    if extra == "color" and kinds:
        return path + [extra], f"color is only allowed on primitives, not on a {kinds[0]} node"
    return path + [extra], f"unknown key {extra!r}{suggest(extra, allowed)}"


def _unknown_node_key(obj, extra, path):
    kinds = node_kinds(obj)
    if not kinds:
        choices = [*solids.KINDS, *OPERATIONS, *UNARY, "ref"]
        return path + [extra], f"unknown node kind {extra!r}{suggest(extra, choices)}; {known_kinds()}"
    kind = kinds[0]
    allowed = ("color", "transform", "comment") if kind in solids.KINDS else ("transform", "comment")
    return path + [extra], (f"unknown key {extra!r}{suggest(extra, allowed)} in a {kind} node; allowed next to "
                            f"{kind!r}: {', '.join(allowed)}")
