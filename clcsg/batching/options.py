"""What a batch does to every scene (:class:`Options`, with its radius rule
:class:`~clcsg.sampling.radius.Radius`) and the check for the optional dependencies (pyarrow,
dask)."""

from __future__ import annotations

import hashlib
import importlib
import json
from dataclasses import asdict, dataclass, replace

import numpy as np

from ..errors import UsageError
from ..sampling.radius import Radius

#: output formats of the samples: name -> file extension
FORMATS = {"parquet": ".parquet", "ply": ".ply"}

#: bump when the outputs of the same scene and options change: old outputs are then redone
OUTPUT_VERSION = 1


class DependencyError(UsageError):
    """An optional dependency (the ``batch`` extra) is not installed."""


def require(module: str, what: str):
    """Import ``module`` or raise :class:`DependencyError` naming the extra that installs it."""
    try:
        return importlib.import_module(module)
    except ImportError:
        raise DependencyError(f"{what} needs the Python package {module.split('.')[0]!r}; "
                              "install it with: pip install 'clcsg[batch]'") from None


@dataclass(frozen=True)
class Options:
    """Per scene: sample at ``radius`` (``normal_form``, ``floor``, ``max_samples`` as in
    :func:`clcsg.sample`), write the samples as ``fmt`` (``parquet`` or ``ply``) and render
    ``views`` images of ``size`` (width, height) on orbit cameras; with ``points`` ((N, 3)
    world points, the same for every scene) or ``random_points`` (N points drawn uniformly in
    each scene's bound grown by 5% of its diagonal on every side, seeded by the scene text's
    digest: the same scene gets the same points) also occupancy and the conservative signed
    distance there (:mod:`clcsg.queries`); ``device`` is the OpenCL device spec of every
    worker (None: each worker's own default, e.g. its ``PYOPENCL_CTX``)."""

    radius: Radius
    fmt: str = "parquet"
    views: int = 0
    size: tuple = (640, 480)
    normal_form: str = "tree"
    floor: float | None = None
    max_samples: int | None = None
    device: str | None = None
    points: object = None
    random_points: int = 0

    def __post_init__(self):
        if self.points is not None:
            object.__setattr__(self, "points", _points(self.points))
        if int(self.random_points) < 0:
            raise UsageError(f"random points must be >= 0, got {self.random_points}")
        if self.fmt not in FORMATS:
            raise UsageError(f"format must be one of {', '.join(FORMATS)}, got {self.fmt!r}")
        if int(self.views) < 0:
            raise UsageError(f"views must be >= 0, got {self.views}")
        if self.normal_form not in ("tree", "dnf"):
            raise UsageError(f"normal form must be 'tree' or 'dnf', got {self.normal_form!r}")
        w, h = self.size
        if int(w) <= 0 or int(h) <= 0:
            raise UsageError(f"image size must be positive, got {w}x{h}")

    def key(self) -> str:
        """What decides the outputs (not the device), as canonical JSON for content hashes."""
        d = asdict(replace(self, points=None))
        d.pop("device")
        d["points"] = None if self.points is None else hashlib.sha256(self.points.tobytes()).hexdigest()
        d["radius"] = [self.radius.value, self.radius.relative]
        d["size"] = list(self.size)
        d["version"] = OUTPUT_VERSION
        return json.dumps(d, sort_keys=True)

    @property
    def queries(self) -> bool:
        """Does every scene get point queries?"""
        return self.points is not None or self.random_points > 0

    def content_hash(self, scene_digest: str, dependencies=()) -> str:
        """sha256 of the scene text's digest, the files it reads (``dependencies``: a
        ``.scad`` program's includes and uses, each (path, sha256 of its contents)), the clcsg
        version and :meth:`key`: equal hashes, equal outputs."""
        from .. import __version__

        deps = "".join(f"{path}\0{digest}\n" for path, digest in dependencies)
        text = f"{scene_digest}\n{deps}clcsg {__version__}\n{self.key()}"
        return hashlib.sha256(text.encode()).hexdigest()


def file_digests(paths) -> list[tuple[str, str]]:
    """(path, sha256 of its contents) of every file; a file that cannot be read has the
    digest ``missing`` (so its scene is not complete any more)."""
    out = []
    for path in paths:
        try:
            with open(path, "rb") as f:
                out.append((path, hashlib.file_digest(f, "sha256").hexdigest()))
        except OSError:
            out.append((path, "missing"))
    return out


def _points(points) -> np.ndarray:
    """Query points: an (N, 3) array or a ``.npy`` file holding one."""
    import os

    if isinstance(points, (str, os.PathLike)):
        try:
            points = np.load(os.fspath(points), allow_pickle=False)
        except (OSError, ValueError) as e:
            raise UsageError(f"points: cannot read {os.fspath(points)!r} as a .npy array: {e}") from None
    try:
        p = np.ascontiguousarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        raise UsageError("points must be an (N, 3) array of numbers") from None
    if p.ndim != 2 or p.shape[1] != 3 or not np.isfinite(p).all():
        raise UsageError(f"points must be a finite (N, 3) array, got shape {p.shape}")
    return p
