"""The scene a viewer shows: loaded from its file, compiled and sampled on one device, and
loaded again when the file (or a ``.scad`` file it includes or uses) changes.

A :class:`Session` holds the last good :class:`Model` (samples, tape, radius, timings) and the
message of the last failed load.  A failed load (a broken edit, a deleted file, a radius whose
sampling would pass the sample limit) leaves the model as it was, so the viewer keeps showing
it beside the error.  Every method that touches the device runs in the caller's thread; the
server calls them from its single device thread, one at a time.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field

from ..errors import ClcsgError
from ..pipeline import Pipeline
from ..sampling.radius import Radius
from ..readers.scenes import load
from ..readers.scad import load_scad
from ..readers.mesh_files import mesh_files

#: the viewer's default sample limit (the resource guard's; ``clcsg view --max-samples``)
DEFAULT_MAX_SAMPLES = 5_000_000


def parse_radius(value) -> Radius | None:
    """A radius from the page's control or ``--radius``: scene units or a percentage of the
    diagonal (:class:`~clcsg.sampling.radius.Radius`), or None for ``"auto"``."""
    if value is None or str(value).strip().lower() in ("", "auto"):
        return None
    return Radius.parse(value)


@dataclass
class Model:
    """One sampled version of the scene."""

    version: int
    scene: object  # clcsg.Scene
    samples: object  # clcsg.Samples
    radius: float
    auto: bool  # the radius is the automatic one
    times: dict = field(default_factory=dict)  # load_s, compile_s, sample_s, total_s
    #: seconds per traced pixel of the last exact frame that built no program (the viewer's
    #: prediction), None before
    raytrace_rate: float | None = None

    @property
    def tape(self):
        return self.samples.tape

    def summary(self) -> dict:
        """What the page's status line shows."""
        st = self.samples.stats
        return {"version": self.version, "samples": len(self.samples), "radius": self.radius, "auto_radius": self.auto,
                "quadrics": int(self.tape.n_quadrics), "empty": bool(self.tape.empty),
                "unresolved": int(st.get("unresolved", 0) or 0),
                **{k: round(v, 4) for k, v in self.times.items()}}


class Session:
    """The scene file ``path`` sampled on ``context``.

    ``radius``: None for the automatic radius (1/100 of the scene's diagonal, recomputed on
    every load), else a fixed one.  ``default_color``: the colour of primitives without one
    (``--colors``).  ``max_samples``: the resource guard's sample limit.  ``floor``: the
    sampler's floor (None: its default).
    """

    def __init__(self, path, context, radius: Radius | None = None, normal_form: str = "tree",
                 default_color=None, max_samples: int | None = None, floor: float | None = None):
        self.path = os.path.abspath(os.fspath(path))
        self.context = context
        self.radius = radius
        self.normal_form = normal_form
        self.default_color = default_color
        self.max_samples = DEFAULT_MAX_SAMPLES if max_samples is None else int(max_samples)
        self.floor = floor
        self.model: Model | None = None
        self.error: str | None = None
        self.files: list[str] = [self.path]
        self._version = 0

    @property
    def name(self) -> str:
        return os.path.basename(self.path)

    # -- loading ----------------------------------------------------------------------------------
    def read(self):
        """The scene from the file; for ``.scad`` also records the files OpenSCAD read."""
        if self.path.lower().endswith(".scad") and os.path.isfile(self.path):
            scene, deps = load_scad(self.path, with_dependencies=True)
            self.files = deps
            return scene
        scene = load(self.path)
        self.files = [self.path, *mesh_files(scene.shape)]
        return scene

    def sample(self, scene, radius: Radius | None, times: dict) -> Model:
        """A new model of ``scene`` at ``radius`` (None: automatic); raises ClcsgError."""
        pipe = Pipeline(scene, self.context, self.normal_form)
        t = time.perf_counter()
        pipe.tape  # compiled once; the radius and the sampler share it
        times["compile_s"] = time.perf_counter() - t
        r = pipe.radius(radius)
        t = time.perf_counter()
        samples = pipe.samples(r, progress=None, max_samples=self.max_samples, floor=self.floor)
        times["sample_s"] = time.perf_counter() - t
        if self.default_color is not None:
            samples.with_default_color(self.default_color)
        self._version += 1
        times["total_s"] = sum(times.values())
        return Model(self._version, scene, samples, r, radius is None, times)

    def load(self) -> Model:
        """Read, compile and sample the file; the new model replaces the old one.  Raises a
        ClcsgError (the model and ``error`` stay as they were)."""
        times: dict = {}
        t = time.perf_counter()
        scene = self.read()
        times["load_s"] = time.perf_counter() - t
        model = self.sample(scene, self.radius, times)
        self.model, self.error = model, None
        return model

    def reload(self) -> Model | None:
        """:meth:`load`, keeping the last good model on failure: returns the new model, or
        None with the one-line message in ``error``."""
        try:
            return self.load()
        except ClcsgError as e:
            self.error = " ".join(str(e).split()) or type(e).__name__
            return None

    def set_radius(self, value) -> Model | None:
        """Sample the current scene again at ``value`` (a number, or ``"auto"``/None).  Returns
        the new model, or None with the message in ``error`` (radius and model unchanged)."""
        try:
            radius = parse_radius(value)
            if self.model is None:
                self.radius = radius
                return self.load()
            model = self.sample(self.model.scene, radius, {"load_s": 0.0})
        except ClcsgError as e:
            self.error = " ".join(str(e).split()) or type(e).__name__
            return None
        self.radius, self.model, self.error = radius, model, None
        return model
