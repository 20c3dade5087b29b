"""Peer comparison: manifold3d (mesh Booleans) on the zoo solids and the Menger sponge, and
OpenSCAD (``openscad -o part.stl part.scad``) on the everyday parts of ``examples/``.

manifold3d: for each zoo model the CSG graph is translated node by node into manifold3d:
boxes, finite cylinders, cone frusta, spheres and ellipsoids become ``Manifold.cube`` /
``cylinder`` / ``sphere`` (ellipsoids: a scaled sphere) with ``circular_segments`` = n;
half-spaces, slabs and infinite cylinders become boxes / cylinders clipped to 4x the scene
bound; transforms are ``Manifold.transform``; a complement inside an intersection becomes a
difference.  At each tessellation level n the time of the Boolean build (construction,
Booleans and ``to_mesh``, which forces manifold's lazy evaluation) and of sampling the result
(area-weighted random points on its triangles, as many as clcsg's medium-size sample count)
is measured, best of several runs.

Surface error of a sample x: the first-order distance to the nearest surface quadric of the
scene, min over its unique quadrics Q of |Q(x)| / |grad Q(x)| (the quadrics of the scene's
compiled tape).  At the small errors of interest it equals the Euclidean distance to that
quadric up to a relative O(error / curvature radius); being a minimum over all quadrics (not
only the visible CSG surface) it never overstates the error.  Reported: maximum and RMS over
the samples, relative to the diagonal of the scene bound.  clcsg's own samples are measured the
same way.

Equal accuracy: the first tessellation level whose maximum relative error is <= 1e-4; if no
measured level reaches it, the level is extrapolated from a power-law fit (error ~ n^-a) of
the measured levels, and the time at that level from a power-law fit of time against n;
the output says which.  Our time is the whole ``clcsg.sample`` call at the medium size (tree
shape, warm: after one run that builds the kernels).

The Menger sponge (``examples/menger3.csg``, 220 boxes): clcsg at r = 1% of the bound's
diagonal against manifold3d building the same cube-minus-boxes graph (translated as above;
boxes are exact, so every tessellation level meets the accuracy target) and sampling as many
points, in the same run.

OpenSCAD: for each everyday part, the wall time of ``openscad -o part.stl part.scad`` (CGAL
Booleans on the tessellation the file's ``$fn`` asks for) in a temporary directory, once; and
of ``openscad -o part.csg part.scad`` (the CSG export that ``clcsg.load("part.scad")`` runs).
Beside it: our warm sampling time of the exported ``examples/part.csg`` at r = 1% of the
diagonal, the ratio ours / openscad, and the end-to-end ratio (CSG export + sampling) /
openscad STL.  Skipped, with the reason recorded, when ``openscad`` is not on PATH.
``--quick``: two segment levels on two zoo models, two everyday parts, a plate of 100 holes.
"""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import tempfile
import time
import warnings

import numpy as np

import clcsg
from clcsg.cl.device import get_context

from . import zoo
from .common import Load, Translator, Unsupported, clcsg_command, diagonal, environment_for_runs, environment, fmt, surface_error, time_sampling, write

TARGET = 1e-4  # relative to the bound's diagonal
SEGMENTS = [16, 32, 64, 128, 256]
QUICK_SEGMENTS = [16, 64]


def sample_mesh(mesh, count, rng):
    """``count`` area-weighted random points on the triangles of a manifold3d Mesh."""
    V = np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3]
    T = np.asarray(mesh.tri_verts, dtype=np.int64)
    a, b, c = V[T[:, 0]], V[T[:, 1]], V[T[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    cdf = np.cumsum(area)
    tri = np.searchsorted(cdf, rng.random(count) * cdf[-1])
    u, v = rng.random(count), rng.random(count)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    return a[tri] + u[:, None] * (b[tri] - a[tri]) + v[:, None] * (c[tri] - a[tri]), len(T)


def _powerfit(x, y):
    """(a, b) of log y = a + b log x (least squares)."""
    lx, ly = np.log(np.asarray(x, float)), np.log(np.asarray(y, float))
    b, a = np.polyfit(lx, ly, 1)
    return a, b


def manifold_levels(manifold3d, shape, bound, segments, count, repeats, tape, rng, label, error_points=None) -> dict:
    """Build and sample ``shape`` with manifold3d at each tessellation level (the error on
    ``error_points`` random samples of the ``count``, or all)."""
    diag = diagonal(bound)
    rec = {"levels": []}
    for n in segments:
        try:
            tr = Translator(manifold3d, n, bound)
            tb = tsamp = float("inf")
            for _ in range(repeats):
                t0 = time.perf_counter()
                mesh = tr.build(shape).to_mesh()
                t1 = time.perf_counter()
                pts, ntri = sample_mesh(mesh, count, rng)
                t2 = time.perf_counter()
                tb, tsamp = min(tb, t1 - t0), min(tsamp, t2 - t1)
        except Unsupported as e:
            rec["unsupported"] = str(e)
            break
        if error_points is not None and len(pts) > error_points:
            pts = pts[rng.choice(len(pts), size=error_points, replace=False)]
        err = surface_error(tape, pts)
        lvl = {"segments": n, "triangles": ntri, "build_s": tb, "sample_s": tsamp, "total_s": tb + tsamp,
               "max_rel_error": float(err.max() / diag), "rms_rel_error": float(np.sqrt(np.mean(err ** 2)) / diag)}
        rec["levels"].append(lvl)
        print(f"{label} n={n}: {ntri} triangles, build {1e3 * tb:.1f} ms, sampling {1e3 * tsamp:.1f} ms, "
              f"max error {lvl['max_rel_error']:.2e} of the diagonal", flush=True)
    rec.update(equal_accuracy(rec["levels"]))
    return rec


def ours(ctx, scene, radius, repeats, budget=20.0) -> dict:
    ts = time_sampling(scene, radius, ctx, repeats=repeats, budget=budget)
    s = ts["samples"]
    tape = s.tape
    diag = diagonal(tape.bound)
    err = surface_error(tape, s.positions) if len(s) else np.zeros(1)
    st = s.stats
    return {"samples": len(s), "ours_s": ts["seconds"], "ours_cpu_s": ts["cpu_s"], "ours_first_run_s": ts["first_s"],
            "ours_compile_s": st.get("compile_s"), "ours_subdivide_s": st.get("subdivide_s"),
            "ours_finish_s": st.get("finish_s"), "ours_unresolved": st.get("unresolved"),
            "ours_leaf_distances_per_query": st.get("leaf_distances_per_query"),
            "ours_max_rel_error": float(err.max() / diag), "ours_rms_rel_error": float(np.sqrt(np.mean(err ** 2)) / diag),
            "quadrics": int(tape.n_quadrics), "diagonal": diag, "radius": radius, "_tape": tape}


def run_openscad(exe, scad, ext, timeout=900.0) -> dict:
    """Wall time of ``openscad -o part.EXT part.scad`` in a temporary directory."""
    with tempfile.TemporaryDirectory(prefix="clcsg-bench-") as d:
        out = os.path.join(d, os.path.splitext(os.path.basename(scad))[0] + "." + ext)
        t0 = time.perf_counter()
        try:
            p = subprocess.run([exe, "-o", out, os.path.abspath(scad)], cwd=d, capture_output=True, text=True,
                               timeout=timeout)
        except subprocess.TimeoutExpired:
            return {"seconds": None, "error": f"timed out after {timeout:.0f} s"}
        wall = time.perf_counter() - t0
        rec = {"seconds": wall, "returncode": p.returncode}
        if p.returncode != 0 or not os.path.exists(out):
            rec["error"] = " ".join((p.stderr or "").split())[-300:]
            return rec
        rec["bytes"] = os.path.getsize(out)
        if ext == "stl":
            with open(out, "rb") as f:
                data = f.read()
            rec["facets"] = data.count(b"facet normal") if data[:5] == b"solid" else \
                int.from_bytes(data[80:84], "little")
    return rec


def run_cli(scad, repeats, timeout=900.0) -> dict:
    """Best wall time of the ``clcsg sample part.scad -o part.ply`` process (r = 1% of the
    diagonal, the default): what a user waits for, the ``openscad`` export and the start
    included; a first run warms the caches a user's second run finds."""
    best, rec = None, {}
    with tempfile.TemporaryDirectory(prefix="clcsg-bench-") as d:
        argv = clcsg_command() + ["sample", os.path.abspath(scad), "-o", os.path.join(d, "part.ply"), "--quiet"]
        for _ in range(1 + max(1, repeats)):
            t0 = time.perf_counter()
            p = subprocess.run(argv, cwd=d, capture_output=True, text=True, timeout=timeout, env=environment_for_runs())
            wall = time.perf_counter() - t0
            if p.returncode != 0:
                return {"seconds": None, "error": " ".join((p.stderr or "").split())[-300:]}
            if rec.get("runs"):  # the first run only warms the caches
                best = wall if best is None else min(best, wall)
            rec["runs"] = rec.get("runs", 0) + 1
    rec["seconds"] = best
    return rec


def plate_row(ctx, manifold3d, holes, repeats) -> dict:
    """The vent plate (``bench/zoo.py`` ``plate``: a 200 x 200 x 5 mm plate minus ``holes`` x
    ``holes`` chamfered holes, 2 holes^2 + 1 primitives) sampled at r = 1% of its diagonal,
    the first call (compile, kernel builds for its register count, guard) and a warm one,
    against manifold3d building and sampling it at 32 circular segments (the cones and
    cylinders then miss the surface by about 1e-3 of the diagonal: equal accuracy would need
    several times the segments).  Errors are measured on 2,000 random samples of each."""
    shape = zoo.plate(holes)
    scene = clcsg.Scene(shape, source=f"plate_{holes * holes}_holes")
    diag = diagonal(scene.compile("tree").bound)
    ts = time_sampling(scene, zoo.PART_RADIUS * diag, ctx, repeats=repeats, warm=True)
    s = ts["samples"]
    rng = np.random.default_rng(4)
    pick = rng.choice(len(s), size=min(2000, len(s)), replace=False)
    rec = {"model": scene.source, "holes": holes * holes, "primitives": 2 * holes * holes + 1, "samples": len(s),
           "ours_first_run_s": ts["first_s"], "ours_s": ts["seconds"], "ours_cpu_s": ts["cpu_s"],
           "ours_unresolved": s.stats.get("unresolved"),
           "ours_max_rel_error": float(surface_error(s.tape, s.positions[pick]).max() / diag)}
    if manifold3d is not None:
        lv = manifold_levels(manifold3d, shape, s.tape.bound, [32], len(s), 1, s.tape, rng,
                             f"plate {holes * holes} holes manifold3d", error_points=2000)
        rec.update({"levels": lv["levels"]})
        m = lv["levels"][0] if lv.get("levels") else None
        if m:
            rec["manifold_s"] = m["total_s"]
            rec["first_run_over_manifold"] = ts["first_s"] / m["total_s"]
            rec["ours_over_manifold"] = ts["seconds"] / m["total_s"]
    print(f"plate {holes * holes} holes: clcsg first call {ts['first_s']:.2f} s, warm {ts['seconds']:.2f} s "
          f"({len(s)} samples), manifold3d {fmt(rec.get('manifold_s'), '.2f')} s: first call "
          f"{fmt(rec.get('first_run_over_manifold'), '.2f')}x", flush=True)
    return rec


def openscad_rows(ctx, names, repeats) -> dict:
    exe = shutil.which("openscad")
    if exe is None:
        return {"available": False, "reason": "openscad is not on PATH", "parts": []}
    try:
        version = subprocess.run([exe, "--version"], capture_output=True, text=True, timeout=60)
        version = (version.stdout + version.stderr).strip()
    except Exception as e:  # noqa: BLE001
        version = f"unknown ({type(e).__name__})"
    parts = []
    for name in names:
        scad, csg = zoo.example_path(name, "scad"), zoo.example_path(name, "csg")
        if not (os.path.exists(scad) and os.path.exists(csg)):
            parts.append({"part": name, "skipped": f"{scad} or {csg} is missing"})
            continue
        stl = run_openscad(exe, scad, "stl")
        export = run_openscad(exe, scad, "csg")
        cli = run_cli(scad, repeats)
        scene = clcsg.load(csg)
        diag = diagonal(scene.compile("tree").bound)
        o = ours(ctx, scene, zoo.PART_RADIUS * diag, repeats)
        o.pop("_tape")
        rec = {"part": name, "openscad_stl_s": stl.get("seconds"), "openscad_stl": stl,
               "openscad_csg_export_s": export.get("seconds"), "openscad_csg_export": export, **o,
               "cli_process_s": cli.get("seconds"), "cli": cli}
        if stl.get("seconds"):
            rec["ours_over_openscad"] = o["ours_s"] / stl["seconds"]
            if cli.get("seconds"):
                rec["cli_over_openscad"] = cli["seconds"] / stl["seconds"]
            if export.get("seconds"):
                rec["export_plus_ours_over_openscad"] = (export["seconds"] + o["ours_s"]) / stl["seconds"]
        parts.append(rec)
        print(f"openscad {name}: -o part.stl {fmt(stl.get('seconds'), '.2f')} s, -o part.csg "
              f"{fmt(export.get('seconds'), '.2f')} s; clcsg {o['ours_s']:.3f} s at r = 1% of the diagonal "
              f"({o['samples']} samples): {fmt(rec.get('ours_over_openscad'), '.3f')}x; the CLI process from the "
              f".scad {fmt(cli.get('seconds'), '.2f')} s: {fmt(rec.get('cli_over_openscad'), '.3f')}x", flush=True)
    return {"available": True, "executable": exe, "version": version, "parts": parts}


def sponge_row(ctx, manifold3d, repeats) -> dict:
    path = zoo.example_path(zoo.SPONGE, "csg")
    if not os.path.exists(path):
        return {"skipped": f"{path} is missing"}
    scene = clcsg.load(path)
    diag = diagonal(scene.compile("tree").bound)
    o = ours(ctx, scene, zoo.PART_RADIUS * diag, repeats)
    tape = o.pop("_tape")
    rec = {"model": zoo.SPONGE, **o}
    if manifold3d is not None:
        lv = manifold_levels(manifold3d, scene.shape, tape.bound, [16], o["samples"], max(repeats, 2), tape,
                             np.random.default_rng(2), "menger3 manifold3d")
        rec.update(lv)
        if rec.get("manifold_s_at_target"):
            rec["ours_over_manifold"] = o["ours_s"] / rec["manifold_s_at_target"]
    print(f"sponge: clcsg {o['ours_s']:.2f} s ({o['samples']} samples), manifold3d "
          f"{fmt(rec.get('manifold_s_at_target'), '.2f')} s: {fmt(rec.get('ours_over_manifold'), '.2f')}x", flush=True)
    return rec


def run(quick=False, device=None):
    warnings.simplefilter("ignore")
    ctx = get_context(device)
    load = Load()
    try:
        import manifold3d
    except Exception as e:  # noqa: BLE001 - any import failure means "not available"
        manifold3d = None
        manifold_msg = f"manifold3d is not available ({type(e).__name__}: {e}); install it with pip install 'clcsg[bench]'"
        print(manifold_msg)
    segments = QUICK_SEGMENTS if quick else SEGMENTS
    repeats = 1 if quick else 3
    models = zoo.MODELS
    if quick:
        models = [m for m in models if m.name in ("lens", "flange")]
    rng = np.random.default_rng(1)
    results = []
    if manifold3d is not None:
        for m in models:
            shape = m.build()
            scene = clcsg.Scene(shape, source=m.name)
            diag = diagonal(scene.compile("tree").bound)
            o = ours(ctx, scene, diag * zoo.SIZES["medium"], repeats)
            tape = o.pop("_tape")
            rec = {"model": m.name, **o}
            rec.update(manifold_levels(manifold3d, shape, tape.bound, segments, o["samples"], repeats, tape, rng,
                                       m.name))
            if rec.get("manifold_s_at_target"):
                rec["ours_over_manifold"] = o["ours_s"] / rec["manifold_s_at_target"]
            results.append(rec)
    sponge = sponge_row(ctx, manifold3d, 1 if quick else 2)
    plate = plate_row(ctx, manifold3d, 10 if quick else 50, 1)
    openscad = openscad_rows(ctx, ("l_bracket", "project_box") if quick else zoo.EVERYDAY, repeats)
    env = load.into(environment(ctx))
    env["manifold3d"] = None if manifold3d is None else (getattr(manifold3d, "__version__", None)
                                                          or _dist_version("manifold3d"))
    env["openscad"] = openscad.get("version")
    payload = {"environment": env, "available": manifold3d is not None, "quick": bool(quick),
               "method": " ".join(__doc__.split()), "target_rel_error": TARGET, "segments": segments,
               "models": results, "sponge": sponge, "plate": plate, "openscad": openscad}
    if manifold3d is None:
        payload["message"] = manifold_msg
    path = write("peers", payload)
    print()
    print(table(payload))
    print(f"\nwritten to {path}")
    return payload


def _dist_version(name):
    try:
        from importlib.metadata import version

        return version(name)
    except Exception:  # noqa: BLE001
        return None


def equal_accuracy(levels) -> dict:
    ok = [lv for lv in levels if lv["max_rel_error"] <= TARGET]
    if ok:
        lv = ok[0]
        return {"target_segments": lv["segments"], "manifold_s_at_target": lv["total_s"], "target_how": "measured"}
    usable = [lv for lv in levels if lv["max_rel_error"] > 0]
    if len(usable) < 2:
        return {"target_how": "not reached, too few levels to extrapolate"}
    ae, be = _powerfit([lv["segments"] for lv in usable], [lv["max_rel_error"] for lv in usable])
    if be >= 0:
        return {"target_how": "not reached, error does not fall with n", "error_exponent": be}
    n_t = math.exp((math.log(TARGET) - ae) / be)
    at, bt = _powerfit([lv["segments"] for lv in usable[-3:]], [lv["total_s"] for lv in usable[-3:]])
    return {"target_segments": n_t, "manifold_s_at_target": math.exp(at + bt * math.log(n_t)),
            "target_how": "extrapolated", "error_exponent": be, "time_exponent": bt}


def table(payload) -> str:
    env = payload["environment"]
    lines = [f"manifold3d {env.get('manifold3d')} vs clcsg ({env['device']}, {env['compute_units']} CUs): "
             f"time to build and sample each solid with the same number of samples; error = max first-order "
             f"distance to the nearest surface quadric / bound diagonal", "",
             "| model | quadrics | samples | segments | triangles | manifold build (ms) | manifold sampling (ms) | "
             "manifold max error | manifold RMS error |", "|---|---|---|---|---|---|---|---|---|"]
    for r in payload["models"]:
        for lv in r["levels"]:
            lines.append(f"| {r['model']} | {r['quadrics']} | {r['samples']:,} | {lv['segments']} | {lv['triangles']:,} | "
                         f"{1e3 * lv['build_s']:.1f} | {1e3 * lv['sample_s']:.1f} | {lv['max_rel_error']:.1e} | "
                         f"{lv['rms_rel_error']:.1e} |")
    lines += ["", f"At equal accuracy (max error <= {payload['target_rel_error']:g} of the diagonal):", "",
              "| model | clcsg (ms) | clcsg max error | manifold segments needed | manifold (ms) | how | clcsg / manifold |",
              "|---|---|---|---|---|---|---|"]
    for r in payload["models"]:
        nt = r.get("target_segments")
        mt = r.get("manifold_s_at_target")
        ratio = r.get("ours_over_manifold")
        lines.append(f"| {r['model']} | {1e3 * r['ours_s']:.1f} | {r['ours_max_rel_error']:.1e} | "
                     f"{'-' if nt is None else f'{nt:.0f}'} | {'-' if mt is None else f'{1e3 * mt:.1f}'} | "
                     f"{r.get('target_how', '-')}{' (' + r['unsupported'] + ')' if r.get('unsupported') else ''} | "
                     f"{'-' if ratio is None else f'{ratio:.2f}x'} |")
    sp = payload.get("sponge") or {}
    if sp and not sp.get("skipped"):
        lines += ["", "The level-3 Menger sponge (220 boxes), clcsg at r = 1% of the diagonal vs manifold3d:", "",
                  "| samples | clcsg (s) | clcsg unresolved | manifold3d build + sampling (s) | triangles | "
                  "manifold max error | clcsg / manifold |", "|---|---|---|---|---|---|---|"]
        lv = (sp.get("levels") or [{}])[0]
        lines.append(f"| {sp['samples']:,} | {sp['ours_s']:.2f} | {sp.get('ours_unresolved', 0):,} | "
                     f"{fmt(sp.get('manifold_s_at_target'), '.2f')} | {fmt(lv.get('triangles'), ',')} | "
                     f"{fmt(lv.get('max_rel_error'), '.1e')} | {fmt(sp.get('ours_over_manifold'), '.2f', 1, 'x')} |")
    pl = payload.get("plate") or {}
    if pl:
        lines += ["", f"The vent plate ({pl['holes']:,} chamfered holes, {pl['primitives']:,} primitives), clcsg at r = 1% "
                  "of the diagonal vs manifold3d at 32 segments (build + sampling):", "",
                  "| samples | clcsg first call (s) | clcsg warm (s) | clcsg max error | manifold3d (s) | triangles | "
                  "manifold max error | first call / manifold |", "|---|---|---|---|---|---|---|---|"]
        lv = (pl.get("levels") or [{}])[0]
        lines.append(f"| {pl['samples']:,} | {pl['ours_first_run_s']:.2f} | {pl['ours_s']:.2f} | "
                     f"{pl['ours_max_rel_error']:.1e} | {fmt(pl.get('manifold_s'), '.2f')} | "
                     f"{fmt(lv.get('triangles'), ',')} | {fmt(lv.get('max_rel_error'), '.1e')} | "
                     f"{fmt(pl.get('first_run_over_manifold'), '.2f', 1, 'x')} |")
    osc = payload.get("openscad") or {}
    if not osc.get("available", False):
        lines += ["", f"OpenSCAD: skipped ({osc.get('reason', 'not run')})"]
    else:
        lines += ["", f"OpenSCAD ({osc.get('version')}): openscad -o part.stl part.scad vs clcsg sampling the "
                  f"exported part.csg at r = 1% of the diagonal", "",
                  "| part | quadrics | openscad -o .stl (s) | facets | openscad -o .csg (s) | clcsg samples | "
                  "clcsg (s) | clcsg / openscad | (export + clcsg) / openscad | clcsg CLI from the .scad (s) | "
                  "CLI / openscad |", "|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in osc.get("parts", []):
            if r.get("skipped"):
                lines.append(f"| {r['part']} | skipped: {r['skipped']} |||||||||")
                continue
            lines.append(f"| {r['part']} | {r['quadrics']} | {fmt(r['openscad_stl_s'], '.2f')} | "
                         f"{fmt(r['openscad_stl'].get('facets'), ',')} | {fmt(r['openscad_csg_export_s'], '.2f')} | "
                         f"{r['samples']:,} | {r['ours_s']:.3f} | {fmt(r.get('ours_over_openscad'), '.3f', 1, 'x')} | "
                         f"{fmt(r.get('export_plus_ours_over_openscad'), '.3f', 1, 'x')} | "
                         f"{fmt(r.get('cli_process_s'), '.2f')} | {fmt(r.get('cli_over_openscad'), '.3f', 1, 'x')} |")
    return "\n".join(lines)
