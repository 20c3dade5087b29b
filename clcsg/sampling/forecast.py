"""The level loop's forecast of the seconds left (the sampling bar's ETA), from the levels seen.

Pure arithmetic on the level history, no OpenCL and no clock: :class:`Forecast` is fed, level
by level, the cells the level had, the samples emitted so far, the children it queued and the
seconds it took, and answers the seconds left.  The sampler's progress (``_Progress`` in
:mod:`clcsg.sampling.sampler`) turns that into the bar's fraction; tests and ``python -m bench
progress`` replay recorded histories through it.

**Levels.**  A root cell of diagonal d_0 is split into four (the edges cut at SPLIT_AT and
SPLIT_AT_Y, the larger part at most s = SPLIT_LARGER of the edge) while its diagonal exceeds
QUAD_SPLIT_DIAG radii, then in two along its longest edge, which shrinks the diagonal by s every
two levels.  With n_q = ceil(log(d_0 / (QUAD_SPLIT_DIAG r)) / log(1 / s)) four-way levels for
the largest root cell and d_q = d_0 s^n_q, its cells reach a diagonal D after
n_q + 2 log(d_q / D) / log(1 / s) levels: the *peak level* at D = PEAK_DIAG r (2 radii: the
surface cells are resolved about there, and the cells per level stop growing) and the *last
level* at D = the floor, rounded (cells smaller than it are dropped; the floor is measured on
the cell's 3-D diagonal, so the level is right within one on the runs of ``python -m bench
progress``).

**Cells ahead.**  After a level of n cells with c children queued, the cells of the levels
ahead are c, c g_1, c g_1 g_2, ... up to the last level, with g = sqrt(c / n_prev) the growth
over the last two levels.  Before the peak g is kept in [1/2, 2] during the four-way levels
(cells along a trimming curve double when both edges halve) and in [1/2, sqrt 2] after (they
double every two levels).  Past the peak the cells left are of two kinds: surface still being
resolved, while the level emits at least SURFACE_SHARE of the most samples a level emitted
(the sponge, the plate), which declines (g kept in [1/4, 1/2]); or cells along trimming curves
that stay undecided and split down to the floor (the gear, the rook, the pen stand: half of
their run), which grow (g kept in [1.2, sqrt 2]).  A forecast made before the peak takes the
levels past it to shrink by PAST_PEAK_SURFACE or PAST_PEAK_TAIL per level by the same test.
The cells of the last level are dropped, not split: they cost FLOOR_COST of a cell.

**Samples ahead.**  While the samples per level still grow, the expected count not yet emitted
(:func:`clcsg.compile.bounds.estimates.expected_samples`); once past their peak, a halving per
level (as many again as the last level emitted), at most the expected count left.

**Seconds.**  A level costs a + b (cells + SAMPLE_COST samples emitted): a the cheapest level
seen (the launch and the counter read), SAMPLE_COST the cost of
emitting and finishing a sample against classifying a cell (0.25-0.35 on PoCL CPU; one
parameter, since the early levels, with few cells and many samples, cannot separate the two),
and b fitted to the levels seen, weighted DECAY^age so it follows the cost per cell as the
tapes get shorter deeper down.  The first level is left out once there is another: it also
pays one-off costs (the program's first launch, the root tapes at full length).

The constants were chosen on the recorded level histories of ``python -m bench progress``
(replayed through this class); they are rules of thumb of the subdivision, not fits to a
machine, SAMPLE_COST aside.
"""

from __future__ import annotations

import math

#: the cell diagonal, in radii, at which the surface cells are resolved (the peak level)
PEAK_DIAG = 2.0
#: weight of a level in the time fit per level of age
DECAY = 0.7
#: least and largest growth of the cells per level before the peak (see the module docstring)
GROWTH_MIN, GROWTH_QUAD, GROWTH_PAIR = 0.5, 2.0, math.sqrt(2)
#: growth of the undecided tail past the peak, at least and at most
TAIL_MIN, TAIL_MAX = 1.2, math.sqrt(2)
#: decline per level of cells still resolving surface past the peak, at least and at most
DECLINE_MIN, DECLINE_MAX = 0.25, 0.5
#: the levels past the peak, forecast before it: decline while resolving surface, else the tail
PAST_PEAK_SURFACE, PAST_PEAK_TAIL = 0.5, 0.71
#: a level resolves surface while it emits at least this share of the most samples a level emitted
SURFACE_SHARE = 0.2
#: the cost of a sample emitted over that of a cell classified (measured on PoCL CPU: 0.25-0.35)
SAMPLE_COST = 0.3
#: the cost of a cell at the floor's level (dropped, not split) over that of a cell split
FLOOR_COST = 0.5
#: decline per level of the samples emitted once past their peak
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
    count (0: unknown); ``quad``, ``peak`` and ``last`` from :func:`level_bounds` (None: not
    known; ``max_levels`` then ends the tail)."""

    def __init__(self, estimate: int = 0, quad: float = 0.0, peak: float | None = None, last: float | None = None,
                 max_levels: int = 400):
        self.estimate = max(0, int(estimate))
        self.quad = quad
        self.peak = max_levels if peak is None else peak
        self.last = max_levels - 1 if last is None else min(max_levels - 1, math.floor(last + 0.5))
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
        # still resolving surface (a good share of the most samples a level emitted), or the
        # undecided cells along trimming curves that split down to the floor
        surface = self.emitted[-1] >= SURFACE_SHARE * max(self.emitted)
        n, out, lv = float(children), [], len(h)
        while n >= 1 and lv <= self.last:
            out.append(n)
            if past and surface:
                n *= min(max(g, DECLINE_MIN), DECLINE_MAX)
            elif past:
                n *= min(max(g, TAIL_MIN), TAIL_MAX)
            elif lv < self.peak:
                n *= min(max(g, GROWTH_MIN), GROWTH_QUAD if lv < self.quad else GROWTH_PAIR)
            else:
                n *= PAST_PEAK_SURFACE if surface else PAST_PEAK_TAIL
            lv += 1
        return out

    def samples_ahead(self) -> float:
        """Forecast samples of the levels ahead (module docstring)."""
        e = self.emitted[-1]
        left = self.estimate - self.samples
        if e < max(self.emitted):  # past the emission's peak: halving per level
            tail = e * SAMPLES_DECLINE / (1 - SAMPLES_DECLINE)
            return min(tail, left) if left > 0 else tail
        if left > 0:  # still growing: the expected count not yet emitted
            return left
        return e * SAMPLES_DECLINE / (1 - SAMPLES_DECLINE)

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
        if b <= 0:  # nothing to fit yet: the mean cost of the levels so far, first included
            b = sum(secs) / max(sum(n + SAMPLE_COST * e for n, e in zip(cells, emitted)), 1)
        return a, b, SAMPLE_COST * b

    def seconds_left(self, children: int) -> float:
        """Forecast seconds of the levels after the last one added, given its children."""
        ahead = self.cells_ahead(children)
        if not ahead:
            return 0.0
        a, b, c = self.costs()
        # cells at the floor's level are dropped, not split: FLOOR_COST of a cell's cost
        work = sum(ahead) - (1 - FLOOR_COST) * (ahead[-1] if len(self.cells) + len(ahead) - 1 == self.last else 0)
        return a * len(ahead) + b * work + c * self.samples_ahead()

