"""The memory a reader will need, checked against the machine's before it starts.

Reading a scene builds Python objects worth a multiple of the file's size.  Both readers
stream (the file is read a chunk or a JSON event at a time and the model built as it goes), so
the peak is the model plus small buffers: measured on generated files of 0.5 to 50 MB
(``python -m bench load``: ``tracemalloc`` and ``resource.getrusage``), an OpenSCAD ``.csg``
export peaks at 3 to 6.5 times its size and a ``.json`` scene at 4 to 9 times; the factors
below are those bounds, rounded up.  A ``.json`` text read whole (a string, or a file with an
error, read again to report it in document order) costs :data:`WHOLE_JSON_FACTOR`.  :func:`check_input` raises a one-line :class:`~clcsg.errors.LimitError` (exit code
5, like the sampler's resource guard) when that estimate passes the memory available now
(``MemAvailable`` of ``/proc/meminfo``; no check where it is unknown), before a byte is
parsed, instead of the machine swapping or the out-of-memory killer ending the process.
"""

from __future__ import annotations

import os

from ..errors import LimitError

#: peak bytes of memory per byte of a .csg file while it is read into a Scene
CSG_FACTOR = 10
#: peak bytes of memory per byte of a .json scene file while it is read into a Scene
JSON_FACTOR = 10
#: the same for a .json scene read whole (``loads_json`` on a string, or a file with an error,
#: read again to report its first error in document order)
WHOLE_JSON_FACTOR = 50


def available_memory() -> float:
    """Bytes of memory available to this process now (inf where unknown)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return float("inf")


def _size(n: float) -> str:
    for unit in ("bytes", "KiB", "MiB", "GiB", "TiB"):
        if n < 1024 or unit == "TiB":
            return f"{n:.0f} {unit}" if unit == "bytes" else f"{n:.3g} {unit}"
        n /= 1024.0
    return f"{n:.3g} TiB"  # pragma: no cover


def check_input(source: str, nbytes: int, factor: float, available: float | None = None) -> None:
    """LimitError if reading ``nbytes`` of input at ``factor`` bytes of memory per byte would
    pass the memory ``available`` (default: :func:`available_memory`)."""
    need = float(nbytes) * factor
    have = available_memory() if available is None else float(available)
    if need > have:
        raise LimitError(f"{source}: reading this {_size(nbytes)} file needs about {_size(need)} of memory, "
                         f"more than the {_size(have)} available; free memory, use a machine with more, "
                         "or split the model")


def check_file(path: str, factor: float) -> None:
    """:func:`check_input` for the file at ``path`` (nothing if it cannot be stat'ed: the
    reader reports that)."""
    try:
        size = os.path.getsize(path)
    except OSError:
        return
    check_input(path, size, factor)
