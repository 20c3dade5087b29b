"""Device buffers, each checked against the device's limits before it is created.

A buffer larger than the device's ``max_mem_alloc_size`` or its global memory would fail in the
driver (``INVALID_BUFFER_SIZE``, ``MEM_OBJECT_ALLOCATION_FAILURE``) or, worse, later in a kernel;
:func:`check_allocation` refuses it first with a :class:`~clcsg.errors.LimitError` that names the
buffer and the limit, which the CLI prints as one line.
"""

from __future__ import annotations

import numpy as np

from ..errors import LimitError


def check_allocation(context, nbytes: int, what: str, hint: str = "use a larger radius") -> None:
    """Refuse a ``what`` buffer of ``nbytes`` that ``context``'s device cannot allocate."""
    info = context.info
    if nbytes > info.max_mem_alloc or nbytes > info.global_mem:
        raise LimitError(
            f"a {what} buffer of {nbytes / 2**20:.1f} MiB is more than {info.describe()} can allocate "
            f"({info.max_mem_alloc / 2**20:.0f} MiB per buffer, {info.global_mem / 2**20:.0f} MiB in all); {hint}"
        )


def device_buffer(context, nbytes: int, what: str, writable: bool = True, hint: str = "use a larger radius"):
    """An uninitialized device buffer of ``nbytes`` (at least 16), checked first."""
    import pyopencl as cl

    check_allocation(context, nbytes, what, hint)
    flags = cl.mem_flags.READ_WRITE if writable else cl.mem_flags.WRITE_ONLY
    return cl.Buffer(context.ctx, flags, max(int(nbytes), 16))


def upload(context, array, writable=False, what: str = "input"):
    """A device buffer initialized from ``array`` (a one-element dummy if it is empty: zero-size
    buffers are not allowed), checked first."""
    import pyopencl as cl

    mf = cl.mem_flags
    a = np.ascontiguousarray(array)
    data = a if a.size else np.zeros(1, dtype=a.dtype)
    check_allocation(context, data.nbytes, what)
    flags = (mf.READ_WRITE if writable else mf.READ_ONLY) | mf.COPY_HOST_PTR
    return cl.Buffer(context.ctx, flags, hostbuf=data)
