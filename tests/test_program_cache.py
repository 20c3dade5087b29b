"""Built programs are kept on disk: a second process loads the binary instead of building the
source (``clcsg.cl.programs``), and a changed source or option builds again."""

from __future__ import annotations

import json
import subprocess
import sys

#: builds a program in a fresh process; prints whether pyopencl was asked to build source
CHILD = r"""
import json, sys
import pyopencl as cl
from clcsg.cl import programs
from clcsg.cl.device import get_context
built = []
real = cl.Program
def program(*args):
    if len(args) == 2 and isinstance(args[1], str):
        built.append(len(args[1]))
    return real(*args)
cl.Program = program
ctx = get_context(None)
prg = programs.build(ctx, "cl/quadric_check.cl", json.loads(sys.argv[1]))
print(json.dumps({"source_builds": len(built), "kernels": sorted(prg.kernel_names.split(";"))}))
"""


def _child(tmp_path, defines) -> dict:
    env = {**__import__("os").environ, "CLCSG_CACHE_DIR": str(tmp_path)}
    env.pop("CLCSG_NO_CACHE", None)
    out = subprocess.run([sys.executable, "-c", CHILD, json.dumps(defines)], capture_output=True, text=True,
                         timeout=300, env=env)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_a_second_process_loads_the_binary(tmp_path, cl_context):
    first = _child(tmp_path, {})
    assert first["source_builds"] == 1 and first["kernels"]
    assert len(list(tmp_path.glob("*.bin"))) == 1
    second = _child(tmp_path, {})
    assert second == {**first, "source_builds": 0}


def test_other_options_build_again(tmp_path, cl_context):
    _child(tmp_path, {})
    other = _child(tmp_path, {"CLCSG_CACHE_TEST": 1})
    assert other["source_builds"] == 1
    assert len(list(tmp_path.glob("*.bin"))) == 2
