"""The view record (``rendering/shade.h``: camera in device coordinates plus the shading
options) shared by the splat renderer and the exact ray tracer, so both produce the same pixel
for the same hit."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..errors import UsageError


def view_dtype(real) -> np.dtype:
    """numpy mirror of ``view_rec`` in rendering/shade.h (C natural alignment)."""
    return np.dtype(
        [
            ("eye", real, 3),
            ("d00", real, 3),
            ("dx", real, 3),
            ("dy", real, 3),
            ("forward", real, 3),
            ("right", real, 3),
            ("up", real, 3),
            ("focal", real),
            ("width", np.int32),
            ("height", np.int32),
            ("background", np.float32, 4),
            ("key", np.float32, 3),
            ("ambient", np.float32),
            ("diffuse", np.float32),
            ("specular", np.float32),
            ("shininess", np.float32),
            ("gamma", np.float32),
        ],
        align=True,
    )


def parse_color(c, what="background") -> tuple[float, float, float, float]:
    """RGBA in [0, 1] from 3 or 4 numbers in [0, 1] (alpha defaults to 1)."""
    try:
        v = [float(x) for x in c]
    except (TypeError, ValueError):
        raise UsageError(f"{what} must be 3 or 4 numbers in [0, 1], got {c!r}") from None
    if len(v) == 3:
        v.append(1.0)
    if len(v) != 4 or not all(math.isfinite(x) and 0.0 <= x <= 1.0 for x in v):
        raise UsageError(f"{what} must be 3 or 4 numbers in [0, 1], got {list(c)}")
    return tuple(v)


@dataclass(frozen=True)
class Shading:
    """Blinn-Phong shading shared by both renderers (rendering/shade.h).

    Two white lights: a headlight at the eye and a key light whose direction is given in the
    camera frame as weights of (right, up, backward = -forward).  Quadric colors are taken as
    display values, linearized with ``gamma``, lit, and encoded again with 1 / ``gamma``.
    ``background`` (RGBA in [0, 1]) is written unlit.
    """

    background: tuple = (1.0, 1.0, 1.0, 1.0)
    ambient: float = 0.12
    diffuse: float = 0.85
    specular: float = 0.25
    shininess: float = 40.0
    gamma: float = 2.2
    key: tuple = (-0.4, 0.6, 0.7)

    def with_options(self, **kw) -> "Shading":
        unknown = set(kw) - set(self.__dataclass_fields__)
        if unknown:
            raise UsageError(f"unknown shading option {sorted(unknown)[0]!r}; known: {', '.join(self.__dataclass_fields__)}")
        if "background" in kw and kw["background"] is not None:
            kw["background"] = parse_color(kw["background"])
        kw = {k: v for k, v in kw.items() if v is not None}
        s = replace(self, **kw)
        for name in ("ambient", "diffuse", "specular", "shininess", "gamma"):
            v = float(getattr(s, name))
            if not (math.isfinite(v) and v >= 0) or (name == "gamma" and v == 0):
                raise UsageError(f"shading option {name} must be a non-negative number, got {getattr(s, name)}")
        return s


def pack_view(camera, origin, real, shading: Shading | None = None) -> np.ndarray:
    """The ``view_rec`` of ``camera`` in device coordinates (eye - origin), one element."""
    shading = shading or Shading()
    rec = np.zeros(1, dtype=view_dtype(real))
    d00, dx, dy = camera.pixel_basis()
    rec["eye"] = np.asarray(camera.eye, dtype=np.float64) - np.asarray(origin, dtype=np.float64)
    rec["d00"] = d00
    rec["dx"] = dx
    rec["dy"] = dy
    rec["forward"] = camera.forward
    rec["right"] = camera.right
    rec["up"] = camera.up
    rec["focal"] = camera.focal
    rec["width"] = camera.width
    rec["height"] = camera.height
    rec["background"] = parse_color(shading.background)
    kr, ku, kb = shading.key
    key = kr * camera.right + ku * camera.up - kb * camera.forward
    rec["key"] = key / np.linalg.norm(key)
    for name in ("ambient", "diffuse", "specular", "shininess", "gamma"):
        rec[name] = getattr(shading, name)
    return rec
