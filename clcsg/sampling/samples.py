"""Surface samples: numpy arrays on the host and their device buffers for the renderer."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..cl.memory import upload
from ..model.colors import parse_color, recolor_defaults
from ..cl.records import PackedScene, SceneBuffers, pack, sample_dtype, tape_rows


@dataclass
class Samples:
    """Samples on the CSG surface (world coordinates, float64).

    Every sample lies on quadric ``quadrics[i]`` of ``tape.quadrics``; ``signs[i]`` is the side
    the solid is on there (+1: the negative side, so the outward normal ``normals[i]`` is
    ``+grad Q / |grad Q|``); ``primitives[i]`` is the primitive instance (``tape.instances``, in
    tree order) whose own boundary holds it, the first one where several do; its colour is that
    instance's.  Its clip program is ``clip_ops[clip_first[i] : clip_first[i] + clip_count[i]]``
    (tape rows; empty: no clipping): a fragment of its splat on the quadric is kept iff the
    program's membership differs between the quadric's two sides.  Equal programs are stored
    once.  Guarantee: every point of the CSG surface has a sample on the same quadric within
    ``radius`` (the sampler's radius; ``radii`` may be smaller where a small cell allowed it),
    except in features narrower than the floor: ``stats["unresolved"]`` counts the
    *unresolved cells*, cells the sampler could still not decide (surface or not, covered or
    not) when they had shrunk below the floor (``stats["floor"]``, by default min(radius / 10,
    1e-3 of the scene's diagonal)); they are dropped.  They lie along edges and tangent
    contacts, where two surfaces meet, so thousands are normal (their number grows with the
    edge length over the floor); a feature thinner than the floor can be missed (pass a
    smaller ``floor`` to :func:`clcsg.sample`).

    Output: :meth:`to_ply` (binary PLY, double precision), :meth:`save` / :func:`load_samples`
    (``.npz`` with the tape: render again without the scene), :meth:`to_open3d` and
    :meth:`to_trimesh` (point clouds of those libraries).
    """

    positions: np.ndarray
    normals: np.ndarray
    radii: np.ndarray
    quadrics: np.ndarray
    signs: np.ndarray
    primitives: np.ndarray
    clip_first: np.ndarray
    clip_count: np.ndarray
    clip_ops: np.ndarray
    radius: float
    tape: object
    packed: PackedScene
    stats: dict = field(default_factory=dict)
    _device: dict = field(default_factory=dict, repr=False)

    def __len__(self) -> int:
        return len(self.positions)

    @classmethod
    def empty(cls, radius, tape, packed, stats) -> "Samples":
        z3 = np.zeros((0, 3))
        zi = np.zeros(0, dtype=np.int32)
        return cls(z3, z3.copy(), np.zeros(0), zi, zi.copy(), zi.copy(), zi.copy(), zi.copy(),
                   np.zeros((0, 4), dtype=np.int32), radius, tape, packed, stats)

    @property
    def colors(self) -> np.ndarray:
        """(N, 4) float32 RGBA of each sample's primitive."""
        table = np.array([inst.color for inst in self.tape.instances], dtype=np.float32).reshape(-1, 4)
        if not len(self):
            return np.zeros((0, 4), dtype=np.float32)
        return table[np.maximum(self.primitives, 0)]

    @property
    def bound(self) -> np.ndarray:
        return self.tape.bound

    # -- device side --------------------------------------------------------------------------
    def records(self, real=None) -> np.ndarray:
        """The samples as ``sample_rec`` structs in device coordinates."""
        rec = np.zeros(len(self), dtype=sample_dtype(self.packed.real if real is None else real))
        fields = {"pos": self.positions - self.packed.origin, "normal": self.normals, "radius": self.radii,
                  "quadric": self.quadrics, "sign": self.signs, "primitive": self.primitives,
                  "clip_first": self.clip_first, "clip_count": self.clip_count}
        for name, values in fields.items():
            rec[name] = values
        rec["splat_primitive"] = splat_primitives(self.packed, fields["pos"], self.radii, self.quadrics)
        return rec

    def device_buffers(self, context, real=None):
        """(SceneBuffers, sample buffer, clip buffer) on ``context`` in precision ``real``,
        uploaded once."""
        real = np.dtype(self.packed.real if real is None else real)
        key = (id(context.ctx), real.str)
        if key not in self._device:
            packed = self.packed if real == np.dtype(self.packed.real) else pack(self.tape, real, self.packed.origin)
            self._device[key] = (SceneBuffers(context, packed), upload(context, self.records(real)),
                                 upload(context, tape_rows(self.clip_ops)))
        return self._device[key]

    def with_default_color(self, color) -> int:
        """Give the primitives that have clcsg's default colour the colour ``color`` (RGBA or
        any colour :func:`clcsg.model.colors.parse_color` reads, e.g. OpenSCAD's ``"#f9d72c"``);
        returns how many primitives changed.  The device buffers are packed again."""
        n = recolor_defaults(self.tape, parse_color(color))
        if n:
            self.packed = pack(self.tape, self.packed.real, self.packed.origin)
            self._device.clear()
        return n


def splat_primitives(packed: PackedScene, pos: np.ndarray, radii: np.ndarray, quadrics: np.ndarray) -> np.ndarray:
    """Per sample the primitive that the colour rule (``primitives.h``, ``primitive_at``) gives
    every point of its splat, or -1 where it may vary over the splat (the resolve pass then
    decides per pixel).  ``pos``: device coordinates.

    ``primitive_at`` at p on quadric q only considers the owners of q whose padded box holds p,
    and takes the first owner of q where none of them holds p.  So over the ball B(s, r) the
    answer is that first owner if no owner's box meets the ball, or if the only box that does
    is the first owner's; a quadric with one owner always gives it.  The ball is grown by a
    relative 1e-3 and the rounding of the device's precision (fragments are accepted within r
    in that precision)."""
    n = len(pos)
    out = np.full(n, -1, dtype=np.int32)
    if not n or not len(packed.owners):
        return out
    q = np.asarray(quadrics, dtype=np.int64)
    first, count = packed.owners["first"][q].astype(np.int64), packed.owners["count"][q].astype(np.int64)
    owned = count > 0
    out[owned] = packed.owner_list[first[owned]]
    multi = np.flatnonzero(count > 1)
    if not len(multi):
        return out
    reps = count[multi]
    rows = np.repeat(multi, reps)  # one row per (sample, owner) pair
    k = np.arange(len(rows)) - np.repeat(np.cumsum(reps) - reps, reps)
    inst = packed.owner_list[first[rows] + k]
    box = packed.prim_boxes.astype(np.float64)[inst]
    p = pos[rows]
    with np.errstate(invalid="ignore"):
        gap = np.maximum(np.maximum(box[:, 0, :3] - p, p - box[:, 1, :3]), 0.0)
    r = np.asarray(radii, dtype=np.float64)[rows]
    reach = r * (1 + 1e-3) + 64 * float(np.finfo(packed.real).eps) * (np.linalg.norm(p, axis=1) + r)
    meets = ~((gap * gap).sum(axis=1) > reach * reach)  # an empty box (lo = inf) never meets
    hits = np.bincount(rows[meets], minlength=n)[multi]
    first_meets = np.bincount(rows[meets & (k == 0)], minlength=n)[multi] > 0
    out[multi[~((hits == 0) | ((hits == 1) & first_meets))]] = -1
    return out
