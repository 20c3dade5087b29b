"""Surface samples: numpy arrays on the host and their device buffers for the renderer."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..cl.memory import upload
from ..model.colors import parse_color, recolor_defaults
from ..cl.records import PackedScene, SceneBuffers, pack, sample_dtype, tape_rows
from .splat_colours import splat_primitives


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

    A plain data type; its conversions live with the writers: :func:`clcsg.write_samples`
    (binary PLY, double precision, or ``.npz`` with the tape: render again without the scene;
    :func:`clcsg.load_samples` reads it back), :func:`clcsg.to_open3d` and
    :func:`clcsg.to_trimesh` (point clouds of those libraries).
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
        """(SceneBuffers, sample buffer, clip buffer, id buffer) on ``context`` in precision
        ``real``, uploaded once.  The id buffer holds each sample's (quadric, splat_primitive)
        as an int2: the resolve pass looks them up per pixel, and the whole records (80 bytes
        each in double) would take a cache line or two per lookup."""
        real = np.dtype(self.packed.real if real is None else real)
        key = (id(context.ctx), real.str)
        if key not in self._device:
            packed = self.packed if real == np.dtype(self.packed.real) else pack(self.tape, real, self.packed.origin)
            rec = self.records(real)
            ids = np.stack([rec["quadric"], rec["splat_primitive"]], axis=1).astype(np.int32)
            self._device[key] = (SceneBuffers(context, packed), upload(context, rec),
                                 upload(context, tape_rows(self.clip_ops)), upload(context, ids))
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

