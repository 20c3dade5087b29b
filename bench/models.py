"""The model zoo benchmark: the paper's Table 2 sampling columns for six solids (``bench/zoo.py``)
of 3, 5, 5, 21, 31 and 80 unique quadrics at three splat sizes, the CSG tree and the DNF shape
of the tape side by side in the same run; then the everyday OpenSCAD parts of ``examples/``
and the level-3 Menger sponge at r = 1% of the bound's diagonal.

Per row (one model, size and shape): samples, sampling time (the whole ``clcsg.sample`` call,
compilation of the tape included; warm: one run at the large radius first builds the kernels
for the tape's register count, then the least of up to 100 runs, fewer once 8 s are spent),
its process CPU time (all threads: core-seconds, which other processes on a shared machine do
not inflate; the least of the same runs), the split into ``compile_s`` / ``subdivide_s`` /
``finish_s`` and the ``classify`` kernel's profiling time, distance queries, leaf distances
per query, prune evaluations, cells decided by pruning alone,
unresolved cells (dropped at the floor), tape lengths per level (mean and max over the cells of
a level; summarized as the mean over levels of the per-level mean, and the largest max), and
the ratio to the paper: sampling time x compute units / the paper's single-core time (the
paper's Table 2 column, one 4.8 GHz core), and the same with CPU time.

On PoCL's CPU device (not with ``--quick``) the medium tree rows of the zoo are timed again
in a child process with one PoCL worker thread (``one_thread`` in the JSON): the paper's
single core, without the contention of two threads.

Splat sizes are relative to the model: radius = diagonal of the scene bound times 1/50
(large), 1/150 (medium), 1/500 (small).  The everyday parts and the sponge use 1/100.  Where
the DNF does not fit (``clcsg.errors.LimitError``: the term limit, or the sampler's buffers)
the row records the reason (``dnf: term limit``) and only the tree shape is timed.  The DNF
rows of the parts and the sponge are not tried with ``--quick`` (their DNF compilation alone
takes 0.4-14 s before it hits a limit).

Rendering (splats against the ray tracer) is ``python -m bench render``.  ``--quick``: the
medium size only, one timed run per row (after the warm-up).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
import warnings


import clcsg
from clcsg.cl.device import get_context
from clcsg.errors import LimitError

from . import zoo
from .common import Load, diagonal, environment, environment_for_runs, fmt, sampling_record, time_sampling, write

SHAPES = ("tree", "dnf")


def limit_reason(err: Exception) -> str:
    msg = " ".join(str(err).split())
    if "DNF terms" in msg or "term limit" in msg or "terms, past the limit" in msg:
        return "dnf: term limit"
    if "buffer" in msg:
        return "dnf: sampler buffer limit"
    return "dnf: limit"


def measure(ctx, scene, radius, normal_form, repeats, budget, warm_radius=None) -> dict:
    """One row: :func:`bench.common.sampling_record` of a warm timing.  ``warm_radius``: build
    the kernels with one run at that (larger, cheaper) radius first; None: no warm-up (the
    kernels of this tape are already built in this process)."""
    first = None
    if warm_radius is not None:
        t0 = time.perf_counter()
        clcsg.sample(scene, warm_radius, device=ctx, normal_form=normal_form, progress=False)
        first = time.perf_counter() - t0
    ts = time_sampling(scene, radius, ctx, repeats=repeats, budget=budget, normal_form=normal_form, warm=False)
    rec = sampling_record(ts, ctx.info.compute_units)
    rec["warmup_s"] = first
    return rec


def tape_info(tape) -> dict:
    st = tape.stats
    return {"instructions": st.get("instructions"), "leaves": st.get("leaves"), "registers": st.get("registers"),
            "quadrics": st.get("quadrics"), "primitives": st.get("primitives"), "depth": st.get("depth"),
            "terms": st.get("terms"), "dnf_terms_estimate": st.get("dnf_terms")}


def shape_rows(ctx, scene, name, kind, sizes, repeats, budget, paper=None, try_dnf=True) -> tuple[dict, list]:
    """(model info, rows) of one scene: every size x both shapes (the DNF as far as it fits;
    ``try_dnf`` False: the tree only, the DNF rows say so)."""
    warnings.simplefilter("ignore")

    t0 = time.perf_counter()
    tree = scene.compile("tree")
    info = {"model": name, "kind": kind, "bound": tree.bound.tolist(), "diagonal": diagonal(tree.bound),
            "tree_compile_s": time.perf_counter() - t0, "tree": tape_info(tree)}
    dnf_error = None
    if not try_dnf:
        dnf_error = True
        info["dnf"] = None
        info["dnf_skipped"] = "dnf: not tried (--quick)"
        info["dnf_message"] = "--quick samples the everyday parts and the sponge with the tree shape only"
    else:
        try:
            t0 = time.perf_counter()
            dnf = scene.compile("dnf")
            info["dnf_compile_s"] = time.perf_counter() - t0
            info["dnf"] = tape_info(dnf)
        except LimitError as e:
            info["dnf_compile_s"] = time.perf_counter() - t0
            dnf_error = e
            info["dnf"] = None
            info["dnf_skipped"] = limit_reason(e)
            info["dnf_message"] = " ".join(str(e).split())
    diag = info["diagonal"]
    rows = []
    warmed = set()
    for size, frac in sizes.items():
        radius = diag * frac
        for nf in SHAPES:
            row = {"model": name, "kind": kind, "size": size, "radius": radius, "radius_over_diagonal": frac,
                   "normal_form": nf, "quadrics": info["tree"]["quadrics"]}
            if nf == "dnf" and dnf_error is not None:
                row.update(skipped=info["dnf_skipped"], message=info["dnf_message"])
                rows.append(row)
                continue
            warm = None if nf in warmed else max(radius, diag / 50)
            try:
                row.update(measure(ctx, scene, radius, nf, repeats, budget, warm))
            except LimitError as e:
                if nf == "tree":
                    raise
                row.update(skipped=limit_reason(e), message=" ".join(str(e).split()))
                rows.append(row)
                print(f"{name} {size} {nf}: {row['skipped']}", flush=True)
                continue
            warmed.add(nf)
            if paper is not None:
                p = paper(size)
                row["paper"] = p
                row["ratio_to_paper"] = row["sampling_s_times_cu"] / (1e-3 * p["sampling_ms"])
                row["cpu_ratio_to_paper"] = row["sampling_cpu_s"] / (1e-3 * p["sampling_ms"])
                row["cpu_p10_ratio_to_paper"] = row["sampling_cpu_p10_s"] / (1e-3 * p["sampling_ms"])
                row["queries_ratio_to_paper"] = row["distance_queries"] / p["distance_queries"]
            rows.append(row)
            print(_row_line(row), flush=True)
    return info, rows


def _row_line(r) -> str:
    extra = ""
    if r.get("ratio_to_paper"):
        extra = (f", x{r['ratio_to_paper']:.1f} the paper (CPU time x{r['cpu_ratio_to_paper']:.1f}, "
                 f"distance queries x{r['queries_ratio_to_paper']:.2f})")
    return (f"{r['model']} {r['size']} {r['normal_form']}: {r['samples']} samples, "
            f"{1e3 * r['sampling_s']:.1f} ms{extra}, {r['leaf_distances_per_query']:.2f} leaf distances per "
            f"query, {r['unresolved']} unresolved")


def run(quick=False, device=None):
    ctx = get_context(device)
    load = Load()
    warnings.simplefilter("ignore")
    sizes = {"medium": zoo.SIZES["medium"]} if quick else dict(zoo.SIZES)
    # the least of 10 moved 20-30% between runs on the 2-core VM, the least of 30 still 10-15%
    # (the lens: 4.69-5.29 ms of CPU); the budget keeps the slow rows short
    repeats = 1 if quick else 100
    budget = 0.0 if quick else 8.0
    models, rows = [], []
    for m in zoo.MODELS:
        scene = clcsg.Scene(m.build(), source=m.name)
        info, rr = shape_rows(ctx, scene, m.name, "zoo", sizes, repeats, budget,
                              paper=lambda size, name=m.name: zoo.paper_row(name, size))
        info.update(description=m.description, paper_quadrics=m.quadrics)
        models.append(info)
        rows += rr
    parts = {"1% of the diagonal": zoo.PART_RADIUS}
    for name in zoo.EVERYDAY + (zoo.SPONGE,):
        path = zoo.example_path(name, "csg")
        if not os.path.exists(path):
            print(f"{name}: {path} is missing; skipped")
            continue
        scene = clcsg.load(path)
        kind = "sponge" if name == zoo.SPONGE else "openscad part"
        info, rr = shape_rows(ctx, scene, name, kind, parts, repeats, budget, try_dnf=not quick)
        info["source"] = os.path.relpath(path, os.path.dirname(zoo.EXAMPLES_DIR))
        models.append(info)
        rows += rr
    one = None if quick or not is_pocl_cpu(ctx) else one_thread(device, repeats, budget)
    env = load.into(environment(ctx))
    payload = {
        "environment": env, "quick": bool(quick), "method": " ".join(__doc__.split()),
        "sizes": sizes, "part_radius_over_diagonal": zoo.PART_RADIUS, "models": models, "rows": rows,
        "paper": "Trettner & Kobbelt 2021, Table 2: sampling on one 4.8 GHz core",
        "targets": targets(rows, env["compute_units"]),
        "one_thread": one,
    }
    path = write("models", payload)
    print()
    print(table(payload))
    if one and "error" not in one:
        print("\nOne PoCL thread, medium tree, CPU time / the paper: "
              + ", ".join(f"{k} {v['cpu_ratio_to_paper']:.2f}x ({v['cpu_p10_ratio_to_paper']:.2f}x at the 10th "
                          "percentile)" for k, v in one.items()))
    elif one:
        print(f"\nOne PoCL thread: {one['error']}")
    print(f"\nwritten to {path}")
    return payload


def is_pocl_cpu(ctx) -> bool:
    """PoCL's CPU device, whose worker threads ``POCL_MAX_PTHREAD_COUNT`` caps."""
    return ctx.info.type == "cpu" and "portable computing language" in ctx.info.platform.lower()


def one_thread_cpu(device=None, repeats=100, budget=8.0, names=None) -> dict:
    """{zoo model: {"cpu_s", "cpu_ratio_to_paper", "cpu_p10_s", ...}}: the least (and the 10th
    percentile) process CPU time of a medium tree call in this process, as :func:`run` times
    it.  Meant for a process whose PoCL runs one worker thread (:func:`one_thread`)."""
    ctx = get_context(device)
    warnings.simplefilter("ignore")
    out = {}
    for m in zoo.MODELS:
        if names is not None and m.name not in names:
            continue
        scene = clcsg.Scene(m.build(), source=m.name)
        radius = zoo.SIZES["medium"] * diagonal(scene.compile("tree").bound)
        ts = time_sampling(scene, radius, ctx, repeats=repeats, budget=budget, warm=True)
        paper_s = 1e-3 * zoo.paper_row(m.name, "medium")["sampling_ms"]
        out[m.name] = {"cpu_s": ts["cpu_s"], "cpu_ratio_to_paper": ts["cpu_s"] / paper_s,
                       "cpu_p10_s": ts["cpu_p10_s"], "cpu_p10_ratio_to_paper": ts["cpu_p10_s"] / paper_s,
                       "runs": ts["runs"]}
    return out


def one_thread(device, repeats, budget, names=None) -> dict:
    """:func:`one_thread_cpu` in a child process with one PoCL worker thread
    (``POCL_MAX_PTHREAD_COUNT=1``, read when PoCL loads): the paper's setting, one core, without
    the two threads' contention for the output counters and the cells the other wrote, which
    moves the least CPU time of 100 calls by 5-10% between runs (the machine's own speed still
    drifts: the lens's least took 4.13-4.20 ms one evening hour and 4.8-5.0 ms the next).
    ``{"error": ...}`` if the child failed."""
    code = ("import json, sys; from bench.models import one_thread_cpu; "
            "print(json.dumps(one_thread_cpu(*json.loads(sys.argv[1]))))")
    args = json.dumps([device, repeats, budget, names])
    env = environment_for_runs()  # this clcsg first on the path
    bench_root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env["PYTHONPATH"] = os.pathsep.join([bench_root, env["PYTHONPATH"]])
    env["POCL_MAX_PTHREAD_COUNT"] = "1"
    done = subprocess.run([sys.executable, "-c", code, args], env=env, capture_output=True, text=True)
    if done.returncode != 0:
        return {"error": (done.stderr.strip().splitlines() or ["failed"])[-1]}
    return json.loads(done.stdout.strip().splitlines()[-1])


def targets(rows, cu) -> dict:
    """The issue's targets, checked on these rows."""
    zoo_rows = [r for r in rows if r["kind"] == "zoo" and not r.get("skipped")]
    tree = [r for r in zoo_rows if r["normal_form"] == "tree"]
    leaf = {r["model"]: max(x["leaf_distances_per_query"] for x in tree if x["model"] == r["model"]) for r in tree}
    med = {r["model"]: r["ratio_to_paper"] for r in tree if r["size"] == "medium"}
    sponge = [r for r in rows if r["kind"] == "sponge" and r["normal_form"] == "tree" and not r.get("skipped")]
    return {
        "max_leaf_distances_per_query_tree": leaf,
        "leaf_distances_at_most_3": bool(leaf) and all(v <= 3 for v in leaf.values()),
        "medium_time_x_cu_over_paper_tree": med,
        "medium_at_or_under_paper": bool(med) and all(v <= 1 for v in med.values()),
        "medium_cpu_over_paper_tree": {r["model"]: r["cpu_ratio_to_paper"] for r in tree if r["size"] == "medium"},
        "medium_cpu_p10_over_paper_tree": {r["model"]: r["cpu_p10_ratio_to_paper"] for r in tree
                                           if r["size"] == "medium"},
        "medium_queries_over_paper_tree": {r["model"]: r["queries_ratio_to_paper"] for r in tree
                                           if r["size"] == "medium"},
        "sponge_s": sponge[0]["sampling_s"] if sponge else None,
        "sponge_under_10_s": bool(sponge) and sponge[0]["sampling_s"] < 10,
    }


def table(payload) -> str:
    env = payload["environment"]
    cu = env["compute_units"]
    lines = [f"Sampling, tree vs DNF ({env['device']}, {cu} CUs; ms; 'x paper' = time x {cu} CUs / the paper's "
             f"single-core time, [paper ms])", "",
             "| model | size | samples [paper] | tree ms | DNF ms | tree x paper | DNF x paper | leaf dist./query "
             "tree / DNF | prune evals tree / DNF | tape mean / max tree | tape mean / max DNF | unresolved tree / DNF |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    rows = payload["rows"]
    keys = list(dict.fromkeys((r["model"], r["size"]) for r in rows))
    for model, size in keys:
        t = next((r for r in rows if r["model"] == model and r["size"] == size and r["normal_form"] == "tree"), {})
        d = next((r for r in rows if r["model"] == model and r["size"] == size and r["normal_form"] == "dnf"), {})
        p = t.get("paper")
        dskip = d.get("skipped")

        def dv(key, spec=".1f", scale=1.0, suffix=""):
            return dskip if dskip else fmt(d.get(key), spec, scale, suffix)

        samples = f"{t.get('samples', 0):,}" + (f" [{p['samples']:,}]" if p else "")
        paper_ms = f" [{p['sampling_ms']}]" if p else ""
        tm = lambda r: f"{r['tape_mean']['mean']:.1f} / {r['tape_max']['max']:.0f}"  # noqa: E731
        lines.append(
            f"| {model} | {size} | {samples} | {fmt(t.get('sampling_s'), '.1f', 1e3)}"
            f"{paper_ms} | {dv('sampling_s', '.1f', 1e3)} | "
            f"{fmt(t.get('ratio_to_paper'), '.1f', 1, 'x')} | {dv('ratio_to_paper', '.1f', 1, 'x') if p else '-'} | "
            f"{fmt(t.get('leaf_distances_per_query'), '.2f')} / {dv('leaf_distances_per_query', '.2f')} | "
            f"{fmt(t.get('prune_evaluations'), ',.0f')} / {dv('prune_evaluations', ',.0f')} | "
            f"{tm(t) if t else '-'} | {dskip if dskip else (tm(d) if d else '-')} | "
            f"{fmt(t.get('unresolved'), ',.0f')} / {dv('unresolved', ',.0f')} |")
    lines += ["", "Where the time goes (tree shape; ms): compile (Python), subdivide (level loop), of it the "
              "classify kernel, finish (reading the samples back, clip programs deduplicated)", "",
              "| model | size | total | compile | subdivide | classify kernel | finish | levels | queries | "
              "CPU time / wall |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if r["normal_form"] != "tree" or r.get("skipped"):
            continue
        lines.append(f"| {r['model']} | {r['size']} | {1e3 * r['sampling_s']:.1f} | {fmt(r['compile_s'], '.1f', 1e3)} | "
                     f"{fmt(r['subdivide_s'], '.1f', 1e3)} | {fmt(r['classify_kernel_s'], '.1f', 1e3)} | "
                     f"{fmt(r['finish_s'], '.1f', 1e3)} | {r['levels']} | {r['distance_queries']:,} | "
                     f"{r['sampling_cpu_s'] / r['sampling_s']:.2f} |")
    t = payload.get("targets", {})
    lines += ["", f"Targets: leaf distances per query <= 3 on every zoo model: {t.get('leaf_distances_at_most_3')}; "
              f"medium time x CUs <= paper: {t.get('medium_at_or_under_paper')}; sponge < 10 s: "
              f"{t.get('sponge_under_10_s')}"]
    return "\n".join(lines)
