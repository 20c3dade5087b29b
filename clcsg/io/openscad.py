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

Grammar (a hand-written tokenizer and recursive-descent parser, no dependencies; the rules
for statements and nodes run on an explicit stack, see ``_trampoline``)::

    file       := statement* EOF
    statement  := ';'  |  '{' statement* '}'  |  modifier* NAME '(' arguments ')' child
    child      := ';'  |  '{' statement* '}'  |  statement        (one child without braces)
    modifier   := '*' | '%' | '!' | '#'
    arguments  := [ argument (',' argument)* [','] ]
    argument   := NAME '=' value  |  value
    value      := ['-' | '+'] NUMBER | STRING | 'true' | 'false' | 'undef' | 'inf' | 'nan'
                | '[' [ value (',' value)* [','] ] ']'  |  '[' value ':' value [':' value] ']'
    NUMBER     := digits ['.' digits] | '.' digits, with an optional exponent (1e-05, -3.5E+2)
    comments   := '// ...' to the end of the line, '/* ... */'

Semantics follow OpenSCAD's own evaluator (2021.01 and later), including its quirks:

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
* ``color`` takes ``[r, g, b]``, ``[r, g, b, a]``, a CSS/SVG color name (:data:`WEB_COLORS`)
  or ``"#rgb"``, ``"#rgba"``, ``"#rrggbb"``, ``"#rrggbbaa"``, optionally with an ``alpha``.
  As in OpenSCAD the *outermost* color wins: ``color("red") color("blue") cube(1);`` is red
  (openscad/openscad#4057, #5446).  Colors OpenSCAD could not parse are exported as
  ``color([-1, -1, -1, a])``, which sets no color.
* Arguments that OpenSCAD ignores with a warning (a ``size`` that is not a number or a
  3-vector, a non-boolean ``center``, unknown names) are ignored here too, with a warning;
  ``undef`` means "not given".

The parser raises nothing but :class:`SceneError` for any input text: syntax errors read
``<file>:<line>:<col>: syntax error: expected ...``.

Deep nesting: the parser and the evaluator keep pending nodes on explicit stacks instead of
recursing, so any nesting depth loads (1,000 nested ``difference()`` are an ordinary model;
:data:`MAX_NODE_DEPTH`, 100,000 levels, only bounds memory for absurd input).  Values are
parsed recursively; vectors nested deeper than :data:`MAX_DEPTH` (100) levels are refused
(CSG export nests them 2 deep).  Code that walks the resulting :class:`Shape` graph must not
recurse per level either.

``.scad`` programs are exported by the ``openscad`` binary first: :mod:`clcsg.io.scad`.
"""

from __future__ import annotations

import bisect
import math
import os
import re
import warnings
from dataclasses import dataclass
from types import GeneratorType

import numpy as np

from ..model.csg import Difference, Intersection, Shape, Transformed, Union
from ..errors import SceneError
from ..model.scene import Scene

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


class OpenScadWarning(UserWarning):
    """Something OpenSCAD also warns about and skips (an empty primitive, a bad argument)."""


# CSS Color Module Level 4 named colors, as OpenSCAD's ColorNode.cc lists them (0-255), plus
# OpenSCAD's own "transparent".  Names are matched case-insensitively.
WEB_COLORS: dict[str, tuple[int, int, int] | tuple[int, int, int, int]] = {
    "aliceblue": (240, 248, 255),
    "antiquewhite": (250, 235, 215),
    "aqua": (0, 255, 255),
    "aquamarine": (127, 255, 212),
    "azure": (240, 255, 255),
    "beige": (245, 245, 220),
    "bisque": (255, 228, 196),
    "black": (0, 0, 0),
    "blanchedalmond": (255, 235, 205),
    "blue": (0, 0, 255),
    "blueviolet": (138, 43, 226),
    "brown": (165, 42, 42),
    "burlywood": (222, 184, 135),
    "cadetblue": (95, 158, 160),
    "chartreuse": (127, 255, 0),
    "chocolate": (210, 105, 30),
    "coral": (255, 127, 80),
    "cornflowerblue": (100, 149, 237),
    "cornsilk": (255, 248, 220),
    "crimson": (220, 20, 60),
    "cyan": (0, 255, 255),
    "darkblue": (0, 0, 139),
    "darkcyan": (0, 139, 139),
    "darkgoldenrod": (184, 134, 11),
    "darkgray": (169, 169, 169),
    "darkgreen": (0, 100, 0),
    "darkgrey": (169, 169, 169),
    "darkkhaki": (189, 183, 107),
    "darkmagenta": (139, 0, 139),
    "darkolivegreen": (85, 107, 47),
    "darkorange": (255, 140, 0),
    "darkorchid": (153, 50, 204),
    "darkred": (139, 0, 0),
    "darksalmon": (233, 150, 122),
    "darkseagreen": (143, 188, 143),
    "darkslateblue": (72, 61, 139),
    "darkslategray": (47, 79, 79),
    "darkslategrey": (47, 79, 79),
    "darkturquoise": (0, 206, 209),
    "darkviolet": (148, 0, 211),
    "deeppink": (255, 20, 147),
    "deepskyblue": (0, 191, 255),
    "dimgray": (105, 105, 105),
    "dimgrey": (105, 105, 105),
    "dodgerblue": (30, 144, 255),
    "firebrick": (178, 34, 34),
    "floralwhite": (255, 250, 240),
    "forestgreen": (34, 139, 34),
    "fuchsia": (255, 0, 255),
    "gainsboro": (220, 220, 220),
    "ghostwhite": (248, 248, 255),
    "gold": (255, 215, 0),
    "goldenrod": (218, 165, 32),
    "gray": (128, 128, 128),
    "green": (0, 128, 0),
    "greenyellow": (173, 255, 47),
    "grey": (128, 128, 128),
    "honeydew": (240, 255, 240),
    "hotpink": (255, 105, 180),
    "indianred": (205, 92, 92),
    "indigo": (75, 0, 130),
    "ivory": (255, 255, 240),
    "khaki": (240, 230, 140),
    "lavender": (230, 230, 250),
    "lavenderblush": (255, 240, 245),
    "lawngreen": (124, 252, 0),
    "lemonchiffon": (255, 250, 205),
    "lightblue": (173, 216, 230),
    "lightcoral": (240, 128, 128),
    "lightcyan": (224, 255, 255),
    "lightgoldenrodyellow": (250, 250, 210),
    "lightgray": (211, 211, 211),
    "lightgreen": (144, 238, 144),
    "lightgrey": (211, 211, 211),
    "lightpink": (255, 182, 193),
    "lightsalmon": (255, 160, 122),
    "lightseagreen": (32, 178, 170),
    "lightskyblue": (135, 206, 250),
    "lightslategray": (119, 136, 153),
    "lightslategrey": (119, 136, 153),
    "lightsteelblue": (176, 196, 222),
    "lightyellow": (255, 255, 224),
    "lime": (0, 255, 0),
    "limegreen": (50, 205, 50),
    "linen": (250, 240, 230),
    "magenta": (255, 0, 255),
    "maroon": (128, 0, 0),
    "mediumaquamarine": (102, 205, 170),
    "mediumblue": (0, 0, 205),
    "mediumorchid": (186, 85, 211),
    "mediumpurple": (147, 112, 219),
    "mediumseagreen": (60, 179, 113),
    "mediumslateblue": (123, 104, 238),
    "mediumspringgreen": (0, 250, 154),
    "mediumturquoise": (72, 209, 204),
    "mediumvioletred": (199, 21, 133),
    "midnightblue": (25, 25, 112),
    "mintcream": (245, 255, 250),
    "mistyrose": (255, 228, 225),
    "moccasin": (255, 228, 181),
    "navajowhite": (255, 222, 173),
    "navy": (0, 0, 128),
    "oldlace": (253, 245, 230),
    "olive": (128, 128, 0),
    "olivedrab": (107, 142, 35),
    "orange": (255, 165, 0),
    "orangered": (255, 69, 0),
    "orchid": (218, 112, 214),
    "palegoldenrod": (238, 232, 170),
    "palegreen": (152, 251, 152),
    "paleturquoise": (175, 238, 238),
    "palevioletred": (219, 112, 147),
    "papayawhip": (255, 239, 213),
    "peachpuff": (255, 218, 185),
    "peru": (205, 133, 63),
    "pink": (255, 192, 203),
    "plum": (221, 160, 221),
    "powderblue": (176, 224, 230),
    "purple": (128, 0, 128),
    "rebeccapurple": (102, 51, 153),
    "red": (255, 0, 0),
    "rosybrown": (188, 143, 143),
    "royalblue": (65, 105, 225),
    "saddlebrown": (139, 69, 19),
    "salmon": (250, 128, 114),
    "sandybrown": (244, 164, 96),
    "seagreen": (46, 139, 87),
    "seashell": (255, 245, 238),
    "sienna": (160, 82, 45),
    "silver": (192, 192, 192),
    "skyblue": (135, 206, 235),
    "slateblue": (106, 90, 205),
    "slategray": (112, 128, 144),
    "slategrey": (112, 128, 144),
    "snow": (255, 250, 250),
    "springgreen": (0, 255, 127),
    "steelblue": (70, 130, 180),
    "tan": (210, 180, 140),
    "teal": (0, 128, 128),
    "thistle": (216, 191, 216),
    "tomato": (255, 99, 71),
    "turquoise": (64, 224, 208),
    "violet": (238, 130, 238),
    "wheat": (245, 222, 179),
    "white": (255, 255, 255),
    "whitesmoke": (245, 245, 245),
    "yellow": (255, 255, 0),
    "yellowgreen": (154, 205, 50),
    # OpenSCAD's own addition
    "transparent": (0, 0, 0, 0),
}

_PRIMITIVES = frozenset(("cube", "sphere", "cylinder"))

#: Nodes this reader understands.
SUPPORTED_NODES = (
    "group", "union", "difference", "intersection", "render", "multmatrix", "color",
    "cube", "sphere", "cylinder",
)

_UNSUPPORTED_HINT = "clcsg samples quadric primitives only (cube, sphere, cylinder)"

# Module names that exist only in the .scad language: OpenSCAD's export turns them into
# multmatrix/group, so meeting one means the file is a .scad source, not a CSG export.
_SOURCE_MODULES = frozenset(
    "translate rotate scale mirror children echo assert intersection_for parent_module".split()
)
# Keywords of the .scad language that cannot even be parsed as a node.
_SOURCE_KEYWORDS = frozenset("module function if else for let each include use".split())
_SOURCE_HINT = (
    "this is OpenSCAD source, not CSG export; export the model with "
    "\"openscad -o model.csg model.scad\" first"
)


# -- values -----------------------------------------------------------------------------------
class _Undef:
    __slots__ = ()

    def __repr__(self):
        return "undef"


UNDEF = _Undef()


@dataclass(frozen=True)
class _Range:
    start: object
    step: object
    end: object

    def __repr__(self):
        return f"[{_fmt(self.start)}:{_fmt(self.step)}:{_fmt(self.end)}]"


def _is_num(v) -> bool:
    return isinstance(v, float)  # numbers are always parsed to float; bools stay bool


def _fmt(v, limit: int = 60) -> str:
    """A value as OpenSCAD would print it, one line, shortened to ``limit`` characters."""
    if v is True:
        s = "true"
    elif v is False:
        s = "false"
    elif isinstance(v, float):
        s = f"{v:g}"
    elif isinstance(v, str):
        s = '"' + v.encode("unicode_escape").decode("ascii").replace('"', '\\"') + '"'
    elif isinstance(v, list):
        parts = []
        n = 2
        for x in v:
            p = _fmt(x, limit)
            parts.append(p)
            n += len(p) + 2
            if n > limit:
                break
        s = "[" + ", ".join(parts) + "]"
    else:
        s = repr(v)
    if len(s) > limit:
        s = s[: limit - 3] + "..."
    return s


# -- tokens -----------------------------------------------------------------------------------
_TOKEN_RE = re.compile(
    r"""
    (?P<ws>[ \t\r\n\f\v]+)
  | (?P<lcomment>//[^\n]*)
  | (?P<bcomment>/\*.*?\*/)
  | (?P<num>(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?)
  | (?P<id>\$?[A-Za-z_][A-Za-z0-9_]*)
  | (?P<str>"(?:[^"\\]|\\.)*")
  | (?P<punct>[()\[\]{},;=:!#%*+\-])
    """,
    re.VERBOSE | re.DOTALL | re.ASCII,
)

_ESCAPES = {"n": "\n", "t": "\t", "r": "\r", '"': '"', "\\": "\\"}
_ESCAPE_RE = re.compile(r"\\(x[0-9A-Fa-f]{2}|u[0-9A-Fa-f]{4}|U[0-9A-Fa-f]{6}|.)", re.DOTALL)


def _unescape(body: str) -> str:
    def sub(m):
        e = m.group(1)
        if e in _ESCAPES:
            return _ESCAPES[e]
        if len(e) > 1:
            code = int(e[1:], 16)
            return chr(code) if code < 0x110000 else "\ufffd"
        return "\\" + e  # OpenSCAD keeps unknown escapes (with a warning)

    return _ESCAPE_RE.sub(sub, body)


@dataclass(frozen=True)
class _Token:
    kind: str  # num, str, id, punct, eof
    text: str
    value: object
    pos: int


def _show(tok: _Token) -> str:
    if tok.kind == "eof":
        return "end of file"
    t = tok.text
    if len(t) > 24:
        t = t[:21] + "..."
    return repr(t)


class _Source:
    """The text plus offset -> (line, column) and message formatting."""

    def __init__(self, text: str, name: str):
        self.text = text
        self.name = name
        self._line_starts = [0] + [m.end() for m in re.finditer("\n", text)]

    def where(self, pos: int) -> str:
        i = bisect.bisect_right(self._line_starts, pos) - 1
        return f"{self.name}:{i + 1}:{pos - self._line_starts[i] + 1}"

    def error(self, pos: int, message: str) -> SceneError:
        return SceneError(_one_line(f"{self.where(pos)}: {message}"))

    def warn(self, pos: int, message: str) -> None:
        where = self.where(pos)
        line = int(where.rsplit(":", 2)[1])
        # reported at the .csg file's line, not at this module's
        warnings.warn_explicit(_one_line(f"{where}: {message}"), OpenScadWarning, self.name, line)


def _one_line(s: str) -> str:
    return " ".join(s.splitlines())


def _tokenize(src: _Source) -> list[_Token]:
    text = src.text
    out: list[_Token] = []
    pos = 0
    n = len(text)
    match = _TOKEN_RE.match
    while pos < n:
        m = match(text, pos)
        if m is None:
            c = text[pos]
            if text.startswith("/*", pos):
                raise src.error(pos, "syntax error: unterminated comment (missing '*/')")
            if c == '"':
                raise src.error(pos, "syntax error: unterminated string (missing '\"')")
            if c == "<" and text[:pos].rstrip().endswith(("include", "use")):
                raise src.error(pos, f"syntax error: unexpected character '<': {_SOURCE_HINT}")
            raise src.error(pos, f"syntax error: unexpected character {c!r}")
        kind = m.lastgroup
        t = m.group()
        if kind == "num":
            out.append(_Token("num", t, float(t), pos))
        elif kind == "id":
            out.append(_Token("id", t, t, pos))
        elif kind == "str":
            out.append(_Token("str", t, _unescape(t[1:-1]), pos))
        elif kind == "punct":
            out.append(_Token("punct", t, t, pos))
        pos = m.end()
    out.append(_Token("eof", "", None, n))
    return out


def _run(gen):
    """Drive a generator that yields sub-generators (calls) and returns a result.

    A call ``x = yield sub`` runs ``sub`` to completion and sends its return value back as
    ``x``; the pending generators live on a list, so arbitrarily deep call chains need no
    Python (or C) stack.  A generator may also yield a non-generator request, which is
    handed to ``handle(request)``; that returns a value to send back or a generator to run.
    """
    return _trampoline(gen, None)


def _trampoline(gen, handle):
    stack = [gen]
    value = None
    while True:
        try:
            req = stack[-1].send(value)
        except StopIteration as stop:
            stack.pop()
            if not stack:
                return stop.value
            value = stop.value
            continue
        if type(req) is not GeneratorType:
            req = handle(req)
            if type(req) is not GeneratorType:
                value = req
                continue
        stack.append(req)
        value = None


# -- syntax tree ------------------------------------------------------------------------------
@dataclass
class _Arg:
    name: str | None
    value: object
    pos: int


@dataclass
class _Node:
    name: str
    args: list[_Arg]
    children: list["_Node"]
    modifiers: str  # subset of "*%!#" in source order
    pos: int  # of the name
    has_children_block: bool = False  # children were given (block or single statement)

    @property
    def disabled(self) -> bool:
        return "*" in self.modifiers

    @property
    def background(self) -> bool:
        return "%" in self.modifiers

    @property
    def root(self) -> bool:
        return "!" in self.modifiers


class _Parser:
    def __init__(self, src: _Source):
        self.src = src
        self.toks = _tokenize(src)
        self.i = 0
        self.depth = 0  # nested nodes
        self.vdepth = 0  # nested vectors and signs

    # token helpers
    @property
    def tok(self) -> _Token:
        return self.toks[self.i]

    def peek(self, k: int = 1) -> _Token:
        return self.toks[min(self.i + k, len(self.toks) - 1)]

    def is_punct(self, p: str, tok: _Token | None = None) -> bool:
        t = self.tok if tok is None else tok
        return t.kind == "punct" and t.text == p

    def advance(self) -> _Token:
        t = self.toks[self.i]
        if t.kind != "eof":
            self.i += 1
        return t

    def fail(self, what: str, tok: _Token | None = None):
        t = self.tok if tok is None else tok
        raise self.src.error(t.pos, f"syntax error: expected {what}, got {_show(t)}")

    def expect(self, p: str, what: str | None = None) -> _Token:
        if not self.is_punct(p):
            self.fail(what or repr(p))
        return self.advance()

    def enter(self, tok: _Token, what: str = "depth"):
        d = getattr(self, what) + 1
        setattr(self, what, d)
        limit = MAX_NODE_DEPTH if what == "depth" else MAX_DEPTH
        if d > limit:
            kind = "nodes" if what == "depth" else "values"
            raise self.src.error(tok.pos, f"{kind} nested deeper than {limit} levels are not supported")

    def leave(self, what: str = "depth"):
        setattr(self, what, getattr(self, what) - 1)

    # grammar
    #
    # statements(), statement() and instantiation() are the recursive-descent rules written as
    # generators: where a rule needs a sub-rule it yields the sub-rule's generator and _run()
    # sends back its result.  _run() keeps the pending rules on an explicit stack, so the
    # nesting depth of the input is bounded by MAX_NODE_DEPTH, not by Python's recursion limit
    # (``yield from`` would recurse in C once per level).
    def parse_file(self) -> list[_Node]:
        nodes = _run(self.statements(end=None))
        if self.tok.kind != "eof":  # pragma: no cover - statements() stops only at eof here
            self.fail("a statement")
        return nodes

    def statements(self, end: str | None):
        out: list[_Node] = []
        while True:
            t = self.tok
            if t.kind == "eof":
                if end is not None:
                    self.fail(repr(end))
                return out
            if end is not None and self.is_punct(end):
                return out
            if self.is_punct(";"):  # statement() inlined for the commonest cases
                self.advance()
            elif t.kind == "id":
                out.append((yield self.instantiation()))
            else:
                out.extend((yield self.statement()))

    def statement(self):
        t = self.tok
        if self.is_punct(";"):
            self.advance()
            return []
        if self.is_punct("{"):
            self.enter(t)
            self.advance()
            body = yield self.statements("}")
            self.expect("}")
            self.leave()
            return body
        return [(yield self.instantiation())]

    def instantiation(self):
        mods = ""
        while self.tok.kind == "punct" and self.tok.text in "*%!#":
            mods += self.advance().text
        t = self.tok
        if t.kind != "id":
            if mods:
                self.fail("a node name after the modifier")
            self.fail("a node such as cube(...), group() or ';'")
        name = t.text
        if name in _SOURCE_KEYWORDS or (self.is_punct("=", self.peek()) and not mods):
            raise self.src.error(t.pos, f"syntax error: unexpected {name!r}: {_SOURCE_HINT}")
        if name in ("true", "false", "undef"):
            self.fail("a node such as cube(...), group() or ';'")
        self.advance()
        self.expect("(", f"'(' after {name}")
        args = self.arguments()
        self.expect(")", f"',' or ')' in the arguments of {name}()")
        node = _Node(name, args, [], mods, t.pos)
        c = self.tok
        if self.is_punct(";"):
            self.advance()
        elif self.is_punct("{"):
            self.enter(c)
            self.advance()
            node.children = yield self.statements("}")
            self.expect("}")
            self.leave()
            node.has_children_block = True
        elif c.kind == "id" or (c.kind == "punct" and c.text in "*%!#"):
            self.enter(c)
            node.children = [(yield self.instantiation())]
            self.leave()
            node.has_children_block = True
        else:
            self.fail(f"';' or '{{' after {name}(...)")
        return node

    def arguments(self) -> list[_Arg]:
        args: list[_Arg] = []
        while not self.is_punct(")"):
            t = self.tok
            if t.kind == "id" and self.is_punct("=", self.peek()):
                self.advance()
                self.advance()
                args.append(_Arg(t.text, self.value(), t.pos))
            else:
                args.append(_Arg(None, self.value(), t.pos))
            if self.is_punct(","):
                self.advance()
            elif not self.is_punct(")"):
                self.fail("',' or ')'")
        return args

    def value(self):
        t = self.tok
        if self.is_punct("-") or self.is_punct("+"):
            self.enter(t, "vdepth")
            self.advance()
            v = self.value()
            self.leave("vdepth")
            if not _is_num(v):
                raise self.src.error(t.pos, f"syntax error: {t.text!r} must be followed by a number")
            return -v if t.text == "-" else v
        if t.kind in ("num", "str"):
            self.advance()
            return t.value
        if t.kind == "id":
            word = t.text
            if word in ("true", "false"):
                self.advance()
                return word == "true"
            if word == "undef":
                self.advance()
                return UNDEF
            if word == "inf":
                self.advance()
                return math.inf
            if word == "nan":
                self.advance()
                return math.nan
            raise self.src.error(
                t.pos,
                f"syntax error: expected a value (number, string, vector, true, false or undef), "
                f"got {_show(t)}: variables and expressions do not occur in CSG export",
            )
        if self.is_punct("["):
            self.enter(t, "vdepth")
            self.advance()
            if self.is_punct("]"):
                self.advance()
                self.leave("vdepth")
                return []
            first = self.value()
            if self.is_punct(":"):
                self.advance()
                second = self.value()
                if self.is_punct(":"):
                    self.advance()
                    third = self.value()
                    r = _Range(first, second, third)
                else:
                    r = _Range(first, 1.0, second)
                self.expect("]", "']' closing the range")
                self.leave("vdepth")
                return r
            items = [first]
            while True:
                if self.is_punct(","):
                    self.advance()
                    if self.is_punct("]"):
                        break
                    items.append(self.value())
                elif self.is_punct("]"):
                    break
                else:
                    self.fail("',' or ']' in the vector")
            self.advance()
            self.leave("vdepth")
            return items
        self.fail("a value (number, string, vector, true, false or undef)")


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
}


@dataclass
class _Evaluator:
    src: _Source

    def warn(self, pos: int, message: str):
        self.src.warn(pos, message)

    # arguments
    def bind(self, node: _Node) -> dict:
        """Arguments by parameter name, as OpenSCAD's Parameters::parse assigns them."""
        positional, named = _PARAMS[node.name]
        known = set(positional) | set(named)
        out: dict = {}
        k = 0
        for a in node.args:
            if a.name is None:
                if k >= len(positional):
                    self.warn(a.pos, f"{node.name}(): too many unnamed arguments: {_fmt(a.value)} ignored")
                    continue
                name = positional[k]
                k += 1
            else:
                name = a.name
                if name.startswith("$"):
                    # $fn, $fa, $fs: tessellation settings, irrelevant for exact surfaces; but a
                    # small $fn is how OpenSCAD users ask for prisms (hex nuts) on purpose
                    fn = a.value
                    if name == "$fn" and node.name in ("sphere", "cylinder") and _is_num(fn) and 0.0 < fn <= 8.0:
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
    def shape(self, nodes: list[_Node]) -> Shape | None:
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
            return self.node(root, _Ctx())
        return self.union_of(nodes, _Ctx())

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

    # The tree is evaluated without recursion: the n_* methods of nodes with children are
    # generators that yield ``(child, ctx)`` requests, or the generator of children(), and get
    # the child's shape sent back; node() drives them with an explicit stack (_trampoline).
    def children(self, node: _Node, ctx: _Ctx):
        """The children that take part (not disabled, not background), evaluated."""
        out = []
        for c in node.children:
            if not (c.disabled or c.background):
                out.append((yield (c, ctx)))
        return out

    def union_of(self, nodes: list[_Node], ctx: _Ctx) -> Shape | None:
        shapes = [self.node(c, ctx) for c in nodes if not (c.disabled or c.background)]
        return _union(shapes)

    def node(self, node: _Node, ctx: _Ctx) -> Shape | None:
        r = self._start((node, ctx))
        return _trampoline(r, self._start) if type(r) is GeneratorType else r

    def _start(self, request):
        """Evaluate a primitive, or return the generator that evaluates a node with children."""
        node, ctx = request
        method = getattr(self, "n_" + node.name, None) if node.name in _PARAMS else None
        if method is None:
            if node.name in _SOURCE_MODULES:
                raise self.src.error(node.pos, f"{node.name}() is not supported: {_SOURCE_HINT}")
            raise self.src.error(node.pos, f"{node.name}() is not supported: {_UNSUPPORTED_HINT}")
        return method(node, ctx)

    # Booleans and groups
    def n_group(self, node, ctx):
        self.bind(node)
        return _union((yield self.children(node, ctx)))

    n_union = n_group
    n_render = n_group

    def n_difference(self, node, ctx):
        self.bind(node)
        kids = yield self.children(node, ctx)
        if not kids or kids[0] is None:
            return None
        rest = [k for k in kids[1:] if k is not None]
        return Difference([kids[0], *rest]) if rest else kids[0]

    def n_intersection(self, node, ctx):
        self.bind(node)
        kids = yield self.children(node, ctx)
        if not kids or any(k is None for k in kids):
            return None
        return Intersection(kids) if len(kids) > 1 else kids[0]

    # transform
    def n_multmatrix(self, node, ctx):
        p = self.bind(node)
        child = _union((yield self.children(node, ctx)))
        m = np.eye(4)
        raw = p.get("m")
        if isinstance(raw, list):
            for i, row in enumerate(raw[:4]):
                if isinstance(row, list):
                    for j, v in enumerate(row[:4]):
                        if _is_num(v):
                            m[i, j] = v
        elif raw is not None:
            self.warn(node.pos, f"multmatrix(): m = {_fmt(raw)} is not a matrix: the identity is used")
        with np.errstate(all="ignore"):
            if m[3, 3] != 1.0:
                m = m / m[3, 3]
        if child is None:
            return None
        if not np.all(np.isfinite(m)):
            self.warn(node.pos, "multmatrix(): the matrix contains NaN or infinity: its children are left out, as OpenSCAD does")
            return None
        if np.any(m[3, :3] != 0.0):
            self.warn(node.pos, f"multmatrix(): the projective last row {_fmt(m[3].tolist())} is ignored, as OpenSCAD does")
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
                rgba[i] = v if _is_num(v) else 0.0
        elif isinstance(c, str):
            name = c.lower()
            if name in WEB_COLORS:
                named = WEB_COLORS[name]
                rgba = [x / 255.0 for x in named] + ([1.0] if len(named) == 3 else [])
            else:
                hexc = _parse_hex_color(name)
                if hexc is None:
                    self.warn(node.pos, f"color(): unable to parse color {_fmt(c)}: no color is set, as in OpenSCAD")
                else:
                    rgba = hexc
        elif c is not None:
            self.warn(node.pos, f"color(): {_fmt(c)} is not a color: no color is set, as in OpenSCAD")
        alpha = p.get("alpha")
        if _is_num(alpha):
            rgba[3] = alpha
        elif alpha is not None:
            self.warn(node.pos, f"color(): alpha = {_fmt(alpha)} is not a number: ignored")
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
            self.warn(node.pos, f"color(): {_fmt(c)} has negative components: no color is set, as in OpenSCAD")
        # OpenSCAD: the outermost color wins (a color node only colors what has none yet)
        if color is not None and ctx.color is None:
            ctx = _Ctx(color)
        return _union((yield self.children(node, ctx)))

    # primitives
    def _no_children(self, node):
        if node.has_children_block and node.children:
            self.warn(node.pos, f"{node.name}() does not support child nodes: they are ignored, as in OpenSCAD")

    def _center(self, node, p) -> bool:
        c = p.get("center", False)
        if isinstance(c, bool):
            return c
        self.warn(node.pos, f"{node.name}(): center = {_fmt(c)} is not true or false: treated as false, as in OpenSCAD")
        return False

    def _make(self, node, factory, ctx, **params):
        from ..model import solids

        try:
            return getattr(solids, factory)(color=ctx.color, **params)
        except (SceneError, ValueError, ArithmeticError, TypeError) as e:
            raise self.src.error(node.pos, f"{node.name}(): {e}") from None

    def n_cube(self, node, ctx):
        self._no_children(node)
        p = self.bind(node)
        size = (1.0, 1.0, 1.0)
        s = p.get("size")
        if _is_num(s):
            size = (s, s, s)
        elif isinstance(s, list) and len(s) == 3 and all(_is_num(v) for v in s):
            size = tuple(s)
        elif s is not None:
            self.warn(node.pos, f"cube(): unable to convert size = {_fmt(s)} to a number or a vector of 3 numbers: size 1 is used, as in OpenSCAD")
        center = self._center(node, p)
        if not all(math.isfinite(v) and v > 0.0 for v in size):
            self.warn(node.pos, f"cube(size = {_fmt(list(size))}) is empty (a size is zero, negative or not finite): left out, as in OpenSCAD")
            return None
        c = (0.0, 0.0, 0.0) if center else tuple(v / 2.0 for v in size)
        return self._make(node, "box", ctx, size=size, center=c)

    def _radius(self, node, p, d_name, r_name):
        """OpenSCAD's lookup_radius: a diameter wins over a radius."""
        d, r = p.get(d_name), p.get(r_name)
        for name, v in ((d_name, d), (r_name, r)):
            if v is not None and not _is_num(v):
                self.warn(node.pos, f"{node.name}(): {name} = {_fmt(v)} is not a number: ignored")
        if _is_num(d):
            if _is_num(r):
                self.warn(node.pos, f"{node.name}(): ignoring radius {r_name!r} as diameter {d_name!r} is given too")
            return d / 2.0
        return r if _is_num(r) else None

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
        if h is not None and not _is_num(h):
            self.warn(node.pos, f"cylinder(): h = {_fmt(h)} is not a number: ignored")
        h = h if _is_num(h) else 1.0
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


def _union(shapes: list) -> Shape | None:
    kept = [s for s in shapes if s is not None]
    if not kept:
        return None
    return kept[0] if len(kept) == 1 else Union(kept)


def _parse_hex_color(s: str) -> list[float] | None:
    """OpenSCAD's parse_hex_color: "#rgb", "#rgba", "#rrggbb", "#rrggbbaa"."""
    if len(s) not in (4, 5, 7, 9) or s[0] != "#":
        return None
    digits = s[1:]
    if not all(ch in "0123456789abcdefABCDEF" for ch in digits):
        return None
    stride = 1 if len(s) in (4, 5) else 2
    top = 15.0 if stride == 1 else 255.0
    rgba = [1.0, 1.0, 1.0, 1.0]
    for i in range(len(digits) // stride):
        rgba[i] = int(digits[i * stride : (i + 1) * stride], 16) / top
    return rgba


# -- entry points -----------------------------------------------------------------------------
def parse_csg(text: str, source: str = "<string>") -> Scene:
    """Parse OpenSCAD CSG export ``text`` into a :class:`Scene`.

    Raises :class:`SceneError` (one line: ``<source>:<line>:<col>: ...``) and nothing else for
    any text; emits :class:`OpenScadWarning` for what OpenSCAD also skips with a warning.  An
    empty model is an empty union (a scene with no DNF terms).
    """
    if not isinstance(text, str):
        raise SceneError(f"{source}: expected the text of a .csg file, got {type(text).__name__}")
    if text.startswith("\ufeff"):
        text = text[1:]
    try:
        src = _Source(text, str(source))
        nodes = _Parser(src).parse_file()
        shape = _Evaluator(src).shape(nodes)
    except SceneError:
        raise
    except RecursionError:
        raise SceneError(f"{source}: the model is nested too deeply") from None
    except MemoryError:
        raise SceneError(f"{source}: the model is too large to load") from None
    if shape is None:
        src.warn(len(text), "the model is empty (nothing to render)")
        shape = Union([])
    return Scene(shape, None, str(source))


def load_csg(path) -> Scene:
    """Load an OpenSCAD ``.csg`` file (``openscad -o model.csg model.scad``)."""
    p = os.fspath(path)
    try:
        with open(p, "rb") as f:
            data = f.read()
    except FileNotFoundError:
        raise SceneError(f"{p}: no such file") from None
    except OSError as e:
        raise SceneError(f"{p}: cannot read: {e.strerror or e}") from None
    text = data.decode("utf-8", errors="replace")
    return parse_csg(text, source=p)
