"""A scene: a CSG shape plus the optional bound that unbounded terms are clipped to.

Scene files are read and written by :mod:`clcsg.readers.scenes` (``clcsg.load``, ``clcsg.save``).
:meth:`Scene.compile` and :meth:`Scene.normalize` are the one place where the model reaches up
to ``compile``: they import it when called, so the model imports nothing of ours above it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import UsageError
from .csg import Shape


@dataclass
class Scene:
    shape: Shape
    bound: np.ndarray | None = None  # (2, 3) lo, hi corners, or None
    source: str = "scene"  # file name or description, used in error messages
    _tapes: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self):
        if not isinstance(self.shape, Shape):
            hint = "; a scene file is read with clcsg.load(path)" if isinstance(self.shape, (str, bytes)) else ""
            raise UsageError(f"Scene: the shape must be a clcsg Shape, not {type(self.shape).__name__} "
                             f"{self.shape!r:.60}{hint}")

    def compile(self, normal_form: str = "tree", term_limit: int | None = None):
        """The scene's :class:`~clcsg.compile.tape.Tape`: the CSG tree itself (``"tree"``, the
        default) or the paper's disjunctive normal form as an OR of ANDs (``"dnf"``; the term
        limit applies to it only).  Compiled once per (shape, bound, normal form, term limit):
        the callers that need the bound before sampling (a relative radius, the viewer, the
        batch tasks) and the sampler share one tape."""
        from ..compile.tape import compile_scene

        bound = None if self.bound is None else np.asarray(self.bound, dtype=np.float64).tobytes()
        key = (bound, normal_form, term_limit)
        shape, tape = self._tapes.get(key, (None, None))
        if shape is not self.shape:
            tape = compile_scene(self, normal_form, term_limit)
            self._tapes[key] = (self.shape, tape)
        return tape

    def normalize(self, term_limit: int | None = None):
        """The scene's :class:`~clcsg.compile.dnf.Dnf`."""
        from ..compile.dnf import DEFAULT_TERM_LIMIT, normalize

        return normalize(
            self.shape,
            term_limit=DEFAULT_TERM_LIMIT if term_limit is None else term_limit,
            user_bound=self.bound,
            source=self.source,
        )
