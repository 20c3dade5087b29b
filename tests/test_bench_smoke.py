"""Smoke tests of the benchmark harness (bench/): small pieces of every part on tiny inputs, no
timing thresholds, about half a minute in all."""

from __future__ import annotations

import ast
import json
import math
import os
import sys
import warnings

import numpy as np
import pytest

import clcsg

# bench/ is not part of the installed package: import it from the repository root
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

from bench import common, micro, models, peers, startup, zoo  # noqa: E402


@pytest.fixture(autouse=True)
def _quiet():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yield


@pytest.mark.parametrize("model", zoo.MODELS, ids=lambda m: m.name)
def test_zoo_has_the_paper_complexity(model):
    assert clcsg.Scene(model.build()).normalize().n_quadrics == model.quadrics
    assert model.name in zoo.PAPER_TABLE2


def test_zoo_files_match_the_generator():
    for m in zoo.MODELS:
        path = os.path.join(zoo.ZOO_DIR, f"{m.name}.json")
        assert clcsg.load(path).normalize().n_quadrics == m.quadrics


def test_example_parts_exist():
    for name in zoo.EVERYDAY + (zoo.SPONGE,):
        assert os.path.exists(zoo.example_path(name, "csg")), name
        assert os.path.exists(zoo.example_path(name, "scad")), name


def test_no_import_cycles_between_bench_modules():
    """common and zoo import no other bench module; the parts import only common and zoo."""
    bench_dir = os.path.join(ROOT, "bench")
    imports = {}
    for f in os.listdir(bench_dir):
        if not f.endswith(".py"):
            continue
        tree = ast.parse(open(os.path.join(bench_dir, f), encoding="utf-8").read())
        mods = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.level == 1:
                mods.update([node.module] if node.module else [a.name for a in node.names])
        imports[f[:-3]] = mods
    assert imports["common"] == set() and imports["zoo"] == set()
    for name, mods in imports.items():
        if name != "__main__":
            assert mods <= {"common", "zoo"}, (name, mods)


def test_startup_measures_the_three_commands(cl_context):
    """One round of the start-up part: each command ran (CPU and wall times), the ratios are
    against the bare start, and the sampling command imports modules the bare start does not."""
    result = startup.measure(1)
    rows = {r["command"]: r for r in result["rows"]}
    assert set(rows) == {"bare", "version", "two cubes"}
    for r in rows.values():
        assert r["cpu_s"]["min"] > 0 and r["wall_s"]["min"] >= r["cpu_s"]["min"] / 4
    for name in ("version", "two cubes"):
        assert rows[name]["cpu_ratio"] == pytest.approx(rows[name]["cpu_s"]["min"] / rows["bare"]["cpu_s"]["min"])
    imports = result["extra_imports"]
    assert imports["modules"] > 0 and any(k.startswith("clcsg.") for k in imports["by_package_ms"])
    assert "| two cubes |" in startup.table(result)


def test_micro_kernels_run(cl_context):
    """Every Table 1 micro kernel builds and returns finite sums (a tiny launch, not a measurement)."""
    real = cl_context.real_dtype
    for dependent in (False, True):
        r = micro.Runner(cl_context, real, dependent)
        for _, kernel in [("baseline", "baseline")] + micro.OPS:
            r.launch(kernel, 128)
            assert np.isfinite(r.checksum[kernel]), kernel


def test_tape_query_benchmark(cl_context):
    """The tape distance query (bench/kernels/query.cl) on a zoo model's tape, both shapes: numbers
    exist, leaf distances per query > 0 on the root tape, pruning never adds leaves."""
    rows = micro.measure_queries(cl_context, 1, models=("drilled_die",), limit=128, min_launch=0.0)
    shapes = {(r["normal_form"], r["tape"]) for r in rows}
    assert shapes == {(nf, t) for nf in ("tree", "dnf") for t in ("root tape", "pruned over 2r")}
    for r in rows:
        assert r["queries"] > 0 and r["points"] > 0
        assert math.isfinite(r["ns_per_query_per_core"]) and r["ns_per_query_per_cu"] > 0
        assert r["checksum_finite"]
    for nf in ("tree", "dnf"):
        root = next(r for r in rows if r["normal_form"] == nf and r["tape"] == "root tape")
        pruned = next(r for r in rows if r["normal_form"] == nf and r["tape"] != "root tape")
        # a point on one of the die's 5 quadrics evaluates the other 4 on the root tape
        assert 0 < root["leaf_distances_per_query"] <= root["leaves"]
        assert pruned["leaf_distances_per_query"] <= root["leaf_distances_per_query"]
        assert pruned["tape_rows_mean"] <= root["instructions"]


def test_models_rows_have_both_shapes(cl_context):
    """A models row set (lens, large size only): tree and DNF side by side with the sampler's
    statistics and the ratio to the paper."""
    m = zoo.model("lens")
    scene = clcsg.Scene(m.build(), source=m.name)
    info, rows = models.shape_rows(cl_context, scene, m.name, "zoo", {"large": zoo.SIZES["large"]}, 1, 0.0,
                                   paper=lambda size: zoo.paper_row(m.name, size))
    assert [r["normal_form"] for r in rows] == ["tree", "dnf"]
    assert info["tree"]["instructions"] > 0 and info["dnf"]["instructions"] > 0
    for r in rows:
        assert not r.get("skipped")
        assert r["samples"] > 0 and r["sampling_s"] > 0 and r["distance_queries"] > 0
        assert r["leaf_distances_per_query"] > 0
        assert r["prune_evaluations"] > 0
        assert r["tape_mean"]["mean"] > 0 and r["tape_max"]["max"] >= r["tape_mean"]["mean"]
        assert r["unresolved"] >= 0 and r["levels"] > 0
        assert r["ratio_to_paper"] == pytest.approx(r["sampling_s"] * cl_context.info.compute_units / 1.51e-3)
    # the same solid: the same samples
    assert rows[0]["samples"] == rows[1]["samples"]
    text = models.table({"environment": {"device": "d", "compute_units": 2}, "rows": rows,
                         "targets": models.targets(rows, 2)})
    assert "| lens | large |" in text
    json.dumps(rows, default=common._json_default)


def test_models_times_the_zoo_on_one_pocl_thread(cl_context):
    """The one-thread pass runs in a child process (PoCL reads its thread count when it loads;
    another device ignores it) and gives each model's least CPU time and its ratio to the
    paper's single core."""
    one = models.one_thread(None, 1, 0.0, names=["lens"])
    assert set(one) == {"lens"}, one
    lens = one["lens"]
    assert lens["runs"] == 1 and lens["cpu_s"] > 0
    assert lens["cpu_ratio_to_paper"] == pytest.approx(lens["cpu_s"] / (1e-3 * zoo.paper_row("lens", "medium")["sampling_ms"]))
    assert lens["cpu_p10_s"] == lens["cpu_s"]  # one call: its own 10th percentile
    assert lens["cpu_p10_ratio_to_paper"] == pytest.approx(lens["cpu_ratio_to_paper"])


def test_timing_gives_the_least_and_the_tenth_percentile_cpu_time(cl_context):
    """Of twenty calls, the least CPU time and the third least (the 10th percentile), in order."""
    m = next(m for m in zoo.MODELS if m.name == "lens")
    scene = clcsg.Scene(m.build(), source=m.name)
    ts = common.time_sampling(scene, 0.1, cl_context, repeats=20, budget=60.0)
    assert ts["runs"] == 20
    assert 0 < ts["cpu_s"] <= ts["cpu_p10_s"]


def test_models_records_the_dnf_limit(cl_context):
    """A part whose DNF passes the term limit gets a tree row and a 'dnf: term limit' row."""
    scene = clcsg.load(zoo.example_path("rook", "csg"))
    info, rows = models.shape_rows(cl_context, scene, "rook", "openscad part", {"r": 0.05}, 1, 0.0)
    tree, dnf = rows
    assert tree["normal_form"] == "tree" and tree["samples"] > 0 and tree["leaf_distances_per_query"] > 0
    assert dnf["skipped"] == "dnf: term limit" and info["dnf_skipped"] == "dnf: term limit"


def test_manifold_translation_matches_the_quadrics():
    """The manifold3d version of a zoo model lies near its quadrics (coarse tessellation)."""
    manifold3d = pytest.importorskip("manifold3d", reason="manifold3d (the peer benchmark) is in the [test] and [bench] extras")

    shape = zoo.flange()
    tape = clcsg.Scene(shape).compile("tree")
    diag = common.diagonal(tape.bound)
    mesh = peers.Translator(manifold3d, 32, tape.bound).build(shape).to_mesh()
    pts, _ = peers.sample_mesh(mesh, 2000, np.random.default_rng(0))
    err = peers.surface_error(tape, pts)
    assert err.max() < 0.02 * diag
    # and the mesh's bound is the scene's
    assert np.allclose(pts.min(0), tape.bound[0], atol=0.02 * diag)
    assert np.allclose(pts.max(0), tape.bound[1], atol=0.02 * diag)


def test_manifold_builds_the_sponge_exactly():
    """The Menger sponge (boxes only) translates to manifold3d with no tessellation error."""
    manifold3d = pytest.importorskip("manifold3d", reason="manifold3d (the peer benchmark) is in the [test] and [bench] extras")
    scene = clcsg.load(zoo.example_path(zoo.SPONGE, "csg"))
    tape = scene.compile("tree")
    mesh = peers.Translator(manifold3d, 16, tape.bound).build(scene.shape).to_mesh()
    pts, ntri = peers.sample_mesh(mesh, 2000, np.random.default_rng(0))
    assert ntri > 1000
    assert peers.surface_error(tape, pts).max() < 1e-6 * common.diagonal(tape.bound)


def test_render_row_pieces(cl_context):
    """The render part's pieces on a tiny image: the tree ray tracer reports its tile pruning,
    the splats an overdraw."""
    from bench import render

    tape = clcsg.Scene(zoo.lens()).compile("tree")
    cam = common.fit_camera(tape.bound, 64, 36, zoo.model("lens").direction)
    t, st = render.time_render(clcsg.raytrace, tape, cam, cl_context, 1)
    rec = render.raytrace_record(t, st)
    assert rec["seconds"] > 0 and rec["tile_tape_mean"] > 0 and rec["prune_s"] >= 0
    assert rec["covered_pixels"] > 0


def test_render_many_leaves(cl_context):
    """The many-leaf part on a tiny image: hundreds of leaves per tile on the plate, the same
    image with and without the ray tracer's acceleration."""
    from bench import render

    rows = render.many_leaves(cl_context, 64, 36, 1, quick=True)
    assert [r["scene"] for r in rows] == ["plate_256_holes_oblique", "sphere_column_inside"]
    assert rows[0]["after"]["tile_leaves_max"] >= 200
    for r in rows:
        assert r["same_image"] and r["after"]["covered_pixels"] > 0 and r["after"]["cpu_seconds"] > 0


def test_csg_surface_error_sees_a_quadric_extension():
    """The mesh benchmark's distance to the CSG surface: a point on the plane of a box's top
    face but beside the box is 0 from that quadric and 0.5 from the solid; a point above the
    face is 0.3 from both.  The bound is from above, within the growth step and the probes'
    spacing."""
    from bench.common import CSG_ERROR_STEP, csg_surface_error, surface_error

    tape = clcsg.Scene(clcsg.box(2.0)).compile()
    x = np.array([[1.5, 0.0, 1.0], [0.0, 0.0, 1.3]])
    assert surface_error(tape, x)[0] < 1e-12
    d = csg_surface_error(tape, x, 1e-3)
    assert 0.5 <= d[0] <= 0.5 * CSG_ERROR_STEP ** 2
    assert 0.3 <= d[1] <= 0.3 * CSG_ERROR_STEP ** 2
