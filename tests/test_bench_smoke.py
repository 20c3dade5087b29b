"""Smoke tests of the benchmark harness (bench/): no timing assertions, a few seconds in all."""

from __future__ import annotations

import os
import sys

import numpy as np
import pytest

import clcsg

# bench/ is not part of the installed package: import it from the repository root
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

from bench import micro, zoo  # noqa: E402


@pytest.mark.parametrize("model", zoo.MODELS, ids=lambda m: m.name)
def test_zoo_has_the_paper_complexity(model):
    assert clcsg.Scene(model.build()).normalize().n_quadrics == model.quadrics


def test_zoo_files_match_the_generator():
    for m in zoo.MODELS:
        path = os.path.join(zoo.ZOO_DIR, f"{m.name}.json")
        assert clcsg.load(path).normalize().n_quadrics == m.quadrics


def test_micro_kernels_run(cl_context):
    """Every micro kernel builds and returns finite sums (a tiny launch, not a measurement)."""
    real = cl_context.real_dtype
    for dependent in (False, True):
        r = micro.Runner(cl_context, real, dependent)
        for _, kernel in [("baseline", "baseline")] + micro.OPS:
            r.launch(kernel, 128)
            assert np.isfinite(r.checksum[kernel]), kernel


def test_manifold_translation_matches_the_quadrics():
    """The manifold3d version of a zoo model lies near its quadrics (coarse tessellation)."""
    manifold3d = pytest.importorskip("manifold3d")
    from bench import peers

    shape = zoo.flange()
    dnf = clcsg.Scene(shape).normalize()
    diag = float(np.linalg.norm(dnf.bound[1] - dnf.bound[0]))
    mesh = peers.Translator(manifold3d, 32, dnf.bound).build(shape).to_mesh()
    pts, _ = peers.sample_mesh(mesh, 2000, np.random.default_rng(0))
    err = peers.surface_error(dnf, pts)
    assert err.max() < 0.02 * diag
    # and the mesh's bound is the scene's
    assert np.allclose(pts.min(0), dnf.bound[0], atol=0.02 * diag)
    assert np.allclose(pts.max(0), dnf.bound[1], atol=0.02 * diag)
