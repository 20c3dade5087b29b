"""The same model written with the Python API and as an OpenSCAD .csg export renders the same,
and the examples' solids agree with OpenSCAD's own STL render."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

import clcsg
from clcsg.compile.dnf import normalize
from clcsg.readers.openscad import parse_csg
from clcsg.model.csg import contains

from test_openscad import quiet_load

EXAMPLES = Path(__file__).parent.parent / "examples"

CSG = """
color([0.8, 0.3, 0.2, 1]) {
  difference() {
    cube(size = [2, 2, 2], center = true);
    cylinder($fn = 64, h = 3, r1 = 0.5, r2 = 0.5, center = true);
    multmatrix([[0.707107, -0.707107, 0, 0], [0.707107, 0.707107, 0, 0], [0, 0, 1, 0.4], [0, 0, 0, 1]]) {
      cube(size = [0.6, 3, 0.4], center = true);
    }
  }
  multmatrix([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 1], [0, 0, 0, 1]]) {
    sphere($fn = 32, r = 0.6);
  }
}
"""


def python_model():
    c = (0.8, 0.3, 0.2, 1)
    slot = clcsg.box((0.6, 3, 0.4), color=c).rotate((0, 0, 1), 45).translate((0, 0, 0.4))
    body = clcsg.box(2, color=c) - clcsg.cylinder(3, 0.5, color=c) - slot
    return body | clcsg.sphere(0.6, center=(0, 0, 1), color=c)


@pytest.mark.parametrize("method", ["raytrace", "splat"])
def test_python_and_csg_render_alike(method, cl_context):
    a = python_model()
    b = parse_csg(CSG, source="model.csg")
    da, db = clcsg.Scene(a).normalize(), b.normalize()
    assert da.n_quadrics == db.n_quadrics and da.n_terms == db.n_terms
    cam = clcsg.Camera.fit(da.bound, 96, 72)
    if method == "raytrace":
        ia, ib = clcsg.raytrace(a, cam, device=cl_context), clcsg.raytrace(b, cam, device=cl_context)
    else:
        ia = clcsg.render(clcsg.sample(a, 0.08, device=cl_context), cam, device=cl_context)
        ib = clcsg.render(clcsg.sample(b, 0.08, device=cl_context), cam, device=cl_context)
    ma, mb = np.isfinite(ia.depth), np.isfinite(ib.depth)
    assert ma.sum() > 1000
    # the 6-digit rotation moves edges by ~1e-6: allow a handful of silhouette pixels
    assert np.mean(ma == mb) >= 0.999
    both = ma & mb
    rel = np.abs(ia.depth[both] - ib.depth[both]) / ia.depth[both]
    assert np.quantile(rel, 0.999) <= 1e-4
    same_color = np.all(np.abs(ia.rgba[both].astype(int) - ib.rgba[both].astype(int)) <= 2, axis=1)
    assert same_color.mean() >= 0.995


# -- against OpenSCAD itself (the openscad binary; CI installs it) ------------------
def _read_ascii_stl(path) -> np.ndarray:
    verts = [line.split()[1:] for line in open(path) if line.lstrip().startswith("vertex")]
    return np.array(verts, dtype=float).reshape(-1, 3, 3)


def _inside_mesh(tris, pts, direction):
    """Ray-parity point-in-mesh (Moller-Trumbore) along ``direction``."""
    v0, e1, e2 = tris[:, 0], tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    p = np.cross(direction, e2)
    det = (e1 * p).sum(1)
    out = np.zeros(len(pts), dtype=bool)
    for k in range(0, len(pts), 256):
        t = pts[k : k + 256, None, :] - v0
        q = np.cross(t, e1)
        with np.errstate(all="ignore"):
            u = (t * p).sum(-1) / det
            v = (q * direction).sum(-1) / det
            s = (q * e2).sum(-1) / det
        hits = (u >= 0) & (v >= 0) & (u + v <= 1) & (s > 0)
        out[k : k + 256] = hits.sum(1) % 2 == 1
    return out


@pytest.mark.skipif(
    not shutil.which("openscad") and not os.environ.get("CI"),
    reason="openscad is not installed (apt-get install openscad; .ci/run installs it)",
)
@pytest.mark.parametrize("name", ["pawn.csg", "flange.csg"])
def test_examples_match_openscad_render(name, tmp_path):
    # coarse facets keep OpenSCAD fast; points closer than the facet error are not compared
    text = (EXAMPLES / name).read_text().replace("$fn = 96", "$fn = 24")
    (tmp_path / name).write_text(text)
    stl = tmp_path / "model.stl"
    subprocess.run(
        ["openscad", "--export-format", "asciistl", "-o", str(stl), str(tmp_path / name)],
        check=True, capture_output=True, timeout=300,
    )
    tris = _read_ascii_stl(stl)
    scene = quiet_load(EXAMPLES / name)
    dnf = normalize(scene.shape)
    lo, hi = dnf.bound
    pts = np.random.default_rng(7).uniform(lo - 1, hi + 1, (4000, 3))
    dist = np.min([np.abs(dnf.quadric(i).distance(pts)) for i in range(dnf.n_quadrics)], axis=0)
    pts = pts[dist > 0.5]  # facet error of $fn = 24 at r = 40 is 0.34
    votes = sum(
        _inside_mesh(tris, pts, np.asarray(d) / np.linalg.norm(d))
        for d in ([1, 0.123, 0.0456], [-0.1, 1, 0.07], [0.03, -0.09, -1])
    )
    ours = contains(scene.shape, pts)
    assert ours.sum() > 100
    np.testing.assert_array_equal(ours, votes >= 2)
    np.testing.assert_array_equal(dnf.contains(pts), ours)
