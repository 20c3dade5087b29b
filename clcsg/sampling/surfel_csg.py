"""Sampling a CSG graph with point operands (:class:`~clcsg.model.surfels.Surfels`): which
samples of the quadric operands and which surfels lie on the solid's surface, and the clip
programs that cut their splats exactly.

A point operand j is a Boolean variable S_j of the tree.  Write F_sigma for the solid with
every S_j replaced by the constant sigma_j (everything or nothing), sigma in {0, 1}^k.  Then at
any point x the solid is F_sigma(x) with sigma_j = [x in S_j] (the two-surfel classification of
:mod:`clcsg.model.surfels`), so

* a sample p of a quadric from the device sampler run on F_sigma is on the solid's surface iff
  it is on F_sigma's surface and [p in S_j] = sigma_j for every j: the 2^k runs are sampled
  with :func:`clcsg.sample` and each keeps only its own samples;
* a surfel of operand j at center c is on the surface iff switching S_j switches the solid at
  c (the other operands at their classification there):  F_{sigma, S_j = 1}(c) !=
  F_{sigma, S_j = 0}(c), evaluated on the host (:func:`clcsg.compile.interpret.contains`).
  Its splat is a disk on its tangent plane (a plane quadric); the solid lies behind the plane
  if F(S_j = 1) holds at c, in front of it otherwise.

Clipping (section 3.3 of the paper, on the clip programs the splat renderer already runs;
built by :mod:`clcsg.sampling.surfel_clips`):
near another operand a splat keeps the tape pruned over its ball with its own quadric
substituted, where every point operand is replaced by the half-space of one surfel: its own
tangent plane for the splat's own operand, the surfel whose center is nearest to the splat's
center for any other (its *partner*).  A quadric splat near a point operand is so cut along
the partner's tangent plane, a surfel splat near a quadric exactly along the quadric.  The
tape with markers (one placeholder plane per operand, swapped per splat) is compiled once.
Splats farther than their radius from every other operand keep the run's clip program (or
none).  A splat near another operand is kept or dropped by that clip program, not by its
center: a quadric sample whose center falls on the wrong side of a cloud, or a surfel whose
center is off the surface (probed at points of its disk for the side the solid is on), may
still cover the surface up to the edge with part of its disk.  Assumption: the surfels cover their surface (every surface point within a radius of a
surfel), so a splat whose center is farther than its radius plus twice the largest surfel
radius from every center of an operand does not meet that operand's surface.
"""

from __future__ import annotations

import itertools
import time
import warnings
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from ..compile.interpret import contains
from ..compile.tape import Tape, compile_shape
from ..cl.constants import OP_LEAF
from ..errors import LimitError
from ..cl.records import pack
from ..model.csg import Complement, Primitive, Union
from ..model.quadric import Quadric
from ..model.scene import Scene
from ..model.solids import box, halfspace
from ..model.surfels import Surfels, has_surfels, operands, substitute
from ..readers.scenes import as_scene
from . import sampler
from .sampler import dedupe_programs
from .samples import Samples
from .surfel_clips import ClipPrograms

#: 2^k device runs for k point operands
MAX_OPERANDS = 4

#: the phases of :func:`sample_with_surfels` whose process CPU seconds ``stats["host_cpu_s"]`` holds
PHASES = ("device_runs", "classify", "keep", "clips", "combine")


@contextmanager
def _timed(stats: dict, phase: str):
    t = time.process_time()
    try:
        yield
    finally:
        cpu = stats.setdefault("host_cpu_s", dict.fromkeys(PHASES, 0.0))
        cpu[phase] += time.process_time() - t


def everything():
    return Complement(Union([]))


def nothing():
    return Union([])


def proxy_scene(scene: Scene) -> Scene:
    """The scene with every point operand replaced by its box: its bound holds the solid's,
    and it frames the camera (it is not the solid)."""
    return Scene(substitute(scene.shape, lambda key, s: box(s.box()[1] - s.box()[0], 0.5 * sum(s.box()))),
                 scene.bound, scene.source)


@dataclass
class SurfelTape(Tape):
    """The tape of a solid with point operands: the tape with one marker plane per operand
    (``markers``: quadric index and the sign of its literal where the operand holds), the
    quadric table extended by the surfels' tangent planes, and the tapes of the 2^k
    substitutions (``folded``) for membership."""

    operands: list = field(default_factory=list)
    markers: list = field(default_factory=list)
    folded: dict = field(default_factory=dict)
    #: quadrics from this index on are surfel tangent planes
    first_surfel_quadric: int = 0
    #: per operand the instance its surfels are samples of (its marker's)
    operand_instances: list = field(default_factory=list)
    #: the scene sampled (for :meth:`exact`)
    scene: object = None

    def exact(self) -> Tape:
        """The tape of the scene with each point operand compiled as the mesh of its surface
        (:func:`~clcsg.compile.tape.compile_scene`): what the exact ray tracer traces."""
        return self.scene.compile(self.shape)

    def contains(self, points) -> np.ndarray:
        """Membership of ``points`` in the solid: F_sigma with sigma the classification."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        cls = np.array([s.contains(p) for s in self.operands]).reshape(len(self.operands), len(p))
        out = np.zeros(len(p), dtype=bool)
        for sigma, t in self.folded.items():
            sel = np.all(cls == np.array(sigma, dtype=bool)[:, None], axis=0)
            if sel.any() and not t.empty:
                out[sel] = contains(t.ops, t.quadrics, p[sel])
        return out


def _marker(j: int, bound) -> Primitive:
    """Operand j's placeholder: a plane through the bound's center with a fixed irregular
    normal (coinciding with no face of a scene)."""
    n = np.array([0.5773 + 0.13 * j, -0.3217 + 0.071 * j, 0.7519 - 0.05 * j])
    n /= np.linalg.norm(n)
    return halfspace(n, float(n @ (0.5 * (bound[0] + bound[1]))))


def sample(scene, radius, device=None, **options) -> Samples:
    """:func:`clcsg.sample`: the device sampler (:func:`clcsg.sampling.sampler.sample`, same
    arguments), and for a scene with point operands the combination of its runs described in
    the module docstring."""
    sc = as_scene(scene, options.pop("bound", None))
    if not has_surfels(sc.shape):
        return sampler.sample(sc, radius, device, **options)
    radius, _ = sampler.checked_radius(radius, options.get("floor"))
    ctx = sampler.scene_context(device)
    return sample_with_surfels(sc, radius, lambda s: sampler.sample(s, radius, ctx, **options))


def marker_tape(scene: Scene, radius: float) -> tuple[SurfelTape, np.ndarray]:
    """(tape, bound): the tape of ``scene`` with each point operand replaced by its marker
    plane, and the bound of :func:`proxy_scene` grown by ``radius`` (the runs' bound)."""
    ops = operands(scene.shape)
    keys, clouds = list(ops), list(ops.values())
    bound = proxy_scene(scene).compile().bound
    bound = np.array([bound[0] - radius, bound[1] + radius])
    markers = {k: _marker(j, bound) for j, k in enumerate(keys)}
    tape = compile_shape(substitute(scene.shape, lambda key, s: markers[key]), bound, scene.source)
    literal = {id(i.node): (i.index, i.literals[0]) for i in tape.instances if id(i.node) in map(id, markers.values())}
    tape = SurfelTape(**{f: getattr(tape, f) for f in Tape.__dataclass_fields__}, operands=clouds,
                      markers=[literal[id(markers[k])][1] for k in keys], scene=scene)
    tape.first_surfel_quadric = tape.n_quadrics
    tape.operand_instances = [literal[id(markers[k])][0] for k in keys]
    return tape, bound


def sample_with_surfels(scene: Scene, radius: float, run) -> Samples:
    """Samples of ``scene`` (with point operands) at ``radius``; ``run(scene)`` is the device
    sampler (:func:`clcsg.sample` with the caller's options) on a scene without them."""
    ops = operands(scene.shape)
    keys, clouds = list(ops), list(ops.values())
    if len(keys) > MAX_OPERANDS:
        raise LimitError(f"{scene.source}: {len(keys)} point operands; at most {MAX_OPERANDS} are sampled "
                         f"(2^k sampler runs)")
    tape, bound = marker_tape(scene, radius)
    marker_inst = tape.operand_instances
    prog = ClipPrograms(tape)
    inst_index = {(id(i.node), i.matrix.tobytes()): i.index for i in tape.instances}
    parts: list = []
    n_regs = tape.n_regs
    stats = {"point_operands": len(keys), "surfels": int(sum(len(s) for s in clouds)), "runs": 0}
    for sigma in itertools.product((0, 1), repeat=len(keys)):
        folded = substitute(scene.shape, lambda key, s: everything() if sigma[keys.index(key)] else nothing())
        with warnings.catch_warnings(), _timed(stats, "device_runs"):
            warnings.simplefilter("ignore")  # a run whose solid is empty (S = nothing in S - C) is normal
            got = run(Scene(folded, bound, scene.source))
        stats["runs"] += 1
        for name in sampler.SUMMED_STATS:
            stats[name] = stats.get(name, 0) + int(got.stats.get(name, 0))
        stats["levels"] = max(stats.get("levels", 0), int(got.stats.get("levels", 0)))
        stats.setdefault("floor", got.stats.get("floor"))
        tape.folded[sigma] = got.tape
        n_regs = max(n_regs, got.tape.n_regs)
        if len(got):
            parts.append(_quadric_samples(got, sigma, clouds, prog, inst_index, stats))
    for j, cloud in enumerate(clouds):
        parts.append(_surfel_samples(j, cloud, tape, prog, marker_inst[j], stats))
    with _timed(stats, "combine"):
        return _combined(parts, tape, prog, n_regs, radius, stats)


def _classified(clouds, points, skip=-1):
    """Per operand (None for operand ``skip``): (distance, index) of the surfel nearest to each
    point and the point's membership, from one k-d tree query per operand."""
    return [None if j == skip else s.classify(points) for j, s in enumerate(clouds)]


def _slices(first, count) -> np.ndarray:
    """The row indices first[i] .. first[i] + count[i] - 1 of every i, concatenated."""
    total = int(count.sum())
    starts = np.repeat(np.cumsum(count) - count, count)
    return np.repeat(first, count) + (np.arange(total) - starts)


def _quadric_samples(got: Samples, sigma, clouds, prog: ClipPrograms, inst_index, stats) -> dict:
    """The samples of the run on F_sigma that are on the solid's surface, in combined numbering."""
    p = got.positions
    with _timed(stats, "classify"):
        cls = _classified(clouds, p)
        keep = np.ones(len(p), dtype=bool)
        near = np.zeros(len(p), dtype=bool)
        for j, ((d, _, inside), s) in enumerate(zip(cls, clouds)):
            keep &= inside == bool(sigma[j])
            near |= d < got.radii + 2.0 * float(s.radii.max())
    with _timed(stats, "clips"):
        remap = np.array([prog.table.add(m)[0] for m in got.tape.quadrics], dtype=np.int32)
        insts = np.array([inst_index.get((id(i.node), i.matrix.tobytes()), -1) for i in got.tape.instances] + [-1],
                         dtype=np.int32)
        first = np.zeros(len(p), dtype=np.int32)
        count = np.zeros(len(p), dtype=np.int32)
        quadrics = remap[got.quadrics]
        # a splat near a cloud is decided by its clip program, not by its center: its center may
        # be on the wrong side while part of its disk covers the surface
        keep |= near
        sel = np.flatnonzero(near)
        planes = [(s.points[c[1][sel]], s.normals[c[1][sel]]) for c, s in zip(cls, clouds)]
        first[sel], count[sel], keep[sel] = prog.clip_many(p[sel], got.radii[sel], quadrics[sel], planes)
        far = np.flatnonzero(keep & ~near & (got.clip_count > 0))
        if len(far):
            rows = got.clip_ops[_slices(got.clip_first[far], got.clip_count[far])].copy()
            leaf = rows[:, 0] == OP_LEAF
            rows[leaf, 2] = remap[rows[leaf, 2]]
            start, _ = prog.add_rows(rows)
            count[far] = got.clip_count[far]
            first[far] = start + np.cumsum(count[far]) - count[far]
    k = keep
    return dict(positions=p[k], normals=got.normals[k], radii=got.radii[k], quadrics=quadrics[k],
                signs=got.signs[k], primitives=insts[got.primitives[k]], clip_first=first[k], clip_count=count[k])


def _surfel_samples(j: int, cloud: Surfels, tape: SurfelTape, prog: ClipPrograms, inst: int, stats) -> dict:
    """The surfels of operand j on the solid's surface, as plane samples."""
    c, n, r = cloud.points, cloud.normals, cloud.radii
    with _timed(stats, "classify"):
        cls = _classified(tape.operands, c, skip=j)
        inside, outside = _sides(tape, j, c, cls)
    with _timed(stats, "keep"):
        keep = inside != outside
        near = np.zeros(len(c), dtype=bool)
        scene_q = [q for q in range(tape.n_quadrics) if q not in {mq for mq, _ in tape.markers}]
        for q in scene_q:
            m = tape.quadrics[q]
            if not np.any(m[:3, :3]):  # a plane: value 2 m[:3, 3] . x + m[3, 3], linear
                g = 2.0 * m[:3, 3]
                d = (c @ g + m[3, 3]) / np.linalg.norm(g)
            else:
                d = Quadric(m).distance(c)
            near |= np.abs(d) < r
        for i, s in enumerate(tape.operands):
            if i != j:
                near |= cls[i][0] < r + 2.0 * float(s.radii.max())
        solid_inside = inside.copy()
        late = np.flatnonzero(near & ~keep)  # centers off the surface: a point of the disk may be on it
        if len(late):
            found, side = _disk_sides(tape, j, c[late], n[late], r[late])
            keep[late[found]] = True
            solid_inside[late[found]] = side[found]
    with _timed(stats, "clips"):
        quadrics = np.full(len(c), -1, dtype=np.int32)
        csign = np.ones(len(c), dtype=np.int32)
        quadrics[keep], csign[keep] = prog.planes(c[keep], n[keep])
        signs = np.where(solid_inside, csign, -csign).astype(np.int32)
        normals = np.where(solid_inside[:, None], n, -n)
        first = np.zeros(len(c), dtype=np.int32)
        count = np.zeros(len(c), dtype=np.int32)
        sel = np.flatnonzero(keep & near)
        planes = [(c[sel], n[sel]) if k == j else (s.points[cls[k][1][sel]], s.normals[cls[k][1][sel]])
                  for k, s in enumerate(tape.operands)]
        first[sel], count[sel], keep[sel] = prog.clip_many(c[sel], r[sel], np.full(len(sel), tape.markers[j][0]),
                                                           planes)
        lits = tape.instances[inst].literals  # the instance owns its surfels' planes (colours)
        owned = {q for q, _ in lits}
        q_kept, s_kept = quadrics[keep], signs[keep]
        _, at = np.unique(q_kept, return_index=True)
        for q, sg in zip(q_kept[np.sort(at)].tolist(), s_kept[np.sort(at)].tolist()):
            if q not in owned:
                owned.add(q)
                lits.append((q, sg))
    k = keep
    return dict(positions=c[k], normals=normals[k], radii=r[k].copy(), quadrics=quadrics[k], signs=signs[k],
                primitives=np.full(int(k.sum()), inst, dtype=np.int32), clip_first=first[k], clip_count=count[k])


def _sides(tape: SurfelTape, j: int, x, classified=None) -> tuple[np.ndarray, np.ndarray]:
    """The solid at ``x`` with operand j everything and with it nothing, every other operand
    at its classification there (``classified``: :func:`_classified` of ``x``, if known)."""
    classified = _classified(tape.operands, x, skip=j) if classified is None else classified
    cls = [None if got is None else got[2] for got in classified]
    side = {}
    for v in (0, 1):
        m = np.zeros(len(x), dtype=bool)
        for sigma, t in tape.folded.items():
            if sigma[j] != v or t.empty:
                continue
            sel = np.ones(len(x), dtype=bool)
            for i, ci in enumerate(cls):
                if ci is not None:
                    sel &= ci == bool(sigma[i])
            if sel.any():
                m[sel] = contains(t.ops, t.quadrics, x[sel])
        side[v] = m
    return side[1], side[0]


#: points on a disk probed for the surface when its center is not on it: this many on the
#: circle at 0.9 of its radius
DISK_PROBES = 12


def _disk_sides(tape: SurfelTape, j: int, c, n, r) -> tuple[np.ndarray, np.ndarray]:
    """(found, inside) per disk: whether a probe point of the disk is on the surface (switching
    operand j switches the solid there), and if so whether the solid is behind the disk."""
    t1 = np.cross(n, np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]]))
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(n, t1)
    phi = 2 * np.pi * np.arange(DISK_PROBES) / DISK_PROBES
    x = c[:, None] + 0.9 * r[:, None, None] * (np.cos(phi)[None, :, None] * t1[:, None] + np.sin(phi)[None, :, None] * t2[:, None])
    inside, outside = _sides(tape, j, x.reshape(-1, 3))
    inside, flips = inside.reshape(len(c), -1), (inside != outside).reshape(len(c), -1)
    first = np.argmax(flips, axis=1)
    return flips.any(axis=1), inside[np.arange(len(c)), first]


def _combined(parts, tape: SurfelTape, prog: ClipPrograms, n_regs, radius, stats) -> Samples:
    """One :class:`Samples` over the combined quadric table, equal clip programs stored once."""
    cat = {name: np.concatenate([p[name] for p in parts]) if parts else None
           for name in ("positions", "normals", "radii", "quadrics", "signs", "primitives", "clip_first", "clip_count")}
    tape.quadrics = prog.table.matrices()
    tape.n_regs = n_regs
    tape.instance_program = None  # the marker instances own the surfel planes; no instance CSG
    for j, s in enumerate(tape.operands):
        inst = tape.instances[tape.operand_instances[j]]
        inst.color = s.color
        inst.box = s.box()
        inst.face_boxes = None
    rows = np.concatenate(prog.rows) if prog.rows else np.zeros((0, 4), dtype=np.int32)
    packed = pack(tape)
    if cat["positions"] is None or not len(cat["positions"]):
        return Samples.empty(radius, tape, packed, stats)
    first, count, ops = dedupe_programs(rows, cat["clip_first"], cat["clip_count"]) if len(rows) else \
        (np.zeros_like(cat["clip_first"]), cat["clip_count"], rows)
    stats.update(samples=int(len(cat["positions"])), clipped_samples=int((count > 0).sum()), clip_rows=int(len(ops)),
                 radius=radius, tape_quadrics=int(tape.first_surfel_quadric - len(tape.markers)),
                 surfels_kept=int((cat["quadrics"] >= tape.first_surfel_quadric).sum()))
    return Samples(cat["positions"], cat["normals"], cat["radii"], cat["quadrics"].astype(np.int32),
                   cat["signs"].astype(np.int32), cat["primitives"].astype(np.int32), first, count, ops,
                   radius, tape, packed, stats)
