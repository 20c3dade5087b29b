"""Shared fixtures.

``cl_context``: the session's OpenCL :class:`~clcsg.cl.device.Context`, chosen like the CLI
default (``PYOPENCL_CTX`` if set, else the first GPU, else the first CPU; never Oclgrind), so
``PYOPENCL_CTX=1:0 pytest`` runs the same tests on another device.  Without any OpenCL device
the tests that use it are skipped, except under CI (``CI`` set), where that is a failure.

Tests marked ``oclgrind`` (the kernels under the simulator, ~1000x slower than a device) are
deselected unless ``CLCSG_OCLGRIND=1``: CI runs them as a job of their own, not as skips.
Optional libraries: ``optional_libs.require_module``.

``tmp_scene``: ``tmp_scene(shape_or_scene, name="scene.json") -> path`` writes a scene file
into the test's tmp_path.
"""

from __future__ import annotations

import os

import pytest

try:
    from hypothesis import HealthCheck, settings

    # kernel builds make the first example of a test slow: no per-example deadline; CI runs
    # are derandomized so a failure reproduces.
    settings.register_profile("dev", deadline=None, print_blob=True)
    settings.register_profile(
        "ci", deadline=None, print_blob=True, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
    )
    settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci" if os.environ.get("CI") else "dev"))
except ImportError:  # pragma: no cover - hypothesis is in the [test] extra
    pass


def pytest_collection_modifyitems(config, items):
    if os.environ.get("CLCSG_OCLGRIND") == "1":
        return
    chosen, deselected = [], []
    for item in items:
        (deselected if item.get_closest_marker("oclgrind") else chosen).append(item)
    if deselected:
        config.hook.pytest_deselected(items=deselected)
        items[:] = chosen


@pytest.fixture(scope="session")
def cl_context():
    from clcsg.errors import DeviceError
    from clcsg.cl.device import get_context

    try:
        return get_context()
    except DeviceError as e:
        if os.environ.get("CI"):
            pytest.fail(f"no usable OpenCL device under CI: {e}")
        pytest.skip(f"no usable OpenCL device: {e}")


@pytest.fixture
def tmp_scene(tmp_path):
    """A function writing a Shape or Scene to a scene file in tmp_path; returns the path."""
    from clcsg.readers.scenes import save

    def write(obj, name: str = "scene.json"):
        path = tmp_path / name
        save(obj, path)
        return path

    return write
