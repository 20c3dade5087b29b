"""The sampler's samples on the device, one region per field (``finish.h`` writes them).

Two buffers, one of reals (the device's precision) and one of int32, each a run of regions in
the order of :data:`~clcsg.cl.constants.SAMPLE_REAL_COLUMNS` /
:data:`~clcsg.cl.constants.SAMPLE_INT_COLUMNS`: a region holds ``cap`` entries of its field's
width (3 for a position), so sample k's position is ``reals[3 k : 3 k + 3]`` and its normal
``reals[3 cap + 3 k : ...]``.  The host reads each field's first n entries straight into its
own array: there is no record to take apart (a strided copy per field cost the lens 0.4 ms of
its 6 ms per call).
"""

from __future__ import annotations

import numpy as np

from ..cl.constants import SAMPLE_INT_COLUMNS, SAMPLE_REAL_COLUMNS
from ..cl.memory import check_allocation, upload


def _offsets(columns) -> tuple[dict, int]:
    """({name: (offset in units of the capacity, width)}, total width)."""
    out, offset = {}, 0
    for name, width in columns:
        out[name] = (offset, width)
        offset += width
    return out, offset


REAL_LAYOUT, REAL_WIDTH = _offsets(SAMPLE_REAL_COLUMNS)
INT_LAYOUT, INT_WIDTH = _offsets(SAMPLE_INT_COLUMNS)
INT = np.dtype(np.int32)


def bytes_per_sample(real) -> int:
    """Device bytes per sample of capacity."""
    return REAL_WIDTH * np.dtype(real).itemsize + INT_WIDTH * INT.itemsize


class SampleColumns:
    """The sample buffers of one run, ``cap`` samples each.  ``buffer(nbytes, what)`` makes a
    device buffer (the driver's pool, or zeroed memory where a checker needs it);
    ``on_device``: grow by copies on the device (else through host memory, which Oclgrind's
    uninitialized-value checker follows)."""

    def __init__(self, ctx, real, cap: int, buffer, on_device: bool = True):
        self.ctx, self.real, self.cap = ctx, np.dtype(real), int(cap)
        self.buffer, self.on_device = buffer, on_device
        self.reals = buffer(REAL_WIDTH * self.cap * self.real.itemsize, "sample")
        self.ints = buffer(INT_WIDTH * self.cap * INT.itemsize, "sample")

    def args(self) -> tuple:
        """The kernel arguments (reals, ints, capacity)."""
        return self.reals, self.ints, np.uint32(self.cap)

    def buffers(self) -> tuple:
        return self.reals, self.ints

    def grow(self, n_used: int, cap: int) -> None:
        """Larger buffers holding the first ``n_used`` entries of every region."""
        self.reals = self._moved(self.reals, REAL_LAYOUT, REAL_WIDTH, self.real, n_used, cap)
        self.ints = self._moved(self.ints, INT_LAYOUT, INT_WIDTH, INT, n_used, cap)
        self.cap = int(cap)

    def _moved(self, old, layout, width, dtype, n_used, cap):
        import pyopencl as cl

        if self.on_device:
            new = self.buffer(width * cap * dtype.itemsize, "sample")
            for offset, w in layout.values():
                if n_used:
                    cl.enqueue_copy(self.ctx.queue, new, old, byte_count=w * n_used * dtype.itemsize,
                                    src_offset=offset * self.cap * dtype.itemsize,
                                    dst_offset=offset * cap * dtype.itemsize)
            return new
        check_allocation(self.ctx, width * cap * dtype.itemsize, "sample")
        data = np.zeros(max(width * cap, 1), dtype=dtype)
        if n_used:
            host = np.empty(width * self.cap, dtype=dtype)
            cl.enqueue_copy(self.ctx.queue, host, old)
            for offset, w in layout.values():
                src, dst = offset * self.cap, offset * cap
                data[dst:dst + w * n_used] = host[src:src + w * n_used]
        return upload(self.ctx, data, writable=True)

    def read(self, n: int, transfers: list) -> dict:
        """The first ``n`` entries of every field, {name: (n, width) or (n,) array}, enqueued
        without waiting: their events go to ``transfers``, which the caller keeps until it has
        finished the queue (pyopencl waits for a dropped one at once).  Adjacent regions of one
        width are read by one rectangular copy into one array, whose rows are the fields'
        arrays."""
        import pyopencl as cl

        out = {}
        for buf, layout, dtype in ((self.reals, REAL_LAYOUT, self.real), (self.ints, INT_LAYOUT, INT)):
            for names, offset, width in _runs(layout):
                block = np.empty((len(names), n, width), dtype=dtype)
                if n:
                    row = width * dtype.itemsize
                    transfers.append(cl.enqueue_copy(
                        self.ctx.queue, block, buf, buffer_origin=(offset * self.cap * dtype.itemsize, 0),
                        host_origin=(0, 0), region=(n * row, len(names)), buffer_pitches=(self.cap * row,),
                        host_pitches=(n * row,), is_blocking=False))
                for k, name in enumerate(names):
                    out[name] = block[k] if width > 1 else block[k, :, 0]
        return out


def _runs(layout) -> list:
    """Adjacent regions of one width: [(names, offset of the first, width)]."""
    runs = []
    for name, (offset, width) in layout.items():
        if runs and runs[-1][2] == width:
            runs[-1][0].append(name)
        else:
            runs.append(([name], offset, width))
    return runs
