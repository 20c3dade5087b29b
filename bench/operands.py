"""``python -m bench operands``: meshes and point clouds as CSG operands, against manifold3d in
the same run.

Each model is a closed triangle mesh minus 20 cylinders:

* ``bosses_k``: a plate with k x k square bosses (a CAD-like mesh: many triangles, few face
  planes), built and meshed by manifold3d; k = 80 has 103,244 triangles on 327 face planes;
* ``icosphere_s``: a tessellated sphere (subdivision s; every triangle its own plane: the case
  where clcsg's cost grows fastest, since a mesh operand is an expression of its face planes);
  s = 6 has 81,920;
* ``torus_100000``: a torus of 100,000 triangles, each its own plane, not convex: the issue's
  100k-triangle STL.

Meshes of more than ``clcsg.model.polyhedron.PARTITION_PLANES`` face planes are k-d trees of
local BSPs (:mod:`clcsg.model.mesh_partition`), so that a region's tapes hold the planes of
the cells near it.  Per model, process CPU time (``time.process_time``; PoCL runs its kernels
in this process's threads) of: building the operand (the checks and the expression),
compiling, sampling at 1/200 of the bound's diagonal (warm: the kernels built once before; the
sampler's own split ``host_s`` (the resource guard's estimate and the root tapes) and
``device_s`` (its levels and reading the samples back) beside it), rendering the splats and ray tracing
at 320x240; and manifold3d's Boolean of the same mesh minus the cylinders (32 segments) with
``to_mesh``.  Ratios are clcsg's sampling path (build + compile + sample) over manifold3d's
Boolean.

In the same run, a point cloud as a CSG operand (``surfel_rows``): a sphere of n surfels (50k,
200k, 500k) minus a box, against manifold3d on a mesh of the same sphere.  The cloud is a
Fibonacci sampling of the unit sphere with its exact normals and one radius, ``COVER`` times the
square root of the area per surfel, sqrt(4 pi / n): on a near-hexagonal lattice the covering
radius is about 0.62 of that, so the disks close the surface (measured: ``cover_distance_max``,
the largest distance from 100,000 random points of the sphere to the nearest center, against
the radius).  The box is ``BOX`` (size, center): it cuts off a corner of the sphere, so the
solid has a convex rim where cloud and box meet.  Sampling radius: the surfel radius.  Per
cloud, process CPU seconds of: building the operand (the checks, then the k-d tree), sampling
(warm: the kernels built once on a small cloud before; its wall seconds beside it), split as
``clcsg.sample`` reports it in ``stats["host_cpu_s"]`` (the device runs, host classification of
samples against the cloud, keep/drop of surfels, clip programs, combining), and rendering the
splats at 640 x 480 (warm).  Peer: a trimesh icosphere of comparable vertex count minus the
same box through manifold3d (mesh to Manifold, the Boolean, ``to_mesh``), time only.  The
ratio is clcsg's path (build + tree + sample) over manifold3d's Boolean.  ``python -m bench
surfels`` runs the surfel rows alone (:func:`run_surfels`, ``surfels.json``).

``--quick``: the smallest model of each family, and the 50k-surfel cloud.
"""

from __future__ import annotations

import time
import warnings

import numpy as np

import clcsg
from clcsg.cl.device import get_context

from .common import Load, diagonal, environment, fmt, write

FULL = {"bosses": (4, 8, 12, 80), "icosphere": (1, 2, 3, 4, 5, 6), "torus": (100_000,)}
QUICK = {"bosses": (4,), "icosphere": (1,)}
N_CYLINDERS = 20
SEGMENTS = 32
W, H = 320, 240

SURFELS_FULL = (50_000, 200_000, 500_000)
SURFELS_QUICK = (50_000,)
COVER = 1.0
BOX = (1.2, (0.7, 0.5, 0.4))
SURFEL_W, SURFEL_H = 640, 480
EYE, TARGET = (2.6, -2.4, 1.9), (0.2, 0.0, 0.0)
#: icosphere subdivision with the vertex count (10 4^s + 2) nearest each cloud's size
ICO = {50_000: 6, 200_000: 7, 500_000: 8}


def _bosses(mf, k):
    m = mf.Manifold.cube([2.0 * k, 2.0 * k, 1.0])
    for i in range(k):
        for j in range(k):
            m = m + mf.Manifold.cube([1.0, 1.0, 1.0]).translate([2.0 * i + 0.5, 2.0 * j + 0.5, 0.5])
    mesh = m.to_mesh()
    v, f = np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3], np.asarray(mesh.tri_verts, dtype=np.int64)
    rng = np.random.default_rng(k)
    xy = rng.uniform(0.3, 2.0 * k - 0.3, (N_CYLINDERS, 2))
    holes = [(x, y, 0.75, 0.12 * (k / 4) ** 0.5, 4.0) for x, y in xy]
    return v, f, holes


def _icosphere(s):
    import trimesh

    m = trimesh.creation.icosphere(s)
    rng = np.random.default_rng(s)
    ang = rng.uniform(0, 2 * np.pi, N_CYLINDERS)
    rad = np.sqrt(rng.uniform(0, 0.6, N_CYLINDERS))
    holes = [(r * np.cos(a), r * np.sin(a), 0.0, 0.06, 3.0) for r, a in zip(rad, ang)]
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64), holes


def _torus(n):
    """A torus of ``n`` triangles (500 x n / 1000 sections), minus cylinders through its ring."""
    import trimesh

    minor = max(8, int(round((n / 2.5) ** 0.5)))
    major = max(8, n // (2 * minor))
    m = trimesh.creation.torus(1.0, 0.4, major_sections=major, minor_sections=minor)
    ang = np.linspace(0, 2 * np.pi, N_CYLINDERS, endpoint=False)
    holes = [(np.cos(a), np.sin(a), 0.0, 0.12, 3.0) for a in ang]
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64), holes


def _times(fn):
    """(process CPU seconds, wall seconds, result) of ``fn()``."""
    t, w = time.process_time(), time.perf_counter()
    out = fn()
    return time.process_time() - t, time.perf_counter() - w, out


def _cpu(fn):
    seconds, _, out = _times(fn)
    return seconds, out


def _ours(v, f, holes, ctx):
    build_s, mesh = _cpu(lambda: clcsg.polyhedron(v, f, max_planes=len(f)))
    cyl = [clcsg.cylinder(h, r, center=(x, y, z)) for x, y, z, r, h in holes]
    scene = clcsg.Scene(clcsg.difference(mesh, *cyl))
    compile_s, tape = _cpu(scene.compile)
    radius = diagonal(tape.bound) / 200
    clcsg.sample(scene, radius, device=ctx, progress=False)  # builds the kernels for this tape
    scene = clcsg.Scene(clcsg.difference(clcsg.polyhedron(v, f, max_planes=len(f)), *cyl))
    scene.compile()
    sample_s, samples = _cpu(lambda: clcsg.sample(scene, radius, device=ctx, progress=False))
    st = samples.stats
    device_s = float(st.get("subdivide_s", 0.0)) + float(st.get("finish_s", 0.0))
    cam = clcsg.Camera.fit(tape, W, H)
    clcsg.render(samples, cam, device=ctx)
    render_s, img = _cpu(lambda: clcsg.render(samples, cam, device=ctx))
    clcsg.raytrace(tape, cam, device=ctx)
    trace_s, exact = _cpu(lambda: clcsg.raytrace(tape, cam, device=ctx))
    return {"face_planes": int(mesh.surfaces.get("plane", 0)), "quadrics": tape.stats["quadrics"],
            "instructions": tape.stats["instructions"], "radius": radius, "samples": len(samples),
            "unresolved_cells": int(samples.stats.get("unresolved", 0)),
            "build_cpu_s": build_s, "compile_cpu_s": compile_s, "sample_cpu_s": sample_s,
            "sample_device_s": device_s, "sample_host_s": max(0.0, float(st.get("total_s", 0.0)) - device_s),
            "render_cpu_s": render_s, "raytrace_cpu_s": trace_s,
            "mask_agreement": float((img.mask == exact.mask).mean())}


def _manifold(mf, v, f, holes):
    def run():
        m = mf.Manifold(mf.Mesh(vert_properties=v.astype(np.float32), tri_verts=f.astype(np.uint32)))
        for x, y, z, r, h in holes:
            m = m - mf.Manifold.cylinder(h, r, r, circular_segments=SEGMENTS, center=True).translate([x, y, z])
        return m.to_mesh()

    run()
    seconds, out = _cpu(run)
    return {"boolean_cpu_s": seconds, "triangles": int(len(out.tri_verts)), "segments": SEGMENTS}


def measure(ctx, quick=False) -> list:
    """One row per mesh: clcsg's numbers and manifold3d's Boolean of the same mesh."""
    import manifold3d as mf

    warnings.simplefilter("ignore")
    rows = []
    for family, sizes in (QUICK if quick else FULL).items():
        for k in sizes:
            v, f, holes = {"bosses": lambda: _bosses(mf, k), "icosphere": lambda: _icosphere(k),
                           "torus": lambda: _torus(k)}[family]()
            ours = _ours(v, f, holes, ctx)
            peer = _manifold(mf, v, f, holes)
            path = ours["build_cpu_s"] + ours["compile_cpu_s"] + ours["sample_cpu_s"]
            rows.append(_row(f"{family}_{k}", ours, peer, path, triangles=int(len(f))))
    return rows


def _row(model: str, ours: dict, peer: dict, path: float, **extra) -> dict:
    """A result row: clcsg's figures, manifold3d's, and clcsg's sampling path (CPU s) over
    manifold3d's Boolean."""
    return {"model": model, **extra, "clcsg": ours, "manifold3d": peer,
            "ratio_sample_path_over_manifold": path / max(peer["boolean_cpu_s"], 1e-9)}


def table(rows) -> str:
    out = ["| model | triangles | planes | build s | compile s | sample s | samples | render s | raytrace s "
           "| manifold3d s | ratio |",
           "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        o = r["clcsg"]
        out.append(f"| {r['model']} | {r['triangles']} | {o['face_planes']} | {fmt(o['build_cpu_s'], '.2f')} "
                   f"| {fmt(o['compile_cpu_s'], '.2f')} | {fmt(o['sample_cpu_s'], '.2f')} | {o['samples']} "
                   f"| {fmt(o['render_cpu_s'], '.2f')} | {fmt(o['raytrace_cpu_s'], '.2f')} "
                   f"| {fmt(r['manifold3d']['boolean_cpu_s'], '.3f')} "
                   f"| {fmt(r['ratio_sample_path_over_manifold'], '.0f')} |")
    return "\n".join(out)


def sphere_cloud(n):
    """(points, normals, radius): n Fibonacci points of the unit sphere, exact normals, the
    covering radius ``COVER`` sqrt(4 pi / n)."""
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    th = np.pi * (1 + 5 ** 0.5) * i
    u = np.stack([np.cos(th) * np.sin(phi), np.sin(th) * np.sin(phi), np.cos(phi)], 1)
    return u, u.copy(), COVER * np.sqrt(4 * np.pi / n)


def _surfel_scene(cloud):
    size, center = BOX
    return clcsg.Scene(cloud - clcsg.box(size, center=center))


def _cover(cloud, rng):
    x = rng.normal(size=(100_000, 3))
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    d, _ = cloud.nearest(x, 1)
    return float(d.max())


def _surfels_ours(n, ctx):
    p, nrm, r = sphere_cloud(n)
    build_s, cloud = _cpu(lambda: clcsg.surfels(p, nrm, r))
    tree_s, _ = _cpu(lambda: cloud.tree)
    cover = _cover(cloud, np.random.default_rng(n))
    scene = _surfel_scene(clcsg.surfels(p, nrm, r))
    scene.shape.operands[0].tree  # the tree is the operand's (built above for its own timing)
    sample_s, sample_wall_s, smp = _times(lambda: clcsg.sample(scene, r, device=ctx, progress=False))
    cam = clcsg.Camera.look_at(EYE, TARGET, width=SURFEL_W, height=SURFEL_H)
    clcsg.render(smp, cam, device=ctx)
    render_s, img = _cpu(lambda: clcsg.render(smp, cam, device=ctx))
    st = smp.stats
    host = {k: float(v) for k, v in st.get("host_cpu_s", {}).items()}
    visible = img.ids >= 0
    return {"surfels": n, "surfel_radius": r, "cover_distance_max": cover,
            "build_cpu_s": build_s, "tree_cpu_s": tree_s, "sample_cpu_s": sample_s, "sample_wall_s": sample_wall_s,
            "sample_split_cpu_s": host,
            "runs": int(st["runs"]), "samples": len(smp), "surfels_kept": int(st.get("surfels_kept", 0)),
            "clipped_samples": int(st.get("clipped_samples", 0)), "clip_rows": int(st.get("clip_rows", 0)),
            "render_cpu_s": render_s, "pixels": int(visible.sum()),
            "surfel_pixels": int((visible & (img.ids >= smp.tape.first_surfel_quadric)).sum())}


def _surfels_manifold(mf, n):
    import trimesh

    m = trimesh.creation.icosphere(ICO[n])
    v, f = np.asarray(m.vertices, dtype=np.float32), np.asarray(m.faces, dtype=np.uint32)
    size, center = BOX

    def run():
        a = mf.Manifold(mf.Mesh(vert_properties=v, tri_verts=f))
        b = mf.Manifold.cube([size] * 3, center=True).translate(list(center))
        return (a - b).to_mesh()

    run()
    seconds, out = _cpu(run)
    return {"subdivision": ICO[n], "vertices": int(len(v)), "triangles": int(len(f)),
            "boolean_cpu_s": seconds, "out_triangles": int(len(out.tri_verts))}


def measure_surfels(ctx, quick=False) -> list:
    """One row per cloud size: clcsg's numbers and manifold3d's on the icosphere."""
    import manifold3d as mf

    warnings.simplefilter("ignore")
    p, nrm, r = sphere_cloud(5_000)
    clcsg.sample(_surfel_scene(clcsg.surfels(p, nrm, r)), r, device=ctx, progress=False)  # builds the kernels
    rows = []
    for n in SURFELS_QUICK if quick else SURFELS_FULL:
        ours = _surfels_ours(n, ctx)
        peer = _surfels_manifold(mf, n)
        path = ours["build_cpu_s"] + ours["tree_cpu_s"] + ours["sample_cpu_s"]
        rows.append(_row(f"sphere_cloud_{n}_minus_box", ours, peer, path))
    return rows


def surfel_table(rows) -> str:
    out = ["| surfels | radius | build+tree s | sample s (wall) | device runs s | classify s | keep s | clips s "
           "| combine s | samples | render s | manifold3d (vertices) s | ratio |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for row in rows:
        o, m = row["clcsg"], row["manifold3d"]
        h = o["sample_split_cpu_s"]
        out.append(f"| {o['surfels']} | {o['surfel_radius']:.4f} | {fmt(o['build_cpu_s'] + o['tree_cpu_s'], '.2f')} "
                   f"| {fmt(o['sample_cpu_s'], '.2f')} ({fmt(o.get('sample_wall_s'), '.2f')}) "
                   f"| {fmt(h.get('device_runs'), '.2f')} "
                   f"| {fmt(h.get('classify'), '.2f')} | {fmt(h.get('keep'), '.2f')} | {fmt(h.get('clips'), '.2f')} "
                   f"| {fmt(h.get('combine'), '.2f')} | {o['samples']} | {fmt(o['render_cpu_s'], '.3f')} "
                   f"| {fmt(m['boolean_cpu_s'], '.3f')} ({m['vertices']}) "
                   f"| {fmt(row['ratio_sample_path_over_manifold'], '.1f')} |")
    return "\n".join(out)


def _surfel_setup() -> dict:
    return {"box": {"size": BOX[0], "center": BOX[1]}, "image": [SURFEL_W, SURFEL_H]}


def run(quick=False, device=None):
    """The meshes minus cylinders (``rows``) and the surfel clouds minus a box (``surfel_rows``)."""
    load = Load()
    ctx = get_context(device)
    rows = measure(ctx, quick)
    surfel_rows = measure_surfels(ctx, quick)
    env = load.into(environment(ctx))
    env["timer"] = "process CPU time (one warm run each)"
    payload = {"environment": env, "quick": quick, "rows": rows, "surfel_rows": surfel_rows,
               "surfel_setup": _surfel_setup()}
    print(write("operands", payload))
    print(table(rows))
    print()
    print(surfel_table(surfel_rows))
    return payload


def run_surfels(quick=False, device=None):
    """``python -m bench surfels``: the surfel rows alone, written to ``surfels.json``."""
    load = Load()
    ctx = get_context(device)
    rows = measure_surfels(ctx, quick)
    env = load.into(environment(ctx))
    env["timer"] = "process CPU time (one warm run each)"
    payload = {"environment": env, "quick": quick, **_surfel_setup(), "rows": rows}
    print(write("surfels", payload))
    print(surfel_table(rows))
    return payload
