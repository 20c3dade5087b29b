"""The level loop's forecast of the seconds left (the sampling bar's ETA), from the levels seen.

Pure arithmetic on the level history, no OpenCL and no clock: :class:`Forecast` is fed, level
by level, the cells the level had, the samples emitted so far, the children it queued and the
seconds it took, and answers the seconds left.  The sampler's progress (``_Progress`` in
:mod:`clcsg.sampling.sampler`) turns that into the bar's fraction; tests and ``python -m bench
progress`` replay recorded histories through it.

**Levels.**  A root cell of diagonal d_0 is split into four (both edges cut at SPLIT_AT, the
larger part s = SPLIT_LARGER of the edge) while its diagonal exceeds QUAD_SPLIT_DIAG radii,
then in two along its longest edge, which shrinks the diagonal by s every two levels.  With
n_q = ceil(log(d_0 / (QUAD_SPLIT_DIAG r)) / log(1 / s)) four-way levels for the largest root
cell and d_q = d_0 s^n_q, its cells reach a diagonal D after n_q + 2 log(d_q / D) / log(1 / s)
levels: the *peak level* at D = PEAK_DIAG r (2 radii: there the surface cells are resolved,
and the cells per level stop growing; within a level of the largest level on the runs of
``python -m bench progress``) and the *last level* at D = the floor (cells smaller than it are
dropped, so no level past it has cells; the floor is measured on the 3-D diagonal, slightly
larger, so this is about one level early: the forecast runs to its ceiling).

**Cells ahead.**  After a level of n cells with c children queued, the cells of the levels
ahead are c, c g, c g^2, ... up to the last level, with g = sqrt(c / n_prev) the growth over
the last two levels, kept in [1/2, 2] during the four-way levels (cells along a trimming curve
double when both edges halve) and in [1/2, sqrt 2] after (they double every two levels).
Before the peak the levels past it are forecast to halve (the cells left there are those along
trimming curves, most resolved within a few levels); once past it, the growth seen goes on: a
decline (curves resolving) or sqrt 2 (cells that stay undecided split down to the floor, the
tail that is half of the run on the gear, the rook and the pen stand).

**Samples ahead.**  The samples a level emits decline once the surface is resolved; with e the
samples of the last level and rho = e / e_prev < 1, the samples ahead are e rho / (1 - rho)
(rho at most 1/2: surface cells resolve at least half per level), at most the expected count
not yet emitted (:func:`clcsg.compile.bounds.estimates.expected_samples`), and exactly that
while the emission still grows (the early levels).

**Seconds.**  A level costs a + b (cells + SAMPLE_COST samples emitted): a the cheapest level
seen (launches, the counter read, the finish pass's fixed part), SAMPLE_COST the cost of
emitting and finishing a sample against classifying a cell (0.25-0.35 on PoCL CPU; one
parameter, since the early levels, with few cells and many samples, cannot separate the two),
and b fitted to the levels seen, weighted DECAY^age so it follows the cost per cell as the
tapes get shorter deeper down.  The first level is left out once there is another: it also
pays one-off costs (the program's first launch, the buffers' first use).
"""

from __future__ import annotations

import math

#: the cell diagonal, in radii, at which the surface cells are resolved (the peak level)
PEAK_DIAG = 2.0
#: weight of a level in the time fit per level of age
DECAY = 0.7
#: least and largest growth of the cells per level (see the module docstring)
GROWTH_MIN, GROWTH_QUAD, GROWTH_PAIR = 0.5, 2.0, math.sqrt(2)
#: the cost of a sample emitted over that of a cell classified (measured on PoCL CPU: 0.25-0.35)
SAMPLE_COST = 0.3
#: largest decline ratio of the samples per level once they decline
SAMPLES_DECLINE = 0.5


def level_bounds(root_diagonal: float, radius: float, floor: float, split_larger: float,
                 quad_split_diag: float) -> tuple[float, float, float]:
    """(four-way levels n_q, the peak level, at which cells reach PEAK_DIAG radii, the level
    ``last`` at which they reach the floor) for the largest root cell (module docstring)."""
    if not (root_diagonal > 0 and radius > 0 and floor > 0):
        return 0.0, 0.0, 0.0
    step = math.log(1 / split_larger)
    quad = 0
    if root_diagonal > quad_split_diag * radius:
        quad = math.ceil(math.log(root_diagonal / (quad_split_diag * radius)) / step)
    d = root_diagonal * split_larger ** quad
    return (float(quad), quad + max(0.0, 2 * math.log(d / (PEAK_DIAG * radius)) / step),
            quad + max(0.0, 2 * math.log(d / floor) / step))


class Forecast:
    """Seconds left of the level loop (module docstring).  ``estimate``: the expected sample
    count (0: unknown); ``quad`` and ``last`` from :func:`level_bounds` (``last`` None: no
    bound known, ``max_levels`` ends the tail)."""

    def __init__(self, estimate: int = 0, quad: float = 0.0, peak: float | None = None, last: float | None = None,
                 max_levels: int = 400):
        self.estimate = max(0, int(estimate))
        self.quad = quad
        self.peak = max_levels if peak is None else peak
        self.last = max_levels - 1 if last is None else min(max_levels - 1, math.ceil(last))
        self.max_levels = max_levels
        self.cells: list[int] = []
        self.emitted: list[int] = []
        self.seconds: list[float] = []
        self.samples = 0

    def add(self, cells: int, samples: int, seconds: float) -> None:
        """A level done: its cells, the samples emitted so far (after it), its seconds."""
        self.cells.append(int(cells))
        self.emitted.append(max(0, int(samples) - self.samples))
        self.samples = int(samples)
        self.seconds.append(max(0.0, float(seconds)))

    def cells_ahead(self, children: int) -> list[float]:
        """Forecast cells of the levels after the last one added."""
        if not children:
            return []
        h = self.cells
        g = (children / max(h[-2], 1)) ** 0.5 if len(h) > 1 else children / max(h[-1], 1)
        past = len(h) > self.peak
        n, out, lv = float(children), [], len(h)
        while n >= 1 and lv <= self.last:
            out.append(n)
            if lv < self.peak or past:
                n *= min(max(g, GROWTH_MIN), GROWTH_QUAD if lv < self.quad else GROWTH_PAIR)
            else:
                n *= GROWTH_MIN
            lv += 1
        return out

    def samples_ahead(self) -> float:
        """Forecast samples of the levels ahead (module docstring)."""
        left = max(0, self.estimate - self.samples) if self.estimate else None
        e = self.emitted[-1]
        prev = self.emitted[-2] if len(self.emitted) > 1 else 0
        if prev > 0 and e < prev:
            rho = min(e / prev, SAMPLES_DECLINE)
            tail = e * rho / (1 - rho)
            return tail if left is None else min(tail, left)
        if left is None or (left == 0 and e > 0):  # growing past the estimate, or nothing known
            return e * SAMPLES_DECLINE / (1 - SAMPLES_DECLINE)
        return left

    def costs(self) -> tuple[float, float, float]:
        """(a, b, c) of the level time model a + b cells + c samples (module docstring)."""
        secs, cells, emitted = self.seconds, self.cells, self.emitted
        a = min(secs)
        first = 1 if len(secs) > 1 else 0
        w = x = 0.0
        for i in range(first, len(secs)):
            age = DECAY ** (len(secs) - 1 - i)
            w += age * (secs[i] - a)
            x += age * (cells[i] + SAMPLE_COST * emitted[i])
        b = w / x if x > 0 else 0.0
        return a, b, SAMPLE_COST * b

    def seconds_left(self, children: int) -> float:
        """Forecast seconds of the levels after the last one added, given its children."""
        ahead = self.cells_ahead(children)
        if not ahead:
            return 0.0
        a, b, c = self.costs()
        return a * len(ahead) + b * sum(ahead) + c * self.samples_ahead()

