"""Every device record: the numpy dtype (clcsg/cl/records.py, clcsg/rendering/shading.py) has the
C struct's size and field offsets on the device, in both precisions (the model is pyopencl's
match_dtype_to_c_struct)."""

import numpy as np
import pytest

from clcsg.cl import programs
from clcsg.cl.records import RECORDS
from clcsg.rendering.shading import view_dtype

CASES = [(name, header, factory) for name, header, factory in RECORDS] + [("view_rec", "shade.h", view_dtype)]


def device_layout(cl_context, name, header, names, real):
    import pyopencl as cl

    src = f'#include "{header}"\n#include "tape.h"\n__kernel void k(__global long *out) {{\n'
    src += f"out[0] = sizeof({name});\n"
    for n, field in enumerate(names):
        src += f"out[{n + 1}] = (long)&((({name} *)0)->{field});\n"
    src += "}\n"
    opts = programs.build_options(real=real) + ["-I", programs.package_dir("cl/include"),
                                                "-I", programs.package_dir("rendering")]
    prg = cl.Program(cl_context.ctx, src).build(options=opts)
    out = np.zeros(len(names) + 1, dtype=np.int64)
    buf = cl.Buffer(cl_context.ctx, cl.mem_flags.WRITE_ONLY, out.nbytes)
    prg.k(cl_context.queue, (1,), None, buf)
    cl.enqueue_copy(cl_context.queue, out, buf)
    return out


@pytest.mark.parametrize("real", [np.float64, np.float32], ids=["double", "float"])
@pytest.mark.parametrize("name,header,factory", CASES, ids=[c[0] for c in CASES])
def test_record_matches_c_struct(cl_context, name, header, factory, real):
    if real == np.float64 and not cl_context.info.fp64:
        pytest.skip("device has no fp64")
    dt = factory(real)
    out = device_layout(cl_context, name, header, dt.names, real)
    assert out[0] == dt.itemsize, f"{name}: sizeof {out[0]} on the device, {dt.itemsize} in numpy"
    assert list(out[1:]) == [dt.fields[n][1] for n in dt.names], name
