"""Packing a :class:`~clcsg.host.dnf.Dnf` into the device buffers of ``kernels/layout.h``.

The numpy dtypes below mirror the C structs field by field (``align=True`` gives C's natural
alignment, which OpenCL uses for structs in global memory).  Coordinates on the device are
relative to ``origin`` (the center of the scene bound): every quadric is translated by
``-origin`` before packing, which keeps float32 devices precise far from the world origin.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.quadric import Quadric, affine
from ..compile.dnf import Dnf


def quadric_dtype(real) -> np.dtype:
    return np.dtype(
        [("coef", real, 10), ("lam_min", real), ("lam_max", real), ("color", np.float32, 4)],
        align=True,
    )


LITERAL_DTYPE = np.dtype([("quadric", np.int32), ("sign", np.int32)], align=True)


def term_dtype(real) -> np.dtype:
    return np.dtype(
        [("first", np.int32), ("count", np.int32), ("lo", real, 3), ("hi", real, 3)], align=True
    )


def sample_dtype(real) -> np.dtype:
    return np.dtype(
        [
            ("pos", real, 3),
            ("normal", real, 3),
            ("radius", real),
            ("quadric", np.int32),
            ("sign", np.int32),
            ("term", np.int32),
            ("clip_first", np.int32),
            ("clip_count", np.int32),
        ],
        align=True,
    )


@dataclass
class PackedScene:
    """Host copies of the scene buffers, in device coordinates (world - origin)."""

    real: np.dtype
    origin: np.ndarray  # (3,) float64
    quadrics: np.ndarray  # quadric_dtype
    literals: np.ndarray  # LITERAL_DTYPE
    terms: np.ndarray  # term_dtype
    local_matrices: np.ndarray  # (U, 4, 4) float64 quadrics in device coordinates


def pack(dnf: Dnf, real=np.float64, origin=None) -> PackedScene:
    real = np.dtype(real)
    if origin is None:
        origin = 0.5 * (dnf.bound[0] + dnf.bound[1]) if dnf.n_terms else np.zeros(3)
    origin = np.asarray(origin, dtype=np.float64)
    shift = affine(translation=-origin)
    U = dnf.n_quadrics
    q = np.zeros(U, dtype=quadric_dtype(real))
    local = np.zeros((U, 4, 4))
    for i in range(U):
        ql = Quadric(dnf.quadrics[i]).transform(shift)
        local[i] = ql.matrix
        q["coef"][i] = ql.coefficients()
        lmin, lmax = ql.eigenvalue_range()
        q["lam_min"][i] = lmin
        q["lam_max"][i] = lmax
    q["color"] = dnf.colors
    lits = [lit for term in dnf.terms for lit in term]
    literals = np.zeros(len(lits), dtype=LITERAL_DTYPE)
    if lits:
        literals["quadric"] = [qi for qi, _ in lits]
        literals["sign"] = [s for _, s in lits]
    terms = np.zeros(dnf.n_terms, dtype=term_dtype(real))
    counts = np.array([len(t) for t in dnf.terms], dtype=np.int32)
    terms["count"] = counts
    terms["first"] = np.concatenate([[0], np.cumsum(counts)[:-1]]) if len(counts) else []
    if dnf.n_terms:
        terms["lo"] = dnf.term_bounds[:, 0] - origin
        terms["hi"] = dnf.term_bounds[:, 1] - origin
    return PackedScene(real, origin, q, literals, terms, local)


class SceneBuffers:
    """The packed scene uploaded to a device (read-only buffers)."""

    def __init__(self, context, packed: PackedScene):
        import pyopencl as cl

        mf = cl.mem_flags
        self.packed = packed

        def up(a):
            # zero-sized buffers are not allowed: upload one dummy element instead
            data = a if a.size else np.zeros(1, dtype=a.dtype)
            return cl.Buffer(context.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=data)

        self.quadrics = up(packed.quadrics)
        self.literals = up(packed.literals)
        self.terms = up(packed.terms)
        self.n_quadrics = len(packed.quadrics)
        self.n_terms = len(packed.terms)
