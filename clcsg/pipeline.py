"""The one path every front end takes: scene -> compiled tape -> radius -> samples -> camera -> image.

``clcsg sample``, ``clcsg render``, the viewer and the batch workers all go through
:class:`Pipeline`, so each step has one rule:

* the scene is read by :func:`clcsg.readers.scenes.load` (the format from the file name);
* the tape is :meth:`Scene.compile <clcsg.model.scene.Scene.compile>`, compiled once per scene,
  bound and normal form (the radius and the sampler share it);
* the radius is :func:`resolve_radius`: scene units, or a fraction of the compiled bound's
  diagonal (:func:`bound_diagonal`), :data:`DEFAULT_RADIUS` when none is given;
* the camera is fitted to the solid's silhouette (:meth:`Camera.fit_silhouette
  <clcsg.rendering.camera.Camera.fit_silhouette>`) unless the caller gives one;
* the image is splats of the samples (:func:`clcsg.render`) or the exact ray tracer
  (:func:`clcsg.raytrace`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .model.scene import Scene
from .readers import scenes
from .sampling.radius import Radius
from .model.surfels import has_surfels
from .sampling.surfel_csg import proxy_scene, sample

if TYPE_CHECKING:
    from .rendering.camera import Camera

#: the radius when none is given: 1% of the diagonal of the scene's bound
DEFAULT_RADIUS = Radius(0.01, relative=True)


def bound_diagonal(bound) -> float:
    """|hi - lo| of a scene bound; 1 when it is missing, empty or degenerate (a relative radius
    then means that fraction of one scene unit)."""
    if bound is None:
        return 1.0
    d = float(np.linalg.norm(np.asarray(bound[1], dtype=np.float64) - np.asarray(bound[0], dtype=np.float64)))
    return d if d > 0 and math.isfinite(d) else 1.0


def resolve_radius(radius, bound) -> float:
    """The sampling radius in scene units for a scene of this bound: ``radius`` is a
    :class:`~clcsg.sampling.radius.Radius`, a number or text such as ``"1%"`` (None:
    :data:`DEFAULT_RADIUS`); a relative radius is r = value * :func:`bound_diagonal`."""
    spec = DEFAULT_RADIUS if radius is None else Radius.parse(radius)
    return spec.of(bound_diagonal(bound))


@dataclass
class Pipeline:
    """One scene on one device: ``Pipeline(scene, ctx).samples("1%")``, then
    :meth:`camera` and :meth:`image`.  ``normal_form`` / ``term_limit`` choose the tape
    (the CSG tree, or the paper's DNF)."""

    scene: Scene
    device: object = None  # a clcsg.cl.device context, a device spec or None (the default)
    normal_form: str = "tree"
    term_limit: int | None = None

    @classmethod
    def load(cls, path, bound=None, **kw) -> "Pipeline":
        """The pipeline of the scene file ``path`` (``bound``, (2, 3) or None, overrides its own)."""
        return cls(scenes.as_scene(scenes.load(path), bound), **kw)

    @property
    def tape(self):
        """The compiled tape (compiled on first use, then cached by the scene).  With point
        operands it is the tape of :func:`~clcsg.sampling.surfel_csg.proxy_scene` (each replaced
        by its box): the bound and the camera fit use it; the samples do not."""
        if has_surfels(self.scene.shape):
            if getattr(self, "_proxy", None) is None:
                self._proxy = proxy_scene(self.scene)
            return self._proxy.compile(self.normal_form, self.term_limit)
        return self.scene.compile(self.normal_form, self.term_limit)

    def radius(self, radius=None) -> float:
        """:func:`resolve_radius` against the compiled bound (an absolute radius needs no compile)."""
        spec = DEFAULT_RADIUS if radius is None else Radius.parse(radius)
        if not spec.relative:
            return spec.value
        return resolve_radius(spec, None if self.tape.empty else self.tape.bound)

    def samples(self, radius=None, **options):
        """:func:`clcsg.sample` of the scene at :meth:`radius` (``options``: floor, max_samples,
        progress, ...)."""
        return sample(self.scene, self.radius(radius), device=self.device, normal_form=self.normal_form,
                      term_limit=self.term_limit, **options)

    def camera(self, width: int, height: int, fov: float = 45.0, up=(0.0, 0.0, 1.0), tape=None) -> Camera:
        """The default view: the solid's silhouette fitted into the image (a probe ray trace of
        ``tape``, by default the pipeline's)."""
        from .rendering.camera import Camera  # the renderers are not imported by sampling alone

        return Camera.fit_silhouette(self.tape if tape is None else tape, width, height, fov=fov, up=up,
                                     device=self.device)

    def image(self, camera: Camera, samples=None, method: str = "splat", **options):
        """The image of ``camera``: splats of ``samples`` (``method="splat"``) or the exact ray
        tracer of the tape (``"raytrace"``); ``options`` go to :func:`clcsg.render` /
        :func:`clcsg.raytrace` (background, aa, ...)."""
        from .rendering.raytracer import raytrace
        from .rendering.splat import render

        if method == "raytrace":  # a point operand is traced as the mesh of its surface
            tape = self.scene.compile(self.normal_form, self.term_limit)
            return raytrace(tape, camera, device=self.device, **options)
        return render(samples, camera, device=self.device, **options)
