"""postproc/dktlbm/sweepmap.py, `dkt-sweep map`: the borders between DKT patterns across
gamma and dh.

The tests run the map against a stand-in program (map_fake.py) whose pattern is a known
function of (gamma, dh) with two straight borders ('repeated' for gamma < 1.23 + 0.1 dh, 'once'
for gamma < 1.97 + 0.13 dh, else 'never'; just below the first border the second kiss comes
late, so a point there settles only at t_end = 8 s; a 'never' point leaves a 15-D_1 window and
settles at 30), called in-process, and once through `dkt-sweep map` with a stand-in mpiexec.
Each test's docstring says what it proves."""

from __future__ import annotations

import csv
import os
import stat
import subprocess
from pathlib import Path

import map_fake as fake
import pytest

from dkt_run import dkt_command
from dktlbm import sweepmap
from dktlbm.sweep import PlannedRun, SweepError

SWEEP = dkt_command("sweep")
FAKE = Path(__file__).resolve().parent / "map_fake.py"
T_END = 4.0
SCENE = """! a pair scene for the map tests (run only by the stand-in)
&pair
  gamma = 2.0, dh = 2.5
/
&run
  t_end = 4.0
/
&window
  above = 15
/
"""
X_TOL, Y_TOL = 0.05, 0.1
Run = tuple[float, float, float, float]  # gamma, dh, t_end, window.above


@pytest.fixture
def base(tmp_path: Path) -> Path:
    path = tmp_path / "pairscene.nml"
    path.write_text(SCENE)
    return path


@pytest.fixture
def log(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """The stand-in's log: a line per run it was asked for."""
    path = tmp_path / "fake.log"
    monkeypatch.setenv("FAKE_LOG", str(path))
    return path


def runs_in(log: Path) -> list[Run]:
    if not log.is_file():
        return []
    return [tuple(map(float, line.split())) for line in log.read_text().splitlines()]


def settings(base: Path, out: Path, x_points: int = 5, y_points: int = 4,
             sets: list[str] | None = None, x: tuple[float, float] = (1.0, 3.0),
             y: tuple[float, float] = (1.5, 6.0)) -> sweepmap.MapSettings:
    return sweepmap.MapSettings(
        base.resolve(), sweepmap.Axis("gamma", *x, x_points, X_TOL),
        sweepmap.Axis("dh", *y, y_points, Y_TOL), sets or [], out.resolve(), str(FAKE),
        T_END, 32.0, 15.0, 60.0)


class FakeLaunch:
    """Runs the stand-in in-process, each call's runs in order; with `kill_after` K it raises
    KeyboardInterrupt (as a killed map stops) once K runs are done, in the middle of a call."""

    def __init__(self, kill_after: int | None = None) -> None:
        self.calls: list[list[PlannedRun]] = []
        self.kill_after, self.done = kill_after, 0

    def __call__(self, todo: list[PlannedRun], every: list[PlannedRun]) -> None:
        self.calls.append(todo)
        for r in todo:
            if self.kill_after is not None and self.done == self.kill_after:
                raise KeyboardInterrupt
            fake.main(r.args[1:])
            self.done += 1


def rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


def true_edges(xs: list[float], ys: list[float]) -> set[tuple[str, float, float, float]]:
    """The grid edges whose ends differ in the stand-in's truth: (along, fixed, lo, hi)."""
    found = set()
    for y in ys:
        for a, b in zip(xs, xs[1:], strict=False):
            if fake.pattern(a, y) != fake.pattern(b, y):
                found.add(("x", y, a, b))
    for x in xs:
        for a, b in zip(ys, ys[1:], strict=False):
            if fake.pattern(x, a) != fake.pattern(x, b):
                found.add(("y", x, a, b))
    return found


def check_bracket(b: dict[str, str]) -> None:
    """A border point's bracket is at most its key's tolerance wide, on one grid line, and the
    truth at its ends is the pattern it names there (so the true border crosses it)."""
    x_lo, x_hi, y_lo, y_hi = (float(b[k]) for k in ("x_lo", "x_hi", "y_lo", "y_hi"))
    if b["along"] == "x":
        assert y_lo == y_hi and 0 < x_hi - x_lo <= X_TOL * (1 + 1e-9), b
    else:
        assert x_lo == x_hi and 0 < y_hi - y_lo <= Y_TOL * (1 + 1e-9), b
    assert fake.pattern(x_lo, y_lo) == b["pattern_lo"] != b["pattern_hi"] == fake.pattern(
        x_hi, y_hi), b
    assert b["patterns"] == "|".join(sorted((b["pattern_lo"], b["pattern_hi"])))


def test_borders_lie_within_tolerance_of_the_true_lines(tmp_path: Path, base: Path,
                                                       log: Path) -> None:
    """On a 5 x 4 grid with 2 jobs: every border point's bracket is at most the key's tolerance
    wide and holds the true border (the truth at its ends is the pattern named there), every
    grid edge whose ends truly differ has one (along x and along y), and no other has. Each
    border (1: never|once, 2: once|repeated) is one polyline whose points go up in dh along
    its order. map.csv has every run, the 20 grid points among them, with map.csv's columns;
    the summary counts the border points."""
    out = tmp_path / "m"
    _, borders, summary = sweepmap.trace_map(settings(base, out), 2, FakeLaunch())
    got = rows(out / "borders.csv")
    assert list(got[0]) == list(sweepmap.BORDER_COLUMNS)
    for b in got:
        check_bracket(b)
    cfg = settings(base, out)
    edges = true_edges(cfg.x.grid(), cfg.y.grid())
    assert any(e[0] == "x" for e in edges) and any(e[0] == "y" for e in edges)
    found = set()
    for b in got:
        along = b["along"]
        fixed = float(b["y_lo"] if along == "x" else b["x_lo"])
        lo, hi = (float(b[f"{along}_lo"]), float(b[f"{along}_hi"]))
        grid = cfg.x.grid() if along == "x" else cfg.y.grid()
        cell = max(g for g in grid if g <= lo), min(g for g in grid if g >= hi)
        found.add((along, fixed, *cell))
    assert found == edges and len(got) == len(edges)
    assert {(b["border"], b["patterns"]) for b in got} == {("1", "never|once"),
                                                          ("2", "once|repeated")}
    for number in ("1", "2"):
        line = sorted((b for b in got if b["border"] == number), key=lambda b: int(b["order"]))
        assert {b["piece"] for b in line} == {"1"}
        assert [int(b["order"]) for b in line] == list(range(1, len(line) + 1))
        dhs = [float(b["y"]) for b in line]
        assert dhs == sorted(dhs) or dhs == sorted(dhs, reverse=True), dhs
    table = rows(out / "map.csv")
    assert list(table[0]) == list(sweepmap.MAP_COLUMNS)
    assert len({(r["x"], r["y"]) for r in table if r["role"] == "grid"}) == 20
    assert len(table) == len(runs_in(log)) == len({r["dir"] for r in table})
    assert summary.startswith(f"map of gamma x dh: 20 grid points, {len(got)} border points "
                              f"(never|once: ")


def test_points_settle_as_in_bisect(tmp_path: Path, base: Path, log: Path) -> None:
    """The settling rules are bisect's: a point just below the repeated-to-once border ('once'
    and closing in at t_end = 4 s) is run again to 8 s, where it is 'repeated' and settled;
    a 'never' point leaves the 15-D_1 window (not settled) and is run again with
    window.above = 30, where it settles; every other point settles in one run. map.csv's
    rows say so (t_end, above, status, settled), and the stand-in ran exactly those runs."""
    out = tmp_path / "m"
    sweepmap.trace_map(settings(base, out), 2, FakeLaunch())
    table = rows(out / "map.csv")
    points: dict[tuple[float, float], list[tuple[str, str, str, str, str]]] = {}
    for r in table:
        points.setdefault((float(r["x"]), float(r["y"])), []).append(
            (r["t_end"], r["above"], r["status"], r["pattern"], r["settled"]))
    late = [p for p in points if fake.late(*p)]
    never = [p for p in points if fake.pattern(*p) == "never"]
    assert late and never, "the test must exercise both reruns"
    for p, mine in points.items():
        if fake.late(*p):
            assert mine == [("4", "15", "finished", "once", "no"),
                            ("8", "15", "finished", "repeated", "yes")], (p, mine)
        elif fake.pattern(*p) == "never":
            assert mine == [("4", "15", "window_escape", "never", "no"),
                            ("4", "30", "finished", "never", "yes")], (p, mine)
        else:
            assert mine == [("4", "15", "finished", fake.pattern(*p), "yes")], (p, mine)
    assert sorted(runs_in(log)) == sorted(
        (float(r["x"]), float(r["y"]), float(r["t_end"]), float(r["above"])) for r in table)


def test_a_killed_map_resumes_without_running_a_point_twice(tmp_path: Path, base: Path,
                                                            log: Path) -> None:
    """A map killed three runs into its second launch (its runs.csv lost too), then run
    again: the stand-in's log holds no run twice, the two invocations ran exactly the runs of
    one uninterrupted map, and borders.csv is that map's. A third invocation runs nothing
    and gives the same summary."""
    fresh = tmp_path / "fresh"
    _, _, summary = sweepmap.trace_map(settings(base, fresh), 2, FakeLaunch())
    whole = runs_in(log)
    log.unlink()

    out = tmp_path / "m"
    killer = FakeLaunch(kill_after=20 + 3)  # the 20 grid points, then 3 runs of the next call
    with pytest.raises(KeyboardInterrupt):
        sweepmap.trace_map(settings(base, out), 2, killer)
    assert len(killer.calls) >= 2 and not (out / "borders.csv").exists()
    (out / "runs.csv").unlink()
    first = runs_in(log)
    _, _, summary2 = sweepmap.trace_map(settings(base, out), 2, FakeLaunch())
    ran = runs_in(log)
    assert len(ran) == len(set(ran)), "a run ran twice"
    assert sorted(ran) == sorted(whole) and len(first) < len(ran)
    assert summary2 == summary
    assert rows(out / "borders.csv") == rows(fresh / "borders.csv")

    again = FakeLaunch()
    _, _, summary3 = sweepmap.trace_map(settings(base, out), 2, again)
    assert again.calls == [] and runs_in(log) == ran and summary3 == summary


def test_finer_tolerance_narrows_with_the_runs_the_directory_holds(
        tmp_path: Path, base: Path, log: Path) -> None:
    """A map of gamma in [1, 1.5] and dh in [1.5, 2.5] (2 x 2: the repeated-to-once border
    crosses both edges along gamma) with 4 jobs runs each edge in thirds; the same map with
    half the tolerance and 2 jobs (halves) first narrows each edge with those runs, so every
    run it adds lies inside a bracket of the first map, none runs twice, and its brackets lie
    in the first ones, half as wide. Another --set for that directory is refused before any
    run."""
    out = tmp_path / "m"
    area = dict(x_points=2, y_points=2, x=(1.0, 1.5), y=(1.5, 2.5))
    sweepmap.trace_map(settings(base, out, **area), 4, FakeLaunch())
    before = [(float(b["x_lo"]), float(b["x_hi"]), float(b["y"]))
              for b in rows(out / "borders.csv")]
    assert len(before) == 2 and all(b[1] - b[0] <= X_TOL * (1 + 1e-9) for b in before)
    first = runs_in(log)
    finer = settings(base, out, **area)
    finer.x.tol = X_TOL / 2
    sweepmap.trace_map(finer, 2, FakeLaunch())
    ran = runs_in(log)
    assert len(ran) == len(set(ran)) and len(ran) > len(first)
    for g, h, _, _ in ran[len(first):]:
        assert any(lo < g < hi and h == y for lo, hi, y in before), (g, h)
    for b in rows(out / "borders.csv"):
        x_lo, x_hi, y = float(b["x_lo"]), float(b["x_hi"]), float(b["y"])
        assert any(lo <= x_lo < x_hi <= hi and y == y0 for lo, hi, y0 in before), b
        assert x_hi - x_lo <= X_TOL / 2 * (1 + 1e-9)
    with pytest.raises(SweepError, match="sets"):
        sweepmap.trace_map(settings(base, out, sets=["lbm.tau=0.6"], **area), 1, FakeLaunch())
    assert runs_in(log) == ran


def test_an_edge_across_three_patterns_gives_both_borders(tmp_path: Path, base: Path,
                                                          log: Path) -> None:
    """On a 2 x 2 grid (gamma 1 and 3: 'repeated' and 'never' at both dh) each grid edge along
    gamma crosses 'once' between: it gives two border points, once|repeated and then
    never|once, each within tolerance of its true line; the edges along dh give none."""
    out = tmp_path / "m"
    sweepmap.trace_map(settings(base, out, x_points=2, y_points=2), 2, FakeLaunch())
    got = rows(out / "borders.csv")
    for b in got:
        check_bracket(b)
    by_dh: dict[str, list[str]] = {}
    for b in sorted(got, key=lambda b: float(b["x"])):
        assert b["along"] == "x"
        by_dh.setdefault(b["y"], []).append(b["patterns"])
    assert by_dh == {"1.5": ["once|repeated", "never|once"],
                     "6": ["once|repeated", "never|once"]}


def test_keep_going_marks_unsettled_points_and_maps_around_them(tmp_path: Path, base: Path,
                                                               log: Path) -> None:
    """With --max-t-end equal to the first t_end, the points just below the repeated-to-once
    border ('once' and closing in at 4 s) cannot settle. Without --keep-going the map stops
    there (SweepError naming --max-t-end). With it (gamma from 1.35, so that the grid point
    (1.35, 1.5) is such a point) the map completes: exactly the points in that band are
    unsettled (map.csv: settled 'no'), no edge from the unsettled grid point is bisected,
    an edge that meets one stops with its bracket as it is, naming the point, which lies in
    the bracket, whose ends still hold the true border; every other border point is within
    tolerance; the summary counts the unsettled points; the same map again runs nothing."""
    area = dict(x=(1.35, 3.0))
    stop = settings(base, tmp_path / "stop", **area)
    stop.max_t_end = T_END
    with pytest.raises(SweepError, match="--max-t-end"):
        sweepmap.trace_map(stop, 2, FakeLaunch())

    out = tmp_path / "m"
    cfg = settings(base, out, **area)
    cfg.max_t_end, cfg.keep_going = T_END, True
    m, _, summary = sweepmap.trace_map(cfg, 2, FakeLaunch())
    table = rows(out / "map.csv")
    points = {(float(r["x"]), float(r["y"])) for r in table}
    assert m.unsettled == {p for p in points if fake.late(*p)}
    assert (1.35, 1.5) in m.unsettled
    for r in table:
        if (float(r["x"]), float(r["y"])) in m.unsettled:
            assert r["settled"] == "no", r
    xs, ys = cfg.x.grid(), cfg.y.grid()
    off_grid = points - {(x, y) for x in xs for y in ys}
    assert not [p for p in off_grid if (p[0] == 1.35 and p[1] < ys[1])
                or (p[1] == 1.5 and p[0] < xs[1])], "an edge from an unsettled point ran"
    got = rows(out / "borders.csv")
    stuck = [b for b in got if b["unsettled"]]
    assert stuck, "the test must meet an unsettled point inside a bracket"
    for b in got:
        if not b["unsettled"]:
            check_bracket(b)
            continue
        along = b["along"]
        lo, hi = float(b[f"{along}_lo"]), float(b[f"{along}_hi"])
        fixed = float(b["y_lo"] if along == "x" else b["x_lo"])
        for t in map(float, b["unsettled"].split()):
            assert lo < t < hi and fake.late(*((t, fixed) if along == "x" else (fixed, t))), b
        assert fake.pattern(float(b["x_lo"]), float(b["y_lo"])) == b["pattern_lo"]
        assert fake.pattern(float(b["x_hi"]), float(b["y_hi"])) == b["pattern_hi"]
        assert b["pattern_lo"] != b["pattern_hi"]
    n = len(m.unsettled)
    assert summary.endswith(f", {n} unsettled point{'s' if n != 1 else ''}")
    before = runs_in(log)
    again = FakeLaunch()
    _, _, summary2 = sweepmap.trace_map(cfg, 2, again)
    assert again.calls == [] and runs_in(log) == before and summary2 == summary
    assert rows(out / "borders.csv") == got


def stand_in(path: Path, text: str) -> Path:
    path.write_text(text)
    path.chmod(path.stat().st_mode | stat.S_IEXEC)
    return path


def sweep_cli(*args: str | Path, env: dict[str, str]) -> subprocess.CompletedProcess:
    return subprocess.run([*SWEEP, *map(str, args)], capture_output=True,
                          text=True, timeout=300, env={**env, "MPLBACKEND": "Agg"})


def test_command_line_writes_the_tables_and_a_real_figure(tmp_path: Path, base: Path,
                                                          log: Path) -> None:
    """`dkt-sweep map` here (run_plan with a stand-in mpiexec, 2 jobs): exit 0, the summary
    line last; map.csv and borders.csv with their columns, every bracket within tolerance
    of the truth; map.png an image matplotlib reads, of the figure's size and more than a
    few colours (not blank). The same command again runs nothing (the stand-in's log does
    not grow); with another --set it is refused (exit 2, naming the sets), and a --cut that
    is not x=V or y=V is refused by the parser."""
    from matplotlib.image import imread

    mpiexec = stand_in(tmp_path / "mpiexec",
                       '#!/bin/bash\n[ "$1" = --version ] && exit 0\nshift 2\nexec "$@"\n')
    env = {**os.environ, "MPIEXEC": str(mpiexec), "MPIEXEC_PREFLAGS": ""}
    out = tmp_path / "m"
    command = ["map", base, "--x", "gamma", "--x-range", "1:3", "--x-points", "3",
               "--x-tol", "0.1", "--y", "dh", "--y-range", "1.5:6", "--y-points", "2",
               "--y-tol", "0.2", "--exe", FAKE, "--out", out, "--jobs", "2",
               "--max-t-end", "32", "--max-above", "60", "--cut", "y=2", "--cut", "x=2"]
    proc = sweep_cli(*command, env=env)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert proc.stdout.strip().splitlines()[-1].startswith("map of gamma x dh: 6 grid points")
    table = rows(out / "map.csv")
    assert list(table[0]) == list(sweepmap.MAP_COLUMNS) and len(table) == len(runs_in(log))
    got = rows(out / "borders.csv")
    assert got and list(got[0]) == list(sweepmap.BORDER_COLUMNS)
    for b in got:
        x_lo, x_hi, y_lo, y_hi = (float(b[k]) for k in ("x_lo", "x_hi", "y_lo", "y_hi"))
        assert fake.pattern(x_lo, y_lo) == b["pattern_lo"] != b["pattern_hi"] == fake.pattern(
            x_hi, y_hi)
        assert (x_hi - x_lo <= 0.1 + 1e-9) if b["along"] == "x" else (y_hi - y_lo <= 0.2 + 1e-9)
    image = imread(out / "map.png")
    assert image.ndim == 3 and image.shape[0] >= 500 and image.shape[1] >= 700, image.shape
    assert len({tuple(px) for px in image.reshape(-1, image.shape[2])[::97]}) > 10
    before = runs_in(log)
    proc = sweep_cli(*command, env=env)
    assert proc.returncode == 0 and "reuse" in proc.stdout and runs_in(log) == before
    proc = sweep_cli(*command, "--set", "lbm.tau=0.6", env=env)
    assert proc.returncode == 2 and proc.stderr.startswith("error: ") and "sets" in proc.stderr
    proc = sweep_cli(*command, "--cut", "z=1", env=env)
    assert proc.returncode == 2 and "x=VALUE or y=VALUE" in proc.stderr
    assert runs_in(log) == before
