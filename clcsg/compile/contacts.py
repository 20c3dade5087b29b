"""Quadrics that keep one sign on another's surface, and root tapes that know it.

A sampling task of quadric s uses its tapes only at points of s's surface: the corners and
samples of its cells, and the points where a ray meets a splat of s, which the renderer clips
with the sample's clip program.  So in s's root tape a leaf of another quadric o may be replaced
by a constant wherever o keeps one sign on the whole surface Q_s = 0.  A certificate of that is
a scalar mu with W = A_o - mu A_s semidefinite (an S-lemma certificate): at every point p of
the surface, p^T A_o p = p^T W p + mu p^T A_s p = p^T W p, which has W's sign.

Interval bounds cannot decide such a leaf near a tangent contact: the blends that hull() and
minkowski() build (a face plane touching an edge cylinder along a line, a cone touching its
sphere along a circle) make o's value on s vanish to second order along the contact, so the
cells beside the contact have all four corners off the surface by next to nothing, no bound
proves their patch free of the surface, and they split down to the floor (half the cells of
a rounded box).  For a contact, W is semidefinite and singular at the certificate; where W is
singular det(A_o - mu A_s) = 0, so the candidates for mu are the real roots of that polynomial
(of degree at most 4, on the complement of the null space the two matrices share: two parallel
cylinders share their axis direction, and their pencil's determinant vanishes for every mu).
Pairs apart (o's value on s bounded away from 0) are left to the interval bounds, which
decide them once the cells are as small as the gap.

Not covered: a plane through a cone's apex touching it along a ruling keeps one sign on each
nappe but opposite signs on the two, so no certificate holds on the whole cone (the hull of a
box and a disc is made of such pairs); nor does a surface that passes through an edge of the
solid without bounding it there (a separator of a rotate_extrude through a profile vertex).

The pair is taken in a frame centered on the region where it matters and scaled to the scene
(:func:`in_frames`), each matrix scaled to a largest entry of 1.  W counts as semidefinite when
its eigenvalues are not below -EPS (1 + |mu|): on s's surface the replaced leaf is then wrong
only where o's value is within 2 EPS (1 + |mu|) of zero (in that frame), a band along the
contact some 1e-6 of the scene wide for a tangent contact (o's value grows with the square of
the distance from it), far below the sampler's floor, for a crossing narrower still.
"""

from __future__ import annotations

import numpy as np

from ..model.quadric import ray_distance
from .interpret import _F, _LIVE, _T, prune
from .tape import leaf_quadrics

#: a quadric is tried against another if its conservative distance from the center of the
#: other's region is within this many half-diagonals of it
REACH = 1.5
#: eigenvalues of W down to -EPS times its scale count as zero (see the module docstring)
EPS = 1e-12
#: roots of the pencil's determinant whose imaginary part is below this (relative): a double
#: root, perturbed by rounding, splits into a complex pair
ROOT_IMAG = 1e-3
#: eigenvalues of o @ o + s @ s below this (relative) span the null space o and s share
NULL = 1e-12
#: the most pairs of quadrics tried for contacts in one scene
PAIR_BUDGET = 50_000
#: a pair whose least eigenvalue reaches above APART within APART_BRACKET (relative) of its
#: mu (APART_STEPS golden-section steps) is apart, not in contact: two holes of the 2,500-hole
#: plate 4 mm apart reach 5.6e-4, a contact stays at rounding (1e-14)
APART = 1e-9
APART_BRACKET = 0.5
APART_STEPS = 40
#: where the least eigenvalue is tried first (relative to mu): most pairs apart show it there
APART_PROBES = (-0.3, -0.1, -0.01, 0.01, 0.1, 0.3)
#: decimals of the unit matrices that tell pairs apart (pairs equal to them are solved once)
KEY_DIGITS = 9
#: a root whose W has a least eigenvalue above -NEAR is refined (REFINE: the bracket, relative;
#: GOLDEN_STEPS: the golden-section steps, to 0.618^80 of it)
NEAR = 1e-6
REFINE = 1e-4
GOLDEN_STEPS = 80


def in_frames(a: np.ndarray, centers: np.ndarray, size: float) -> np.ndarray:
    """The matrices ``a`` (N, 4, 4) in the frames x = c_n + size u (``centers`` (N, 3)): T^T A T
    for T = [[size I, c], [0, 1]], each scaled to a largest entry of 1."""
    m, b, k = a[:, :3, :3], a[:, :3, 3], a[:, 3, 3]
    mc = np.einsum("nij,nj->ni", m, centers)
    out = np.empty_like(a)
    out[:, :3, :3] = size * size * m
    out[:, :3, 3] = out[:, 3, :3] = size * (mc + b)
    out[:, 3, 3] = np.einsum("ni,ni->n", centers, mc + 2.0 * b) + k
    return out / np.maximum(np.abs(out).max(axis=(1, 2), keepdims=True), 1e-300)


def _least(w: np.ndarray) -> np.ndarray:
    return np.linalg.eigvalsh(w)[..., 0]


def _common_null(o: np.ndarray, s: np.ndarray) -> np.ndarray:
    """(N, 4, 4) the projectors onto the null space each pair of o and s shares (the axis
    direction of two parallel cylinders, of a cylinder and a plane along it)."""
    w, v = np.linalg.eigh(o @ o + s @ s)
    null = w <= NULL * np.maximum(w.max(axis=1, keepdims=True), 1e-300)
    return np.einsum("nik,nk,njk->nij", v, null.astype(np.float64), v)


def _roots(o: np.ndarray, s: np.ndarray) -> np.ndarray:
    """(N, 7) candidates for mu per pair (N, 4, 4): the roots of det(o - mu s), on the
    complement of the null space each pair shares (its projector is added to o, so that the
    determinant is the complement's), NaN where a root is missing or far from real (a double
    root, perturbed by rounding, splits into a nearly real pair: its real part is kept), then
    the means of neighbouring close roots."""
    o = o + _common_null(o, s)
    mus = np.cos(np.pi * (np.arange(5) + 0.5) / 5)  # Chebyshev points: a stable fit
    dets = np.linalg.det(o[:, None] - mus[None, :, None, None] * s[:, None])
    coeffs = np.linalg.solve(np.vander(mus, 5), dets.T).T  # (N, 5), highest power first
    big = np.abs(coeffs) > 1e-14 * np.abs(coeffs).max(axis=1, keepdims=True)
    degree = np.where(big.any(axis=1), 4 - big.argmax(axis=1), 0)
    out = np.full((len(o), 4), np.nan)
    for d in range(1, 5):
        rows = np.flatnonzero(degree == d)
        if not len(rows):
            continue
        c = coeffs[rows, 5 - d - 1:]
        companion = np.zeros((len(rows), d, d))
        companion[:, 0, :] = -c[:, 1:] / c[:, :1]
        companion[:, np.arange(1, d), np.arange(d - 1)] = 1.0
        r = np.linalg.eigvals(companion)
        out[rows, :d] = np.where(np.abs(r.imag) <= ROOT_IMAG * (1.0 + np.abs(r.real)), r.real, np.nan)
    # a double root split by rounding into two close real roots: their mean is the root to
    # rounding (a complex pair's real part is that mean already)
    srt = np.sort(out, axis=1)
    close = np.abs(srt[:, 1:] - srt[:, :-1]) <= ROOT_IMAG * (1.0 + np.abs(srt[:, 1:]))
    return np.concatenate([out, np.where(close, 0.5 * (srt[:, 1:] + srt[:, :-1]), np.nan)], axis=1)


def _refine(o, s, mu, side, bracket=None, steps=None) -> tuple[np.ndarray, np.ndarray]:
    """(mu, least eigenvalue of side (o - mu s)) for the pairs (K, 4, 4) with mu within
    ``bracket`` (relative; REFINE) of ``mu`` maximizing it (the least eigenvalue is concave in
    mu: a golden-section search of ``steps`` steps, GOLDEN_STEPS, for all pairs at once)."""
    side = side[:, None, None]
    half = (REFINE if bracket is None else bracket) * (1.0 + np.abs(mu))
    a, b = mu - half, mu + half
    g = 0.5 * (np.sqrt(5.0) - 1.0)
    c, d = b - g * (b - a), a + g * (b - a)

    def f(x):
        return _least(side * (o - x[:, None, None] * s))

    fc, fd = f(c), f(d)
    for _ in range(GOLDEN_STEPS if steps is None else steps):
        left = fc >= fd  # the maximum lies in [a, d]
        a, b = np.where(left, a, c), np.where(left, d, b)
        c_new, d_new = b - g * (b - a), a + g * (b - a)
        moved = np.where(left, c_new, d_new)
        fm = f(moved)
        c, fc, d, fd = (np.where(left, c_new, d), np.where(left, fm, fd), np.where(left, c, d_new),
                        np.where(left, fc, fm))
    best = fc >= fd
    return np.where(best, c, d), np.where(best, fc, fd)


def _high(o, s, mu, side, offsets) -> np.ndarray:
    """(K,) the largest least eigenvalue of side (o - m s) over m = mu + offsets (1 + |mu|)."""
    m = mu[:, None] + np.asarray(offsets)[None, :] * (1.0 + np.abs(mu))[:, None]
    w = side[:, None, None, None] * (o[:, None] - m[:, :, None, None] * s[:, None])
    return np.linalg.eigvalsh(w)[..., 0].max(axis=1)


def _certificates(s: np.ndarray, o: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(sign, mu) per pair of unit matrices (N, 4, 4) in contact: sign +1 if o - mu s is
    positive semidefinite (o >= 0 on the surface of s), -1 if negative, 0 (mu NaN) if no
    candidate is, or if the pair is apart.  A pair is apart if the least eigenvalue, on the
    complement of the null space the pair shares, comes above APART for some mu: o's value on
    s is then bounded away from 0, and interval bounds decide it once the cells are as small
    as the gap; tried first at APART_PROBES, then by a golden-section search."""
    sign, found = np.zeros(len(s), dtype=np.int64), np.full(len(s), np.nan)
    done = np.zeros(len(s), dtype=bool)
    roots = _roots(o, s)
    lifted = {side: o + side * _common_null(o, s) for side in (1, -1)}
    for k in range(roots.shape[1]):
        for side in (1, -1):
            todo = np.flatnonzero(~done & np.isfinite(roots[:, k]))
            if not len(todo):
                continue
            mu = roots[todo, k]
            lam = np.linalg.eigvalsh(side * (o[todo] - mu[:, None, None] * s[todo]))
            scale = 1.0 + np.abs(mu)
            # near semidefinite, and W not 0 (o on s's surface)
            near = (lam[:, 0] >= -NEAR * scale) & (lam[:, -1] > EPS * scale)
            todo, mu, least = todo[near], mu[near], lam[near, 0]
            sides = np.full(len(todo), side)
            apart = _high(lifted[side][todo], s[todo], mu, sides, APART_PROBES) > APART
            done[todo[apart]] = True
            todo, mu, least, sides = todo[~apart], mu[~apart], least[~apart], sides[~apart]
            grow = least < 0
            if grow.any():
                mu[grow], least[grow] = _refine(o[todo[grow]], s[todo[grow]], mu[grow], sides[grow])
            ok = least >= -EPS * (1.0 + np.abs(mu))
            todo, mu, sides = todo[ok], mu[ok], sides[ok]
            touch = _refine(lifted[side][todo], s[todo], mu, sides, APART_BRACKET, APART_STEPS)[1] <= APART
            done[todo] = True
            sign[todo[touch]], found[todo[touch]] = side, mu[touch]
    return sign, found


def _holds(s, o, sign, mu) -> np.ndarray:
    """Whether sign (o - mu s) is positive semidefinite (and not 0) for each pair."""
    lam = np.linalg.eigvalsh(sign[:, None, None] * (o - mu[:, None, None] * s))
    scale = EPS * (1.0 + np.abs(mu))
    return (lam[:, 0] >= -scale) & (lam[:, -1] > scale)


def signs_on(a_s, a_o, centers, size: float) -> np.ndarray:
    """(N,) per pair +1 if the quadric ``a_o[n]`` is >= 0 on the whole surface of ``a_s[n]``
    ((N, 4, 4) matrices in world coordinates), -1 if <= 0, 0 if no certificate is found.  The
    pairs are taken in the frames x = centers[n] + size u (:func:`in_frames`): centered on the
    region where they matter, scaled to the scene.  Pairs that are the same there (to
    KEY_DIGITS decimals: a pattern of holes) are solved once, and the certificate checked on
    each of them."""
    s = in_frames(np.asarray(a_s, dtype=np.float64).reshape(-1, 4, 4), centers, size)
    o = in_frames(np.asarray(a_o, dtype=np.float64).reshape(-1, 4, 4), centers, size)
    if not len(s):
        return np.zeros(0, dtype=np.int64)
    keys = np.ascontiguousarray(np.round(np.concatenate([s, o], axis=1).reshape(len(s), -1), KEY_DIGITS) + 0.0)
    keys = keys.view(np.dtype((np.void, keys.dtype.itemsize * keys.shape[1]))).ravel()
    order = np.argsort(keys, kind="stable")
    first = np.r_[True, keys[order][1:] != keys[order][:-1]]
    group = np.empty(len(s), dtype=np.int64)
    group[order] = np.cumsum(first) - 1
    reps = order[first]
    rep_sign, rep_mu = _certificates(s[reps], o[reps])
    sign, mu = rep_sign[group], rep_mu[group]
    has = np.flatnonzero(sign != 0)
    failed = has[~_holds(s[has], o[has], sign[has], mu[has])]
    sign[failed] = _certificates(s[failed], o[failed])[0] if len(failed) else sign[failed]
    return sign


def sign_on(a_s, a_o, bound) -> int:
    """:func:`signs_on` of one pair, in the frame of the scene bound ``bound`` (2, 3)."""
    lo, hi = (np.asarray(b, dtype=np.float64) for b in bound)
    size = float(np.max(0.5 * (hi - lo)))
    return int(signs_on(np.asarray(a_s)[None], np.asarray(a_o)[None], (0.5 * (lo + hi))[None], size)[0])


def contact_tape(ops, quadrics, self_quadric: int, signs: dict) -> np.ndarray:
    """The root tape ``ops`` of ``self_quadric`` with the leaves of the quadrics o that keep one
    sign on its surface (``signs``: {o: +1 or -1}) replaced by constants and folded
    (:func:`~clcsg.compile.interpret.prune`)."""

    def state(q, sign):
        if q not in signs:
            return _LIVE
        return _F if sign * signs[q] > 0 else _T

    pruned, _decided, _evals = prune(np.asarray(ops, dtype=np.int32).reshape(-1, 4), quadrics, np.zeros(3), 0.0,
                                     self_quadric, leaf_state=state)
    return pruned


def _meets(matrices: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(N,) whether the surface of ``matrices[n]`` may come within REACH half-diagonals of the
    box [lo[n], hi[n]]: by the conservative distance from the box's center (eqs. 10, 11; a
    filter only: a pair it drops gets no certificate)."""
    c = 0.5 * (lo + hi)
    x = np.concatenate([c, np.ones((len(c), 1))], axis=1)
    mx = np.einsum("nij,nj->ni", matrices, x)
    lam = np.linalg.eigvalsh(matrices[:, :3, :3])
    d = ray_distance(np.einsum("ni,ni->n", x, mx), 2.0 * np.linalg.norm(mx[:, :3], axis=1), lam[:, 0], lam[:, -1])
    return np.abs(d) <= REACH * 0.5 * np.linalg.norm(hi - lo, axis=1)


def contact_root_tapes(tape, spans: dict, rows: np.ndarray, regions: dict) -> tuple[dict, np.ndarray]:
    """The root tapes of the quadrics of ``spans`` ({quadric: (first, count)} into ``rows``, from
    :func:`~clcsg.compile.root_tapes.prune_root_tapes`) with the leaves of every quadric in
    contact with their surface folded (:func:`contact_tape`): the changed tapes are appended to
    the rows and their quadrics pointed at them.

    The pairs tried are a quadric and the other quadrics of its root tape whose surface comes
    near its region (``regions``: {quadric: (lo, hi)}, a world box holding every point of its
    surface where its root tape is used: the box of its tasks' patches grown by the splat
    radius; :func:`_meets`), not two planes (a plane keeps one sign on another only if parallel, and
    then interval bounds decide it).  Past PAIR_BUDGET pairs none is tried (the 2,500-hole
    plate has 300,000, and no contact).  The certificates are kept on the tape."""
    quadrics = np.asarray(tape.quadrics, dtype=np.float64)
    n = len(quadrics)
    plane = ~np.any(quadrics[:, :3, :3] != 0, axis=(1, 2))
    leaves_of: dict = {}
    selfs, others = [], []
    for q, (first, count) in spans.items():
        if (first, count) not in leaves_of:
            leaves_of[first, count] = leaf_quadrics(rows[first:first + count])
        o = leaves_of[first, count]
        o = o[(o != q) & ~(plane[o] & plane[q])]
        selfs.append(np.full(len(o), q, dtype=np.int64))
        others.append(o)
    s_q = np.concatenate(selfs) if selfs else np.zeros(0, dtype=np.int64)
    o_q = np.concatenate(others) if others else np.zeros(0, dtype=np.int64)
    if not len(s_q) or len(s_q) > PAIR_BUDGET:
        return spans, rows
    lo = np.array([regions[q][0] for q in spans], dtype=np.float64).reshape(-1, 3)
    hi = np.array([regions[q][1] for q in spans], dtype=np.float64).reshape(-1, 3)
    at = {q: k for k, q in enumerate(spans)}
    region = np.array([at[q] for q in s_q.tolist()], dtype=np.int64)
    near = _meets(quadrics[o_q], lo[region], hi[region])
    s_q, o_q, region = s_q[near], o_q[near], region[near]
    codes = s_q * n + o_q
    known = tape.__dict__.setdefault("_contact_signs", {})
    todo = np.flatnonzero([c not in known for c in codes.tolist()])
    if len(todo):
        size = float(np.max(0.5 * (np.asarray(tape.bound[1]) - np.asarray(tape.bound[0]))))
        found = signs_on(quadrics[s_q[todo]], quadrics[o_q[todo]],
                         0.5 * (lo[region[todo]] + hi[region[todo]]), size)
        known.update(zip(codes[todo].tolist(), found.tolist()))
        tape.__dict__["_contact_count"] = tape.__dict__.get("_contact_count", 0) + int(np.count_nonzero(found))
    sign = np.array([known[c] for c in codes.tolist()], dtype=np.int64)
    certified: dict = {}
    for q, o, v in zip(s_q[sign != 0].tolist(), o_q[sign != 0].tolist(), sign[sign != 0].tolist()):
        certified.setdefault(q, {})[o] = v
    extra, used, out = [], len(rows), dict(spans)
    for q, signs in certified.items():
        first, count = spans[q]
        new = contact_tape(rows[first:first + count], quadrics, q, signs)
        out[q] = (used, len(new))
        extra.append(new)
        used += len(new)
    return out, np.concatenate([rows] + extra).astype(np.int32) if extra else rows


def contact_pairs(tape) -> int:
    """The pairs (sampled quadric, other quadric) in contact found on ``tape`` so far (counted
    as they are found: this is asked on every sampling call)."""
    return tape.__dict__.get("_contact_count", 0)
