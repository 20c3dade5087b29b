"""Building the OpenCL programs shipped in the package.

A program is named by its path inside the package (``"sampling/sampler.cl"``), so each kernel
sits next to the module that drives it.  Sources are read with importlib.resources (they work
from an installed wheel); ``cl/include`` (headers shared by every stage) and the source's own
folder are the include path.  Parameters are ``-D`` build options, and the constants that host
and kernels share (:mod:`clcsg.cl.constants`) are passed as build options too, so they have one
source.  Built programs are cached per (context, path, options, hash of the sources);
pyopencl also caches binaries on disk.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.resources
import threading

import numpy as np
from .constants import defines as shared

_cache: dict = {}
_lock = threading.Lock()
_exit = contextlib.ExitStack()


def package_dir(sub: str) -> str:
    """A real directory for package folder ``sub`` (extracted if the package is zipped)."""
    res = importlib.resources.files("clcsg").joinpath(*sub.split("/"))
    return str(_exit.enter_context(importlib.resources.as_file(res)))


def source(path: str) -> str:
    return importlib.resources.files("clcsg").joinpath(*path.split("/")).read_text(encoding="utf-8")


def _headers_hash(folders) -> str:
    h = hashlib.sha256()
    for folder in folders:
        d = importlib.resources.files("clcsg").joinpath(*folder.split("/"))
        for f in sorted(d.iterdir(), key=lambda p: p.name):
            if f.name.endswith(".h"):
                h.update(f.read_bytes())
    return h.hexdigest()


def real_options(real) -> list[str]:
    return ["-DCLCSG_DOUBLE"] if np.dtype(real) == np.float64 else []


def build_options(defines: dict | None = None, real=np.float64) -> list[str]:
    """``-D`` options: precision, the shared constants, then ``defines``."""
    merged = {**shared(), **(defines or {})}
    return real_options(real) + [f"-D{k}={v}" for k, v in sorted(merged.items())]


def build(context, path: str, defines: dict | None = None, real=np.float64):
    """The built program at package path ``path`` for ``context`` (cached).

    ``defines`` become ``-DKEY=VALUE`` options; ``real`` selects double or float.
    """
    import pyopencl as cl

    opts = build_options(defines, real)
    src = source(path)
    folder = path.rpartition("/")[0]
    key = (id(context.ctx), path, tuple(opts), hashlib.sha256(src.encode()).hexdigest(),
           _headers_hash(["cl/include", folder]))
    with _lock:
        prg = _cache.get(key)
        if prg is None:
            options = opts + ["-I", package_dir("cl/include"), "-I", package_dir(folder)]
            prg = cl.Program(context.ctx, src).build(options=options)
            _cache[key] = prg
    return prg


_kernels: dict = {}


def kernel(prg, name: str):
    """The kernel ``name`` of a built program, retrieved once per program."""
    import pyopencl as cl

    key = (id(prg), name)
    k = _kernels.get(key)
    if k is None or k[0] is not prg:
        k = _kernels[key] = (prg, cl.Kernel(prg, name))
    return k[1]


def event_seconds(ev) -> float:
    try:
        return (ev.profile.end - ev.profile.start) * 1e-9
    except Exception:  # queue without profiling
        return float("nan")
