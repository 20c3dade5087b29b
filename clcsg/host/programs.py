"""Building the OpenCL programs in ``clcsg/kernels`` (shipped as package data).

Sources are found with importlib.resources, so they work from an installed wheel; the
kernels directory is passed as an include path for the shared headers.  Parameters are
``-D`` build options.  Built programs are cached per (context, file, options, source hash);
pyopencl additionally caches binaries on disk.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.resources
import threading

import numpy as np

_cache: dict = {}
_lock = threading.Lock()
_exit = contextlib.ExitStack()


def kernels_dir() -> str:
    """A real directory holding the kernel sources (extracted if the package is zipped)."""
    res = importlib.resources.files("clcsg") / "kernels"
    return str(_exit.enter_context(importlib.resources.as_file(res)))


def source(name: str) -> str:
    return (importlib.resources.files("clcsg") / "kernels" / name).read_text(encoding="utf-8")


def _headers_hash() -> str:
    h = hashlib.sha256()
    for f in sorted((importlib.resources.files("clcsg") / "kernels").iterdir(), key=lambda p: p.name):
        if f.name.endswith(".h"):
            h.update(f.read_bytes())
    return h.hexdigest()


def real_options(real) -> list[str]:
    return ["-DCLCSG_DOUBLE"] if np.dtype(real) == np.float64 else []


def build(context, name: str, defines: dict | None = None, real=np.float64):
    """The built program ``kernels/<name>`` for ``context`` (cached).

    ``defines`` become ``-DKEY=VALUE`` options; ``real`` selects double or float.
    """
    import pyopencl as cl

    opts = real_options(real) + [f"-D{k}={v}" for k, v in sorted((defines or {}).items())]
    src = source(name)
    key = (id(context.ctx), name, tuple(opts), hashlib.sha256(src.encode()).hexdigest(), _headers_hash())
    with _lock:
        prg = _cache.get(key)
        if prg is None:
            options = opts + ["-I", kernels_dir()]
            prg = cl.Program(context.ctx, src).build(options=options)
            _cache[key] = prg
    return prg
