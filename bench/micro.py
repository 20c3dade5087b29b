"""Microbenchmarks: the paper's Table 1 (operations per second) on the selected OpenCL device.

Method (also stored in the JSON as ``method``)
----------------------------------------------
The evaluation rows (Q(x), N(x), h(x, y), distortion, minimum distortion over a region,
quadric-line intersection, conservative distance d(x0)) run the package's own device functions
(``bench/kernels/micro.cl`` includes ``cl/include/quadric.h`` and ``sampling/heightfield.h``).  Every
work-item loads one of eight quadrics of different types (sphere, rotated ellipsoid, cylinder,
cone, hyperboloids of one and two sheets, paraboloid, plane) and its principal frame into
registers and derives a point in [-1, 1]^3 from its global id.  It then runs K = 256
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

The tape distance query (``bench/kernels/query.cl``): d_q(p) = ``surface_distance(tape_eval(...))``
of ``cl/include/tape.h``, the query the sampler runs at every cell corner, timed on each zoo
model's tape (tree and DNF shape) at up to 4096 points on its quadrics (medium-size samples of
the tree shape, each with its own quadric substituted), K = 8 queries per work-item, launches
of >= 100 ms, best of several.  Two tapes per point: the root tape (what a root cell queries)
and the tape pruned over the ball of radius 2r around the point by ``tape_prune`` (what a fine
cell of the sampler queries: its patch grown by r).  Reported: ns per query per core (process
CPU time) and per CU (wall time), and leaf distances per query counted by the kernel.

``python -m bench micro [--quick] [--device D]``; ``--quick``: fewer repeats, the first
precision only, one sampling radius, two zoo models for the tape query.
"""

from __future__ import annotations

import math
import os
import time
import warnings

import numpy as np

import clcsg
from clcsg.cl import programs
from clcsg.cl.device import get_context
from clcsg.model.quadric import Quadric

from . import zoo
from .common import Load, environment, event_seconds, kernel_events, kernel_seconds, write

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
    return " ".join(("The sampling rows" + __doc__.split("The sampling rows")[1].split("The tape distance")[0]).split())


def query_text() -> str:
    return " ".join(("The tape distance" + __doc__.split("The tape distance")[1].split("``python -m")[0]).split())


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
    from clcsg.compile.quadric_frames import principal_frame
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
    opts = programs.build_options({"DEPENDENT": int(bool(dependent))}, real) + [
        "-I", programs.package_dir("cl/include"), "-I", programs.package_dir("sampling"), "-I", KERNELS]
    return cl.Program(ctx.ctx, src).build(options=opts)


# -- timing helpers -------------------------------------------------------------------------------


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


# -- the tape distance query on the zoo models ---------------------------------------------------

QUERY_K = 8
#: the pruned tape of a point: the ball of this many radii around it (a fine cell's patch grown
#: by r)
PRUNE_RADII = 2.0


def build_query(ctx, real, n_regs):
    """``bench/kernels/query.cl`` for a tape with ``n_regs`` registers."""
    import pyopencl as cl

    with open(os.path.join(KERNELS, "query.cl"), encoding="utf-8") as f:
        src = f.read()
    opts = programs.build_options({"TAPE_REGS": int(n_regs)}, real) + [
        "-I", programs.package_dir("cl/include"), "-I", programs.package_dir("sampling")]
    return cl.Program(ctx.ctx, src).build(options=opts)


def query_points(ctx, scene, radius, limit=4096, seed=0):
    """(tree tape, world positions, quadric indices) of up to ``limit`` medium-size samples."""
    s = clcsg.sample(scene, radius, device=ctx, progress=False)
    rng = np.random.default_rng(seed)
    idx = rng.choice(len(s), size=min(len(s), limit), replace=False) if len(s) else np.zeros(0, int)
    return s.tape, s.positions[idx], s.quadrics[idx].astype(np.int32)


def _same_quadrics(a, b, used) -> bool:
    return len(b.quadrics) > int(max(used, default=-1)) and all(
        np.allclose(a.quadrics[q], b.quadrics[q], rtol=0, atol=1e-12) for q in np.unique(used))


def time_tape_queries(ctx, tape, positions, quadrics, radius, repeats=3, min_launch=None) -> list[dict]:
    """Rows for the root tape and the pruned tapes of ``tape`` at ``positions`` (world) on
    ``quadrics`` (indices into ``tape.quadrics``)."""
    import pyopencl as cl

    from clcsg.cl.records import SceneBuffers, pack

    min_launch = MIN_LAUNCH if min_launch is None else min_launch
    real = np.dtype(ctx.real_dtype)
    packed = pack(tape, real)
    sb = SceneBuffers(ctx, packed)
    prg = build_query(ctx, real, packed.n_regs)
    k_prune, k_query = cl.Kernel(prg, "prune_points"), cl.Kernel(prg, "op_tape_query")
    mf = cl.mem_flags
    m = len(positions)
    n = len(packed.tape)
    pts = np.ascontiguousarray((positions - packed.origin).astype(real))
    pbuf = cl.Buffer(ctx.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=pts)
    qbuf = cl.Buffer(ctx.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(quadrics, np.int32))
    # the pruned tapes, one slot of n + 1 rows per point
    arena = cl.Buffer(ctx.ctx, mf.READ_WRITE, m * (n + 1) * packed.tape.itemsize)
    pfirst, pcount, pevals = (np.zeros(m, np.int32), np.zeros(m, np.int32), np.zeros(m, np.uint32))
    bf, bc, be = (cl.Buffer(ctx.ctx, mf.READ_WRITE, a.nbytes) for a in (pfirst, pcount, pevals))
    k_prune(ctx.queue, (-(-m // Runner.WG) * Runner.WG,), (Runner.WG,), sb.quadrics, sb.tape, np.int32(n), pbuf,
            qbuf, np.int32(m), real.type(PRUNE_RADII * radius), arena, bf, bc, be)
    for a, buf in ((pfirst, bf), (pcount, bc), (pevals, be)):
        cl.enqueue_copy(ctx.queue, a, buf)
    ctx.queue.finish()
    rfirst = np.zeros(m, np.int32)
    rcount = np.full(m, n, np.int32)
    rows = []
    stats = tape.stats
    cu = ctx.info.compute_units
    for label, tapes, first, count in (("root tape", sb.tape, rfirst, rcount),
                                       ("pruned over 2r", arena, pfirst, pcount)):
        fbuf = cl.Buffer(ctx.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=first)
        cbuf = cl.Buffer(ctx.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=count)
        bufs = {}

        def launch(nn):
            if nn not in bufs:
                bufs.clear()
                bufs[nn] = (cl.Buffer(ctx.ctx, mf.WRITE_ONLY, nn * real.itemsize),
                            cl.Buffer(ctx.ctx, mf.WRITE_ONLY, nn * 4))
            out, lv = bufs[nn]
            ctx.queue.finish()
            c0 = time.process_time()
            ev = k_query(ctx.queue, (nn,), (Runner.WG,), sb.quadrics, tapes, fbuf, cbuf, pbuf, qbuf, np.int32(m),
                         np.int32(QUERY_K), out, lv)
            ev.wait()
            return event_seconds(ev), time.process_time() - c0

        nn = -(-m // Runner.WG) * Runner.WG
        launch(nn)
        while True:
            t, _ = launch(nn)
            if t >= min_launch or nn >= 1 << 22:
                break
            nn = int(min(max(2.0, 1.5 * min_launch / max(t, 1e-6)), 16.0) * nn) // Runner.WG * Runner.WG
        runs = [launch(nn) for _ in range(repeats)]
        t, c = min(x for x, _ in runs), min(y for _, y in runs)
        leaves = np.zeros(nn, np.uint32)
        cl.enqueue_copy(ctx.queue, leaves, bufs[nn][1])
        checksum = np.zeros(nn, real)
        cl.enqueue_copy(ctx.queue, checksum, bufs[nn][0])
        q = nn * QUERY_K
        lpq = float(leaves.astype(np.float64).sum()) / q
        rows.append({
            "tape": label, "normal_form": tape.shape, "instructions": int(n), "leaves": int(stats["leaves"]),
            "quadrics": int(tape.n_quadrics), "registers": int(packed.n_regs), "points": int(m),
            "tape_rows_mean": float(count.mean()) if m else 0.0, "tape_rows_max": int(count.max()) if m else 0,
            "prune_evaluations_per_point": float(pevals.mean()) if label != "root tape" and m else None,
            "queries": q, "launch_s": t, "cpu_s": c, "cores_busy": c / t if t > 0 else None,
            "ns_per_query_per_core": 1e9 * c / q, "ns_per_query_per_cu": 1e9 * t * cu / q,
            "leaf_distances_per_query": lpq,
            "ns_per_leaf_per_core": 1e9 * c / q / lpq if lpq > 0 else None,
            "checksum_finite": bool(np.isfinite(checksum).all()),
        })
    return rows


def measure_queries(ctx, repeats, models=None, limit=4096, min_launch=None) -> list[dict]:
    """Tape query rows of the zoo models (``models``: names, or all), both shapes."""
    warnings.simplefilter("ignore")
    out = []
    for m in zoo.MODELS:
        if models is not None and m.name not in models:
            continue
        scene = clcsg.Scene(m.build(), source=m.name)
        tree = scene.compile("tree")
        diag = float(np.linalg.norm(tree.bound[1] - tree.bound[0]))
        radius = diag * zoo.SIZES["medium"]
        tape, pos, qs = query_points(ctx, scene, radius, limit)
        for nf in ("tree", "dnf"):
            t = tape if nf == "tree" else scene.compile("dnf")
            pp, qq = pos, qs
            if nf == "dnf" and not _same_quadrics(tape, t, qs):
                s = clcsg.sample(scene, radius, device=ctx, normal_form="dnf", progress=False)
                idx = np.random.default_rng(0).choice(len(s), size=min(len(s), limit), replace=False)
                pp, qq = s.positions[idx], s.quadrics[idx].astype(np.int32)
            for row in time_tape_queries(ctx, t, pp, qq, radius, repeats, min_launch):
                row.update(model=m.name, radius=radius)
                out.append(row)
                print(f"query {m.name} {nf} {row['tape']}: {row['ns_per_query_per_core']:.0f} ns per query per "
                      f"core, {row['leaf_distances_per_query']:.2f} leaf distances", flush=True)
    return out


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
                cand = (wall, s.stats, kernel_seconds(log, "classify"), cpu)
                if best is None or cand[0] < best[0]:
                    best = cand
            wall, st, t_classify, cpu = best
            n = st["samples"]
            lo, hi = PAPER[row]
            rows.append({
                "operation": row, "scene": what, "radius": r, "samples": n, "levels": st["levels"],
                "distance_queries": st["distance_queries"], "buffer_growths": st.get("buffer_growths"),
                "total_s": wall, "subdivide_s": st["subdivide_s"], "classify_kernel_s": t_classify,
                "finish_s": st["finish_s"], "compile_s": st["compile_s"],
                "analyse_s": st["analyse_s"], "leaf_distances_per_query": st["leaf_distances_per_query"],
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
    lines += ["", "The tape distance query d_q(p) = surface_distance(tape_eval(...)) at medium-size sample "
              "positions of the zoo models (K = 8 queries per work-item)", "",
              "| model | shape | tape | instructions / leaves / registers | tape rows (mean) | ns per query per core | "
              "ns per query per CU (wall) | leaf distances per query | ns per leaf |",
              "|---|---|---|---|---|---|---|---|---|"]
    for q in payload.get("distance_queries", []):
        lines.append(f"| {q['model']} | {q['normal_form']} | {q['tape']} | {q['instructions']} / {q['leaves']} / "
                     f"{q['registers']} | {q['tape_rows_mean']:.1f} | {q['ns_per_query_per_core']:.0f} | "
                     f"{q['ns_per_query_per_cu']:.0f} | {q['leaf_distances_per_query']:.2f} | "
                     f"{f(q['ns_per_leaf_per_core'], '.1f')} |")
    c = payload["clock"]
    lines += ["", f"Clock estimate (dependent FMA chain, {c['fma_latency_cycles']} cycles per FMA): "
              f"{c['clock_ghz']:.2f} GHz per core-second of CPU time ({c['clock_ghz_wall']:.2f} GHz from wall time "
              f"per CU); the paper's core ran at {PAPER_GHZ} GHz."]
    return "\n".join(lines)


def run(quick=False, device=None):
    ctx = get_context(device)
    load = Load()
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
    queries = measure_queries(ctx, 2 if quick else 3, models=("lens", "flange") if quick else None,
                              limit=1024 if quick else 4096, min_launch=0.05 if quick else None)
    env = load.into(environment(ctx))
    payload = {
        "environment": env,
        "method": method_text(),
        "sampling_method": sampling_text(),
        "query_method": query_text(),
        "quick": bool(quick),
        "iterations_per_work_item": K,
        "query_iterations_per_work_item": QUERY_K,
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
