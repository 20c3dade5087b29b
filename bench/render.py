"""Render speed: splats against the exact ray tracer, and what each overdraw optimization buys.

Per scene: ray tracer kernel time; splat rasterizer + resolve kernel time with surface-aligned
bounds and back-face culling each on and off (paper section 6.1, Fig. 13: about 10x from all
optimizations together), with fragments (ray-quadric solves), overdraw (fragments per covered
pixel) and clip evaluations.  Times are OpenCL profiling-event times (the best of several
runs), so they exclude sampling, uploads and program builds.  The paper's Table 2 render
column (RTX 2080 Ti) is reported beside the ratios.
"""

from __future__ import annotations

import warnings

import clcsg
from clcsg.cl.device import get_context

from .common import environment, write

SCENES = [
    ("drilled block", "examples/drilled_block.json", 0.02),
    ("bracket", "examples/bracket.json", 1.0),
    ("flange", "examples/flange.csg", 1.0),
    ("pawn", "examples/pawn.csg", 0.4),
]

#: paper Table 2: ray tracing / splat render time at 1080p, for its 80-quadric model
PAPER_SPEEDUP_80 = 9.15 / 0.32


def _best(fn, repeats):
    best, out = None, None
    for _ in range(repeats):
        out = fn()
        t = out.stats["kernel_seconds"]
        best = t if best is None else min(best, t)
    return best, out


def run(quick=False, device=None):
    ctx = get_context(device)
    w, h = (480, 270) if quick else (1920, 1080)
    repeats = 1 if quick else 3
    warnings.simplefilter("ignore")
    rows = []
    for name, path, radius in SCENES:
        scene = clcsg.load(path)
        samples = clcsg.sample(scene, radius, device=ctx)
        cam = clcsg.Camera.fit(samples.dnf.bound, w, h)
        t_rt, _ = _best(lambda: clcsg.raytrace(samples.dnf, cam, device=ctx), repeats)
        row = {"scene": name, "quadrics": samples.dnf.n_quadrics, "terms": samples.dnf.n_terms,
               "samples": len(samples), "radius": radius, "width": w, "height": h, "raytrace_s": t_rt}
        for sa in (False, True):
            for bf in (False, True):
                t, img = _best(lambda: clcsg.render(samples, cam, device=ctx, surface_aligned=sa,
                                                    backface_culling=bf), repeats)
                key = f"{'sa' if sa else 'ball'}_{'bf' if bf else 'nobf'}"
                row[key] = {"seconds": t, "fragments": img.stats["fragments"],
                            "overdraw": img.stats["overdraw"], "clip_evaluations": img.stats["clip_evaluations"]}
        row["speedup_vs_raytrace"] = t_rt / row["sa_bf"]["seconds"]
        row["optimizations_gain"] = row["ball_nobf"]["seconds"] / row["sa_bf"]["seconds"]
        rows.append(row)
    payload = {"environment": environment(ctx), "resolution": [w, h], "paper_speedup_80_quadrics": PAPER_SPEEDUP_80,
               "rows": rows}
    path = write("render", payload)
    print(f"| scene | quadrics | samples | ray tracer (ms) | splats (ms) | speedup | overdraw off/on | "
          f"gain of the optimizations |\n|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['scene']} | {r['quadrics']} | {r['samples']} | {1e3 * r['raytrace_s']:.1f} | "
              f"{1e3 * r['sa_bf']['seconds']:.1f} | {r['speedup_vs_raytrace']:.2f}x | "
              f"{r['ball_nobf']['overdraw']:.1f} / {r['sa_bf']['overdraw']:.1f} | {r['optimizations_gain']:.2f}x |")
    print(f"\n{w}x{h} on {payload['environment']['device']}; paper: {PAPER_SPEEDUP_80:.0f}x on 80 quadrics (GPU); "
          f"written to {path}")
    return payload
