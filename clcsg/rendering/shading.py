"""The view record (``rendering/shade.h``: camera in device coordinates plus the shading
options) shared by the splat renderer and the exact ray tracer, so both produce the same pixel
for the same hit."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..errors import UsageError
from ..model.colors import ColorError
from ..model.colors import parse_color as parse

#: the float options of :class:`Shading` (non-negative numbers), in ``view_rec`` order
_WEIGHTS = ("ambient", "ground", "diffuse", "headlight", "key_light", "fill_light", "rim", "specular", "shininess",
            "gamma")


def view_dtype(real) -> np.dtype:
    """numpy mirror of ``view_rec`` in rendering/shade.h (C natural alignment)."""
    camera = [(name, real, 3) for name in ("eye", "d00", "dx", "dy", "forward", "right", "up")]
    return np.dtype(
        camera
        + [("focal", real), ("width", np.int32), ("height", np.int32), ("background", np.float32, 4)]
        + [(name, np.float32, 3) for name in ("key", "fill", "sky")]
        + [(name, np.float32) for name in _WEIGHTS]
        + [("spec_cut", np.float32)],
        align=True,
    )


def parse_color(c, what="background") -> tuple[float, float, float, float]:
    """RGBA in [0, 1] from 3 or 4 numbers in [0, 1] (alpha defaults to 1) or a colour name or
    ``#hex`` string (:func:`clcsg.model.colors.parse_color`)."""
    try:
        return parse(c)
    except ColorError as e:
        raise UsageError(f"{what} must be 3 or 4 numbers in [0, 1] or a color name: {e}") from None


@dataclass(frozen=True)
class Shading:
    """The lighting shared by both renderers (rendering/shade.h), in linear light::

        albedo * (ambient * lerp(ground, 1, (1 + n.sky) / 2)
                  + diffuse * (headlight d_head + key_light d_key + fill_light d_fill)
                  + rim * (1 - n.v)^3) + specular * Blinn-Phong(key)

    A hemisphere light from the world's up (the camera's ``sky``: the ``up`` it was built
    with) gives every face a value by its orientation, so faces no light reaches, such as the
    inside of a hollow part, stay readable; a headlight at the eye, a key light from the upper
    left and a weaker fill from the lower right (directions in the camera frame as weights of
    (right, up, backward = -forward)).  ``rim`` (off by default: on a light background it
    blurs the silhouette) brightens grazing faces.  All lights are white: shading scales a
    colour, it never shifts its hue.  Colours are display values, linearized with ``gamma``, lit, and encoded
    again with 1 / ``gamma``; ``background`` (RGBA in [0, 1]) is written unlit.
    """

    background: tuple = (1.0, 1.0, 1.0, 1.0)
    ambient: float = 0.3
    ground: float = 0.1
    diffuse: float = 0.75
    headlight: float = 0.4
    key_light: float = 0.65
    fill_light: float = 0.2
    rim: float = 0.0
    specular: float = 0.18
    shininess: float = 32.0
    gamma: float = 2.2
    key: tuple = (-0.5, 0.75, 0.45)
    fill: tuple = (0.7, -0.35, 0.45)

    def with_options(self, **kw) -> "Shading":
        unknown = set(kw) - set(self.__dataclass_fields__)
        if unknown:
            raise UsageError(f"unknown shading option {sorted(unknown)[0]!r}; known: {', '.join(self.__dataclass_fields__)}")
        if "background" in kw and kw["background"] is not None:
            kw["background"] = parse_color(kw["background"])
        kw = {k: v for k, v in kw.items() if v is not None}
        s = replace(self, **kw)
        for name in _WEIGHTS:
            v = float(getattr(s, name))
            if not (math.isfinite(v) and v >= 0) or (name == "gamma" and v == 0):
                raise UsageError(f"shading option {name} must be a non-negative number, got {getattr(s, name)}")
        for name in ("key", "fill"):
            d = np.asarray(getattr(s, name), dtype=np.float64).reshape(-1)
            if d.shape != (3,) or not np.all(np.isfinite(d)) or not d.any():
                raise UsageError(f"shading option {name} must be a non-zero direction (3 numbers), got {getattr(s, name)}")
        return s


def _camera_direction(camera, weights) -> np.ndarray:
    """A unit world direction from weights of (right, up, backward) of the camera frame."""
    r, u, b = (float(x) for x in weights)
    d = r * camera.right + u * camera.up - b * camera.forward
    return d / np.linalg.norm(d)


def highlight_cut(specular: float, shininess: float) -> float:
    """The n.h at or under which shade.h skips the highlight: specular (n.h)^shininess <= 2^-64
    there, so the term changes no lit colour but one within 2^-64 of an 8-bit threshold
    (-1, never skipped, for shininess 0: there x^0 = 1)."""
    if shininess <= 0:
        return -1.0
    if specular <= 0:
        return math.inf
    return min(1.0, 2.0 ** ((-64.0 - math.log2(specular)) / shininess))


def pack_view(camera, origin, real, shading: Shading | None = None) -> np.ndarray:
    """The ``view_rec`` of ``camera`` in device coordinates (eye - origin), one element."""
    shading = shading or Shading()
    rec = np.zeros(1, dtype=view_dtype(real))
    d00, dx, dy = camera.pixel_basis()
    sky = getattr(camera, "sky", None)
    values = {
        "eye": np.asarray(camera.eye, dtype=np.float64) - np.asarray(origin, dtype=np.float64),
        "d00": d00, "dx": dx, "dy": dy, "forward": camera.forward, "right": camera.right, "up": camera.up,
        "focal": camera.focal, "width": camera.width, "height": camera.height,
        "background": parse_color(shading.background),
        "key": _camera_direction(camera, shading.key), "fill": _camera_direction(camera, shading.fill),
        "sky": camera.up if sky is None else sky,
        **{name: getattr(shading, name) for name in _WEIGHTS},
        "spec_cut": highlight_cut(shading.specular, shading.shininess),
    }
    for name, v in values.items():
        rec[name] = v
    return rec
