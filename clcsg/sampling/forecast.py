"""The level loop's forecast of the seconds left (the sampling bar's ETA), from the levels seen.

Pure arithmetic on the level history, no OpenCL and no clock: :class:`Forecast` is fed, level
by level, the cells the level classified (the halves of the small cells it split in place
included: they are the cells the levels below would have had, so the history keeps the shape
described here, with fewer levels at its end), the samples emitted so far, the children it
queued and the seconds it took, and answers the seconds left.  The sampler's progress (``_Progress`` in
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

**Populations.**  Root cells of different sizes reach their peak at different levels: the
bounds above are taken per root cell (:func:`peak_levels`), and the cells alive at a level are
those of the root cells whose peak is at most three levels behind it.  Their peak (the *top*)
is the area-weighted median of those root cells' peaks (the level with the most cells on the
zoo, where the largest root cell's peak was one level late on three of six models), or an
earlier level into which the cells grew by less than PEAK_GROWTH.

**Cells ahead.**  After a level of n cells with c children queued, the cells of the levels
ahead are c, c g_1, c g_1 g_2, ... up to the last level.  Before the top, g is the growth over
the last two levels (one, at the first levels of a population), kept in [GROWTH_MIN, 4] during
the four-way levels and [GROWTH_MIN, 2] after, and AT_PEAK of that into the top.  The two
levels after it keep 0.8 of the cells each (PAST_PEAK); the recorded runs then take one of two
courses.  A *collapse* (the zoo, the sponge, the plate: the cells are now small enough for one
sample to cover each): 0.4 into the third level, 0.05 into the fourth, halving after.  A
*tail* (the pen stand at 0.05%: cells along curves that pruning never decides, split down to
the floor, a third of its run): as many cells again each level, TAIL_LEVEL of the most a level
had at most, down to the floor.  The levels tell which: two levels past the top, cells that
emit fewer than TAIL_YIELD samples each are a tail, more than COLLAPSE_YIELD a collapse; past
the collapse level, a tail keeps TAIL_SHARE of the most cells, or BARREN_SHARE of them while
emitting fewer than TAIL_YIELD samples each.  Until then the forecast is the weighted
geometric mean of the two (TAIL_WEIGHT on the tail; the two differ by 3-6x there, so one of
them is missed by up to about 2x whichever it leans to).  Root cells that peak after the
cells alive have collapsed (the plate's faces, after its 2,500 holes) add their own cells: as
many per area at their peak as the cells alive had, growing into it by 4 or 2 a level
(:meth:`Forecast.later_cells`).  The cells of the last level are dropped, not split: they cost
FLOOR_COST of a cell.  All of it is at most CELLS_PER_SAMPLE cells per expected sample.

**Samples ahead.**  While the samples per level still grow, the expected count not yet emitted
(:func:`clcsg.compile.bounds.estimates.expected_samples`); once past their peak, a halving per
level (as many again as the last level emitted), at most the expected count left.

**Seconds.**  A level costs a + b (cells + SAMPLE_COST samples emitted): a the cheapest level
seen after the first, at most LEVEL_COST (the launch and the counter read), SAMPLE_COST the
cost of emitting and finishing a sample against classifying a cell (0.2-0.8 on the recorded
runs; one parameter, since the early levels, with few cells and many samples, cannot separate
the two), and b fitted to the levels seen, weighted DECAY^age so it follows the cost per cell
as the tapes get shorter deeper down.  The first level is left out once there is another: it
also pays one-off costs (the root tapes at full length; the program's first launch, which
builds its code, runs before the level loop's clock starts); alone, it gives b less its
one-off share FIRST_LEVEL and no a.

**Shown.**  After the first levels of a run (a few hundred cells, their time mostly the launch)
the forecast extrapolates cells ahead 10^2-10^5 times the cells seen so far (and the children
queued).  On the recorded runs, where it extrapolated more than ETA_EXTRAPOLATION times, 14 of
its 20 forecasts were more than 2x off (up to 290x); at most that, they were within 0.54-1.8x
of the seconds actually left, the sponge's 2.8x once, 4% into its run.  So the ETA shown is
None (unknown) until then; the bar's fraction uses the forecast all along.

The constants were chosen on the level histories of ``python -m bench progress``'s runs,
replayed through this class (``bench.progress.replay_history``; ``tests/data`` keeps a set);
they are rules of thumb of the subdivision, not fits to a machine, SAMPLE_COST aside.
"""

from __future__ import annotations

import math

import numpy as np

#: the cell diagonal, in radii, at which the surface cells are resolved (the peak level)
PEAK_DIAG = 2.0
#: weight of a level in the time fit per level of age
DECAY = 0.7
#: least and largest growth of the cells per level before the peak (see the module docstring)
GROWTH_MIN, GROWTH_QUAD, GROWTH_PAIR = 0.5, 4.0, 2.0
#: growth into the peak level at most, over the growth of the levels before it
AT_PEAK = 0.75
#: a level (at the end of the four-way levels or after) into which the cells grew by less is
#: the peak level, whatever :func:`level_bounds` says
PEAK_GROWTH = 1.4
#: growth into the levels 1, 2, ... after the peak level (index 0 unused), the last one the
#: collapse level's: past it the cells still undecided are few (one sample covers each), unless
#: they are a tail along curves that pruning never decides
PAST_PEAK = (None, 0.8, 0.8)
#: growth into the collapse level
COLLAPSE_ONSET = 0.4
#: cells of the level after the collapse level over those of the collapse level, and the
#: decline per level after it
COLLAPSE, AFTER_COLLAPSE = 0.05, 0.5
#: a level past the collapse level keeping this share of the most cells a level had is a tail
TAIL_SHARE = 0.3
#: a level past the collapse level keeping this share of the most cells and emitting fewer
#: than TAIL_YIELD samples per cell is a tail too (the pen stand's contacts at 0.05%: 19%)
BARREN_SHARE = 0.1
#: samples per cell of a level past the peak below which it is a tail, above which a collapse
TAIL_YIELD, COLLAPSE_YIELD = 0.25, 0.3
#: the tail's weight in the forecast while the scenario is not known
TAIL_WEIGHT = 0.2
#: the cells per level of a tail not yet seen, over the most cells a level had
TAIL_LEVEL = 0.5
#: growth per level of a tail to the floor, at least and at most
TAIL_MIN, TAIL_MAX = 0.9, 1.2
#: the most a level costs whatever its cells (the launch and the counter read; the cheapest
#: level seen, at most this, seconds)
LEVEL_COST = 0.002
#: the first level's cost per cell over a later level's (the root tapes at full length: 1.3-1.4
#: on the 2,500-hole plate, whose first chain is one level; 2.4-3.4 while the first level also
#: built the program's code)
FIRST_LEVEL = 1.5
#: the most cells a run has per expected sample (the bench runs: 0.04-1.6)
CELLS_PER_SAMPLE = 4.0
#: the cost of a sample emitted over that of a cell classified (fits per recorded run: 0.2-0.8)
SAMPLE_COST = 0.5
#: the cost of a cell at the floor's level (dropped, not split) over that of a cell split
FLOOR_COST = 0.5
#: the most cells ahead, over the cells seen, for which the seconds left are shown as an ETA
#: (module docstring)
ETA_EXTRAPOLATION = 100
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


def _work(cells: float, emitted: float) -> float:
    """A level's work in cells: its cells and SAMPLE_COST per sample it emitted."""
    return cells + SAMPLE_COST * emitted


def peak_levels(diagonals: np.ndarray, radius: float, split_larger: float, quad_split_diag: float) -> np.ndarray:
    """The peak level (:func:`level_bounds`) of root cells of these diagonals."""
    d = np.asarray(diagonals, dtype=np.float64)
    step = math.log(1 / split_larger)
    with np.errstate(divide="ignore", invalid="ignore"):
        quad = np.where(d > quad_split_diag * radius, np.ceil(np.log(d / (quad_split_diag * radius)) / step), 0.0)
        dq = d * split_larger ** quad
        pair = np.maximum(0.0, 2 * np.log(dq / (PEAK_DIAG * radius)) / step)
    return np.where(d > 0, quad + np.nan_to_num(pair), 0.0)


class Forecast:
    """Seconds left of the level loop (module docstring).  ``estimate``: the expected sample
    count (0: unknown); ``quad``, ``peak`` and ``last`` from :func:`level_bounds` (None: not
    known; ``max_levels`` then ends the tail)."""

    def __init__(self, estimate: int = 0, quad: float = 0.0, peak: float | None = None, last: float | None = None,
                 max_levels: int = 400, roots: tuple | None = None):
        self.estimate = max(0, int(estimate))
        self.quad = quad
        self.peak = max_levels if peak is None else peak
        # (peak levels, areas) of the root cells, by peak level
        self.roots = None
        if roots is not None and len(roots[0]):
            order = np.argsort(roots[0], kind="stable")
            self.roots = (np.asarray(roots[0])[order], np.asarray(roots[1], dtype=np.float64)[order])
        self._peaks: dict = {}  # peak_at by level
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

    def add_chain(self, levels, seconds: float) -> None:
        """The levels of one chain, (level, cells, samples so far, children) each, done in
        ``seconds`` together: shared among them by their work as :meth:`costs` counts it
        (1 + cells + SAMPLE_COST samples emitted), so that the time model sees each level's
        share."""
        shares, seen = [], self.samples
        for _, cells, samples, _ in levels:
            shares.append(1 + _work(cells, max(0, samples - seen)))
            seen = samples
        for (_, cells, samples, _), share in zip(levels, shares):
            self.add(cells, samples, seconds * share / sum(shares))

    def cells_ahead(self, children: int, tail: bool = False) -> list[float]:
        """Forecast cells of the levels after the last one added: the collapse scenario, or
        (``tail``) the tail one, of the cells alive, and the cells to come of root cells that
        peak later (module docstring)."""
        if not children:
            return []
        h = self.cells
        top = self.peak_level(children)
        start = self.population_start(top)
        if len(h) - start >= 2:
            g = (children / max(h[-2], 1)) ** 0.5
        elif len(h) - start == 1:
            g = children / max(h[-1], 1)
        else:  # the first level of these cells: as they grow before their peak
            g = GROWTH_QUAD if len(h) < self.quad else GROWTH_PAIR
        most = max(h[start:] + [children])
        later = self.later_cells(top, most)
        n, out, lv = float(children), [], len(h)
        while lv <= self.last and (n >= 1 or any(x >= 1 for x in later[lv:])):
            out.append(n + (later[lv] if lv < len(later) else 0.0))
            k = lv + 1 - top  # the next level's place against the peak's
            if k <= 0:  # into the peak level: a share AT_PEAK of the growth only
                grow = GROWTH_QUAD if lv < self.quad else GROWTH_PAIR
                n *= min(max(g, GROWTH_MIN), grow * (AT_PEAK if k == 0 else 1.0))
            elif k < len(PAST_PEAK):
                n *= PAST_PEAK[k]
            elif tail and len(h) - top > len(PAST_PEAK):  # the tail seen: its own growth
                n *= min(max(g, TAIL_MIN), TAIL_MAX)
            elif tail:  # not yet seen: TAIL_LEVEL of the most cells a level had, or fewer
                n = min(n, TAIL_LEVEL * most)
            elif k == len(PAST_PEAK):
                n *= COLLAPSE_ONSET
            else:
                n *= COLLAPSE if k == len(PAST_PEAK) + 1 else AFTER_COLLAPSE
            n = n if n >= 1 else 0.0
            lv += 1
        return out

    def population_start(self, top: int) -> int:
        """The first level whose cells are mostly of the root cells that peak at ``top``."""
        for level in range(len(self.cells), 0, -1):
            if math.floor(self.peak_at(level - 1)) != top:
                return level
        return 0

    def later_cells(self, top: int, most: float) -> list[float]:
        """Per level, the cells to come of the root cells that peak after the cells alive
        (peak at ``top``, at most ``most`` cells a level) have collapsed: as many per area at
        their peak as the cells alive had, growing into it and declining after it as
        :meth:`cells_ahead` forecasts (the 2,500-hole plate: its holes' cells peak at level
        0, its two faces' cells at level 6)."""
        out = [0.0] * (self.last + 1)
        if self.roots is None:
            return out
        peaks, areas = self.roots
        whole = np.floor(peaks)
        alive = (whole <= top + len(PAST_PEAK)) & (peaks >= len(self.cells) - len(PAST_PEAK))
        alive_area = float(areas[alive].sum()) if alive.any() else 0.0
        if not alive_area > 0:
            return out
        for p in np.unique(whole[whole > top + len(PAST_PEAK)]).astype(int).tolist():
            share = float(areas[whole == p].sum()) / alive_area
            if not math.isfinite(most * share):  # areas too small to compare (a degenerate scene)
                continue
            n = most * share
            for lv in range(min(p, self.last), -1, -1):  # into the peak
                out[lv] += n
                n /= GROWTH_QUAD if lv <= self.quad else GROWTH_PAIR
            n = most * share
            for lv in range(p + 1, self.last + 1):  # after it
                k = lv - p
                n *= (PAST_PEAK[k] if k < len(PAST_PEAK) else COLLAPSE_ONSET if k == len(PAST_PEAK)
                      else COLLAPSE if k == len(PAST_PEAK) + 1 else AFTER_COLLAPSE)
                out[lv] += n
        return out

    def peak_level(self, children: int) -> int:
        """The peak level: the one :func:`level_bounds` gives, or an earlier one (at the
        four-way levels' end or after) into which the cells grew by less than PEAK_GROWTH."""
        top = math.floor(self.peak_at(len(self.cells)))
        h = self.cells + [children]
        for i in range(max(1, math.ceil(self.quad)), min(top, len(h))):
            if h[i] < PEAK_GROWTH * h[i - 1]:
                return i
        return top

    def peak_at(self, level: int) -> float:
        """The peak level of the cells alive at ``level``: the area-median peak of the root
        cells whose cells have not collapsed there (peak level + len(PAST_PEAK) >= ``level``;
        all of them where none is left), or the ``peak`` given."""
        if self.roots is None:
            return self.peak
        if level not in self._peaks:
            peaks, areas = self.roots
            first = min(int(np.searchsorted(peaks, level - len(PAST_PEAK))), len(peaks) - 1)
            held = np.cumsum(areas[first:])
            k = min(int(np.searchsorted(held, 0.5 * held[-1])), len(held) - 1)
            self._peaks[level] = float(peaks[first + k])
        return self._peaks[level]

    def scenario(self, children: int) -> str:
        """Which cells the levels ahead have: ``"collapse"`` or ``"tail"`` once the levels
        show it, else ``"both"`` (not yet known: the forecast hedges).  Past the collapse level,
        the tail keeps TAIL_SHARE of the most cells a level had, or BARREN_SHARE of them while
        emitting fewer than TAIL_YIELD samples per cell; from the second level past
        the peak, a level whose cells emit fewer than TAIL_YIELD samples each is stuck on
        curves that pruning never decides (a tail), one whose cells emit more than
        COLLAPSE_YIELD is still resolving surface (a collapse)."""
        past = len(self.cells) - 1 - self.peak_level(children)
        y = self.emitted[-1] / max(self.cells[-1], 1)
        if past > len(PAST_PEAK):
            share = children / max(self.cells)
            return "tail" if share >= TAIL_SHARE or (share >= BARREN_SHARE and y < TAIL_YIELD) else "collapse"
        if past >= 2:
            if y < TAIL_YIELD:
                return "tail"
            if y > COLLAPSE_YIELD:
                return "collapse"
        return "both"

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
        first = 1 if len(secs) > 1 else 0
        a = min(min(secs[first:]), LEVEL_COST) if first else 0.0
        w = x = 0.0
        for i in range(first, len(secs)):
            age = DECAY ** (len(secs) - 1 - i)
            w += age * (secs[i] - a)
            x += age * _work(cells[i], emitted[i])
        b = w / x if x > 0 and first else 0.0
        if b <= 0:  # nothing to fit yet: the first level's cost, less its one-off share
            b = secs[0] / FIRST_LEVEL / max(_work(cells[0], emitted[0]), 1)
        return a, b, SAMPLE_COST * b

    def seconds_left(self, children: int) -> float:
        """Forecast seconds of the levels after the last one added, given its children: while
        the scenario is not known, the geometric mean of the two (within 2x of either while
        they differ by 4x at most)."""
        if not children:
            return 0.0
        a, b, c = self.costs()
        known = self.scenario(children)
        if known == "both":  # a weighted geometric mean of the two
            (n_c, w_c), (n_t, w_t) = self._work(children, False), self._work(children, True)
            levels, cells = max(n_c, n_t), w_c ** (1 - TAIL_WEIGHT) * w_t ** TAIL_WEIGHT
        else:
            levels, cells = self._work(children, known == "tail")
        return a * levels + b * cells + c * self.samples_ahead()

    def extrapolation(self, children: int) -> float:
        """The cells the levels ahead have (the collapse scenario) over the cells of the levels
        seen and the ``children`` queued."""
        return sum(self.cells_ahead(children)) / max(sum(self.cells) + children, 1)

    def eta(self, children: int, seconds: float) -> float | None:
        """``seconds`` (:meth:`seconds_left`) as the ETA to show, or None while the forecast
        extrapolates more than ETA_EXTRAPOLATION times the cells seen (module docstring)."""
        return seconds if not children or self.extrapolation(children) <= ETA_EXTRAPOLATION else None

    def _work(self, children: int, tail: bool) -> tuple[int, float]:
        """(levels, cells) ahead in one scenario; cells at the floor's level are dropped, not
        split: FLOOR_COST of a cell's cost."""
        ahead = self.cells_ahead(children, tail)
        floor = ahead[-1] if ahead and len(self.cells) + len(ahead) - 1 == self.last else 0
        cells = sum(ahead) - (1 - FLOOR_COST) * floor
        if self.estimate:  # the early levels' growth, kept to what the expected samples allow
            cells = min(cells, CELLS_PER_SAMPLE * self.estimate)
        return len(ahead), cells
