"""Checks of untrusted arrays before they reach a device: dtypes, shapes, ranges, tapes.

A file clcsg reads (a ``.npz`` of samples, a PLY, a Parquet manifest) may come from anyone.
The kernels index buffers with the numbers in it (quadric ids, clip program offsets, tape
registers), so every one of them is checked here on the host first; a failed check is a
one-line :class:`~clcsg.errors.SceneError` (exit code 3) naming the file, the array and the
reason.

Tapes (rows ``(op, out, a, b)``, :mod:`clcsg.compile.tape`) are *well-formed* for ``n_regs``
registers and ``n_quadrics`` quadrics when every op is known, every register written or read
is in ``[0, n_regs)``, every LEAF names a quadric in ``[0, n_quadrics)`` with sign +1 or -1,
CONST holds 0 or 1, the unused operand of COPY and CONST is 0 (every field is checked, as
the tape pruner writes them), and every register an AND, OR or COPY reads was written by an earlier row of the same
program (:func:`check_programs`, vectorized: sort by (program, register), first writer per
key, one binary search per read).  The kernels size their private register files with
``n_regs`` (``TAPE_REGS``), so it is bounded by :data:`MAX_REGS`.
"""

from __future__ import annotations

import numpy as np

from ..cl.constants import OP_AND, OP_CONST, OP_COPY, OP_LEAF, OP_OR
from ..errors import SceneError

#: the most registers a tape read from a file may use (the kernels keep them in private memory)
MAX_REGS = 256
#: the most rows, samples or quadrics an index-holding array may have (32-bit kernel indices)
MAX_ROWS = (1 << 31) - 1

_KINDS = {"float": "f", "int": "iu", "bool": "b", "str": "U"}


class Checker:
    """Checks of the arrays of one file, named ``where`` in the messages."""

    def __init__(self, arrays: dict, where: str):
        self.arrays = arrays
        self.where = where

    def fail(self, name: str, reason: str):
        raise SceneError(f"{self.where}: {name}: {reason}")

    def get(self, name: str, kind: str, shape: tuple | None = None) -> np.ndarray:
        """Array ``name`` of dtype kind ``kind`` ("float", "int", "bool", "str") and ``shape``
        (None entries are free; returns the array with every free length known)."""
        if name not in self.arrays:
            self.fail(name, "missing (an incomplete or damaged sample file)")
        a = self.arrays[name]
        if a.dtype.kind not in _KINDS[kind]:
            self.fail(name, f"expected {kind} values, got dtype {a.dtype}")
        if shape is not None and (a.ndim != len(shape) or any(s is not None and s != n for s, n in zip(shape, a.shape))):
            want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"
            self.fail(name, f"expected shape {want}, got {a.shape}")
        if a.ndim and a.shape[0] > MAX_ROWS:
            self.fail(name, f"{a.shape[0]} rows are more than the kernels can index")
        return a

    def scalar(self, name: str, kind: str):
        return self.get(name, kind, ()).item()

    def finite(self, name: str, a: np.ndarray) -> np.ndarray:
        if not np.isfinite(a).all():
            self.fail(name, "contains NaN or infinity")
        return a

    def in_range(self, name: str, a: np.ndarray, lo: int, hi: int, what: str = "") -> None:
        """Every value of ``a`` in ``[lo, hi)``."""
        if a.size and (int(a.min()) < lo or int(a.max()) >= hi):
            bad = a[(a < lo) | (a >= hi)].flat[0]
            self.fail(name, f"value {int(bad)} out of range [{lo}, {hi}){what}")

    def signs(self, name: str, a: np.ndarray) -> None:
        if a.size and not np.isin(a, (-1, 1)).all():
            self.fail(name, "signs must be +1 or -1")


def _program_rows(first: np.ndarray, count: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(row index, program id) of every row of the programs ``[first, first + count)``."""
    total = int(count.sum())
    pid = np.repeat(np.arange(len(first)), count)
    starts = np.repeat(first - np.concatenate([[0], np.cumsum(count)[:-1]]), count)
    return np.arange(total, dtype=np.int64) + starts, pid


def check_programs(chk: Checker, name: str, ops: np.ndarray, first, count, n_regs: int, n_quadrics: int) -> None:
    """The programs ``ops[first[k] : first[k] + count[k]]`` are well-formed (module docstring);
    ``first`` and ``count`` are int64 arrays already in range."""
    rows, pid = _program_rows(np.asarray(first, np.int64), np.asarray(count, np.int64))
    if not len(rows):
        return
    t = ops[rows].astype(np.int64)
    op, out, a, b = t[:, 0], t[:, 1], t[:, 2], t[:, 3]
    chk.in_range(f"{name} op codes", op, 0, OP_CONST + 1)
    chk.in_range(f"{name} output registers", out, 0, n_regs, f" (n_regs = {n_regs})")
    leaf = op == OP_LEAF
    chk.in_range(f"{name} leaf quadrics", a[leaf], 0, n_quadrics, f" ({n_quadrics} quadrics)")
    chk.signs(f"{name} leaf signs", b[leaf])
    binary = (op == OP_AND) | (op == OP_OR)
    unary = op == OP_COPY
    const = op == OP_CONST
    chk.in_range(f"{name} constants", a[const], 0, 2, " (CONST takes 0 or 1)")
    chk.in_range(f"{name} unused operands", b[unary | const], 0, 1, " (COPY and CONST rows have b = 0)")
    reads = np.concatenate([np.flatnonzero(binary | unary), np.flatnonzero(binary)])
    regs = np.concatenate([a[binary | unary], b[binary]])
    chk.in_range(f"{name} operand registers", regs, 0, n_regs, f" (n_regs = {n_regs})")
    key = pid * n_regs + out
    uniq, first_write = np.unique(key, return_index=True)
    want = pid[reads] * n_regs + regs
    k = np.minimum(np.searchsorted(uniq, want), len(uniq) - 1)
    ok = (uniq[k] == want) & (first_write[k] < reads)
    if not ok.all():
        bad = reads[~ok][0]
        chk.fail(name, f"row {int(rows[bad])} reads a register no earlier row of its program wrote")


def check_spans(chk: Checker, name: str, first: np.ndarray, count: np.ndarray, n_rows: int):
    """The distinct non-empty spans ``[first, first + count)`` lie in ``[0, n_rows)`` and do
    not overlap (as clcsg stores programs: each once); returns them as (first, count) int64."""
    f = first.astype(np.int64)
    c = count.astype(np.int64)
    chk.in_range(f"{name} counts", c, 0, n_rows + 1, f" ({n_rows} rows)")
    live = c > 0
    chk.in_range(f"{name} offsets", f, 0, n_rows + 1, f" ({n_rows} rows)")  # empty spans too: every index in range
    chk.in_range(f"{name} offsets", f[live], 0, n_rows, f" ({n_rows} rows)")
    if live.any() and int((f[live] + c[live]).max()) > n_rows:
        chk.fail(name, f"a program runs past the {n_rows} rows stored")
    spans = np.unique(np.stack([f[live], c[live]], axis=1), axis=0) if live.any() else np.zeros((0, 2), np.int64)
    if len(spans) > 1 and (spans[1:, 0] < spans[:-1, 0] + spans[:-1, 1]).any():
        chk.fail(name, "programs overlap (clcsg stores each program once, apart)")
    return spans[:, 0], spans[:, 1]


def max_register(ops: np.ndarray) -> int:
    """The highest register a tape writes (-1 for no rows)."""
    return int(ops[:, 1].max()) if len(ops) else -1
