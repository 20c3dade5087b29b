"""How honest the sampling progress is: the ETA against the time actually left, the bar's
percentage, and the expected sample count shown before sampling against the real count.

Each run is the real command line, ``clcsg sample SCENE -r R -o x.ply --progress json``, in a
fresh process; its stderr is read line by line and each JSON line is stamped with the time it
arrives (``time.perf_counter`` in this process).  The *sampling bar* lives between the sample
step's ``start`` event and its last level (the progress event at 100%, ``done == total``);
with t measured from the step's start and T the time of that last level:

* **ETA ratio**: for every progress event of the bar in the second half (t >= T / 2) that has
  at least :data:`MIN_LEFT` seconds left (the bar shows whole seconds; a shorter remainder is
  "00:00" whatever the forecast), the ratio eta / (T - t); per run its worst factor (the
  largest of max ratio and 1 / min ratio) and the median ratio.  *Within 2x*: the worst factor
  is at most 2;
* **monotone**: done / total never decreases from one event to the next;
* **expected / real**: the ``estimated`` field of the events (the expected sample count,
  known before the first level) over the samples written.

The runs take 2-6 s each on a 2-core machine (the sampling bar 1-3 s): the zoo models, a few
examples and the 50 x 50 perforated plate (:func:`bench.zoo.plate`, 5,001 primitives), at radii
small enough for the level loop to be the bulk of the run (at 0.2-0.3% of the diagonal the
examples sample in under 0.5 s).  Every run is made ``rounds`` times (the machine
is shared and the ETA is about wall time), the runs in turn.  The level histories (per level:
cells, samples, arrival time) are kept in the JSON; :func:`record_histories` records them
in this process level by level, for :func:`replay_history` to feed a forecast.  A separate
pass measures expected / real on every example at r = 1% and 0.2% of the diagonal
(``clcsg.sample`` in this process, no timing).  Writes ``bench/results/progress.json``.
"""

from __future__ import annotations

import glob
import io
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
import warnings

from .common import Load, clcsg_command, environment_for_runs, git_commit, git_dirty, package_root, write
from .zoo import EXAMPLES_DIR, ZOO_DIR, plate

#: seconds left below which an event's ETA is not judged (see the module docstring)
MIN_LEFT = 0.1

#: (name, scene: a path under examples/ or "plate50", radius as the CLI takes it)
RUNS = [
    ("gear", "zoo/gear.json", "0.05%"),
    ("bracket (zoo)", "zoo/bracket.json", "0.05%"),
    ("flange (zoo)", "zoo/flange.json", "0.04%"),
    ("lens", "zoo/lens.json", "0.03%"),
    ("rook", "rook.csg", "0.05%"),
    ("pen_stand", "pen_stand.csg", "0.05%"),
    ("menger3", "menger3.csg", "0.1%"),
    ("plate 50x50", "plate50", "1%"),
]
QUICK = ("gear", "rook", "menger3", "plate 50x50")


def scene_path(scene: str, folder: str) -> str:
    if scene == "plate50":
        import clcsg

        path = os.path.join(folder, "plate50.json")
        if not os.path.exists(path):
            clcsg.save(plate(50), path)
        return path
    return os.path.join(EXAMPLES_DIR, scene)


def record(argv, env) -> tuple[list, float]:
    """(events with their arrival time in seconds since launch as ``"t"``, process wall time)."""
    t0 = time.perf_counter()
    p = subprocess.Popen(argv, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, bufsize=1)
    events = []
    for line in p.stderr:
        t = time.perf_counter() - t0
        try:
            ev = json.loads(line)
        except json.JSONDecodeError:
            continue  # a warning printed outside the reporter
        ev["t"] = t
        events.append(ev)
    rc = p.wait()
    wall = time.perf_counter() - t0
    if rc != 0:
        raise RuntimeError(f"{' '.join(argv)} exited with {rc}")
    return events, wall


def bar_events(events) -> tuple[float, list]:
    """(arrival of the sample step's start, the sampling bar's progress events)."""
    start = next(e["t"] for e in events if e["event"] == "start" and e["step"] == "sample")
    bar = [e for e in events if e["event"] == "progress" and e["step"] == "sample" and e["label"] == "sampling"]
    return start, bar


def history(events) -> dict:
    """The level history of a run: per level its cells, the samples after it, the time (since
    the sample step's start) its progress event arrived, the bar's total and ETA; the expected
    count."""
    start, bar = bar_events(events)
    done = [e["done"] for e in bar]
    return {"cells": [d - p for d, p in zip(done, [0] + done[:-1])], "samples": [e["samples"] for e in bar],
            "t": [round(e["t"] - start, 5) for e in bar], "total": [e["total"] for e in bar],
            "eta": [e["eta"] for e in bar], "estimated": bar[-1]["estimated"] if bar else 0}


def judge(points, end, min_left: float = MIN_LEFT) -> dict:
    """ETA ratios over the second half: ``points`` are (t, eta, fraction) of the bar, ``end``
    the time of its last level (all since the step's start); events with less than
    ``min_left`` seconds left are not judged."""
    ratios = [eta / (end - t) for t, eta, _ in points if t >= end / 2 and end - t >= min_left and eta is not None]
    fractions = [f for _, _, f in points]
    out = {"monotone": all(b >= a for a, b in zip(fractions, fractions[1:])), "judged": len(ratios)}
    if ratios:
        out.update(max_ratio=max(ratios), min_ratio=min(ratios), median_ratio=statistics.median(ratios),
                   worst=max(max(ratios), 1 / max(min(ratios), 1e-9)))
        out["within_2x"] = out["worst"] <= 2
    return out


def measure_run(events, wall) -> dict:
    start, bar = bar_events(events)
    end_ev = next(e for e in events if e["event"] == "end" and e["step"] == "sample")
    last = next(i for i, e in enumerate(bar) if e["done"] == e["total"])
    end = bar[last]["t"] - start
    summary = next(e for e in events if e["event"] == "summary")
    points = [(e["t"] - start, e["eta"], e["done"] / e["total"]) for e in bar[:last + 1]]
    out = {"wall_s": wall, "sample_step_s": end_ev["t"] - start, "bar_s": end, "levels": len(bar),
           "first_level_s": bar[0]["t"] - start, "samples": summary["samples"],
           "estimated": bar[-1]["estimated"], "expected_ratio": bar[-1]["estimated"] / max(summary["samples"], 1)}
    out.update(judge(points, end))
    out["history"] = history(events)
    return out


def record_histories(path: str, runs=RUNS) -> list:
    """Record the level history of each run in this process (no timing of the bar): the
    sampler's progress is observed as it is fed, chain by chain, so that
    :func:`replay_history` can feed a :class:`~clcsg.sampling.forecast.Forecast` the same.
    Per run: the forecast's inputs (expected samples, level bounds, the root cells' peak
    levels and areas, merged where the peaks agree to 1e-3), the samples written and per
    chain its arrival (seconds since the level loop started) and (level, cells, samples so
    far, children) per level.  A warm run (the kernels built) is recorded.  Writes JSON to
    ``path`` (``tests/data/level_histories.json`` is one)."""
    import numpy as np

    import clcsg
    from clcsg.progress import Reporter
    from clcsg.sampling import sampler

    out = []
    seen: dict = {}
    init, chain = sampler._Progress.__init__, sampler._Progress.chain

    def observed_init(self, *args, **kwargs):
        init(self, *args, **kwargs)
        f = self.forecast
        peaks, areas = f.roots if f.roots is not None else ([], [])
        merged, at = np.unique(np.round(peaks, 3), return_inverse=True)
        summed = np.zeros(len(merged))
        np.add.at(summed, at, areas)
        seen.update(estimate=f.estimate, quad=f.quad, peak=f.peak, last=f.last, max_levels=f.max_levels,
                    roots=[merged.tolist(), summed.tolist()], chains=[], t0=time.perf_counter())

    def observed_chain(self, levels):
        seen["chains"].append([round(time.perf_counter() - seen["t0"], 5), [[int(x) for x in lv] for lv in levels]])
        chain(self, levels)

    folder = tempfile.mkdtemp(prefix="clcsg-progress-")
    sampler._Progress.__init__, sampler._Progress.chain = observed_init, observed_chain
    try:
        for name, scene, radius in runs:
            sc = clcsg.load(scene_path(scene, folder))
            tape = sc.compile()
            r = float(radius.rstrip("%")) / 100 * float(np.linalg.norm(tape.bound[1] - tape.bound[0]))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                clcsg.sample(sc, r, progress=False)  # builds the kernels
                # a reporter that shows something, so that the sampler forecasts
                s = clcsg.sample(sc, r, progress=Reporter("json", stream=io.StringIO()))
            seen.pop("t0")
            out.append({"name": name, "samples": len(s), **seen})
    finally:
        sampler._Progress.__init__, sampler._Progress.chain = init, chain
    with open(path, "w") as f:
        json.dump(out, f, separators=(",", ":"))
    return out


def replay_history(run: dict, min_left: float = 0.1) -> dict:
    """Feed a recorded run (:func:`record_histories`) to a fresh
    :class:`~clcsg.sampling.forecast.Forecast` chain by chain, the chain's seconds shared by
    its levels' work as the sampler shares them, and judge the ETA it shows after each chain
    (the seconds left forecast, or none while it extrapolates too far: ``Forecast.eta``) over
    the second half of the run (:func:`judge`, with ``min_left`` of the run's
    seconds as the least left), and the fraction elapsed / (elapsed + forecast) held at its
    largest as the bar shows it (``final_fraction``: the last one's)."""
    from clcsg.sampling.forecast import Forecast

    fc = Forecast(run["estimate"], run["quad"], run["peak"], run["last"], run["max_levels"], run["roots"])
    points, t_last, shown = [], 0.0, 0.0
    for t, levels in run["chains"]:
        fc.add_chain(levels, t - t_last)
        t_last = t
        left = fc.seconds_left(levels[-1][3])
        shown = 1.0 if not levels[-1][3] else max(shown, min(t / (t + left), 0.999) if t + left > 0 else 0.0)
        points.append((t, fc.eta(levels[-1][3], left), shown))
    out = judge(points, points[-1][0], min_left * points[-1][0])
    out["final_fraction"] = points[-1][2]
    return out


def expected_counts(radii=(0.01, 0.002)) -> list:
    """expected / real samples on every example (the sponge aside at the smaller radius)."""
    import clcsg

    rows = []
    paths = sorted(glob.glob(os.path.join(EXAMPLES_DIR, "*.json")) + glob.glob(os.path.join(EXAMPLES_DIR, "*.csg"))
                   + glob.glob(os.path.join(ZOO_DIR, "*.json")))
    for path in paths:
        scene = clcsg.load(path)
        tape = scene.compile()
        diag = float(((tape.bound[1] - tape.bound[0]) ** 2).sum() ** 0.5)
        row = {"scene": os.path.relpath(path, EXAMPLES_DIR)}
        for rel in radii:
            if "menger" in path and rel < 0.01:
                continue
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                s = clcsg.sample(scene, rel * diag, progress=False)
            row[f"{rel:.1%}"] = s.stats["expected_samples"] / max(len(s), 1)
        rows.append(row)
    return rows


def measure(rounds: int, quick: bool) -> dict:
    env = environment_for_runs()
    cli = clcsg_command()
    folder = tempfile.mkdtemp(prefix="clcsg-progress-")
    runs = [r for r in RUNS if not quick or r[0] in QUICK]
    results = {name: [] for name, _, _ in runs}
    for _ in range(rounds):
        for name, scene, radius in runs:
            argv = cli + ["sample", scene_path(scene, folder), "-r", radius, "-o", os.path.join(folder, "x.ply"),
                          "--progress", "json"]
            results[name].append(measure_run(*record(argv, env)))
    return {"runs": [{"name": n, "scene": s, "radius": r, "rounds": results[n]} for n, s, r in runs],
            "expected": expected_counts((0.01,) if quick else (0.01, 0.002))}


def _f(x, spec=".2f"):
    return "-" if x is None else format(x, spec)


def table(result: dict) -> str:
    lines = ["| run | r | levels | bar s | ETA worst (2nd half) | ETA median | within 2x | monotone | expected/real |",
             "|---|---|---:|---|---|---|---|---|---:|"]
    for run in result["runs"]:
        rs = run["rounds"]
        lines.append(f"| {run['name']} | {run['radius']} | {rs[0]['levels']} | "
                     + " / ".join(_f(r["bar_s"], ".1f") for r in rs) + " | "
                     + " / ".join(_f(r.get("worst"), ".1f") + "x" for r in rs) + " | "
                     + " / ".join(_f(r.get("median_ratio")) for r in rs) + " | "
                     + " / ".join("yes" if r.get("within_2x") else "no" for r in rs) + " | "
                     + " / ".join("yes" if r["monotone"] else "NO" for r in rs) + " | "
                     + f"{rs[0]['expected_ratio']:.2f} |")
    within = sum(r.get("within_2x", False) for run in result["runs"] for r in run["rounds"])
    total = sum(len(run["rounds"]) for run in result["runs"])
    keys = [k for k in result["expected"][0] if k != "scene"]
    lines += ["", f"ETA within 2x over the second half: {within} of {total} runs (rounds separated by /)", "",
              "| example (expected / real samples) | " + " | ".join(f"r = {k}" for k in keys) + " |",
              "|---|" + "---:|" * len(keys)]
    for row in result["expected"]:
        lines.append(f"| {row['scene']} | " + " | ".join(_f(row.get(k)) for k in keys) + " |")
    return "\n".join(lines)


def run(quick: bool = False, device=None, rounds: int | None = None) -> dict:
    """Measure (``rounds`` of every run; 2, quick: 2 of 4 runs), write progress.json, print the
    tables.  ``device`` is not used: each process picks its device as ``clcsg`` does."""
    load = Load()
    result = measure(rounds or 2, quick)
    result["environment"] = load.into({"date": time.strftime("%Y-%m-%dT%H:%M:%S"), "cpus": os.cpu_count(),
                                       "clcsg": package_root(), "python": sys.version.split()[0],
                                       "git_commit": git_commit(), "git_dirty": git_dirty(),
                                       "timing": "wall time of JSON lines as they arrive on the pipe"})
    path = write("progress", result)
    print(table(result))
    print(f"wrote {path}")
    return result
