"""Output files: image formats by extension, checked before any work; PLY read back with
plyfile; samples saved as .npz and rendered again; Open3D and trimesh point clouds."""

from __future__ import annotations

import io
import os
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image as PILImage

import clcsg
from clcsg.cli import app as cli
from clcsg.errors import SceneError, UsageError
from clcsg.writers.output_files import IMAGE_FORMATS
from clcsg.writers.samples_npz import load_samples
from optional_libs import require_module

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PART = (clcsg.box(2, color=(0.9, 0.5, 0.1)) - clcsg.cylinder(3, 0.5)) | clcsg.sphere(0.6, center=(0, 0, 1.1))


@pytest.fixture(scope="module")
def part_samples(cl_context):
    return clcsg.sample(PART, 0.12, device=cl_context, progress=False)


@pytest.fixture
def scene_file(tmp_path):
    path = tmp_path / "part.json"
    clcsg.save(PART, path)
    return path


# -- images ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("ext", sorted(IMAGE_FORMATS))
def test_every_image_extension_writes_what_pillow_reads(cl_context, scene_file, tmp_path, capsys, ext):
    out = tmp_path / f"part{ext}"
    argv = ["render", str(scene_file), "-o", str(out), "--method", "raytrace", "--size", "40x30", "--transparent"]
    if IMAGE_FORMATS[ext] == "JPEG":
        with pytest.warns(UserWarning, match="JPEG has no alpha channel"):
            rc = cli.main(argv)
    else:
        rc = cli.main(argv)
    assert rc == 0, capsys.readouterr().err
    back = np.asarray(PILImage.open(out))
    ref = clcsg.raytrace(PART, clcsg.Camera.fit_silhouette(PART, 40, 30, device=cl_context), device=cl_context,
                         background=(1, 1, 1, 0))
    if IMAGE_FORMATS[ext] == "JPEG":  # no alpha: RGB, lossy
        assert back.shape == (30, 40, 3)
        assert np.abs(back.astype(int) - ref.rgba[..., :3]).mean() < 12
    else:  # PNG, lossless WebP, TIFF: the exact RGBA, transparent background included
        assert back.shape == (30, 40, 4)
        assert np.array_equal(back, ref.rgba)
        assert np.all(back[~ref.mask][:, 3] == 0)
    assert capsys.readouterr().out.strip().endswith(str(out))


def test_image_save_and_repr_png(tmp_path):
    rgba = np.zeros((6, 8, 4), np.uint8)
    rgba[..., 0] = np.arange(8) * 30
    rgba[..., 3] = 255
    img = clcsg.Image(rgba, np.zeros((6, 8), np.float32), np.zeros((6, 8), np.int32))
    png = img._repr_png_()
    assert png.startswith(b"\x89PNG") and np.array_equal(np.asarray(PILImage.open(io.BytesIO(png))), rgba)
    with pytest.raises(UsageError, match=r"unknown image format \('\.bmp'\); use \.png, \.jpg, \.jpeg, \.webp") as e:
        img.save(tmp_path / "x.bmp")
    assert "\n" not in str(e.value)
    with pytest.raises(UsageError, match="no such directory"):
        img.save(tmp_path / "missing" / "x.png")


@pytest.mark.parametrize("argv, message", [
    (["sample", "{scene}", "-r", "0.001", "-o", "{tmp}/x.png"], "-o {tmp}/x.png: unknown sample format ('.png'); use .ply or .npz"),
    (["sample", "{scene}", "-r", "0.001", "-o", "{tmp}/x"], "unknown sample format (no extension)"),
    (["sample", "{scene}", "-r", "0.001", "-o", "{tmp}/x.ply", "--stats", "{tmp}/s.txt"], "--stats {tmp}/s.txt: unknown statistics format"),
    (["render", "{scene}", "-r", "0.001", "-o", "{tmp}/x.bmp"], "unknown image format ('.bmp'); use .png, .jpg, .jpeg, .webp, .tif or .tiff"),
    (["render", "{scene}", "-r", "0.001", "-o", "{tmp}/x.png", "--depth", "{tmp}/d.txt"], "--depth {tmp}/d.txt: unknown depth format"),
    (["render", "{scene}", "-r", "0.001", "-o", "{tmp}/nodir/x.png"], "cannot write there: no such directory"),
])
def test_unknown_output_formats_fail_before_any_work(tmp_path, capsys, monkeypatch, argv, message):
    """A tiny radius on the Menger sponge would sample for minutes: the error comes first (no
    scene is compiled or sampled: those steps fail the test if they start)."""
    from clcsg.pipeline import Pipeline

    def forbidden(*a, **k):
        raise AssertionError("work started before the output paths were checked")

    for name in ("tape", "samples", "image"):
        monkeypatch.setattr(Pipeline, name, property(forbidden) if name == "tape" else forbidden)
    scene = os.path.join(ROOT, "examples", "menger3.csg")
    fill = {"scene": scene, "tmp": str(tmp_path)}
    rc = cli.main([a.format(**fill) for a in argv])
    err = capsys.readouterr().err
    assert rc == 2, (rc, err)
    assert err.count("\n") == 1 and err.startswith("clcsg: error: ") and message.format(**fill) in err, err


def test_unknown_output_format_from_the_shell(tmp_path):
    r = subprocess.run([sys.executable, "-m", "clcsg", "sample", os.path.join(ROOT, "examples", "menger3.csg"),
                        "-r", "0.0001", "-o", str(tmp_path / "x.png")], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.count("\n") == 1 and "unknown sample format ('.png')" in r.stderr


def test_background_colors_and_transparency(tmp_path, scene_file, capsys):
    from clcsg.cli.render import parse_background

    assert parse_background("1,1,1") == (1.0, 1.0, 1.0, 1.0)
    assert parse_background("255,255,229") == pytest.approx((1.0, 1.0, 229 / 255, 1.0))
    assert parse_background("#ffffe5") == pytest.approx((1.0, 1.0, 229 / 255, 1.0))
    assert parse_background("navy") == pytest.approx((0, 0, 128 / 255, 1.0))
    assert parse_background("0 0 0 0") == (0.0, 0.0, 0.0, 0.0)
    for bad in ("0,0", "0,0,-1", "bleu", "#12"):
        with pytest.raises(UsageError, match="^--background: "):
            parse_background(bad)
    with pytest.warns(UserWarning, match="JPEG has no alpha"):
        assert cli.main(["render", str(scene_file), "-o", str(tmp_path / "t.jpg"), "--method", "raytrace",
                         "--size", "16x12", "--transparent"]) == 0


# -- PLY --------------------------------------------------------------------------------------------
def test_ply_reads_back_with_plyfile_bit_for_bit(part_samples, tmp_path):
    plyfile = pytest.importorskip("plyfile", reason="plyfile is in the [test] extra")
    s = part_samples
    path = tmp_path / "s.ply"
    clcsg.write_samples(s, path)
    v = plyfile.PlyData.read(str(path))["vertex"].data
    assert len(v) == len(s) > 500
    for k, name in enumerate("xyz"):
        assert v[name].dtype == np.dtype("<f8") and np.array_equal(v[name], s.positions[:, k])
        assert np.array_equal(v["n" + name], s.normals[:, k])
    rgb = np.round(255 * np.clip(s.colors[:, :3], 0, 1)).astype(np.uint8)
    assert np.array_equal(np.column_stack([v["red"], v["green"], v["blue"]]), rgb)
    assert {tuple(c) for c in rgb} >= {(230, 128, 26), (204, 204, 204)}  # the orange box, the grey sphere
    assert np.array_equal(v["quadric"], s.quadrics) and np.array_equal(v["primitive"], s.primitives)
    assert np.array_equal(v["radius"], s.radii)
    clcsg.write_samples(s, tmp_path / "f.ply", float32=True)
    v32 = plyfile.PlyData.read(str(tmp_path / "f.ply"))["vertex"].data
    assert v32["x"].dtype == np.dtype("<f4") and np.array_equal(v32["x"], s.positions[:, 0].astype(np.float32))


# -- NPZ --------------------------------------------------------------------------------------------
def test_saved_samples_round_trip_and_render_the_same_image(part_samples, tmp_path, cl_context):
    s = part_samples
    path = tmp_path / "s.npz"
    clcsg.write_samples(s, path)
    t = load_samples(path)
    for name in ("positions", "normals", "radii", "quadrics", "signs", "primitives", "clip_first", "clip_count",
                 "clip_ops"):
        a, b = getattr(s, name), getattr(t, name)
        assert a.dtype == b.dtype and np.array_equal(a, b), name
    assert t.radius == s.radius and t.stats["samples"] == len(s)
    a, b = s.tape, t.tape
    assert np.array_equal(a.ops, b.ops) and a.n_regs == b.n_regs and np.array_equal(a.quadrics, b.quadrics)
    assert np.array_equal(a.bound, b.bound) and a.shape == b.shape and a.stats == b.stats and a.empty == b.empty
    assert a.owners() == b.owners()
    for x, y in zip(a.instances, b.instances, strict=True):
        assert y.node is None and x.literals == y.literals and tuple(x.color) == y.color
        assert np.array_equal(x.matrix, y.matrix)
    for field in ("quadrics", "tape", "prims", "prim_literals", "owners", "owner_list", "origin"):
        assert np.array_equal(getattr(s.packed, field), getattr(t.packed, field)), field
    cam = clcsg.Camera.fit(s, 64, 48)
    one, two = clcsg.render(s, cam, device=cl_context), clcsg.render(t, cam, device=cl_context)
    assert one.mask.sum() > 500
    assert np.array_equal(one.rgba, two.rgba) and np.array_equal(one.ids, two.ids)
    assert np.array_equal(one.depth, two.depth)
    # the command line renders the saved samples as they are (in its default view: the silhouette)
    png = tmp_path / "again.png"
    assert cli.main(["render", str(path), "-o", str(png), "--size", "64x48", "--quiet"]) == 0
    view = clcsg.render(s, clcsg.Camera.fit_silhouette(s.tape, 64, 48, device=cl_context), device=cl_context)
    assert np.array_equal(np.asarray(PILImage.open(png)), view.rgba)


def test_saved_samples_of_unbounded_primitives_load(cl_context, tmp_path):
    """Half-spaces and infinite cylinders have instance boxes with infinite sides: the file
    keeps them and loads (it was refused as a bad box), and renders the same image."""
    gear = os.path.join(ROOT, "examples", "zoo", "gear.json")
    s = clcsg.sample(gear, 0.05, device=cl_context, progress=False)
    boxes = [i.box for i in s.tape.instances if i.box is not None]
    assert any(not np.isfinite(np.asarray(b)).all() for b in boxes)
    path = tmp_path / "gear.npz"
    clcsg.write_samples(s, path)
    t = load_samples(path)
    for x, y in zip(s.tape.instances, t.tape.instances, strict=True):
        assert (x.box is None) == (y.box is None)
        if x.box is not None:
            assert np.array_equal(x.box[0], y.box[0]) and np.array_equal(x.box[1], y.box[1])
    cam = clcsg.Camera.fit(s, 64, 48)
    one, two = clcsg.render(s, cam, device=cl_context), clcsg.render(t, cam, device=cl_context)
    assert one.mask.sum() > 500 and np.array_equal(one.rgba, two.rgba) and np.array_equal(one.depth, two.depth)


def test_saved_samples_keep_the_colour_rule(cl_context, tmp_path):
    """The instance program is saved with the samples: a flush inlay loaded from ``.npz``
    still shows its own colour (the first boundary that holds a point would show the plate's),
    pixel for pixel as before saving; a file without one still loads."""
    plate = clcsg.box((4, 4, 1), color=(0.6, 0.6, 0.6))
    inlay = (plate - clcsg.box((2, 1.5, 1), center=(0.5, 0, 0.3))) | clcsg.box((2, 1.5, 0.6), center=(0.5, 0, 0.2),
                                                                             color=(1, 0, 0))
    s = clcsg.sample(inlay, 0.1, device=cl_context, progress=False)
    path = tmp_path / "inlay.npz"
    clcsg.write_samples(s, path)
    t = load_samples(path)
    (ops, regs), (ops2, regs2) = s.tape.instance_program, t.tape.instance_program
    assert np.array_equal(ops, ops2) and regs == regs2 and t.packed.instance_rows == s.packed.instance_rows > 0
    cam = clcsg.Camera.look_at((0.5, 0, 8), (0.5, 0, 0), up=(0, 1, 0), fov=10, width=32, height=24)
    one, two = clcsg.render(s, cam, device=cl_context), clcsg.render(t, cam, device=cl_context)
    assert one.mask.all() and np.all(one.primitives == 2)
    assert np.array_equal(one.rgba, two.rgba) and np.array_equal(one.primitives, two.primitives)
    with np.load(path) as z:
        old = {k: z[k] for k in z.files if k not in ("instance_ops", "instance_n_regs")}
    np.savez(tmp_path / "old.npz", **old)
    assert load_samples(tmp_path / "old.npz").tape.instance_program is None


def test_cli_sample_writes_npz_and_refuses_what_saved_samples_cannot_do(scene_file, tmp_path, capsys):
    out = tmp_path / "s.npz"
    assert cli.main(["sample", str(scene_file), "-r", "0.2", "-o", str(out)]) == 0
    assert "samples on" in capsys.readouterr().out
    assert len(load_samples(out)) > 100
    for argv, message in ((["--method", "raytrace"], "--method raytrace needs a scene file"),
                          (["-r", "0.1"], "--radius does not apply to saved samples")):
        assert cli.main(["render", str(out), "-o", str(tmp_path / "x.png")] + argv) == 2
        assert message in capsys.readouterr().err
    ply = tmp_path / "s.ply"
    assert cli.main(["sample", str(scene_file), "-r", "0.2", "-o", str(ply), "-q"]) == 0
    assert cli.main(["render", str(ply), "-o", str(tmp_path / "x.png")]) == 2
    assert "has no CSG tape" in capsys.readouterr().err
    bogus = tmp_path / "bogus.npz"
    np.savez(bogus, positions=np.zeros((3, 3)))
    with pytest.raises(SceneError, match="not a clcsg sample file"):
        load_samples(bogus)
    with pytest.raises(SceneError, match="no such file"):
        load_samples(tmp_path / "nope.npz")


# -- other libraries --------------------------------------------------------------------------------
def test_to_trimesh(part_samples):
    trimesh = pytest.importorskip("trimesh", reason="trimesh is in the [test] extra")
    s = part_samples
    pc = clcsg.to_trimesh(s)
    assert isinstance(pc, trimesh.PointCloud)
    assert np.array_equal(pc.vertices, s.positions)
    assert np.array_equal(pc.colors, np.round(255 * np.clip(s.colors, 0, 1)).astype(np.uint8))
    assert np.array_equal(pc.metadata["normals"], s.normals) and np.array_equal(pc.metadata["quadrics"], s.quadrics)


def test_to_open3d(part_samples):
    o3d = require_module("open3d", "pip install open3d-cpu, 105 MB; .ci/run installs it")
    s = part_samples
    pc = clcsg.to_open3d(s)
    assert isinstance(pc, o3d.geometry.PointCloud)
    assert np.array_equal(np.asarray(pc.points), s.positions)
    assert np.array_equal(np.asarray(pc.normals), s.normals)
    assert np.allclose(np.asarray(pc.colors), s.colors[:, :3])


def test_missing_library_names_the_pip_package(part_samples, monkeypatch):
    monkeypatch.setitem(sys.modules, "open3d", None)  # makes `import open3d` fail
    with pytest.raises(ImportError, match=r"pip install open3d"):
        clcsg.to_open3d(part_samples)
