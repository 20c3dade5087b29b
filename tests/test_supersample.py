"""Supersampling (``clcsg.render(..., aa=N)``, ``clcsg.raytrace(..., aa=N)``, ``clcsg render --aa N``):
edges get intermediate values, interiors match the plain render, depth and ids stay those of the
pixel centre, the filter averages in linear light, and bad values are one-line errors."""

from __future__ import annotations

import numpy as np
import pytest

import clcsg
from clcsg.cli.app import main
from clcsg.errors import UsageError
from clcsg.rendering.supersample import MAX_AA, check_aa, downsample

PART = clcsg.box(2) - clcsg.cylinder(3, 0.5, color=(0.8, 0.3, 0.2))


@pytest.fixture(scope="module")
def part(cl_context):
    samples = clcsg.sample(PART, 0.06, device=cl_context, progress=False)
    return samples, clcsg.Camera.fit(samples, 96, 72)


def _interior(ids) -> np.ndarray:
    """Pixels whose 3 x 3 neighbourhood shows one quadric (no edge or silhouette near)."""
    p = np.pad(ids, 1, constant_values=-2)
    same = np.ones(ids.shape, bool)
    for di in range(3):
        for dj in range(3):
            same &= p[di:di + ids.shape[0], dj:dj + ids.shape[1]] == ids
    return same & (ids >= 0)


@pytest.mark.parametrize("aa", [2, 3])
def test_edges_blend_and_interiors_match(part, cl_context, aa):
    samples, cam = part
    plain = clcsg.render(samples, cam, device=cl_context)
    smooth = clcsg.render(samples, cam, device=cl_context, aa=aa)
    assert smooth.rgba.shape == plain.rgba.shape and smooth.stats["aa"] == aa
    inner = _interior(plain.ids)
    assert inner.sum() > 1000
    diff = np.abs(smooth.rgba.astype(int) - plain.rgba.astype(int)).max(axis=-1)
    assert diff[inner].max() <= 2
    # the silhouette against the white background: values strictly between the two
    silhouette = (plain.ids >= 0) != (np.roll(plain.ids, 1, axis=1) >= 0)
    grey = smooth.rgba[..., :3].astype(int)
    blended = silhouette & (grey.min(axis=-1) < 250) & (diff > 8)
    assert blended.sum() > 20
    plain_colours = {tuple(c) for c in plain.rgba.reshape(-1, 4)}
    new = [tuple(c) for c in smooth.rgba[silhouette]]
    assert sum(c not in plain_colours for c in new) > 20  # colours the plain render does not have
    # depth and ids are those of the pixel centre
    assert np.mean(smooth.ids == plain.ids) > 0.999
    same = (smooth.ids == plain.ids) & (plain.ids >= 0)
    assert np.allclose(smooth.depth[same], plain.depth[same], rtol=1e-5)
    if aa % 2 == 0:  # from a plain render: exactly
        assert np.array_equal(smooth.ids, plain.ids) and np.array_equal(smooth.primitives, plain.primitives)


def test_raytrace_supersampling_matches_the_splats(part, cl_context):
    samples, cam = part
    splats = clcsg.render(samples, cam, device=cl_context, aa=2)
    exact = clcsg.raytrace(PART, cam, device=cl_context, aa=2)
    assert np.array_equal(exact.ids, splats.ids)
    diff = np.abs(exact.rgba.astype(int) - splats.rgba.astype(int)).max(axis=-1)
    assert np.mean(diff <= 2) > 0.99


def test_filter_averages_in_linear_light():
    # half black, half white subpixels: linear mean 0.5 -> 0.5^(1/2.2) of 255 = 186, not 128
    rgba = np.zeros((2, 2, 4), np.uint8)
    rgba[..., 3] = 255
    rgba[0, :, :3] = 255
    out = downsample(rgba, 2, 2.2)
    assert out.shape == (1, 1, 4) and out[0, 0, 3] == 255
    assert abs(int(out[0, 0, 0]) - 186) <= 1
    # over a transparent background the colour stays, the alpha halves
    rgba[1] = 0
    rgba[0, :, :3] = (200, 100, 50)
    out = downsample(rgba, 2, 2.2)
    assert tuple(out[0, 0]) == (200, 100, 50, 128)


def test_bad_aa_values_are_usage_errors():
    for bad in (0, -1, MAX_AA + 1, 2.5, "x"):
        with pytest.raises(UsageError, match="aa"):
            check_aa(bad, 64, 48)
    with pytest.raises(UsageError, match="subpixels"):
        check_aa(8, 4096, 4096)
    assert check_aa(3, 64, 48) == 3


def test_cli_render_aa(tmp_path, tmp_scene, cl_context, capsys):
    from PIL import Image

    scene = tmp_scene(PART)
    out, ids = tmp_path / "smooth.png", tmp_path / "ids.npy"
    plain_ids = tmp_path / "plain_ids.npy"
    assert main(["render", str(scene), "-o", str(out), "--size", "96x72", "--aa", "3", "--ids", str(ids), "-q"]) == 0
    assert main(["render", str(scene), "-o", str(tmp_path / "p.png"), "--size", "96x72", "--ids", str(plain_ids),
                 "-q"]) == 0
    assert Image.open(out).size == (96, 72)
    assert np.mean(np.load(ids) == np.load(plain_ids)) > 0.999
    assert main(["render", str(scene), "-o", str(out), "--aa", "9"]) == 2
    assert "aa" in capsys.readouterr().err
