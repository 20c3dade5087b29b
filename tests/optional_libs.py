"""Optional libraries in tests: skipped where missing, a failure under CI (``.ci/run`` installs them)."""

from __future__ import annotations

import importlib
import os

import pytest


def require_module(name: str, install: str):
    """Import ``name``; skip the test without it, but fail under CI (``CI`` set)."""
    try:
        return importlib.import_module(name)
    except ImportError:
        if os.environ.get("CI"):
            pytest.fail(f"{name} is not installed under CI ({install})")
        pytest.skip(f"{name} is not installed (optional: {install})")
