"""The tree pipeline on scenes the DNF could not take, against the independent tree oracle:
OpenSCAD parts exported with the real openscad (examples/), a level-3 Menger sponge, a chain of
1,000 nested differences, a DAG sharing a sub-graph many times, a tree whose DNF would exceed
10^9 terms, nested differences, coincident faces between many coloured parts, views from
inside, radii far larger than the features, and a perforated plate of thousands of primitives
(a 20 x 20 grid of chamfered holes by default, the 50 x 50 grid of 5,001 primitives with
CLCSG_LARGE=1)."""

from __future__ import annotations

import os
import types
import warnings

import numpy as np
import pytest

import clcsg
from clcsg import Camera, raytrace, render, sample

import tree_oracle as T
from coverage import uncovered

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
W, H = 80, 60


def oracle_ids(shape, s):
    ids = T.quadric_table(shape).match(s.tape.quadrics)
    return types.SimpleNamespace(positions=s.positions, quadrics=ids[s.quadrics])


def check_samples(shape, s, radius, n_lines=8000):
    size = float(np.linalg.norm(s.bound[1] - s.bound[0]))
    Q = s.tape.quadrics[s.quadrics]
    on_q, on_csg = T.sample_residuals(shape, s.positions, Q, tol=1e-9 * size)
    assert on_q.max() <= 1e-6 * size and on_csg.all(), (~on_csg).sum()
    pad = 1e-3 * size
    ref = T.surface_points(shape, s.bound + [[-pad], [pad]], n_lines=n_lines)
    if len(ref) <= 100:  # a small or thin solid: few of the lines meet it, so draw ten times more
        ref = T.surface_points(shape, s.bound + [[-pad], [pad]], n_lines=10 * n_lines)
    assert len(ref) > 100
    missing = uncovered(ref.points, ref.quadrics, oracle_ids(shape, s), radius, slack=1e-5)
    assert len(missing) == 0, f"{len(missing)} of {len(ref)} surface points uncovered, e.g. {ref.points[missing[:3]].tolist()}"


def check_images(img, ref, frac=0.998):
    """Splats against the exact ray tracer: mask, depth, primitive and colour per pixel."""
    agree = (img.mask == ref.mask).mean()
    assert agree >= frac, agree
    both = img.mask & ref.mask
    rd = np.abs(img.depth[both].astype(np.float64) - ref.depth[both]) / ref.depth[both]
    assert rd.max(initial=0) <= 1e-4
    assert (img.primitives[both] == ref.primitives[both]).mean() >= frac
    same = both & (img.primitives == ref.primitives)
    diff = np.abs(img.rgba[same].astype(int) - ref.rgba[same].astype(int)).max(axis=-1)
    assert (diff <= 2).mean() >= frac


def diag_of(tape):
    return float(np.linalg.norm(tape.bound[1] - tape.bound[0]))


@pytest.mark.parametrize("name", ["pipe_flange", "rook", "project_box", "l_bracket", "plate_12_holes"])
def test_everyday_openscad_parts(name, cl_context):
    scene = clcsg.load(os.path.join(ROOT, "examples", f"{name}.csg"))
    tape = scene.compile()
    assert tape.stats["dnf_terms"] > 10**5 or name == "l_bracket"  # past the DNF's term limit
    r = diag_of(tape) / 60
    s = sample(scene, r, device=cl_context)
    # pruned tapes: a distance query evaluates a handful of the tape's leaves (the queries left
    # are the ones near trimming curves, where two or three leaves stay live)
    assert s.stats["leaf_distances_per_query"] <= min(10, tape.stats["leaves"] / 5)
    check_samples(scene.shape, s, r)
    cam = Camera.fit(tape, W, H)
    check_images(render(s, cam, device=cl_context), raytrace(tape, cam, device=cl_context))


def test_menger_sponge_level_3(cl_context):
    scene = clcsg.load(os.path.join(ROOT, "examples", "menger3.csg"))
    tape = scene.compile()
    assert tape.stats["dnf_terms"] > 1e30 and tape.stats["primitives"] == 220
    r = diag_of(tape) / 50
    s = sample(scene, r, device=cl_context)
    check_samples(scene.shape, s, r, n_lines=4000)
    cam = Camera.fit(tape, W, H)
    check_images(render(s, cam, device=cl_context), raytrace(tape, cam, device=cl_context))


def _chain(n):
    """((((box - s1) - s2) - ...) - sn): n nested Difference nodes, as OpenSCAD writes them."""
    shape = clcsg.box((40, 4, 4))
    for i in range(n):
        shape = clcsg.difference(shape, clcsg.sphere(0.3, center=(-19.5 + 39 * i / n, 2.0 * (i % 2) - 1.0, 2.0)))
    return shape


def test_chain_of_1000_nested_differences(cl_context, tmp_path):
    text = "difference() {\n" * 1000 + "cube(size = [40, 4, 4], center = true);\n"
    for i in range(1000):
        x, y = -19.5 + 39 * i / 1000, 2.0 * (i % 2) - 1.0
        text += f"multmatrix([[1, 0, 0, {x!r}], [0, 1, 0, {y}], [0, 0, 1, 2], [0, 0, 0, 1]]) {{ sphere(r = 0.3); }}\n}}\n"
    path = tmp_path / "chain.csg"
    path.write_text(text)
    scene = clcsg.load(path)
    tape = scene.compile()
    assert tape.stats["depth"] >= 1000 and tape.stats["primitives"] == 1001
    s = sample(scene, 0.3, device=cl_context)
    check_samples(_chain(1000), s, 0.3, n_lines=4000)
    cam = Camera.look_at((0, -30, 12), (0, 0, 0), width=W, height=H)
    check_images(render(s, cam, device=cl_context), raytrace(tape, cam, device=cl_context))


def _shared(levels):
    """x_{k+1} = x_k & (x_k | box_k) with binary nodes (the operators would flatten x_k's
    operands into the new node): the tree has 2^levels copies of the sphere, the DAG one."""
    from clcsg.model.csg import Intersection, Union

    x = clcsg.sphere(1.0)
    for k in range(levels):
        x = Intersection((x, Union((x, clcsg.box(0.3, center=(np.cos(k), np.sin(k), 0.9))))))
    return x


def test_dag_sharing_a_subgraph_many_times_gives_a_linear_tape(cl_context):
    n20, n40 = (len(clcsg.Scene(_shared(k)).compile().ops) for k in (20, 40))
    assert n40 <= 2.2 * n20
    x = _shared(40)
    assert clcsg.Scene(x).compile().stats["leaves"] <= 1 + 6 * 40
    s = sample(x, 0.08, device=cl_context)
    check_samples(x, s, 0.08)


def test_nested_differences_four_deep(cl_context):
    shape = clcsg.difference(
        clcsg.box(4), clcsg.difference(clcsg.box(3.4), clcsg.difference(clcsg.sphere(1.65), clcsg.difference(
            clcsg.cylinder(5, 1.2), clcsg.box(0.8)))))
    s = sample(shape, 0.08, device=cl_context)
    check_samples(shape, s, 0.08)


def test_dnf_past_1e9_terms_samples_and_renders(cl_context):
    plate = clcsg.box((60, 40, 4))
    holes = [clcsg.cylinder(6, 1.0, center=(x, y, 0)) | clcsg.cone(1.2, 2.0, 1.0, center=(x, y, 1.41))
             for x in range(-25, 26, 10) for y in (-12, 0, 12)]
    shape = plate - clcsg.union(*holes)
    tape = clcsg.Scene(shape).compile()
    assert tape.stats["dnf_terms"] > 1e9
    with pytest.raises(clcsg.errors.LimitError):
        clcsg.Scene(shape).compile("dnf")
    s = sample(shape, 0.6, device=cl_context)
    check_samples(shape, s, 0.6)
    cam = Camera.fit(tape, W, H)
    check_images(render(s, cam, device=cl_context), raytrace(tape, cam, device=cl_context))


def test_coincident_faces_between_many_coloured_parts(cl_context):
    """A 4 x 4 grid of unit boxes touching face to face, with flush tops and one taller box per
    row, every box in its own colour: internal faces are not surface, every sample and every
    pixel shows the primitive the oracle finds there."""
    parts = []
    rng = np.random.default_rng(5)
    for i in range(4):
        for j in range(4):
            h = 1.5 if j == i else 1.0
            parts.append(clcsg.box((1, 1, h), center=(i, j, h / 2), color=tuple(rng.random(3))))
    shape = clcsg.union(*parts)
    s = sample(shape, 0.08, device=cl_context)
    check_samples(shape, s, 0.08)
    Q = s.tape.quadrics[s.quadrics]
    exact, loose = T.primitive_at(shape, s.positions, Q), T.primitive_at(shape, s.positions, Q, tol=1e-9)
    firm = exact == loose
    assert np.array_equal(s.primitives[firm], exact[firm]) and firm.mean() > 0.9
    tape = s.tape
    for cam in (Camera.fit(tape, W, H), Camera.look_at((1.5, 1.5, 6), (1.5, 1.5, 0), up=(0, 1, 0), width=W, height=H)):
        img, ref = render(s, cam, device=cl_context), raytrace(tape, cam, device=cl_context)
        check_images(img, ref)
        o, d = cam.rays()
        hits = T.cast(shape, o, d)
        ok = ~T.fragile(shape, o, d) & hits.mask & img.mask
        assert (img.primitives[ok] == hits.primitive[ok]).all()
        colors = np.array([p.color for p in tape.instances])
        # a pixel's hue is its primitive's colour (shading only scales it)
        shown = img.rgba[ok][:, :3].astype(float)
        base = colors[img.primitives[ok], :3]
        cos = (shown * base).sum(1) / (np.linalg.norm(shown, axis=1) * np.linalg.norm(base, axis=1) + 1e-12)
        assert np.median(cos) > 0.97


def test_splats_from_inside_multi_part_solids(cl_context):
    parts = (clcsg.box(2, color=(1, 0, 0)) | clcsg.box(2, center=(1.5, 0.5, 0), color=(0, 1, 0))
             | clcsg.sphere(0.9, center=(2.6, 0.5, 0.8), color=(0, 0, 1))) - clcsg.sphere(0.5)
    s = sample(parts, 0.07, device=cl_context)
    for eye, target in [((0.8, 0.2, 0.1), (2.4, 1, 0)), ((1.4, 0.4, -0.2), (-1, -0.6, 0.3))]:
        cam = Camera.look_at(eye, target, fov=75, width=W, height=H)
        img = render(s, cam, device=cl_context)
        assert img.stats["backface_culling"] is False
        check_images(img, raytrace(s.tape, cam, device=cl_context))


@pytest.mark.parametrize("radius", [2.0, 20.0, 1e6])
def test_radius_far_larger_than_the_features_still_covers_them(radius, cl_context):
    part = clcsg.box(2) - clcsg.cylinder(3, 0.5) - clcsg.cylinder(3, 0.5, axis=(1, 0, 0))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        s = sample(part, radius, device=cl_context)
    check_samples(part, s, radius)
    bores = [q for q in range(s.tape.n_quadrics) if np.any(s.tape.quadrics[q][:3, :3])]
    assert len(bores) == 2 and set(bores) <= set(np.unique(s.quadrics).tolist())


def perforated_plate(n, size=200.0, thick=4.0):
    """A size x size x thick plate minus an n x n grid of holes, each a cylinder union a cone
    that chamfers its top edge (2 n^2 + 1 primitives): a vent or speaker grill."""
    pitch = size / n
    rh = 0.25 * pitch
    holes = []
    for i in range(n):
        for j in range(n):
            x, y = -size / 2 + pitch * (i + 0.5), -size / 2 + pitch * (j + 0.5)
            holes.append(clcsg.cylinder(thick + 2, rh, center=(x, y, 0))
                         | clcsg.cone(0.3 * thick, 0.9 * rh, 1.8 * rh, center=(x, y, 0.475 * thick)))
    return clcsg.difference(clcsg.box((size, size, thick)), *holes)


@pytest.mark.parametrize("n", [20] + ([50] if os.environ.get("CLCSG_LARGE") else []))
def test_perforated_plate_of_thousands_of_primitives(n, cl_context):
    """Sampled at 1% of its diagonal; the tape arena holds the tapes of one level's live cells,
    each stored with the rows pruning kept (the rows written at a level are, up to the dead
    rows a forward pass leaves, the tapes of the next level's cells, two cells to a tape).
    Compile and sampling of the 50 x 50 plate take minutes on a loaded 2-core machine: it runs
    with CLCSG_LARGE=1."""
    shape = perforated_plate(n)
    tape = clcsg.Scene(shape).compile()
    assert tape.stats["primitives"] == 2 * n * n + 1
    r = diag_of(tape) / 100
    s = sample(shape, r, device=cl_context)
    st = s.stats
    cells, means, rows = st["cells_per_level"], st["tape_mean_per_level"], st["arena_rows_per_level"]
    for level in range(len(cells) - 1):
        kept = means[level + 1] * cells[level + 1] / 2
        # the root tape's forward pass leaves dead rows (values absorbed later) at level 0
        bound = 1.5 * kept + 16 if level else len(tape.ops) * cells[1] / 2
        assert kept <= rows[level] <= bound, (level, kept, rows[level])
    assert st["arena_rows"] == max(rows)
    check_samples(shape, s, r, n_lines=3000 if n <= 20 else 1500)
