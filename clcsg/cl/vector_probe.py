"""Does a device's compiler build 8-wide vector math?  Run as ``python -m clcsg.cl.vector_probe
P D`` (platform and device index), it builds and runs :data:`SOURCE` there and prints ``ok``.

The renderer's kernels shade eight pixels as one real8 / float8 vector.  PoCL's pip wheel
(LLVM 14) on CPUs newer than its LLVM (AMD Zen 4: target "znver3" with the AVX-512 kernel
library) builds one-line kernels but stops in LLVM's code generator on ``sqrt``, ``fma`` or
``fabs`` of a double8 ("LLVM ERROR: Cannot select ... _cl_sqrtDv8_d"), and LLVM then aborts
the whole process.  Hence a child process: its death is the answer, not the caller's.
"""

from __future__ import annotations

import sys

#: the builtins of the renderer's 8-wide code, in double where the device has it
SOURCE = r"""
#ifdef cl_khr_fp64
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
typedef double8 probe8;
#else
typedef float8 probe8;
#endif
__kernel void clcsg_vector_probe(__global float *out)
{
    size_t i = get_global_id(0);
    probe8 x = (probe8)(1, 2, 3, 4, 5, 6, 7, 8) + (probe8)(i);
    probe8 y = fma(x, sqrt(x), copysign(fabs(x), -x)) + exp2(x / 64) + log2(x) + fmin(x, (probe8)(2));
    y = select(y, 1 / sqrt(y * y), isless(y, (probe8)(0)));
    float8 f = convert_float8(y);
    out[i] = f.s0 + f.s7;
}
"""

#: work-items of the probe's launch (a work-group of 64, as the renderer's)
ITEMS = 64


def run(platform_index: int, device_index: int) -> None:
    """Build and run :data:`SOURCE` on the device; raises on a failure."""
    import numpy as np
    import pyopencl as cl

    dev = cl.get_platforms()[platform_index].get_devices()[device_index]
    ctx = cl.Context([dev])
    queue = cl.CommandQueue(ctx)
    prg = cl.Program(ctx, SOURCE).build()
    out = np.zeros(ITEMS, dtype=np.float32)
    buf = cl.Buffer(ctx, cl.mem_flags.WRITE_ONLY, out.nbytes)
    cl.Kernel(prg, "clcsg_vector_probe")(queue, (ITEMS,), None, buf)
    cl.enqueue_copy(queue, out, buf)
    queue.finish()
    if not np.isfinite(out).all():
        raise RuntimeError("the 8-wide vector probe computed non-finite values")


if __name__ == "__main__":
    run(int(sys.argv[1]), int(sys.argv[2]))
    print("ok", flush=True)
