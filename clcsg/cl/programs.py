"""Building the OpenCL programs shipped in the package.

A program is named by its path inside the package (``"sampling/sampler.cl"``), so each kernel
sits next to the module that drives it.  Sources are read from the package's folder
(through importlib.resources where the package is zipped); ``cl/include`` (headers shared by every stage) and the source's own
folder are the include path.  Parameters are ``-D`` build options, and the constants that host
and kernels share (:mod:`clcsg.cl.constants`) are passed as build options too, so they have one
source.  Built programs are cached per (context, path, options, hash of the sources) in the
process, and their binaries on disk across processes (:func:`cache_dir`: loading a binary
takes about a hundredth of a second where a build from source, even one the driver's own
cache answers, takes several), so a second ``clcsg sample`` builds nothing.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import platform
import tempfile
import threading
import time

import numpy as np

from .constants import defines as shared

_cache: dict = {}
_lock = threading.Lock()
_builds = 0
_exit = contextlib.ExitStack()


#: the clcsg package's folder
_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@functools.lru_cache(maxsize=None)
def package_dir(sub: str) -> str:
    """A real directory for package folder ``sub``: in the package's folder (as pip installs
    it), else extracted through importlib.resources (a zipped package)."""
    d = os.path.join(_ROOT, *sub.split("/"))
    if os.path.isdir(d):
        return d
    import importlib.resources

    res = importlib.resources.files("clcsg").joinpath(*sub.split("/"))
    return str(_exit.enter_context(importlib.resources.as_file(res)))


def source(path: str) -> str:
    folder, name = path.rpartition("/")[::2]
    with open(os.path.join(package_dir(folder) if folder else _ROOT, name), encoding="utf-8") as f:
        return f.read()


def _headers_hash(folders) -> str:
    h = hashlib.sha256()
    for folder in folders:
        d = package_dir(folder)
        for name in sorted(os.listdir(d)):
            if name.endswith(".h"):
                with open(os.path.join(d, name), "rb") as f:
                    h.update(f.read())
    return h.hexdigest()


def _stamp(folders) -> tuple:
    """(name, mtime, size) of the headers in ``folders``: a cheap check that they are unchanged."""
    out = []
    for folder in folders:
        d = package_dir(folder)
        for name in sorted(os.listdir(d)):
            if name.endswith(".h"):
                st = os.stat(os.path.join(d, name))
                out.append((folder, name, st.st_mtime_ns, st.st_size))
    return tuple(out)


_hashed: dict = {}


def _source_and_hashes(path: str, folder: str) -> tuple[str, str, str]:
    """(source, its hash, the hash of the headers it may include), re-read only when a file's
    modification time or size changed (a sampling call builds two programs; hashing every
    header each time cost about a millisecond)."""
    src_file = os.path.join(package_dir(folder), path.rpartition("/")[2])
    st = os.stat(src_file)
    stamp = (st.st_mtime_ns, st.st_size, _stamp(("cl/include", folder)))
    hit = _hashed.get(path)
    if hit is not None and hit[0] == stamp:
        return hit[1]
    src = source(path)
    out = (src, hashlib.sha256(src.encode()).hexdigest(), _headers_hash(["cl/include", folder]))
    _hashed[path] = (stamp, out)
    return out


def real_options(real) -> list[str]:
    return ["-DCLCSG_DOUBLE"] if np.dtype(real) == np.float64 else []


def build_options(defines: dict | None = None, real=np.float64) -> list[str]:
    """``-D`` options: precision, the shared constants, then ``defines``."""
    merged = {**shared(), **(defines or {})}
    return real_options(real) + [f"-D{k}={v}" for k, v in sorted(merged.items())]


def cache_dir() -> str | None:
    """Where program binaries are kept: ``$CLCSG_CACHE_DIR``, else ``clcsg/programs`` in
    ``$XDG_CACHE_HOME`` (default ``~/.cache``); None (no disk cache) if ``$CLCSG_NO_CACHE`` is
    set."""
    if os.environ.get("CLCSG_NO_CACHE"):
        return None
    root = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.environ.get("CLCSG_CACHE_DIR") or os.path.join(root, "clcsg", "programs")


def _binary_path(context, key) -> str | None:
    """The cache file of a program: named by the hash of its key and of the device and driver
    (a new driver or device never loads an old binary).  None for Oclgrind: the simulator is
    there to check the kernels, and pyopencl's build of a program from binaries makes an API
    call (a kernel lookup) that Oclgrind reports as an error."""
    folder = cache_dir()
    devices = context.ctx.devices
    if folder is None or len(devices) != 1 or "oclgrind" in devices[0].platform.name.lower():
        return None
    d = devices[0]
    ident = repr((key[1:], d.name, d.version, d.driver_version, d.platform.name, d.platform.version))
    return os.path.join(folder, hashlib.sha256(ident.encode()).hexdigest() + ".bin")


def _from_binary(cl, context, binary_path, options):
    """The program built from its cached binary, or None (no file, or the driver refused it)."""
    try:
        with open(binary_path, "rb") as f:
            binary = f.read()
        return cl.Program(context.ctx, list(context.ctx.devices), [binary]).build(options=options)
    except (OSError, cl.Error):
        return None


def _store_binary(cl, prg, binary_path) -> None:
    """Write the program's binary atomically; a cache that cannot be written is skipped."""
    try:
        (binary,) = prg.get_info(cl.program_info.BINARIES)
        os.makedirs(os.path.dirname(binary_path), exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=os.path.dirname(binary_path), suffix=".tmp")
        with os.fdopen(fd, "wb") as f:
            f.write(binary)
        os.replace(tmp, binary_path)
    except (OSError, ValueError, cl.Error):
        pass


#: wrapped around every source built for PoCL's CPU device on x86-64.  PoCL's distributed
#: kernel library (sqrt, fmin, dot, length, atomics, ...) is compiled for a generic CPU whose
#: target features include ``clwb``; on a host whose detected CPU lacks that flag in LLVM's
#: table (a Rocket Lake, for one) LLVM refuses to inline any builtin into the kernel (a callee
#: may not use features its caller lacks), so every fmin became a call.  Giving our functions
#: the feature makes the builtins inlinable again (sampling the zoo: 1.24-1.3x less CPU); it
#: only enables an instruction set flag, it does not emit any instruction.  ``#line 1`` keeps
#: the compiler's line numbers those of the file.
POCL_CPU_PRELUDE = ('#pragma clang attribute push (__attribute__((target("clwb"))), apply_to = function)\n'
                    "#line 1\n")
POCL_CPU_POSTLUDE = "\n#pragma clang attribute pop\n"


def _wrapped(context, src: str) -> str:
    """``src`` as built for ``context``'s device (:data:`POCL_CPU_PRELUDE` on PoCL's x86-64 CPU
    device)."""
    devices = context.ctx.devices
    if len(devices) != 1:
        return src
    d = devices[0]
    import pyopencl as cl

    pocl = "portable computing language" in d.platform.name.lower()
    x86 = platform.machine().lower() in ("x86_64", "amd64")
    if pocl and x86 and d.type & cl.device_type.CPU:
        return POCL_CPU_PRELUDE + src + POCL_CPU_POSTLUDE
    return src


_wrapped_hashes: dict = {}


def _wrapped_hash(wrapped: str, src_hash: str) -> str:
    """The hash of a wrapped source, computed once per source hash (hashing the whole
    wrapped text on every build call cost a few tenths of a millisecond)."""
    h = _wrapped_hashes.get(src_hash)
    if h is None:
        h = _wrapped_hashes[src_hash] = hashlib.sha256(wrapped.encode()).hexdigest()
    return h


#: programs that Oclgrind (21.10) gets unoptimized: its interpreter has no implementation of the
#: scope intrinsic that LLVM's inliner emits into the splat kernel ("Undefined external
#: function: llvm.experimental.noalias.scope.decl").  Only there: unoptimized, the 3-vectors'
#: unused fourth lanes show up in its uninitialized-value checks.
OCLGRIND_UNOPTIMIZED = {"rendering/splat.cl": ["-cl-opt-disable"]}


def _device_options(context, path: str) -> list[str]:
    """Build options of program ``path`` on ``context``'s device beyond the shared ones
    (on Oclgrind ``CLCSG_PLAIN_INLINE=1``, see ``cl/include/layout.h``, and
    :data:`OCLGRIND_UNOPTIMIZED`; on PoCL's CPU devices ``CLCSG_PREFETCH=1``, where the
    kernels ask for memory ahead with clang's ``__builtin_prefetch``: OpenCL's ``prefetch()``
    does nothing there, and ``CLCSG_STREAM_STORES=1``, where the image outputs are written with
    clang's ``__builtin_nontemporal_store``)."""
    import pyopencl as cl

    devices = context.ctx.devices
    if any("oclgrind" in d.platform.name.lower() for d in devices):
        return ["-DCLCSG_PLAIN_INLINE=1"] + list(OCLGRIND_UNOPTIMIZED.get(path, []))
    if all("portable computing language" in d.platform.name.lower() and d.type & cl.device_type.CPU
           for d in devices):
        return ["-DCLCSG_PREFETCH=1", "-DCLCSG_STREAM_STORES=1"]
    return []


#: how long a program found by :func:`build` is handed out again without checking its sources'
#: modification times (a sampling call builds two programs; the check lists and stats the
#: header folders, about 0.2 ms a call); an edited kernel is picked up after at most this long
RECHECK_SECONDS = 1.0
_recent: dict = {}


def build(context, path: str, defines: dict | None = None, real=np.float64):
    """The built program at package path ``path`` for ``context`` (cached in the process and,
    as a binary, on disk).

    ``defines`` become ``-DKEY=VALUE`` options; ``real`` selects double or float.
    """
    global _builds
    import pyopencl as cl

    recent_key = (id(context.ctx), path, tuple(sorted((defines or {}).items())), np.dtype(real).str)
    recent = _recent.get(recent_key)
    now = time.monotonic()
    if recent is not None and now - recent[1] < RECHECK_SECONDS:
        return recent[0]
    opts = build_options(defines, real) + _device_options(context, path)
    folder = path.rpartition("/")[0]
    src, src_hash, headers = _source_and_hashes(path, folder)
    wrapped = _wrapped(context, src)
    if wrapped is not src:
        src, src_hash = wrapped, _wrapped_hash(wrapped, src_hash)
    key = (id(context.ctx), path, tuple(opts), src_hash, headers)
    with _lock:
        prg = _cache.get(key)
        if prg is None:
            options = opts + ["-I", package_dir("cl/include"), "-I", package_dir(folder)]
            binary_path = _binary_path(context, key)
            prg = None if binary_path is None else _from_binary(cl, context, binary_path, options)
            if prg is None:
                prg = cl.Program(context.ctx, src).build(options=options)
                if binary_path is not None:
                    _store_binary(cl, prg, binary_path)
            _cache[key] = prg
            _builds += 1
        _recent[recent_key] = (prg, now)
    return prg


def builds() -> int:
    """How many programs this process has built or loaded from the disk cache so far: work
    during which it grew paid a one-off cost (a build, a kernel's first launch) that a timing
    meant to predict the next run must leave out."""
    return _builds


_kernels: dict = {}


def kernel(prg, name: str):
    """The kernel ``name`` of a built program, retrieved once per program."""
    import pyopencl as cl

    key = (id(prg), name)
    k = _kernels.get(key)
    if k is None or k[0] is not prg:
        k = _kernels[key] = (prg, cl.Kernel(prg, name))
    return k[1]


def launch(knl, queue, global_size, local_size, *args, wait_for=None):
    """Enqueue ``knl`` on ``args`` (buffers and numpy scalars).  The scalars' dtypes are
    declared to pyopencl once per kernel and argument signature, so it packs them directly:
    undeclared, it tries a chain of casts on every argument of every launch, each failed one a
    C++ exception (about 40 us of CPU per launch of a 17-argument kernel on PoCL)."""
    types = tuple(map(type, args))
    if getattr(knl, "_clcsg_types", None) != types:
        knl.set_scalar_arg_dtypes([np.dtype(t) if issubclass(t, np.generic) else None for t in types])
        knl._clcsg_types = types
    return knl(queue, global_size, local_size, *args, wait_for=wait_for)


def relaunch(knl, queue, global_size, local_size, changed: dict, wait_for=None):
    """Enqueue ``knl`` again with the arguments of its last launch (:func:`launch`) but those
    in ``changed`` ({index: buffer or numpy scalar}): a chain of levels swaps a few buffers and
    counts its rows, and setting its 30-odd arguments anew cost about 20 us per launch.  The
    arguments stay set on the kernel object, so a kernel shared by threads needs the same care
    as with :func:`launch` (pyopencl's call sets and enqueues in two steps as well).  A numpy
    scalar goes in by its bytes, as pyopencl's own call passes it (``set_arg`` tries a chain
    of conversions first: 12 us per scalar)."""
    import pyopencl as cl

    by_bytes = getattr(knl, "_set_arg_buf", knl.set_arg)
    for i, value in changed.items():
        (by_bytes if isinstance(value, np.generic) else knl.set_arg)(i, value)
    return cl.enqueue_nd_range_kernel(queue, knl, global_size, local_size, wait_for=wait_for)


def event_seconds(ev) -> float:
    try:
        return (ev.profile.end - ev.profile.start) * 1e-9
    except Exception:  # queue without profiling
        return float("nan")
