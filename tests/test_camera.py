"""The camera contract (clcsg/rendering/camera.py): pixel (i, j) is the ray through ((j + .5)/W, (i + .5)/H)."""

import math

import numpy as np
import pytest

from clcsg.rendering.camera import Camera, orbit
from clcsg.errors import UsageError


def test_frame_is_orthonormal_and_up_is_projected():
    cam = Camera.look_at((3, -4, 2), (0.5, 0.2, 0.1), up=(0.1, 0.3, 1.0), fov=50, width=80, height=60)
    frame = np.stack([cam.right, cam.up, cam.forward])
    assert np.allclose(frame @ frame.T, np.eye(3), atol=1e-14)
    assert np.allclose(cam.forward, (cam.target - cam.eye) / np.linalg.norm(cam.target - cam.eye))
    # up stays in the plane of the given up and the view direction, on the same side
    given = np.array([0.1, 0.3, 1.0])
    assert abs(np.linalg.det(np.stack([cam.up, given, cam.forward]))) < 1e-12
    assert cam.up @ given > 0
    # right-handed: right = forward x up
    assert np.allclose(np.cross(cam.forward, cam.up), cam.right)


def test_center_rays_and_corners():
    W, H, fov = 64, 48, 60.0
    cam = Camera.look_at((0, -10, 0), (0, 0, 0), up=(0, 0, 1), fov=fov, width=W, height=H)
    o, d = cam.rays()
    assert o.shape == d.shape == (H, W, 3)
    assert np.allclose(np.linalg.norm(d, axis=-1), 1.0)
    assert np.all(o == cam.eye)
    # the image center lies between the four middle pixels
    mid = d[H // 2 - 1 : H // 2 + 1, W // 2 - 1 : W // 2 + 1].mean(axis=(0, 1))
    assert np.allclose(mid / np.linalg.norm(mid), cam.forward, atol=1e-12)
    # row 0 is the top (+z here), column 0 the left (-x here)
    assert d[0, W // 2, 2] > 0 and d[-1, W // 2, 2] < 0
    assert d[H // 2, 0, 0] < 0 and d[H // 2, -1, 0] > 0
    # vertical fov: the top edge of the image plane is at angle fov/2
    f = cam.focal
    assert math.isclose(f, (H / 2) / math.tan(math.radians(fov) / 2))
    top = d[0, W // 2]
    ang = math.atan2(top[2], top[1])
    assert math.isclose(ang, math.atan((H / 2 - 0.5) / f), rel_tol=1e-12)


def test_pixel_formula_and_projection_roundtrip():
    cam = Camera.look_at((1, 2, 3), (-1, 0.5, 0.25), up=(0, 0, 1), fov=40, width=31, height=17)
    o, d = cam.rays()
    f = cam.focal
    for i, j in [(0, 0), (16, 30), (5, 12)]:
        x = (j + 0.5) / cam.width
        y = (i + 0.5) / cam.height
        expect = cam.forward + (x - 0.5) * cam.width / f * cam.right - (y - 0.5) * cam.height / f * cam.up
        assert np.allclose(d[i, j], expect / np.linalg.norm(expect), atol=1e-15)
        # a point along the ray projects to the pixel center
        xy, z = cam.project(cam.eye + 7.0 * d[i, j])
        assert np.allclose(xy, [j + 0.5, i + 0.5], atol=1e-9)
        assert cam.pixel_of(cam.eye + 7.0 * d[i, j]) == (i, j)


def _corners(bound):
    return np.array([[bound[i][0], bound[j][1], bound[k][2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])


def test_fit_frames_the_bound_at_90_percent():
    bound = np.array([[-1.0, -2.0, 0.0], [3.0, 1.0, 0.5]])
    c = bound.mean(0)
    rng = np.random.default_rng(1)
    inner = rng.uniform(bound[0], bound[1], (2000, 3))
    for W, H in [(64, 48), (48, 64), (100, 20)]:
        cam = Camera.fit(bound, W, H, fov=45)
        xy, z = cam.project(_corners(bound))
        assert np.all(z > 0)
        # the corners span 90 % of the frame in the larger relative extent, centred
        extent = (xy.max(0) - xy.min(0)) / [W, H]
        assert max(extent) == pytest.approx(0.9, abs=1e-4)
        assert np.allclose(0.5 * (xy.max(0) + xy.min(0)), [W / 2, H / 2], atol=1e-4 * max(W, H))
        # so the whole box is in view, 5 % from the border
        xy, z = cam.project(inner)
        assert np.all(z > 0)
        assert np.all((xy >= 0.05 * np.array([W, H]) - 1e-6) & (xy <= 0.95 * np.array([W, H]) + 1e-6))
        # the view direction is the default one; the target is on the view axis, at the center's depth
        d = np.array([0.62, -0.95, 0.55])
        assert np.allclose(cam.forward, -d / np.linalg.norm(d), atol=1e-12)
        assert np.allclose(np.cross(cam.target - cam.eye, cam.forward), 0, atol=1e-9)
        assert (cam.target - cam.eye) @ cam.forward == pytest.approx((c - cam.eye) @ cam.forward)


def test_fit_frames_points_and_samples_like_objects():
    rng = np.random.default_rng(2)
    u = rng.normal(size=(5000, 3))
    pts = 0.7 * u / np.linalg.norm(u, axis=1, keepdims=True) + [2.0, -1.0, 0.5]  # a sphere of points
    for W, H in [(96, 72), (72, 96)]:
        cam = Camera.fit(pts, W, H)
        xy, _ = cam.project(pts)
        extent = (xy.max(0) - xy.min(0)) / [W, H]
        assert max(extent) == pytest.approx(0.9, abs=1e-4)
        assert np.allclose(0.5 * (xy.max(0) + xy.min(0)), [W / 2, H / 2], atol=1e-3)

    class HasPositions:  # what Samples offers: positions frame the camera, not the bound
        positions = pts
        bound = np.array([[-10.0] * 3, [10.0] * 3])

    cam = Camera.fit(HasPositions(), 96, 72)
    xy, _ = cam.project(pts)
    assert max((xy.max(0) - xy.min(0)) / [96, 72]) == pytest.approx(0.9, abs=1e-4)


def test_fit_without_centering_looks_at_the_center():
    bound = np.array([[-1.0, -2.0, 0.0], [3.0, 1.0, 0.5]])
    cam = Camera.fit(bound, 64, 48, centered=False)
    assert np.allclose(cam.target, bound.mean(0), atol=1e-9)
    xy, _ = cam.project(_corners(bound))
    extent = (xy.max(0) - xy.min(0)) / [64, 48]
    side = np.abs(xy - [32, 24]).max(0) / [32, 24]
    # the binding constraint is met exactly: 90 % of the frame or 5 % from a border
    assert max(extent) <= 0.9 + 1e-4 and max(side) <= 0.95 + 1e-4
    assert max(extent) == pytest.approx(0.9, abs=1e-4) or max(side) == pytest.approx(0.95, abs=1e-4)


def test_fit_default_is_three_quarter_view_from_above():
    cam = Camera.fit(np.array([[-1, -1, -1], [1, 1, 1.0]]), 64, 48)
    v = cam.eye - cam.target
    assert v[2] > 0 and abs(v[0]) > 0.1 * np.linalg.norm(v) and abs(v[1]) > 0.1 * np.linalg.norm(v)
    # direction parallel to up still works
    top = Camera.fit(np.array([[-1, -1, -1], [1, 1, 1.0]]), 64, 48, direction=(0, 0, 1))
    assert np.allclose(top.forward, [0, 0, -1])


def test_fit_accepts_objects_with_bound():
    class HasBound:
        bound = np.array([[0, 0, 0], [1, 1, 1.0]])

    cam = Camera.fit(HasBound(), 32, 24, centered=False)
    assert np.allclose(cam.target, 0.5)
    centred = Camera.fit(HasBound(), 32, 24)
    assert np.allclose(centred.forward, cam.forward)
    xy, _ = centred.project(_corners(HasBound.bound))
    assert np.allclose(0.5 * (xy.max(0) + xy.min(0)), [16, 12], atol=1e-4)


def test_orbit():
    bound = np.array([[-1, -1, -1], [1, 1, 1.0]])
    cams = list(orbit(bound, 6, elevation=30, width=40, height=30))
    assert len(cams) == 6
    dists = [np.linalg.norm(c.eye - c.target) for c in cams]
    assert np.allclose(dists, dists[0])
    for c in cams:
        v = (c.eye - c.target) / np.linalg.norm(c.eye - c.target)
        assert math.isclose(math.degrees(math.asin(v[2])), 30, abs_tol=1e-9)
        assert (c.width, c.height) == (40, 30)
    # azimuths equally spaced
    az = sorted(math.atan2(c.eye[1], c.eye[0]) % (2 * math.pi) for c in cams)
    assert np.allclose(np.diff(az), 2 * math.pi / 6)
    # around a camera: keeps its target, distance and size
    base = Camera.look_at((0, -5, 1), (0, 0, 1), fov=30, width=20, height=10)
    around = list(orbit(base, 4, elevation=0))
    assert np.allclose(around[0].eye, base.eye)
    for c in around:
        assert np.allclose(c.target, base.target) and (c.width, c.height, c.fov) == (20, 10, 30)
        assert math.isclose(np.linalg.norm(c.eye - c.target), 5)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(eye=(0, 0, 0), target=(0, 0, 0)), "eye and target must differ"),
        (dict(eye=(0, 0, 5), target=(0, 0, 0)), "parallel"),
        (dict(eye=(1, 0, 0), target=(0, 0, 0), up=(0, 0, 0)), "up"),
        (dict(eye=(1, 0, 0), target=(0, 0, 0), fov=0), "fov"),
        (dict(eye=(1, 0, 0), target=(0, 0, 0), fov=180), "fov"),
        (dict(eye=(1, 0, 0), target=(0, 0, 0), fov=float("nan")), "fov"),
        (dict(eye=(1, 0, 0), target=(0, 0, 0), width=0), "image size"),
        (dict(eye=(1, 0, 0), target=(0, 0, 0), height=-3), "image size"),
        (dict(eye=(1, 0, 0), target=(0, 0, 0), width=2.5), "image size"),
        (dict(eye=(float("nan"), 0, 0), target=(0, 0, 0)), "eye must be finite"),
        (dict(eye=(1, 0), target=(0, 0, 0)), "eye must be 3 numbers"),
        (dict(eye=(1, 0, 0), target=(0, float("inf"), 0)), "target must be finite"),
    ],
)
def test_validation(kwargs, message):
    with pytest.raises(UsageError, match=message) as e:
        Camera.look_at(**kwargs)
    assert "\n" not in str(e.value)


def test_fit_and_orbit_validation():
    with pytest.raises(UsageError):
        Camera.fit(np.array([[0, 0, 0], [np.nan, 1, 1]]), 10, 10)
    with pytest.raises(UsageError):
        Camera.fit(np.zeros(3), 10, 10)
    with pytest.raises(UsageError, match="fill"):
        Camera.fit(np.array([[0, 0, 0], [1, 1, 1.0]]), 10, 10, fill=1.5)
    with pytest.raises(UsageError):
        list(orbit(np.array([[0, 0, 0], [1, 1, 1.0]]), 0))
    with pytest.raises(UsageError):
        list(orbit(np.array([[0, 0, 0], [1, 1, 1.0]]), 3, elevation=90))
