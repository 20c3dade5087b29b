"""Progress: tqdm bars on a terminal (a real pseudo-terminal), nothing but the summary in a
pipe, JSON lines with --progress json, silence with --quiet; the sampler's forecast."""

from __future__ import annotations

import io
import json
import math
import os
import pty
import re
import select
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import clcsg
from clcsg.progress import Reporter, current, for_option, using

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENE = os.path.join(ROOT, "examples", "pawn.csg")
SAMPLE = ["sample", SCENE, "-r", "0.4"]
SUMMARY = re.compile(r"^[\d,]+ samples on \d+ quadrics \(r = 0\.4, \d+ levels, [\d,]+ unresolved cells\) "
                     r"in [\d.]+ s \(load [\d.]+, sample [\d.]+, write [\d.]+\) -> .*\.ply$")


def env(**extra):
    e = dict(os.environ, CLCSG_PROGRESS_DELAY="0", COLUMNS="120")
    e.pop("CLCSG_PRECISION", None)
    e.update(extra)
    return e


def run_in_pty(argv, timeout=120):
    """Run ``python -m clcsg argv`` with stdin, stdout and stderr on a new pseudo-terminal;
    returns (exit code, everything it wrote)."""
    master, slave = pty.openpty()
    proc = subprocess.Popen([sys.executable, "-m", "clcsg", *argv], stdin=slave, stdout=slave, stderr=slave,
                            env=env(), close_fds=True)
    os.close(slave)
    out = b""
    try:
        while True:
            ready, _, _ = select.select([master], [], [], timeout)
            if not ready:
                proc.kill()
                break
            try:
                chunk = os.read(master, 1 << 16)
            except OSError:  # the child closed the terminal
                break
            if not chunk:
                break
            out += chunk
    finally:
        os.close(master)
        proc.wait(timeout=30)
    return proc.returncode, out.decode("utf-8", "replace")


def run_in_pipe(argv):
    return subprocess.run([sys.executable, "-m", "clcsg", *argv], capture_output=True, text=True, timeout=120,
                          env=env())


def test_a_terminal_shows_bars_and_the_summary(tmp_path):
    rc, out = run_in_pty(SAMPLE + ["-o", str(tmp_path / "p.ply"), "--stats", str(tmp_path / "s.json")])
    assert rc == 0, out
    frames = [f for f in re.split(r"[\r\n]+", out) if f.strip()]
    bars = [f for f in frames if f.startswith("sampling: ") and "%|" in f and "level" in f]
    # the bar moves once per chain of levels (the counters are read once per chain); while it
    # is shown, the chains after the first are one level long.  The reporter's ticker redraws
    # the bar as it stands to keep its clock going: such a frame repeats the cells, the level
    # and the samples of the one before it, and is not a move
    def state(bar):  # what a move changes: the cells, the level and the samples
        return (re.search(r"[\d.]+[kMG]?/[\d.]+[kMG]? cells", bar).group(0),
                re.search(r"level \d+, [\d,]+ samples", bar).group(0))

    moves = [bar for k, bar in enumerate(bars) if k == 0 or state(bar) != state(bars[k - 1])]
    stats = json.loads((tmp_path / "s.json").read_text())
    chains = stats["chains"]
    assert chains >= 3 and len(moves) == chains, out[-2000:]
    shown = [int(re.search(r", level (\d+),", bar).group(1)) for bar in moves]
    assert shown == list(range(shown[0], stats["levels"] + 1)), shown
    # done / total in cells with an ETA and the samples so far against the estimate
    for bar in bars:
        assert re.search(r"\d+%\|.*\| [\d.]+[kMG]?/[\d.]+[kMG]? cells \[\d\d:\d\d<\d\d:\d\d, level \d+, [\d,]+ samples "
                         r"\(estimate [\d,]+\)\]", bar), bar
    assert bars[-1].startswith("sampling: 100%|")
    assert any(f.startswith("sampling: clip programs: 100%|") for f in frames)
    assert any(f.startswith("loading ") for f in frames)
    summary, stats_path = frames[-1].strip().rsplit(", ", 1)
    assert SUMMARY.match(summary) and stats_path.endswith("s.json"), frames[-1]
    assert (tmp_path / "p.ply").stat().st_size > 1000


def test_a_pipe_gets_only_the_summary(tmp_path):
    r = run_in_pipe(SAMPLE + ["-o", str(tmp_path / "p.ply")])
    assert r.returncode == 0, r.stderr
    assert r.stderr == ""
    lines = r.stdout.splitlines()
    assert len(lines) == 1 and SUMMARY.match(lines[0]), r.stdout


def test_quiet_prints_nothing(tmp_path):
    rc, out = run_in_pty(SAMPLE + ["-o", str(tmp_path / "p.ply"), "--quiet"])
    assert rc == 0 and out.strip() == "", out
    assert (tmp_path / "p.ply").exists()


def test_json_progress_is_one_object_per_line(tmp_path):
    out = tmp_path / "p.ply"
    r = run_in_pipe(SAMPLE + ["-o", str(out), "--progress", "json"])
    assert r.returncode == 0, r.stderr
    events = [json.loads(line) for line in r.stderr.splitlines()]  # every line parses
    kinds = [e["event"] for e in events]
    assert kinds[0] == "start" and kinds[-1] == "summary" and "progress" in kinds
    steps = {e["step"] for e in events if e["event"] == "start"}
    assert steps == {"load", "sample", "write"}
    ends = {e["step"]: e for e in events if e["event"] == "end"}
    assert set(ends) == steps and all(e["elapsed"] >= 0 for e in ends.values())
    progress = [e for e in events if e["event"] == "progress"]
    assert all(e["unit"] == "cells" and 0 < e["done"] <= e["total"] for e in progress)
    last = progress[-1]
    assert last["done"] == last["total"] and last["eta"] == 0 and last["samples"] > 0 and last["estimated"] > 0
    levels = [e["level"] for e in progress if "level" in e]
    assert levels == sorted(levels) and len(set(levels)) > 3 and levels[-1] == events[-1]["levels"]
    summary = events[-1]
    assert summary["command"] == "sample" and summary["outputs"] == [str(out)] and summary["samples"] > 0
    assert set(summary["seconds"]) == {"load", "sample", "write", "total"}
    assert SUMMARY.match(r.stdout.strip())  # the summary line is still printed


def test_json_mode_reports_warnings_and_errors_as_json(tmp_path):
    empty = tmp_path / "empty.csg"
    empty.write_text("difference() { cube(1); cube(2, center = true); }\n")
    r = run_in_pipe(["sample", str(empty), "-r", "0.1", "-o", str(tmp_path / "e.ply"), "--progress", "json"])
    assert r.returncode == 0, r.stderr
    events = [json.loads(line) for line in r.stderr.splitlines()]
    warnings = [e for e in events if e["event"] == "warning"]
    assert warnings and "empty" in warnings[0]["message"]
    r = run_in_pipe(["sample", str(tmp_path / "missing.json"), "-r", "0.1", "-o", str(tmp_path / "e.ply"),
                     "--progress", "json"])
    assert r.returncode == 3
    (err,) = [json.loads(line) for line in r.stderr.splitlines() if '"error"' in line]
    assert err["exit_code"] == 3 and "no such file" in err["message"]


# -- the reporter itself --------------------------------------------------------------------------
class Tty(io.StringIO):
    def isatty(self):
        return True


def test_reporter_modes():
    assert Reporter("auto", stream=io.StringIO()).mode == "none"
    assert Reporter("auto", stream=Tty()).mode == "bar"
    assert Reporter("auto", stream=Tty(), quiet=True).mode == "none"
    with pytest.raises(ValueError, match="progress mode"):
        Reporter("fancy")
    assert for_option(False).mode == "none" and for_option(True).mode == "bar"
    rep = Reporter("json", stream=io.StringIO())
    assert for_option(rep) is rep and for_option(None) is not rep
    with using(rep):
        assert current() is rep and for_option(None) is rep
    assert current() is not rep


def test_bars_wait_for_the_delay_and_clear_when_done():
    fast = Tty()
    rep = Reporter("bar", stream=fast, delay=10.0)
    with rep.step("load", "loading x") as st:
        st.update(done=3, total=10)
    assert fast.getvalue() == ""  # shorter than the delay: never shown
    slow = Tty()
    rep = Reporter("bar", stream=slow, delay=0.0)
    with rep.step("sample", "sampling", unit="cells") as st:
        st.update(done=30, total=120, note="level 3")
    text = slow.getvalue()
    assert "sampling:  25%|" in text and "30/120 cells" in text and "level 3" in text
    assert text.endswith("\r")  # the bar is cleared (leave=False)


def test_a_forecast_is_the_eta_whatever_the_rate():
    """``Step.update(forecast=...)``: the ETA (JSON and bar) is the caller's forecast counting
    down, not the rate so far times the count left (which a held fraction would keep low)."""
    buf = io.StringIO()
    rep = Reporter("json", stream=buf)
    with rep.step("sample", "sampling") as st:
        st.update(done=90, total=100, forecast=600.0, always=True)
        assert 599.0 < st.eta() <= 600.0
    progress = [json.loads(line) for line in buf.getvalue().splitlines() if '"progress"' in line]
    assert 599.0 < progress[0]["eta"] <= 600.0
    tty = Tty()
    rep = Reporter("bar", stream=tty, delay=0.0)
    with rep.step("sample", "sampling", unit="cells") as st:
        st.update(done=90, total=100, forecast=600.0)
        assert "<09:5" in tty.getvalue() or "<10:00" in tty.getvalue(), tty.getvalue()


def test_an_unknown_forecast_shows_no_eta():
    """``forecast=nan``: the ETA is not known; JSON gives null and the bar a question mark, not
    the rate so far times the count left."""
    buf = io.StringIO()
    rep = Reporter("json", stream=buf)
    with rep.step("sample", "sampling") as st:
        st.update(done=10, total=100, forecast=math.nan, always=True)
        assert st.eta() is None
        st.update(done=20, total=100, forecast=5.0, always=True)
        assert 4.0 < st.eta() <= 5.0
    progress = [json.loads(line) for line in buf.getvalue().splitlines() if '"progress"' in line]
    assert progress[0]["eta"] is None and 4.0 < progress[1]["eta"] <= 5.0
    tty = Tty()
    rep = Reporter("bar", stream=tty, delay=0.0)
    with rep.step("sample", "sampling", unit="cells") as st:
        st.update(done=10, total=100, forecast=math.nan)
        assert "<?" in tty.getvalue(), tty.getvalue()


def test_json_reporter_events():
    buf = io.StringIO()
    rep = Reporter("json", stream=buf)
    with rep.step("render", "rendering") as st:
        st.update(done=1, total=4, phase=True)
        st.update(done=4)
    rep.summary("render", "done in 1 s", out=io.StringIO(), pixels=12)
    events = [json.loads(line) for line in buf.getvalue().splitlines()]
    assert [e["event"] for e in events] == ["start", "progress", "progress", "end", "summary"]
    assert events[1]["total"] == 4 and events[2]["done"] == 4 and events[2]["eta"] == 0
    assert events[-1]["text"] == "done in 1 s" and events[-1]["pixels"] == 12


def test_the_sampler_reports_levels_and_a_forecast(cl_context):
    buf = io.StringIO()
    rep = Reporter("json", stream=buf)
    s = clcsg.sample(clcsg.box(2) - clcsg.sphere(1.3), 0.1, device=cl_context, progress=rep)
    events = [json.loads(line) for line in buf.getvalue().splitlines()]
    progress = [e for e in events if e["event"] == "progress" and e["label"] == "sampling"]
    # one event per chain of levels, at its last level
    levels = [e["level"] for e in progress]
    assert levels == sorted(set(levels)) and levels[-1] == s.stats["levels"]
    assert 1 < len(levels) <= s.stats["chains"]
    # the bar counts every cell classified, the halves of cells split in place too
    assert progress[-1]["done"] == s.stats["cells"] == progress[-1]["total"]
    assert s.stats["cells"] > sum(s.stats["cells_per_level"])
    assert progress[-1]["samples"] == len(s) and len(s) / 2 <= progress[-1]["estimated"] <= 2 * len(s)
    assert all(e["total"] >= e["done"] for e in progress)
    assert events[-1]["event"] == "end" and events[-1]["step"] == "sample"


def test_the_bar_never_goes_back_on_a_terminal(tmp_path):
    """The percentage of the sampling bar on a pty, frame by frame, never decreases; the expected
    sample count it shows is within 2x of the real count."""
    scene = os.path.join(ROOT, "examples", "rook.csg")
    rc, out = run_in_pty(["sample", scene, "-r", "1%", "-o", str(tmp_path / "p.ply")])
    assert rc == 0, out
    frames = [f for f in re.split(r"[\r\n]+", out) if f.startswith("sampling: ") and "%|" in f and "level" in f]
    pct = [int(re.match(r"sampling:\s+(\d+)%", f).group(1)) for f in frames]
    assert len(pct) >= 5 and pct == sorted(pct) and pct[-1] == 100, pct
    est = int(re.search(r"estimate ([\d,]+)\)", frames[-1]).group(1).replace(",", ""))
    samples = int(re.search(r"level \d+, ([\d,]+) samples", frames[-1]).group(1).replace(",", ""))
    assert 0.5 <= est / samples <= 2, (est, samples)


EXAMPLES = sorted(os.path.relpath(p, ROOT) for pat in ("examples/*.json", "examples/*.csg", "examples/zoo/*.json")
                  for p in __import__("glob").glob(os.path.join(ROOT, pat)) if "menger" not in p)
#: where the expected count misses 2x (none since the expected count uses the measured area)
EXPECTED_MISSES: dict = {}


@pytest.mark.parametrize("path", [pytest.param(p, marks=pytest.mark.xfail(strict=True, reason=EXPECTED_MISSES[p]))
                                  if p in EXPECTED_MISSES else p for p in EXAMPLES])
def test_the_expected_sample_count_is_within_2x(path, cl_context):
    """The count the progress shows before sampling (``expected_samples``) against the real
    count at r = 1% of the diagonal, on every example (the level-3 sponge aside: it has its
    own test module)."""
    import warnings

    scene = clcsg.load(os.path.join(ROOT, path))
    tape = scene.compile()
    r = float(((tape.bound[1] - tape.bound[0]) ** 2).sum() ** 0.5) / 100
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        s = clcsg.sample(scene, r, device=cl_context, progress=False)
    assert 0.5 <= s.stats["expected_samples"] / len(s) <= 2, s.stats["expected_samples"] / len(s)


LEVEL_HISTORIES = os.path.join(ROOT, "tests", "data", "level_histories.json")


def _recorded_runs():
    with open(LEVEL_HISTORIES) as f:
        return json.load(f)


@pytest.mark.parametrize("run", _recorded_runs(), ids=lambda r: r["name"])
def test_the_forecast_on_recorded_level_histories(run):
    """Forecast (the sampler's ETA) fed the level histories of ``python -m bench progress``'s
    runs as the sampler feeds it, chain by chain (recorded by
    ``bench.progress.record_histories``: warm runs in one process, 0.2-3 s each): the fraction
    it gives the bar never goes back and ends at 100%, and over the second half of each run
    (judged while at least 10% of it is left) its seconds left are within 2x of the seconds
    actually left, worst and median (the bench's target)."""
    from bench.progress import replay_history

    judged = replay_history(run)
    assert judged["monotone"] and judged["final_fraction"] == 1.0 and judged["judged"] >= 1, judged
    assert judged["worst"] <= 2.0 and 0.5 <= judged["median_ratio"] <= 2.0, judged


@pytest.mark.parametrize("run", _recorded_runs(), ids=lambda r: r["name"])
def test_the_eta_is_withheld_while_the_forecast_extrapolates_far(run):
    """Replayed chain by chain, the ETA shown is the forecast where it extrapolates at most
    ETA_EXTRAPOLATION times the cells seen and None elsewhere; every forecast more than 4x off
    the seconds actually left (while a tenth of the run is left, as the bench judges) was
    withheld, and an ETA is shown before the last level."""
    from clcsg.sampling.forecast import ETA_EXTRAPOLATION, Forecast

    fc = Forecast(run["estimate"], run["quad"], run["peak"], run["last"], run["max_levels"], run["roots"])
    end = run["chains"][-1][0]
    t_last, shown = 0.0, 0
    for t, levels in run["chains"][:-1]:
        fc.add_chain(levels, t - t_last)
        t_last = t
        children = levels[-1][3]
        left = fc.seconds_left(children)
        eta = fc.eta(children, left)
        assert (eta == left) if fc.extrapolation(children) <= ETA_EXTRAPOLATION else eta is None
        if eta is not None and end - t >= 0.1 * end:
            shown += 1
            assert 0.25 <= eta / (end - t) <= 4, (t, eta, end - t)
    assert shown >= 1


def test_the_forecast_ends_at_the_floor_and_fits_the_costs():
    """The cells ahead stop at the floor's level; the time model's fixed cost is the cheapest
    level after the first (at most LEVEL_COST), its per-cell cost about the history's, and a
    sample costs SAMPLE_COST cells; with one level seen, that level's cost per cell less its
    one-off share (FIRST_LEVEL) and no fixed cost."""
    from clcsg.sampling.forecast import FIRST_LEVEL, LEVEL_COST, SAMPLE_COST, Forecast

    fc = Forecast(10_000, quad=2, peak=6, last=9)
    fc.add(10, 0, 0.03)
    a, b, _ = fc.costs()
    assert a == 0 and b == pytest.approx(0.03 / FIRST_LEVEL / 10)
    cells = [40, 160, 320, 640, 900, 1200]
    seconds = [1e-3 + 1e-6 * (n + SAMPLE_COST * 100) for n in cells]
    for k, (n, sec) in enumerate(zip(cells, seconds)):
        fc.add(n, 100 * (k + 1), sec)
    ahead = fc.cells_ahead(1600)
    assert len(ahead) == 9 - len(cells) and ahead[0] == 1600
    a, b, c = fc.costs()
    assert a == min(seconds) < LEVEL_COST and 0.5e-6 < b < 1e-6 and c == pytest.approx(SAMPLE_COST * b)
    assert fc.seconds_left(0) == 0.0


def test_the_forecast_tells_a_tail_from_a_collapse_by_the_samples_per_cell():
    """Two levels past the peak, cells that emit few samples each are a tail (they trail down
    to the floor: the forecast keeps them level by level), cells that emit many are still
    resolving surface (they collapse two levels later); before that the forecast hedges
    between the two."""
    from clcsg.sampling.forecast import Forecast

    def fed(per_cell):
        fc = Forecast(1_000_000, quad=2, peak=6, last=16)
        samples = 0
        for level, n in enumerate([10, 40, 160, 320, 640, 1000, 1500, 1200, 1000]):
            samples += int(per_cell * n) if level >= 3 else 0
            fc.add(n, samples, 0.01)
        return fc

    assert fed(0.05).scenario(1100) == "tail" and fed(0.6).scenario(1100) == "collapse"
    early = Forecast(1_000_000, quad=2, peak=6, last=16)
    for n in [10, 40, 160, 320, 640, 1000, 1500, 1200]:
        early.add(n, 0, 0.01)
    assert early.scenario(1000) == "both"
    tail, collapse = fed(0.05).cells_ahead(1100, tail=True), fed(0.6).cells_ahead(1100)
    assert len(tail) == 16 - 9 + 1 and min(tail) >= 0.5 * 1100
    assert collapse[0] == 1100 and collapse[1] < 0.1 * 1100


def test_the_forecast_adds_root_cells_that_peak_later():
    """Root cells whose peak comes after the cells alive have collapsed (the plate's two faces
    after its holes) add their cells: as many per area at their peak as the cells alive had,
    growing into it."""
    from clcsg.sampling.forecast import GROWTH_QUAD, Forecast

    # 100 units of area peaking at level 0 (1,000 cells), 30 more peaking at level 6
    fc = Forecast(1_000_000, quad=6, peak=6, last=12, roots=([0.0, 6.0], [100.0, 30.0]))
    for n in [1000, 900]:
        fc.add(n, 0, 0.01)
    later = fc.later_cells(0, 1000)
    assert later[6] == pytest.approx(300) and later[5] == pytest.approx(300 / GROWTH_QUAD)
    ahead = fc.cells_ahead(400)
    assert ahead[0] == pytest.approx(400 + later[2]) and ahead[4] == pytest.approx(later[6], rel=0.01)


def test_the_bar_fraction_never_goes_back_and_ends_at_100():
    """sampler._Progress fed level by level as the sampler does: the fraction shown never goes
    back, is 100% only after the last level, and the bar's total is the cells over it."""
    from clcsg.sampling.sampler import _Progress

    buf = io.StringIO()
    prog = _Progress(Reporter("json", stream=buf), estimate=10_000, max_levels=400)
    cells = [4, 8, 16, 32, 64, 128, 256, 400, 300, 150, 40, 0]
    samples = [0, 0, 0, 10, 200, 1500, 4000, 7000, 9000, 9800, 10100, 10150]
    shown = []
    for level, (n, s) in enumerate(zip(cells[:-1], samples[1:])):
        prog.level(level, n, s, cells[level + 1])
        shown.append(prog.fraction)
        if cells[level + 1]:
            assert 0 < prog.fraction < 1
    prog.done()
    assert shown == sorted(shown) and shown[-1] == 1.0
    events = [json.loads(line) for line in buf.getvalue().splitlines()]
    progress = [e for e in events if e["event"] == "progress" and "level" in e]
    pct = [e["done"] / e["total"] for e in progress]
    assert pct == sorted(pct) and pct[-1] == 1.0 and progress[-1]["eta"] == 0
    for e, f in zip(progress, shown):
        assert abs(e["done"] / e["total"] - f) <= 0.01 + 1 / e["total"]


def test_a_chain_of_levels_shares_its_seconds_by_their_work():
    """Levels that ran in one chain are reported at once: the forecast sees each level's share
    of the chain's seconds, in proportion to 1 + cells + SAMPLE_COST samples emitted."""
    from clcsg.sampling.forecast import SAMPLE_COST
    from clcsg.sampling.sampler import _Progress

    prog = _Progress(Reporter("json", stream=io.StringIO()), estimate=1_000, max_levels=400)
    levels = [(0, 10, 0, 40), (1, 40, 100, 160), (2, 160, 400, 300)]
    prog.chain(levels)
    work = [1 + 10, 1 + 40 + SAMPLE_COST * 100, 1 + 160 + SAMPLE_COST * 300]
    secs = prog.forecast.seconds
    assert prog.forecast.cells == [10, 40, 160] and len(secs) == 3 and sum(secs) > 0
    for s, w in zip(secs, work):
        assert s / sum(secs) == pytest.approx(w / sum(work))
    assert 0 < prog.fraction < 1


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.integers(1, 10**6), st.integers(0, 10**6), st.floats(0, 1.0)), min_size=1, max_size=30),
       st.integers(0, 10**7), st.floats(0, 30), st.floats(0, 40), st.floats(0, 40),
       st.lists(st.tuples(st.floats(0, 20), st.floats(0, 1e4)), max_size=8))
def test_the_forecast_is_finite_and_not_negative_on_any_history(levels, estimate, quad, peak, last, roots):
    """Whatever the levels seen (cells, samples emitted, seconds), the level bounds and the
    root cells' peaks, the seconds left are a finite number, 0 with no children, and the
    cells ahead stop at the last level."""
    from clcsg.sampling.forecast import Forecast

    fc = Forecast(estimate, quad, peak, last, roots=tuple(map(list, zip(*roots))) if roots else None)
    samples = 0
    for cells, emitted, seconds in levels:
        samples += emitted
        fc.add(cells, samples, seconds)
        for children in (0, 1, cells, 4 * cells):
            left = fc.seconds_left(children)
            assert math.isfinite(left) and left >= 0 and (children or left == 0)
            assert len(fc.cells_ahead(children)) <= max(0, fc.last - len(fc.cells) + 1)
