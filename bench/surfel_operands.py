"""``python -m bench surfels``: a point cloud as a CSG operand, a sphere of n surfels minus a box,
against manifold3d on a mesh of the same sphere.

The cloud is a Fibonacci sampling of the unit sphere with its exact normals and one radius,
``COVER`` times the square root of the area per surfel, sqrt(4 pi / n): on a near-hexagonal
lattice the covering radius is about 0.62 of that, so the disks close the surface (measured:
``cover_distance_max``, the largest distance from 100,000 random points of the sphere to the
nearest center, against the radius).  The box is ``BOX`` (size, center): it cuts off a corner
of the sphere, so the solid has a convex rim where cloud and box meet.  Sampling radius: the
surfel radius.

Per cloud, process CPU seconds (``time.process_time``; PoCL runs its kernels in this process's
threads) of: building the operand (the checks, then the k-d tree), sampling (warm: the kernels
built once on a small cloud before), split as ``clcsg.sample`` reports it in
``stats["host_cpu_s"]`` (the device runs, host classification of samples against the cloud,
keep/drop of surfels, clip programs, combining), and rendering the splats at 640 x 480 (warm).
Peer: a trimesh icosphere of comparable vertex count minus the same box through manifold3d
(mesh to Manifold, the Boolean, ``to_mesh``), time only.  :func:`measure` is what ``python -m
bench operands`` calls for its surfel rows.
"""

from __future__ import annotations

import time
import warnings

import numpy as np

import clcsg
from clcsg.cl.device import get_context

from .common import Load, environment, fmt, write

FULL = (50_000, 200_000, 500_000)
QUICK = (50_000,)
COVER = 1.0
BOX = (1.2, (0.7, 0.5, 0.4))
W, H = 640, 480
EYE, TARGET = (2.6, -2.4, 1.9), (0.2, 0.0, 0.0)
#: icosphere subdivision with the vertex count (10 4^s + 2) nearest each cloud's size
ICO = {50_000: 6, 200_000: 7, 500_000: 8}


def sphere_cloud(n):
    """(points, normals, radius): n Fibonacci points of the unit sphere, exact normals, the
    covering radius ``COVER`` sqrt(4 pi / n)."""
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    th = np.pi * (1 + 5 ** 0.5) * i
    u = np.stack([np.cos(th) * np.sin(phi), np.sin(th) * np.sin(phi), np.cos(phi)], 1)
    return u, u.copy(), COVER * np.sqrt(4 * np.pi / n)


def _cpu(fn):
    t = time.process_time()
    out = fn()
    return time.process_time() - t, out


def _scene(cloud):
    size, center = BOX
    return clcsg.Scene(cloud - clcsg.box(size, center=center))


def _cover(cloud, rng):
    x = rng.normal(size=(100_000, 3))
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    d, _ = cloud.nearest(x, 1)
    return float(d.max())


def _ours(n, ctx):
    p, nrm, r = sphere_cloud(n)
    build_s, cloud = _cpu(lambda: clcsg.surfels(p, nrm, r))
    tree_s, _ = _cpu(lambda: cloud.tree)
    cover = _cover(cloud, np.random.default_rng(n))
    scene = _scene(clcsg.surfels(p, nrm, r))
    scene.shape.operands[0].tree  # the tree is the operand's (built above for its own timing)
    sample_s, smp = _cpu(lambda: clcsg.sample(scene, r, device=ctx, progress=False))
    cam = clcsg.Camera.look_at(EYE, TARGET, width=W, height=H)
    clcsg.render(smp, cam, device=ctx)
    render_s, img = _cpu(lambda: clcsg.render(smp, cam, device=ctx))
    st = smp.stats
    host = {k: float(v) for k, v in st.get("host_cpu_s", {}).items()}
    visible = img.ids >= 0
    return {"surfels": n, "surfel_radius": r, "cover_distance_max": cover,
            "build_cpu_s": build_s, "tree_cpu_s": tree_s, "sample_cpu_s": sample_s, "sample_split_cpu_s": host,
            "runs": int(st["runs"]), "samples": len(smp), "surfels_kept": int(st.get("surfels_kept", 0)),
            "clipped_samples": int(st.get("clipped_samples", 0)), "clip_rows": int(st.get("clip_rows", 0)),
            "render_cpu_s": render_s, "pixels": int(visible.sum()),
            "surfel_pixels": int((visible & (img.ids >= smp.tape.first_surfel_quadric)).sum())}


def _manifold(n):
    import manifold3d as mf
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


def measure(ctx, quick=False) -> list:
    """One row per cloud size: clcsg's numbers and manifold3d's on the icosphere."""
    warnings.simplefilter("ignore")
    p, nrm, r = sphere_cloud(5_000)
    clcsg.sample(_scene(clcsg.surfels(p, nrm, r)), r, device=ctx, progress=False)  # builds the kernels
    rows = []
    for n in QUICK if quick else FULL:
        ours = _ours(n, ctx)
        peer = _manifold(n)
        path = ours["build_cpu_s"] + ours["tree_cpu_s"] + ours["sample_cpu_s"]
        rows.append({"model": f"sphere_cloud_{n}_minus_box", "clcsg": ours, "manifold3d": peer,
                     "ratio_sample_path_over_manifold": path / max(peer["boolean_cpu_s"], 1e-9)})
    return rows


def table(rows) -> str:
    out = ["| surfels | radius | build+tree s | sample s | device runs s | classify s | keep s | clips s "
           "| combine s | samples | render s | manifold3d (vertices) s |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for row in rows:
        o, m = row["clcsg"], row["manifold3d"]
        h = o["sample_split_cpu_s"]
        out.append(f"| {o['surfels']} | {o['surfel_radius']:.4f} | {fmt(o['build_cpu_s'] + o['tree_cpu_s'], '.2f')} "
                   f"| {fmt(o['sample_cpu_s'], '.2f')} | {fmt(h.get('device_runs'), '.2f')} "
                   f"| {fmt(h.get('classify'), '.2f')} | {fmt(h.get('keep'), '.2f')} | {fmt(h.get('clips'), '.2f')} "
                   f"| {fmt(h.get('combine'), '.2f')} | {o['samples']} | {fmt(o['render_cpu_s'], '.3f')} "
                   f"| {fmt(m['boolean_cpu_s'], '.3f')} ({m['vertices']}) |")
    return "\n".join(out)


def run(quick=False, device=None):
    load = Load()
    ctx = get_context(device)
    rows = measure(ctx, quick)
    env = load.into(environment(ctx))
    env["timer"] = "process CPU time (one warm run each)"
    payload = {"environment": env, "quick": quick, "box": {"size": BOX[0], "center": BOX[1]},
               "image": [W, H], "rows": rows}
    print(write("surfels", payload))
    print(table(rows))
    return payload
