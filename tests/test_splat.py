"""The splat renderer (rendering/splat.cl + resolve.cl) against the exact ray tracer.

Criteria (paper section 6: pixel-perfect, hole-free): the coverage mask equals the ray
tracer's on >= 99.9 % of the pixels, there is no hole (background where the ray tracer hits)
at pixels whose 3x3 neighbourhood is all surface in the ray tracer, depth agrees within 1e-4
relative where both hit, and ids agree on >= 99.9 % of the pixels; with every combination of
the overdraw optimizations, from outside, grazing and close-up views, with tiny and large
radii.  The ray tracer itself is checked against the numpy oracle in test_raytrace.py.
"""

import dataclasses
import types

import numpy as np
import pytest

import clcsg
from clcsg.rendering.camera import Camera, orbit
from clcsg.errors import DeviceError, UsageError
from clcsg.cl.records import pack
from clcsg.model.quadric import Quadric
from clcsg import raytrace, render
from clcsg.sampling.samples import Samples

import tree_oracle as T
from clcsg.compile.interpret import member

from clcsg import sample

W, H = 96, 72
FLAGS = [(False, False), (True, False), (False, True), (True, True)]

THREE_CYL = (
    clcsg.box(2.0, color=(0.9, 0.6, 0.3))
    - clcsg.cylinder(3, 0.55)
    - clcsg.cylinder(3, 0.55, axis=(1, 0, 0))
    - clcsg.cylinder(3, 0.55, axis=(0, 1, 0))
)
SCENES = {
    "sphere": clcsg.sphere(1.0, center=(0.3, -0.2, 0.1)),
    "box_minus_3_cylinders": THREE_CYL,
    "union_of_spheres": clcsg.sphere(1.0) | clcsg.sphere(0.8, center=(1.1, 0.2, 0.3)),
    "hyperboloid_and_box": clcsg.quadric(Quadric.hyperboloid_one_sheet(radii=(0.5, 0.5, 0.8)).matrix)
    & clcsg.box((2, 2, 1.6)),
    "cone_frustum": clcsg.cone(2.0, r1=1.0, r2=0.4),
    "touching_boxes": clcsg.box(1.0) | clcsg.box(1.0, center=(1.0, 0, 0)),
}


def interior(mask):
    """Pixels whose 3x3 neighbourhood is all True (away from silhouette edges)."""
    p = np.pad(mask, 1, constant_values=False)
    out = np.ones_like(mask)
    for di in range(3):
        for dj in range(3):
            out &= p[di : di + mask.shape[0], dj : dj + mask.shape[1]]
    return out


def check(img, ref, frac=0.999, rel=1e-4):
    assert img.rgba.shape == ref.rgba.shape
    agree = (img.mask == ref.mask).mean()
    assert agree >= frac, f"coverage masks agree on {agree:.5f} of the pixels"
    holes = interior(ref.mask) & ~img.mask
    assert not holes.any(), f"{holes.sum()} holes at {np.argwhere(holes)[:5].tolist()}"
    both = img.mask & ref.mask
    assert both.any()
    rd = np.abs(img.depth[both].astype(np.float64) - ref.depth[both]) / ref.depth[both]
    assert rd.max() <= rel, f"depth rel diff {rd.max()}"
    ids = (img.ids == ref.ids).mean()
    assert ids >= frac, f"ids agree on {ids:.5f} of the pixels"
    # the same hit is shaded the same way (shade.h is shared)
    same = both & (img.ids == ref.ids)
    diff = np.abs(img.rgba[same].astype(int) - ref.rgba[same].astype(int)).max(axis=-1)
    assert (diff <= 2).mean() >= frac
    assert np.all(np.isinf(img.depth[~img.mask])) and np.all(img.ids[~img.mask] == -1)


def views(dnf, w=W, h=H):
    b = dnf.bound
    c = 0.5 * (b[0] + b[1])
    R = 0.5 * np.linalg.norm(b[1] - b[0])
    out = [Camera.fit(dnf, w, h)]
    out += list(orbit(b, 3, elevation=-40, width=w, height=h))[1:2]
    top = b[1][2]
    out.append(Camera.look_at((c[0] + 3 * R, c[1] - 1.2 * R, top + 1e-3 * R), (c[0], c[1], top), fov=40, width=w, height=h))
    return out


_samples = {}


def samples_of(name, radius):
    key = (name, radius)
    if key not in _samples:
        _samples[key] = sample(SCENES[name], radius)
    return _samples[key]


@pytest.mark.parametrize("name", sorted(SCENES))
def test_splats_match_raytracer(cl_context, name):
    S = samples_of(name, 0.12)
    assert len(S) > 0
    for cam in views(S.tape):
        ref = raytrace(S.tape, cam, device=cl_context)
        for sa, bf in FLAGS:
            img = render(S, cam, device=cl_context, surface_aligned=sa, backface_culling=bf)
            check(img, ref)


@pytest.mark.parametrize("size", [(93, 61), (7, 5), (1, 9)])
def test_rows_that_are_not_whole_resolve_lanes(cl_context, size):
    """Widths that are not a multiple of the resolve pass's RESOLVE_LANES pixels per
    work-item (and narrower than one): every pixel of the row's last lanes is written."""
    from clcsg.cl.constants import RESOLVE_LANES

    assert size[0] % RESOLVE_LANES
    S = samples_of("box_minus_3_cylinders", 0.12)
    for cam in views(S.tape, *size)[:2]:
        ref = raytrace(S.tape, cam, device=cl_context)
        img = render(S, cam, device=cl_context)
        check(img, ref, frac=0.99 if min(size) < 10 else 0.999)
        assert img.mask[:, -1].any() or not ref.mask[:, -1].any()


@pytest.mark.parametrize("radius", [0.02, 0.8])
def test_tiny_and_large_radii(cl_context, radius):
    """Tiny splats (many samples, few clip literals) and large ones (heavy clipping: splats
    much larger than the holes they must not cover)."""
    S = sample(THREE_CYL, radius)
    if radius > 0.5:
        assert S.clip_count.max() >= 3 and S.clip_count.mean() > 1.5
    for cam in views(S.tape)[:2]:
        ref = raytrace(S.tape, cam, device=cl_context)
        for sa, bf in FLAGS:
            check(render(S, cam, device=cl_context, surface_aligned=sa, backface_culling=bf), ref)


def test_close_up(cl_context):
    """The eye close to the surface: one splat covers many pixels; splats next to the eye
    reach the eye plane and get the whole screen as their bound."""
    S = samples_of("box_minus_3_cylinders", 0.5)
    cams = [
        Camera.look_at((0.35, -0.3, 1.25), (0.0, 0.0, 0.9), fov=60, width=W, height=H),
        Camera.look_at((1.1, -1.1, 0.7), (0.6, -0.6, 0.2), fov=70, width=W, height=H),
    ]
    for cam in cams:
        ref = raytrace(S.tape, cam, device=cl_context)
        assert ref.mask.mean() > 0.5
        for sa, bf in FLAGS:
            img = render(S, cam, device=cl_context, surface_aligned=sa, backface_culling=bf)
            check(img, ref)
            # one splat covers many pixels: far fewer samples than covered pixels win
            winners = img.stats["covered_pixels"]
            assert winners > 0 and len(S) < 2000


def test_grazing_views(cl_context):
    S = samples_of("box_minus_3_cylinders", 0.12)
    for eps in (1e-2, 1e-5):
        # eye almost in the plane of the top face (z = 1) and of the front face (y = -1)
        for eye, tgt in [((4.0, -0.5, 1.0 + eps), (0.0, 0.3, 1.0)), ((-0.3, -1.0 - eps, 4.0), (0.2, -1.0, 0.0))]:
            cam = Camera.look_at(eye, tgt, fov=40, width=W, height=H)
            ref = raytrace(S.tape, cam, device=cl_context)
            for sa, bf in FLAGS:
                check(render(S, cam, device=cl_context, surface_aligned=sa, backface_culling=bf), ref)


def test_optimizations_reduce_overdraw(cl_context):
    S = samples_of("box_minus_3_cylinders", 0.12)
    cam = Camera.fit(S.tape, W, H)
    st = {f: render(S, cam, device=cl_context, surface_aligned=f[0], backface_culling=f[1]).stats for f in FLAGS}
    base = st[(False, False)]
    for key in ("fragments", "clip_evaluations", "covered_pixels", "overdraw", "splats_culled", "bound_pixels"):
        assert key in base
    assert base["splats_culled"] == 0
    assert st[(True, False)]["fragments"] < 0.8 * base["fragments"]
    assert st[(False, True)]["splats_culled"] > 0.2 * len(S)
    assert st[(False, True)]["fragments"] < 0.8 * base["fragments"]
    assert st[(True, True)]["overdraw"] < 0.5 * base["overdraw"]
    assert all(s["covered_pixels"] == base["covered_pixels"] for s in st.values())
    assert base["overdraw"] == pytest.approx(base["fragments"] / base["covered_pixels"])
    assert base["splats_drawn"] + base["splats_offscreen"] == len(S)
    quiet = render(S, cam, device=cl_context, stats=False)
    assert "fragments" not in quiet.stats and quiet.stats["covered_pixels"] == base["covered_pixels"]


def test_eye_inside_turns_culling_off(cl_context):
    """From inside the solid back faces are what one sees: culling must not apply."""
    S = samples_of("sphere", 0.12)
    c = np.array([0.3, -0.2, 0.1])
    cam = Camera.look_at(c + [0.2, 0.1, 0.0], c + [1, 0.3, 0.2], fov=60, width=64, height=48)
    img = render(S, cam, device=cl_context)
    assert img.stats["backface_culling"] is False and "inside" in img.stats["backface_culling_note"]
    ref = raytrace(S.tape, cam, device=cl_context)
    # the ray tracer reports the exit point from inside as well (first root t > 0)
    check(img, ref)
    assert img.mask.all()


# -- samples built without the sampler: dense exact surface points from the oracle --------------


def synthetic_samples(shape, radius, cell=0.25):
    """Samples from the tree oracle's surface points thinned to one per (cell * radius) voxel and
    quadric, each with the whole tape as its clip program (exact everywhere).  Lines dense
    enough that every surface point is within ~0.5 r of a kept point."""
    tape = clcsg.Scene(shape).compile()
    b = tape.bound
    R = 0.5 * np.linalg.norm(b[1] - b[0])
    n_lines = int(min(4e5, 60 * (R / radius) ** 2))
    sp = T.surface_points(shape, b + [[-1e-3 * R], [1e-3 * R]], n_lines=n_lines, directions="both")
    to_tape = {int(o): t for t, o in enumerate(T.quadric_table(shape).match(tape.quadrics)) if o >= 0}
    qi = np.array([to_tape[int(o)] for o in sp.quadrics], dtype=np.int32)
    key = np.column_stack([np.floor(sp.points / (cell * radius)).astype(np.int64), qi])
    _, first = np.unique(key, axis=0, return_index=True)
    first.sort()
    n = len(first)
    return Samples(sp.points[first], sp.normals[first], np.full(n, float(radius)), qi[first],
                   sp.signs[first].astype(np.int32), sp.primitives[first].astype(np.int32),
                   np.zeros(n, np.int32), np.full(n, len(tape.ops), np.int32), tape.ops.copy(), float(radius), tape,
                   pack(tape))


def test_synthetic_samples_render_exactly(cl_context):
    """The renderer alone, fed with samples that do not come from the sampler."""
    shape = SCENES["touching_boxes"] | clcsg.sphere(0.4, center=(0.5, 0, 0.5))
    S = synthetic_samples(shape, 0.15)
    for cam in views(S.tape, 64, 48)[:2]:
        ref = raytrace(S.tape, cam, device=cl_context)
        for sa, bf in [(False, False), (True, True)]:
            check(render(S, cam, device=cl_context, surface_aligned=sa, backface_culling=bf), ref)


def test_no_clipping_shows_overhang(cl_context):
    """Without clip sets the splats overhang the holes: the clip test is what makes it exact."""
    S = samples_of("box_minus_3_cylinders", 0.3)
    cam = Camera.fit(S.tape, W, H)
    ref = raytrace(S.tape, cam, device=cl_context)
    bare = dataclasses.replace(S, clip_count=np.zeros_like(S.clip_count), _device={})
    img = render(bare, cam, device=cl_context)
    assert (img.mask & ~ref.mask).sum() > 20 or (img.ids != ref.ids).sum() > 20


def test_empty_samples_and_errors(cl_context):
    S = samples_of("sphere", 0.12)
    cam = Camera.fit(S.tape, 32, 24)
    empty = dataclasses.replace(
        S, positions=S.positions[:0], normals=S.normals[:0], radii=S.radii[:0], quadrics=S.quadrics[:0],
        signs=S.signs[:0], primitives=S.primitives[:0], clip_first=S.clip_first[:0], clip_count=S.clip_count[:0], _device={},
    )
    img = render(empty, cam, device=cl_context, background=(0, 0, 0))
    assert not img.mask.any() and np.all(img.rgba[..., :3] == 0)
    with pytest.raises(UsageError, match="Samples"):
        render(SCENES["sphere"], cam, device=cl_context)
    no_atomics = types.SimpleNamespace(
        ctx=cl_context.ctx, queue=cl_context.queue, device=cl_context.device,
        info=dataclasses.replace(cl_context.info, int64_atomics=False),
    )
    with pytest.raises(DeviceError, match="int64"):
        render(S, cam, device=no_atomics)


def test_default_camera_and_float_precision(cl_context):
    S = samples_of("sphere", 0.12)
    img = render(S, device=cl_context, stats=False)
    assert img.rgba.shape == (480, 640, 4) and img.mask.any()
    cam = Camera.fit(S.tape, 64, 48)
    f = render(S, cam, device=cl_context, precision="float")
    check(f, raytrace(S.tape, cam, device=cl_context), frac=0.995, rel=1e-4)


# -- one splat at a time: the screen bounds and culling tests are conservative -------------------


def splat_reference(S, k, cam, culling, margin=0.0):
    """Depth of the fragments of sample k alone (numpy, float64): near root first, radius,
    depth > 0, back-face (if culling) and clip tests, each loosened by ``margin`` (relative;
    negative tightens).  +inf where the splat writes nothing."""
    o, v = cam.rays()
    v = v.reshape(-1, 3)
    e = cam.eye
    s = S.positions[k]
    r = S.radii[k]
    Q = Quadric(S.tape.quadrics[S.quadrics[k]])
    a = s - e
    tc = v @ a
    org = e + tc[:, None] * v
    roots = Q.intersect_line(org, v)
    out = np.full(len(v), np.inf)
    done = np.zeros(len(v), dtype=bool)
    prog = S.clip_ops[S.clip_first[k] : S.clip_first[k] + S.clip_count[k]]
    for tau in roots:
        p = org + tau[:, None] * v
        ok = np.isfinite(tau) & ~done
        with np.errstate(invalid="ignore"):
            ok &= np.sum((p - s) ** 2, axis=1) <= r * r * (1 + margin)
            ok &= tc + tau > 0
            side = np.full(len(p), S.signs[k])
            if len(prog):
                neg, pos = member(prog, S.tape.quadrics, np.nan_to_num(p), int(S.quadrics[k]))
                if margin <= 0:
                    ok &= neg != pos
                side = np.where(neg, 1, -1)
            if culling:
                g = side[:, None] * Q.gradient(p)
                ok &= np.sum(g * v, axis=1) <= margin * np.linalg.norm(g, axis=1)
        out[ok] = (tc + tau)[ok]
        done |= ok
    return out.reshape(cam.height, cam.width)


def only(S, k):
    sl = slice(k, k + 1)
    return dataclasses.replace(
        S, positions=S.positions[sl], normals=S.normals[sl], radii=S.radii[sl], quadrics=S.quadrics[sl],
        signs=S.signs[sl], primitives=S.primitives[sl], clip_first=S.clip_first[sl], clip_count=S.clip_count[sl], _device={},
    )


SINGLE = {
    "thin_cylinder": (clcsg.cylinder(1.5, 0.08, axis=(0.3, 0.2, 1.0)), 0.3),
    "hyperboloid_and_box": (SCENES["hyperboloid_and_box"], 0.4),
    "cone_frustum": (clcsg.cone(2.0, r1=1.0, r2=0.0), 0.3),  # up to the apex: zero gradient
    "box_minus_3_cylinders": (THREE_CYL, 0.5),
}


@pytest.mark.parametrize("name", sorted(SINGLE))
def test_single_splat_fragments_are_exact(cl_context, name):
    """Each splat alone writes exactly the pixels whose ray meets its quadric within r of the
    sample and passes the clip (and back-face) tests: no screen bound, surface-aligned slab or
    culling test may lose a fragment, whatever the curvature (a cylinder thinner than the
    splat, saddles, a cone apex) or the view (close-up, grazing)."""
    shape, radius = SINGLE[name]
    S = sample(shape, radius)
    dnf = S.tape
    b = dnf.bound
    c = 0.5 * (b[0] + b[1])
    R = 0.5 * np.linalg.norm(b[1] - b[0])
    cams = [
        Camera.fit(dnf, 48, 36),
        Camera.look_at(c + [0.5 * R, -0.6 * R, 0.45 * R], c, fov=80, width=48, height=36),
        Camera.look_at((c[0] + 3 * R, c[1] - R, b[1][2] + 1e-4 * R), (c[0], c[1], b[1][2]), fov=40, width=48, height=36),
    ]
    rng = np.random.default_rng(7)
    picks = rng.choice(len(S), size=min(12, len(S)), replace=False)
    written = 0

    def close_ups(k):
        # per sample: views from 3 r away, one steep and one oblique, so the splat spans many
        # pixels and a bound that is a few percent too small shows
        s, n, r = S.positions[k], S.normals[k], S.radii[k]
        t = np.cross(n, [0.3, 0.5, 0.8])
        t /= np.linalg.norm(t)
        return [Camera.look_at(s + 3 * r * (d / np.linalg.norm(d)), s + 0.3 * r * t, up=np.cross(t, n) + 0.2 * n,
                               fov=60, width=48, height=36) for d in (n + 0.3 * t, 0.5 * n + t)]

    pairs = [(cam, int(k)) for cam in cams for k in picks]
    pairs += [(cam, int(k)) for k in picks for cam in close_ups(int(k))]
    for cam, k in pairs:
        one = only(S, k)
        for sa, bf in FLAGS:
            img = render(one, cam, device=cl_context, surface_aligned=sa, backface_culling=bf)
            culling = img.stats["backface_culling"]
            ref = splat_reference(S, k, cam, culling)
            loose = np.isfinite(splat_reference(S, k, cam, culling, 1e-7))
            tight = np.isfinite(splat_reference(S, k, cam, culling, -1e-7))
            missing = tight & ~img.mask
            extra = img.mask & ~loose
            assert not missing.any(), f"sample {k} flags {sa, bf}: {missing.sum()} fragments lost"
            assert not extra.any(), f"sample {k} flags {sa, bf}: {extra.sum()} extra fragments"
            both = img.mask & np.isfinite(ref)
            rtol = 1e-5 if img.stats["precision"] == "double" else 1e-4
            assert np.allclose(img.depth[both], ref[both], rtol=rtol)
            written += int(img.mask.sum())
    assert written > 500


# -- `clcsg render` (clcsg/cli/render.py) ----------------------------------------------------------


def _run_cli(argv):
    import argparse

    from clcsg.cli.render import add_parser as add_render_parser, run as cli_render

    parser = argparse.ArgumentParser(prog="clcsg")
    add_render_parser(parser.add_subparsers(dest="command"))
    return cli_render(parser.parse_args(["render"] + argv))


def test_cli_render(cl_context, tmp_path, capsys):
    import json

    from PIL import Image as PILImage

    path = tmp_path / "part.json"
    clcsg.save(THREE_CYL, path)
    out = {}
    for method in ("splat", "raytrace"):
        png, dep, ids, st = (tmp_path / f"{method}.{ext}" for ext in ("png", "d.npy", "i.npy", "json"))
        rc = _run_cli([str(path), "-o", str(png), "--method", method, "--size", "64x48", "-r", "0.1",
                       "--depth", str(dep), "--ids", str(ids), "--stats", str(st), "--background", "0,0,255"])
        assert rc == 0
        rgba = np.asarray(PILImage.open(png))
        assert rgba.shape == (48, 64, 4)
        d, i = np.load(dep), np.load(ids)
        assert d.dtype == np.float32 and i.dtype == np.int32 and d.shape == i.shape == (48, 64)
        assert np.all(rgba[i < 0][:, :3] == [0, 0, 255])
        stats = json.loads(st.read_text())
        assert stats["method"] == method
        out[method] = (rgba, d, i)
    assert "splats" in capsys.readouterr().out
    assert (out["splat"][2] == out["raytrace"][2]).mean() >= 0.999
    # explicit camera: the target pixel shows the surface point straight ahead
    png = tmp_path / "eye.png"
    ids = tmp_path / "eye.npy"
    assert _run_cli([str(path), "-o", str(png), "--size", "33x25", "--eye", "0.8,-5,0.7", "--target", "0.8,0,0.7",
                     "--fov", "30", "--method", "raytrace", "--ids", str(ids)]) == 0
    i = np.load(ids)
    assert i[12, 16] >= 0 and i[0, 0] == -1


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--size", "64x0"], "--size"),
        (["--size", "big"], "--size"),
        (["--eye", "1,2"], "--eye"),
        (["--background", "0,0"], "--background"),
        (["--background", "0,0,-1"], "--background"),
        (["-r", "0"], "--radius"),
        (["--fov", "180"], "fov"),
        (["--eye", "0,0,0", "--target", "0,0,0"], "eye and target"),
    ],
)
def test_cli_render_errors(tmp_path, argv, message):
    path = tmp_path / "s.json"
    clcsg.save(clcsg.sphere(1.0), path)
    with pytest.raises(UsageError, match=message):
        _run_cli([str(path), "-o", str(tmp_path / "x.png"), "--method", "raytrace"] + argv)


def test_splat_and_sample_colours_follow_the_bounding_rule(cl_context):
    """Flush inlays, faces of three primitives, a coloured cutter, cubes side by side: every
    sample carries the oracle's primitive, and splat pixels the ray tracer's."""
    from test_raytrace import COLOUR_SCENES, colour_views

    for name, shape in sorted(COLOUR_SCENES.items()):
        S = sample(shape, 0.08)
        Q = S.tape.quadrics[S.quadrics]
        exact = T.primitive_at(shape, S.positions, Q)
        loose = T.primitive_at(shape, S.positions, Q, tol=1e-9)
        firm = exact == loose
        assert firm.mean() > 0.9 and np.array_equal(S.primitives[firm], exact[firm]), name
        for cam in colour_views(S.tape):
            ref = raytrace(S.tape, cam, device=cl_context)
            img = render(S, cam, device=cl_context)
            both = interior(img.mask & ref.mask) & (img.ids == ref.ids)
            assert both.sum() > 300, name
            assert (img.primitives[both] == ref.primitives[both]).mean() >= 0.999, name


def l_bracket():
    """Two boxes overlapping in an L (faces shared by both), drilled, the upright in its own
    colour: planes with several owners, where the colour rule needs the instance program."""
    base = clcsg.box((3, 1, 0.4), center=(0, 0, -0.3), color=(0.7, 0.7, 0.7))
    upright = clcsg.box((3, 0.4, 2), center=(0, 0.3, 0.5), color=(0.2, 0.4, 0.9))
    holes = clcsg.cylinder(1, 0.2, center=(0.9, -0.1, -0.3)) | clcsg.cylinder(1, 0.2, center=(-0.9, -0.1, -0.3))
    return (base | upright) - holes


def test_a_splats_primitive_holds_over_its_ball():
    """A splat's primitive decided once on the host (sampling/splat_colours.py) is the float64
    oracle's primitive at every other sample of its quadric inside its ball; most splats get one."""
    from scipy.spatial import cKDTree
    from test_raytrace import COLOUR_SCENES

    for name, shape in sorted({**COLOUR_SCENES, "l_bracket": l_bracket()}.items()):
        S = sample(shape, 0.08)
        fixed = S.records()["splat_primitive"]
        Q = S.tape.quadrics[S.quadrics]
        exact = T.primitive_at(shape, S.positions, Q)
        firm = exact == T.primitive_at(shape, S.positions, Q, tol=1e-9)
        pairs = cKDTree(S.positions).query_pairs(float(S.radii.max()), output_type="ndarray")
        pairs = np.concatenate([pairs, pairs[:, ::-1]])
        i, j = pairs[:, 0], pairs[:, 1]
        near = np.linalg.norm(S.positions[i] - S.positions[j], axis=1) <= S.radii[i]
        check = near & (S.quadrics[i] == S.quadrics[j]) & (fixed[i] >= 0) & firm[j]
        assert check.sum() > 500 and (fixed >= 0).mean() > 0.8, name
        assert np.array_equal(fixed[i[check]], exact[j[check]]), name
