"""The model zoo benchmark: the paper's Table 2 columns for six solids (``bench/zoo.py``) of 3, 5,
5, 21, 31 and 80 unique quadrics, each at three splat sizes, plus the gallery images.

Per row: unique quadrics, DNF terms and literals, samples, distance queries (evaluations of
eq. 22), clip indices, unresolved cells, sampling time (whole ``clcsg.sample`` call, best of
several runs after a warm-up that builds the program; also the ``classify`` kernel time from
profiling events and the process CPU time), render time at 1920x1080 for the splat renderer
and the exact ray tracer (device time of their kernels from profiling events, shading
included, best of several; counters off), their ratio (also as the ratio of process CPU
times of the whole calls, which other processes on a shared machine do not distort), and the
overdraw (fragments per
covered pixel, from a separate run with counters on).

Splat sizes are relative to the model: radius = diagonal of the scene bound times 1/50
(large), 1/150 (medium), 1/500 (small).  The camera looks at the model from the model's view
direction and is moved so that the solid's silhouette (from a 192-pixel-wide exact ray tracing)
spans ~90% of the image (the paper: "approximately screen-filling").

``query_cost``: per model, the mean number of literal distances (and terms) one evaluation of
eq. 22 computes, replayed in numpy at the medium-size samples with the kernel's culling rules
and ``enough`` = 4 r (a fine cell) or infinity (a root cell), in the kernel's term order and
nearest-box-first.

A resolution sweep (splat and ray tracer at 480x270 ... 3840x2160) for two models feeds the
render-time plot.  ``--quick``: 480x270, the medium size only, one run each, no sweep.
"""

from __future__ import annotations

import math
import os
import time
import warnings

import numpy as np

import clcsg
from clcsg.rendering.camera import Camera
from clcsg.cl.device import get_context

from . import common, micro, zoo
from .common import environment, write

SIZES = {"large": 1 / 50, "medium": 1 / 150, "small": 1 / 500}
FULL_HD = (1920, 1080)
QUICK_RES = (480, 270)
GALLERY_RES = (800, 600)
GALLERY_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "docs", "gallery")
SWEEP_MODELS = ("steinmetz", "gear")
SWEEP_RES = [(480, 270), (960, 540), (1920, 1080), (3840, 2160)]

#: paper Table 2: quadrics -> size -> (samples, distance queries, clip indices, sampling ms,
#: render ms (RTX 2080 Ti), ray tracing ms (one per model))
PAPER = [
    (3, {"large": (5454, 22372, 2, 1.51, 0.34), "medium": (23452, 47336, 2, 3.39, 0.23),
         "small": (249014, 100398, 2, 8.51, 0.27)}, 0.36),
    (5, {"large": (8112, 103296, 52, 7.63, 0.27), "medium": (35904, 215040, 23, 16.45, 0.18),
         "small": (329856, 576048, 17, 66.87, 0.26)}, 1.14),
    (5, {"large": (9465, 52578, 52, 4.38, 0.31), "medium": (27882, 103908, 31, 8.71, 0.28),
         "small": (205075, 254592, 25, 23.47, 0.26)}, 0.87),
    (21, {"large": (7134, 30802, 78, 6.26, 0.45), "medium": (31940, 85744, 37, 18.01, 0.39),
          "small": (104972, 171958, 31, 37.91, 0.33)}, 0.72),
    (31, {"large": (28432, 196298, 51, 36.63, 0.96), "medium": (91895, 325705, 34, 62.23, 0.87),
          "small": (184533, 415847, 29, 83.36, 0.69)}, 4.43),
    (80, {"large": (10176, 194024, 299, 94.47, 0.32), "medium": (141200, 558582, 244, 292.35, 0.34),
          "small": (655727, 1182464, 236, 623.92, 0.47)}, 9.15),
]


def fit_camera(bound, width, height, direction, fill=0.9) -> Camera:
    """A camera looking at the bound's center from ``direction``, at the distance where the
    projection of the bound's corners spans ``fill`` of the image (width or height)."""
    b = np.asarray(bound, dtype=np.float64)
    cam = Camera.fit(b, width, height, direction=direction)
    corners = np.array([[x, y, z] for x in b[:, 0] for y in b[:, 1] for z in b[:, 2]])
    for _ in range(6):
        xy, _z = cam.project(corners)
        span = max(np.abs(xy[:, 0] - width / 2).max() / (width / 2), np.abs(xy[:, 1] - height / 2).max() / (height / 2))
        if not math.isfinite(span) or abs(span / fill - 1) < 0.01:
            break
        d = cam.eye - cam.target
        cam = Camera.look_at(cam.target + d * (span / fill), cam.target, up=(0, 0, 1), fov=cam.fov,
                             width=width, height=height)
    return cam


def fit_to_silhouette(dnf, width, height, direction, fill=0.9, ctx=None) -> Camera:
    """:func:`fit_camera`, then moved along the view direction until the solid's silhouette
    (found with a low-resolution exact ray tracing) spans ``fill`` of the image."""
    _render, raytrace = _render_fns()
    cam = fit_camera(dnf.bound, width, height, direction, fill)
    small_w = 192
    small_h = max(2, round(small_w * height / width))
    for _ in range(3):
        ids = raytrace(dnf, cam.resized(small_w, small_h), device=ctx).ids
        ys, xs = np.nonzero(ids >= 0)
        if len(xs) == 0:
            break
        span = max(np.abs(xs + 0.5 - small_w / 2).max() / (small_w / 2),
                   np.abs(ys + 0.5 - small_h / 2).max() / (small_h / 2))
        if abs(span / fill - 1) < 0.02:
            break
        d = cam.eye - cam.target
        cam = Camera.look_at(cam.target + d * (span / fill), cam.target, up=(0, 0, 1), fov=cam.fov,
                             width=width, height=height)
    return cam


def query_cost(dnf, samples, enough, limit=20000, seed=0) -> dict:
    """How many literal distances one evaluation of eq. 22 (``csg_distance`` in
    kernels/sampler.cl) computes, replayed in numpy at sample positions with the kernel's
    rules: every term is scanned for the sample's literal (quadric and polarity); terms that
    hold it are always evaluated (the union of the own terms), any other term is skipped when
    its bound box is at least ``enough`` or the nearest other term so far away; an evaluated
    term computes the distances of all its literals except those on the sample's quadric.
    Terms are visited in index order (as the kernel does) and nearest-box-first."""
    from clcsg.model.quadric import Quadric

    rng = np.random.default_rng(seed)
    n = len(samples)
    idx = rng.choice(n, size=min(n, limit), replace=False) if n else np.zeros(0, int)
    p = samples.positions[idx]
    own_q, own_s = samples.quadrics[idx], samples.signs[idx]
    qd = np.stack([Quadric(m).distance(p) for m in dnf.quadrics], axis=1)  # (N, U)
    lo, hi = dnf.term_bounds[:, 0], dnf.term_bounds[:, 1]
    box = np.linalg.norm(np.maximum(lo[None] - p[:, None], 0) + np.maximum(p[:, None] - hi[None], 0), axis=2)
    # member[n, t]: term t holds the sample's literal
    member = np.zeros((len(p), dnf.n_terms), dtype=bool)
    for t, lits in enumerate(dnf.terms):
        for qi, sg in lits:
            member[:, t] |= (own_q == qi) & (own_s == sg)
    out = {}
    for order in ("index", "nearest_first"):
        evals = np.zeros(len(p))
        visited = np.zeros(len(p))
        other = np.full(len(p), np.inf)
        rows = np.arange(len(p))
        order_idx = np.argsort(np.where(member, -1.0, box), axis=1) if order == "nearest_first" else \
            np.broadcast_to(np.arange(dnf.n_terms), box.shape)
        for k in range(dnf.n_terms):
            t = order_idx[:, k]
            b = box[rows, t]
            mem = member[rows, t]
            active = mem | ~((b >= enough) | (b >= other))
            other = np.where(~active, np.minimum(other, b), other)
            for ti in np.unique(t[active]):
                sel = active & (t == ti)
                v = np.full(sel.sum(), -np.inf)
                cnt = np.zeros(sel.sum())
                for qi, sg in dnf.terms[ti]:
                    live = own_q[sel] != qi
                    cnt += live
                    v = np.where(live, np.maximum(v, sg * qd[sel, qi]), v)
                v = np.where(b[sel] > 0, np.maximum(v, b[sel]), v)
                other[sel] = np.where(mem[sel], other[sel], np.minimum(other[sel], v))
                evals[sel] += cnt
                visited[sel] += 1
        out[order] = {"literals_per_query": float(evals.mean()), "terms_per_query": float(visited.mean())}
    out["enough"] = float(enough)
    out["points"] = int(len(p))
    out["literals_total"] = int(sum(len(t) for t in dnf.terms))
    out["membership_scan_per_query"] = out["literals_total"]
    return out


def _render_fns():
    import importlib

    r = importlib.import_module("clcsg.render")
    return r.render, r.raytrace


def time_sampling(shape, radius, ctx, repeats, budget):
    """Best of up to ``repeats`` runs (fewer once ``budget`` seconds are spent): dict."""
    best = None
    spent = 0.0
    for k in range(repeats):
        with micro.kernel_events() as log:
            c0, t0 = time.process_time(), time.perf_counter()
            s = clcsg.sample(shape, radius, device=ctx, progress=False)
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        classify = micro.kernel_seconds(log, "classify")
        finish = micro.kernel_seconds(log, "finish")
        if best is None or wall < best["seconds"]:
            best = {"seconds": wall, "cpu_s": cpu, "classify_kernel_s": classify, "finish_kernel_s": finish,
                    "samples_obj": s, "runs": k + 1}
        spent += wall
        best["runs"] = k + 1
        if spent > budget:
            break
    return best


def time_render(fn, subject, cam, ctx, repeats, **kw):
    """(best kernel seconds, stats of the best run) of a renderer, counters off.  The stats
    get ``cpu_seconds``: the least process CPU time of a whole call (host work included), a
    measure that does not grow when other processes take cores."""
    best, stats, best_cpu = float("inf"), None, float("inf")
    for _ in range(repeats):
        c0 = time.process_time()
        img = fn(subject, cam, device=ctx, **kw)
        best_cpu = min(best_cpu, time.process_time() - c0)
        t = img.stats["kernel_seconds"]
        if t < best:
            best, stats = t, img.stats
    stats = dict(stats)
    stats["cpu_seconds"] = best_cpu
    return best, stats


def run(quick=False, device=None):
    ctx = get_context(device)
    render, raytrace = _render_fns()
    load0 = os.getloadavg()[0]
    warnings.simplefilter("ignore")
    W, H = QUICK_RES if quick else FULL_HD
    sizes = {"medium": SIZES["medium"]} if quick else SIZES
    repeats = 1 if quick else 3
    budget = 0.0 if quick else 20.0
    # the gallery is written only with the default result directory (not with --out)
    gallery = os.path.abspath(common.RESULTS) == os.path.abspath(os.path.join(os.path.dirname(__file__), "results"))
    rows, models = [], []
    for mi, m in enumerate(zoo.MODELS):
        shape = m.build()
        scene = clcsg.Scene(shape, source=m.name)
        dnf = scene.normalize()
        diag = float(np.linalg.norm(dnf.bound[1] - dnf.bound[0]))
        cam = fit_to_silhouette(dnf, W, H, m.direction, ctx=ctx)
        t_rt, st_rt = time_render(raytrace, dnf, cam, ctx, repeats)
        paper_q, paper_sizes, paper_rt = zoo_paper(mi)
        clcsg.sample(shape, diag / 20, device=ctx, progress=False)  # build the sampler program
        info = {"model": m.name, "description": m.description, "quadrics": dnf.n_quadrics,
                "paper_quadrics": m.quadrics, "terms": dnf.n_terms, "literals": sum(len(t) for t in dnf.terms),
                "bound": dnf.bound.tolist(), "diagonal": diag, "raytrace_s": t_rt,
                "raytrace_covered_pixels": st_rt["covered_pixels"], "paper_raytrace_ms": paper_rt,
                "raytrace_cpu_s": st_rt["cpu_seconds"]}
        t0 = time.perf_counter()
        scene.normalize()
        info["normalize_s"] = time.perf_counter() - t0
        models.append(info)
        medium_samples = None
        for size, frac in sizes.items():
            radius = diag * frac
            ts = time_sampling(shape, radius, ctx, repeats, budget)
            s = ts.pop("samples_obj")
            st = s.stats
            render(s, cam.resized(64, 36), device=ctx, stats=False)  # build
            t_sp, st_sp = time_render(render, s, cam, ctx, repeats, stats=False)
            counted = render(s, cam, device=ctx, stats=True).stats
            p = paper_sizes[size]
            row = {
                "model": m.name, "quadrics": dnf.n_quadrics, "terms": dnf.n_terms, "size": size,
                "radius": radius, "radius_over_diagonal": frac, "samples": st["samples"],
                "distance_queries": st["distance_queries"], "clip_indices": st["clip_indices"],
                "unresolved": st.get("unresolved"), "levels": st["levels"],
                "sampling_s": ts["seconds"], "sampling_cpu_s": ts["cpu_s"], "sampling_runs": ts["runs"],
                "classify_kernel_s": ts["classify_kernel_s"], "finish_kernel_s": ts["finish_kernel_s"],
                "normalize_s": st["normalize_s"], "analyse_s": st["analyse_s"], "subdivide_s": st["subdivide_s"],
                "finish_s": st["finish_s"],
                "width": W, "height": H, "splat_s": t_sp, "splat_pass_s": st_sp["splat_seconds"],
                "resolve_pass_s": st_sp["resolve_seconds"], "raytrace_s": t_rt,
                "raytrace_over_splat": t_rt / t_sp if t_sp > 0 else None,
                "splat_cpu_s": st_sp["cpu_seconds"], "raytrace_cpu_s": st_rt["cpu_seconds"],
                "raytrace_over_splat_cpu": st_rt["cpu_seconds"] / st_sp["cpu_seconds"],
                "overdraw": counted.get("overdraw"), "fragments": counted.get("fragments"),
                "covered_pixels": counted.get("covered_pixels"), "splats_drawn": counted.get("splats_drawn"),
                "splats_culled": counted.get("splats_culled"), "clip_evaluations": counted.get("clip_evaluations"),
                "us_per_query_kernel_per_cu": 1e6 * ts["classify_kernel_s"] * ctx.info.compute_units
                / max(st["distance_queries"], 1),
                "paper": {"samples": p[0], "distance_queries": p[1], "clip_indices": p[2], "sampling_ms": p[3],
                          "render_ms": p[4], "raytrace_ms": paper_rt,
                          "raytrace_over_splat": paper_rt / p[4]},
            }
            rows.append(row)
            print(_row_line(row), flush=True)
            if size == "medium":
                medium_samples = s
                limit = 3000 if quick else 20000
                info["query_cost"] = {"fine_cell": query_cost(dnf, s, 4 * radius, limit=limit),
                                      "root_cell": query_cost(dnf, s, np.inf, limit=limit)}
        if gallery and medium_samples is not None:
            os.makedirs(GALLERY_DIR, exist_ok=True)
            gcam = fit_to_silhouette(dnf, *GALLERY_RES, m.direction, fill=0.9, ctx=ctx)
            render(medium_samples, gcam, device=ctx).save(os.path.join(GALLERY_DIR, f"{m.name}.png"))
    sweep = [] if quick else resolution_sweep(ctx, repeats)
    env = environment(ctx)
    env["loadavg_start"] = round(load0, 2)
    env["loadavg_end"] = round(os.getloadavg()[0], 2)
    payload = {
        "environment": env, "quick": bool(quick), "method": " ".join(__doc__.split()),
        "resolution": [W, H], "sizes": sizes, "models": models, "rows": rows, "resolution_sweep": sweep,
        "paper": "Trettner & Kobbelt 2021, Table 2: sampling on one 4.8 GHz core, rendering on an RTX 2080 Ti",
    }
    path = write("models", payload)
    print()
    print(table(payload))
    print(f"\nwritten to {path}")
    return payload


def zoo_paper(index):
    return PAPER[index]


def resolution_sweep(ctx, repeats) -> list[dict]:
    render, raytrace = _render_fns()
    out = []
    for m in zoo.MODELS:
        if m.name not in SWEEP_MODELS:
            continue
        shape = m.build()
        dnf = clcsg.Scene(shape).normalize()
        diag = float(np.linalg.norm(dnf.bound[1] - dnf.bound[0]))
        s = clcsg.sample(shape, diag * SIZES["medium"], device=ctx, progress=False)
        for w, h in SWEEP_RES:
            cam = fit_to_silhouette(dnf, w, h, m.direction, ctx=ctx)
            t_sp, st = time_render(render, s, cam, ctx, repeats, stats=False)
            t_rt, st_rt = time_render(raytrace, dnf, cam, ctx, repeats)
            out.append({"model": m.name, "quadrics": dnf.n_quadrics, "width": w, "height": h, "pixels": w * h,
                        "samples": len(s), "splat_s": t_sp, "splat_pass_s": st["splat_seconds"],
                        "resolve_pass_s": st["resolve_seconds"], "raytrace_s": t_rt,
                        "splat_cpu_s": st["cpu_seconds"], "raytrace_cpu_s": st_rt["cpu_seconds"]})
            print(f"sweep {m.name} {w}x{h}: splat {1e3 * t_sp:.1f} ms, ray tracer {1e3 * t_rt:.1f} ms", flush=True)
    return out


def _row_line(r) -> str:
    return (f"{r['model']} {r['size']}: {r['samples']} samples, {r['distance_queries']} queries, "
            f"sampling {1e3 * r['sampling_s']:.1f} ms, splat {1e3 * r['splat_s']:.1f} ms, "
            f"ray tracer {1e3 * r['raytrace_s']:.1f} ms")


def table(payload) -> str:
    W, H = payload["resolution"]
    env = payload["environment"]
    lines = [f"Model zoo ({env['device']}, {env['compute_units']} CUs, {W}x{H}; times in ms; "
             f"paper values in brackets: sampling on one 4.8 GHz core, rendering on an RTX 2080 Ti)", "",
             "| model | quadrics | terms | size | samples | dist. queries | #clip | sampling | render splat | "
             "render ray tracer | ray tracer / splat | same, CPU time | overdraw |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in payload["rows"]:
        p = r["paper"]
        lines.append(
            f"| {r['model']} | {r['quadrics']} | {r['terms']} | {r['size']} | {r['samples']:,} [{p['samples']:,}] | "
            f"{r['distance_queries']:,} [{p['distance_queries']:,}] | {r['clip_indices']} [{p['clip_indices']}] | "
            f"{1e3 * r['sampling_s']:.1f} [{p['sampling_ms']}] | {1e3 * r['splat_s']:.1f} [{p['render_ms']}] | "
            f"{1e3 * r['raytrace_s']:.1f} [{p['raytrace_ms']}] | {r['raytrace_over_splat']:.2f}x "
            f"[{p['raytrace_over_splat']:.1f}x] | {r['raytrace_over_splat_cpu']:.2f}x | {r['overdraw']:.2f} |")
    if payload.get("resolution_sweep"):
        lines += ["", "Render time against resolution (medium splat size; ms)", "",
                  "| model | resolution | splat | ray tracer | ray tracer / splat | same, CPU time |",
                  "|---|---|---|---|---|---|"]
        for s in payload["resolution_sweep"]:
            lines.append(f"| {s['model']} | {s['width']}x{s['height']} | {1e3 * s['splat_s']:.1f} | "
                         f"{1e3 * s['raytrace_s']:.1f} | {s['raytrace_s'] / s['splat_s']:.2f}x | "
                         f"{s['raytrace_cpu_s'] / s['splat_cpu_s']:.2f}x |")
    return "\n".join(lines)
