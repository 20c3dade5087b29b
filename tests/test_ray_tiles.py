"""The ray tracer's tile depth ranges (clcsg/rendering/tiles.cl, tiles.h: tile_depths) against
float64 ray-box intersections: every pixel ray's stretch inside the scene bound lies within its
tile's depth range, however the range was narrowed."""

import numpy as np
import pytest

import clcsg
from clcsg.cl.device import choose_real
from clcsg.cl.memory import upload
from clcsg.cl.records import SceneBuffers, pack
from clcsg.rendering.camera import Camera
from clcsg.rendering.raytracer import TILE, _bound_args, prune_tiles
from clcsg.rendering.shading import pack_view


def _tile_depths(ctx, tape, cam):
    real = choose_real(ctx, "auto")
    packed = pack(tape, real=real)
    scene = SceneBuffers(ctx, packed)
    view = upload(ctx, pack_view(cam, packed.origin, real))
    bufs, _, _, stats = prune_tiles(ctx, scene, view, _bound_args(tape, packed, real), cam.width, cam.height, real)
    ntx, nty = -(-cam.width // TILE), -(-cam.height // TILE)
    z = np.empty((nty, ntx, 2), dtype=real)
    import pyopencl as cl

    cl.enqueue_copy(ctx.queue, z, bufs[2])
    ctx.queue.finish()
    return z.astype(np.float64), stats


def _ray_depths(tape, cam):
    """(entry, exit) depths along the forward axis of each pixel ray in the bound (float64),
    NaN where it misses; entry clamped to the eye."""
    o, d = cam.rays()
    lo, hi = tape.bound
    with np.errstate(divide="ignore", invalid="ignore"):
        t0, t1 = (lo - o) / d, (hi - o) / d
    ta = np.nanmax(np.minimum(t0, t1), axis=-1).clip(0)
    tb = np.nanmin(np.maximum(t0, t1), axis=-1)
    c = d @ cam.forward
    miss = ~(ta <= tb)
    ta[miss], tb[miss] = np.nan, np.nan
    return ta * c, tb * c


def _plate():
    return clcsg.box((40, 40, 2)) - clcsg.cylinder(4, 3)


CAMERAS = [
    ((0, -40, 8), (0, 5, 0), 60),  # grazing, the narrowing's case
    ((3, -2, 30), (0, 0, 0), 50),  # from above
    ((0, 0, 0.5), (5, 3, 0.2), 70),  # from inside the bound
    ((50, 40, 1), (0, 0, 0), 20),  # edge on
]


@pytest.mark.parametrize("eye,target,fov", CAMERAS)
def test_every_ray_in_the_bound_is_inside_its_tiles_depth_range(cl_context, eye, target, fov):
    tape = clcsg.Scene(_plate()).compile()
    cam = Camera.look_at(eye, target, fov=fov, width=83, height=45)
    z, _ = _tile_depths(cl_context, tape, cam)
    za, zb = _ray_depths(tape, cam)
    i, j = np.nonzero(~np.isnan(za))
    assert len(i) > 0
    tz = z[i // TILE, j // TILE]
    eps = 1e-12 * (np.abs(za[i, j]) + np.abs(zb[i, j]) + 1)
    assert np.all(tz[:, 0] <= za[i, j] + eps), "a ray enters the bound before its tile's depth range"
    assert np.all(tz[:, 1] >= zb[i, j] - eps), "a ray leaves the bound after its tile's depth range"


def test_a_grazing_view_narrows_the_tile_ranges(cl_context):
    """Seen grazing, a tile's rays cross the plate's thickness over a short stretch: the tile
    ranges are far shorter than the bound's corner depths (which every tile would get)."""
    tape = clcsg.Scene(_plate()).compile()
    eye, target, fov = CAMERAS[0]
    cam = Camera.look_at(eye, target, fov=fov, width=320, height=180)
    z, _ = _tile_depths(cl_context, tape, cam)
    corners = np.array([[x, y, w] for x in tape.bound[:, 0] for y in tape.bound[:, 1] for w in tape.bound[:, 2]])
    depth = (corners - cam.eye) @ cam.forward
    full = depth.max() - max(depth.min(), 0)
    za, _ = _ray_depths(tape, cam)
    i, j = np.nonzero(~np.isnan(za))
    met = np.unique((i // TILE) * z.shape[1] + j // TILE)  # tiles with a ray in the bound
    spans = (z[..., 1] - z[..., 0]).ravel()[met]
    assert len(met) > 10
    assert np.median(spans) < 0.25 * full
