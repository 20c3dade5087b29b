"""The measured CSG surface area (Crofton's formula over random lines, clcsg.compile.bounds.
surface_area) against areas known in closed form."""

from __future__ import annotations

import math

import numpy as np
import pytest

import clcsg
from clcsg.compile.bounds.regions import quadric_regions
from clcsg.compile.bounds.surface_area import surface_areas
from clcsg.model.csg import Union
from clcsg.model.scene import Scene


def _area(shape, lines=1024, seed=0):
    tape = Scene(shape).compile()
    return surface_areas(tape, quadric_regions(tape.quadrics, tape.instances, tape.bound), lines=lines, seed=seed)


def _box_minus_sphere(h, R):
    """Area of the cube [-h, h]^3 minus the ball of radius R (h < R < h sqrt 2: the ball
    pokes through each face in a disc and its caps beyond the faces do not meet)."""
    faces = 6 * (4 * h * h - math.pi * (R * R - h * h))
    inner = 4 * math.pi * R * R - 6 * 2 * math.pi * R * (R - h)
    return faces + inner


@pytest.mark.parametrize("seed", [0, 1])
def test_sphere_cylinder_and_box_minus_sphere(seed):
    a = _area(clcsg.sphere(1.0), seed=seed)
    assert abs(a.sum() / (4 * math.pi) - 1) < 0.08
    a = _area(clcsg.cylinder(2.0, 0.5), seed=seed)  # two discs and the side
    assert abs(a.sum() / (2 * math.pi * 0.25 + 2 * math.pi * 0.5 * 2.0) - 1) < 0.08
    a = _area(clcsg.box(2) - clcsg.sphere(1.3), seed=seed)
    assert abs(a.sum() / _box_minus_sphere(1.0, 1.3) - 1) < 0.08
    assert np.all(a >= 0)


def test_a_quadric_with_no_csg_surface_measures_zero():
    """A sphere inside a bigger sphere's union carries no CSG surface."""
    a = _area(Union([clcsg.sphere(2.0), clcsg.sphere(0.5)]))
    assert abs(a.sum() / (4 * math.pi * 4) - 1) < 0.08
    assert (a > 0).sum() == 1


def test_the_measurement_is_the_same_every_run():
    np.testing.assert_array_equal(_area(clcsg.box(2) - clcsg.sphere(1.3)), _area(clcsg.box(2) - clcsg.sphere(1.3)))


@pytest.mark.parametrize("seed", [0, 7])
def test_the_lines_are_isotropic_and_cross_the_ball_uniformly(seed):
    """isotropic_lines: unit directions with the sphere's moments (mean 0, E[d d^T] = I / 3),
    points in the disc across the center orthogonal to their direction, spread uniformly in it
    (E[rho^2] = R^2 / 2), and the Crofton count of a centered sphere of radius r: E[n] = 2 r^2 / R^2."""
    from clcsg.compile.bounds.surface_area import isotropic_lines

    c, R, n = np.array([1.0, -2.0, 0.5]), 3.0, 4096
    d, o = isotropic_lines(c, R, n, seed)
    assert np.allclose(np.linalg.norm(d, axis=1), 1)
    assert np.abs(d.mean(axis=0)).max() < 0.02 and np.abs(d.T @ d / n - np.eye(3) / 3).max() < 0.02
    w = o - c
    assert np.abs(np.sum(w * d, axis=1)).max() < 1e-12 and np.linalg.norm(w, axis=1).max() <= R * (1 + 1e-12)
    assert abs(np.mean(np.sum(w * w, axis=1)) / (R * R / 2) - 1) < 0.02
    r = 1.2
    b = np.sum(w * d, axis=1)
    crossings = 2 * (np.sum(w * w, axis=1) - b * b < r * r)
    assert abs(crossings.mean() / (2 * r * r / (R * R)) - 1) < 0.05


def test_the_lines_of_many_balls_at_once_are_those_of_each_ball():
    """isotropic_lines with centers (k, 3), radii and seeds (k,): per ball the same lines, bit
    for bit, as a call for that ball alone (surface_areas draws all quadrics' lines at once)."""
    from clcsg.compile.bounds.surface_area import isotropic_lines

    rng = np.random.default_rng(3)
    c, R, seeds = rng.normal(size=(5, 3)), rng.uniform(0.1, 4.0, 5), np.array([0, 1, 2, 17, 300])
    d, o = isotropic_lines(c, R, 64, seeds)
    assert d.shape == o.shape == (5, 64, 3)
    for j in range(5):
        dj, oj = isotropic_lines(c[j], float(R[j]), 64, int(seeds[j]))
        np.testing.assert_array_equal(d[j], dj)
        np.testing.assert_array_equal(o[j], oj)
