"""Reading large scene files: time and peak memory against the file's size.

Generated models (:func:`write_csg`, :func:`write_json`): one union of cubes, spheres and
cylinders, each rotated and translated and with its own color, written as an OpenSCAD CSG
export (``multmatrix`` / ``color`` / primitive, as ``openscad -o`` writes them) and as a clcsg
``.json`` scene, at about 0.5, 5 and 50 MB.  Each file is loaded in a fresh Python process
(``clcsg.load``) that reports

* process CPU time of the load,
* the peak of Python's allocations while loading (``tracemalloc``) per byte of the file,
* the growth of the peak resident set size (``resource.getrusage``'s ``ru_maxrss``) per byte
  of the file (the process's own peak; imports and the schema's validators are made first),

and, for the ``.csg`` files, ``openscad``'s CPU time to read the same file and export it
again as CSG (``openscad -o out.csg in.csg``: its parse and tree evaluation; no geometry is
built), where the binary is installed.  Writes ``bench/results/load.json``.
"""

from __future__ import annotations

import json
import math
import os
import random
import resource
import shutil
import subprocess
import sys
import tempfile
import time

from .common import Load, fmt, write

SIZES_MB = (0.5, 5.0, 50.0)

_MEASURE = """
import json, os, resource, sys, time, tracemalloc, warnings
warnings.simplefilter("ignore")
import clcsg
import clcsg.readers.openscad, clcsg.readers.scene_stream
from clcsg.readers.scene_schema import scene_schema
from clcsg.readers.scenes import load
scene_schema()  # imports and the validators: not part of reading a file
path, traced = sys.argv[1], sys.argv[2] == "1"
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
if traced:
    tracemalloc.start()
t = time.process_time()
scene = load(path)
cpu = time.process_time() - t
out = {"cpu_s": cpu, "rss_growth": (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - base) * 1024}
if traced:
    out["traced_peak"] = tracemalloc.get_traced_memory()[1]
print(json.dumps(out))
"""


def _rotation(rnd):
    """A rotation matrix from three angles, multiples of 15 degrees or arbitrary."""
    ax, ay, az = (math.radians(rnd.choice([0, 15, 30, 45, 90, rnd.uniform(0, 360)])) for _ in range(3))
    ca, sa, cb, sb, cc, sc = math.cos(ax), math.sin(ax), math.cos(ay), math.sin(ay), math.cos(az), math.sin(az)
    return [[cc * cb, cc * sb * sa - sc * ca, cc * sb * ca + sc * sa],
            [sc * cb, sc * sb * sa + cc * ca, sc * sb * ca - cc * sa],
            [-sb, cb * sa, cb * ca]]


def _items(seed: int = 1):
    """(kind, parameters, 3x4 matrix, rgb) of the generated model, endlessly."""
    rnd = random.Random(seed)
    n = 0
    while True:
        r = _rotation(rnd)
        t = [round(rnd.uniform(-100, 100), 4) for _ in range(3)]
        m = [[round(v, 6) + 0.0 for v in r[i]] + [t[i]] for i in range(3)]
        rgb = [round(rnd.random(), 3) for _ in range(3)]
        k = n % 3
        if k == 0:
            yield "cube", [round(rnd.uniform(1, 5), 3) for _ in range(3)], m, rgb
        elif k == 1:
            yield "sphere", round(rnd.uniform(1, 5), 3), m, rgb
        else:
            yield "cylinder", (round(rnd.uniform(1, 9), 3), round(rnd.uniform(0.5, 3), 3)), m, rgb
        n += 1


def _g(v) -> str:
    return f"{v:g}"


def write_csg(path: str, nbytes: int, seed: int = 1) -> int:
    """An OpenSCAD CSG export of about ``nbytes``; the number of primitives."""
    n = 0
    with open(path, "w") as f:
        f.write("group() {\n")
        for kind, p, m, c in _items(seed):
            if f.tell() >= nbytes:
                break
            rows = ", ".join("[" + ", ".join(_g(v) for v in row) + "]" for row in m)
            f.write(f"\tmultmatrix([{rows}, [0, 0, 0, 1]]) {{\n\t\tcolor([{_g(c[0])}, {_g(c[1])}, {_g(c[2])}, 1]) {{\n")
            if kind == "cube":
                f.write(f"\t\t\tcube(size = [{', '.join(map(_g, p))}], center = true);\n")
            elif kind == "sphere":
                f.write(f"\t\t\tsphere($fn = 0, $fa = 12, $fs = 2, r = {_g(p)});\n")
            else:
                f.write(f"\t\t\tcylinder($fn = 0, $fa = 12, $fs = 2, h = {_g(p[0])}, r1 = {_g(p[1])}, r2 = {_g(p[1])}, "
                        "center = false);\n")
            f.write("\t\t}\n\t}\n")
            n += 1
        f.write("}\n")
    return n


def write_json(path: str, nbytes: int, seed: int = 1) -> int:
    """The same model as a clcsg ``.json`` scene of about ``nbytes``; the number of primitives."""
    n = 0
    with open(path, "w") as f:
        f.write('{"clcsg": 1, "root": {"union": [\n')
        for kind, p, m, c in _items(seed):
            if f.tell() >= nbytes:
                break
            if kind == "cube":
                node = {"box": {"size": p}}
            elif kind == "sphere":
                node = {"sphere": {"radius": p}}
            else:
                node = {"cylinder": {"height": p[0], "radius": p[1], "center": [0, 0, p[0] / 2]}}
            node["color"] = c
            node["transform"] = [{"matrix": m + [[0, 0, 0, 1]]}]
            f.write(("" if n == 0 else ",\n") + json.dumps(node, separators=(",", ":")))
            n += 1
        f.write("\n]}}\n")
    return n


def measure(path: str, traced: bool) -> dict:
    """The load of ``path`` in a fresh process (see the module's docstring)."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = {**os.environ, "PYTHONPATH": root + os.pathsep + os.environ.get("PYTHONPATH", "")}
    r = subprocess.run([sys.executable, "-c", _MEASURE, path, "1" if traced else "0"], capture_output=True,
                       text=True, env=env, timeout=3600)
    if r.returncode != 0:
        raise RuntimeError(r.stderr.strip().splitlines()[-1] if r.stderr.strip() else f"exit {r.returncode}")
    return json.loads(r.stdout)


def openscad_seconds(path: str) -> float | None:
    """CPU seconds of ``openscad -o out.csg path`` (children's rusage), or None without it."""
    exe = shutil.which("openscad")
    if exe is None:
        return None
    with tempfile.TemporaryDirectory() as d:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        r = subprocess.run([exe, "-o", os.path.join(d, "out.csg"), path], capture_output=True, timeout=3600)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if r.returncode != 0:
        return None
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def run(quick: bool = False, device=None) -> None:
    load = Load()
    sizes = SIZES_MB[:2] if quick else SIZES_MB
    rows = []
    with tempfile.TemporaryDirectory() as d:
        for mb in sizes:
            for ext, writer in ((".csg", write_csg), (".json", write_json)):
                path = os.path.join(d, f"model_{mb:g}mb{ext}")
                n = writer(path, int(mb * 1e6))
                size = os.path.getsize(path)
                plain = measure(path, traced=False)
                traced = measure(path, traced=True)
                row = {"format": ext[1:], "megabytes": size / 1e6, "primitives": n, "cpu_s": plain["cpu_s"],
                       "us_per_primitive": 1e6 * plain["cpu_s"] / n,
                       "rss_growth_per_byte": plain["rss_growth"] / size,
                       "traced_peak_per_byte": traced["traced_peak"] / size,
                       "openscad_cpu_s": openscad_seconds(path) if ext == ".csg" else None}
                rows.append(row)
                write("load", {"environment": _environment(load), "files": rows})  # what is done so far
                print(f"{ext} {size / 1e6:.1f} MB: {row['cpu_s']:.1f} s, peak {row['traced_peak_per_byte']:.1f}x "
                      f"(traced), {row['rss_growth_per_byte']:.1f}x (RSS)", flush=True)
    env = _environment(load)
    path = write("load", {"environment": env, "files": rows})
    print("| file | MB | primitives | load s | us / primitive | peak / size (tracemalloc) | peak RSS growth / size | openscad s |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| .{r['format']} | {r['megabytes']:.1f} | {r['primitives']:,} | {fmt(r['cpu_s'], '.2f')} | "
              f"{fmt(r['us_per_primitive'], '.0f')} | {fmt(r['traced_peak_per_byte'], '.1f')}x | "
              f"{fmt(r['rss_growth_per_byte'], '.1f')}x | {fmt(r['openscad_cpu_s'], '.2f', none='-')} |")
    if env["openscad"] is None:
        print("openscad is not installed: no peer column")
    print(f"wrote {path}")


def _environment(load) -> dict:
    return load.into({"date": time.strftime("%Y-%m-%dT%H:%M:%S"), "cpus": os.cpu_count(), "python": sys.version.split()[0],
                      "openscad": _openscad_version(),
                      "timer": "process CPU time of clcsg.load in a fresh process; openscad: CPU time of "
                               "openscad -o out.csg in.csg (parse and tree evaluation, no geometry)"})


def _openscad_version() -> str | None:
    exe = shutil.which("openscad")
    if exe is None:
        return None
    r = subprocess.run([exe, "--version"], capture_output=True, text=True)
    return (r.stdout + r.stderr).strip().splitlines()[0] if r.returncode == 0 else None
