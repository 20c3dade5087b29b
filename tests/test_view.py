"""``clcsg view``: the web viewer as a real subprocess, driven by a websocket client that speaks the
page's protocol and by headless Chromium (selenium) on the real page.

* Frames arrive and show the model; orbiting changes them; the ray tracer toggle gives the same
  picture; a resting frame is followed by a supersampled one.
* Live reload: an edit of the scene (or of a ``.scad`` file it includes) shows the new model;
  a broken edit or a deleted file is a message in the page and one line on the terminal, the
  last good model stays and the server keeps running.
* Bad input stays clean: a port in use, a huge or tiny radius, malformed requests, missing
  packages, a missing openscad or a syntax error in the ``.scad`` file.
* Nobody else gets in: 127.0.0.1 only, nothing served but the assets (path traversal is 404),
  foreign Host headers and websocket Origins are 403, the downloads need the page's token.

Tests that need openscad or Chromium fail under CI ($CI set: .ci/run installs them) and are
skipped with a reason elsewhere.
"""

from __future__ import annotations

import asyncio
import http.client
import io
import json
import os
import shutil
import socket
import time
import urllib.parse

import numpy as np
import pytest

import clcsg

from viewer_client import Page, ViewProcess, decode, http_get, run_view

pytest.importorskip("aiohttp", reason="clcsg view needs the view extra (aiohttp)")
pytest.importorskip("watchfiles", reason="clcsg view needs the view extra (watchfiles)")

PART = clcsg.box(2) - clcsg.cylinder(3, 0.5)
RED_BALL = clcsg.sphere(1.0, color=(0.9, 0.1, 0.1))


def _need(what: str, found) -> None:
    if not found:
        if os.environ.get("CI"):
            pytest.fail(f"{what} is missing under CI (.ci/run installs it)")
        pytest.skip(f"{what} is not installed")


def _one_error_line(text: str) -> str:
    lines = [ln for ln in text.splitlines() if ln.strip()]
    assert len(lines) == 1, f"expected one line, got {lines}"
    assert lines[0].startswith("clcsg: error: ")
    return lines[0]


def run_async(coro):
    return asyncio.run(coro)


@pytest.fixture(scope="module")
def served(tmp_path_factory, cl_context):
    """A `clcsg view part.json` server for the whole module: (process, scene path)."""
    work = tmp_path_factory.mktemp("view")
    scene = work / "part.json"
    clcsg.save(PART, scene)
    with ViewProcess(scene, work) as proc:
        yield proc, scene
    assert proc.proc.returncode == 0, proc.stderr()
    assert "stopped after" in proc.stdout()


# -- nobody else gets in ---------------------------------------------------------------------------


def test_listens_on_loopback_127_0_0_1_only(served):
    proc, _ = served
    with socket.create_connection(("127.0.0.1", proc.port), timeout=5):
        pass
    with pytest.raises(OSError):  # another loopback address: nothing listens there
        socket.create_connection(("127.0.0.2", proc.port), timeout=5).close()
    assert "127.0.0.1" in proc.url


def _raw_get(port: int, path: str, host: str | None = None) -> int:
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
    conn.putrequest("GET", path, skip_host=True)
    conn.putheader("Host", host or f"127.0.0.1:{port}")
    conn.endheaders()
    status = conn.getresponse().status
    conn.close()
    return status


def test_serves_only_its_assets(served):
    proc, scene = served
    status, body, headers = http_get(proc.url)
    assert status == 200 and b"clcsg-token" in body and headers["Content-Type"].startswith("text/html")
    assert "default-src 'self'" in headers["Content-Security-Policy"]
    status, body, headers = http_get(proc.url + "viewer.js")
    assert status == 200 and b"WebSocket" in body and "javascript" in headers["Content-Type"]
    for path in ("/../../etc/passwd", "/%2e%2e/%2e%2e/etc/passwd", "/viewer.js/../../../../etc/passwd",
                 "/..%2f..%2fetc%2fpasswd", "//etc/passwd", "/assets/index.html", "/index.html",
                 f"/{scene.name}", f"/{scene}", "/save/../../etc/passwd", "/ws/../../etc/passwd"):
        assert _raw_get(proc.port, path) == 404, path


def test_foreign_host_header_is_forbidden(served):
    proc, _ = served
    assert _raw_get(proc.port, "/", host="evil.example") == 403  # DNS rebinding
    assert _raw_get(proc.port, "/", host=f"localhost:{proc.port}") == 200


def test_websocket_needs_own_origin_and_token(served):
    import aiohttp

    proc, _ = served
    page = Page(proc.url)

    async def status(origin, token):
        async with aiohttp.ClientSession() as s:
            try:
                kw = {"origin": origin} if origin else {}
                async with s.ws_connect(f"ws://127.0.0.1:{proc.port}/ws?token={token}", **kw):
                    return 101
            except aiohttp.WSServerHandshakeError as e:
                return e.status

    own = proc.url.rstrip("/")
    assert run_async(status("http://evil.example", page.token)) == 403
    assert run_async(status(f"http://127.0.0.1:{proc.port + 1}", page.token)) == 403
    assert run_async(status(None, page.token)) == 403
    assert run_async(status(own, "wrong")) == 403
    assert run_async(status(own, page.token)) == 101


def test_downloads_need_the_token(served):
    proc, _ = served
    page = Page(proc.url)
    view = run_async(_fitted(proc.url))
    q = "view=" + urllib.parse.quote(json.dumps(view)) + "&width=64&height=48"
    assert http_get(f"{proc.url}save/view.png?{q}")[0] == 403
    status, body, headers = http_get(f"{proc.url}save/view.png?token={page.token}&{q}&aa=3")
    assert status == 200 and body.startswith(b"\x89PNG") and "attachment" in headers["Content-Disposition"]
    assert decode(body).shape == (48, 64, 3)
    status, body, _ = http_get(f"{proc.url}save/view.npz?token={page.token}&{q}")
    arrays = np.load(io.BytesIO(body))
    assert arrays["rgba"].shape == (48, 64, 4) and arrays["depth"].dtype == np.float32
    assert (arrays["ids"] >= 0).any() and np.isfinite(arrays["depth"][arrays["ids"] >= 0]).all()
    status, body, _ = http_get(f"{proc.url}save/samples.ply?token={page.token}")
    assert status == 200 and body.startswith(b"ply\n")
    plyfile = pytest.importorskip("plyfile")
    assert len(plyfile.PlyData.read(io.BytesIO(body))["vertex"]) > 100
    status, body, _ = http_get(f"{proc.url}save/view.png?token={page.token}&view=nonsense&width=64&height=48")
    assert status == 400 and b"view" in body


# -- frames ----------------------------------------------------------------------------------------


async def _fitted(url):
    async with Page(url) as page:
        return (await page.hello())[1]


def _covered(img) -> np.ndarray:
    return np.any(img < 235, axis=-1)  # the background is white


def test_frames_show_the_model_and_orbit_changes_them(served, cl_context):
    from clcsg.viewer.frames import camera_of

    proc, _ = served

    async def body():
        async with Page(proc.url) as page:
            scene, view = await page.hello()
            assert scene["model"]["samples"] > 100 and scene["model"]["quadrics"] == 9 and scene["error"] is None
            header, data = await page.frame(view, 80, 60, quality="drag")
            assert header["format"] == "jpeg" and decode(data).shape == (60, 80, 3)
            header, data = await page.frame(view)
            assert header["format"] == "png" and header["aa"] == 1
            rest = decode(data)
            assert 0.1 < _covered(rest).mean() < 0.9
            refined, data = await page.receive(("frame",))  # the supersampled resting frame
            assert refined["id"] == header["id"] and refined["aa"] > 1
            smooth = decode(data)
            assert np.abs(smooth.astype(int) - rest.astype(int)).max() > 20  # smoothed edges
            turned = dict(view, azimuth=view["azimuth"] + 40)
            _, data = await page.frame(turned)
            other = decode(data)
            assert (_covered(other) != _covered(rest)).mean() > 0.02
            header, data = await page.frame(view, method="raytrace")
            exact = decode(data)
            assert (_covered(exact) != _covered(rest)).mean() < 0.02  # the splats' picture
            # the ray tracer's picture at the frame's supersampling (PNG: lossless)
            traced = clcsg.raytrace(PART, camera_of(view, 160, 120), device=cl_context, aa=header["aa"])
            assert np.array_equal(exact, traced.rgba[..., :3])

    run_async(body())


def test_bad_requests_get_a_message_and_the_server_keeps_serving(served):
    proc, _ = served

    async def body():
        async with Page(proc.url) as page:
            _, view = await page.hello()
            for bad in ({"width": 100000}, {"view": {"target": [0, 0]}}, {"view": dict(view, distance=-1)},
                        {"view": dict(view, fov="wide")}, {"method": "magic"}):
                req = {"view": view, "width": 40, "height": 30, **bad}
                got = await page.frame(**req)
                assert isinstance(got, dict) and got["type"] == "error" and got["message"], bad
            await page.ws.send_str("not json")
            assert (await page.receive(("error",)))["message"].startswith("unknown message")
            header, _ = await page.frame(view, 40, 30)
            assert header["covered"] > 0

    run_async(body())
    assert proc.alive()


def test_radius_control_huge_tiny_and_auto(served):
    proc, _ = served

    async def body():
        async with Page(proc.url) as page:
            scene, view = await page.hello()
            auto = scene["model"]["radius"]
            await page.send(type="radius", value="1e6")
            huge = await page.receive(("scene", "error"))
            assert huge["type"] == "scene" and huge["model"]["radius"] == 1e6 and not huge["model"]["auto_radius"]
            header, _ = await page.frame(view, 40, 30)
            assert header["covered"] > 0 and header["version"] == huge["model"]["version"]
            for bad in ("1e-7", "-1", "nan", "lots"):
                await page.send(type="radius", value=bad)
                err = await page.receive(("scene", "error"))
                assert err["type"] == "error" and "radius" in err["message"], bad
            header, _ = await page.frame(view, 40, 30)  # the last good model stays
            assert header["version"] == huge["model"]["version"]
            await page.send(type="radius", value="auto")
            back = await page.receive(("scene", "error"))
            assert back["type"] == "scene" and back["model"]["radius"] == auto and back["model"]["auto_radius"]

    run_async(body())
    assert proc.alive()


def test_broken_edit_and_deleted_file_keep_the_last_good_model(served):
    proc, scene = served
    good = scene.read_text()

    async def body():
        async with Page(proc.url) as page:
            first, view = await page.hello()
            scene.write_text(good.replace("{", "{{", 1))  # a JSON syntax error
            err = await page.receive(("error", "scene"))
            assert err["type"] == "error" and scene.name in err["message"]
            header, _ = await page.frame(view, 40, 30)
            assert header["version"] == first["model"]["version"] and header["covered"] > 0
            scene.unlink()
            err = await page.receive(("error", "scene"))
            assert err["type"] == "error" and "no such file" in err["message"]
            clcsg.save(RED_BALL, scene)
            new = await page.receive(("scene", "error"))
            assert new["type"] == "scene" and new["error"] is None and new["model"]["quadrics"] == 1
            _, data = await page.frame(view, 80, 60)
            img = decode(data).astype(int)
            assert ((img[..., 0] - img[..., 1]) > 60).sum() > 50  # the red ball is on screen
            scene.write_text(good)
            assert (await page.receive(("scene",)))["model"]["quadrics"] == 9

    try:
        run_async(body())
    finally:
        scene.write_text(good)
    assert proc.alive()
    warnings = [ln for ln in proc.stderr().splitlines() if "reload failed" in ln]
    assert len(warnings) >= 2 and all(ln.startswith("clcsg: warning: reload failed") for ln in warnings)


# -- clean errors on the terminal ------------------------------------------------------------------


def test_port_in_use_is_one_line(served, tmp_path):
    proc, scene = served
    t = time.monotonic()
    r = run_view(scene, tmp_path, "--port", str(proc.port))
    assert r.returncode == 2 and time.monotonic() - t < 30
    assert "already in use" in _one_error_line(r.stderr)


def test_missing_packages_are_one_line(tmp_path):
    scene = tmp_path / "part.json"
    clcsg.save(PART, scene)
    code = ("import sys; sys.modules['aiohttp'] = None; from clcsg.cli.app import main; "
            f"sys.exit(main(['view', {str(scene)!r}, '--no-browser']))")
    import subprocess
    import sys

    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2
    assert "pip install 'clcsg[view]'" in _one_error_line(r.stderr)


# -- .scad in --------------------------------------------------------------------------------------


def _openscad():
    from clcsg.errors import SceneError
    from clcsg.readers.scad import find_openscad

    try:
        return find_openscad()
    except SceneError:
        _need("openscad", None)


def test_scad_errors_are_one_line(tmp_path):
    _openscad()
    model = tmp_path / "model.scad"
    model.write_text("cube(1);\n")
    r = run_view(model, tmp_path, env={"OPENSCAD": str(tmp_path / "nowhere" / "openscad")})
    assert r.returncode == 3 and "OpenSCAD not found" in _one_error_line(r.stderr)
    model.write_text("cube(1\n")
    r = run_view(model, tmp_path)
    line = _one_error_line(r.stderr)
    assert r.returncode == 3 and "model.scad" in line and "syntax error" in line.lower()


def test_scad_reloads_when_an_included_file_changes(tmp_path, cl_context):
    _openscad()
    (tmp_path / "parts.scad").write_text("module part() { cube(1, center=true); }\n")
    main = tmp_path / "main.scad"
    main.write_text("use <parts.scad>\npart();\n")

    async def body(proc):
        async with Page(proc.url) as page:
            scene, view = await page.hello()
            assert scene["model"]["quadrics"] == 6 and "parts.scad" in scene["files"]
            header, _ = await page.frame(view, 40, 30)
            assert header["covered"] > 0
            (tmp_path / "parts.scad").write_text("module part() { sphere(1); }\n")
            new = await page.receive(("scene", "error"))
            assert new["type"] == "scene" and new["model"]["quadrics"] == 1
            (tmp_path / "parts.scad").write_text("module part() { sphere(1) }\n")  # a syntax error
            err = await page.receive(("scene", "error"))
            assert err["type"] == "error" and "parts.scad" in err["message"]
            header, _ = await page.frame(view, 40, 30)
            assert header["version"] == new["model"]["version"]

    with ViewProcess(main, tmp_path) as proc:
        run_async(body(proc))
        assert proc.alive()
    assert proc.proc.returncode == 0


# -- the page in a real browser --------------------------------------------------------------------


def _browser():
    chromium = next((p for p in map(shutil.which, ("chromium", "chromium-browser", "google-chrome")) if p), None)
    driver = shutil.which("chromedriver")
    _need("chromium and chromium-driver", chromium and driver)
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.options import Options
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        _need("selenium (the test extra)", None)
    opts = Options()
    opts.binary_location = chromium
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--window-size=420,360"):
        opts.add_argument(arg)
    return webdriver.Chrome(service=Service(driver), options=opts)


PIXELS_JS = """
const c = document.getElementById('view'), d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
let covered = 0, red = 0, hash = 0;
for (let i = 0; i < d.length; i += 4) {
  if (d[i] < 235 || d[i + 1] < 235 || d[i + 2] < 235) { covered++; hash = (hash * 31 + (i >> 2)) >>> 0; }
  if (d[i] - d[i + 1] > 60) red++;
}
return {covered, red, hash, pixels: c.width * c.height, state: window.clcsgViewer.last,
        version: window.clcsgViewer.model && window.clcsgViewer.model.version};
"""


def _wait_for(driver, predicate, what, timeout=60.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        px = driver.execute_script(PIXELS_JS)
        if px["state"] and predicate(px):
            return px
        time.sleep(0.1)
    raise AssertionError(f"timed out waiting for {what}; last: {px}, status: "
                         f"{driver.find_element('id', 'status').text!r}")


def test_page_in_headless_chromium(tmp_path, cl_context):
    scene = tmp_path / "part.json"
    clcsg.save(PART, scene)
    driver = _browser()
    try:
        with ViewProcess(scene, tmp_path) as proc:
            driver.get(proc.url)
            first = _wait_for(driver, lambda p: p["state"]["quality"] == "rest", "a first frame")
            assert 0.05 < first["covered"] / first["pixels"] < 0.95 and first["red"] == 0
            assert "samples" in driver.find_element("id", "status").text
            from selenium.webdriver.common.action_chains import ActionChains

            canvas = driver.find_element("id", "view")
            last_id = first["state"]["id"]
            ActionChains(driver).move_to_element(canvas).click_and_hold().move_by_offset(60, 10) \
                .move_by_offset(40, 0).release().perform()
            turned = _wait_for(driver, lambda p: p["state"]["id"] > last_id and p["state"]["quality"] == "rest",
                               "a frame after dragging")
            assert turned["hash"] != first["hash"]
            exact = driver.find_element("id", "exact")
            exact.click()  # the first exact frame of the model: full size and supersampled (it is cheap)
            traced = _wait_for(driver, lambda p: p["state"]["method"] == "raytrace", "an exact frame")
            st, size = traced["state"], driver.execute_script("const c = document.getElementById('view'); "
                                                               "return [c.width, c.height];")
            assert [st["width"], st["height"]] == size and not st["reduced"] and st["aa"] >= 2, st
            assert abs(traced["covered"] - turned["covered"]) < 0.1 * turned["covered"]
            exact.click()
            clcsg.save(RED_BALL, scene)
            red = _wait_for(driver, lambda p: p["red"] > 50, "the edited model")
            assert red["version"] > 1
            assert not driver.find_element("id", "error").is_displayed()
            scene.write_text("{ not json")
            _wait_for(driver, lambda p: driver.find_element("id", "error").is_displayed(), "the error message")
            assert scene.name in driver.find_element("id", "error").text
            assert driver.execute_script(PIXELS_JS)["red"] > 50  # the last good model stays
    finally:
        driver.quit()


def test_exact_frames_full_size_and_antialiased_at_rest(tmp_path, cl_context):
    """The first exact frame is traced at full size; later ones are predicted from the last
    warm one: full size and supersampled at rest while they fit, smaller only past the budget."""
    from clcsg.viewer import frames
    from clcsg.viewer.session import Session

    scene = tmp_path / "part.json"
    clcsg.save(PART, scene)
    model = Session(scene, cl_context).load()
    view = frames.fitted_view(model.samples, 160, 120)
    cam = frames.camera_of(view, 160, 120)
    assert model.raytrace_rate is None and frames.raytrace_camera(model, cam) is cam
    req = {"view": view, "width": 160, "height": 120, "method": "raytrace", "quality": "rest", "id": 1}
    _, first = frames.frame(cl_context, model, req)
    assert (first["width"], first["height"]) == (160, 120) and not first["reduced"]
    assert model.raytrace_rate > 0
    model.raytrace_rate = 1e-8  # a fast ray tracer: full size, the rest frame supersampled
    _, rest = frames.frame(cl_context, model, req)
    assert not rest["reduced"] and rest["aa"] == max(frames.REST_AA)
    _, drag = frames.frame(cl_context, model, {**req, "quality": "drag"})
    assert drag["aa"] == 1 and not drag["reduced"]
    model.raytrace_rate = 1.0  # far past the budget: the smallest size
    small = frames.raytrace_camera(model, cam)
    assert (small.width, small.height) == (160 // frames.MIN_SCALE, 120 // frames.MIN_SCALE)
    assert np.allclose(small.eye, cam.eye) and small.fov == cam.fov
    _, reduced = frames.frame(cl_context, model, req)
    assert reduced["reduced"] and reduced["aa"] == 1



TWO_CUBES = clcsg.box(1.0) | clcsg.box(1.0, center=(1.5, 0, 0))


def test_first_exact_resting_frame_is_full_size_and_supersampled(tmp_path, cl_context):
    """After the viewer's warm-up, the first resting exact 800x600 frame of a cheap view (two
    cubes from three times the fitted distance: a plain trace takes tens of ms, its 2x2
    supersampled estimate a fraction of the budget even on a loaded machine) comes at full
    size and supersampled: the plain render that makes the prediction is timed warm."""
    from clcsg.viewer import frames
    from clcsg.viewer.session import Session

    scene = tmp_path / "cubes.json"
    clcsg.save(TWO_CUBES, scene)
    model = Session(scene, cl_context).load()
    frames.warm_up(cl_context, model)
    view = frames.fitted_view(model.samples, 800, 600)
    view["distance"] *= 3
    req = {"view": view, "width": 800, "height": 600, "method": "raytrace", "quality": "rest", "id": 1}
    data, first = frames.frame(cl_context, model, req)
    assert (first["width"], first["height"], first["reduced"]) == (800, 600, False)
    assert first["aa"] >= 2 and model.raytrace_rate > 0
    img = decode(frames.unpack(data)[1])
    cam = frames.camera_of(view, 800, 600)
    smooth = frames.render(cl_context, model, cam, "raytrace", first["aa"], complete=False).rgba[..., :3]
    plain = frames.render(cl_context, model, cam, "raytrace", complete=False).rgba[..., :3]
    assert np.array_equal(img, smooth)  # the PNG is lossless: the frame is the supersampled trace
    edge = np.any(img != plain, axis=-1)
    assert 0 < edge.mean() < 0.05  # the filter changed the edge pixels only
