"""Render speed: splats against the exact tree ray tracer per zoo model at 1920x1080 (the
paper's Table 2 render columns), and what each overdraw optimization buys.

Per zoo model: the camera looks at the model from its view direction, at the distance where the
solid's silhouette (a 96-pixel-wide exact ray tracing) spans ~90% of the image (the paper:
"approximately screen-filling").  The splats are the medium-size samples (radius = diagonal /
150, tree shape).  Times are OpenCL profiling-event times of the kernels (best of several runs;
counters off), so they exclude sampling, uploads and program builds: for the splats the splat
pass plus the resolve/shading pass, for the ray tracer its per-tile pruning pass
(``prune_s``: tile and depth-slab tapes) plus the tracing pass; the two of the ratio (the ray
tracer and the splats with both optimizations on) are run in alternation, 8 rounds of one
each, and each takes its best.  Beside them: the ray tracer's mean pruned tape
length per 16x16 tile (``tile_tape_mean``) and prune evaluations, the process CPU time of the
whole calls (which other processes on a shared machine do not distort), and the overdraw
(fragments per covered pixel, from a separate run with counters on) with surface-aligned
bounds and back-face culling each on and off (paper section 6.1, Fig. 13).  Last, a 1080p
splat frame of the gear against a kernel that only writes the frame's four buffers
(``bench/kernels/frame_write.cl``), on the same device (``frame_floor``: the best of 8 rounds
that each time both, so that a busy moment of the machine weighs on both alike).

The ray tracer's cost grows with the tape, so the DNF shape is compared with the tree shape
at 320x180 only (the same image either way), and a resolution sweep (480x270 ... 3840x2160)
runs on one model.  The ray tracer runs once when a run takes more than a few seconds.
Many leaves per tile (``many_leaves``): the ray tracer with and without its per-ray
acceleration (culling boxes and per-ray pruning; the same image) on scenes whose tile tapes
hold hundreds to thousands of leaves: plates of 200 x 200 x 5 mm minus a 16 x 16 and a 50 x 50
grid of chamfered holes seen obliquely, and a bored column of 220 spheres seen from inside.
``--quick``: 320x180, one run each, no sweep, the DNF ray tracer not on the gear, only the
all-on and all-off optimization settings, no 2,500-hole plate.  ``--gallery``: also write docs/gallery/*.png
(800x600, splats).
"""

from __future__ import annotations

import os
import time
import warnings


import clcsg
from clcsg.cl.device import get_context

from . import zoo
from .common import Load, diagonal, environment, fit_to_silhouette, fmt, write

FULL_HD = (1920, 1080)
QUICK_RES = (320, 180)
SHAPE_RES = (320, 180)
#: --quick traces the DNF shape only on models with at most this many quadrics
QUICK_DNF_QUADRICS = 31
GALLERY_RES = (800, 600)
GALLERY_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "docs", "gallery")
SWEEP_MODELS = ("steinmetz",)
SWEEP_RES = [(480, 270), (960, 540), (1920, 1080), (3840, 2160)]
#: a renderer whose run took longer than this (seconds) is not run again
LONG_RUN = 4.0
#: rounds of the ray tracer and the splats in alternation for their ratio (the machine's speed
#: drifts by a third within seconds; the best of each over these rounds)
PAIR_ROUNDS = 8


def time_render(fn, subject, cam, ctx, repeats, **kw):
    """(best kernel seconds, stats of the best run) of a renderer.  The stats get
    ``cpu_seconds`` (the least process CPU time of a whole call) and ``runs``."""
    best, stats, best_cpu, runs = float("inf"), None, float("inf"), 0
    for _ in range(max(1, repeats)):
        c0, t0 = time.process_time(), time.perf_counter()
        img = fn(subject, cam, device=ctx, **kw)
        best_cpu = min(best_cpu, time.process_time() - c0)
        runs += 1
        t = img.stats["kernel_s"]
        if t < best:
            best, stats = t, img.stats
        if time.perf_counter() - t0 > LONG_RUN:
            break
    stats = dict(stats)
    stats["cpu_seconds"] = best_cpu
    stats["runs"] = runs
    return best, stats


def time_pair(a, b, rounds):
    """time_render of two renderers (each ``(fn, subject, cam, ctx, kw)``) in alternation, one
    run of each per round, so that a busy moment of the machine weighs on both alike: their
    (best kernel seconds, stats of the best run) as time_render's."""
    got = [[float("inf"), None, float("inf"), 0] for _ in range(2)]
    for _ in range(max(1, rounds)):
        for (fn, subject, cam, ctx, kw), g in zip((a, b), got):
            c0 = time.process_time()
            img = fn(subject, cam, device=ctx, **kw)
            g[2] = min(g[2], time.process_time() - c0)
            g[3] += 1
            if img.stats["kernel_s"] < g[0]:
                g[0], g[1] = img.stats["kernel_s"], img.stats
    out = []
    for best, stats, cpu, runs in got:
        stats = dict(stats)
        stats.update(cpu_seconds=cpu, runs=runs)
        out.append((best, stats))
    return out


def raytrace_record(t, st) -> dict:
    return {"seconds": t, "prune_s": st.get("prune_s"), "tile_tape_mean": st.get("tile_tape_mean"),
            "tape_instructions": st.get("tape_instructions"), "prune_evaluations": st.get("prune_evaluations"),
            "covered_pixels": st.get("covered_pixels"), "cpu_seconds": st.get("cpu_seconds"), "runs": st.get("runs")}


def model_row(ctx, m, W, H, repeats, shapes_res=SHAPE_RES, gallery=False, dnf=True, quick=False) -> dict:
    warnings.simplefilter("ignore")
    scene = clcsg.Scene(m.build(), source=m.name)
    tree = scene.compile("tree")
    diag = diagonal(tree.bound)
    cam = fit_to_silhouette(tree, W, H, m.direction, ctx=ctx)
    clcsg.raytrace(tree, cam.resized(64, 36), device=ctx)  # build
    s = clcsg.sample(scene, diag * zoo.SIZES["medium"], device=ctx, progress=False)
    # the ray tracer and the splats of the ratio, in alternation
    primary = {"surface_aligned": True, "backface_culling": True, "stats": False}
    clcsg.render(s, cam.resized(64, 36), device=ctx, **primary)  # build
    (t_rt, st_rt), pair_splats = time_pair((clcsg.raytrace, tree, cam, ctx, {}), (clcsg.render, s, cam, ctx, primary),
                                           PAIR_ROUNDS if repeats > 1 else 1)
    paper = zoo.paper_row(m.name, "medium")
    row = {"model": m.name, "quadrics": tree.n_quadrics, "tape_instructions": int(len(tree.ops)),
           "samples": len(s), "radius": s.radius, "width": W, "height": H,
           "raytrace": raytrace_record(t_rt, st_rt), "paper": paper}
    configs = [(True, True), (False, False)] if quick else [(True, True), (True, False), (False, True), (False, False)]
    for sa, bf in configs:
        if True:
            kw = {"surface_aligned": sa, "backface_culling": bf}
            if sa and bf:
                t, st = pair_splats
            else:
                clcsg.render(s, cam.resized(64, 36), device=ctx, stats=False, **kw)  # build
                t, st = time_render(clcsg.render, s, cam, ctx, repeats, stats=False, **kw)
            counted = clcsg.render(s, cam, device=ctx, stats=True, **kw).stats
            key = f"{'sa' if sa else 'ball'}_{'bf' if bf else 'nobf'}"
            row[key] = {"seconds": t, "splat_pass_s": st["splat_s"], "resolve_pass_s": st["resolve_s"],
                        "cpu_seconds": st["cpu_seconds"], "overdraw": counted.get("overdraw"),
                        "fragments": counted.get("fragments"), "covered_pixels": counted.get("covered_pixels"),
                        "splats_drawn": counted.get("splats_drawn"), "splats_culled": counted.get("splats_culled"),
                        "clip_evaluations": counted.get("clip_evaluations")}
    sp = row["sa_bf"]
    row["raytrace_over_splat"] = t_rt / sp["seconds"] if sp["seconds"] > 0 else None
    row["raytrace_over_splat_cpu"] = st_rt["cpu_seconds"] / sp["cpu_seconds"] if sp["cpu_seconds"] > 0 else None
    row["optimizations_gain"] = row["ball_nobf"]["seconds"] / sp["seconds"] if sp["seconds"] > 0 else None
    # the ray tracer on both shapes of the tape at a lower resolution
    w2, h2 = shapes_res
    cam2 = cam.resized(w2, h2)
    row["shapes"] = {"width": w2, "height": h2}
    for nf in ("tree", "dnf"):
        if nf == "dnf" and not dnf:
            row["shapes"][nf] = None
            continue
        tape = tree if nf == "tree" else scene.compile("dnf")
        if (w2, h2) == (W, H) and nf == "tree":
            row["shapes"][nf] = row["raytrace"]
            continue
        clcsg.raytrace(tape, cam2.resized(64, 36), device=ctx)  # build (its register count)
        t, st = time_render(clcsg.raytrace, tape, cam2, ctx, repeats)
        row["shapes"][nf] = raytrace_record(t, st)
    if gallery:
        os.makedirs(GALLERY_DIR, exist_ok=True)
        gcam = fit_to_silhouette(tree, *GALLERY_RES, m.direction, ctx=ctx)
        clcsg.render(s, gcam, device=ctx).save(os.path.join(GALLERY_DIR, f"{m.name}.png"))
    print(f"{m.name}: ray tracer {1e3 * t_rt:.0f} ms (tile tape {st_rt['tile_tape_mean']:.1f}), splats "
          f"{1e3 * sp['seconds']:.0f} ms, {row['raytrace_over_splat']:.2f}x; {w2}x{h2} ray tracer tree "
          f"{1e3 * row['shapes']['tree']['seconds']:.0f} ms / DNF "
          f"{fmt((row['shapes']['dnf'] or {}).get('seconds'), '.0f', 1e3)} ms", flush=True)
    return row


def write_floor(ctx, W, H, repeats=5) -> dict:
    """The best kernel time and process CPU time of writing a W x H frame's four outputs once
    (bench/kernels/frame_write.cl), with the renderers' pixel work-group shape."""
    import numpy as np
    import pyopencl as cl

    from clcsg.cl.programs import event_seconds
    from clcsg.rendering.raytracer import pixel_range

    with open(os.path.join(os.path.dirname(os.path.abspath(__file__)), "kernels", "frame_write.cl")) as f:
        prg = cl.Program(ctx.ctx, f.read()).build()
    bufs = [cl.Buffer(ctx.ctx, cl.mem_flags.WRITE_ONLY, W * H * 4) for _ in range(4)]
    write_frame = cl.Kernel(prg, "write_frame")
    best, cpu = float("inf"), float("inf")
    for _ in range(repeats + 1):
        c0 = time.process_time()
        ev = write_frame(ctx.queue, *pixel_range(W, H), *bufs, np.int32(W), np.int32(H))
        ev.wait()
        cpu = min(cpu, time.process_time() - c0)
        best = min(best, event_seconds(ev))
    return {"seconds": best, "cpu_seconds": cpu}


#: rounds of the frame against the buffer write: each round times both, so a busy moment of
#: the machine weighs on both alike; the best of each is kept
FLOOR_ROUNDS = 8


def frame_floor(ctx, repeats, model="gear", size=FULL_HD) -> dict:
    """A 1080p splat frame (kernels: splat pass + resolve pass) of the gear against a kernel
    that only writes the frame's buffers, on the same device; kernel and process CPU times, the
    best of :data:`FLOOR_ROUNDS` rounds that each time both."""
    m = next(x for x in zoo.MODELS if x.name == model)
    scene = clcsg.Scene(m.build(), source=m.name)
    tree = scene.compile("tree")
    cam = fit_to_silhouette(tree, *size, m.direction, ctx=ctx)
    s = clcsg.sample(scene, diagonal(tree.bound) * zoo.SIZES["medium"], device=ctx, progress=False)
    clcsg.render(s, cam.resized(64, 36), device=ctx, stats=False)  # build
    t, st, floor = float("inf"), None, {"seconds": float("inf"), "cpu_seconds": float("inf")}
    for _ in range(max(repeats, FLOOR_ROUNDS)):
        t_r, st_r = time_render(clcsg.render, s, cam, ctx, 1, stats=False)
        if t_r < t:
            t, st = t_r, st_r
        f = write_floor(ctx, *size, repeats=1)
        floor = {k: min(floor[k], f[k]) for k in floor}
    row = {"model": model, "width": size[0], "height": size[1], "samples": len(s), "splat_s": t,
           "splat_pass_s": st["splat_s"], "resolve_pass_s": st["resolve_s"], "frame_cpu_s": st["cpu_seconds"],
           "write_s": floor["seconds"], "write_cpu_s": floor["cpu_seconds"],
           "frame_over_write": t / floor["seconds"] if floor["seconds"] > 0 else None}
    print(f"{model} {size[0]}x{size[1]}: splat frame {1e3 * t:.1f} ms (splat {1e3 * st['splat_s']:.1f}, resolve "
          f"{1e3 * st['resolve_s']:.1f}), buffer write {1e3 * floor['seconds']:.2f} ms: "
          f"{fmt(row['frame_over_write'], '.0f', 1, 'x')}", flush=True)
    return row


def resolution_sweep(ctx, repeats) -> list[dict]:
    out = []
    for m in zoo.MODELS:
        if m.name not in SWEEP_MODELS:
            continue
        scene = clcsg.Scene(m.build(), source=m.name)
        tree = scene.compile("tree")
        s = clcsg.sample(scene, diagonal(tree.bound) * zoo.SIZES["medium"], device=ctx, progress=False)
        for w, h in SWEEP_RES:
            cam = fit_to_silhouette(tree, w, h, m.direction, ctx=ctx)
            t_sp, st = time_render(clcsg.render, s, cam, ctx, repeats, stats=False)
            t_rt, st_rt = time_render(clcsg.raytrace, tree, cam, ctx, repeats)
            out.append({"model": m.name, "quadrics": tree.n_quadrics, "width": w, "height": h, "pixels": w * h,
                        "samples": len(s), "splat_s": t_sp, "splat_pass_s": st["splat_s"],
                        "resolve_pass_s": st["resolve_s"], "raytrace_s": t_rt,
                        "raytrace_prune_s": st_rt["prune_s"], "tile_tape_mean": st_rt["tile_tape_mean"],
                        "splat_cpu_s": st["cpu_seconds"], "raytrace_cpu_s": st_rt["cpu_seconds"]})
            print(f"sweep {m.name} {w}x{h}: splat {1e3 * t_sp:.1f} ms, ray tracer {1e3 * t_rt:.1f} ms", flush=True)
    return out


def many_leaves(ctx, W, H, repeats, quick=False) -> list[dict]:
    """The ray tracer without and with its per-ray acceleration on the many-leaf scenes: best
    kernel and process CPU times, the tile tapes' largest leaf count, whether the images agree."""
    import numpy as np

    from clcsg.rendering.raytracer import trace
    from clcsg.rendering.shading import Shading

    def fn(accelerate):
        return lambda tape, cam, device: trace(device, tape, cam, Shading(), accelerate=accelerate)

    rows = []
    for name, tape, cam0 in zoo.many_leaf_scenes(quick):
        cam = cam0.resized(W, H)
        row = {"scene": name, "quadrics": tape.n_quadrics, "primitives": len(tape.instances),
               "tape_instructions": int(len(tape.ops)), "width": W, "height": H}
        images = {}
        for key, acc in (("before", False), ("after", True)):
            fn(acc)(tape, cam, ctx)  # build (its private list size depends on the view)
            t, st = time_render(fn(acc), tape, cam, ctx, repeats)
            row[key] = {"seconds": t, "prune_s": st["prune_s"], "cpu_seconds": st["cpu_seconds"], "runs": st["runs"],
                        "tile_leaves_max": st["tile_leaves_max"], "slab_quadrics_max": st["slab_quadrics_max"],
                        "covered_pixels": st["covered_pixels"]}
            images[key] = fn(acc)(tape, cam.resized(min(W, 320), min(H, 180)), ctx)
        a, b = images["before"], images["after"]
        row["same_image"] = bool(np.array_equal(a.depth, b.depth) and np.array_equal(a.ids, b.ids))
        row["cpu_gain"] = row["before"]["cpu_seconds"] / row["after"]["cpu_seconds"]
        print(f"{name}: {row['primitives']} primitives, tile leaves up to {row['after']['tile_leaves_max']}; CPU "
              f"{1e3 * row['before']['cpu_seconds']:.0f} -> {1e3 * row['after']['cpu_seconds']:.0f} ms "
              f"({row['cpu_gain']:.2f}x), same image: {row['same_image']}", flush=True)
        rows.append(row)
    return rows


def run(quick=False, device=None, gallery=False):
    ctx = get_context(device)
    load = Load()
    warnings.simplefilter("ignore")
    W, H = QUICK_RES if quick else FULL_HD
    repeats = 1 if quick else 3
    rows = [model_row(ctx, m, W, H, repeats, gallery=gallery, dnf=not quick or m.quadrics <= QUICK_DNF_QUADRICS,
                      quick=quick)
            for m in zoo.MODELS]
    sweep = [] if quick else resolution_sweep(ctx, repeats)
    many = many_leaves(ctx, W, H, repeats, quick)
    floor = frame_floor(ctx, repeats)
    env = load.into(environment(ctx))
    payload = {"environment": env, "quick": bool(quick), "method": " ".join(__doc__.split()), "resolution": [W, H],
               "rows": rows, "resolution_sweep": sweep, "frame_floor": floor, "many_leaves": many,
               "paper": "Trettner & Kobbelt 2021, Table 2 (medium size): rendering on an RTX 2080 Ti"}
    path = write("render", payload)
    print()
    print(table(payload))
    print(f"\nwritten to {path}")
    return payload


def table(payload) -> str:
    W, H = payload["resolution"]
    env = payload["environment"]
    lines = [f"Splats vs the tree ray tracer ({env['device']}, {env['compute_units']} CUs, {W}x{H}, medium splats; "
             f"ms; paper values in brackets, RTX 2080 Ti)", "",
             "| model | quadrics | samples | splats | ray tracer | of it tile pruning | tile tape mean / tape | "
             "ray tracer / splat | same, CPU time | overdraw on / off | gain of the optimizations |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in payload["rows"]:
        p, rt, sp = r["paper"], r["raytrace"], r["sa_bf"]
        lines.append(
            f"| {r['model']} | {r['quadrics']} | {r['samples']:,} | {1e3 * sp['seconds']:.1f} [{p['render_ms']}] | "
            f"{1e3 * rt['seconds']:.1f} [{p['raytrace_ms']}] | {fmt(rt['prune_s'], '.1f', 1e3)} | "
            f"{fmt(rt['tile_tape_mean'], '.1f')} / {r['tape_instructions']} | "
            f"{fmt(r['raytrace_over_splat'], '.2f', 1, 'x')} [{p['raytrace_over_splat']:.1f}x] | "
            f"{fmt(r['raytrace_over_splat_cpu'], '.2f', 1, 'x')} | {fmt(sp['overdraw'], '.2f')} / "
            f"{fmt(r['ball_nobf']['overdraw'], '.2f')} | {fmt(r['optimizations_gain'], '.2f', 1, 'x')} |")
    r0 = payload["rows"][0]["shapes"]
    lines += ["", f"The ray tracer on the two shapes of the tape ({r0['width']}x{r0['height']}; ms)", "",
              "| model | tree | tree tile tape mean | DNF | DNF tile tape mean | DNF / tree |", "|---|---|---|---|---|---|"]
    for r in payload["rows"]:
        t, d = r["shapes"]["tree"], r["shapes"]["dnf"] or {}
        ratio = d["seconds"] / t["seconds"] if d.get("seconds") and t["seconds"] > 0 else None
        lines.append(f"| {r['model']} | {1e3 * t['seconds']:.1f} | {fmt(t['tile_tape_mean'], '.1f')} | "
                     f"{fmt(d.get('seconds'), '.1f', 1e3, none='not run (--quick)')} | "
                     f"{fmt(d.get('tile_tape_mean'), '.1f')} | {fmt(ratio, '.2f', 1, 'x')} |")
    f = payload.get("frame_floor")
    if f:
        lines += ["", f"A {f['width']}x{f['height']} splat frame of the {f['model']} against a kernel that only writes "
                  "the frame's four buffers (ms; process CPU in brackets)", "",
                  "| splat pass | resolve pass | frame | buffer write | frame / write |", "|---|---|---|---|---|",
                  f"| {1e3 * f['splat_pass_s']:.1f} | {1e3 * f['resolve_pass_s']:.1f} | {1e3 * f['splat_s']:.1f} "
                  f"[{1e3 * f['frame_cpu_s']:.0f}] | {1e3 * f['write_s']:.2f} [{1e3 * f['write_cpu_s']:.1f}] | "
                  f"{fmt(f['frame_over_write'], '.0f', 1, 'x')} |"]
    if payload.get("many_leaves"):
        lines += ["", f"The ray tracer on many leaves per tile ({W}x{H}; ms, process CPU; before / after: without / "
                  "with culling boxes and per-ray pruning)", "",
                  "| scene | primitives | tile leaves (max) | kernel before | kernel after | CPU before | CPU after | "
                  "CPU gain | same image |", "|---|---|---|---|---|---|---|---|---|"]
        for m in payload["many_leaves"]:
            b, a = m["before"], m["after"]
            lines.append(f"| {m['scene']} | {m['primitives']:,} | {a['tile_leaves_max']:,} | {1e3 * b['seconds']:.1f} | "
                         f"{1e3 * a['seconds']:.1f} | {1e3 * b['cpu_seconds']:.0f} | {1e3 * a['cpu_seconds']:.0f} | "
                         f"{m['cpu_gain']:.2f}x | {'yes' if m['same_image'] else 'NO'} |")
    if payload.get("resolution_sweep"):
        lines += ["", "Render time against resolution (medium splat size; ms)", "",
                  "| model | resolution | splat | ray tracer | ray tracer / splat | same, CPU time |",
                  "|---|---|---|---|---|---|"]
        for s in payload["resolution_sweep"]:
            lines.append(f"| {s['model']} | {s['width']}x{s['height']} | {1e3 * s['splat_s']:.1f} | "
                         f"{1e3 * s['raytrace_s']:.1f} | {s['raytrace_s'] / s['splat_s']:.2f}x | "
                         f"{s['raytrace_cpu_s'] / s['splat_cpu_s']:.2f}x |")
    return "\n".join(lines)
