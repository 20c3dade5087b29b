"""The default look: framing (the silhouette spans 90 % of the frame), the shading (faces of a
hollow part read apart, hues kept, splats equal to the ray tracer), OpenSCAD's colours,
transparent backgrounds, and the one colour parser behind them."""

from __future__ import annotations

import glob
import os
import warnings

import numpy as np
import pytest

import clcsg
from clcsg import Camera
from clcsg.cli import app as cli
from clcsg.model import colors
from clcsg.model.csg import DEFAULT_COLOR

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLES = sorted(glob.glob(os.path.join(ROOT, "examples", "*.json")) + glob.glob(os.path.join(ROOT, "examples", "*.csg")))
W, H = 96, 72


def span(img) -> float:
    """The silhouette's larger relative extent: max(width / W, height / H) of the mask's box."""
    ys, xs = np.nonzero(img.mask)
    return max((xs.max() - xs.min() + 1) / img.width, (ys.max() - ys.min() + 1) / img.height)


def load(path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the OpenSCAD examples' $fn notes
        return clcsg.load(path)


# -- framing --------------------------------------------------------------------------------------
@pytest.mark.parametrize("path", EXAMPLES, ids=os.path.basename)
def test_the_fitted_view_frames_the_silhouette_at_90_percent(cl_context, path):
    """The default camera of `clcsg render --method raytrace`: the ray tracer's mask spans
    85-95 % of the frame in its larger relative extent, and is centred."""
    tape = load(path).compile()
    cam = Camera.fit_silhouette(tape, W, H, device=cl_context)
    img = clcsg.raytrace(tape, cam, device=cl_context)
    assert 0.85 <= span(img) <= 0.95, f"{os.path.basename(path)}: {span(img):.3f}"
    ys, xs = np.nonzero(img.mask)
    assert abs((xs.min() + xs.max() + 1) / 2 - W / 2) <= 0.06 * W
    assert abs((ys.min() + ys.max() + 1) / 2 - H / 2) <= 0.06 * H


@pytest.mark.parametrize("name, radius", [("spheres.json", 0.05), ("drilled_block.json", 0.06), ("pawn.csg", 0.8)])
def test_a_view_fitted_to_samples_frames_the_silhouette(cl_context, name, radius):
    """The default camera of `clcsg render` (splats): fitted to the samples' positions."""
    scene = load(os.path.join(ROOT, "examples", name))
    s = clcsg.sample(scene, radius, device=cl_context, progress=False)
    for w, h in ((W, H), (H, W)):
        img = clcsg.raytrace(s.tape, Camera.fit(s, w, h), device=cl_context)
        assert 0.85 <= span(img) <= 0.95, f"{name} {w}x{h}: {span(img):.3f}"


def test_the_bound_fit_is_looser_than_the_silhouette_fit(cl_context):
    scene = load(os.path.join(ROOT, "examples", "spheres.json"))
    tape = scene.compile()
    loose = clcsg.raytrace(tape, Camera.fit(tape, W, H), device=cl_context)
    tight = clcsg.raytrace(tape, Camera.fit_silhouette(tape, W, H, device=cl_context), device=cl_context)
    assert span(loose) < 0.85 < span(tight)


# -- shading --------------------------------------------------------------------------------------
# an open tray: the floor shows between the walls
HOLLOW = clcsg.box((2, 2, 0.6), center=(0, 0, 0.3)) - clcsg.box((1.6, 1.6, 0.6), center=(0, 0, 0.5))


def face_luminance(img):
    """Mean luminance of every visible face (quadric id) and the lengths of the borders
    between faces in the image (4-neighbour pixel pairs)."""
    lum = img.rgba[..., :3].astype(float) @ [0.2126, 0.7152, 0.0722]
    faces = {int(q): float(lum[img.ids == q].mean()) for q in np.unique(img.ids[img.mask])
             if (img.ids == q).sum() >= 15}
    borders: dict = {}
    for a, b in ((img.ids[:, :-1], img.ids[:, 1:]), (img.ids[:-1, :], img.ids[1:, :])):
        sel = (a != b) & (a >= 0) & (b >= 0)
        for x, y in zip(a[sel], b[sel]):
            key = (min(x, y), max(x, y))
            borders[key] = borders.get(key, 0) + 1
    return faces, borders


def test_the_inside_of_a_hollow_box_reads(cl_context):
    """Seen from the default view, the floor, the inner walls, the rim and the outer walls of
    an open tray are told apart: faces of different orientation that meet in the image differ
    by at least 8 grey levels (the inner corner, the floor against each wall, the rim against
    the walls), and the darkest face is at most 80 % as bright as the brightest.  (The rim and
    the floor face the same way: a local shading model, which both renderers share, gives
    them one shade; the depth step between them is the walls'.)"""
    tape = clcsg.Scene(HOLLOW).compile()
    cam = Camera.fit_silhouette(tape, 160, 120, device=cl_context)
    img = clcsg.raytrace(tape, cam, device=cl_context)
    faces, borders = face_luminance(img)
    assert len(faces) == 6  # floor, rim, 2 inner and 2 outer walls
    assert min(faces.values()) <= 0.8 * max(faces.values())
    def normal(q):  # every face is a plane: Q = 2 n.x + c
        b = tape.quadrics[q][:3, 3]
        return b / np.linalg.norm(b)

    meeting = [(a, b) for (a, b), n in borders.items() if n >= 8 and a in faces and b in faces
               and abs(abs(normal(a) @ normal(b)) - 1) > 1e-6]
    assert len(meeting) >= 6
    for a, b in meeting:
        assert abs(faces[a] - faces[b]) >= 8, (a, b, faces)


def test_shading_keeps_hues_and_splats_match_the_ray_tracer(cl_context):
    part = (clcsg.box(2, color=(0.9, 0.3, 0.2)) - clcsg.sphere(1.3, color=(0.2, 0.5, 0.9))) | clcsg.cylinder(
        2.6, 0.3, color=(0.2, 0.7, 0.3))
    s = clcsg.sample(part, 0.07, device=cl_context, progress=False)
    cam = Camera.fit(s, W, H)
    splat, exact = clcsg.render(s, cam, device=cl_context), clcsg.raytrace(s.tape, cam, device=cl_context)
    same = splat.mask & exact.mask & (splat.ids == exact.ids)
    assert same.sum() > 0.9 * exact.mask.sum()
    diff = np.abs(splat.rgba[same].astype(int) - exact.rgba[same].astype(int)).max(axis=-1)
    assert (diff <= 2).mean() >= 0.999  # shade.h is shared: the same hit, the same pixel
    base = np.array([inst.color[:3] for inst in s.tape.instances])[exact.primitives[exact.mask]]
    shown = exact.rgba[exact.mask][:, :3].astype(float)
    cos = (shown * base).sum(1) / (np.linalg.norm(shown, axis=1) * np.linalg.norm(base, axis=1))
    assert np.median(cos) > 0.98  # white lights: shading scales a colour, it does not tint it


def test_openscad_colors_and_transparency(cl_context, tmp_path, capsys):
    from PIL import Image as PILImage

    scene = tmp_path / "plain.csg"
    scene.write_text("difference() { cube(10, center = true); color(\"red\") sphere(6.5); }\n")
    out = tmp_path / "o.png"
    assert cli.main(["render", str(scene), "-o", str(out), "--method", "raytrace", "--size", "64x48",
                     "--colors", "openscad", "--transparent", "--ids", str(tmp_path / "i.npy"), "-q"]) == 0
    rgba = np.asarray(PILImage.open(out))
    mask = np.load(tmp_path / "i.npy") >= 0
    assert np.all(rgba[~mask][:, 3] == 0) and np.all(rgba[mask][:, 3] == 255)
    yellow = np.array(colors.from_string(colors.OPENSCAD_FACE)[:3])
    shown = rgba[mask][:, :3].astype(float)
    cos_yellow = shown @ yellow / (np.linalg.norm(shown, axis=1) * np.linalg.norm(yellow))
    cos_red = shown @ [1, 0, 0] / np.linalg.norm(shown, axis=1)
    # the cube (no colour) is OpenSCAD's yellow, the red sphere's inside stays red
    assert (cos_yellow > 0.99).sum() > 0.3 * mask.sum() and (cos_red > 0.99).sum() > 0.05 * mask.sum()
    tape = clcsg.load(scene).compile()
    assert colors.recolor_defaults(tape, colors.scheme_color("openscad")) == 1
    assert colors.scheme_color("clcsg") is None and colors.recolor_defaults(tape, None) == 0


def test_samples_take_a_default_color(cl_context):
    s = clcsg.sample(clcsg.box(1) | clcsg.sphere(0.4, center=(0, 0, 0.7), color=(1, 0, 0)), 0.2, device=cl_context,
                     progress=False)
    assert s.with_default_color("#f9d72c") == 1
    shown = np.unique(s.colors[:, :3], axis=0)
    assert len(shown) == 2
    assert np.allclose(shown, [[249 / 255, 215 / 255, 44 / 255], [1, 0, 0]], atol=1e-6)
    assert not np.isclose(shown, DEFAULT_COLOR[:3], atol=1e-6).all(axis=1).any()
    img = clcsg.render(s, Camera.fit(s, 32, 24), device=cl_context)  # re-packed for the device
    assert img.mask.any()


# -- the one colour parser ------------------------------------------------------------------------
@pytest.mark.parametrize("value, rgba", [
    ("red", (1, 0, 0, 1)),
    ("SteelBlue", (70 / 255, 130 / 255, 180 / 255, 1)),
    ("transparent", (0, 0, 0, 0)),
    ("#f00", (1, 0, 0, 1)),
    ("#f008", (1, 0, 0, 136 / 255)),
    ("#f9d72c", (249 / 255, 215 / 255, 44 / 255, 1)),
    ("#FF000080", (1, 0, 0, 128 / 255)),
    ([0.1, 0.2, 0.3], (0.1, 0.2, 0.3, 1)),
    ((0.1, 0.2, 0.3, 0.5), (0.1, 0.2, 0.3, 0.5)),
])
def test_color_forms(value, rgba):
    assert colors.parse_color(value) == pytest.approx(rgba)


def test_color_names_are_pillows_and_openscads():
    from PIL import ImageColor

    assert len(colors.NAMED_COLORS) == len(ImageColor.colormap) + 1 == 149
    assert colors.parse_color_text("255, 255, 229") == pytest.approx(colors.from_string(colors.OPENSCAD_BACKGROUND))
    assert colors.parse_color_text(" navy ") == pytest.approx((0, 0, 128 / 255, 1))


@pytest.mark.parametrize("value, message", [
    ("stelblue", "unknown color name 'stelblue' (did you mean 'steelblue'?)"),
    ("#12345", "'#12345' is not a hex color"),
    ([1, 0], "expected 3 or 4 numbers"),
    ([1, 2, 0], "color components must be in [0, 1], got 2"),
    ([1, float("nan"), 0], "finite numbers"),
    (3, "expected 3 or 4 numbers or a color name"),
])
def test_bad_colors(value, message):
    with pytest.raises(colors.ColorError) as e:
        colors.parse_color(value)
    assert message in str(e.value) and "\n" not in str(e.value)
