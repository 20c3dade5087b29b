"""Samples as ``.npz``: everything needed to render them again without the scene.

:func:`save_samples` writes one uncompressed numpy archive (``numpy.savez``, no pickles):

* the per-sample arrays of :class:`~clcsg.sampling.samples.Samples` (positions, normals,
  radii, quadrics, signs, primitives, clip_first, clip_count) with the deduplicated clip rows
  (clip_ops) and the sampler's radius, in their own dtypes (positions float64, bit for bit);
* the tape the samples clip against: ``tape_ops``, ``tape_n_regs``, ``tape_quadrics``,
  ``tape_bound``, ``tape_shape``, ``tape_stats`` (JSON), ``tape_empty``, per primitive
  instance its literals, colour, world matrix and box (the CSG node itself is not stored),
  and the CSG over the instances (``instance_ops``, ``instance_n_regs``: the instance program
  of the colour rule, :mod:`clcsg.compile.instance_program`; absent from older files, whose
  samples then render with the first instance whose boundary holds a point);
* the device origin and precision of the packed scene, and the sampling statistics (JSON).

:func:`load_samples` rebuilds a :class:`~clcsg.compile.tape.Tape` (instances with
``node=None``) and packs it again with the saved origin and precision, so rendering the loaded
samples gives the same image, pixel for pixel.
"""

from __future__ import annotations

import json
import os

import numpy as np

from ..atomic import atomic_open
from ..cl.records import pack
from ..compile.tape import Instance, Tape
from ..errors import LimitError, SceneError
from ..readers.budget import available_memory
from ..sampling.samples import Samples
from .validate import MAX_REGS, Checker, check_programs, check_spans, max_register

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
    if t.instance_program is not None:
        data.update(instance_ops=np.asarray(t.instance_program[0]), instance_n_regs=np.array(int(t.instance_program[1])))
    with atomic_open(path, "wb", "samples") as f:
        np.savez(f, **data)


#: arrays every sample file has (``instance_kinds`` is informational and optional)
REQUIRED = (*ARRAYS, "format", "version", "radius", "tape_ops", "tape_n_regs", "tape_quadrics", "tape_bound",
            "tape_shape", "tape_stats", "tape_empty", "instance_literals", "instance_literal_counts",
            "instance_colors", "instance_matrices", "instance_boxes", "origin", "real", "stats")
#: the device precisions a sample file may ask for
REALS = ("<f8", "<f4")
#: a sample file's arrays may take at most this fraction of the machine's free memory
MEMORY_FRACTION = 0.5


def _read_arrays(p: str) -> dict:
    """Every array of the archive at ``p``; SceneError for a file that is not one."""
    import zipfile
    import zlib

    try:
        z = np.load(p, allow_pickle=False)
    except FileNotFoundError:
        raise SceneError(f"{p}: no such file") from None
    except IsADirectoryError:
        raise SceneError(f"{p}: is a directory, not a sample file (.npz)") from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as e:
        raise SceneError(f"{p}: not a sample file (.npz): {' '.join(str(e).split())}") from None
    if not isinstance(z, np.lib.npyio.NpzFile):
        raise SceneError(f"{p}: not a sample file (.npz): it holds a single array")
    with z:
        size = sum(info.file_size for info in z.zip.infolist())
        if size > MEMORY_FRACTION * available_memory():
            raise LimitError(f"{p}: its arrays take {size / 2**20:.0f} MiB, more than half of the memory "
                             "available; free memory or use a machine with more")
        out = {}
        for name in z.files:
            try:
                out[name] = z[name]
            except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error, NotImplementedError) as e:
                raise SceneError(f"{p}: array {name!r} cannot be read (truncated or damaged file): "
                                 f"{' '.join(str(e).split())}") from None
    return out


def _check_header(chk) -> None:
    if "format" not in chk.arrays or chk.arrays["format"].dtype.kind != "U" or str(chk.arrays["format"]) != FORMAT:
        raise SceneError(f"{chk.where}: not a clcsg sample file (it has no \"format\": {FORMAT!r} entry)")
    version = chk.scalar("version", "int")
    if version > VERSION:
        chk.fail("version", f"sample file version {version} is newer than this clcsg reads ({VERSION})")
    if version < 1:
        chk.fail("version", f"unknown sample file version {version}")
    missing = [k for k in REQUIRED if k not in chk.arrays]
    if missing:
        chk.fail(missing[0], "missing (an incomplete or damaged sample file)")


def _check_json(chk, name: str) -> dict:
    text = chk.scalar(name, "str")
    try:
        v = json.loads(text)
    except ValueError:
        chk.fail(name, "is not JSON")
    if not isinstance(v, dict):
        chk.fail(name, "expected a JSON object")
    return v


def _check_tape(chk) -> dict:
    """The tape's arrays, checked (see :mod:`clcsg.writers.validate`)."""

    ops = chk.get("tape_ops", "int", (None, 4))
    n_regs = chk.scalar("tape_n_regs", "int")
    quadrics = chk.finite("tape_quadrics", chk.get("tape_quadrics", "float", (None, 4, 4)))
    if not np.allclose(quadrics, np.swapaxes(quadrics, 1, 2), rtol=0, atol=1e-9 * max(1.0, float(np.abs(quadrics).max(initial=0)))):
        chk.fail("tape_quadrics", "quadric matrices must be symmetric")
    used = max_register(ops) + 1
    if not 1 <= n_regs <= MAX_REGS:
        chk.fail("tape_n_regs", f"{n_regs} registers: expected 1 to {MAX_REGS}")
    if n_regs != max(used, 1):
        chk.fail("tape_n_regs", f"{n_regs} registers, but the tape writes {used}")
    empty = chk.scalar("tape_empty", "bool")
    if not len(ops) and not empty:
        chk.fail("tape_ops", "a non-empty solid needs at least one instruction")
    check_programs(chk, "tape_ops", ops, np.zeros(1 if len(ops) else 0, np.int64), np.array([len(ops)] * bool(len(ops))),
                   n_regs, len(quadrics))
    bound = chk.finite("tape_bound", chk.get("tape_bound", "float", (2, 3)))
    if not empty and (bound[0] > bound[1]).any():
        chk.fail("tape_bound", "lower corner above the upper corner")
    shape = chk.scalar("tape_shape", "str")
    if shape not in ("tree", "dnf"):
        chk.fail("tape_shape", f"expected 'tree' or 'dnf', got {shape!r}")
    return dict(ops=ops.astype(np.int32), n_regs=int(n_regs), quadrics=quadrics.astype(np.float64), bound=bound,
                shape=shape, stats=_check_json(chk, "tape_stats"), empty=bool(empty))


def _check_instances(chk, n_quadrics: int) -> list:
    """(matrix, literals, color, box) per primitive instance, checked."""
    counts = chk.get("instance_literal_counts", "int", (None,))
    n = len(counts)
    lits = chk.get("instance_literals", "int", (None, 2))
    chk.in_range("instance_literal_counts", counts, 0, len(lits) + 1)
    if int(counts.astype(np.int64).sum()) != len(lits):
        chk.fail("instance_literal_counts", f"they add up to {int(counts.sum())}, but there are {len(lits)} literals")
    chk.in_range("instance_literals quadrics", lits[:, 0], 0, n_quadrics, f" ({n_quadrics} quadrics)")
    chk.signs("instance_literals signs", lits[:, 1])
    colors = chk.finite("instance_colors", chk.get("instance_colors", "float", (n, 4)))
    if ((colors < 0) | (colors > 1)).any():
        chk.fail("instance_colors", "components must lie in [0, 1]")
    mats = chk.finite("instance_matrices", chk.get("instance_matrices", "float", (n, 4, 4)))
    boxes = chk.get("instance_boxes", "float", (n, 2, 3))
    nan = np.isnan(boxes).reshape(n, -1)
    # an unbounded primitive (a half-space, an infinite cylinder) has infinite sides
    ordered = (boxes[:, 0] <= boxes[:, 1]).all(axis=1) & (boxes[:, 0] < np.inf).all(axis=1) \
        & (boxes[:, 1] > -np.inf).all(axis=1)
    if not (nan.all(axis=1) | (~nan.any(axis=1) & ordered)).all():
        chk.fail("instance_boxes", "each box is all NaN (none), or lo <= hi without NaN (infinite sides allowed)")
    starts = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    return [(mats[k].astype(np.float64), [(int(q), int(s)) for q, s in lits[starts[k]:starts[k + 1]]],
             tuple(float(c) for c in colors[k]), None if nan[k].all() else (boxes[k, 0].astype(np.float64),
                                                                               boxes[k, 1].astype(np.float64)))
            for k in range(n)]


def _check_instance_program(chk, n_instances: int):
    """(ops, registers) of the saved instance program, checked; None if the file has none."""
    if "instance_ops" not in chk.arrays and "instance_n_regs" not in chk.arrays:
        return None
    ops = chk.get("instance_ops", "int", (None, 4))
    n_regs = chk.scalar("instance_n_regs", "int")
    if not len(ops) or not 1 <= n_regs <= MAX_REGS:
        chk.fail("instance_n_regs", f"{n_regs} registers for {len(ops)} rows: expected 1 to {MAX_REGS} and a row")
    # the program's leaves are instances: check_programs' "quadrics" range is the instances here
    check_programs(chk, "instance_ops", ops, np.zeros(1, np.int64), np.array([len(ops)]), n_regs, n_instances)
    return ops.astype(np.int32), int(n_regs)


def _check_samples(chk, n_quadrics: int, n_instances: int, n_regs: int) -> dict:
    """The per-sample arrays, checked, in the dtypes :class:`Samples` uses."""

    pos = chk.finite("positions", chk.get("positions", "float", (None, 3)))
    n = len(pos)
    out = {"positions": pos.astype(np.float64),
           "normals": chk.finite("normals", chk.get("normals", "float", (n, 3))).astype(np.float64)}
    radii = chk.finite("radii", chk.get("radii", "float", (n,)))
    if (radii <= 0).any():
        chk.fail("radii", "splat radii must be positive")
    out["radii"] = radii.astype(np.float64)
    ints = {k: chk.get(k, "int", (n,)) for k in ("quadrics", "signs", "primitives", "clip_first", "clip_count")}
    chk.in_range("quadrics", ints["quadrics"], 0, n_quadrics, f" ({n_quadrics} quadrics in the tape)")
    chk.signs("signs", ints["signs"])
    chk.in_range("primitives", ints["primitives"], -1 if n_instances else 0, max(n_instances, 0),
                 f" ({n_instances} primitive instances)")
    clip = chk.get("clip_ops", "int", (None, 4))
    first, count = check_spans(chk, "clip programs (clip_first, clip_count)", ints["clip_first"],
                               ints["clip_count"], len(clip))
    check_programs(chk, "clip_ops", clip, first, count, n_regs, n_quadrics)
    out.update({k: v.astype(np.int32) for k, v in ints.items()})
    out["clip_ops"] = clip.astype(np.int32)
    return out


def load_samples(path):
    """The :class:`~clcsg.sampling.samples.Samples` saved by :func:`save_samples`.

    The file is untrusted: every array is checked (dtype, shape, finite values, every index
    and count in range, the tape and clip programs well-formed: :mod:`clcsg.writers.validate`)
    before anything is packed for a device; anything else is a one-line
    :class:`~clcsg.errors.SceneError` (exit code 3).
    """

    p = os.fspath(path)
    chk = Checker(_read_arrays(p), p)
    _check_header(chk)
    t = _check_tape(chk)
    insts = _check_instances(chk, len(t["quadrics"]))
    arrays = _check_samples(chk, len(t["quadrics"]), len(insts), t["n_regs"])
    radius = chk.scalar("radius", "float")
    if not (np.isfinite(radius) and radius > 0):
        chk.fail("radius", f"must be a positive finite number, got {radius}")
    origin = chk.finite("origin", chk.get("origin", "float", (3,))).astype(np.float64)
    real = chk.scalar("real", "str")
    if real not in REALS:
        chk.fail("real", f"unknown precision {real!r} (expected one of {', '.join(REALS)})")
    stats = _check_json(chk, "stats")
    instances = [Instance(index=k, node=None, matrix=m, literals=lits, color=c, box=box)
                 for k, (m, lits, c, box) in enumerate(insts)]
    tape = Tape(instances=instances, **t)
    tape.instance_program = _check_instance_program(chk, len(insts))
    try:
        with np.errstate(all="ignore"):  # an overflow is reported below, as one error
            packed = pack(tape, np.dtype(real), origin)
    except (SceneError, ValueError, ArithmeticError, np.linalg.LinAlgError) as e:
        raise SceneError(f"{p}: tape_quadrics: {' '.join(str(e).split())}") from None
    coef = packed.quadrics
    if not all(np.isfinite(coef[f]).all() for f in coef.dtype.names) or not np.isfinite(packed.local_matrices).all():
        chk.fail("tape_quadrics", "too large: the quadrics overflow in device coordinates (about the origin)")
    return Samples(**arrays, radius=float(radius), tape=tape, packed=packed, stats=stats)
