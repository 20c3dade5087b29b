"""Scene bounds and the resource guard against what sampling really finds, and random programs
run end to end through the CLI.

Per scene (the zoo, the examples, ``--programs N`` random CSG programs of
:mod:`clcsg.model.random_programs`, radius 1-5% of the diagonal drawn per program):

* **bound ratio**: per axis, the size of the compiled bound over the extent of the samples
  (samples lie exactly on the surface and cover it within the radius, so that extent is the
  solid's less at most 2r, and the ratio is an upper bound of the true one); the largest axis
  is reported, 1.0 is tight;
* **guard ratio**: the guard's estimate of the sample count (``estimated_samples``) over the
  samples the run produced; the guard refuses only past its limits, so a ratio near 1 (and
  never far below) means no false refusal and no surprise.

Random programs run through ``clcsg.cli.main`` (``info``, ``sample``, and ``render`` for
every tenth), in this process: any exit code other than 0 (or 5 for an empty solid's warning,
which is not an error) and any "internal error" on stderr is counted and listed.  The report
is ``bench/results/bounds.json``.
"""

from __future__ import annotations

import contextlib
import glob
import io
import json
import os
import tempfile
import time
import warnings

import numpy as np

import clcsg
from clcsg.cl.device import get_context
from clcsg.cli import main as cli_main
from clcsg.writers.ply import read_samples
from clcsg.model.random_programs import random_program

from .common import Load, diagonal, environment, write
from .zoo import MODELS

EXAMPLES = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "examples")


def bound_ratio(bound, positions) -> float:
    """Largest per-axis ratio of the bound's size to the samples' extent: the samples lie on
    the surface, so their extent is at most the solid's and the ratio at least the true one."""
    b = np.asarray(bound, dtype=np.float64)
    extent = np.maximum(positions.max(axis=0) - positions.min(axis=0), 1e-12)
    return float(((b[1] - b[0]) / extent).max())


def ratios(samples) -> dict:
    """Bound ratio (largest axis) and guard ratio of one sampling run."""
    if len(samples) == 0:
        return {"samples": 0, "bound_ratio": None, "guard_ratio": None}
    est = samples.stats.get("estimated_samples")
    return {
        "samples": len(samples),
        "bound_ratio": bound_ratio(samples.bound, samples.positions),
        "guard_ratio": float(est / len(samples)) if est else None,
    }


def _summary(rows, key) -> dict:
    v = np.array([r[key] for r in rows if r.get(key) is not None], dtype=np.float64)
    if not len(v):
        return {}
    return {"n": len(v), "min": float(v.min()), "median": float(np.median(v)), "p90": float(np.quantile(v, 0.9)),
            "max": float(v.max())}


def named_scenes():
    """(name, scene) of the zoo models and the examples."""
    out = [(f"zoo/{m.name}", clcsg.Scene(m.build())) for m in MODELS]
    for path in sorted(glob.glob(os.path.join(EXAMPLES, "*.json")) + glob.glob(os.path.join(EXAMPLES, "*.csg"))):
        out.append((f"examples/{os.path.basename(path)}", clcsg.load(path)))
    return out


def _cli(argv) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        rc = cli_main(argv)
    return rc, err.getvalue()


def program_row(seed: int, tmp: str, device_spec: str) -> dict:
    """One random program through ``clcsg info`` / ``sample`` (/ ``render``), with its ratios."""
    rng = np.random.default_rng(seed)
    prog = random_program(rng, max_depth=3)
    rel = float(rng.uniform(0.01, 0.05))
    path = os.path.join(tmp, f"p{seed}.csg")
    with open(path, "w") as f:
        f.write(prog.csg)
    row = {"seed": seed, "rel_radius": rel, "errors": []}
    tape = clcsg.load(path).compile()
    row["quadrics"] = len(tape.quadrics)
    row["empty"] = bool(tape.empty)
    if tape.empty:
        return row
    radius = rel * diagonal(tape.bound)
    stats = os.path.join(tmp, f"p{seed}.json")
    runs = [["info", path], ["sample", path, "-r", repr(radius), "-o", os.path.join(tmp, "p.ply"),
                             "--stats", stats, "--quiet", "--device", device_spec]]
    if seed % 10 == 0:
        runs.append(["render", path, "-r", repr(radius), "-o", os.path.join(tmp, "p.png"), "--size", "160x120",
                     "--quiet", "--device", device_spec])
    t0 = time.perf_counter()
    for argv in runs:
        rc, err = _cli(argv)
        if rc != 0 or "internal error" in err or "Traceback" in err:
            row["errors"].append({"command": argv[0], "rc": rc, "stderr": err.strip()[-300:]})
    row["seconds"] = time.perf_counter() - t0
    if os.path.exists(stats):
        with open(stats) as f:
            st = json.load(f)
        est, n = st.get("estimated_samples"), st.get("samples")
        row["samples"] = n
        row["guard_ratio"] = float(est / n) if est and n else None
        p = read_samples(os.path.join(tmp, "p.ply"))["positions"]
        if len(p):
            row["bound_ratio"] = bound_ratio(tape.bound, p)
    return row


def run(quick: bool = False, device=None, programs: int | None = None):
    warnings.simplefilter("ignore")
    ctx = get_context(device)
    load = Load()
    n_programs = programs if programs is not None else (30 if quick else 200)
    scenes = []
    for name, scene in named_scenes():
        tape = scene.compile()
        r = 0.02 * diagonal(tape.bound)
        s = clcsg.sample(scene, r, device=ctx)
        scenes.append({"scene": name, "radius": r, **ratios(s)})
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(n_programs):
            rows.append(program_row(seed, tmp, ctx.info.spec))
            if (seed + 1) % 100 == 0:
                bad = sum(bool(r["errors"]) for r in rows)
                print(f"  {seed + 1} programs, {bad} with errors", flush=True)
    failed = [r for r in rows if r["errors"]]
    internal = [r for r in failed if any("internal error" in e["stderr"] for e in r["errors"])]
    payload = {
        "environment": load.into(environment(ctx)),
        "scenes": scenes,
        "programs": {
            "count": len(rows),
            "empty": sum(r["empty"] for r in rows),
            "failed": len(failed),
            "internal_errors": len(internal),
            "failures": failed[:20],
            "widest_bounds": sorted(({"seed": r["seed"], "bound_ratio": r["bound_ratio"]} for r in rows
                                     if r.get("bound_ratio")), key=lambda r: -r["bound_ratio"])[:10],
            "loosest_estimates": sorted(({"seed": r["seed"], "guard_ratio": r["guard_ratio"]} for r in rows
                                         if r.get("guard_ratio")), key=lambda r: -r["guard_ratio"])[:10],
            "bound_ratio": _summary(rows, "bound_ratio"),
            "guard_ratio": _summary(rows, "guard_ratio"),
            "seconds": _summary(rows, "seconds"),
        },
        "scene_bound_ratio": _summary(scenes, "bound_ratio"),
        "scene_guard_ratio": _summary(scenes, "guard_ratio"),
    }
    path = write("bounds", payload)
    print(markdown(payload))
    print(f"wrote {path}")
    return payload


def markdown(p) -> str:
    lines = ["| scene | samples | bound / sample extent | guard estimate / samples |", "|---|---|---|---|"]
    for s in p["scenes"]:
        br = "-" if s["bound_ratio"] is None else f"{s['bound_ratio']:.3f}"
        gr = "-" if s["guard_ratio"] is None else f"{s['guard_ratio']:.2f}"
        lines.append(f"| {s['scene']} | {s['samples']:,} | {br} | {gr} |")
    pr = p["programs"]

    def q(d):
        return f"median {d['median']:.3f}, 90% {d['p90']:.3f}, max {d['max']:.3f} (min {d['min']:.3f})" if d else "-"

    lines += ["", f"Random programs: {pr['count']} ({pr['empty']} empty), {pr['failed']} failed, "
              f"{pr['internal_errors']} internal errors.",
              f"- bound / sample extent: {q(pr['bound_ratio'])}",
              f"- guard estimate / samples: {q(pr['guard_ratio'])}"]
    return "\n".join(lines)
