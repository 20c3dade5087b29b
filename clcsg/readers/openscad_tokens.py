"""The tokenizer and parser of OpenSCAD's CSG export (the syntax half of :mod:`clcsg.readers.openscad`).

Grammar (a hand-written tokenizer and recursive-descent parser, no dependencies; the rules
for statements and nodes run on an explicit stack, :func:`clcsg.readers.trampoline.run`)::

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

:class:`Parser` turns the text into a list of :class:`Node` (name, arguments, children,
modifiers, position); syntax errors are :class:`~clcsg.errors.SceneError` reading
``<file>:<line>:<col>: syntax error: expected ...``.  Nodes nest up to ``max_node_depth``
levels (explicit stacks, no recursion); values (vectors, signs) are parsed recursively and
nest up to ``max_depth`` levels.
"""

from __future__ import annotations

import math
import re
from sys import intern
import warnings
from dataclasses import dataclass
from typing import NamedTuple

from ..errors import SceneError
from .trampoline import run


class OpenScadWarning(UserWarning):
    """Something OpenSCAD also warns about and skips (an empty primitive, a bad argument)."""


# Keywords of the .scad language that cannot even be parsed as a node.
SOURCE_KEYWORDS = frozenset("module function if else for let each include use".split())
SOURCE_HINT = (
    "this is OpenSCAD source, not CSG export; export the model with "
    "\"openscad -o model.csg model.scad\" first"
)

# -- values -----------------------------------------------------------------------------------
class Undef:
    __slots__ = ()

    def __repr__(self):
        return "undef"


UNDEF = Undef()


@dataclass(frozen=True)
class Range:
    start: object
    step: object
    end: object

    def __repr__(self):
        return f"[{fmt(self.start)}:{fmt(self.step)}:{fmt(self.end)}]"


def is_num(v) -> bool:
    return isinstance(v, float)  # numbers are always parsed to float; bools stay bool


def fmt(v, limit: int = 60) -> str:
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
            p = fmt(x, limit)
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
#: one token after any whitespace and comments (one match per token); no token group matched
#: means the end of the text or a character no token starts with
_TOKEN_RE = re.compile(
    r"""
    (?:[ \t\r\n\f\v]+ | //[^\n]* | /\*.*?\*/)*
    (?:
      (?P<num>(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?)
    | (?P<id>\$?[A-Za-z_][A-Za-z0-9_]*)
    | (?P<str>"(?:[^"\\]|\\.)*")
    | (?P<punct>[()\[\]{},;=:!#%*+\-])
    )?
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


class Token(NamedTuple):
    """A token (a tuple: made millions of times for a large file, so kept cheap)."""

    kind: str  # num, str, id, punct, eof
    text: str
    value: object
    pos: int


def show(tok: Token) -> str:
    if tok.kind == "eof":
        return "end of file"
    t = tok.text
    if len(t) > 24:
        t = t[:21] + "..."
    return repr(t)


class Source:
    """The text plus offset -> (line, column) and message formatting.  Lines are counted only
    when a message needs them (no index of line starts is kept: memory stays that of the text)."""

    def __init__(self, text: str, name: str):
        self.text = text
        self.name = name
        self._mark = (0, 1)  # (offset, its line): messages mostly come in text order

    def where(self, pos: int) -> str:
        at, line = self._mark if pos >= self._mark[0] else (0, 1)
        line += self.text.count("\n", at, pos)
        self._mark = (pos, line)
        start = self.text.rfind("\n", 0, pos) + 1
        return f"{self.name}:{line}:{pos - start + 1}"

    def error(self, pos: int, message: str) -> SceneError:
        return SceneError(one_line(f"{self.where(pos)}: {message}"))

    def warn(self, pos: int, message: str) -> None:
        where = self.where(pos)
        line = int(where.rsplit(":", 2)[1])
        # reported at the .csg file's line, not at this module's
        warnings.warn_explicit(one_line(f"{where}: {message}"), OpenScadWarning, self.name, line)


def one_line(s: str) -> str:
    return " ".join(s.splitlines())


def _bad_character(src: Source, pos: int) -> SceneError:
    text = src.text
    c = text[pos]
    if text.startswith("/*", pos):
        return src.error(pos, "syntax error: unterminated comment (missing '*/')")
    if c == '"':
        return src.error(pos, "syntax error: unterminated string (missing '\"')")
    if c == "<" and text[max(0, pos - 64):pos].rstrip().endswith(("include", "use")):
        return src.error(pos, f"syntax error: unexpected character '<': {SOURCE_HINT}")
    return src.error(pos, f"syntax error: unexpected character {c!r}")


#: distinct number texts whose float objects the tokenizer shares
_NUMBER_CACHE = 1 << 16


def tokenize(src: Source):
    """The tokens of ``src``, one at a time (a generator: no list of tokens is built), the
    last one of kind ``eof``."""
    text = src.text
    n = len(text)
    match = _TOKEN_RE.match
    numbers: dict[str, float] = {}  # one float object per distinct number text (0, 1, ... repeat a lot)
    pos = 0
    while True:
        m = match(text, pos)
        kind = m.lastgroup
        if kind is None:
            end = m.end()
            if end >= n:
                break
            raise _bad_character(src, end)
        start = m.start(kind)
        t = m.group(kind)
        if kind == "num":
            v = numbers.get(t)
            if v is None:
                if len(numbers) > _NUMBER_CACHE:
                    numbers.clear()
                v = numbers[t] = float(t)
            yield Token("num", t, v, start)
        elif kind == "str":
            yield Token("str", t, _unescape(t[1:-1]), start)
        else:  # names and punctuation repeat: one string object each
            t = intern(t)
            yield Token(kind, t, t, start)
        pos = m.end()
    yield Token("eof", "", None, n)



# -- syntax tree ------------------------------------------------------------------------------
@dataclass(slots=True)
class Arg:
    name: str | None
    value: object
    pos: int


@dataclass(slots=True)
class Node:
    name: str
    args: list[Arg]
    children: list["Node"]
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


class Parser:
    """``Parser(src, max_node_depth, max_depth).parse_file()``: the nodes of a CSG export."""

    def __init__(self, src: Source, max_node_depth: int, max_depth: int):
        self.src = src
        self._tokens = tokenize(src)
        self._ahead = [next(self._tokens)]  # the current token and at most one more
        self.depth = 0  # nested nodes
        self.vdepth = 0  # nested vectors and signs
        self.limits = {"depth": max_node_depth, "vdepth": max_depth}

    # token helpers
    @property
    def tok(self) -> Token:
        return self._ahead[0]

    def peek(self) -> Token:
        """The token after the current one."""
        ahead = self._ahead
        if len(ahead) == 1:
            ahead.append(ahead[0] if ahead[0].kind == "eof" else next(self._tokens))
        return ahead[1]

    def is_punct(self, p: str, tok: Token | None = None) -> bool:
        t = self.tok if tok is None else tok
        return t.kind == "punct" and t.text == p

    def advance(self) -> Token:
        ahead = self._ahead
        t = ahead[0]
        if t.kind != "eof":
            if len(ahead) == 1:
                ahead[0] = next(self._tokens)
            else:
                del ahead[0]
        return t

    def fail(self, what: str, tok: Token | None = None):
        t = self.tok if tok is None else tok
        raise self.src.error(t.pos, f"syntax error: expected {what}, got {show(t)}")

    def expect(self, p: str, what: str | None = None) -> Token:
        if not self.is_punct(p):
            self.fail(what or repr(p))
        return self.advance()

    def enter(self, tok: Token, what: str = "depth"):
        d = getattr(self, what) + 1
        setattr(self, what, d)
        limit = self.limits[what]
        if d > limit:
            kind = "nodes" if what == "depth" else "values"
            raise self.src.error(tok.pos, f"{kind} nested deeper than {limit} levels are not supported")

    def leave(self, what: str = "depth"):
        setattr(self, what, getattr(self, what) - 1)

    # grammar
    #
    # statements(), statement() and instantiation() are the recursive-descent rules written as
    # generators: where a rule needs a sub-rule it yields the sub-rule's generator and run()
    # sends back its result.  run() keeps the pending rules on an explicit stack, so the
    # nesting depth of the input is bounded by max_node_depth, not by Python's recursion limit
    # (``yield from`` would recurse in C once per level).
    def parse_file(self) -> list[Node]:
        nodes = run(self.statements(end=None))
        if self.tok.kind != "eof":  # pragma: no cover - statements() stops only at eof here
            self.fail("a statement")
        return nodes

    def statements(self, end: str | None):
        out: list[Node] = []
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
        if name in SOURCE_KEYWORDS or (self.is_punct("=", self.peek()) and not mods):
            raise self.src.error(t.pos, f"syntax error: unexpected {name!r}: {SOURCE_HINT}")
        if name in ("true", "false", "undef"):
            self.fail("a node such as cube(...), group() or ';'")
        self.advance()
        self.expect("(", f"'(' after {name}")
        args = self.arguments()
        self.expect(")", f"',' or ')' in the arguments of {name}()")
        node = Node(name, args, [], mods, t.pos)
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

    def arguments(self) -> list[Arg]:
        args: list[Arg] = []
        while not self.is_punct(")"):
            t = self.tok
            if t.kind == "id" and self.is_punct("=", self.peek()):
                self.advance()
                self.advance()
                args.append(Arg(t.text, self.value(), t.pos))
            else:
                args.append(Arg(None, self.value(), t.pos))
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
            if not is_num(v):
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
                f"got {show(t)}: variables and expressions do not occur in CSG export",
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
                    r = Range(first, second, third)
                else:
                    r = Range(first, 1.0, second)
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

