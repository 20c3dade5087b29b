"""The ray tracer's culling boxes (clcsg/rendering/ray_culling.py) against a float64 numpy
evaluation of the tape: outside a quadric's culling box, taking the quadric's sign as its
culling sign leaves the solid's membership unchanged."""

import numpy as np
from hypothesis import assume, given, settings, strategies as st

import clcsg
from clcsg.cl.constants import OP_AND, OP_CONST, OP_COPY, OP_LEAF, OP_OR
from clcsg.cl.records import pack
from clcsg.errors import UnboundedError
from clcsg.rendering.ray_culling import cull_boxes

from strategies import shapes


def membership(ops, signs):
    """The tape's membership at points whose quadric signs are ``signs`` (U, P): a literal
    (q, s) holds where s * sign_q <= 0."""
    regs = {}
    for op, out, a, b in np.asarray(ops):
        if op == OP_LEAF:
            regs[out] = b * signs[a] <= 0
        elif op == OP_AND:
            regs[out] = regs[a] & regs[b]
        elif op == OP_OR:
            regs[out] = regs[a] | regs[b]
        elif op == OP_COPY:
            regs[out] = regs[a]
        elif op == OP_CONST:
            regs[out] = np.full(signs.shape[1], bool(a))
    return regs[np.asarray(ops)[-1][1]]


def check_culling(shape, seed=0, n=4000):
    try:
        tape = clcsg.Scene(shape).compile()
    except UnboundedError:
        assume(False)
    packed = pack(tape)
    rows = cull_boxes(packed)
    lo, hi = tape.bound
    span = hi - lo
    pts = np.random.default_rng(seed).uniform(lo - 0.05 * span, hi + 0.05 * span, (n, 3))
    xh = np.concatenate([pts, np.ones((n, 1))], axis=1)
    signs = np.sign(np.einsum("pi,qij,pj->qp", xh, tape.quadrics, xh))
    truth = membership(tape.ops, signs)
    dev = pts - packed.origin
    culled = 0
    for q in np.flatnonzero(rows[:, 3] != 0):
        out = np.any((dev < rows[q, :3]) | (dev > rows[q, 4:7]), axis=1)
        forced = signs.copy()
        forced[q, out] = rows[q, 3]
        assert np.array_equal(membership(tape.ops, forced), truth), f"quadric {q}"
        culled += int(out.sum())
    return rows, culled


def test_plate_and_spheres_cull_their_holes_and_balls():
    plate = clcsg.box((10, 10, 1)) - clcsg.union(*[clcsg.cylinder(2, 0.3, (x, y, 0)) for x in range(-4, 5, 2)
                                                   for y in range(-4, 5, 2)])
    rows, culled = check_culling(plate)
    assert (rows[:, 3] != 0).sum() == 25 and culled > 0  # every hole's cylinder; the planes never
    balls = clcsg.union(*[clcsg.sphere(0.4, (k, 0.1 * k, 0)) for k in range(12)])
    rows, culled = check_culling(balls)
    assert (rows[:, 3] != 0).sum() == 12 and culled > 0


def test_a_quadric_whose_literals_disagree_in_sign_is_never_culled():
    """The unit sphere is the solid of one primitive and the outside of another (a raw quadric
    primitive, -Q <= 0): no one sign keeps both; the small sphere is culled."""
    outside = clcsg.quadric(-np.diag([1.0, 1.0, 1.0, -1.0])) & clcsg.box(3)
    shape = clcsg.sphere(1.0) | outside | clcsg.sphere(0.5, (3, 0, 0))
    rows, culled = check_culling(shape)
    tape = clcsg.Scene(shape).compile()
    curved = [q for q in range(tape.n_quadrics) if np.any(tape.quadrics[q][:3, :3] != 0)]
    assert len(curved) == 2 and culled > 0
    assert (rows[curved, 3] != 0).sum() == 1


@settings(max_examples=30)
@given(shapes(), st.integers(0, 2**16))
def test_culling_sign_keeps_membership_on_random_programs(shape, seed):
    check_culling(shape, seed, n=300)
