"""The sampling radius as users give it: in scene units (``0.05``) or relative to the scene's
size (``1%``: 1% of the diagonal of the scene's bound), for every command and the batch API."""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..errors import UsageError


@dataclass(frozen=True)
class Radius:
    """The sampling radius: ``value`` in scene units, or (``relative``) the fraction ``value``
    of the diagonal of the scene's bound, r = value * |hi - lo|."""

    value: float
    relative: bool = False

    @classmethod
    def parse(cls, spec, name: str = "radius") -> "Radius":
        """From a number (scene units), ``"0.05"`` or ``"1%"`` (1% of the bound's diagonal);
        ``name`` is what an error message calls it."""
        if isinstance(spec, Radius):
            return spec
        text = str(spec).strip()
        relative = text.endswith("%")
        try:
            v = float(text[:-1] if relative else text)
        except ValueError:
            raise UsageError(f"{name} must be a number or a percentage such as 1%, got {spec!r}") from None
        if not (math.isfinite(v) and v > 0):
            raise UsageError(f"{name} must be a positive finite number or percentage, got {spec!r}")
        return cls(v / 100 if relative else v, relative)

    def of(self, diagonal: float) -> float:
        """The radius for a scene whose bound has this diagonal."""
        return self.value * diagonal if self.relative else self.value

    def __str__(self) -> str:
        return f"{100 * self.value:g}%" if self.relative else f"{self.value:g}"
