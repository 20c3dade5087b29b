"""Host compile time against the number of primitives: is it linear?

Two families of scenes built with the Python API, each at sizes from about 100 to 5,000
primitives:

* **plate**: a 200 x 200 x 5 mm plate minus an n x n grid of chamfered holes (per hole a
  cylinder and a cone frustum: 2 n^2 + 1 primitives; n = 50 is the 2,500-hole vent plate);
* **union**: identical spheres (radius 0.6 on a unit grid, each touching its neighbours) in one
  union.

Per scene, process CPU time (``time.process_time``, best of the repeats: the machine is
shared) of ``Scene.compile`` (tape, tree bounds, quadric table), of the tree bounds alone
(:func:`clcsg.compile.bounds.tree.tree_bounds`), and of the sampler's root tasks with their pruned
root tapes (:func:`clcsg.sampling.sampler.root_tasks`, radius 1% of the bound's diagonal), of the resource
guard's estimate from the quadrics' regions (:func:`clcsg.compile.bounds.estimates.estimate_regions`), the
full tape's rows and the root tapes' mean rows.  Microseconds per primitive staying flat as the
size grows is what linear means.  Writes ``bench/results/compile.json``.
"""

from __future__ import annotations

import math
import os
import time

import numpy as np

import clcsg
from clcsg.cl.records import pack
from clcsg.compile.bounds.estimates import estimate_regions
from clcsg.compile.bounds.regions import quadric_regions
from clcsg.compile.bounds.tree import tree_bounds
from clcsg.compile.quadric_frames import principal_frame
from clcsg.model.csg import Union
from clcsg.model.quadric import Quadric
from clcsg.model.scene import Scene
from clcsg.sampling.sampler import root_tasks

from .common import Load, fmt, least_cpu, write
from .zoo import plate

PLATE_GRIDS = (7, 10, 16, 22, 32, 50)
UNION_SIZES = (100, 250, 500, 1000, 2500, 5000)


def spheres(n: int):
    """n spheres of radius 0.6 on a unit grid, in one union."""
    k = math.ceil(n ** (1 / 3))
    return Union([clcsg.sphere(0.6, (i % k, (i // k) % k, i // (k * k))) for i in range(n)])


def measure(shape, repeats: int = 2) -> dict:
    compile_s, tape = least_cpu(lambda: Scene(shape).compile(), repeats)
    bounds_s, _ = least_cpu(lambda: tree_bounds(shape), repeats)
    radius = 0.01 * float(np.linalg.norm(tape.bound[1] - tape.bound[0]))
    packed = pack(tape, np.float64)
    frames = [principal_frame(Quadric(m)) for m in packed.local_matrices]
    roots_s, (tasks, cells, rows) = least_cpu(lambda: root_tasks(tape, packed, frames, radius), repeats)
    regions = quadric_regions(tape.quadrics, tape.instances, tape.bound)
    est_s, est = least_cpu(lambda: estimate_regions(tape.quadrics, regions, radius), repeats)
    n = len(tape.instances)
    return {
        "primitives": n, "quadrics": tape.n_quadrics, "instructions": int(len(tape.ops)),
        "compile_cpu_s": compile_s, "tree_bounds_cpu_s": bounds_s, "root_tasks_cpu_s": roots_s,
        "estimate_regions_cpu_s": est_s, "estimated_samples": est.samples,
        "compile_us_per_primitive": 1e6 * compile_s / n, "tasks": int(len(tasks)),
        "root_tape_rows_mean": float(np.mean(cells["tape_count"])) if len(cells) else 0.0,
        "root_tape_rows_max": int(cells["tape_count"].max()) if len(cells) else 0,
        "root_rows_total": int(len(rows)), "bound": tape.bound.tolist(),
    }


def run(quick: bool = False, device=None) -> None:
    load = Load()
    grids = PLATE_GRIDS[:4] if quick else PLATE_GRIDS
    sizes = UNION_SIZES[:4] if quick else UNION_SIZES
    rows = []
    for n in grids:
        rows.append({"family": "plate", "holes": n * n, **measure(plate(n))})
    for n in sizes:
        rows.append({"family": "union", **measure(spheres(n))})
    env = load.into({"date": time.strftime("%Y-%m-%dT%H:%M:%S"), "cpus": os.cpu_count(),
                     "timer": "process CPU time, best of 2"})
    path = write("compile", {"environment": env, "scenes": rows})
    print("| scene | primitives | compile s | us / primitive | tree bounds s | root tasks s | estimate s | root tape rows (mean / full) |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['family']} | {r['primitives']:,} | {fmt(r['compile_cpu_s'], '.2f')} | "
              f"{fmt(r['compile_us_per_primitive'], '.0f')} | {fmt(r['tree_bounds_cpu_s'], '.2f')} | "
              f"{fmt(r['root_tasks_cpu_s'], '.2f')} | {fmt(r['estimate_regions_cpu_s'], '.3f')} | {fmt(r['root_tape_rows_mean'], '.0f')} / {r['instructions']:,} |")
    print(f"wrote {path}")
