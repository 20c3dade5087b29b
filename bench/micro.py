"""Microbenchmarks: the paper's Table 1 (operations per second) on the selected OpenCL device.

Method (also stored in the JSON as ``method``)
----------------------------------------------
The evaluation rows (Q(x), N(x), h(x, y), distortion, minimum distortion over a region,
quadric-line intersection, conservative distance d(x0)) run the package's own device functions
(``bench/kernels/micro.cl`` includes ``clcsg/kernels/sampler.cl`` and ``quadric.h``).  Every
work-item loads one of eight quadrics of different types (sphere, rotated ellipsoid, cylinder,
cone, hyperboloids of one and two sheets, paraboloid, plane) and its principal frame into
registers and derives a point in [-1, 1]^3 from its global id.  It then runs K = 256
#: the paper's single-core clock (i9-9900K turbo)
PAPER_GHZ = 4.8
iterations and sums the results; the sum is the only store, so memory traffic is one quadric
load and one store per 256 operations.  Two modes: *throughput* (the paper's kind of figure):
iteration k evaluates at p.x = x0 + k eps, independent iterations as in a loop over an array,
but with an input that changes with k, so the compiler can neither hoist the operation out of
the loop nor drop it; *latency*: the result perturbs the next input (p.x += eps v), one
dependent chain per work-item.  ``eps`` is a kernel argument.  The time comes from OpenCL
profiling events (kernel start to end).  Each launch takes at least 100 ms (the global size is
calibrated per kernel).  The time of a ``baseline`` kernel, the same loop with a trivial
operation (p.x + p.y), measured at a size that also takes >= 100 ms and scaled to the same
number of iterations, is subtracted.  Each figure is the best of several launches.
Throughput = work-items * K / (t_op - t_baseline).  "Per CU" divides by the device's compute
units (on PoCL's CPU device one CU is one core), which is how the figures compare with the
paper's single 4.8 GHz core.  Because the machine is shared, the process's CPU time during
each launch is recorded too: "per core-second" = operations / (CPU seconds of the op launch -
CPU seconds of the baseline), which does not depend on how many cores other processes took.

The sampling rows run ``clcsg.sample`` on a single quadric: a plane clipped to the scene bound
[-1, 1]^3 (the paper's "no subdivision" case: the root cells are filled at once) and a unit
sphere ("with subdivision").  They report samples per second of the whole call, of
``stats['subdivide_s']`` (the level loop: classify launches and their read-backs), and of the
``classify`` kernel alone (summed profiling events of its launches).

``python -m bench micro [--quick] [--device D]``; ``--quick``: fewer repeats, float only when
the device has no fp64, smaller sampling radii.
"""

from __future__ import annotations

import contextlib
import math
import os
import re
import time
import warnings

import numpy as np

import clcsg
from clcsg.cl import programs
from clcsg.cl.device import get_context
from clcsg.model.quadric import Quadric

from .common import environment, write

KERNELS = os.path.join(os.path.dirname(__file__), "kernels")

K = 256
#: the paper's single-core clock (i9-9900K turbo)
PAPER_GHZ = 4.8
#: a launch must take at least this long (seconds) to be measured
MIN_LAUNCH = 0.1

#: paper Table 1, one 4.8 GHz core: row -> (ops/s low, ops/s high)
PAPER = {
    "quadric value Q(x)": (315e6, 315e6),
    "quadric normal N(x)": (220e6, 220e6),
    "heightfield value h(x, y)": (1000e6, 1000e6),
    "heightfield distortion delta(x, y)": (625e6, 625e6),
    "min distortion over a region": (150e6, 150e6),
    "quadric-line intersection": (53e6, 53e6),
    "conservative distance d(x0)": (130e6, 130e6),
    "sampling: single quadric, no subdivision": (135e6, 135e6),
    "sampling: single quadric, with subdivision": (40e6, 70e6),
}

OPS = [
    ("quadric value Q(x)", "op_value"),
    ("quadric normal N(x)", "op_normal"),
    ("heightfield value h(x, y)", "op_height"),
    ("heightfield distortion delta(x, y)", "op_distortion"),
    ("min distortion over a region", "op_min_distortion"),
    ("quadric-line intersection", "op_intersect"),
    ("conservative distance d(x0)", "op_distance"),
]


def method_text() -> str:
    return " ".join(__doc__.split("Method (also stored in the JSON as ``method``)")[1]
                    .split("The sampling rows")[0].replace("-" * 46, "").split())


def sampling_text() -> str:
    return " ".join(("The sampling rows" + __doc__.split("The sampling rows")[1].split("``python -m")[0]).split())


# -- quadrics -------------------------------------------------------------------------------------


def quadrics() -> list[Quadric]:
    rot = clcsg.model.csg.rotation_matrix((1, 2, 3), 35.0)
    return [
        Quadric.sphere((0.1, 0.0, -0.1), 0.8),
        Quadric.ellipsoid((0.0, 0.1, 0.0), (0.9, 0.6, 0.4), rotation=rot),
        Quadric.cylinder((1, 1, 0), 0.5, (0.0, 0.0, 0.1)),
        Quadric.cone((0.0, 0.0, -0.2), (0, 1, 1), 0.7),
        Quadric.hyperboloid_one_sheet((0, 0, 0), (1, 0, 1), (0.4, 0.5, 0.6)),
        Quadric.hyperboloid_two_sheets((0, 0, 0), (0, 0, 1), (0.5, 0.5, 0.3)),
        Quadric.elliptic_paraboloid((0, 0, -0.8), (0, 0, 1), (0.6, 0.7)),
        Quadric.half_space((1, 2, 3), 0.2),
    ]


def pack_quadrics(qs, real):
    from clcsg.compile.frames import principal_frame
    from clcsg.cl.records import quadric_dtype
    from clcsg.sampling.sampler import frame_records

    rec = np.zeros(len(qs), dtype=quadric_dtype(real))
    for i, q in enumerate(qs):
        rec["coef"][i] = q.coefficients()
        rec["lam_min"][i], rec["lam_max"][i] = q.eigenvalue_range()
    return rec, frame_records([principal_frame(q) for q in qs], real)


def build_micro(ctx, real, dependent=False):
    """The program of ``bench/kernels/micro.cl`` for ``real`` (float32 / float64)."""
    import pyopencl as cl

    with open(os.path.join(KERNELS, "micro.cl"), encoding="utf-8") as f:
        src = f.read()
    opts = programs.real_options(real) + [f"-DDEPENDENT={int(bool(dependent))}", "-DMASK_WORDS=1", "-I", programs.package_dir("cl/include"), "-I", programs.package_dir("sampling"), "-I", programs.package_dir("rendering"), "-I", KERNELS]
    return cl.Program(ctx.ctx, src).build(options=opts)


# -- timing helpers -------------------------------------------------------------------------------


def event_seconds(ev) -> float:
    ev.wait()
    return 1e-9 * (ev.profile.end - ev.profile.start)


@contextlib.contextmanager
def kernel_events():
    """Record the profiling event of every kernel launched through ``pyopencl.Kernel.__call__``
    inside the block: yields a list of (kernel name, event)."""
    import pyopencl as cl

    log = []
    original = cl.Kernel.__call__

    def traced(self, *args, **kwargs):
        ev = original(self, *args, **kwargs)
        log.append((self.function_name, ev))
        return ev

    cl.Kernel.__call__ = traced
    try:
        yield log
    finally:
        cl.Kernel.__call__ = original


def kernel_seconds(log, name=None) -> float:
    return sum(event_seconds(ev) for n, ev in log if name is None or n == name)


class Runner:
    """Launches the micro kernels of one precision and mode at calibrated sizes."""

    WG = 64

    def __init__(self, ctx, real, dependent):
        import pyopencl as cl

        self.cl = cl
        self.ctx = ctx
        self.real = np.dtype(real)
        self.dependent = bool(dependent)
        self.prg = build_micro(ctx, real, dependent)
        self.kernels = {}
        rec, fr = pack_quadrics(quadrics(), real)
        mf = cl.mem_flags
        self.nq = len(rec)
        self.qbuf = cl.Buffer(ctx.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=rec)
        self.fbuf = cl.Buffer(ctx.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=fr)
        self.out = None
        self.checksum = {}
        # latency: a tiny perturbation by the result; throughput: inputs march by eps per step
        self.eps = 1e-9 if self.dependent else 1e-3

    def launch(self, kernel, n) -> tuple[float, float]:
        """(event seconds, process CPU seconds) of one launch of ``n`` work-items."""
        cl = self.cl
        if self.out is None or self.out.size < n * self.real.itemsize:
            self.out = cl.Buffer(self.ctx.ctx, cl.mem_flags.WRITE_ONLY, n * self.real.itemsize)
        k = self.kernels.get(kernel)
        if k is None:
            k = self.kernels[kernel] = cl.Kernel(self.prg, kernel)
        self.ctx.queue.finish()
        c0 = time.process_time()
        ev = k(self.ctx.queue, (n,), (self.WG,), self.qbuf, self.fbuf, np.int32(self.nq), np.int32(K),
               self.real.type(self.eps), self.real.type(0.05), self.out)
        ev.wait()
        cpu = time.process_time() - c0
        t = event_seconds(ev)
        res = np.empty(min(n, 4096), dtype=self.real)
        cl.enqueue_copy(self.ctx.queue, res, self.out)
        self.checksum[kernel] = float(np.nansum(res))
        return t, cpu

    def calibrate(self, kernel) -> int:
        """A global size whose launch takes >= 1.5 MIN_LAUNCH."""
        n = self.WG * 64
        self.launch(kernel, n)  # warm-up
        while True:
            t, _ = self.launch(kernel, n)
            if t >= 1.5 * MIN_LAUNCH:
                return n
            grow = 2 * MIN_LAUNCH / max(t, 1e-6)
            n = int(min(max(2.0, grow), 64.0) * n) // self.WG * self.WG

    def best(self, kernel, n, repeats) -> tuple[float, float]:
        """(best event seconds, best CPU seconds) over ``repeats`` launches."""
        runs = [self.launch(kernel, n) for _ in range(repeats)]
        return min(t for t, _ in runs), min(c for _, c in runs)


#: latency of a double-precision FMA in cycles (Intel since Skylake, AMD since Zen)
FMA_LATENCY = 4


def measure_clock(ctx, repeats) -> dict:
    """Effective core clock from a dependent FMA chain: GHz = 4 cycles / ns per FMA (per
    core-second of CPU time, so other processes on the machine do not distort it)."""
    import pyopencl as cl

    r = Runner(ctx, np.float64 if ctx.info.fp64 else np.float32, False)
    k = cl.Kernel(r.prg, "fma_chain")
    n_items, chain = 256, 1 << 20
    out = cl.Buffer(ctx.ctx, cl.mem_flags.WRITE_ONLY, n_items * r.real.itemsize)
    best_wall = best_cpu = float("inf")
    for _ in range(repeats + 1):
        ctx.queue.finish()
        c0 = time.process_time()
        ev = k(ctx.queue, (n_items,), (r.WG,), np.int32(chain), r.real.type(0.999999), r.real.type(1e-7), out)
        ev.wait()
        best_cpu = min(best_cpu, time.process_time() - c0)
        best_wall = min(best_wall, event_seconds(ev))
    fmas = n_items * chain
    ns_cpu = 1e9 * best_cpu / fmas
    ns_wall_cu = 1e9 * best_wall * ctx.info.compute_units / fmas
    return {"fma_latency_cycles": FMA_LATENCY, "ns_per_fma_per_core": ns_cpu, "ns_per_fma_per_cu_wall": ns_wall_cu,
            "clock_ghz": FMA_LATENCY / ns_cpu, "clock_ghz_wall": FMA_LATENCY / ns_wall_cu}


def measure_ops(ctx, real, dependent, repeats) -> list[dict]:
    r = Runner(ctx, real, dependent)
    cu = ctx.info.compute_units
    n_base = r.calibrate("baseline")
    rows = []
    for name, kernel in OPS:
        n = r.calibrate(kernel)
        t_op, c_op = r.best(kernel, n, repeats)
        nb = max(n, n_base)
        t_base, c_base = (v * n / nb for v in r.best("baseline", nb, repeats))
        ops = n * K
        net, net_cpu = t_op - t_base, c_op - c_base
        # None: the difference to the baseline was lost in timing noise (write valid JSON)
        rate = ops / net if net > 0 else None
        rate_cpu = ops / net_cpu if net_cpu > 0 else None
        inv = lambda x, scale=1.0: None if x is None else scale / x  # noqa: E731
        lo, hi = PAPER[name]
        rows.append({
            "operation": name, "kernel": kernel, "precision": "double" if r.real == np.float64 else "float",
            "mode": "latency" if dependent else "throughput",
            "work_items": n, "iterations": K, "launch_s": t_op, "baseline_s": t_base,
            "launch_cpu_s": c_op, "baseline_cpu_s": c_base, "cores_busy": c_op / t_op,
            "ops_per_s": rate, "ns_per_op": inv(rate, 1e9),
            "ops_per_s_per_cu": None if rate is None else rate / cu, "ns_per_op_per_cu": inv(rate, 1e9 * cu),
            "ops_per_core_s": rate_cpu, "ns_per_op_per_core": inv(rate_cpu, 1e9),
            "paper_ops_per_s_core": lo, "paper_ns_per_op": 1e9 / lo,
            "ratio_per_cu_to_paper": None if rate is None else rate / cu / lo,
            "ratio_per_core_s_to_paper": None if rate_cpu is None else rate_cpu / lo,
            "baseline_ns_per_iteration_per_cu": 1e9 * t_base * cu / ops,
            "checksum": r.checksum.get(kernel),
        })
    return rows


# -- the distance query of eq. 22 on the zoo models ----------------------------------------------


def measure_queries(ctx, repeats, models=None, K=8) -> list[dict]:
    """Time of one ``csg_distance`` (eq. 22) evaluation at the medium-size sample positions of
    zoo models, with ``enough`` = 4 r (a fine cell) and infinity (a root cell), per core-second
    of CPU time, beside the replayed count of literal distances it computes (models.query_cost)."""
    import pyopencl as cl

    from clcsg.cl.records import SceneBuffers
    from clcsg.sampling.sampler import task_dtype

    from . import models as models_mod
    from . import zoo

    real = np.dtype(ctx.real_dtype)
    api = 2 if re.search(r"csg_distance\([^)]*task_terms", programs.source("sampling/sampler.cl")) else 1
    with open(os.path.join(KERNELS, "query.cl"), encoding="utf-8") as f:
        src = f.read()
    opts = programs.real_options(real) + [f"-DQUERY_API={api}", "-DMASK_WORDS=1", "-I", programs.package_dir("cl/include"), "-I", programs.package_dir("sampling"), "-I", programs.package_dir("rendering")]
    try:
        kern = cl.Kernel(cl.Program(ctx.ctx, src).build(options=opts), "op_csg_distance")
    except cl.Error as e:  # the sampler's internals changed under the benchmark
        print(f"distance query benchmark skipped: bench/kernels/query.cl does not build ({str(e).splitlines()[0]})")
        return []
    rows = []
    for m in zoo.MODELS:
        if models is not None and m.name not in models:
            continue
        shape = m.build()
        dnf = clcsg.Scene(shape).normalize()
        diag = float(np.linalg.norm(dnf.bound[1] - dnf.bound[0]))
        radius = diag / 150
        s = clcsg.sample(shape, radius, device=ctx, progress=False)
        rng = np.random.default_rng(0)
        idx = rng.choice(len(s), size=min(len(s), 4096), replace=False)
        packed = s.packed
        # csg_distance reads the task's quadric and polarity (and, with QUERY_API 2, its term
        # list, which is the same for every plane and sheet of a literal group)
        if api == 2:
            from clcsg.sampling.sampler import analyse, root_tasks

            _rec, frames = analyse(packed)
            all_tasks, _roots, _glits, task_terms = root_tasks(dnf, packed, frames)[:4]
            first = {}
            for k in range(len(all_tasks)):
                first.setdefault((int(all_tasks["quadric"][k]), int(all_tasks["sign"][k])), k)
            tasks = all_tasks[[first[(int(s.quadrics[i]), int(s.signs[i]))] for i in idx]]
        else:
            tasks = np.zeros(len(idx), dtype=task_dtype(real))
            tasks["quadric"] = s.quadrics[idx]
            tasks["sign"] = s.signs[idx]
            task_terms = np.zeros(1, np.int32)
        pts = np.ascontiguousarray((s.positions[idx] - packed.origin).astype(real))
        sb = SceneBuffers(ctx, packed)
        mf = cl.mem_flags
        tbuf = cl.Buffer(ctx.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(tasks))
        ttbuf = cl.Buffer(ctx.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(task_terms, np.int32))
        pbuf = cl.Buffer(ctx.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=pts)
        cost = {"fine_cell": models_mod.query_cost(dnf, s, 4 * radius), "root_cell": models_mod.query_cost(dnf, s, np.inf)}
        for label, enough in (("fine_cell", 4 * radius), ("root_cell", np.inf)):
            n = 4096
            out = cl.Buffer(ctx.ctx, mf.WRITE_ONLY, n * real.itemsize)

            def launch(nn):
                ctx.queue.finish()
                c0 = time.process_time()
                ev = kern(ctx.queue, (nn,), (Runner.WG,), sb.quadrics, sb.literals, sb.terms, np.int32(sb.n_terms),
                          ttbuf, tbuf, pbuf, np.int32(len(idx)), np.int32(K), real.type(enough), out)
                ev.wait()
                return event_seconds(ev), time.process_time() - c0

            launch(Runner.WG)
            while True:
                if out.size < n * real.itemsize:
                    out = cl.Buffer(ctx.ctx, mf.WRITE_ONLY, n * real.itemsize)
                t, _ = launch(n)
                if t >= MIN_LAUNCH or n >= 1 << 22:
                    break
                n = int(min(max(2.0, 1.5 * MIN_LAUNCH / max(t, 1e-6)), 16.0) * n) // Runner.WG * Runner.WG
            runs = [launch(n) for _ in range(repeats)]
            t, c = min(x for x, _ in runs), min(y for _, y in runs)
            q = n * K
            lit = cost[label]["index"]["literals_per_query"]
            rows.append({"model": m.name, "query_api": api, "quadrics": dnf.n_quadrics, "terms": dnf.n_terms,
                         "literals": sum(len(tt) for tt in dnf.terms), "cell": label, "enough": float(enough),
                         "queries": q, "launch_s": t, "cpu_s": c, "ns_per_query_per_cu": 1e9 * t * ctx.info.compute_units / q,
                         "ns_per_query_per_core": 1e9 * c / q, "replayed_literals_per_query": lit,
                         "replayed_terms_per_query": cost[label]["index"]["terms_per_query"],
                         "ns_per_literal_per_core": 1e9 * c / q / max(lit, 1)})
            print(f"query {m.name} {label}: {1e9 * c / q:.0f} ns per query per core, {lit:.1f} literals", flush=True)
    return rows


# -- sampling rows --------------------------------------------------------------------------------


def sampling_scenes():
    bound = np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])
    plane = clcsg.Scene(clcsg.halfspace((0, 0, 1), 0.0), bound=bound, source="plane in [-1,1]^3")
    return [
        ("sampling: single quadric, no subdivision", "plane z = 0 in [-1, 1]^3", plane),
        ("sampling: single quadric, with subdivision", "unit sphere", clcsg.Scene(clcsg.sphere(1.0), source="sphere")),
    ]


def measure_sampling(ctx, radii, repeats) -> list[dict]:
    cu = ctx.info.compute_units
    rows = []
    warnings.simplefilter("ignore")
    for row, what, scene in sampling_scenes():
        clcsg.sample(scene, 0.05, device=ctx)  # build the program
        for r in radii:
            best = None
            for _ in range(repeats):
                with kernel_events() as log:
                    c0, t0 = time.process_time(), time.perf_counter()
                    s = clcsg.sample(scene, r, device=ctx, progress=False)
                    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
                cand = (wall, s.stats, kernel_seconds(log, "classify"), kernel_seconds(log, "finish"), cpu)
                if best is None or cand[0] < best[0]:
                    best = cand
            wall, st, t_classify, t_finish, cpu = best
            n = st["samples"]
            lo, hi = PAPER[row]
            rows.append({
                "operation": row, "scene": what, "radius": r, "samples": n, "levels": st["levels"],
                "distance_queries": st["distance_queries"], "buffer_growths": st.get("buffer_growths"),
                "total_s": wall, "subdivide_s": st["subdivide_s"], "classify_kernel_s": t_classify,
                "finish_s": st["finish_s"], "finish_kernel_s": t_finish, "normalize_s": st["normalize_s"],
                "analyse_s": st["analyse_s"],
                "cpu_s": cpu, "samples_per_core_s": n / cpu,
                "samples_per_s": n / wall, "samples_per_s_subdivide": n / st["subdivide_s"],
                "samples_per_s_classify_kernel": n / t_classify if t_classify > 0 else None,
                "ns_per_sample_per_cu_subdivide": 1e9 * cu * st["subdivide_s"] / n,
                "ns_per_sample_per_cu_kernel": 1e9 * cu * t_classify / n if t_classify > 0 else None,
                "paper_samples_per_s_core": [lo, hi],
                "ratio_per_cu_to_paper_subdivide": n / st["subdivide_s"] / cu / hi,
                "ratio_per_core_s_to_paper_whole_call": n / cpu / hi,
                "ratio_per_cu_to_paper_kernel": (n / t_classify / cu / hi) if t_classify > 0 else None,
            })
    return rows


# -- report ---------------------------------------------------------------------------------------


def _rate(x) -> str:
    if x is None or not math.isfinite(x):
        return "-"
    if x >= 1e9:
        return f"{x / 1e9:.2f} G"
    return f"{x / 1e6:.1f} M"


def table(payload) -> str:
    env = payload["environment"]
    cu = env["compute_units"]
    lines = [f"Operations (K = {K} iterations per work-item, baseline subtracted; {env['device']}, {cu} CUs; "
             f"load average at start {env.get('loadavg_start', '?')})", "",
             "| operation | precision | mode | ops/s (device) | ns/op (device) | ops/s per CU | ns/op per CU | "
             "ops per core-second | cycles/op | paper (1 core) | paper ns/op | paper cycles/op | "
             "per CU / paper | per core-s / paper |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    ghz = payload["clock"]["clock_ghz"]
    def f(x, fmt, scale=1.0, suffix=""):
        return "-" if x is None or not math.isfinite(x) else f"{x * scale:{fmt}}{suffix}"

    for r in payload["operations"]:
        lines.append(f"| {r['operation']} | {r['precision']} | {r['mode']} | {_rate(r['ops_per_s'])} | "
                     f"{f(r['ns_per_op'], '.2f')} | {_rate(r['ops_per_s_per_cu'])} | {f(r['ns_per_op_per_cu'], '.2f')} | "
                     f"{_rate(r['ops_per_core_s'])} | {f(r['ns_per_op_per_core'], '.1f', ghz)} | "
                     f"{_rate(r['paper_ops_per_s_core'])} | {r['paper_ns_per_op']:.2f} | "
                     f"{r['paper_ns_per_op'] * PAPER_GHZ:.1f} | {f(r['ratio_per_cu_to_paper'], '.2f', 1, 'x')} | "
                     f"{f(r['ratio_per_core_s_to_paper'], '.2f', 1, 'x')} |")
    lines += ["", "Sampling a single quadric (clcsg.sample; samples/s)", "",
              "| row | scene | r | samples | whole call | whole call per core-s | subdivide_s | classify kernel | "
              "ns/sample per CU (subdivide / kernel) | paper (1 core) | per CU / paper (subdivide / kernel) |",
              "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in payload["sampling"]:
        lo, hi = r["paper_samples_per_s_core"]
        paper = _rate(lo) if lo == hi else f"{lo / 1e6:g}-{hi / 1e6:g} M"
        kern = r["ns_per_sample_per_cu_kernel"]
        lines.append(
            f"| {r['operation'].split(': ')[1]} | {r['scene']} | {r['radius']:g} | {r['samples']:,} | "
            f"{_rate(r['samples_per_s'])} | {_rate(r['samples_per_core_s'])} | {_rate(r['samples_per_s_subdivide'])} | "
            f"{_rate(r['samples_per_s_classify_kernel'])} | "
            f"{r['ns_per_sample_per_cu_subdivide']:.1f} / {kern:.1f} | {paper} | "
            f"{r['ratio_per_cu_to_paper_subdivide']:.2f}x / {r['ratio_per_cu_to_paper_kernel']:.2f}x |")
    lines += ["", "The distance query of eq. 22 (csg_distance) at medium-size sample positions of the zoo models",
              "", "| model | quadrics | terms / literals | cell | ns per query per core | literals per query (replayed) | "
              "terms visited | ns per literal |", "|---|---|---|---|---|---|---|---|"]
    for q in payload.get("distance_queries", []):
        lines.append(f"| {q['model']} | {q['quadrics']} | {q['terms']} / {q['literals']} | {q['cell']} | "
                     f"{q['ns_per_query_per_core']:.0f} | {q['replayed_literals_per_query']:.1f} | "
                     f"{q['replayed_terms_per_query']:.1f} | {q['ns_per_literal_per_core']:.1f} |")
    c = payload["clock"]
    lines += ["", f"Clock estimate (dependent FMA chain, {c['fma_latency_cycles']} cycles per FMA): "
              f"{c['clock_ghz']:.2f} GHz per core-second of CPU time ({c['clock_ghz_wall']:.2f} GHz from wall time "
              f"per CU); the paper's core ran at {PAPER_GHZ} GHz."]
    return "\n".join(lines)


def run(quick=False, device=None):
    ctx = get_context(device)
    load0 = os.getloadavg()[0]
    repeats = 2 if quick else 5
    precisions = [np.float64, np.float32] if ctx.info.fp64 else [np.float32]
    configs = [(real, False) for real in precisions] + [(precisions[0], True)]
    if quick:
        configs = configs[:1]
    ops = []
    for real, dependent in configs:
        ops += measure_ops(ctx, real, dependent, repeats)
    clock = measure_clock(ctx, repeats)
    radii = [0.004] if quick else [0.004, 0.001]
    sampling = measure_sampling(ctx, radii, 2 if quick else 3)
    queries = measure_queries(ctx, repeats, models=("lens", "flange") if quick else None)
    env = environment(ctx)
    env["loadavg_start"] = round(load0, 2)
    env["loadavg_end"] = round(os.getloadavg()[0], 2)
    payload = {
        "environment": env,
        "method": method_text(),
        "sampling_method": sampling_text(),
        "quick": bool(quick),
        "iterations_per_work_item": K,
        "min_launch_s": MIN_LAUNCH,
        "paper": "Trettner & Kobbelt 2021, Table 1: one core of an i9-9900K at 4.8 GHz, C++ (clang -O3 -march=native)",
        "clock": clock,
        "operations": ops,
        "sampling": sampling,
        "distance_queries": queries,
    }
    path = write("micro", payload)
    print(table(payload))
    print(f"\nwritten to {path}")
    return payload
