"""``python -m bench.mesh_figure [PART]``: the README picture of ``clcsg mesh``: the part's
clcsg mesh next to ``openscad -o part.stl`` of the same file, flat-shaded (one grey per
triangle from its normal, a small numpy z-buffer rasterizer) with the triangle edges drawn; written to
``docs/images/mesh_vs_openscad.png``."""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile

import numpy as np

import clcsg

from . import zoo

OUT = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "docs", "images",
                   "mesh_vs_openscad.png")
LIGHT = np.array([0.4, 0.6, 0.7])  # in view coordinates: right, up, towards the viewer


def _view(elev, azim):
    """Rows: the camera's right, up and towards-viewer axes for a turntable view."""
    e, a = np.radians(elev), np.radians(azim)
    back = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
    right = np.cross([0.0, 0.0, 1.0], back)
    right /= np.linalg.norm(right)
    return np.array([right, np.cross(back, right), back])


def rasterize(vertices, triangles, size=600, elev=28, azim=-58):
    """A flat-shaded image (size, size, 3) of the mesh: orthographic, a z-buffer per pixel,
    each triangle one grey from its normal, its edges darkened."""
    rot = _view(elev, azim)
    p = (vertices - 0.5 * (vertices.min(0) + vertices.max(0))) @ rot.T
    scale = 0.46 * size / np.abs(p[:, :2]).max()
    xy = p[:, :2] * scale * np.array([1, -1]) + 0.5 * size
    z = p[:, 2]
    tri = vertices[triangles]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    shade = 0.25 + 0.75 * np.clip(n @ (rot.T @ (LIGHT / np.linalg.norm(LIGHT))), 0, 1)
    depth = np.full((size, size), -np.inf)
    img = np.ones((size, size, 3))
    for k, (a, b, c) in enumerate(triangles):
        x0, y0 = np.floor(np.minimum(np.minimum(xy[a], xy[b]), xy[c])).astype(int)
        x1, y1 = np.ceil(np.maximum(np.maximum(xy[a], xy[b]), xy[c])).astype(int)
        x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, size - 1), min(y1, size - 1)
        if x1 < x0 or y1 < y0:
            continue
        gx, gy = np.meshgrid(np.arange(x0, x1 + 1) + 0.5, np.arange(y0, y1 + 1) + 0.5)
        (ax, ay), (bx, by), (cx, cy) = xy[a], xy[b], xy[c]
        det = (bx - ax) * (cy - ay) - (cx - ax) * (by - ay)
        if det == 0:
            continue
        w1 = ((gx - ax) * (cy - ay) - (cx - ax) * (gy - ay)) / det
        w2 = ((bx - ax) * (gy - ay) - (gx - ax) * (by - ay)) / det
        w0 = 1 - w1 - w2
        inside = (w0 >= 0) & (w1 >= 0) & (w2 >= 0)
        zz = w0 * z[a] + w1 * z[b] + w2 * z[c]
        win = inside & (zz > depth[y0:y1 + 1, x0:x1 + 1])
        if not win.any():
            continue
        edge = np.minimum(np.minimum(w0, w1), w2) * abs(det) / max(
            np.hypot(bx - cx, by - cy), np.hypot(ax - cx, ay - cy), np.hypot(ax - bx, ay - by)) < 0.45
        g = shade[k] * np.array([0.62, 0.66, 0.72])
        col = np.where(edge[..., None], 0.55 * g, g)
        depth[y0:y1 + 1, x0:x1 + 1][win] = zz[win]
        img[y0:y1 + 1, x0:x1 + 1][win] = col[win]
    return img


def main(part: str = "l_bracket") -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import trimesh

    scene = clcsg.load(zoo.example_path(part, "csg"))
    m = clcsg.mesh(scene)
    with tempfile.TemporaryDirectory() as d:
        stl = os.path.join(d, "part.stl")
        subprocess.run(["openscad", "-o", stl, os.path.abspath(zoo.example_path(part, "scad"))], check=True,
                       capture_output=True, timeout=600)
        ref = trimesh.load(stl, force="mesh")
    fig, axes = plt.subplots(1, 2, figsize=(10, 5.6), dpi=120)
    panels = [(m.vertices, m.triangles, f"clcsg mesh (tolerance 0.1%): {len(m.triangles):,} triangles,\n"
               "vertices on the exact quadrics"),
              (np.asarray(ref.vertices), np.asarray(ref.faces), f"openscad -o part.stl: {len(ref.faces):,} triangles,"
               "\ncircles faceted by $fn before the Booleans")]
    for ax, (v, t, title) in zip(axes, panels):
        ax.imshow(rasterize(v, t))
        ax.set_axis_off()
        ax.set_title(title, fontsize=9)
    fig.tight_layout()
    os.makedirs(os.path.dirname(OUT), exist_ok=True)
    fig.savefig(OUT)
    print(f"written to {OUT}")
    return OUT


if __name__ == "__main__":
    main(*sys.argv[1:])
