"""Supersampling: N x N subpixels per pixel, filtered down in linear light.

:func:`supersample` renders the camera's view at N times its width and height (the same
field of view, so the N x N subpixels of a pixel tile it evenly) and averages every N x N
block with a box filter: colours are decoded with the shading's ``gamma`` into linear light,
weighted by alpha (premultiplied, so a half-covered pixel over a transparent background keeps
the surface's colour and gets half its alpha), averaged and encoded again.  Depth, quadric ids
and primitive ids are not averaged: they stay those of the pixel centre, from the centre
subpixel for odd N (its ray is the pixel-centre ray) and from a plain 1 x 1 render for even N.
"""

from __future__ import annotations

import time

import numpy as np

from ..errors import UsageError
from .image import Image

#: the largest N accepted (N^2 subpixels per pixel)
MAX_AA = 8
#: the largest supersampled image, in subpixels
MAX_SUBPIXELS = 1 << 26


def check_aa(aa, width: int, height: int) -> int:
    """``aa`` as an int in [1, MAX_AA] whose supersampled image stays within MAX_SUBPIXELS."""
    try:
        n = int(aa)
    except (TypeError, ValueError):
        raise UsageError(f"aa must be an integer from 1 to {MAX_AA}, got {aa!r}") from None
    if n != aa or not 1 <= n <= MAX_AA:
        raise UsageError(f"aa must be an integer from 1 to {MAX_AA}, got {aa!r}")
    if width * height * n * n > MAX_SUBPIXELS:
        raise UsageError(f"aa {n} at {width}x{height} needs {width * n}x{height * n} subpixels, more than "
                         f"{MAX_SUBPIXELS:,}: use a smaller aa or image")
    return n


def downsample(rgba: np.ndarray, n: int, gamma: float = 2.2) -> np.ndarray:
    """(H*n, W*n, 4) uint8 -> (H, W, 4) uint8: the box filter of n x n blocks in linear light
    (colours decoded with ``gamma``, weighted by alpha): per pixel, with subpixel colours c_k
    (0-255) and alphas a_k (0-255), colour = (sum lut(c_k) a_k / sum a_k)^(1/gamma) and
    alpha = sum a_k / n^2, where lut(c) = (c / 255)^gamma.  The sums run over the n^2 strided
    subpixel planes (one (H, W) plane at a time, no (H*n, W*n) float copy)."""
    h, w = rgba.shape[0] // n, rgba.shape[1] // n
    lut = ((np.arange(256, dtype=np.float64) / 255.0) ** float(gamma)).astype(np.float32)
    lin = np.zeros((h, w, 3), np.float32)
    a = np.zeros((h, w, 1), np.float32)
    for i in range(n):
        for j in range(n):
            sub = rgba[i:h * n:n, j:w * n:n]
            al = sub[..., 3:4].astype(np.float32)
            lin += lut[sub[..., :3]] * al
            a += al
    with np.errstate(divide="ignore", invalid="ignore"):
        colour = np.where(a > 0, lin / a, np.float32(0.0))
    out = np.empty((h, w, 4), dtype=np.uint8)
    out[..., :3] = np.clip(np.round(255.0 * np.clip(colour, 0.0, 1.0) ** (1.0 / float(gamma))), 0, 255)
    out[..., 3] = np.clip(np.round(a[..., 0] * (1.0 / (n * n))), 0, 255)
    return out


def supersample(render_at, camera, aa: int, gamma: float = 2.2, centre: bool = True) -> Image:
    """The image of ``camera`` with ``aa`` x ``aa`` supersampling.

    ``render_at(camera) -> Image`` renders one view (the splat renderer or the ray tracer on
    fixed samples and options).  ``aa = 1`` is a plain render.  Depth and ids are those of the
    pixel centres: for even ``aa`` a plain render of them, unless ``centre`` is False (then the
    subpixel just below and right of the centre: a frame that only shows the colours).
    ``Image.stats`` are the supersampled render's, with ``aa``, ``width`` / ``height`` of the
    result and ``supersample_s`` (the whole call).
    """
    n = check_aa(aa, camera.width, camera.height)
    if n == 1:
        return render_at(camera)
    t0 = time.perf_counter()
    W, H = camera.width, camera.height
    big = render_at(camera.resized(W * n, H * n))
    rgba = downsample(big.rgba, n, gamma)
    if n % 2 or not centre:
        c = n // 2
        depth = None if big.depth is None else big.depth[c::n, c::n].copy()
        ids = big.ids[c::n, c::n].copy()
        prims = None if big.primitives is None else big.primitives[c::n, c::n].copy()
    else:
        plain = render_at(camera)
        depth, ids, prims = plain.depth, plain.ids, plain.primitives
    stats = dict(big.stats)
    stats.update({"aa": n, "width": W, "height": H, "covered_pixels": int((ids >= 0).sum()),
                  "supersample_s": time.perf_counter() - t0})
    return Image(rgba, depth, ids, prims, stats)
