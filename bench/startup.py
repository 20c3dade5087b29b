"""What a process pays before any real work: ``clcsg --version`` and ``clcsg sample`` of two
cubes against a bare ``python -c "import numpy, pyopencl as cl; cl.create_some_context(...)"``.

Three commands, each a fresh process:

* **bare**: import numpy and pyopencl and create a context (the floor for any pyopencl tool);
* **version**: ``clcsg --version`` (the command line alone: neither numpy nor pyopencl);
* **two cubes**: ``clcsg sample two_cubes.csg -o x.ply``, the scene ``cube(10);
  translate([20,0,0]) cube(10);`` as ``openscad -o two_cubes.csg`` writes it.

Each is run once to warm the caches a user's second run finds (Python's bytecode, the program
binaries, the device probe's record), then ``runs`` times, the three in turn so the machine's
load falls on all of them alike.  Per run: process CPU time (user + system, from ``wait4``) and
wall time; per command the minimum and the median, and the ratio of the minima to the bare
start's.  ``-X importtime`` of one more run of each names the modules the sampling command
imports beyond the bare start and their import time.  Writes ``bench/results/startup.json``.
"""

from __future__ import annotations

import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

from .common import Load, clcsg_command, environment_for_runs, fmt, git_commit, git_dirty, package_root, write

#: ``openscad -o two_cubes.csg`` of ``cube(10); translate([20,0,0]) cube(10);``
TWO_CUBES_CSG = """cube(size = [10, 10, 10], center = false);
multmatrix([[1, 0, 0, 20], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]) {
\tcube(size = [10, 10, 10], center = false);
}
"""

BARE = "import numpy, pyopencl as cl; cl.create_some_context(interactive=False)"

#: the targets: a ratio of process CPU and wall time to the bare start
TARGETS = {"version": 0.6, "two cubes": 1.3}


def commands(folder: str) -> dict[str, list[str]]:
    scene = os.path.join(folder, "two_cubes.csg")
    with open(scene, "w", encoding="utf-8") as f:
        f.write(TWO_CUBES_CSG)
    cli = clcsg_command()
    return {"bare": [sys.executable, "-c", BARE], "version": cli + ["--version"],
            "two cubes": cli + ["sample", scene, "-o", os.path.join(folder, "x.ply")]}


def run_once(argv, env) -> tuple[float, float]:
    """(process CPU seconds, wall seconds) of one run of ``argv``; raises on a failure."""
    with tempfile.TemporaryFile() as err:
        t = time.perf_counter()
        p = subprocess.Popen(argv, env=env, stdout=subprocess.DEVNULL, stderr=err)
        _, status, usage = os.wait4(p.pid, 0)
        wall = time.perf_counter() - t
        p.returncode = os.waitstatus_to_exitcode(status)
        if p.returncode != 0:
            err.seek(0)
            raise RuntimeError(f"{' '.join(argv)} exited with {p.returncode}: "
                               f"{err.read().decode(errors='replace').strip()}")
    return usage.ru_utime + usage.ru_stime, wall


def import_times(argv, env) -> dict[str, int]:
    """Module -> its own import time in microseconds (``python -X importtime``)."""
    if argv[0] != sys.executable:
        argv = [sys.executable, "-m", "clcsg"] + argv[1:]
    out = subprocess.run([argv[0], "-X", "importtime"] + argv[1:], env=env, capture_output=True, text=True)
    times = {}
    for line in out.stderr.splitlines():
        m = re.match(r"import time:\s+(\d+) \|\s+\d+ \| \s*(\S+)", line)
        if m:
            times[m[2]] = int(m[1])
    return times


def summary(values) -> dict:
    return {"min": min(values), "median": statistics.median(values), "runs": [round(v, 4) for v in values]}


def extra_imports(env, cmds) -> dict:
    """What the sampling command imports beyond the bare start: counts and import times."""
    bare, cubes = import_times(cmds["bare"], env), import_times(cmds["two cubes"], env)
    extra = {k: v for k, v in cubes.items() if k not in bare}
    groups: dict[str, int] = {}
    for name, us in extra.items():
        parts = name.split(".")
        key = ".".join(parts[:2]) if parts[0] == "clcsg" else parts[0]
        groups[key] = groups.get(key, 0) + us
    top = sorted(groups.items(), key=lambda kv: -kv[1])[:15]
    return {"modules": len(extra), "ms": round(sum(extra.values()) / 1000, 2),
            "bare_modules": len(bare), "bare_ms": round(sum(bare.values()) / 1000, 2),
            "by_package_ms": {k: round(v / 1000, 2) for k, v in top}}


def measure(runs: int) -> dict:
    env = environment_for_runs()
    folder = tempfile.mkdtemp(prefix="clcsg-startup-")
    try:
        cmds = commands(folder)
        for argv in cmds.values():  # warm the bytecode, program and probe caches
            run_once(argv, env)
        cpu = {k: [] for k in cmds}
        wall = {k: [] for k in cmds}
        for _ in range(runs):
            for name, argv in cmds.items():
                c, w = run_once(argv, env)
                cpu[name].append(c)
                wall[name].append(w)
        imports = extra_imports(env, cmds)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    rows = []
    for name in cmds:
        row = {"command": name, "cpu_s": summary(cpu[name]), "wall_s": summary(wall[name])}
        if name != "bare":
            row["cpu_ratio"] = min(cpu[name]) / min(cpu["bare"])
            row["wall_ratio"] = min(wall[name]) / min(wall["bare"])
            row["target_ratio"] = TARGETS[name]
        rows.append(row)
    return {"rows": rows, "extra_imports": imports,
            "commands": {k: " ".join(os.path.basename(a) if i == 0 else a for i, a in enumerate(v))
                         for k, v in cmds.items()}}


def table(result: dict) -> str:
    lines = ["| command | CPU min s | CPU median s | wall min s | wall median s | CPU ratio | wall ratio | target |",
             "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in result["rows"]:
        ratio = [fmt(r.get(k), ".2f", suffix="x") for k in ("cpu_ratio", "wall_ratio", "target_ratio")]
        lines.append(f"| {r['command']} | {r['cpu_s']['min']:.3f} | {r['cpu_s']['median']:.3f} | "
                     f"{r['wall_s']['min']:.3f} | {r['wall_s']['median']:.3f} | " + " | ".join(ratio) + " |")
    imp = result["extra_imports"]
    lines += ["", f"clcsg sample imports {imp['modules']} modules beyond the bare start's {imp['bare_modules']} "
              f"({imp['ms']:.1f} ms of import time, one run): "
              + ", ".join(f"{k} {v:.1f}" for k, v in imp["by_package_ms"].items())]
    return "\n".join(lines)


def run(quick: bool = False, device=None, runs: int | None = None) -> dict:
    """Measure (``runs`` rounds; 10, or 5 with ``quick``), write startup.json, print the table.
    ``device`` is not used: each process picks its device as ``clcsg`` does (``PYOPENCL_CTX``)."""
    load = Load()
    result = measure(runs or (5 if quick else 10))
    result["environment"] = load.into({"date": time.strftime("%Y-%m-%dT%H:%M:%S"), "cpus": os.cpu_count(),
                                       "clcsg": package_root(),
                                       "python": sys.version.split()[0], "git_commit": git_commit(),
                                       "git_dirty": git_dirty(), "timing": "process CPU (user + sys, wait4) "
                                       "and wall time of fresh processes, caches warm"})
    path = write("startup", result)
    print(table(result))
    print(f"wrote {path}")
    return result
