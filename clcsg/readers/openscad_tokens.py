"""The tokenizer and parser of OpenSCAD's CSG export (the syntax half of :mod:`clcsg.readers.openscad`).

Grammar (a hand-written tokenizer and parser, no dependencies; the rules for statements and
nodes run on an explicit stack of open blocks)::

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

:class:`Parser` turns the text, read a chunk at a time by :class:`Source`, into a stream of
events: ``(OPEN, node)`` and ``(CLOSE, node)`` around a node's children, ``(LEAF, node)`` for a
node without (a :class:`Node`: name, arguments, modifiers, position); :func:`tree` builds the
syntax tree from the events where one is needed.  Syntax errors are
:class:`~clcsg.errors.SceneError` reading ``<file>:<line>:<col>: syntax error: expected ...``.
Nodes nest up to ``max_node_depth`` levels (an explicit stack, no recursion); values
(vectors, signs) are parsed recursively and nest up to ``max_depth`` levels.
"""

from __future__ import annotations

import math
import re
from array import array
from bisect import bisect_right
from sys import intern
import warnings
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..errors import SceneError


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
_NUM = r"(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?"
_SNUM = rf"[+-]?{_NUM}"
_ROW = rf"\[\s*{_SNUM}(?:\s*,\s*{_SNUM})*\s*\]"
#: one token after any whitespace and comments (one match per token); no token group matched
#: means the end of the text or a character no token starts with.  ``vec`` is a shortcut: a
#: vector of signed numbers, or a vector of such vectors (a matrix), without comments or a
#: trailing comma, is one token (CSG export writes every size, color and matrix so); any
#: other vector is read token by token, to the same value
_TOKEN_RE = re.compile(
    rf"""
    (?:[ \t\r\n\f\v]+ | //[^\n]* | /\*.*?\*/)*
    (?:
      (?P<num>{_NUM})
    | (?P<vec>\[\s*(?:{_ROW}(?:\s*,\s*{_ROW})*|{_SNUM}(?:\s*,\s*{_SNUM})*)\s*\])
    | (?P<id>\$?[A-Za-z_][A-Za-z0-9_]*)
    | (?P<str>"(?:[^"\\]|\\.)*")
    | (?P<punct>[()\[\]{{}},;=:!#%*+\-])
    )?
    """,
    re.VERBOSE | re.DOTALL | re.ASCII,
)

_SNUM_RE = re.compile(_SNUM, re.ASCII)
_ROW_RE = re.compile(r"\[[^\[\]]*\]")

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
    if tok.kind == "vec":  # as if the vector had been read token by token
        return "'['"
    t = tok.text
    if len(t) > 24:
        t = t[:21] + "..."
    return repr(t)


class Source:
    """The text, read a chunk at a time, and offset -> (line, column) for messages.

    ``chunks`` is an iterable of str pieces of the text; :meth:`read` hands out the next one
    and records where its lines start (an ``array`` of 8-byte offsets, about a fifth of the
    text's size), so that a message can name the line and column of any offset after the text
    itself is gone.  Warnings are collected in :attr:`pending` and emitted by :meth:`flush`:
    the reader emits them once the whole file has parsed (a syntax error anywhere wins over
    the evaluation's warnings, as when the file was parsed before it was evaluated).
    """

    def __init__(self, chunks, name: str):
        self.name = name
        self._chunks = iter(chunks)
        self.length = 0  # characters read so far
        self._lines = array("q", [0])  # offsets of line starts
        self.pending: list[tuple[str, int]] = []

    def read(self) -> str:
        """The next chunk of the text ('' at its end)."""
        c = next(self._chunks, "")
        if c:
            if c.isascii():
                codes = np.frombuffer(c.encode("ascii"), dtype=np.uint8)
            else:
                codes = np.frombuffer(c.encode("utf-32-le", "surrogatepass"), dtype=np.uint32)
            starts = np.flatnonzero(codes == 10).astype(np.int64) + (self.length + 1)
            self._lines.frombytes(starts.tobytes())
            self.length += len(c)
        return c

    def line_col(self, pos: int) -> tuple[int, int]:
        line = bisect_right(self._lines, pos)
        return line, pos - self._lines[line - 1] + 1

    def where(self, pos: int) -> str:
        line, col = self.line_col(pos)
        return f"{self.name}:{line}:{col}"

    def error(self, pos: int, message: str) -> SceneError:
        return SceneError(one_line(f"{self.where(pos)}: {message}"))

    def warn(self, pos: int, message: str) -> None:
        self.pending.append((one_line(f"{self.where(pos)}: {message}"), self.line_col(pos)[0]))

    def flush(self) -> None:
        """Emit the collected warnings (reported at the .csg file's line, not at this module's)."""
        pending, self.pending = self.pending, []
        for message, line in pending:
            warnings.warn_explicit(message, OpenScadWarning, self.name, line)


def chunks_of(text: str, size: int):
    """``text`` in pieces of ``size`` characters."""
    for i in range(0, len(text), size):
        yield text[i:i + size]


def one_line(s: str) -> str:
    return " ".join(s.splitlines())


def _bad_character(src: Source, text: str, i: int, base: int) -> SceneError:
    """The error for the character at ``text[i]`` (offset ``base + i`` of the file)."""
    c = text[i]
    pos = base + i
    if text.startswith("/*", i):
        return src.error(pos, "syntax error: unterminated comment (missing '*/')")
    if c == '"':
        return src.error(pos, "syntax error: unterminated string (missing '\"')")
    if c == "<" and text[max(0, i - 64):i].rstrip().endswith(("include", "use")):
        return src.error(pos, f"syntax error: unexpected character '<': {SOURCE_HINT}")
    return src.error(pos, f"syntax error: unexpected character {c!r}")


#: distinct number texts whose float objects the tokenizer shares, and the longest such text
#: (short numbers such as 0, 1 and 0.5 repeat; long ones rarely do and would make the cache
#: the largest object of the reader)
_NUMBER_CACHE = 4096
_NUMBER_TEXT = 6
#: a match ending this close to the buffer's end may be cut short by it (``1e`` of ``1e5``:
#: the number matches ``1``), so it is retried with the next chunk appended
_AHEAD = 8
#: characters kept before the current token when the buffer is refilled (for messages that
#: look back, such as the ``include <...>`` hint)
_KEEP = 64


def _number(numbers: dict, t: str) -> float:
    """float(t), kept in ``numbers`` if the text is short (0.0 is not kept: ``get() or``
    parses it again, which is cheap)."""
    v = float(t)
    if len(t) <= _NUMBER_TEXT and v:
        if len(numbers) > _NUMBER_CACHE:
            numbers.clear()
        numbers[t] = v
    return v


def tokenize(src: Source):
    """The tokens of ``src``, one at a time (a generator: no list of tokens is built, and only
    the chunk being read is held), the last one of kind ``eof``.

    A token is matched in a buffer that holds the rest of the current chunk; a match that
    ends within :data:`_AHEAD` characters of the buffer's end (a number, name, string or
    comment may go on in the next chunk) or that finds no token is retried after the next
    chunk is appended.  A vector token cut by the buffer's end does not match: that vector is
    read token by token, to the same value."""
    buf = src.read()
    base = 0  # file offset of buf[0]
    more = bool(buf)
    match = _TOKEN_RE.match
    numbers: dict[str, float] = {}  # one float object per distinct number text (0, 1, ... repeat a lot)
    i = 0
    n = len(buf)
    while True:
        m = match(buf, i)
        kind = m.lastgroup
        if more and (kind is None or m.end() + _AHEAD > n):
            keep = max(0, i - _KEEP)
            nxt = src.read()
            if not nxt:
                more = False
            buf = buf[keep:] + nxt
            base += keep
            i -= keep
            n = len(buf)
            continue
        if kind is None:
            end = m.end()
            if end >= n:
                break
            raise _bad_character(src, buf, end, base)
        start = m.start(kind) + base
        t = m.group(kind)
        if kind == "num":
            yield Token("num", t, numbers.get(t) or _number(numbers, t), start)
        elif kind == "vec":
            if t.count("[") == 1:
                v = [numbers.get(x) or _number(numbers, x) for x in _SNUM_RE.findall(t)]
            else:
                v = [[numbers.get(x) or _number(numbers, x) for x in _SNUM_RE.findall(row)] for row in _ROW_RE.findall(t)]
            yield Token("vec", t, v, start)
        elif kind == "str":
            yield Token("str", t, _unescape(t[1:-1]), start)
        else:  # names and punctuation repeat: one string object each
            t = intern(t)
            yield Token(kind, t, t, start)
        i = m.end()
    yield Token("eof", "", None, base + n)


# -- nodes and events -------------------------------------------------------------------------
@dataclass(slots=True)
class Arg:
    name: str | None
    value: object
    pos: int


@dataclass(slots=True)
class Node:
    name: str
    args: list[Arg]
    children: list["Node"]  # filled only where a tree is built (tree(), 2-D profiles)
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


#: event kinds: a node with children starts and ends, a node without children
OPEN, CLOSE, LEAF = 0, 1, 2


def tree(events) -> list[Node]:
    """The nodes of an event stream as a tree (``children`` filled in)."""
    top: list[Node] = []
    stack = [top]
    for kind, node in events:
        if kind == LEAF:
            stack[-1].append(node)
        elif kind == OPEN:
            stack[-1].append(node)
            stack.append(node.children)
        else:
            stack.pop()
    return top


def events_of(nodes):
    """The event stream of a tree of nodes (the inverse of :func:`tree`)."""
    stack = [(n, False) for n in reversed(nodes)]
    while stack:
        node, done = stack.pop()
        if done:
            yield CLOSE, node
        elif node.has_children_block:
            stack.append((node, True))
            stack.extend((c, False) for c in reversed(node.children))
            yield OPEN, node  # (whoever gets it may rebuild node.children from the events)
        else:
            yield LEAF, node


class _Block:
    """An open '{' (``owner``: the node it belongs to, or None for a bare block)."""

    __slots__ = ("owner",)

    def __init__(self, owner):
        self.owner = owner


class _Single:
    """A node whose one child is a statement without braces."""

    __slots__ = ("owner",)

    def __init__(self, owner):
        self.owner = owner


class Parser:
    """``Parser(src, max_node_depth, max_depth).events()``: the nodes of a CSG export as a
    stream of ``(OPEN, node)``, ``(CLOSE, node)`` and ``(LEAF, node)`` events, in file order.

    The statement rules run on an explicit stack of open blocks (no recursion, and no
    syntax tree: a node's children are not kept), so memory follows the nesting depth of the
    file, not its size."""

    def __init__(self, src: Source, max_node_depth: int, max_depth: int):
        self.src = src
        self._tokens = tokenize(src)
        self.tok = next(self._tokens)  # the current token
        self._next = None  # the token after it, once peek() has read it
        self.depth = 0  # nested nodes
        self.vdepth = 0  # nested vectors and signs
        self.max_node_depth = max_node_depth
        self.max_depth = max_depth

    # token helpers
    def peek(self) -> Token:
        """The token after the current one."""
        if self._next is None:
            self._next = self.tok if self.tok.kind == "eof" else next(self._tokens)
        return self._next

    def is_punct(self, p: str, tok: Token | None = None) -> bool:
        t = self.tok if tok is None else tok
        return t.kind == "punct" and t.text == p

    def advance(self) -> Token:
        t = self.tok
        if t.kind != "eof":
            if self._next is None:
                self.tok = next(self._tokens)
            else:
                self.tok, self._next = self._next, None
        return t

    def fail(self, what: str, tok: Token | None = None):
        t = self.tok if tok is None else tok
        raise self.src.error(t.pos, f"syntax error: expected {what}, got {show(t)}")

    def expect(self, p: str, what: str | None = None) -> Token:
        t = self.tok
        if t.kind != "punct" or t.text != p:
            self.fail(what or repr(p))
        return self.advance()

    def enter(self, tok: Token):
        self.depth += 1
        if self.depth > self.max_node_depth:
            raise self.src.error(tok.pos, f"nodes nested deeper than {self.max_node_depth} levels are not supported")

    def enter_value(self, tok: Token):
        self.vdepth += 1
        if self.vdepth > self.max_depth:
            raise self.src.error(tok.pos, f"values nested deeper than {self.max_depth} levels are not supported")

    # grammar
    def events(self):
        """The events of the whole file (a generator)."""
        stack: list = [_Block(None)]  # the file is a block that ends at eof
        while True:
            top = stack[-1]
            t = self.tok
            if type(top) is _Single:
                node = self.header()
            else:
                if t.kind == "punct":
                    p = t.text
                    if p == ";":
                        self.advance()
                        continue
                    if p == "}" and len(stack) > 1:
                        self.advance()
                        stack.pop()
                        self.depth -= 1
                        if top.owner is None:
                            continue
                        yield CLOSE, top.owner
                        while type(stack[-1]) is _Single:  # their one child is complete
                            yield CLOSE, stack.pop().owner
                            self.depth -= 1
                        continue
                    if p == "{":
                        self.enter(t)
                        self.advance()
                        stack.append(_Block(None))
                        continue
                elif t.kind == "eof":
                    if len(stack) > 1:
                        self.fail(repr("}"))
                    return
                node = self.header()
            c = self.tok
            if c.kind == "punct" and c.text == ";":
                self.advance()
                yield LEAF, node
                while type(stack[-1]) is _Single:
                    yield CLOSE, stack.pop().owner
                    self.depth -= 1
            elif c.kind == "punct" and c.text == "{":
                self.enter(c)
                self.advance()
                node.has_children_block = True
                yield OPEN, node
                stack.append(_Block(node))
            elif c.kind == "id" or (c.kind == "punct" and c.text in "*%!#"):
                self.enter(c)
                node.has_children_block = True
                yield OPEN, node
                stack.append(_Single(node))
            else:
                self.fail(f"';' or '{{' after {node.name}(...)")

    def parse_file(self) -> list[Node]:
        """The nodes of the whole file as a tree."""
        return tree(self.events())

    def header(self) -> Node:
        """``modifier* NAME '(' arguments ')'``: a node without its children."""
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
        return Node(name, args, [], mods, t.pos)

    def arguments(self) -> list[Arg]:
        args: list[Arg] = []
        while True:
            t = self.tok
            if t.kind == "punct" and t.text == ")":
                return args
            if t.kind == "id" and self.is_punct("=", self.peek()):
                self.advance()
                self.advance()
                args.append(Arg(t.text, self.value(), t.pos))
            else:
                args.append(Arg(None, self.value(), t.pos))
            t = self.tok
            if t.kind == "punct" and t.text == ",":
                self.advance()
            elif not (t.kind == "punct" and t.text == ")"):
                self.fail("',' or ')'")

    def value(self):
        t = self.tok
        kind = t.kind
        if kind == "num" or kind == "str":
            self.advance()
            return t.value
        if kind == "vec":
            v = t.value
            if self.vdepth + (2 if type(v[0]) is list else 1) > self.max_depth:
                pos = t.pos if self.vdepth + 1 > self.max_depth else t.pos + t.text.index("[", 1)
                raise self.src.error(pos, f"values nested deeper than {self.max_depth} levels are not supported")
            self.advance()
            return v
        if kind == "punct" and (t.text == "-" or t.text == "+"):
            self.enter_value(t)
            self.advance()
            v = self.value()
            self.vdepth -= 1
            if not is_num(v):
                raise self.src.error(t.pos, f"syntax error: {t.text!r} must be followed by a number")
            return -v if t.text == "-" else v
        if kind == "id":
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
        if kind == "punct" and t.text == "[":
            self.enter_value(t)
            self.advance()
            if self.is_punct("]"):
                self.advance()
                self.vdepth -= 1
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
                self.vdepth -= 1
                return r
            items = [first]
            while True:
                t = self.tok
                if t.kind == "punct" and t.text == ",":
                    self.advance()
                    if self.is_punct("]"):
                        break
                    items.append(self.value())
                elif t.kind == "punct" and t.text == "]":
                    break
                else:
                    self.fail("',' or ']' in the vector")
            self.advance()
            self.vdepth -= 1
            return items
        self.fail("a value (number, string, vector, true, false or undef)")
