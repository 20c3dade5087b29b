"""Built programs are kept on disk: a second process loads the binary instead of building the
source (``clcsg.cl.programs``), and a changed source or option builds again.  The device probe
(``clcsg.cl.device``) is remembered there too: a second process does not build it."""

from __future__ import annotations

import json
import subprocess
import sys

#: builds a program in a fresh process; prints how often pyopencl was asked to build source
#: (the device probe counted apart)
CHILD = r"""
import json, sys
import pyopencl as cl
from clcsg.cl import programs
from clcsg.cl.device import PROBE_SOURCE, get_context
built, probes = [], []
real = cl.Program
def program(*args):
    if len(args) == 2 and isinstance(args[1], str):
        (probes if args[1] == PROBE_SOURCE else built).append(len(args[1]))
    return real(*args)
cl.Program = program
ctx = get_context(None)
prg = programs.build(ctx, "cl/quadric_check.cl", json.loads(sys.argv[1]))
print(json.dumps({"source_builds": len(built), "probe_builds": len(probes),
                  "kernels": sorted(prg.kernel_names.split(";"))}))
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
    assert first["probe_builds"] >= 1  # a new cache: the selected device is probed
    assert len(list(tmp_path.glob("*.bin"))) == 1
    assert len(list(tmp_path.glob("probe-*.ok"))) == first["probe_builds"]
    second = _child(tmp_path, {})
    assert second == {**first, "source_builds": 0, "probe_builds": 0}


def test_no_disk_cache_probes_every_process(tmp_path, cl_context, monkeypatch):
    monkeypatch.setenv("CLCSG_NO_CACHE", "1")
    for _ in range(2):
        out = subprocess.run([sys.executable, "-c", CHILD, "{}"], capture_output=True, text=True, timeout=300,
                             env={**__import__("os").environ, "CLCSG_CACHE_DIR": str(tmp_path)})
        assert out.returncode == 0, out.stderr
        child = json.loads(out.stdout.strip().splitlines()[-1])
        assert child["probe_builds"] >= 1 and child["source_builds"] == 1
    assert not list(tmp_path.iterdir())


def test_other_options_build_again(tmp_path, cl_context):
    _child(tmp_path, {})
    other = _child(tmp_path, {"CLCSG_CACHE_TEST": 1})
    assert other["source_builds"] == 1
    assert len(list(tmp_path.glob("*.bin"))) == 2
