"""The exact ray tracer kernel (clcsg/rendering/raytrace.cl) against the float64 numpy oracle."""

import json
import math

import numpy as np
import pytest

import clcsg
from clcsg.rendering.camera import Camera, orbit
from clcsg.errors import UsageError
from clcsg.model.quadric import Quadric
from clcsg import raytrace

import tree_oracle as T
from image_check import compare

W, H = 96, 72


def _scenes():
    three_cyl = (
        clcsg.box(2.0, color=(0.9, 0.6, 0.3))
        - clcsg.cylinder(3, 0.55)
        - clcsg.cylinder(3, 0.55, axis=(1, 0, 0))
        - clcsg.cylinder(3, 0.55, axis=(0, 1, 0))
    )
    hyper = clcsg.quadric(Quadric.hyperboloid_one_sheet(radii=(0.5, 0.5, 0.8)).matrix) & clcsg.box((2, 2, 1.6))
    parab = clcsg.quadric(Quadric.elliptic_paraboloid(apex=(0, 0, -0.8), radii=(0.6, 0.8)).matrix) & clcsg.box(
        (3, 3, 1.6)
    )
    return {
        "sphere": clcsg.sphere(1.0, center=(0.3, -0.2, 0.1)),
        "box_minus_3_cylinders": three_cyl,
        "union_of_spheres": clcsg.sphere(1.0) | clcsg.sphere(0.8, center=(1.1, 0.2, 0.3)) | clcsg.sphere(0.5, center=(0, 0, 1.2)),
        "hyperboloid_and_box": hyper,
        "paraboloid_and_box": parab,
        "cone_frustum": clcsg.cone(2.0, r1=1.0, r2=0.4),
        "touching_boxes": clcsg.box(1.0) | clcsg.box(1.0, center=(1.0, 0, 0)),
    }


SCENES = _scenes()


def _views(dnf):
    b = dnf.bound
    c = 0.5 * (b[0] + b[1])
    R = 0.5 * np.linalg.norm(b[1] - b[0])
    views = [Camera.fit(dnf, W, H)]
    views += list(orbit(b, 3, elevation=-35, width=W, height=H))[1:]
    # grazing: the eye almost in the plane of the top face of the bound, looking along it
    top = b[1][2]
    views.append(Camera.look_at((c[0] + 3 * R, c[1] - 1.1 * R, top + 1e-3 * R), (c[0], c[1], top), fov=40, width=W, height=H))
    # axis-aligned view: rays parallel to box faces, edges land on pixel boundaries
    views.append(Camera.look_at((c[0], c[1] - 4 * R, c[2]), c, fov=35, width=W, height=H))
    return views


@pytest.mark.parametrize("normal_form", ["tree", "dnf"])
@pytest.mark.parametrize("name", sorted(SCENES))
def test_raytrace_matches_oracle(cl_context, name, normal_form):
    shape = SCENES[name]
    tape = clcsg.Scene(shape).compile(normal_form)
    for cam in _views(tape):
        img = raytrace(tape, cam, device=cl_context)
        ref = compare(img, shape, tape, cam)
        assert ref.mask.any()


@pytest.mark.parametrize("name", ["box_minus_3_cylinders", "union_of_spheres"])
def test_raytrace_matches_oracle_at_widths_off_the_lanes(cl_context, name):
    """Widths that are no multiple of the RAY_LANES (8) pixels a work-item traces nor of the
    tile: the last work-item of each row has fewer lanes."""
    shape = SCENES[name]
    tape = clcsg.Scene(shape).compile("tree")
    for w, h in ((61, 43), (13, 9), (5, 4)):
        cam = Camera.fit(tape, w, h)
        ref = compare(raytrace(tape, cam, device=cl_context), shape, tape, cam)
        assert ref.mask.any()


def test_tree_and_dnf_images_are_identical(cl_context):
    shape = SCENES["box_minus_3_cylinders"] | SCENES["union_of_spheres"].translate((0, 0, 1.5))
    tree, dnf = (clcsg.Scene(shape).compile(nf) for nf in ("tree", "dnf"))
    assert dnf.shape == "dnf" and dnf.stats["terms"] > 1
    for cam in _views(tree)[:3]:
        a, b = raytrace(tree, cam, device=cl_context), raytrace(dnf, cam, device=cl_context)
        assert np.array_equal(a.rgba, b.rgba) and np.array_equal(a.ids, b.ids) and np.array_equal(a.depth, b.depth)


def test_touching_boxes_shared_face_is_never_visible(cl_context):
    tape = clcsg.Scene(SCENES["touching_boxes"]).compile()
    pts = np.array([[0.5, 0.1, 0.2], [0.5, -0.3, 0.4], [0.5, 0.2, -0.1]])
    shared = [qi for qi in range(tape.n_quadrics) if np.all(np.abs(clcsg.Quadric(tape.quadrics[qi]).value(pts)) < 1e-12)]
    assert len(shared) == 1
    for cam in orbit(tape.bound, 5, elevation=20, width=48, height=36):
        img = raytrace(tape, cam, device=cl_context)
        assert img.mask.any() and not np.any(img.ids == shared[0])


def test_views_from_inside_match_the_oracle(cl_context):
    """The eye inside multi-part solids: the tree ray tracer sees the inner faces exactly."""
    hollow = clcsg.box(4) - clcsg.box(3) - clcsg.sphere(0.6, center=(1.8, 0, 0))
    parts = (clcsg.box(2, color=(1, 0, 0)) | clcsg.box(2, center=(1.5, 0.5, 0), color=(0, 1, 0))) - clcsg.sphere(0.5)
    for shape, eye, target in [(hollow, (0.3, -0.4, 0.2), (2, 0.3, 0.1)), (parts, (0.8, 0.2, 0.1), (2.4, 1, 0)),
                               (parts, (0.0, 0.0, 0.0), (1, -1, 0.3))]:
        tape = clcsg.Scene(shape).compile()
        cam = Camera.look_at(eye, target, fov=80, width=W, height=H)
        img = raytrace(tape, cam, device=cl_context)
        ref = compare(img, shape, tape, cam)
        assert ref.mask.mean() > 0.5


def test_camera_contract_sphere_center_pixel(cl_context):
    c = np.array([2.0, -1.0, 0.5])
    r = 0.25
    eye = np.array([2.0, -6.0, 1.5])
    cam = Camera.look_at(eye, c, fov=30, width=65, height=49)  # odd size: center pixel ray hits c
    img = raytrace(clcsg.sphere(r, center=c), cam, device=cl_context)
    i, j = cam.pixel_of(c)
    assert (i, j) == (24, 32)
    assert img.ids[i, j] == 0 and img.primitives[i, j] == 0
    assert math.isclose(img.depth[i, j], np.linalg.norm(eye - c) - r, rel_tol=1e-6)
    # the covered region is centered on that pixel
    ii, jj = np.nonzero(img.mask)
    assert abs(ii.mean() - i) < 0.6 and abs(jj.mean() - j) < 0.6


def test_camera_contract_off_center(cl_context):
    cam = Camera.look_at((0, 0, 0), (1, 0.2, 0.1), up=(0, 0, 1), fov=50, width=64, height=48)
    o, d = cam.rays()
    for i, j in [(3, 5), (40, 60), (10, 50)]:
        c = cam.eye + 10.0 * d[i, j]
        img = raytrace(clcsg.sphere(0.05, center=c), cam, device=cl_context)
        assert cam.pixel_of(c) == (i, j)
        assert img.ids[i, j] == 0
        assert math.isclose(img.depth[i, j], 10.0 - 0.05, rel_tol=1e-6)
        assert img.mask.sum() <= 9


def test_shading_and_background(cl_context, tmp_path):
    sh = clcsg.sphere(1.0, color=(0.2, 0.4, 0.9))
    cam = Camera.fit(np.array([[-1, -1, -1], [1, 1, 1.0]]), 64, 48)
    img = raytrace(sh, cam, device=cl_context, background=(0.0, 0.5, 1.0, 0.0))
    assert img.rgba.shape == (48, 64, 4) and img.rgba.dtype == np.uint8
    assert img.depth.dtype == np.float32 and img.ids.dtype == np.int32
    bg = ~img.mask
    assert np.all(img.rgba[bg] == [0, 128, 255, 0])
    fg = img.rgba[img.mask].astype(int)
    assert np.all(fg[:, 3] == 255)
    # blue-ish material stays blue-ish, lit pixels are not black
    assert np.mean(fg[:, 2]) > np.mean(fg[:, 0]) and fg[:, :3].max() > 100
    # a surface facing the headlight is brighter than a grazing one
    o, d = cam.rays()
    ref = T.cast(sh, o, d)
    facing = -(ref.normal * d).sum(-1)
    lum = img.rgba[..., :3].astype(float).sum(-1)
    m = img.mask
    assert np.corrcoef(facing[m], lum[m])[0, 1] > 0.3
    img.save(tmp_path / "a.png")
    img.save_depth(tmp_path / "d.npy")
    img.save_ids(tmp_path / "i.npy")
    img.save_stats(tmp_path / "s.json")
    from PIL import Image as PILImage

    back = np.asarray(PILImage.open(tmp_path / "a.png"))
    assert np.array_equal(back, img.rgba)
    assert np.array_equal(np.load(tmp_path / "d.npy"), img.depth)
    assert np.array_equal(np.load(tmp_path / "i.npy"), img.ids)
    st = json.loads((tmp_path / "s.json").read_text())
    assert st["method"] == "raytrace" and st["covered_pixels"] == int(img.mask.sum())


def test_options_validation(cl_context):
    sh = clcsg.sphere(1.0)
    cam = Camera.fit(np.array([[-1, -1, -1], [1, 1, 1.0]]), 16, 12)
    with pytest.raises(UsageError, match="background"):
        raytrace(sh, cam, device=cl_context, background=(2, 0, 0))
    with pytest.raises(UsageError, match="precision"):
        raytrace(sh, cam, device=cl_context, precision="half")
    with pytest.raises(UsageError, match="shading option"):
        raytrace(sh, cam, device=cl_context, bogus=1)
    with pytest.raises(UsageError, match="camera"):
        raytrace(sh, "not a camera", device=cl_context)


def test_default_camera_fits_scene(cl_context):
    img = raytrace(clcsg.sphere(1.0), device=cl_context)
    assert img.rgba.shape == (480, 640, 4)
    ii, jj = np.nonzero(img.mask)
    assert ii.min() > 0 and jj.min() > 0 and ii.max() < 479 and jj.max() < 639


def test_float_precision_close_to_double(cl_context):
    tape = clcsg.Scene(SCENES["box_minus_3_cylinders"]).compile()
    cam = Camera.fit(tape, 64, 48)
    img = raytrace(tape, cam, device=cl_context, precision="float")
    ref = raytrace(tape, cam, device=cl_context)
    assert (img.mask != ref.mask).mean() < 0.01
    both = img.mask & ref.mask
    assert np.median(np.abs(img.depth[both] - ref.depth[both]) / ref.depth[both]) < 1e-5


def colour_scenes():
    """Scenes whose colours the "first boundary that holds the point" rule gets wrong: flush
    inlays, faces shared by three primitives, a coloured cutter; and two cubes side by side."""
    grey, red, green, blue = (0.6, 0.6, 0.6), (1, 0, 0), (0, 1, 0), (0, 0, 1)
    plate = clcsg.box((4, 4, 1), color=grey)
    box_inlay = (plate - clcsg.box((2, 1.5, 1), center=(0.5, 0, 0.3))) | clcsg.box((2, 1.5, 0.6), center=(0.5, 0, 0.2), color=red)
    round_inlay = (plate - clcsg.cylinder(1, 0.8, center=(-0.6, 0.4, 0.4))) | clcsg.cylinder(0.8, 0.8, center=(-0.6, 0.4, 0.1), color=blue)
    three = (clcsg.box((2, 2, 1), center=(-0.5, 0, 0), color=red) | clcsg.box((2, 2, 1), center=(0.5, 0.3, 0), color=green)
             | clcsg.box((2, 2, 1), center=(0, -0.4, 0), color=blue))
    cutter = clcsg.box(2, color=grey) - clcsg.cylinder(3, 0.6, color=red) - clcsg.sphere(0.5, center=(1, 1, 1), color=green)
    side_by_side = clcsg.box(1.0, color=red) | clcsg.box(1.0, center=(1.0, 0, 0), color=blue)
    return {"box_inlay": box_inlay, "round_inlay": round_inlay, "three_coplanar": three,
            "coloured_cutter": cutter, "cubes_side_by_side": side_by_side}


COLOUR_SCENES = colour_scenes()
#: per scene: instances (tree order) that must be visible from above
COLOUR_VISIBLE = {"box_inlay": {0, 2}, "round_inlay": {0, 2}, "three_coplanar": {0, 1, 2},
                  "coloured_cutter": {0, 1, 2}, "cubes_side_by_side": {0, 1}}


def colour_views(tape):
    c = 0.5 * (tape.bound[0] + tape.bound[1])
    return [Camera.look_at(c + (0.4, -2.5, 6), c, fov=50, width=W, height=H),
            Camera.look_at(c + (5, 3, 4), c, fov=45, width=W, height=H)]


@pytest.mark.parametrize("name", sorted(COLOUR_SCENES))
def test_visible_primitive_colours(cl_context, name):
    """Per pixel against the oracle's rule: the first instance that bounds the solid."""
    shape = COLOUR_SCENES[name]
    tape = clcsg.Scene(shape).compile()
    seen = set()
    for cam in colour_views(tape):
        img = raytrace(tape, cam, device=cl_context)
        compare(img, shape, tape, cam)
        seen |= set(np.unique(img.primitives[img.mask]).tolist())
        for k, inst in enumerate(tape.instances):  # a pixel shows its primitive's colour
            lit = img.mask & (img.primitives == k)
            rgb = img.rgba[lit][:, :3].astype(float)
            if len(rgb) and max(inst.color[:3]) - min(inst.color[:3]) > 0.5:
                assert np.argmax(rgb.mean(axis=0)) == int(np.argmax(inst.color[:3]))
    assert COLOUR_VISIBLE[name] <= seen, f"visible instances {sorted(seen)}"


def test_flush_inlay_top_shows_the_inlay(cl_context):
    shape = COLOUR_SCENES["box_inlay"]
    tape = clcsg.Scene(shape).compile()
    cam = Camera.look_at((0.5, 0, 8), (0.5, 0, 0), up=(0, 1, 0), fov=10, width=32, height=24)
    img = raytrace(tape, cam, device=cl_context)
    assert img.mask.all() and np.all(img.primitives == 2)


def column_of_spheres(n=220, seed=3):
    """n spheres along the z axis, bored through: from the axis one tile sees them all."""
    rng = np.random.default_rng(seed)
    spheres = [clcsg.sphere(0.5, center=(*rng.uniform(-0.25, 0.25, 2), 0.35 * k), color=tuple(rng.uniform(0, 1, 3)))
               for k in range(n)]
    return clcsg.union(*spheres) - clcsg.cylinder(200, 0.12, center=(0, 0, 40))


INSIDE_COLUMN = (0.3, 0.0, 10.0)


def test_hundreds_of_leaves_per_tile_match_the_oracle(cl_context):
    """200+ leaves in one tile's tape, from outside and from inside the bore, per pixel
    against the oracle."""
    shape = column_of_spheres()
    tape = clcsg.Scene(shape).compile()
    views = [Camera.look_at((0.05, -0.08, -4), (0, 0, 10), fov=20, width=48, height=36),
             Camera.look_at((0.02, 0.01, 20.0), (0.1, 0.05, 60), fov=70, width=48, height=36),
             Camera.look_at((3, -2, 30), (0, 0, 38), fov=40, width=48, height=36),
             Camera.look_at(INSIDE_COLUMN, (0.3, 0.5, 14), fov=70, width=48, height=36)]
    assert clcsg.contains(shape, INSIDE_COLUMN)
    leaves = []
    for cam in views:
        img = raytrace(tape, cam, device=cl_context)
        ref = compare(img, shape, tape, cam)
        assert ref.mask.mean() > 0.15
        leaves.append(img.stats["tile_leaves_max"])
    assert max(leaves) >= 200, leaves


def holed_plate(n=16, size=40.0, thick=2.0):
    """A plate minus an n x n grid of holes, each a cylinder and a cone chamfer at the top: seen
    obliquely one tile's frustum crosses hundreds of them."""
    pitch = size / n
    r = 0.3 * pitch
    parts = [clcsg.box((size, size, thick), color=(0.7, 0.7, 0.7))]
    for i in range(n):
        for j in range(n):
            x, y = -size / 2 + (i + 0.5) * pitch, -size / 2 + (j + 0.5) * pitch
            parts.append(clcsg.cylinder(thick + 2, r, (x, y, 0), color=(0.9, 0.3, 0.2)))
            parts.append(clcsg.cone(0.6 * r + 0.01, 1.5 * r, r - 0.01, (x, y, thick / 2 - 0.3 * r)))
    return clcsg.difference(*parts)


def test_holed_plate_with_hundreds_of_leaves_per_tile_matches_the_oracle(cl_context):
    """A plate with 256 chamfered holes (513 primitives), obliquely, grazing, from inside a hole
    and from inside the plate's material, per pixel against the oracle; the trace without
    culling and per-ray pruning gives the same image."""
    from clcsg.rendering.raytracer import trace
    from clcsg.rendering.shading import Shading

    shape = holed_plate()
    tape = clcsg.Scene(shape).compile()
    pitch = 40.0 / 16
    hole = (-20 + 7.5 * pitch, -20 + 7.5 * pitch, 0.0)
    solid = (hole[0] + 0.5 * pitch, hole[1] + 0.5 * pitch, -0.2)
    views = [Camera.look_at((0, -32, 8), (0, 4, 0), fov=60, width=64, height=40),
             Camera.look_at((3, -30, 1.4), (0, 10, 0.6), fov=50, width=64, height=40),
             Camera.look_at(hole, (hole[0] + 3, hole[1] + 20, -0.3), fov=80, width=48, height=36),
             Camera.look_at(solid, (solid[0] + 20, solid[1] + 6, 0.1), fov=80, width=48, height=36)]
    assert not clcsg.contains(shape, hole) and clcsg.contains(shape, solid)
    leaves = []
    for cam in views:
        img = raytrace(tape, cam, device=cl_context)
        ref = compare(img, shape, tape, cam)
        assert ref.mask.mean() > 0.15
        leaves.append(img.stats["tile_leaves_max"])
        plain = trace(cl_context, tape, cam, Shading(), accelerate=False)
        assert np.array_equal(plain.depth, img.depth) and np.array_equal(plain.ids, img.ids)
    assert min(leaves) >= 200, leaves


def test_a_faceted_sphere_whose_rays_pass_many_plane_roots_matches_the_oracle(cl_context):
    """Mesh spheres (a convex mesh: the AND of its face half-spaces, whose planes' extensions
    cross every ray many times before and after the surface) minus two cylinders, from
    outside, obliquely and from inside the solid: 128 face planes per pixel against the
    oracle, 512 against the walk that visits every root on the slab tape (no per-ray pruning),
    which gives the same image as the windowed search (raytrace.cl's window_hit)."""
    from clcsg.rendering.raytracer import trace
    from clcsg.rendering.shading import Shading
    from test_operands import faceted_sphere

    inside = (0.0, 0.55, 0.2)
    views = [lambda t: Camera.fit(t, 64, 48),
             lambda t: Camera.look_at((2.5, -1.5, 1.2), (0, 0, 0), fov=40, width=64, height=48),
             lambda t: Camera.look_at(inside, (0.4, -1, 0.1), fov=90, width=48, height=36)]
    for levels in (2, 3):
        v, f = faceted_sphere(levels)
        shape = clcsg.polyhedron(v, f) - clcsg.cylinder(3, 0.3) - clcsg.cylinder(3, 0.25, axis=(1, 0, 0))
        tape = clcsg.Scene(shape).compile()
        assert clcsg.contains(shape, inside)
        for view in views:
            cam = view(tape)
            img = raytrace(tape, cam, device=cl_context)
            if levels == 2:
                assert compare(img, shape, tape, cam).mask.mean() > 0.2
            plain = trace(cl_context, tape, cam, Shading(), accelerate=False)
            assert np.array_equal(plain.depth, img.depth) and np.array_equal(plain.ids, img.ids)
            assert (img.ids >= 0).mean() > 0.2
