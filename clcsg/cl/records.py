"""numpy mirrors of the device records (``cl/include/layout.h``, ``rendering/shade.h``) and the
packing of a compiled :class:`~clcsg.compile.tape.Tape` into device buffers.

The dtypes use ``align=True`` (C's natural alignment, which OpenCL uses for structs in global
memory); ``tests/test_records.py`` checks every one's size and field offsets on the device.
Coordinates on the device are relative to ``origin`` (the center of the scene bound): every
quadric is translated by ``-origin`` before packing, which keeps float32 precise far from the
world origin.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .constants import INSTANCE_REGS, ROUNDING_ULPS
from .memory import upload

from ..model.quadric import COEFFICIENT_INDEX, affine, check_affine

TAPE_OP_DTYPE = np.dtype([("op", np.int32), ("out", np.int32), ("a", np.int32), ("b", np.int32)], align=True)
OWNER_DTYPE = np.dtype([("first", np.int32), ("count", np.int32)], align=True)
PRIM_DTYPE = np.dtype([("lit_first", np.int32), ("lit_count", np.int32), ("color", np.float32, 4)], align=True)


def quadric_dtype(real) -> np.dtype:
    return np.dtype([("coef", real, 10), ("lam_min", real), ("lam_max", real)], align=True)


def sample_dtype(real) -> np.dtype:
    return np.dtype(
        [("pos", real, 3), ("normal", real, 3), ("radius", real), ("quadric", np.int32), ("sign", np.int32),
         ("primitive", np.int32), ("clip_first", np.int32), ("clip_count", np.int32),
         ("splat_primitive", np.int32)],
        align=True,
    )


def frame_dtype(real) -> np.dtype:
    return np.dtype(
        [("U", real, 9), ("center", real, 3), ("lam", real, 3), ("beta", real, 3), ("gamma", real),
         ("height_factor", real, 3), ("vertex", real, 3), ("vertex_value", real, 3)], align=True
    )


def task_dtype(real) -> np.dtype:
    return np.dtype(
        [("quadric", np.int32), ("plane", np.int32), ("sheet", np.int32), ("pad", np.int32),
         ("zlo", real, 3), ("zhi", real, 3)],
        align=True,
    )


@lru_cache(maxsize=8)  # made per sampling call, 20 us each
def cell_dtype(real) -> np.dtype:
    return np.dtype(
        [("x0", real), ("y0", real), ("x1", real), ("y1", real), ("d", real, 4), ("task", np.int32),
         ("level", np.int32), ("tape_first", np.int32), ("tape_count", np.int32)],
        align=True,
    )


#: (C struct name, header, dtype factory) of every record: the layout test walks this list
RECORDS = (
    ("quadric_rec", "layout.h", quadric_dtype),
    ("prim_rec", "layout.h", lambda real: PRIM_DTYPE),
    ("owner_rec", "layout.h", lambda real: OWNER_DTYPE),
    ("sample_rec", "layout.h", sample_dtype),
    ("frame_rec", "layout.h", frame_dtype),
    ("task_rec", "layout.h", task_dtype),
    ("cell_rec", "layout.h", cell_dtype),
    ("tape_op", "tape.h", lambda real: TAPE_OP_DTYPE),
)


def tape_rows(ops) -> np.ndarray:
    """(N, 4) int32 tape rows as ``tape_op`` records."""
    ops = np.ascontiguousarray(np.asarray(ops, dtype=np.int32).reshape(-1, 4))
    return ops.view(TAPE_OP_DTYPE).reshape(-1)


@dataclass
class PackedScene:
    """Host copies of the scene buffers of a tape, in device coordinates (world - origin)."""

    real: np.dtype
    origin: np.ndarray  # (3,) float64
    quadrics: np.ndarray  # quadric_dtype
    local_matrices: np.ndarray  # (U, 4, 4) float64 quadrics in device coordinates
    tape: np.ndarray  # TAPE_OP_DTYPE rows of the root tape
    prims: np.ndarray  # PRIM_DTYPE
    prim_literals: np.ndarray  # (L, 2) int32
    owners: np.ndarray  # OWNER_DTYPE per quadric
    owner_list: np.ndarray  # int32
    n_regs: int
    prim_boxes: np.ndarray  # (P, 2, 4) real: per instance its box (lo, hi), padded; empty: lo > hi
    instance_tape: np.ndarray  # TAPE_OP_DTYPE rows of the instance program (primitives.h)
    instance_rows: int  # its length; 0: none (or it needs more than INSTANCE_REGS registers)


def pack(tape, real=np.float64, origin=None) -> PackedScene:
    """The device buffers of ``tape`` (a :class:`~clcsg.compile.tape.Tape`)."""
    real = np.dtype(real)
    if origin is None:
        origin = 0.5 * (tape.bound[0] + tape.bound[1])
    origin = np.asarray(origin, dtype=np.float64)
    shift = affine(translation=-origin)
    U = tape.n_quadrics
    q = np.zeros(U, dtype=quadric_dtype(real))
    # Q' = M^-T Q M^-1 (Quadric.transform) for all quadrics at once
    inv = np.linalg.inv(check_affine(shift))
    m = np.asarray(tape.quadrics, dtype=np.float64).reshape(U, 4, 4)
    local = np.einsum("ji,njk,kl->nil", inv, 0.5 * (m + m.transpose(0, 2, 1)), inv)
    local = 0.5 * (local + local.transpose(0, 2, 1))
    if U:
        q["coef"] = local[:, [i for i, _ in COEFFICIENT_INDEX], [j for _, j in COEFFICIENT_INDEX]]
        lam = np.linalg.eigvalsh(local[:, :3, :3])
        q["lam_min"], q["lam_max"] = lam[:, 0], lam[:, -1]
    prims = np.zeros(len(tape.instances), dtype=PRIM_DTYPE)
    lits = []
    for k, inst in enumerate(tape.instances):
        prims["lit_first"][k] = len(lits)
        prims["lit_count"][k] = len(inst.literals)
        prims["color"][k] = inst.color
        lits.extend(inst.literals)
    owners = np.zeros(U, dtype=OWNER_DTYPE)
    owner_list = []
    for qi, insts in enumerate(tape.owners()):
        owners["first"][qi] = len(owner_list)
        owners["count"][qi] = len(insts)
        owner_list.extend(insts)
    boxes = instance_boxes(tape, origin, real)
    program = getattr(tape, "instance_program", None)
    usable = program is not None and program[1] <= INSTANCE_REGS and len(program[0])
    inst = tape_rows(program[0] if usable else np.zeros((1, 4)))
    return PackedScene(
        real, origin, q, local, tape_rows(tape.ops), prims,
        np.array(lits, dtype=np.int32).reshape(-1, 2), owners, np.array(owner_list, dtype=np.int32), tape.n_regs,
        boxes, inst, len(inst) if usable else 0,
    )


def instance_boxes(tape, origin, real) -> np.ndarray:
    """Per instance its bounding box in device coordinates, padded by the rounding margin of
    the precision at the scene's scale (points computed on its boundary stay inside); an
    instance that is provably empty gets an empty box (lo = +inf, hi = -inf)."""
    bound = np.asarray(tape.bound, dtype=np.float64)
    scale = float(np.abs(bound).max(initial=0.0)) + float(np.linalg.norm(bound[1] - bound[0])) + 1.0
    pad = ROUNDING_ULPS * float(np.finfo(real).eps) * scale
    out = np.zeros((max(len(tape.instances), 1), 2, 4), dtype=real)
    out[:, 0, :3], out[:, 1, :3] = np.inf, -np.inf
    for k, inst in enumerate(tape.instances):
        if inst.box is not None:
            with np.errstate(invalid="ignore"):
                out[k, 0, :3] = np.asarray(inst.box[0], dtype=np.float64) - origin - pad
                out[k, 1, :3] = np.asarray(inst.box[1], dtype=np.float64) - origin + pad
    return out


class SceneBuffers:
    """A packed scene uploaded to a device (read-only buffers)."""

    def __init__(self, context, packed: PackedScene):
        self.packed = packed
        self.quadrics = upload(context, packed.quadrics)
        self.tape = upload(context, packed.tape)
        self.prims = upload(context, packed.prims)
        self.prim_literals = upload(context, packed.prim_literals)
        self.owners = upload(context, packed.owners)
        self.owner_list = upload(context, packed.owner_list)
        self.instance_tape = upload(context, packed.instance_tape)
        self.prim_boxes = upload(context, packed.prim_boxes)

    def colour_args(self):
        """The arguments of ``primitive_at`` (cl/include/primitives.h), in its order."""
        return (self.owners, self.owner_list, self.prims, self.prim_literals, self.prim_boxes, self.instance_tape,
                np.int32(self.packed.instance_rows))
