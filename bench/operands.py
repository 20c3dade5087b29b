"""``python -m bench operands``: meshes as CSG operands, against manifold3d in the same run.

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
``device_s`` (its levels and the finish pass) beside it), rendering the splats and ray tracing
at 320x240; and manifold3d's Boolean of the same mesh minus the cylinders (32 segments) with
``to_mesh``.  Ratios are clcsg's sampling path (build + compile + sample) over manifold3d's
Boolean.  ``--quick``: the smallest model of each family.  The point-cloud operands have
their own benchmark (``python -m bench surfels``).
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


def _cpu(fn):
    t = time.process_time()
    out = fn()
    return time.process_time() - t, out


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


def run(quick=False, device=None):
    import manifold3d as mf

    warnings.simplefilter("ignore")
    load = Load()
    ctx = get_context(device)
    rows = []
    for family, sizes in (QUICK if quick else FULL).items():
        for k in sizes:
            v, f, holes = {"bosses": lambda: _bosses(mf, k), "icosphere": lambda: _icosphere(k),
                           "torus": lambda: _torus(k)}[family]()
            ours = _ours(v, f, holes, ctx)
            peer = _manifold(mf, v, f, holes)
            path = ours["build_cpu_s"] + ours["compile_cpu_s"] + ours["sample_cpu_s"]
            rows.append({"model": f"{family}_{k}", "triangles": int(len(f)), "clcsg": ours, "manifold3d": peer,
                         "ratio_sample_path_over_manifold": path / max(peer["boolean_cpu_s"], 1e-9)})
    env = load.into(environment(ctx))
    env["timer"] = "process CPU time (one warm run each)"
    payload = {"environment": env, "quick": quick, "rows": rows}
    print(write("operands", payload))
    print("| model | triangles | planes | build s | compile s | sample s | samples | render s | raytrace s "
          "| manifold3d s | ratio |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        o = r["clcsg"]
        print(f"| {r['model']} | {r['triangles']} | {o['face_planes']} | {fmt(o['build_cpu_s'], '.2f')} "
              f"| {fmt(o['compile_cpu_s'], '.2f')} | {fmt(o['sample_cpu_s'], '.2f')} | {o['samples']} "
              f"| {fmt(o['render_cpu_s'], '.2f')} | {fmt(o['raytrace_cpu_s'], '.2f')} "
              f"| {fmt(r['manifold3d']['boolean_cpu_s'], '.3f')} | {fmt(r['ratio_sample_path_over_manifold'], '.0f')} |")
    return payload
