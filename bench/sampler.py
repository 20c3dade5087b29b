"""Sampler throughput: samples per second per compute unit, beside the paper's Table 1.

The paper's numbers are for one 4.8 GHz core (C++, single thread).  Ours run on the selected
OpenCL device; dividing by its compute units gives a per-core figure for PoCL's CPU device.
Times are the best of several runs of the whole ``clcsg.sample`` call (tree shape) after a
warm-up run that builds the kernels (program build excluded), tape compilation and host-side
packing included.  Beside them: distance queries, leaf distances per query and unresolved
cells.
"""

from __future__ import annotations

import warnings

import clcsg
from clcsg.cl.device import get_context
from clcsg.model.solids import _make

from .common import Load, best_of, environment, write

#: paper Table 1, samples per second on one core: (low, high)
PAPER = {
    "single quadric, no subdivision": (135e6, 135e6),
    "single quadric, with subdivision": (40e6, 70e6),
    "simple CSG": (10e6, 50e6),
    "complex CSG": (0.5e6, 2e6),
}


def scenes():
    B = clcsg.box(2)
    axes = [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 1), (1, -1, 1), (-1, 1, 1), (1, 1, -1)]
    tips = clcsg.intersection(*[_make("infinite_cylinder", None, axis=a, radius=1.0) for a in axes], clcsg.sphere(1.08))
    drill = clcsg.box(2) - clcsg.union(*[clcsg.cylinder(3, 0.5, axis=a) for a in ((1, 0, 0), (0, 1, 0), (0, 0, 1))])
    holes = clcsg.union(*[clcsg.cylinder(3, 0.15, center=(x, y, 0)) for x in (-0.6, -0.2, 0.2, 0.6) for y in (-0.6, 0.6)])
    return [
        ("sphere", "single quadric, with subdivision", clcsg.sphere(1.0)),
        ("box face (plane)", "single quadric, no subdivision", B & clcsg.halfspace((0, 0, 1), 0.0)),
        ("rounded cube", "simple CSG", clcsg.box(2) & clcsg.sphere(1.3)),
        ("drilled block", "simple CSG", drill),
        ("sharp tips (8 quadrics)", "complex CSG", tips),
        ("plate with 8 holes", "complex CSG", clcsg.box((2, 2, 0.3)) - holes),
    ]


def run(quick=False, device=None):
    ctx = get_context(device)
    load = Load()
    radii = [0.02] if quick else [0.04, 0.01, 0.005]
    rows = []
    warnings.simplefilter("ignore")
    for name, row, shape in scenes():
        clcsg.sample(shape, 0.05, device=ctx)  # warm-up: build the program
        for r in radii:
            t, s = best_of(lambda: clcsg.sample(shape, r, device=ctx), 1 if quick else 3)
            rate = len(s) / t
            lo, hi = PAPER[row]
            rows.append({
                "scene": name, "paper_row": row, "radius": r, "samples": len(s),
                "quadrics": s.stats["tape_quadrics"], "tape_instructions": s.stats["tape_instructions"],
                "distance_queries": s.stats["distance_queries"],
                "leaf_distances_per_query": s.stats["leaf_distances_per_query"], "unresolved": s.stats["unresolved"],
                "compile_s": s.stats["compile_s"], "subdivide_s": s.stats["subdivide_s"],
                "finish_s": s.stats["finish_s"],
                "seconds": t, "samples_per_s": rate, "samples_per_s_per_cu": rate / ctx.info.compute_units,
                "paper_samples_per_s_core": [lo, hi],
                "ratio_to_paper_low": rate / ctx.info.compute_units / lo,
            })
    payload = {"environment": load.into(environment(ctx)), "quick": bool(quick), "method": " ".join(__doc__.split()),
               "rows": rows}
    path = write("sampler", payload)
    lines = ["| scene | r | samples | queries | leaf dist./query | time (ms) | samples/s/CU | paper (1 core) | ratio |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lo, hi = r["paper_samples_per_s_core"]
        lines.append(f"| {r['scene']} | {r['radius']} | {r['samples']} | {r['distance_queries']} | "
                     f"{r['leaf_distances_per_query']:.2f} | "
                     f"{1e3 * r['seconds']:.1f} | {r['samples_per_s_per_cu'] / 1e6:.2f} M | "
                     f"{lo / 1e6:g}-{hi / 1e6:g} M | {r['ratio_to_paper_low']:.2f} |")
    print("\n".join(lines))
    print(f"\n{payload['environment']['device']} ({ctx.info.compute_units} CUs); written to {path}")
    return payload
