"""Meshes as CSG operands: ``clcsg.polyhedron``, ``clcsg.load_mesh``, OpenSCAD's ``polyhedron()``
and ``import()``, the scene file's ``mesh`` node.  A mesh is exact (its face planes), so a mesh
model is checked against the equivalent quadric model: samples on the quadric model's surface
(float64 tree oracle), covering it, splats equal to its exact ray-traced image."""

from __future__ import annotations

import numpy as np
import pytest

import clcsg
from clcsg.errors import SceneError

from test_constructions import check_against, export, needs_openscad


def box_mesh(lo, hi):
    """The box lo..hi as 12 outward (counter-clockwise) triangles."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    v = np.array([[(hi if (i >> k) & 1 else lo)[k] for k in range(3)] for i in range(8)])
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    faces = [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]
    return v, np.array(faces)


def prism_mesh(poly, z0, z1):
    """A z-prism over a counter-clockwise simple polygon, as triangles (the polygon fanned
    from each convex corner is not enough for an L: ear-clipped by hand below)."""
    poly = np.asarray(poly, float)
    n = len(poly)
    v = np.r_[np.c_[poly, np.full(n, z0)], np.c_[poly, np.full(n, z1)]]
    faces = []
    for i in range(n):
        j = (i + 1) % n
        faces += [(i, j, n + j), (i, n + j, n + i)]
    return v, faces


# the L: (0,0) (2,0) (2,1) (1,1) (1,2) (0,2), its caps as two rectangles' triangles
L_POLY = [(0, 0), (2, 0), (2, 1), (1, 1), (1, 2), (0, 2)]
L_CAP = [(0, 1, 2), (0, 2, 3), (0, 3, 4), (0, 4, 5)]  # fans from (0,0): every triangle inside the L


def l_prism():
    v, faces = prism_mesh(L_POLY, 0.0, 1.0)
    faces += [(c, b, a) for a, b, c in L_CAP] + [(a + 6, b + 6, c + 6) for a, b, c in L_CAP]
    return v, faces


def test_mesh_box_minus_cylinder_equals_quadric_box(cl_context):
    v, f = box_mesh((-1, -1, -1), (1, 1, 1))
    cut = clcsg.cylinder(3, 0.5)
    check_against(clcsg.polyhedron(v, f) - cut, clcsg.box(2) - cut, cl_context)


def test_l_prism_union_sphere(cl_context):
    v, f = l_prism()
    ref = clcsg.box((2, 1, 1), center=(1, 0.5, 0.5)) | clcsg.box((1, 2, 1), center=(0.5, 1, 0.5))
    ball = clcsg.sphere(0.6, (1.0, 1.0, 1.0))
    check_against(clcsg.polyhedron(v, f) | ball, ref | ball, cl_context)


def test_either_orientation_and_the_box_is_six_planes():
    v, f = box_mesh((0, 0, 0), (1, 2, 3))
    a, b = clcsg.polyhedron(v, f), clcsg.polyhedron(v, f[:, ::-1])
    assert a.describe() == b.describe() == "mesh of 12 triangles: 6 planes"
    pts = np.random.default_rng(1).uniform(-0.5, 3.5, (2000, 3))
    inside = np.all((pts >= 0) & (pts <= [1, 2, 3]), axis=1)
    assert np.array_equal(clcsg.contains(a, pts), inside)
    assert np.array_equal(clcsg.contains(b, pts), inside)
