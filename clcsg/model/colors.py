"""Colours: the one parser for every colour clcsg reads.

Scene files (``"color": "steelblue"``), OpenSCAD's ``color("#f9d72c")`` and the command line's
``--background`` all go through :func:`parse_color` (or :func:`parse_color_text` for a command
line value), so they accept the same forms:

* a CSS / SVG colour name, case-insensitive: the 148 names of CSS Color Module Level 4, taken
  from Pillow's :data:`PIL.ImageColor.colormap` (the same table OpenSCAD's ``ColorNode.cc``
  has), plus OpenSCAD's ``"transparent"`` (black with alpha 0);
* ``"#rgb"``, ``"#rgba"``, ``"#rrggbb"`` or ``"#rrggbbaa"`` (hex digits, parsed by Pillow's
  :func:`PIL.ImageColor.getrgb`);
* 3 or 4 numbers ``[r, g, b(, a)]`` in [0, 1] (alpha 1 when left out); with ``allow_255`` the
  0-255 range too, chosen when any component is above 1.

The result is always an RGBA tuple of 4 floats in [0, 1].  Problems raise :class:`ColorError`
(a ``ValueError``) with a one-line reason; callers add where the value came from (the JSON
path, the ``.csg`` line, the option name).
"""

from __future__ import annotations

import math
import numbers
import re
from collections.abc import Mapping

from .csg import DEFAULT_COLOR

#: OpenSCAD's default face colour, "opencsg-face-front" / "cgal-face-front" of its default
#: colour scheme "Cornfield" (color-schemes/render/cornfield.json): ``clcsg render --colors
#: openscad`` gives it to the primitives that have no colour of their own
OPENSCAD_FACE = "#f9d72c"
#: the background of the same scheme
OPENSCAD_BACKGROUND = "#ffffe5"

#: colour schemes for primitives without a colour (``--colors``); ``None`` keeps clcsg's
#: default (:data:`clcsg.model.csg.DEFAULT_COLOR`, light grey)
SCHEMES = {"clcsg": None, "openscad": OPENSCAD_FACE}

class _NamedColors(Mapping):
    """Pillow's colour table, read on first use: a command that names no colour does not
    import Pillow (it costs a tenth of the start of ``clcsg sample``)."""

    def __init__(self):
        self._table: dict | None = None

    def _load(self) -> dict:
        if self._table is None:
            from PIL import ImageColor

            self._table = {**{name: ImageColor.getrgb(name) for name in sorted(ImageColor.colormap)},
                           "transparent": (0, 0, 0, 0)}  # OpenSCAD's own addition
        return self._table

    def __getitem__(self, name):
        return self._load()[name]

    def __iter__(self):
        return iter(self._load())

    def __len__(self) -> int:
        return len(self._load())


#: every colour name: 0-255 RGB (or RGBA) per lower-case name, as Pillow defines them
NAMED_COLORS: Mapping[str, tuple[int, ...]] = _NamedColors()

_HEX = re.compile(r"#(?:[0-9a-fA-F]{3,4}|[0-9a-fA-F]{6}|[0-9a-fA-F]{8})\Z")
FORMS = 'a color name such as "steelblue", "#rgb", "#rgba", "#rrggbb" or "#rrggbbaa"'


class ColorError(ValueError):
    """A value that is not a colour; the message is the reason, one line."""


def _rgba(values, top: float) -> tuple[float, float, float, float]:
    v = [float(x) / top for x in values]
    return (v[0], v[1], v[2], v[3] if len(v) == 4 else 1.0)


def from_string(text: str) -> tuple[float, float, float, float]:
    """A colour name or ``#hex`` string as RGBA in [0, 1]."""
    s = str(text)
    low = s.lower()
    if low in NAMED_COLORS:
        return _rgba(NAMED_COLORS[low], 255.0)
    if _HEX.match(s):
        digits = s[1:] if len(s) > 5 else "".join(2 * c for c in s[1:])  # #rgb(a) -> #rrggbb(aa)
        return _rgba([int(digits[k:k + 2], 16) for k in range(0, len(digits), 2)], 255.0)
    if s.startswith("#"):
        raise ColorError(f"{text!r} is not a hex color: use #rgb, #rgba, #rrggbb or #rrggbbaa")
    import difflib  # only for the error message

    close = difflib.get_close_matches(low, list(NAMED_COLORS), n=1, cutoff=0.75)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    raise ColorError(f"unknown color name {text!r}{hint}; expected {FORMS}")


def from_numbers(values, allow_255: bool = False) -> tuple[float, float, float, float]:
    """3 or 4 numbers in [0, 1] (or 0-255 with ``allow_255`` when any is above 1) as RGBA."""
    try:
        v = list(values)
    except TypeError:
        raise ColorError(f"expected 3 or 4 numbers or {FORMS}, got {values!r}") from None
    if len(v) not in (3, 4):
        raise ColorError(f"expected 3 or 4 numbers [r, g, b(, a)], got {len(v)}")
    for x in v:
        if isinstance(x, bool) or not isinstance(x, numbers.Real) or not math.isfinite(float(x)):
            raise ColorError(f"color components must be finite numbers, got {x!r}")
    top = 255.0 if allow_255 and any(float(x) > 1.0 for x in v) else 1.0
    for x in v:
        if not 0.0 <= float(x) <= top:
            span = "[0, 1] (or 0-255)" if allow_255 else "[0, 1]"
            raise ColorError(f"color components must be in {span}, got {x:g}")
    return _rgba(v, top)


def parse_color(value, allow_255: bool = False) -> tuple[float, float, float, float]:
    """A colour (a name, a ``#hex`` string or 3-4 numbers) as RGBA floats in [0, 1]."""
    if isinstance(value, str):
        return from_string(value)
    return from_numbers(value, allow_255)


def parse_color_text(text: str, allow_255: bool = True) -> tuple[float, float, float, float]:
    """A command-line colour: ``"R,G,B[,A]"`` (commas and/or spaces) or a name or ``#hex``."""
    s = str(text).strip()
    parts = s.replace(",", " ").split()
    numeric = len(parts) > 1 or (len(parts) == 1 and (parts[0][:1].isdigit() or parts[0][:1] in ".-+"))
    if numeric:
        try:
            nums = [float(p) for p in parts]
        except ValueError:
            raise ColorError(f"expected R,G,B[,A] numbers or {FORMS}, got {text!r}") from None
        return from_numbers(nums, allow_255)
    return from_string(s)


def scheme_color(name: str | None):
    """The RGBA of colour scheme ``name`` (:data:`SCHEMES`), or None for clcsg's default."""
    if name is None:
        return None
    if name not in SCHEMES:
        raise ColorError(f"unknown color scheme {name!r}; known: {', '.join(SCHEMES)}")
    c = SCHEMES[name]
    return None if c is None else from_string(c)


def recolor_defaults(tape, color) -> int:
    """Give every primitive instance of ``tape`` that has clcsg's default colour the colour
    ``color`` (RGBA); returns how many were changed.  Only what rendering reads changes (the
    instances' ``color``), so the tape must be packed again afterwards."""
    if color is None:
        return 0
    default = tuple(float(x) for x in DEFAULT_COLOR)
    n = 0
    for inst in tape.instances:
        if tuple(float(x) for x in inst.color) == default:
            inst.color = tuple(float(x) for x in color)
            n += 1
    return n
