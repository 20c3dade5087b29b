"""Output files: the formats clcsg writes, chosen by extension and checked before any work.

Images (:func:`write_image`, via Pillow): ``.png``, ``.jpg`` / ``.jpeg``, ``.webp`` (lossless,
so the pixels are exact) and ``.tif`` / ``.tiff``; RGBA where the format has alpha, RGB for
JPEG (the alpha channel is dropped: transparent pixels show the background colour).  Samples:
``.ply`` (binary PLY, :mod:`clcsg.writers.ply`) and ``.npz`` (everything needed to render them
again, :mod:`clcsg.writers.samples_npz`).  Per-pixel arrays are ``.npy``, statistics ``.json``.

:func:`check_output` raises a one-line :class:`~clcsg.errors.UsageError` for an unknown
extension, a missing folder or a path that is a directory, and an
:class:`~clcsg.errors.OutputError` for a folder this process cannot write in, so that
``clcsg sample -o x.png`` fails at once instead of after the sampling.

Every writer here goes through :func:`clcsg.atomic.atomic_open`: a temporary in the
target's folder, synced, then renamed over the target; a failure (full disk, ...) is an
:class:`~clcsg.errors.OutputError` (exit code 6) and leaves the old file intact.
"""

from __future__ import annotations

import io
import json
import os

import numpy as np

from ..atomic import atomic_open
from ..errors import OutputError, UsageError
from . import ply, samples_npz

#: image extension -> Pillow format
IMAGE_FORMATS = {".png": "PNG", ".jpg": "JPEG", ".jpeg": "JPEG", ".webp": "WEBP", ".tif": "TIFF", ".tiff": "TIFF"}
#: Pillow formats without an alpha channel
NO_ALPHA = frozenset({"JPEG"})
#: sample extension -> format
SAMPLE_FORMATS = {".ply": "PLY", ".npz": "NPZ"}
#: Pillow's options per format: lossless WebP keeps the exact pixels; high-quality JPEG
_SAVE_OPTIONS = {"WEBP": {"lossless": True, "exact": True}, "JPEG": {"quality": 95}, "TIFF": {"compression": "tiff_lzw"}}


def _names(formats) -> str:
    exts = list(formats)
    return ", ".join(exts[:-1]) + " or " + exts[-1] if len(exts) > 1 else exts[0]


def check_output(path, formats, what: str, option: str | None = "-o") -> str:
    """The format of output ``path`` from its extension (a key of ``formats``: a dict of
    extension -> format, or a single extension); UsageError if the extension is unknown or
    the directory does not exist."""
    if isinstance(formats, str):
        formats = {formats: formats.lstrip(".").upper()}
    p = os.fspath(path)
    where = p if option is None else f"{option} {p}"
    ext = os.path.splitext(p)[1].lower()
    if ext not in formats:
        got = f"{ext!r}" if ext else "no extension"
        raise UsageError(f"{where}: unknown {what} format ({got}); use {_names(formats)}")
    folder = os.path.dirname(os.path.abspath(p))
    if not os.path.isdir(folder):
        raise UsageError(f"{where}: cannot write there: no such directory {os.path.dirname(p) or '.'!r}")
    if os.path.isdir(p):
        raise UsageError(f"{where}: is a directory; give a file name such as {os.path.join(p, 'out' + ext)}")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise OutputError(f"{where}: cannot write there: no permission to create files in "
                          f"{os.path.dirname(p) or '.'!r}")
    return formats[ext]


def check_image_output(path, option: str | None = "-o") -> str:
    return check_output(path, IMAGE_FORMATS, "image", option)


def check_samples_output(path, option: str | None = "-o") -> str:
    return check_output(path, SAMPLE_FORMATS, "sample", option)


def write_samples(samples, path, float32: bool = False) -> None:
    """Write :class:`~clcsg.sampling.samples.Samples` in the format of ``path``'s extension:
    ``.ply`` (binary PLY, double precision unless ``float32``: Open3D, MeshLab, plyfile read it)
    or ``.npz`` (the samples with their tape: :func:`clcsg.load_samples` reads them back,
    ``clcsg render samples.npz`` renders them again)."""
    fmt = check_samples_output(path, None)
    if fmt == "PLY":
        ply.write_samples(samples, path, float32=float32)
    elif float32:
        raise UsageError(f"{path}: float32 applies to PLY output; .npz keeps the samples in double precision")
    else:
        samples_npz.save_samples(samples, path)


def _pil_image(rgba: np.ndarray, fmt: str):
    from PIL import Image as PILImage

    im = PILImage.fromarray(np.ascontiguousarray(rgba, dtype=np.uint8))
    return im.convert("RGB") if fmt in NO_ALPHA else im


def write_image(rgba: np.ndarray, path) -> None:
    """Write an (H, W, 4) uint8 image in the format of ``path``'s extension."""
    p = os.fspath(path)
    fmt = check_image_output(p, None)
    im = _pil_image(rgba, fmt)
    try:
        with atomic_open(p, "wb", "image") as f:
            im.save(f, format=fmt, **_SAVE_OPTIONS.get(fmt, {}))
    except (ValueError, KeyError) as e:
        raise OutputError(f"{p}: cannot write image: {e}") from None


def write_npy(path, array: np.ndarray, what: str = "array") -> None:
    """Write ``array`` as a ``.npy`` file, atomically."""
    with atomic_open(path, "wb", what) as f:
        np.save(f, np.asarray(array), allow_pickle=False)


def write_json(path, obj, what: str = "statistics", **dump_options) -> None:
    """Write ``obj`` as indented JSON (and a final newline), atomically."""
    with atomic_open(path, "w", what) as f:
        json.dump(obj, f, indent=2, **dump_options)
        f.write("\n")


def png_bytes(rgba: np.ndarray) -> bytes:
    """The image as PNG file contents (for Jupyter's ``_repr_png_``)."""
    buf = io.BytesIO()
    _pil_image(rgba, "PNG").save(buf, format="PNG")
    return buf.getvalue()
