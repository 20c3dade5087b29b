"""Samples as ``.npz``: everything needed to render them again without the scene.

:func:`save_samples` writes one uncompressed numpy archive (``numpy.savez``, no pickles):

* the per-sample arrays of :class:`~clcsg.sampling.samples.Samples` (positions, normals,
  radii, quadrics, signs, primitives, clip_first, clip_count) with the deduplicated clip rows
  (clip_ops) and the sampler's radius, in their own dtypes (positions float64, bit for bit);
* the tape the samples clip against: ``tape_ops``, ``tape_n_regs``, ``tape_quadrics``,
  ``tape_bound``, ``tape_shape``, ``tape_stats`` (JSON), ``tape_empty`` and per primitive
  instance its literals, colour, world matrix and box (the CSG node itself is not stored);
* the device origin and precision of the packed scene, and the sampling statistics (JSON).

:func:`load_samples` rebuilds a :class:`~clcsg.compile.tape.Tape` (instances with
``node=None``) and packs it again with the saved origin and precision, so rendering the loaded
samples gives the same image, pixel for pixel.
"""

from __future__ import annotations

import json
import os

import numpy as np

from ..errors import SceneError
from ..errors import UsageError
from ..cl.records import pack
from ..compile.tape import Instance, Tape
from ..sampling.samples import Samples

FORMAT = "clcsg-samples"
VERSION = 1
ARRAYS = ("positions", "normals", "radii", "quadrics", "signs", "primitives", "clip_first", "clip_count", "clip_ops")


def _json(obj) -> np.ndarray:
    def default(v):
        if hasattr(v, "tolist"):
            return v.tolist()
        return str(v)

    return np.array(json.dumps(obj, default=default))


def save_samples(samples, path) -> None:
    """Write ``samples`` (with their tape) as an ``.npz`` archive at ``path`` (the name is
    used as given)."""
    t = samples.tape
    insts = list(t.instances)
    lits = [np.asarray(inst.literals, dtype=np.int64).reshape(-1, 2) for inst in insts]
    boxes = np.full((len(insts), 2, 3), np.nan)
    for k, inst in enumerate(insts):
        if inst.box is not None:
            boxes[k] = np.asarray(inst.box, dtype=np.float64).reshape(2, 3)
    data = {name: np.asarray(getattr(samples, name)) for name in ARRAYS}
    data.update(
        format=np.array(FORMAT), version=np.array(VERSION), radius=np.array(float(samples.radius)),
        tape_ops=np.asarray(t.ops), tape_n_regs=np.array(int(t.n_regs)), tape_quadrics=np.asarray(t.quadrics),
        tape_bound=np.asarray(t.bound, dtype=np.float64), tape_shape=np.array(str(t.shape)),
        tape_stats=_json(t.stats), tape_empty=np.array(bool(t.empty)),
        instance_literals=np.concatenate(lits) if lits else np.zeros((0, 2), np.int64),
        instance_literal_counts=np.array([len(x) for x in lits], dtype=np.int64),
        instance_colors=np.array([tuple(inst.color) for inst in insts], dtype=np.float64).reshape(-1, 4),
        instance_matrices=np.array([inst.matrix for inst in insts], dtype=np.float64).reshape(-1, 4, 4),
        instance_boxes=boxes,
        instance_kinds=np.array([getattr(inst.node, "kind", "") for inst in insts], dtype=str),
        origin=np.asarray(samples.packed.origin, dtype=np.float64), real=np.array(np.dtype(samples.packed.real).str),
        stats=_json(samples.stats),
    )
    p = os.fspath(path)
    try:
        with open(p, "wb") as f:
            np.savez(f, **data)
    except OSError as e:
        raise UsageError(f"{p}: cannot write samples: {e.strerror or e}") from None


def load_samples(path):
    """The :class:`~clcsg.sampling.samples.Samples` saved by :func:`save_samples`."""
    p = os.fspath(path)
    try:
        z = np.load(p, allow_pickle=False)
    except FileNotFoundError:
        raise SceneError(f"{p}: no such file") from None
    except (OSError, ValueError) as e:
        raise SceneError(f"{p}: not a sample file (.npz): {e}") from None
    with z:
        if "format" not in z.files or str(z["format"]) != FORMAT:
            raise SceneError(f"{p}: not a clcsg sample file (it has no \"format\": {FORMAT!r} entry)")
        if int(z["version"]) > VERSION:
            raise SceneError(f"{p}: sample file version {int(z['version'])} is newer than this clcsg reads ({VERSION})")
        missing = [k for k in (*ARRAYS, "tape_ops", "tape_quadrics", "instance_literals") if k not in z.files]
        if missing:
            raise SceneError(f"{p}: incomplete sample file: no {missing[0]!r}")
        counts = z["instance_literal_counts"]
        starts = np.concatenate([[0], np.cumsum(counts)])
        lits, colors, mats, boxes = z["instance_literals"], z["instance_colors"], z["instance_matrices"], z["instance_boxes"]
        instances = []
        for k in range(len(counts)):
            box = boxes[k]
            instances.append(Instance(
                index=k, node=None, matrix=mats[k].copy(),
                literals=[(int(q), int(s)) for q, s in lits[starts[k]:starts[k + 1]]],
                color=tuple(float(c) for c in colors[k]),
                box=None if np.isnan(box).any() else (box[0].copy(), box[1].copy())))
        tape = Tape(ops=z["tape_ops"].astype(np.int32), n_regs=int(z["tape_n_regs"]), quadrics=z["tape_quadrics"].copy(),
                    instances=instances, bound=z["tape_bound"].copy(), shape=str(z["tape_shape"]),
                    stats=json.loads(str(z["tape_stats"])), empty=bool(z["tape_empty"]))
        arrays = {name: z[name].copy() for name in ARRAYS}
        packed = pack(tape, np.dtype(str(z["real"])), z["origin"].copy())
        return Samples(**arrays, radius=float(z["radius"]), tape=tape, packed=packed,
                       stats=json.loads(str(z["stats"])))
