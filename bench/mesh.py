"""``python -m bench mesh``: ``clcsg mesh`` against ``openscad -o part.stl`` and manifold3d.

Per part, the mesh's triangle count, CPU time (process time of ``clcsg.mesh``; the child's CPU
time for openscad, from ``getrusage(RUSAGE_CHILDREN)``; manifold3d's build + ``to_mesh`` by
process time; for clcsg and manifold3d the least of their runs: :data:`REPEATS` each, then
:data:`REPEATS` more alternating with each other, so that the machine's drift does not enter
the ratio) and its measured
largest error over every triangle's centroid, edge midpoints (where chords sag most) and the
point where its nearest quadric peaks on it (where a faceted sphere dips most), and
area-weighted random points, relative to the bound's diagonal: the distance to the nearest
quadric of the scene along its gradient line (``max_rel_error``,
:func:`~bench.common.surface_error`) and, for clcsg and openscad, on the random points and the
2,000 points of largest such error, the distance to the CSG surface itself
(``max_rel_csg_error``, :func:`~bench.common.csg_surface_error`, which also sees a triangle on
a quadric's extension).  Rows:

* the everyday OpenSCAD parts: openscad's STL at the file's own ``$fn`` (its error measured),
  clcsg at the default tolerance (0.1% of the diagonal) and at openscad's measured error
  (equal tolerance), manifold3d at the fewest segments that reach the default tolerance;
* the zoo models: clcsg at the default tolerance and manifold3d at equal tolerance;
* the Menger sponge (not with ``--quick``): clcsg at the default tolerance, manifold3d (exact).

Per row the ratios clcsg / peer of CPU time and triangle count (``ratios``).

Whether the mesh is closed and 2-manifold is checked for every mesh (manifold3d's status and
trimesh's ``is_watertight``).
"""

from __future__ import annotations

import os
import resource
import shutil
import subprocess
import tempfile
import time
import warnings

import numpy as np

import clcsg

from . import zoo
from .common import Load, Translator, Unsupported, csg_surface_error, diagonal, fmt, least_cpu, surface_error, write

SEGMENTS = (12, 14, 16, 18, 20, 24, 28, 32, 40, 48, 56, 64, 80, 96, 128)
QUICK_SEGMENTS = (16, 32, 64)
DEFAULT_REL = 1e-3
SAMPLES = 20000
#: CPU times are the least of this many runs (clcsg and manifold3d alike)
REPEATS = 3


def _sample(vertices, triangles, rng, count=SAMPLES, tape=None):
    """Points where a mesh's error is measured: every triangle's centroid and edge midpoints
    (a chord's sag peaks at its midpoint, which random points rarely hit), with ``tape`` the
    point of each triangle where its nearest quadric's form peaks (:func:`_peaks`: a faceted
    sphere's triangle dips deepest there, rarely at its centroid), and ``count`` area-weighted
    random points (those last)."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    fixed = [(a + b + c) / 3.0, 0.5 * (a + b), 0.5 * (b + c), 0.5 * (c + a)]
    if tape is not None:
        fixed.append(_peaks(tape, a, b, c))
    return np.concatenate(fixed + [_random_points(a, b, c, rng, count)])


def _peaks(tape, a, b, c):
    """Per triangle (a, b, c) the point where Q, its centroid's nearest quadric, restricted to
    the triangle's plane is stationary, x = a + u (b - a) + v (c - a) with grad_(u, v) Q = 0
    (a 2 x 2 system: Q is quadratic in u, v), where that lies inside the triangle; else the
    centroid."""
    from .common import nearest_quadric

    cen = (a + b + c) / 3.0
    q = np.asarray(tape.quadrics)[nearest_quadric(tape, cen)[1]]  # (T, 4, 4)
    e = np.stack([b - a, c - a], axis=1)  # (T, 2, 3)
    ah = np.concatenate([a, np.ones((len(a), 1))], axis=1)
    eh = np.concatenate([e, np.zeros((len(a), 2, 1))], axis=2)  # directions: w = 0
    h = np.einsum("tij,tjk,tlk->til", eh, q, eh)  # (T, 2, 2): e_i^T Q e_j
    g = np.einsum("tij,tjk,tk->ti", eh, q, ah)  # (T, 2): e_i^T Q a
    with np.errstate(all="ignore"):
        det = h[:, 0, 0] * h[:, 1, 1] - h[:, 0, 1] * h[:, 1, 0]
        u = (-g[:, 0] * h[:, 1, 1] + g[:, 1] * h[:, 0, 1]) / det
        v = (-g[:, 1] * h[:, 0, 0] + g[:, 0] * h[:, 1, 0]) / det
        inside = np.isfinite(u) & np.isfinite(v) & (u >= 0) & (v >= 0) & (u + v <= 1)
    u, v = np.where(inside, u, 0.0), np.where(inside, v, 0.0)
    return np.where(inside[:, None], a + u[:, None] * e[:, 0] + v[:, None] * e[:, 1], cen)


def _errors(tape, vertices, triangles, rng, floor) -> tuple[float, float]:
    """(largest distance to the nearest quadric (:func:`~bench.common.surface_error`) over :func:`_sample`'s points,
    largest distance to the CSG surface over its random points and the :data:`WORST` points
    of the first measure), relative to the diagonal."""
    pts = _sample(vertices, triangles, rng, tape=tape)
    err = surface_error(tape, pts)
    pick = np.union1d(np.arange(len(pts) - SAMPLES, len(pts)), np.argsort(err)[-WORST:])
    diag = diagonal(tape.bound)
    return float(err.max() / diag), float(csg_surface_error(tape, pts[pick], floor).max() / diag)


#: points of the largest error to the nearest quadric also measured against the CSG surface
WORST = 2000


def _random_points(a, b, c, rng, count):
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    tri = np.searchsorted(np.cumsum(area), rng.random(count) * area.sum())
    tri = np.minimum(tri, len(a) - 1)
    u, v = rng.random(count), rng.random(count)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    return a[tri] + u[:, None] * (b[tri] - a[tri]) + v[:, None] * (c[tri] - a[tri])


def _closed(vertices, triangles) -> bool:
    import manifold3d
    import trimesh

    mm = manifold3d.Mesh(vert_properties=np.asarray(vertices, np.float32), tri_verts=np.asarray(triangles, np.uint32))
    ok = manifold3d.Manifold(mm).status() == manifold3d.Error.NoError
    return bool(ok and trimesh.Trimesh(vertices, triangles, process=False).is_watertight)


def _interleaved(rec, scene, tape, tolerance) -> None:
    """clcsg's and manifold3d's CPU times again, their runs alternating (the machine's speed
    drifts over a run; a ratio of times taken minutes apart carries the drift), each the least
    of its runs so far."""
    import manifold3d

    level = rec["manifold3d"].get("at_tolerance")
    if level is None:
        return
    n, shape = level["segments"], scene.shape
    for _ in range(REPEATS):
        ours_cpu, _ = least_cpu(lambda: clcsg.mesh(scene, tolerance=tolerance), 1)
        peer_cpu, _ = least_cpu(lambda: Translator(manifold3d, n, tape.bound).build(shape).to_mesh(), 1)
        rec["ours"]["cpu_s"] = min(rec["ours"]["cpu_s"], ours_cpu)
        level["cpu_s"] = min(level["cpu_s"], peer_cpu)


def ours(scene, tape, tolerance, rng) -> dict:
    cpu, m = least_cpu(lambda: clcsg.mesh(scene, tolerance=tolerance), REPEATS)
    err, csg = _errors(tape, m.vertices, m.triangles, rng, 0.01 * m.tolerance)
    return {"triangles": len(m.triangles), "cpu_s": cpu, "max_rel_error": float(err), "max_rel_csg_error": float(csg),
            "tolerance_rel": m.tolerance / diagonal(tape.bound), "closed_manifold": _closed(m.vertices, m.triangles),
            "spanning_triangles": m.stats.get("spanning_triangles"), "planar_patches": m.stats.get("planar_patches"),
            "method": m.stats.get("method"), "facet_rounds": m.stats.get("facet_rounds"),
            "stage_cpu_s": m.stats.get("stage_cpu_s")}


def manifold_row(shape, tape, target_rel, segments, rng) -> dict:
    """manifold3d at the fewest segments whose measured error is under ``target_rel``."""
    import manifold3d

    rec = {"levels": []}
    for n in segments:
        try:
            t0 = time.process_time()
            mesh = Translator(manifold3d, n, tape.bound).build(shape).to_mesh()
            cpu = time.process_time() - t0
        except Unsupported as e:
            rec["unsupported"] = str(e)
            return rec
        v = np.asarray(mesh.vert_properties, np.float64)[:, :3]
        t = np.asarray(mesh.tri_verts, np.int64)
        err = float(surface_error(tape, _sample(v, t, rng, tape=tape)).max() / diagonal(tape.bound))
        rec["levels"].append({"segments": n, "triangles": len(t), "cpu_s": cpu, "max_rel_error": err})
        if err <= target_rel:
            best, _ = least_cpu(lambda: Translator(manifold3d, n, tape.bound).build(shape).to_mesh(), REPEATS)
            rec["levels"][-1]["cpu_s"] = min(cpu, best)
            rec.update(at_tolerance=rec["levels"][-1])
            break
    return rec


def openscad_row(exe, scad, tape, rng, timeout=600.0) -> dict:
    import trimesh

    with tempfile.TemporaryDirectory(prefix="clcsg-bench-mesh-") as d:
        out = os.path.join(d, "part.stl")
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        try:
            p = subprocess.run([exe, "-o", out, os.path.abspath(scad)], cwd=d, capture_output=True, text=True,
                               timeout=timeout)
        except subprocess.TimeoutExpired:
            return {"error": f"timed out after {timeout:.0f} s"}
        wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if p.returncode != 0 or not os.path.exists(out):
            return {"error": " ".join((p.stderr or "").split())[-300:]}
        tm = trimesh.load(out, force="mesh")
    err, csg = _errors(tape, np.asarray(tm.vertices), np.asarray(tm.faces), rng, 1e-5 * diagonal(tape.bound))
    return {"triangles": int(len(tm.faces)), "wall_s": wall,
            "cpu_s": (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime),
            "max_rel_error": err, "max_rel_csg_error": csg, "watertight": bool(tm.is_watertight)}


def _everyday(names, segments, rng):
    exe = shutil.which("openscad")
    rows = []
    for name in names:
        scene = clcsg.load(zoo.example_path(name, "csg"))
        tape = scene.compile()
        rec = {"part": name, "ours": ours(scene, tape, f"{100 * DEFAULT_REL}%", rng)}
        if exe:
            rec["openscad"] = osc = openscad_row(exe, zoo.example_path(name, "scad"), tape, rng)
            if "max_rel_error" in osc:
                rec["ours_at_openscad_error"] = ours(scene, tape, f"{100 * osc['max_rel_error']}%", rng)
        rec["manifold3d"] = manifold_row(scene.shape, tape, DEFAULT_REL, segments, rng)
        _interleaved(rec, scene, tape, f"{100 * DEFAULT_REL}%")
        rec["ratios"] = ratios(rec)
        rows.append(rec)
        print(_line(name, rec), flush=True)
    return rows


def _zoo(names, segments, rng):
    rows = []
    for m in zoo.MODELS:
        if m.name not in names:
            continue
        scene = clcsg.Scene(m.build(), source=m.name)
        tape = scene.compile()
        rec = {"part": m.name, "ours": ours(scene, tape, f"{100 * DEFAULT_REL}%", rng),
               "manifold3d": manifold_row(scene.shape, tape, DEFAULT_REL, segments, rng)}
        _interleaved(rec, scene, tape, f"{100 * DEFAULT_REL}%")
        rec["ratios"] = ratios(rec)
        rows.append(rec)
        print(_line(m.name, rec), flush=True)
    return rows


def _sponge(rng):
    """The Menger sponge: clcsg at the default tolerance, manifold3d (boxes are exact: one level)."""
    scene = clcsg.load(zoo.example_path(zoo.SPONGE, "csg"))
    tape = scene.compile()
    rec = {"part": zoo.SPONGE, "ours": ours(scene, tape, f"{100 * DEFAULT_REL}%", rng),
           "manifold3d": manifold_row(scene.shape, tape, DEFAULT_REL, SEGMENTS[:1], rng)}
    _interleaved(rec, scene, tape, f"{100 * DEFAULT_REL}%")
    rec["ratios"] = ratios(rec)
    print(_line(zoo.SPONGE, rec), flush=True)
    return [rec]


def ratios(rec) -> dict:
    """clcsg / peer for CPU time and triangles (below 1: clcsg is faster, or has fewer)."""
    o, out = rec["ours"], {}
    peers = {"openscad": rec.get("openscad", {}), "manifold3d": rec["manifold3d"].get("at_tolerance") or {}}
    for name, p in peers.items():
        if p.get("cpu_s"):
            out[f"cpu_vs_{name}"] = o["cpu_s"] / p["cpu_s"]
        if p.get("triangles"):
            out[f"triangles_vs_{name}"] = o["triangles"] / p["triangles"]
    eq = rec.get("ours_at_openscad_error")
    if eq and peers["openscad"].get("cpu_s"):
        out["cpu_vs_openscad_at_its_error"] = eq["cpu_s"] / peers["openscad"]["cpu_s"]
        out["triangles_vs_openscad_at_its_error"] = eq["triangles"] / peers["openscad"]["triangles"]
    return out


def _line(name, rec) -> str:
    o = rec["ours"]
    s = f"{name}: clcsg {o['triangles']} triangles {o['cpu_s']:.2f} s (error {o['max_rel_error']:.1e})"
    if "openscad" in rec and "triangles" in rec["openscad"]:
        osc = rec["openscad"]
        s += f"; openscad {osc['triangles']} triangles {osc['cpu_s']:.2f} s (error {osc['max_rel_error']:.1e})"
    mf = rec["manifold3d"].get("at_tolerance")
    if mf:
        s += f"; manifold3d n={mf['segments']} {mf['triangles']} triangles {mf['cpu_s']:.3f} s"
    return s


def table(payload) -> str:
    head = ("| part | clcsg triangles | clcsg CPU s | clcsg max error (to the CSG surface) | openscad triangles | openscad CPU s | "
            "openscad max error | clcsg at openscad's error: triangles / CPU s | manifold3d at 0.1%: triangles / CPU s | "
            "CPU clcsg / openscad | CPU clcsg / manifold3d | triangles clcsg / manifold3d |")
    lines = [head, "|" + "---|" * 12]
    for r in payload["everyday"] + payload["zoo"] + payload.get("sponge", []):
        o, osc = r["ours"], r.get("openscad", {})
        eq = r.get("ours_at_openscad_error")
        mf = r["manifold3d"].get("at_tolerance")
        lines.append(f"| {r['part']} | {o['triangles']} | {o['cpu_s']:.2f} | {o['max_rel_error']:.1e} "
                     f"({fmt(o.get('max_rel_csg_error'), '.1e')}) | "
                     f"{osc.get('triangles', '-')} | {fmt(osc.get('cpu_s'), '.2f')} | "
                     f"{fmt(osc.get('max_rel_error'), '.1e')} | "
                     f"{(str(eq['triangles']) + ' / ' + format(eq['cpu_s'], '.2f')) if eq else '-'} | "
                     f"{(str(mf['triangles']) + ' / ' + format(mf['cpu_s'], '.3f')) if mf else '-'} | "
                     f"{fmt(r['ratios'].get('cpu_vs_openscad'), '.2f')} | {fmt(r['ratios'].get('cpu_vs_manifold3d'), '.0f')} | "
                     f"{fmt(r['ratios'].get('triangles_vs_manifold3d'), '.2f')} |")
    return "\n".join(lines)


def run(quick=False, device=None):
    warnings.simplefilter("ignore")
    load = Load()
    rng = np.random.default_rng(5)
    segments = QUICK_SEGMENTS if quick else SEGMENTS
    everyday = ("l_bracket", "rook") if quick else zoo.EVERYDAY
    models = ("lens", "drilled_die") if quick else tuple(m.name for m in zoo.MODELS)
    payload = {"method": " ".join(__doc__.split()), "quick": bool(quick), "default_rel_tolerance": DEFAULT_REL,
               "everyday": _everyday(everyday, segments, rng), "zoo": _zoo(models, segments, rng),
               "sponge": [] if quick else _sponge(rng)}
    payload["environment"] = load.into({"date": time.strftime("%Y-%m-%dT%H:%M:%S"), "cpus": os.cpu_count(),
                                        "clcsg": clcsg.__version__, "timing": "process CPU time"})
    path = write("mesh", payload)
    print()
    print(table(payload))
    print(f"\nwritten to {path}")
    return payload
