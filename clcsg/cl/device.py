"""OpenCL device selection, in the style of pyopencl's ``PYOPENCL_CTX``.

A device is named by a *spec*:

==============  =====================================================================
spec            device
==============  =====================================================================
(none)          ``PYOPENCL_CTX`` if set, else the first GPU, else the first CPU
``cpu``         the first CPU device
``gpu``         the first GPU device
``P:D``         device D of platform P (indices as ``clcsg devices`` lists them)
``P``           the first device of platform P
``oclgrind``    the Oclgrind simulator
==============  =====================================================================

``P`` and ``D`` mean what they mean in ``PYOPENCL_CTX``: an index, or else a case-insensitive
substring of the platform / device name (``intel:0``, ``pocl``); an empty part means 0.

Oclgrind (a platform whose name contains "Oclgrind") is a simulator about a thousand times
slower than a real device.  The default, ``cpu`` and ``gpu`` never pick it; only ``oclgrind``,
a ``P:D`` / ``P`` naming it, or ``PYOPENCL_CTX`` pointing at it do.

A device is used only if its compiler builds a one-line kernel and the renderer's 8-wide
vector math (:mod:`.vector_probe`, in a child process).  PoCL's pip wheel, for one, fails on
CPUs newer than its LLVM ("unknown target CPU 'generic'" on AMD Zen 5; "LLVM ERROR: Cannot
select" on a double8's sqrt on Zen 4): the default, ``cpu`` and ``gpu`` then pass over it to
the next device of the rule, and naming it gets that reason.  A
device that built the probe once is remembered in the program cache and not probed again until
its driver changes.

The rule lives in the pure function :func:`choose`, which works on a list of
:class:`DeviceInfo` and a mapping of environment variables, so it can be tested on synthetic
device lists.  Every failure raises :class:`~clcsg.errors.DeviceError` (exit code 4) with a
one-line message.
"""

from __future__ import annotations

import hashlib
import os
import threading
from dataclasses import asdict, dataclass
from typing import Callable, Mapping, Sequence

import numpy as np

from ..errors import DeviceError, UsageError
from .programs import cache_dir
from .vector_probe import SOURCE as VECTOR_SOURCE

__all__ = [
    "Context",
    "DeviceInfo",
    "NO_PLATFORM",
    "choose",
    "choose_usable",
    "default_rule",
    "devices",
    "get_context",
    "list_devices",
    "real_dtype",
    "require_int64_atomics",
    "select_device",
]

NO_PLATFORM = "no OpenCL platform found; install one with: pip install 'clcsg[pocl]'"

#: the spec keywords (anything else is parsed as P:D or P)
KEYWORDS = ("cpu", "gpu", "oclgrind")

VALID_SPECS = "cpu, gpu, oclgrind, P:D or P (see `clcsg devices`)"


@dataclass(frozen=True)
class DeviceInfo:
    """What clcsg needs to know about one OpenCL device (plain data, no OpenCL handles)."""

    platform_index: int
    device_index: int
    platform: str
    name: str
    type: str  # 'cpu', 'gpu', 'accelerator' or 'other'
    compute_units: int
    fp64: bool
    int64_atomics: bool  # cl_khr_int64_base_atomics and cl_khr_int64_extended_atomics
    is_oclgrind: bool
    max_mem_alloc: int  # bytes
    global_mem: int  # bytes

    @property
    def spec(self) -> str:
        """``"P:D"``: the spec that selects exactly this device."""
        return f"{self.platform_index}:{self.device_index}"

    def describe(self) -> str:
        """One line: ``0:0 pthread-Intel(R) ... (cpu, Portable Computing Language)``."""
        return f"{self.spec} {self.name} ({self.type}, {self.platform})"

    def as_dict(self) -> dict:
        d = asdict(self)
        d["spec"] = self.spec
        return d


# -- the selection rule (pure) ----------------------------------------------------------------


def _available(infos: Sequence[DeviceInfo]) -> str:
    return "; ".join(f"{i.spec} {i.name} ({i.type})" for i in infos) or "none"


def default_rule(infos: Sequence[DeviceInfo]) -> int:
    """Index (into ``infos``) of the first GPU, else the first CPU, else the first other device.

    Oclgrind is never chosen.
    """
    if not infos:
        raise DeviceError(NO_PLATFORM)
    real = [k for k, i in enumerate(infos) if not i.is_oclgrind]
    for kind in ("gpu", "cpu"):
        for k in real:
            if infos[k].type == kind:
                return k
    if real:
        return real[0]
    raise DeviceError(
        "only the Oclgrind simulator is available and it is never chosen by default; "
        "select it with --device oclgrind, or install a real device with: pip install 'clcsg[pocl]'"
    )


def _first_of_type(infos: Sequence[DeviceInfo], kind: str) -> int:
    for k, i in enumerate(infos):
        if i.type == kind and not i.is_oclgrind:
            return k
    hint = "; install PoCL with: pip install 'clcsg[pocl]'" if kind == "cpu" else ""
    raise DeviceError(
        f"device {kind!r}: no {kind.upper()} OpenCL device found (available: {_available(infos)}){hint}"
    )


def _match_part(part: str, names: list[tuple[int, str]], what: str, where: str, last: bool):
    """Resolve one part of P:D: an index, else a name substring; returns the index or None."""
    part = part.strip()
    if part == "":
        return names[0][0] if names else None
    try:
        n = int(part)
    except ValueError:
        pass
    else:
        idx = [i for i, _ in names]
        if n in idx:
            return n
        valid = ", ".join(map(str, idx)) or "none"
        raise DeviceError(f"{where}: {what.format(n)} is out of range (valid: {valid}; see `clcsg devices`)")
    hits = [i for i, name in names if part.lower() in name.lower()]
    if not hits:
        return None
    # pyopencl picks the last platform and the first device whose name matches
    return hits[-1] if last else hits[0]


def _parse_pd(infos: Sequence[DeviceInfo], text: str, where: str) -> int:
    """Index into ``infos`` of the device that ``P:D`` / ``P`` in ``text`` names."""
    text = text.split(",")[0]  # PYOPENCL_CTX allows "P:D1,D2"; clcsg uses one device
    parts = text.split(":")
    if len(parts) > 2:
        raise DeviceError(f"{where}: expected P:D or P; valid choices: {VALID_SPECS}")
    platforms: dict[int, str] = {}
    for i in infos:
        platforms.setdefault(i.platform_index, i.platform)
    p = _match_part(parts[0], sorted(platforms.items()), "platform index {}", where, last=True)
    if p is None:
        raise DeviceError(
            f"{where}: no platform matches {parts[0].strip()!r}; valid choices: {VALID_SPECS}; "
            f"platforms: {', '.join(f'{k} {v}' for k, v in sorted(platforms.items()))}"
        )
    on_p = [(k, i) for k, i in enumerate(infos) if i.platform_index == p]
    if len(parts) == 1:
        return on_p[0][0]
    names = [(i.device_index, i.name) for _, i in on_p]
    d = _match_part(parts[1], names, f"device index {{}} on platform {p}", where, last=False)
    if d is None:
        raise DeviceError(
            f"{where}: no device on platform {p} matches {parts[1].strip()!r}; "
            f"devices there: {_available([i for _, i in on_p])}; valid choices: {VALID_SPECS}"
        )
    return next(k for k, i in on_p if i.device_index == d)


def choose(infos: Sequence[DeviceInfo], spec: str | None = None, env: Mapping[str, str] | None = None) -> int:
    """Index into ``infos`` of the device that ``spec`` selects (the rule, without OpenCL).

    ``spec`` is None (default rule), ``cpu``, ``gpu``, ``oclgrind``, ``P:D`` or ``P``.
    ``env`` supplies ``PYOPENCL_CTX`` for the default (an empty value counts as unset).
    Raises :class:`DeviceError`.
    """
    if not infos:
        raise DeviceError(NO_PLATFORM)
    env = {} if env is None else env
    if spec is None or not str(spec).strip():
        ctx = env.get("PYOPENCL_CTX", "").strip()
        if ctx:
            return _parse_pd(infos, ctx, f"PYOPENCL_CTX={ctx!r}")
        return default_rule(infos)
    s = str(spec).strip()
    key = s.lower()
    if key in ("cpu", "gpu"):
        return _first_of_type(infos, key)
    if key == "oclgrind":
        for k, i in enumerate(infos):
            if i.is_oclgrind:
                return k
        raise DeviceError(f"device 'oclgrind': Oclgrind is not installed (available: {_available(infos)})")
    try:
        return _parse_pd(infos, s, f"device {s!r}")
    except DeviceError as e:
        if "no platform matches" in str(e):
            raise DeviceError(
                f"unknown device {s!r}; valid choices: {VALID_SPECS}; available: {_available(infos)}"
            ) from None
        raise


# -- OpenCL enumeration ---------------------------------------------------------------------


def _cl():
    try:
        import pyopencl as cl
    except Exception as e:  # pragma: no cover - broken installation
        raise DeviceError(
            f"cannot import pyopencl ({type(e).__name__}: {e}); install with: pip install 'clcsg[pocl]'"
        ) from e
    return cl


def _type_name(t: int, cl) -> str:
    dt = cl.device_type
    if t & dt.GPU:
        return "gpu"
    if t & dt.CPU:
        return "cpu"
    if t & dt.ACCELERATOR:
        return "accelerator"
    return "other"


def _info(p_idx: int, platform, d_idx: int, dev, cl) -> DeviceInfo:
    ext = set(dev.extensions.split())
    try:
        dfp = int(dev.double_fp_config)
    except Exception:
        dfp = 0
    return DeviceInfo(
        platform_index=p_idx,
        device_index=d_idx,
        platform=platform.name.strip(),
        name=dev.name.strip(),
        type=_type_name(int(dev.type), cl),
        compute_units=int(dev.max_compute_units),
        fp64=("cl_khr_fp64" in ext) or dfp != 0,
        int64_atomics={"cl_khr_int64_base_atomics", "cl_khr_int64_extended_atomics"} <= ext,
        is_oclgrind="oclgrind" in platform.name.lower(),
        max_mem_alloc=int(dev.max_mem_alloc_size),
        global_mem=int(dev.global_mem_size),
    )


def _enumerate() -> list[tuple[DeviceInfo, object]]:
    """Every (DeviceInfo, pyopencl.Device), in PYOPENCL_CTX order."""
    cl = _cl()
    try:
        platforms = cl.get_platforms()
    except (cl.Error, RuntimeError) as e:
        if "PLATFORM_NOT_FOUND" in str(e) or "no CL platforms" in str(e):
            raise DeviceError(NO_PLATFORM) from None
        first = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise DeviceError(f"cannot list OpenCL platforms: {first}") from None
    if not platforms:
        raise DeviceError(NO_PLATFORM)
    out = []
    for p_idx, platform in enumerate(platforms):
        try:
            devs = platform.get_devices()
        except (cl.Error, RuntimeError):  # DEVICE_NOT_FOUND: a platform without devices
            continue
        for d_idx, dev in enumerate(devs):
            out.append((_info(p_idx, platform, d_idx, dev, cl), dev))
    if not out:
        raise DeviceError(f"OpenCL platforms found ({', '.join(p.name for p in platforms)}) but no devices; "
                          "install one with: pip install 'clcsg[pocl]'")
    return out


def list_devices() -> list[DeviceInfo]:
    """Every OpenCL device, in ``P:D`` order.  Raises :class:`DeviceError` if there is none."""
    return [info for info, _ in _enumerate()]


#: ``clcsg.devices()``
devices = list_devices


#: built once per device to learn whether its compiler works
PROBE_SOURCE = "__kernel void clcsg_probe(__global int *out) { out[get_global_id(0)] = 1; }"

#: what to do when no device compiles (the message's tail)
NO_COMPILER_HINT = ("PoCL's pip wheel cannot compile for CPUs newer than its LLVM; install Debian's "
                    "pocl-opencl-icd (apt-get install pocl-opencl-icd) or another OpenCL runtime")

_probe_results: dict = {}
_probe_contexts: dict = {}


def _probe_mark(dev) -> str | None:
    """The file that records that ``dev`` built :data:`PROBE_SOURCE` and ran the vector probe:
    in the program cache (:func:`~clcsg.cl.programs.cache_dir`), named by the hash of the probes
    and of the device's and driver's names and versions, so a new driver or device probes again.  None when the
    disk cache is off."""
    folder = cache_dir()
    if folder is None:
        return None
    p = dev.platform
    ident = repr((PROBE_SOURCE, VECTOR_SOURCE, dev.name, dev.version, dev.driver_version, p.name, p.version))
    return os.path.join(folder, "probe-" + hashlib.sha256(ident.encode()).hexdigest() + ".ok")


def _remember_probe(mark: str) -> None:
    try:
        os.makedirs(os.path.dirname(mark), exist_ok=True)
        with open(mark, "w", encoding="utf-8") as f:
            f.write(PROBE_SOURCE + "\n")
    except OSError:  # a cache that cannot be written only costs the next process a probe
        pass


def _build_error(dev) -> str | None:
    """None if ``dev`` builds :data:`PROBE_SOURCE`, else the first error line of its compiler
    (remembered per device for the process; the probe's context is kept for :class:`Context`).

    A success is also remembered on disk (:func:`_probe_mark`): the build takes a few tens of
    milliseconds, as long as the rest of a small ``clcsg sample``'s start, and the answer only
    changes with the driver.  A failure is probed again in each process."""
    key = int(dev.int_ptr)
    if key not in _probe_results:
        mark = _probe_mark(dev)
        if mark is not None and os.path.exists(mark):
            _probe_results[key] = None
            return None
        cl = _cl()
        try:
            ctx = cl.Context([dev])
            cl.Program(ctx, PROBE_SOURCE).build()
            error = None if "oclgrind" in dev.platform.name.lower() else _vector_error(dev)
            _probe_results[key] = error
            if error is None:
                _probe_contexts[key] = ctx
                if mark is not None:
                    _remember_probe(mark)
        except (cl.Error, RuntimeError) as e:
            lines = [ln.strip() for ln in str(e).splitlines() if ln.strip()]
            errors = [ln for ln in lines if ln.lower().startswith("error")]
            _probe_results[key] = (errors or lines or [type(e).__name__])[0]
    return _probe_results[key]


#: seconds the 8-wide vector probe's child may take (a build on a slow, busy machine)
VECTOR_PROBE_TIMEOUT = 300


def _vector_error(dev) -> str | None:
    """None if ``dev`` builds and runs the renderer's 8-wide vector math
    (:mod:`.vector_probe`, in a child process: the failure it finds aborts its process), else
    the reason in one line."""
    p_idx = next(k for k, p in enumerate(_cl().get_platforms()) if p.int_ptr == dev.platform.int_ptr)
    d_idx = next(k for k, d in enumerate(dev.platform.get_devices()) if d.int_ptr == dev.int_ptr)
    return vector_probe_error(p_idx, d_idx)


def vector_probe_error(platform_index: int, device_index: int) -> str | None:
    """:func:`_vector_error` of the device at (platform, device) index."""
    import subprocess
    import sys

    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([root] + [p for p in [os.environ.get("PYTHONPATH")] if p]))
    try:
        r = subprocess.run([sys.executable, "-m", "clcsg.cl.vector_probe", str(platform_index), str(device_index)],
                           capture_output=True, text=True, timeout=VECTOR_PROBE_TIMEOUT, env=env)
    except subprocess.TimeoutExpired:
        return f"its compiler took over {VECTOR_PROBE_TIMEOUT} s on 8-wide vector math"
    if r.returncode == 0 and r.stdout.startswith("ok"):
        return None
    lines = [ln.strip() for ln in (r.stderr + r.stdout).splitlines() if ln.strip()]
    why = [ln for ln in lines if "LLVM ERROR" in ln or ln.lower().startswith("error")] or lines[-1:] or [f"exit code {r.returncode}"]
    return f"its compiler fails on 8-wide vector math ({why[0]})"


def _by_rule(spec: str | None, env: Mapping[str, str]) -> bool:
    """True if ``spec`` picks a device by rule (default, ``cpu``, ``gpu``), not by name."""
    if spec is None or not str(spec).strip():
        return not env.get("PYOPENCL_CTX", "").strip()
    return str(spec).strip().lower() in ("cpu", "gpu")


def choose_usable(infos: Sequence[DeviceInfo], spec: str | None, env: Mapping[str, str],
                  build_error: Callable[[int], str | None]) -> int:
    """Index into ``infos`` of the device ``spec`` selects whose compiler works.

    ``build_error(k)`` is None if device ``k`` compiles, else the reason.  A choice by rule
    (default, ``cpu``, ``gpu``) passes over devices that do not compile, in the rule's order; a
    device named by ``P:D`` / ``PYOPENCL_CTX`` is used or refused, never replaced.  Raises
    :class:`DeviceError` naming every device tried and why it failed.
    """
    left = list(range(len(infos)))
    failures = []
    while left:
        try:
            pick = choose([infos[j] for j in left], spec, env)
        except DeviceError:
            if not failures:
                raise
            break
        k = left[pick]
        error = build_error(k)
        if error is None:
            return k
        failures.append(f"{infos[k].describe()}: {error}")
        if not _by_rule(spec, env):
            break
        left.remove(k)
    raise DeviceError(f"no usable OpenCL device: {'; '.join(failures)}; {NO_COMPILER_HINT}")


def _select(spec: str | None):
    found = _enumerate()
    k = choose_usable([i for i, _ in found], spec, os.environ, lambda j: _build_error(found[j][1]))
    return found[k]


def select_device(spec: str | None = None):
    """The ``pyopencl.Device`` that ``spec`` names (see the module docstring)."""
    return _select(spec)[1]


# -- contexts ---------------------------------------------------------------------------------


class Context:
    """An OpenCL context and profiling command queue on one device."""

    def __init__(self, device, info: DeviceInfo):
        cl = _cl()
        self.device = device
        self.info = info
        try:
            self.ctx = _probe_contexts.pop(int(device.int_ptr), None) or cl.Context([device])
            self.queue = cl.CommandQueue(
                self.ctx, device, properties=cl.command_queue_properties.PROFILING_ENABLE
            )
        except cl.Error as e:
            raise DeviceError(f"cannot create an OpenCL context on {info.describe()}: {e}") from None

    @property
    def real_dtype(self):
        return real_dtype(self)

    def __repr__(self) -> str:
        return f"<clcsg Context {self.info.describe()}>"


_contexts: dict = {}
_lock = threading.Lock()


#: the context each (spec, PYOPENCL_CTX) selected: listing the platforms and devices again
#: on every call cost about 0.15 ms, a tenth of a small scene's host work per sampling call
_selected: dict = {}


def get_context(spec: str | None = None) -> Context:
    """The :class:`Context` of the device ``spec`` selects; one per device, reused."""
    chosen = (spec, os.environ.get("PYOPENCL_CTX", ""))
    c = _selected.get(chosen)
    if c is not None:
        return c
    info, dev = _select(spec)
    key = (info.platform_index, info.device_index, info.name)
    with _lock:
        c = _contexts.get(key)
        if c is None:
            c = _contexts[key] = Context(dev, info)
        _selected[chosen] = c
        return c


def _info_of(context) -> DeviceInfo:
    if isinstance(context, DeviceInfo):
        return context
    return context.info


def require_int64_atomics(context, what: str) -> None:
    """Raise :class:`DeviceError` unless the device has 64-bit integer atomics."""
    info = _info_of(context)
    if not info.int64_atomics:
        raise DeviceError(
            f"device {info.describe()} lacks cl_khr_int64_extended_atomics, needed by {what} "
            "(pick another with --device; see `clcsg devices`)"
        )


def real_dtype(context):
    """``numpy.float64`` if the device has fp64, else ``numpy.float32``.

    ``CLCSG_PRECISION=float`` forces float32 (to test the path GPUs without fp64 take)."""
    forced = os.environ.get("CLCSG_PRECISION", "").strip().lower()
    if forced in ("float", "float32", "single"):
        return np.float32
    return np.float64 if _info_of(context).fp64 else np.float32


def context_of(device):
    """A clcsg Context from None / a device spec string / a Context."""
    if device is None or isinstance(device, str):
        return get_context(device)
    if hasattr(device, "ctx") and hasattr(device, "queue"):
        return device
    raise UsageError(f"device must be a device spec string or a clcsg Context, got {type(device).__name__}")


def choose_real(context, precision="auto"):
    """numpy float type for the kernels: 'auto' (double where the device has fp64, unless
    CLCSG_PRECISION=float forces float32; see device.real_dtype), 'double', 'float'."""
    if precision in (None, "auto"):
        return np.dtype(real_dtype(context))
    if precision in ("double", "float64", np.float64):
        if not context.info.fp64:
            raise DeviceError(f"device {context.info.describe()} has no fp64 (cl_khr_fp64); use precision='float'")
        return np.dtype(np.float64)
    if precision in ("float", "float32", np.float32):
        return np.dtype(np.float32)
    raise UsageError(f"precision must be 'auto', 'double' or 'float', got {precision!r}")
