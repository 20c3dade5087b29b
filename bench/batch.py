"""Batch throughput: the 1,000 random programs of ``examples/random_batch.py`` (``--quick``:
50) sampled at r = 1% of each bound's diagonal, Parquet output, one configuration after the
other, each into a fresh folder:

* ``single process``: one Python process runs the scene tasks one after the other
  (:func:`clcsg.batching.task.run_job` and the atomic writes, no engine);
* ``local pool``: ``clcsg.batch`` with the local process pool of N workers;
* ``dask``: ``clcsg.batch`` on a Dask LocalCluster of N worker processes (one thread each).

Per-core throughput: every process is limited to one PoCL thread (``POCL_MAX_PTHREAD_COUNT=1``)
so that a worker is one core.  Two measures of it: *wall*, the engines' scenes per second per
worker over the single process's (the parallel efficiency: it needs the cores to be free),
and *CPU*, scenes per CPU second of every process of the configuration (the driver, the
workers, Dask's scheduler and nannies: ``getrusage`` of this process and its children) over
the single process's, which other programs on a shared machine do not inflate: the engine's
overhead in core-seconds.  Target: >= 90% (overhead < 10%).  Two processes running at once
on this machine's two cores are slower per scene than one alone (shared caches and memory,
other programs): the row of plain single processes side by side, each on every other scene
with no engine, measures that, and the engines are also compared with it (the engine's own
overhead); the local pool with one worker compares with the single process directly.  A last
single-process row lets PoCL use every core (the everyday one-process figure).  Both include each engine's start
(spawning workers, importing, opening devices) and the manifest.  The machine is shared: the
load average is recorded at the start and the end.
"""

from __future__ import annotations

import json
import os
import resource
import runpy
import subprocess
import sys
import tempfile
import time
import warnings

from .common import Load, environment, write

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RADIUS = "1%"
ONE_THREAD = {"POCL_MAX_PTHREAD_COUNT": "1"}
WORKERS = 2
#: programs sampled once before the timed runs (their kernels are built and cached on disk)
WARM = 100


def single(source: str, radius: str, outdir: str, device=None) -> dict:
    """Run every scene of ``source`` in this process; totals as a dict."""
    from clcsg.batching import inputs
    from clcsg.batching.options import Options, Radius
    from clcsg.batching.outputs import publish_files, stage_files
    from clcsg.batching.task import init_worker, run_job

    warnings.simplefilter("ignore")
    t0 = time.perf_counter()
    init_worker(device)
    options = Options(Radius.parse(radius), device=device)
    samples = ok = 0
    for job in inputs.jobs(source):
        res = run_job(job, options)
        publish_files(stage_files(outdir, res.files))  # as the driver writes them
        ok += res.row["status"] == "ok"
        samples += int(res.row.get("samples") or 0)
    return {"seconds": time.perf_counter() - t0, "ok": ok, "samples": samples}


def _cpu() -> float:
    """CPU seconds of this process and its waited-for children (user + system)."""
    me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def _measured(fn):
    """fn's result with ``cpu_s``: the CPU seconds it cost (all processes it started)."""
    c0 = _cpu()
    r = fn()
    r["cpu_s"] = _cpu() - c0
    return r


def _start_single(source, outdir, device, env):
    code = ("import json, sys; from bench.batch import single; "
            f"print(json.dumps(single({source!r}, {RADIUS!r}, {outdir!r}, {device!r})))")
    return subprocess.Popen([sys.executable, "-c", code], cwd=ROOT, env={**os.environ, **env},
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)


def _result(proc) -> dict:
    out, _ = proc.communicate()
    if proc.returncode:
        raise RuntimeError(f"the single-process run failed (exit {proc.returncode})")
    return json.loads(out.strip().splitlines()[-1])


def _single_subprocess(source, outdir, device, env) -> dict:
    return _result(_start_single(source, outdir, device, env))


def _side_by_side(source, outdir, device, env, k) -> dict:
    """``k`` plain single processes at once, each on every k-th scene (manifest files): what
    the machine gives k processes without any engine."""
    files = sorted(os.listdir(source))
    t0 = time.perf_counter()
    procs = []
    for i in range(k):
        part = os.path.join(outdir + f"_part{i}.txt")
        os.makedirs(os.path.dirname(part), exist_ok=True)
        with open(part, "w") as f:
            f.write("".join(os.path.join(source, name) + "\n" for name in files[i::k]))
        procs.append(_start_single(part, outdir, device, env))
    parts = [_result(p) for p in procs]
    return {"seconds": time.perf_counter() - t0, "ok": sum(r["ok"] for r in parts),
            "samples": sum(r["samples"] for r in parts)}


def _engine(source, outdir, device, env, **kw) -> dict:
    import clcsg

    saved = {k: os.environ.get(k) for k in env}
    os.environ.update(env)  # inherited by the worker processes
    try:
        t0 = time.perf_counter()
        rows = clcsg.batch(source, RADIUS, outdir, device=device, progress=False, **kw).to_pylist()
        seconds = time.perf_counter() - t0
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    ok = [r for r in rows if r["status"] == "ok"]
    return {"seconds": seconds, "ok": len(ok), "samples": sum(r["samples"] for r in ok),
            "task_seconds": sum(r["seconds"] for r in rows if r["seconds"] is not None),
            "task_cpu_s": sum(r["cpu_s"] for r in rows if r["cpu_s"] is not None)}


def _pct(row, key) -> str:
    return f"{100 * row[key]:.0f}%" if key in row else "-"


def run(quick=False, device=None):
    from clcsg.cl.device import get_context

    ctx = get_context(device)
    load = Load()
    n = 50 if quick else int(os.environ.get("CLCSG_BENCH_BATCH_N", "1000"))
    workers = WORKERS
    example = runpy.run_path(os.path.join(ROOT, "examples", "random_batch.py"))
    rows = []
    with tempfile.TemporaryDirectory(prefix="clcsg-bench-batch-") as tmp:
        source = example["write_programs"](tmp, n, seed=0)
        # warm-up: the first programs (the same seed) build the kernels of the register counts
        warm = example["write_programs"](os.path.join(tmp, "warm"), min(n, WARM), seed=0)
        _single_subprocess(warm, os.path.join(tmp, "warm_out"), device, ONE_THREAD)
        configs = [
            ("single process", 1, "1 PoCL thread", lambda o: _single_subprocess(source, o, device, ONE_THREAD)),
            (f"{workers} single processes side by side", workers, "1 PoCL thread each",
             lambda o: _side_by_side(source, o, device, ONE_THREAD, workers)),
            ("local pool", 1, "1 PoCL thread", lambda o: _engine(source, o, device, ONE_THREAD, workers=1)),
            ("local pool", workers, "1 PoCL thread each", lambda o: _engine(source, o, device, ONE_THREAD,
                                                                            workers=workers)),
            ("dask LocalCluster", workers, "1 PoCL thread each",
             lambda o: _engine(source, o, device, ONE_THREAD, dask=f"local:{workers}")),
            ("single process", 1, "PoCL on every core", lambda o: _single_subprocess(source, o, device, {})),
        ]
        for k, (name, procs, threads, fn) in enumerate(configs):
            r = _measured(lambda: fn(os.path.join(tmp, f"out{k}")))
            rows.append({"config": name, "processes": procs, "threads": threads, "scenes": n, **r,
                         "scenes_per_s": n / r["seconds"], "samples_per_s": r["samples"] / r["seconds"]})
    base, base_cpu = rows[0]["scenes_per_s"], rows[0]["cpu_s"]
    pair = rows[1]
    for r in rows:
        r["scenes_per_s_per_process"] = r["scenes_per_s"] / r["processes"]
        r["efficiency_vs_single"] = r["scenes_per_s_per_process"] / base
        r["scenes_per_cpu_s"] = n / r["cpu_s"]
        r["cpu_efficiency_vs_single"] = base_cpu / r["cpu_s"]
        if r["processes"] == pair["processes"]:  # against plain processes side by side: the engine's overhead
            r["efficiency_vs_side_by_side"] = r["scenes_per_s"] / pair["scenes_per_s"]
            r["cpu_efficiency_vs_side_by_side"] = pair["cpu_s"] / r["cpu_s"]
    totals = {r["samples"] for r in rows}
    payload = {"environment": load.into(environment(ctx)), "quick": bool(quick), "programs": n, "radius": RADIUS,
               "method": " ".join(__doc__.split()), "same_samples_everywhere": len(totals) == 1, "rows": rows}
    path = write("batch", payload)
    lines = ["| configuration | processes | PoCL threads | scenes | ok | samples | wall (s) | scenes/s | samples/s | "
             "per process vs single (wall) | CPU s | scenes per CPU s vs single | vs side by side (wall / CPU) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['config']} | {r['processes']} | {r['threads']} | {r['scenes']} | {r['ok']} | "
                     f"{r['samples']:,} | {r['seconds']:.1f} | {r['scenes_per_s']:.2f} | {r['samples_per_s']:,.0f} | "
                     f"{100 * r['efficiency_vs_single']:.0f}% | {r['cpu_s']:.1f} | "
                     f"{100 * r['cpu_efficiency_vs_single']:.0f}% | {_pct(r, 'efficiency_vs_side_by_side')} / "
                     f"{_pct(r, 'cpu_efficiency_vs_side_by_side')} |")
    print("\n".join(lines))
    print(f"\nwrote {path}")
