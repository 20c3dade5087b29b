"""Device buffers kept between calls, so that a call does not allocate what the last one freed.

A fresh buffer costs more than its allocation: on a CPU device its memory is new to the
process, and each page is faulted in and cleared the first time a kernel writes it (about a
tenth of the level-3 Menger sponge's sampling time went to that, inside the kernels).  The
sampler asks its per-call buffers (cells, tape arenas, sample records and clip rows) of
:func:`take` and hands them back with :func:`give` when the call is done;
the next call of about the same size gets the same memory, already mapped.

Sizes are rounded up to classes a quarter-octave apart (at most 25% more than asked), so
calls whose sizes differ a little share buffers.  A pool keeps at most :data:`POOL_SHARE` of
the device's global memory (and :data:`POOL_MAX_BYTES`); a buffer given back past that is
released.  A buffer from the pool holds whatever the last call left in it, as a fresh one
holds whatever its memory held: the sampler's kernels write every field they later read.
Oclgrind's uninitialized-value checker cannot see that, so the sampler takes host-zeroed
buffers there instead (:mod:`clcsg.sampling.sampler`).
"""

from __future__ import annotations

import threading
import weakref

from .memory import check_allocation

#: the largest share of the device's global memory that a pool keeps between calls
POOL_SHARE = 1 / 8
#: and at most this many bytes
POOL_MAX_BYTES = 1 << 30
#: the smallest size class
MIN_CLASS = 1 << 12

_pools: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()
_lock = threading.Lock()


def size_class(nbytes: int) -> int:
    """The smallest class of at least ``nbytes``: 2^e times 1, 5/4, 3/2 or 7/4 (whole numbers
    of bytes from :data:`MIN_CLASS` up), so a class is its own class."""
    n = max(int(nbytes), MIN_CLASS)
    step = 1 << (n.bit_length() - 3)
    return -(-n // step) * step


class BufferPool:
    """Free READ_WRITE buffers of one context, by size class."""

    def __init__(self, context):
        self.context = context
        self.limit = int(min(POOL_SHARE * context.info.global_mem, POOL_MAX_BYTES))
        self.free: dict[int, list] = {}
        self.held = 0
        self.reused = 0  # buffers handed out again
        self.lock = threading.Lock()

    def take(self, nbytes: int, what: str, hint: str = "use a larger radius"):
        """A buffer of at least ``nbytes`` (checked against the device's limits as asked)."""
        import pyopencl as cl

        check_allocation(self.context, nbytes, what, hint)
        size = size_class(nbytes)
        info = self.context.info
        if size > min(info.max_mem_alloc, info.global_mem):
            size = max(int(nbytes), 16)
        with self.lock:
            stack = self.free.get(size)
            if stack:
                self.held -= size
                self.reused += 1
                return stack.pop()
        return cl.Buffer(self.context.ctx, cl.mem_flags.READ_WRITE, size)

    def give(self, *buffers) -> None:
        """Keep ``buffers`` (None entries are skipped) for later calls, within the limit."""
        with self.lock:
            for buf in buffers:
                if buf is None:
                    continue
                size = buf.size
                if size != size_class(size) or self.held + size > self.limit:
                    continue  # not one of ours, or past the limit: released with the last reference
                self.free.setdefault(size, []).append(buf)
                self.held += size

    def clear(self) -> None:
        with self.lock:
            self.free.clear()
            self.held = 0


def pool_of(context) -> BufferPool:
    """The buffer pool of ``context`` (one per context, made on first use)."""
    with _lock:
        pool = _pools.get(context)
        if pool is None:
            pool = _pools[context] = BufferPool(context)
        return pool
