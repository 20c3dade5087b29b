"""The result of a render: color, depth and quadric ids per pixel, plus statistics."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..writers.output_files import png_bytes, write_image, write_json, write_npy


@dataclass
class Image:
    """A rendered image.

    ``rgba``: (H, W, 4) uint8, row 0 at the top.  ``depth``: (H, W) float32, the distance along
    the unit view ray to the visible surface point (+inf on background).  ``ids``: (H, W) int32,
    the index of the visible quadric in the scene's tape (``tape.quadrics``, -1 on background).
    ``primitives``: (H, W) int32, the primitive instance (``tape.instances``, tree order) whose
    boundary holds the visible point, whose colour the pixel shows (-1 on background).
    ``stats``: timings in seconds and renderer counters (see :func:`clcsg.render`).
    """

    rgba: np.ndarray
    depth: np.ndarray
    ids: np.ndarray
    primitives: np.ndarray | None = None
    stats: dict = field(default_factory=dict)

    @property
    def width(self) -> int:
        return int(self.rgba.shape[1])

    @property
    def height(self) -> int:
        return int(self.rgba.shape[0])

    @property
    def mask(self) -> np.ndarray:
        """(H, W) bool: pixels showing the surface."""
        return self.ids >= 0

    def save(self, path) -> None:
        """Write the color image; the format is the extension's: ``.png``, ``.jpg`` / ``.jpeg``
        (no alpha: the alpha channel is dropped), ``.webp`` (lossless) or ``.tif`` / ``.tiff``
        (see :mod:`clcsg.writers.output_files`).  Another extension is a UsageError."""
        write_image(self.rgba, path)

    def _repr_png_(self) -> bytes:
        """The image as PNG, for Jupyter and IPython."""
        return png_bytes(self.rgba)

    def save_depth(self, path) -> None:
        """Write the depth as a .npy file: (H, W) float32, +inf on background."""
        _save_npy(path, self.depth)

    def save_ids(self, path) -> None:
        """Write the quadric ids as a .npy file: (H, W) int32, -1 on background."""
        _save_npy(path, self.ids)

    def save_stats(self, path) -> None:
        """Write the statistics as JSON."""
        write_json(path, _jsonable(self.stats), "stats", sort_keys=True)


def _save_npy(path, a) -> None:
    write_npy(path, a, "array")


def _jsonable(v):
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, float) and not np.isfinite(v):
        return str(v)
    return v
