"""The model zoo: six CSG solids with the complexity of the paper's Table 2 rows (3, 5, 5, 21,
31 and 80 unique quadrics after normalization), built with the Python API.

``python -m bench.zoo`` (re)writes ``examples/zoo/<name>.json`` and checks each model's
unique quadric count (``clcsg.Scene(shape).normalize().n_quadrics``).  The benchmarks build
the shapes from these functions directly; the JSON files are the same scenes for
``clcsg info`` / ``clcsg render``.  This module also holds what several benchmarks share about
the models: the paper's Table 2 rows (``PAPER_TABLE2``), the splat sizes (``SIZES``) and the
everyday OpenSCAD parts and the Menger sponge of ``examples/`` (``EVERYDAY``, ``SPONGE``).

Only primitives that manifold3d can tessellate are used (boxes, slabs, half-spaces, finite
and infinite cylinders, cone frusta, spheres, ellipsoids), so ``bench/peers.py`` can build the
same solids from triangle meshes.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Callable

import clcsg
from clcsg.model.csg import Difference
from clcsg.model.solids import _make

ZOO_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "examples", "zoo")

# a small palette (display RGB)
STEEL = (0.62, 0.66, 0.72)
STEEL_DARK = (0.45, 0.5, 0.58)
BRASS = (0.85, 0.68, 0.32)
COPPER = (0.82, 0.45, 0.3)
RED = (0.8, 0.25, 0.22)
ORANGE = (0.93, 0.55, 0.2)
TEAL = (0.2, 0.6, 0.62)
BLUE = (0.3, 0.45, 0.75)
GREEN = (0.45, 0.68, 0.35)
IVORY = (0.92, 0.88, 0.78)
PLUM = (0.6, 0.35, 0.6)


def icyl(axis, radius, center=(0, 0, 0), color=None):
    """An infinite circular cylinder (one quadric)."""
    return _make("infinite_cylinder", color, axis=axis, radius=radius, center=center)


# -- the six models ---------------------------------------------------------------------------------


def lens():
    """3 quadrics: a biconvex lens (two spheres) cut to a cylinder whose axis lies in the lens
    plane: an organic intersection with two sharp curved edges and four tips."""
    a = clcsg.sphere(1.0, center=(0, 0, -0.62), color=TEAL)
    b = clcsg.sphere(1.0, center=(0, 0, 0.62), color=BLUE)
    c = icyl((1, 0, 0), 0.55, color=IVORY)
    return a & b & c


def drilled_die():
    """5 quadrics: a die rounded by a sphere (three slabs, one quadric each, and the sphere)
    with a bore along its space diagonal."""
    cube = clcsg.intersection(*(clcsg.slab(n, -0.5, 0.5, color=STEEL) for n in ((1, 0, 0), (0, 1, 0), (0, 0, 1))))
    rounded = cube & clcsg.sphere(0.68, color=BRASS)
    return rounded - icyl((1, 1, 1), 0.2, color=RED)


def steinmetz():
    """5 quadrics: the tricylinder (three orthogonal cylinders) with its twelve sharp edges,
    trimmed by a sphere and hollowed by a spherical dimple at one corner."""
    tri = clcsg.intersection(icyl((1, 0, 0), 1.0, color=ORANGE), icyl((0, 1, 0), 1.0, color=COPPER),
                             icyl((0, 0, 1), 1.0, color=BRASS))
    return (tri & clcsg.sphere(1.2, color=IVORY)) - clcsg.sphere(0.55, center=(0.75, -0.75, 0.75), color=RED)


def flange():
    """21 quadrics: a pipe flange: disc, hub, cone-frustum fillet between them, bore with a
    conical chamfer, six bolt holes, two set-screw holes through the hub and a flat for one.""" 
    disc = clcsg.cylinder(0.25, 1.0, center=(0, 0, 0.125), color=STEEL)
    hub = clcsg.cylinder(0.55, 0.42, center=(0, 0, 0.225 + 0.275), color=STEEL)  # z in [0.225, 0.775]
    fillet = clcsg.cone(0.2, 0.62, 0.40, center=(0, 0, 0.25 + 0.1), color=STEEL_DARK)  # z in [0.25, 0.45]
    body = disc | hub | fillet
    bore = icyl((0, 0, 1), 0.25, color=RED)
    chamfer = clcsg.cone(0.2, 0.22, 0.34, center=(0, 0, 0.775 - 0.1 + 0.02), color=ORANGE)
    holes = [icyl((0, 0, 1), 0.08, center=(0.75 * math.cos(a), 0.75 * math.sin(a), 0), color=BRASS)
             for a in (2 * math.pi * k / 6 + math.pi / 6 for k in range(6))]
    screws = [icyl((1, 0, 0), 0.06, center=(0, 0, 0.6), color=COPPER),
              icyl((0, 1, 0), 0.06, center=(0, 0, 0.6), color=COPPER)]
    # a flat on the hub for the set screw along x, above the fillet (z >= its top cap)
    flat = clcsg.intersection(clcsg.halfspace((-1, 0, 0), -0.36, color=STEEL_DARK),
                              clcsg.halfspace((0, 0, -1), -0.45, color=STEEL_DARK))
    return clcsg.difference(body, bore, chamfer, flat, *holes, *screws)


def bracket():
    """31 quadrics: an L bracket: base plate and upright with rounded outer corners (cylinders),
    a concave fillet (a box strip minus a cylinder), two thin triangular ribs (half-spaces),
    four holes in the base and a slot (two cylinders and a box) in the upright."""
    t = 0.12  # plate thickness
    base = clcsg.box((1.6, 1.0, t), center=(0, 0, t / 2), color=STEEL)
    # round the two front corners of the base: corner box minus... keep the plate and add
    # quarter discs: base = (base minus corner squares) | corner cylinders
    r = 0.18
    corners = [clcsg.box((r, r, t), center=(sx * (0.8 - r / 2), -0.5 + r / 2, t / 2)) for sx in (-1, 1)]
    rounds = [clcsg.cylinder(t, r, center=(sx * (0.8 - r), -0.5 + r, t / 2), color=STEEL) for sx in (-1, 1)]
    base = clcsg.difference(base, *corners) | clcsg.union(*rounds)
    upright = clcsg.box((1.6, t, 1.0), center=(0, 0.5 - t / 2, 0.5), color=STEEL)
    fr = 0.14
    fillet = clcsg.box((1.6, fr, fr), center=(0, 0.5 - t - fr / 2, t + fr / 2), color=STEEL_DARK) - \
        icyl((1, 0, 0), fr, center=(0, 0.5 - t - fr, t + fr), color=STEEL_DARK)
    ribs = []
    y_in, y0 = 0.5 - t, 0.5 - t - 0.6  # the upright's inner face; where the ribs meet the base
    for x in (-0.66, 0.66):
        ribs.append(clcsg.intersection(
            clcsg.slab((1, 0, 0), x - 0.025, x + 0.025, color=BLUE),  # a thin feature: 0.05 wide
            clcsg.halfspace((0, 0, -1), -t, color=BLUE),  # z >= t (the base's top face)
            clcsg.halfspace((0, 1, 0), y_in, color=BLUE),  # y <= the upright's inner face
            clcsg.halfspace((0, -1, 1), t - y0, color=BLUE)))  # the slanted edge, 45 degrees
    body = clcsg.union(base, upright, fillet, *ribs)
    holes = [icyl((0, 0, 1), 0.06, center=(x, y, 0), color=RED) for x in (-0.4, 0.4) for y in (-0.3, 0.05)]
    slot = clcsg.union(icyl((0, 1, 0), 0.08, center=(-0.25, 0, 0.6), color=ORANGE),
                       icyl((0, 1, 0), 0.08, center=(0.25, 0, 0.6), color=ORANGE),
                       clcsg.box((0.5, 1.0, 0.16), center=(0, 0.5, 0.6), color=ORANGE))
    return clcsg.difference(body, *holes, slot)


def gear():
    """80 quadrics: a spur gear: 24 tapered teeth (two flank planes each, bounded inwards by a
    plane through the axis), trimmed by the tip cylinder and two chamfer cones, on a rim with a
    hub, a bore with a keyway and six lightening holes."""
    n, h = 24, 0.3
    r_tip, r_root = 1.0, 0.86
    caps = [clcsg.halfspace((0, 0, 1), h / 2, color=STEEL), clcsg.halfspace((0, 0, -1), h / 2, color=STEEL)]
    rim = clcsg.intersection(icyl((0, 0, 1), r_root, color=STEEL), *caps)
    hub = clcsg.cylinder(0.5, 0.3, color=STEEL_DARK)
    half = math.pi / n / 2  # half the tooth's angular width at the root circle
    taper = 0.3  # flank tilt (radians) from the radial direction
    teeth = []
    for k in range(n):
        a = 2 * math.pi * k / n
        flanks = []
        for sign in (1, -1):
            ang = a + sign * half
            px, py = r_root * math.cos(ang), r_root * math.sin(ang)
            na = ang + sign * (math.pi / 2 - taper)  # outward normal of this flank
            nx, ny = math.cos(na), math.sin(na)
            flanks.append(clcsg.halfspace((nx, ny, 0), nx * px + ny * py, color=BRASS))
        # the flanks diverge inwards: bound the tooth by the plane through the axis (tooth k and
        # tooth k + 12 share it)
        side = clcsg.halfspace((-math.cos(a), -math.sin(a), 0), 0.0, color=BRASS)
        teeth.append(clcsg.intersection(*flanks, side, *caps))
    body = clcsg.union(rim, hub, *teeth)
    # 45 degree chamfers at the tips: radius r_tip - 0.03 at the faces
    slope, r_face = 1.0, r_tip - 0.03
    up = clcsg.cone(0.6, r_face + slope * (0.3 + h / 2), r_face - slope * (0.3 - h / 2), color=COPPER)
    down = clcsg.cone(0.6, r_face - slope * (0.3 - h / 2), r_face + slope * (0.3 + h / 2), color=COPPER)
    body = clcsg.intersection(body, icyl((0, 0, 1), r_tip, color=BRASS), up, down)
    bore = icyl((0, 0, 1), 0.12, color=RED)
    key = clcsg.intersection(clcsg.slab((1, 0, 0), -0.04, 0.04, color=RED),
                             clcsg.halfspace((0, -1, 0), 0.0, color=RED),  # y >= 0
                             clcsg.halfspace((0, 1, 0), 0.18, color=RED))
    holes = [icyl((0, 0, 1), 0.12, center=(0.55 * math.cos(a), 0.55 * math.sin(a), 0), color=TEAL)
             for a in (2 * math.pi * (k + 0.5) / 6 for k in range(6))]
    return clcsg.difference(body, bore, key, *holes)


@dataclass(frozen=True)
class Model:
    name: str
    build: Callable
    quadrics: int  # the paper's Table 2 row
    direction: tuple  # view direction (target -> eye) for the gallery and the benchmarks
    description: str


MODELS = [
    Model("lens", lens, 3, (0.8, -1.0, 0.55), "biconvex lens cut by a cylinder"),
    Model("drilled_die", drilled_die, 5, (1.0, 0.45, 0.75), "die rounded by a sphere, drilled along its diagonal"),
    Model("steinmetz", steinmetz, 5, (1.0, -0.9, 0.75), "tricylinder trimmed by a sphere, with a dimple"),
    Model("flange", flange, 21, (0.6, -1.0, 0.9), "pipe flange with hub, fillet, chamfer, bolt and set-screw holes"),
    Model("bracket", bracket, 31, (-0.9, -1.0, 0.8), "L bracket with fillet, ribs, holes and a slot"),
    Model("gear", gear, 80, (0.5, -0.9, 1.1), "spur gear with 24 teeth, keyway and lightening holes"),
]


#: paper Table 2 (Trettner & Kobbelt 2021), one row per zoo model (same order, same quadric
#: count): size -> (samples, distance queries, clip indices, sampling ms on one 4.8 GHz core,
#: render ms on an RTX 2080 Ti), and the ray tracing ms (one per model)
PAPER_TABLE2 = {
    "lens": ({"large": (5454, 22372, 2, 1.51, 0.34), "medium": (23452, 47336, 2, 3.39, 0.23),
              "small": (249014, 100398, 2, 8.51, 0.27)}, 0.36),
    "drilled_die": ({"large": (8112, 103296, 52, 7.63, 0.27), "medium": (35904, 215040, 23, 16.45, 0.18),
                     "small": (329856, 576048, 17, 66.87, 0.26)}, 1.14),
    "steinmetz": ({"large": (9465, 52578, 52, 4.38, 0.31), "medium": (27882, 103908, 31, 8.71, 0.28),
                   "small": (205075, 254592, 25, 23.47, 0.26)}, 0.87),
    "flange": ({"large": (7134, 30802, 78, 6.26, 0.45), "medium": (31940, 85744, 37, 18.01, 0.39),
                "small": (104972, 171958, 31, 37.91, 0.33)}, 0.72),
    "bracket": ({"large": (28432, 196298, 51, 36.63, 0.96), "medium": (91895, 325705, 34, 62.23, 0.87),
                 "small": (184533, 415847, 29, 83.36, 0.69)}, 4.43),
    "gear": ({"large": (10176, 194024, 299, 94.47, 0.32), "medium": (141200, 558582, 244, 292.35, 0.34),
              "small": (655727, 1182464, 236, 623.92, 0.47)}, 9.15),
}

#: splat radius = bound diagonal x this (the paper's three sizes, relative to the model)
SIZES = {"large": 1 / 50, "medium": 1 / 150, "small": 1 / 500}

EXAMPLES_DIR = os.path.dirname(ZOO_DIR)
#: everyday OpenSCAD parts in examples/ (NAME.scad and its export NAME.csg)
EVERYDAY = ("pipe_flange", "rook", "project_box", "l_bracket", "plate_12_holes")
#: the level-3 Menger sponge (examples/menger3.csg / .scad)
SPONGE = "menger3"
#: radius of the everyday parts and the sponge, relative to the bound's diagonal
PART_RADIUS = 0.01


def paper_row(name: str, size: str) -> dict:
    """The paper's Table 2 values of zoo model ``name`` at ``size``."""
    sizes, rt = PAPER_TABLE2[name]
    s, q, clip, ms, render_ms = sizes[size]
    return {"samples": s, "distance_queries": q, "clip_indices": clip, "sampling_ms": ms, "render_ms": render_ms,
            "raytrace_ms": rt, "raytrace_over_splat": rt / render_ms}


def example_path(name: str, ext: str = "csg") -> str:
    return os.path.join(EXAMPLES_DIR, f"{name}.{ext}")


def model(name: str) -> Model:
    for m in MODELS:
        if m.name == name:
            return m
    raise KeyError(name)


def n_quadrics(shape) -> int:
    return clcsg.Scene(shape).normalize().n_quadrics


def write_all(directory=ZOO_DIR) -> list[tuple[str, int, int]]:
    os.makedirs(directory, exist_ok=True)
    out = []
    for m in MODELS:
        shape = m.build()
        path = os.path.join(directory, f"{m.name}.json")
        clcsg.save(shape, path)
        out.append((m.name, n_quadrics(shape), m.quadrics))
    return out


if __name__ == "__main__":
    for name, got, want in write_all():
        print(f"{name:12s} {got:3d} unique quadrics (paper row: {want}){'' if got == want else '  MISMATCH'}")


def plate(n: int, size: float = 200.0, thick: float = 5.0):
    """A plate minus an n x n grid of holes, each a cylinder and a cone chamfer at the top."""
    pitch = size / n
    r = 0.3 * pitch
    parts = [clcsg.box((size, size, thick))]
    for i in range(n):
        for j in range(n):
            x, y = -size / 2 + (i + 0.5) * pitch, -size / 2 + (j + 0.5) * pitch
            parts.append(clcsg.cylinder(thick + 2, r, (x, y, 0)))
            parts.append(clcsg.cone(0.6 * r + 0.01, 1.5 * r, r - 0.01, (x, y, thick / 2 - 0.3 * r)))
    return Difference(parts)


def sphere_column(n=220, seed=3):
    """n spheres of radius 0.5 along the z axis (0.35 apart, centers within 0.25 of it) minus a
    bore of radius 0.12 along the axis."""
    import numpy as np

    rng = np.random.default_rng(seed)
    spheres = [clcsg.sphere(0.5, center=(*rng.uniform(-0.25, 0.25, 2), 0.35 * k)) for k in range(n)]
    return clcsg.union(*spheres) - clcsg.cylinder(200, 0.12, center=(0, 0, 40))


def many_leaf_scenes(quick=False):
    """(name, tape, camera at 64x36) of the many-leaf scenes."""
    import numpy as np

    from clcsg.rendering.camera import Camera

    out = []
    for n in (16,) if quick else (16, 50):
        tape = clcsg.Scene(plate(n)).compile()
        c = 0.5 * (tape.bound[0] + tape.bound[1])
        cam = Camera.look_at(c + np.array([0, -160, 40]), c + np.array([0, 20, 0]), fov=60, width=64, height=36)
        out.append((f"plate_{n * n}_holes_oblique", tape, cam))
    tape = clcsg.Scene(sphere_column()).compile()
    out.append(("sphere_column_inside", tape, Camera.look_at((0.3, 0, 10), (0.3, 0.5, 14), fov=70, width=64, height=36)))
    return out
