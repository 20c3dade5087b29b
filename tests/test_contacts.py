"""Contacts between quadrics (clcsg/compile/contacts.py) against float64 points on the surfaces:
a certified quadric keeps its sign at every point of the other's surface; pairs that cross,
pairs apart and a plane tangent to a double cone (its nappes lie on both sides) get no
certificate; root tapes with the contacts folded agree with the full tape on the surface; and
scenes full of contacts (rounded boxes, hulls) keep the sampler's guarantees with far fewer
cells."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import clcsg
from clcsg import Camera, raytrace, render, sample
from clcsg.compile import contacts
from clcsg.compile.interpret import member
from clcsg.model.quadric import Quadric

from test_tree_pipeline import check_images, check_samples, diag_of

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BOUND = np.array([[-4.0, -4.0, -4.0], [4.0, 4.0, 4.0]])


def points_on(q: Quadric, n=4000, seed=1, bound=BOUND) -> np.ndarray:
    """Points of q's surface inside ``bound``: random lines through it meet it there."""
    rng = np.random.default_rng(seed)
    p = rng.uniform(bound[0], bound[1], size=(n, 3))
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    t1, t2 = q.intersect_line(p, v)
    pts = np.concatenate([p + t1[:, None] * v, p + t2[:, None] * v])
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    return pts[np.all((pts >= bound[0]) & (pts <= bound[1]), axis=1)]


def sign_seen(s: Quadric, o: Quadric) -> int:
    """The sign o keeps on s's surface by points (0 if both signs occur beyond rounding)."""
    v = o.value(points_on(s))
    scale = 1e-9 * np.abs(o.matrix).max()
    pos, neg = (v > scale).any(), (v < -scale).any()
    return 0 if pos and neg else 1 if pos else -1


def rotation(axis, degrees):
    axis = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    a = math.radians(degrees)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(a) * k + (1 - math.cos(a)) * k @ k


def moved(q: Quadric, rot, shift) -> Quadric:
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = rot, shift
    return q.transform(m)


def tangent_cone_of_unit_sphere(apex_z=3.0) -> Quadric:
    """The cone from (0, 0, apex_z) touching the unit sphere along a circle."""
    half = math.asin(1.0 / apex_z)
    return Quadric.cone(apex=(0, 0, apex_z), axis=(0, 0, 1), slope=math.tan(half))


CONTACT = {
    "plane on a sphere": (Quadric.sphere(radius=1.0), Quadric.half_space((0, 0, 1), 1.0)),
    "sphere under a plane": (Quadric.half_space((0, 0, 1), 1.0), Quadric.sphere(radius=1.0)),
    "plane along a cylinder": (Quadric.cylinder(radius=1.0), Quadric.half_space((1, 0, 0), 1.0)),
    "cylinder on a plane": (Quadric.half_space((1, 0, 0), 1.0), Quadric.cylinder(radius=1.0)),
    "spheres outside each other": (Quadric.sphere(radius=1.0), Quadric.sphere((2.0, 0, 0), 1.0)),
    "sphere inside a sphere": (Quadric.sphere(radius=1.0), Quadric.sphere((0.5, 0, 0), 1.5)),
    "parallel cylinders": (Quadric.cylinder(radius=1.0), Quadric.cylinder(radius=0.5, center=(1.5, 0, 0))),
    "cone around a sphere": (Quadric.sphere(radius=1.0), tangent_cone_of_unit_sphere()),
    "sphere in a cone": (tangent_cone_of_unit_sphere(), Quadric.sphere(radius=1.0)),
}

NONE = {
    "plane through a sphere": (Quadric.sphere(radius=1.0), Quadric.half_space((0, 0, 1), 0.3)),
    "crossing cylinders": (Quadric.cylinder(radius=1.0), Quadric.cylinder((1, 0, 0), 1.0)),
    "spheres apart": (Quadric.sphere(radius=1.0), Quadric.sphere((3.0, 0, 0), 1.0)),
    "plane along a double cone": (Quadric.cone(slope=1.0), Quadric.half_space((1, 0, -1), 0.0)),
}


@pytest.mark.parametrize("name", sorted(CONTACT))
def test_a_contact_is_certified_with_the_sign_the_surface_shows(name):
    s, o = CONTACT[name]
    seen = sign_seen(s, o)
    assert seen != 0
    assert contacts.sign_on(s.matrix, o.matrix, BOUND) == seen


@pytest.mark.parametrize("name", sorted(NONE))
def test_crossing_pairs_pairs_apart_and_a_double_cone_get_no_certificate(name):
    s, o = NONE[name]
    assert contacts.sign_on(s.matrix, o.matrix, BOUND) == 0


@settings(max_examples=40, deadline=None)
@given(name=st.sampled_from(sorted(CONTACT)), axis=st.tuples(*[st.floats(-1, 1)] * 3).filter(
    lambda a: np.linalg.norm(a) > 0.1), degrees=st.floats(0, 360), shift=st.tuples(*[st.floats(-1.5, 1.5)] * 3),
       scale=st.sampled_from([1e-3, 1.0, 1e3]))
def test_contacts_survive_rigid_motions_and_scale(name, axis, degrees, shift, scale):
    s, o = CONTACT[name]
    rot = rotation(axis, degrees)
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = scale * rot, scale * np.asarray(shift)
    s2, o2 = s.transform(m), o.transform(m)
    bound = scale * BOUND + scale * np.asarray(shift)
    assert contacts.sign_on(s2.matrix, o2.matrix, bound) == sign_seen(s, o)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_a_certificate_for_random_quadrics_holds_at_every_point_of_the_surface(seed):
    """Random pairs, half of them made to touch (o is s plus a multiple of a squared plane
    through a point of s, tangent to s there when that plane is): whatever is certified holds."""
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(4, 4))
    s = Quadric(a + a.T)
    if not len(points_on(s, 200)):
        return
    b = rng.normal(size=(4, 4))
    o, made = Quadric(b + b.T), 0
    if rng.random() < 0.5:
        p = points_on(s, 200)[0]
        n = s.gradient(p[None])[0]
        plane = np.r_[n, -n @ p]
        made = int(rng.choice([-1, 1]))
        o = Quadric(rng.normal() * s.matrix + made * np.outer(plane, plane))
    sign = contacts.sign_on(s.matrix, o.matrix, BOUND)
    assert sign == made or not made
    if sign:
        v = sign * o.value(points_on(s))
        assert v.min(initial=0.0) >= -1e-9 * np.abs(o.matrix).max() * (1 + np.abs(points_on(s)).max()) ** 2


@pytest.mark.parametrize("name", ["rounded_box", "pen_stand"])
def test_root_tapes_with_contacts_agree_with_the_tape_on_the_surface(name):
    scene = clcsg.load(os.path.join(ROOT, "examples", f"{name}.csg"))
    tape = scene.compile()
    rows = np.asarray(tape.ops, dtype=np.int32)
    lo, hi = tape.bound
    regions = {q: (lo, hi) for q in range(tape.n_quadrics)}
    spans, out = contacts.contact_root_tapes(tape, {q: (0, len(rows)) for q in regions}, rows, regions)
    changed = [q for q in spans if spans[q] != (0, len(rows))]
    assert len(changed) >= 5
    for q in changed:
        first, count = spans[q]
        pts = points_on(Quadric(tape.quadrics[q]), 3000, seed=q, bound=np.array([lo, hi]))
        # away from the contacts (where a folded quadric is 0 on the surface)
        folded = [o for (s, o), v in _signs(tape).items() if s == q and v]
        far = np.ones(len(pts), dtype=bool)
        for o in folded:
            qo = Quadric(tape.quadrics[o])
            far &= np.abs(qo.distance(pts)) > 1e-6 * diag_of(tape)
        full = member(rows, tape.quadrics, pts[far], q)
        short = member(out[first:first + count], tape.quadrics, pts[far], q)
        assert np.array_equal(full[0], short[0]) and np.array_equal(full[1], short[1])


def _signs(tape) -> dict:
    n = tape.n_quadrics
    return {(c // n, c % n): v for c, v in tape.__dict__.get("_contact_signs", {}).items()}


@pytest.mark.parametrize("name", ["rounded_box", "pen_stand", "knob"])
def test_scenes_of_contacts_keep_the_guarantees_with_fewer_cells(name, cl_context, monkeypatch):
    scene = clcsg.load(os.path.join(ROOT, "examples", f"{name}.csg"))
    tape = scene.compile()
    r = diag_of(tape) / 80
    s = sample(scene, r, device=cl_context)
    check_samples(scene.shape, s, r)
    cam = Camera.fit(tape, 80, 60)
    check_images(render(s, cam, device=cl_context), raytrace(tape, cam, device=cl_context))
    monkeypatch.setattr(contacts, "PAIR_BUDGET", 0)  # no contacts: the tape's cells as they were
    without = sample(clcsg.load(os.path.join(ROOT, "examples", f"{name}.csg")), r, device=cl_context)
    cells, cells_without = s.stats["cells"], without.stats["cells"]
    if name == "knob":  # its contacts are a plane on a double cone: none certified
        assert s.stats["contact_pairs"] == 0 and cells == cells_without
    else:
        assert s.stats["contact_pairs"] > 0 and cells <= 0.85 * cells_without
