"""dkt-sweep bisect: the threshold search over pair.gamma or pair.dh.

Most tests run the search against a stand-in program (bisect_fake.py) whose pattern is a known
step function of the value (threshold 1.37; just below it the second kiss comes late, so the
pattern at t_end = 4 s is 'once' with the pair closing in, not settled, and needs t_end = 8 s;
from 1.9 on the upper particle leaves the window unless window.above is 60), called in-process,
through `dkt-sweep bisect` with a stand-in mpiexec, and through Slurm stand-ins (sbatch --wait
running the array tasks under bash, srun executing its arguments). One test bisects a real
coarse scene. Each test's docstring says what it proves."""

from __future__ import annotations

import csv
import json
import math
import os
import re
import shlex
import stat
import subprocess
import sys
import time
from pathlib import Path

import bisect_fake as fake
import pytest

from dkt_run import EXE, ROOT, dkt_command, mpi_env
from dktlbm import sweep

SWEEP = dkt_command("sweep")
FAKE = Path(__file__).resolve().parent / "bisect_fake.py"
T_END = 4.0
SCENE = """! a pair scene for the bisection tests (run only by the stand-in)
&pair
  gamma = 2.0, dh = 2.5
/
&run
  t_end = 4.0
/
"""


@pytest.fixture
def base(tmp_path: Path) -> Path:
    path = tmp_path / "pairscene.nml"
    path.write_text(SCENE)
    return path


def settings(
    base: Path,
    out: Path,
    lo: float = 1.0,
    hi: float = 2.0,
    tol: float = 0.01,
    max_t_end: float = 32.0,
    sets: list[str] | None = None,
    max_above: float = 60.0,
    grow: float = 0.0,
) -> sweep.BisectSettings:
    return sweep.BisectSettings(
        base.resolve(),
        "gamma",
        lo,
        hi,
        tol,
        sets or [],
        out.resolve(),
        str(FAKE),
        T_END,
        max_t_end,
        15.0,
        max_above,
        grow=grow,
    )


class FakeLaunch:
    """Runs the stand-in in-process; records each call as [(value, t_end, above), ...]."""

    def __init__(self) -> None:
        self.calls: list[list[tuple[float, float, float]]] = []

    def __call__(self, todo: list[sweep.PlannedRun], every: list[sweep.PlannedRun]) -> None:
        call = []
        for r in todo:
            s = fake.settings(r.args)
            call.append(
                (
                    float(s["pair.gamma"]),
                    float(s["run.t_end"]),
                    float(s.get("window.above", 15.0)),
                )
            )
            fake.main(r.args[1:])
        self.calls.append(call)


def expected_points(width: float, tol: float, jobs: int) -> list[int]:
    """Points per step of a multisection of `width` down to `tol` with up to `jobs` points a
    step, none more than needed: n = min(jobs, ceil(width/tol) - 1), width / (n + 1)."""
    steps = []
    while width > tol:
        n = min(jobs, math.ceil(width / tol) - 1)
        steps.append(n)
        width /= n + 1
    return steps


@pytest.mark.parametrize("jobs", [1, 2])
def test_search_brackets_the_threshold_and_extends_unsettled_points(
    tmp_path: Path, base: Path, jobs: int
) -> None:
    """The bracket contains the stand-in's threshold 1.37, is at most --tol wide, with
    'repeated' below and 'once' above; lo = 1 and hi = 2 run first in one call. hi leaves the
    window with window.above = 15 and 30, which settles nothing, and is run again with the
    window doubled each time until it finishes at 60, settled. Each step runs min(jobs,
    needed) new points (with --jobs 2 fewer steps than with --jobs 1). Every point in the late
    band is run at t_end 4 ('once' by t_end/2 and by t_end, but closing in: not settled) and
    again at 8 ('repeated', settled although it was 'once' by t_end/2: episodes only add);
    every other point once at 4."""
    launch = FakeLaunch()
    b, summary = sweep.bisect(settings(base, tmp_path / "b"), jobs, launch)
    rows = [r for r in csv.DictReader((tmp_path / "b" / "bisect.csv").open())]
    lo, hi = [r for r in rows if r["row"] == "lo"], [r for r in rows if r["row"] == "hi"]
    assert len(lo) == len(hi) == 1
    a, z = float(lo[0]["value"]), float(hi[0]["value"])
    assert a < fake.THRESHOLD <= z and z - a <= 0.01
    assert (lo[0]["pattern"], hi[0]["pattern"]) == ("repeated", "once")
    assert summary.startswith(
        f"gamma threshold between {lo[0]['value']} (repeated) and {hi[0]['value']} (once), "
    )

    fresh = [c for c in launch.calls if all(t == T_END and a == 15.0 for _, t, a in c)]
    assert sorted(fresh[0]) == [(1.0, T_END, 15.0), (2.0, T_END, 15.0)]
    assert launch.calls[1:3] == [[(2.0, T_END, 30.0)], [(2.0, T_END, 60.0)]]
    assert [len(c) for c in fresh[1:]] == expected_points(1.0, 0.01, jobs)
    assert len(fresh) - 1 == (7 if jobs == 1 else 5)

    runs = [r for r in rows if r["row"] == "run"]
    values = {float(r["value"]) for r in runs}
    assert sum(1 for v in values if fake.late(v)) >= 1, "the test must exercise an extension"
    for v in values - {2.0}:
        mine = sorted((float(r["t_end"]), r["settled"]) for r in runs if float(r["value"]) == v)
        assert mine == ([(4.0, "no"), (8.0, "yes")] if fake.late(v) else [(4.0, "yes")]), v
        if fake.late(v):
            assert [r["pattern"] for r in runs if float(r["value"]) == v] == ["once", "repeated"]
    assert summary.endswith(f", {len(runs)} runs")
    escaped = [(r["status"], r["settled"], r["above"]) for r in runs if r["value"] == "2"]
    assert escaped == [("window_escape", "no", "15"), ("window_escape", "no", "30"),
                       ("finished", "yes", "60")]  # fmt: skip
    assert [Path(r["dir"]).name for r in runs if r["value"] == "2"] == ["g2", "g2_a30", "g2_a60"]


def bracket(summary: str) -> tuple[float, float]:
    """The two ends in bisect's summary line 'gamma threshold between A (p) and B (q), ...'."""
    match = re.search(r"between ([0-9.]+) \(\w+\) and ([0-9.]+) \(", summary)
    assert match, summary
    return float(match[1]), float(match[2])


def test_the_estimate_counts_the_rounds_left_and_times_them() -> None:
    """The estimate of the whole bisection: the rounds left are those a bracket needs at up
    to --jobs points a round (as expected_points counts them: 7 from width 1 to 0.01 with 1
    job, 5 with 2, none once within --tol), times the mean time of a round so far (60 and
    120 s: 7 x 90 s = 0:10:30); before any round has run a point the time is not known, and a
    narrowed bracket gives no line."""
    assert sweep.rounds_left(1.0, 0.01, 1) == len(expected_points(1.0, 0.01, 1)) == 7
    assert sweep.rounds_left(1.0, 0.01, 2) == len(expected_points(1.0, 0.01, 2)) == 5
    assert sweep.rounds_left(0.01, 0.01, 3) == 0
    line = sweep.bisect_estimate(1.0, 2.0, 0.01, 1, [60.0, 120.0])
    assert line is not None and line.startswith(
        "estimate: about 0:10:30 left for the whole bisection: 7 more rounds narrow [1, 2] "
        "to --tol 0.01 (1 point in the next), at 0:01:30 a round so far"), line
    assert sweep.bisect_estimate(1.0, 2.0, 0.01, 2, []) == (
        "estimate: 5 more rounds narrow [1, 2] to --tol 0.01 (2 points in the next); the time "
        "of a round is not known yet")
    assert sweep.bisect_estimate(1.0, 1.01, 0.01, 1, [60.0]) is None


@pytest.mark.parametrize("jobs", [1, 2])
def test_bisect_prints_an_estimate_for_the_whole_bisection_after_each_round(
    tmp_path: Path, base: Path, jobs: int, capsys: pytest.CaptureFixture[str]
) -> None:
    """After the ends' round and after each round that leaves the bracket wider than --tol,
    the search prints one estimate line of the time the whole bisection has left, its count
    of rounds going down by one a round to 1 (none after the last round), the first from the
    ends' round's own time."""
    sweep.bisect(settings(base, tmp_path / "b"), jobs, FakeLaunch())
    lines = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("estimate:")]
    counts = [int(re.search(r"(\d+) more rounds? narrow", ln).group(1)) for ln in lines]
    rounds = len(expected_points(1.0, 0.01, jobs))
    assert counts == list(range(rounds, 0, -1)), lines
    assert all(re.match(r"estimate: about \d+:\d\d:\d\d left for the whole bisection", ln)
               for ln in lines), lines


def test_rerun_reuses_runs_narrows_and_refuses_other_settings(tmp_path: Path, base: Path) -> None:
    """The same bisection again in the same directory runs nothing and gives the same bracket.
    A tighter --tol (here also with one point a step instead of two) first narrows with the
    points settled before (thirds such as 1.3333333: runs.csv must keep their 8 digits), then
    runs only new points, inside the first bracket (none of them run before); its bracket
    lies in the first one, and runs.csv lists both searches' runs.
    Another --set or an edited base scene for that directory is refused with a message
    naming what changed, before any run."""
    out = tmp_path / "b"
    first = FakeLaunch()
    _, summary = sweep.bisect(settings(base, out, tol=0.1), 2, first)
    again = FakeLaunch()
    _, summary2 = sweep.bisect(settings(base, out, tol=0.1), 2, again)
    assert again.calls == [] and summary2 == summary
    lo1, hi1 = bracket(summary)
    finer = FakeLaunch()
    _, summary3 = sweep.bisect(settings(base, out, tol=0.01), 1, finer)
    new = [value for call in finer.calls for value, _, _ in call]
    ran_before = {value for call in first.calls for value, _, _ in call}
    assert new and all(lo1 < value < hi1 and value not in ran_before for value in new)
    plan = {r.id for r in sweep.read_plan(out)}  # runs.csv keeps both searches' runs
    assert {f"g{v:.8g}" for v in ran_before | set(new)} <= {i.split("_")[0] for i in plan}
    lo3, hi3 = bracket(summary3)
    assert lo1 <= lo3 < hi3 <= hi1 and hi3 - lo3 <= 0.01
    with pytest.raises(sweep.SweepError, match="sets"):
        sweep.bisect(settings(base, out, sets=["lbm.tau=0.6"]), 1, again)
    base.write_text(SCENE.replace("2.5", "3.0"))
    with pytest.raises(sweep.SweepError, match="base"):
        sweep.bisect(settings(base, out), 1, again)
    assert again.calls == []


def test_refusals_name_the_problem(tmp_path: Path, base: Path) -> None:
    """Ends with the same pattern are refused naming both patterns (after the two runs only);
    a point not settled within --max-t-end, a point that still leaves the window at
    --max-above, and a run stopped by a guard each stop the search with a message naming the
    run's directory and the reason."""
    launch = FakeLaunch()
    with pytest.raises(sweep.SweepError, match="same pattern, once and once"):
        sweep.bisect(settings(base, tmp_path / "same", lo=1.5, hi=1.8), 1, launch)
    assert len(launch.calls) == 1 and len(launch.calls[0]) == 2
    cases = [
        (dict(lo=1.3, hi=1.5, max_t_end=4.0), "g1.3.*--max-t-end 4"),
        (dict(lo=1.0, hi=2.0, max_above=30.0), "g2_a30.*left the window.*--max-above 30"),
        (dict(lo=1.0, hi=12.0), "g12.*guard"),
    ]
    for k, (kw, pattern) in enumerate(cases):
        with pytest.raises(sweep.SweepError, match=pattern):
            sweep.bisect(settings(base, tmp_path / f"c{k}", **kw), 1, FakeLaunch())


def test_a_growing_window_never_runs_a_point_again_for_an_escape(tmp_path: Path,
                                                                  base: Path) -> None:
    """With window.max_above = 60 in the runs (grow), hi = 2 (which leaves a fixed 15-D_1
    window) finishes in its first run, whose window grows: no run has another window.above,
    and the bracket is the one found with the window doubled. With a limit of 30 the escape at
    the limit stops the search at once, naming window.max_above, and hi is run once only (a
    search that doubled window.above would run g2_a30 next)."""
    launch = FakeLaunch()
    cfg = settings(base, tmp_path / "g", sets=["window.max_above=60"], grow=60.0)
    b, summary = sweep.bisect(cfg, 1, launch)
    assert {a for call in launch.calls for _, _, a in call} == {15.0}
    rows = [r for r in csv.DictReader((tmp_path / "g" / "bisect.csv").open())]
    hi = [r for r in rows if r["row"] == "run" and r["value"] == "2"]
    assert [(r["status"], r["settled"], Path(r["dir"]).name) for r in hi] == [
        ("finished", "yes", "g2")
    ]
    a, z = bracket(summary)
    assert a < fake.THRESHOLD <= z and z - a <= 0.01
    launch = FakeLaunch()
    cfg = settings(base, tmp_path / "l", sets=["window.max_above=30"], grow=30.0)
    with pytest.raises(sweep.SweepError, match=r"g2 .*window.max_above = 30 D_1.*--max-above"):
        sweep.bisect(cfg, 1, launch)
    assert [v for call in launch.calls for v, _, _ in call].count(2.0) == 1


def test_grow_option_puts_the_limit_into_every_run(tmp_path: Path, base: Path) -> None:
    """`bisect --grow --max-above 60` on the command line: every run carries
    window.max_above=60 and none another window.above; a scene that sets window.max_above
    itself grows by its own limit, and --grow adds nothing."""
    mpiexec = stand_in(
        tmp_path / "mpiexec", '#!/bin/bash\n[ "$1" = --version ] && exit 0\nshift 2\nexec "$@"\n'
    )
    env = {**os.environ, "MPIEXEC": str(mpiexec), "MPIEXEC_PREFLAGS": ""}
    for k, extra in enumerate((["--grow", "--max-above", "60"],
                               ["--grow", "--set", "window.max_above=60"])):
        out = tmp_path / f"b{k}"
        proc = sweep_cli(*fake_bisect(base, out), *extra, env=env)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        for r in csv.DictReader((out / "runs.csv").open()):
            args = shlex.split(r["command"])
            assert args.count("window.max_above=60") == 1, args
            assert not any(a.startswith("window.above=") for a in args), args


def test_max_above_means_what_window_max_above_means(tmp_path: Path, base: Path) -> None:
    """--max-above is the longest the window may be above the lowest particle's centre, the
    meaning of the key window.max_above: runs that set window.max_above = 40 (a --set) search
    up to 40 D_1 without --max-above (not 4 x window.above = 60) and grow up to it; --grow
    --max-above 40 adds window.max_above=40 to the runs; without either the search's limit is
    4 x window.above and the runs' windows grow only as the program's default lets them.
    --max-above with a different
    window.max_above is refused with one error line naming both, exit 2 (before any run)."""
    def fields(*extra: str) -> dict[str, object]:
        args = sweep.parser().parse_args([str(x) for x in fake_bisect(base, tmp_path / "o")]
                                         + list(extra))
        return sweep.search_fields(args, base)

    mode = "lbm.precision=single_arith"  # the sweep's precision, added to every search
    got = fields("--set", "window.max_above=40")
    assert (got["max_above"], got["grow"], got["sets"]) == (40.0, 40.0,
                                                            ["window.max_above=40", mode])
    got = fields("--grow", "--max-above", "40")
    assert (got["max_above"], got["grow"], got["sets"]) == (40.0, 40.0,
                                                            [mode, "window.max_above=40"])
    got = fields("--max-above", "40")
    assert (got["max_above"], got["grow"], got["sets"]) == (40.0, 0.0, [mode])
    got = fields()
    assert (got["above"], got["max_above"], got["grow"]) == (15.0, 60.0, 0.0)
    out = tmp_path / "refused"
    proc = sweep_cli(*fake_bisect(base, out), "--set", "window.max_above=40", "--max-above",
                     "120", env=dict(os.environ))
    assert proc.returncode == 2 and not out.exists(), proc.stdout + proc.stderr
    (line,) = proc.stderr.strip().splitlines()
    assert line.startswith("error: --max-above 120 and window.max_above = 40"), line


def stand_in(path: Path, text: str) -> Path:
    path.write_text(text)
    path.chmod(path.stat().st_mode | stat.S_IEXEC)
    return path


def sweep_cli(
    *args: str | Path, env: dict[str, str], timeout: float = 120.0
) -> subprocess.CompletedProcess:
    return subprocess.run(
        [*SWEEP, *map(str, args)],
        capture_output=True,
        text=True,
        timeout=timeout,
        env={**env, "MPLBACKEND": "Agg"},
    )


def fake_bisect(base: Path, out: Path) -> list[str | Path]:
    """The command line of the stand-in's bisection over gamma in [1, 2] to 0.05, 2 jobs."""
    return ["bisect", base, "--key", "gamma", "--lo", "1", "--hi", "2", "--tol", "0.05",
            "--exe", FAKE, "--out", out, "--jobs", "2"]  # fmt: skip


def test_command_line_local_and_collect(tmp_path: Path, base: Path) -> None:
    """`dkt-sweep bisect` here (runs through run_plan with a stand-in mpiexec): exit 0, the
    summary line last, a progress line per run (K of N of each step), bisect.csv with a row
    per run and the bracket, runs.csv holding every run with the plan's command form;
    `collect` on the same directory adds status, t_end, settled and left_window after the
    regime.csv columns, agreeing with bisect.csv. A second identical command reruns nothing;
    one with another --set is refused (exit 2)."""
    mpiexec = stand_in(
        tmp_path / "mpiexec", '#!/bin/bash\n[ "$1" = --version ] && exit 0\nshift 2\nexec "$@"\n'
    )
    env = {**os.environ, "MPIEXEC": str(mpiexec), "MPIEXEC_PREFLAGS": ""}
    out = tmp_path / "b"
    command = fake_bisect(base, out)
    proc = sweep_cli(*command, env=env)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    last = proc.stdout.strip().splitlines()[-1]
    assert last.startswith("gamma threshold between ") and "(repeated) and" in last
    # a progress line after each run, counting the runs of each step from 1 to their number
    steps: dict[int, list[int]] = {}
    for m in re.finditer(r"^progress: step (\d+): (\d+) of (\d+) runs finished, elapsed "
                         r"\d+:\d\d:\d\d, ETA (?:unknown|\d+:\d\d:\d\d)$",
                         proc.stdout, flags=re.M):
        steps.setdefault(int(m.group(1)), []).append(int(m.group(2)))
        assert int(m.group(2)) <= int(m.group(3))
    assert sorted(steps) == list(range(1, len(steps) + 1)) and len(steps) >= 2
    assert all(counts == list(range(1, len(counts) + 1)) for counts in steps.values())
    assert sum(map(len, steps.values())) == len(re.findall(r"^done ", proc.stdout, flags=re.M))
    bis = list(csv.DictReader((out / "bisect.csv").open()))
    runs = [r for r in bis if r["row"] == "run"]
    plan = list(csv.DictReader((out / "runs.csv").open()))
    assert {Path(r["dir"]).name for r in runs} == {r["id"] for r in plan}
    for r in plan:
        args = shlex.split(r["command"])
        assert args[:3] == [str(FAKE), str(base.resolve()), "--set"]
        assert args[-2:] == ["--set", f"output.dir={out.resolve() / r['id']}"]
    proc = sweep_cli("collect", "--out", out, env=env)
    assert proc.returncode == 0, proc.stderr
    regime = {Path(r["dir"]).name: r for r in csv.DictReader((out / "regime.csv").open())}
    assert list(next(iter(regime.values())))[:6] == list(sweep.REGIME_COLUMNS[:6])
    for r in runs:
        g = regime[Path(r["dir"]).name]
        assert (g["pattern"], g["settled"], g["status"]) == (
            r["pattern"],
            r["settled"],
            r["status"],
        )
        assert g["left_window"] == ("yes" if r["status"] == "window_escape" else "no")
    proc = sweep_cli(*command, env=env)
    assert proc.returncode == 0 and "start" not in proc.stdout and "reuse" in proc.stdout
    proc = sweep_cli(*command, "--set", "lbm.tau=0.6", env=env)
    assert proc.returncode == 2 and proc.stderr.startswith("error: ") and "sets" in proc.stderr


FAKE_SBATCH = """#!{python}
import json, os, re, subprocess, sys
from pathlib import Path

args = sys.argv[1:]
with open(os.environ["FAKE_LOG"], "a") as f:
    f.write(json.dumps(args) + "\\n")
array = [a for a in args if a.startswith("--array=")][0].partition("=")[2]
print("Submitted batch job 1001", flush=True)
status = 0
for task in array.split(","):
    env = dict(os.environ, SLURM_ARRAY_TASK_ID=task, SLURM_ARRAY_JOB_ID="1001")
    status |= subprocess.run(["bash", args[-1]], env=env).returncode
sys.exit(status if "--wait" in args else 0)
"""


def test_a_search_runs_in_the_sweep_precision_and_a_begun_one_goes_on_in_its_own(
        tmp_path: Path, base: Path) -> None:
    """`dkt-sweep bisect` on a scene that names no precision says it runs in single_arith and
    puts lbm.precision=single_arith into every run's command; a bisection whose directory was
    begun without it (as by an earlier version: bisect.json's --set list has no precision) goes
    on in the program's default, says so, and runs nothing again."""
    mpiexec = stand_in(
        tmp_path / "mpiexec", '#!/bin/bash\n[ "$1" = --version ] && exit 0\nshift 2\nexec "$@"\n'
    )
    env = {**os.environ, "MPIEXEC": str(mpiexec), "MPIEXEC_PREFLAGS": ""}
    out = tmp_path / "b"
    proc = sweep_cli(*fake_bisect(base, out), env=env)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "precision: lbm.precision = single_arith, the fastest mode" in proc.stdout
    plan = list(csv.DictReader((out / "runs.csv").open()))
    assert plan and all("--set lbm.precision=single_arith" in r["command"] for r in plan)
    old = tmp_path / "old"
    sweep.bisect(settings(base, old, tol=0.05), 2, FakeLaunch())
    before = (old / "runs.csv").read_text()
    proc = sweep_cli(*fake_bisect(base, old), env=env)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert f"precision: lbm.precision = double, as the runs {old} already holds" in proc.stdout
    assert not re.findall(r"^done ", proc.stdout, flags=re.M), proc.stdout
    assert (old / "runs.csv").read_text() == before


def test_slurm_mode_submits_each_step_as_one_array(tmp_path: Path, base: Path) -> None:
    """--slurm: each step is one `sbatch --wait --array=<rows of this step>` of DIR/sweep.slurm
    (written by slurm_script with --ntasks, --time, --partition), whose tasks run their rows'
    commands through srun; the bracket is the one the local mode finds, and runs.csv rows
    2.. are the points in the order they were submitted."""
    bindir = tmp_path / "bin"
    bindir.mkdir()
    log = tmp_path / "sbatch.jsonl"
    stand_in(bindir / "sbatch", FAKE_SBATCH.format(python=sys.executable))
    stand_in(bindir / "srun", '#!/bin/bash\nexec "$@"\n')
    env = {**os.environ, "PATH": f"{bindir}:{os.environ['PATH']}", "FAKE_LOG": str(log)}
    out = tmp_path / "s"
    proc = sweep_cli(
        *fake_bisect(base, out),
        "--slurm",
        "--ntasks",
        "3",
        "--time",
        "00:10:00",
        "--partition",
        "short",
        env=env,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    calls = [json.loads(line) for line in log.read_text().splitlines()]
    plan = list(csv.DictReader((out / "runs.csv").open()))
    submitted = []
    for call in calls:
        assert call[0] == "--wait" and call[-1] == str(out.resolve() / "sweep.slurm")
        submitted += [int(k) for k in call[1].removeprefix("--array=").split(",")]
    assert submitted == list(range(len(plan)))
    script = (out / "sweep.slurm").read_text()
    for option in ("--ntasks=3", "--time=00:10:00", "--partition=short"):
        assert f"#SBATCH {option}" in script
    local = FakeLaunch()
    _, summary = sweep.bisect(settings(base, tmp_path / "l", tol=0.05), 2, local)
    assert proc.stdout.strip().splitlines()[-1] == summary
    assert len(calls) == len(local.calls)


def test_real_bisection_of_a_coarse_scene(tmp_path: Path) -> None:
    """A real bisection: input/case2.nml at 6 spacings per smaller diameter, no fields, to its
    t_end of 8 s (t* = 59: the rules' verdicts at this end time, a check of the machinery,
    not a map), across D_h/D_1 in [2, 5] to 1.5 with 2 runs at a time, windows of fixed length
    (window.max_above = 0, so that the escapes the rules handle happen) up to 120 D_1 (under a
    minute on 2 cores). D_h = 2 kisses once, and the tumble throws the smaller disk
    aside: out of line at 8 s (not settled), it runs to 16 and 32 s, leaving windows of 15,
    30 and 60 D_1 as the pair separates, and settles `once` in line at 32 s. At 5 the upper
    disk leaves the 15-D_1 window, so the point is run again with window.above = 30, where it
    finishes with 'never'. The two ends of the bracket have different patterns, each settled
    (bisect.csv), each run that left the window was followed by one with the window doubled,
    each finished run not settled by one with t_end doubled, the bracket is at most 1.5 wide,
    and pattern.py reads the same pattern from each end's run file. A longer run of a point
    read up to a shorter one's t_end (sweep.verdict with `until`) gives the shorter run's
    verdict."""
    out = tmp_path / "real"
    t0 = time.monotonic()
    proc = sweep_cli(
        "bisect",
        ROOT / "input" / "case2.nml",
        "--key",
        "dh",
        "--lo",
        "2",
        "--hi",
        "5",
        "--tol",
        "1.5",
        "--set",
        "lbm.cells_per_diameter=6",
        "--set",
        "output.field_interval=0",
        "--set",
        "window.max_above=0",
        "--exe",
        EXE,
        "--out",
        out,
        "--jobs",
        "2",
        "--ranks",
        "1",
        "--max-above",
        "120",
        env=mpi_env(),
        timeout=600,
    )
    print(f"real bisection: {time.monotonic() - t0:.1f} s")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    rows = list(csv.DictReader((out / "bisect.csv").open()))
    (lo,), (hi,) = [r for r in rows if r["row"] == "lo"], [r for r in rows if r["row"] == "hi"]
    assert lo["pattern"] != hi["pattern"]
    assert {lo["pattern"], hi["pattern"]} <= {"repeated", "once", "never"}
    assert float(hi["value"]) - float(lo["value"]) <= 1.5
    assert lo["settled"] == hi["settled"] == "yes"
    runs = [r for r in rows if r["row"] == "run"]
    escaped = [r for r in runs if r["status"] == "window_escape"]
    assert escaped, "the test must exercise a window escape"
    for r in escaped:
        assert r["settled"] == "no"
        bigger = [q for q in runs if q["value"] == r["value"] and q["t_end"] == r["t_end"]]
        assert str(2 * int(r["above"])) in [q["above"] for q in bigger]
    unsettled = [r for r in runs if r["status"] == "finished" and r["settled"] == "no"]
    assert unsettled, "the test must exercise a finished run that is not settled"
    for r in unsettled:
        longer = [q for q in runs if q["value"] == r["value"] and q["above"] == r["above"]]
        assert f"{2 * float(r['t_end']):g}" in [q["t_end"] for q in longer]
    for end in (lo, hi):
        h5 = Path(end["dir"]) / "case2.h5"
        report = subprocess.run(
            [sys.executable, "-m", "dktlbm.pattern", str(h5), "--json"],
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert json.loads(report.stdout)["pattern"] == end["pattern"]
    # a longer run of a point, read up to a shorter run's t_end (as a later search reads it,
    # Bisector.known), gives that run's verdict
    pairs = [(r, q) for r in runs for q in runs
             if q["value"] == r["value"] and q["above"] == r["above"]
             and float(q["t_end"]) > float(r["t_end"]) and r["status"] == "finished"
             and float(q["end_t"]) >= float(r["t_end"])]
    assert pairs, "the test must compare a longer run with a shorter one"
    for r, q in pairs:
        short = sweep.verdict(Path(r["dir"]) / "case2.h5")
        cut = sweep.verdict(Path(q["dir"]) / "case2.h5", until=float(r["t_end"]))
        assert [(v.status, v.pattern, v.half, v.episodes, v.first_kiss, v.settled)
                for v in (cut, short)] == [(short.status, short.pattern, short.half,
                                            short.episodes, short.first_kiss,
                                            short.settled)] * 2, (r["dir"], q["dir"])


def test_a_resumed_search_lists_each_run_once(tmp_path: Path, base: Path) -> None:
    """A search stopped by --max-t-end (a late-band point is closing in at t_end and may not
    run longer) and then resumed with a larger limit: the resumed search narrows with the
    points settled before, and bisect.csv lists each run once, including the runs of the
    earlier point that did not settle then (it is read once, not again at each narrowing)."""
    out = tmp_path / "b"
    with pytest.raises(sweep.SweepError, match="max-t-end"):
        sweep.bisect(settings(base, out, max_t_end=T_END), 1, FakeLaunch())
    sweep.bisect(settings(base, out, max_t_end=32.0), 2, FakeLaunch())
    runs = [r["dir"] for r in csv.DictReader((out / "bisect.csv").open()) if r["row"] == "run"]
    assert runs and len(runs) == len(set(runs)), sorted(runs)


def test_kiss_mode_settles_a_kiss_at_once_and_never_as_before(
    tmp_path: Path, base: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """--kiss (a once-to-never threshold): with no episode from gamma = 1.95 on, the bracket
    holds 1.95, 'kisses' below and 'never' above, at most --tol wide. A point that kissed is
    settled by its first run: a late-band point ('once' and closing in at t_end = 4, which
    the pattern rule runs again to 8) is not run again, nor is a point in [1.9, 1.95) that
    kissed and then left the window (the pattern rule doubles the window). 'never' points
    still need the usual rule: they leave the window and settle only at window.above = 60.
    bisect.csv keeps each run's own pattern ('once'), the lo row the class 'kisses'. Then the
    same search from the command line reuses every run and prints the same bracket."""
    monkeypatch.setenv("FAKE_NEVER", "1.95")
    out = tmp_path / "k"
    cfg = settings(base, out)
    cfg.kiss = True
    b, summary = sweep.bisect(cfg, 2, FakeLaunch())
    rows = list(csv.DictReader((out / "bisect.csv").open()))
    lo = next(r for r in rows if r["row"] == "lo")
    hi = next(r for r in rows if r["row"] == "hi")
    assert (lo["pattern"], hi["pattern"]) == ("kisses", "never")
    assert float(lo["value"]) < 1.95 <= float(hi["value"])
    assert float(hi["value"]) - float(lo["value"]) <= 0.01
    runs = [r for r in rows if r["row"] == "run"]
    kissed = [r for r in runs if float(r["value"]) < 1.95]
    late = [r for r in kissed if fake.late(float(r["value"]))]
    escaped = [r for r in kissed if float(r["value"]) >= fake.ESCAPE]
    assert late and escaped, "the test must exercise both shortcuts"
    assert [r["pattern"] for r in late] == ["once"] * len(late)
    assert [r["status"] for r in escaped] == ["window_escape"] * len(escaped)
    for r in kissed:  # one run per kissing point, settled, at the first t_end and window
        assert (r["t_end"], r["above"], r["settled"]) == ("4", "15", "yes"), r
    assert len({r["value"] for r in kissed}) == len(kissed)
    never = {r["value"] for r in runs if float(r["value"]) >= 1.95}
    for value in never:
        mine = [(r["above"], r["settled"]) for r in runs if r["value"] == value]
        assert mine == [("15", "no"), ("30", "no"), ("60", "yes")], (value, mine)

    mpiexec = stand_in(
        tmp_path / "mpiexec", '#!/bin/bash\n[ "$1" = --version ] && exit 0\nshift 2\nexec "$@"\n'
    )
    env = {**os.environ, "MPIEXEC": str(mpiexec), "MPIEXEC_PREFLAGS": ""}
    command = ["bisect", base, "--key", "gamma", "--lo", "1", "--hi", "2", "--tol", "0.01",
               "--exe", FAKE, "--out", out, "--jobs", "2", "--max-t-end", "32",
               "--max-above", "60", "--kiss"]  # fmt: skip
    proc = sweep_cli(*command, env=env)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "start" not in proc.stdout and "reuse" in proc.stdout
    assert proc.stdout.strip().splitlines()[-1] == summary
    assert "(kisses) and" in summary and "(never)" in summary


def _run_rows(out: Path) -> dict[tuple[str, str], dict[str, str]]:
    """bisect.csv's run rows by (value, t_end)."""
    rows = csv.DictReader((out / "bisect.csv").open())
    return {(r["value"], r["t_end"]): r for r in rows if r["row"] == "run"}


def _seed(b: sweep.Bisector, monkeypatch: pytest.MonkeyPatch, value: float, t_end: float,
          signal_at: float | None) -> None:
    """Run the stand-in for `value` to `t_end` as the search would name it, stopped by a
    signal at `signal_at` s (None: not stopped)."""
    if signal_at is None:
        monkeypatch.delenv("FAKE_SIGNAL_AT", raising=False)
    else:
        monkeypatch.setenv("FAKE_SIGNAL_AT", str(signal_at))
    fake.main(b.planned(value, t_end, 15.0).args[1:])
    monkeypatch.delenv("FAKE_SIGNAL_AT", raising=False)


def test_longer_and_stopped_runs_answer_without_running_again(
    tmp_path: Path, base: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A point the directory's runs already answer is not run again, and the search gives
    what a fresh one gives, row for row (pattern, episodes, first kiss, settled):
    - a longer run of the value (its id with a later t_end) answers an earlier t_end, read up
      to it: the late-band points were run only to 8 s, and their rows at t_end = 4 ('once',
      closing in: not settled) come from those runs, the same as the fresh search's runs to 4;
    - one of them stopped by a signal at 6.5 s, after its second kiss: 'repeated', settled,
      also at t_end = 8;
    - a run stopped after its first kiss settles nothing under the pattern rule (a second
      may come): it is run again."""
    fresh = tmp_path / "fresh"
    _, summary = sweep.bisect(settings(base, fresh, tol=0.05), 1, FakeLaunch())
    first = _run_rows(fresh)
    values = sorted({float(v) for v, _ in first})
    late = [v for v in values if fake.late(v)]
    early = [v for v in values if v < fake.THRESHOLD and not fake.late(v)]
    assert len(late) >= 2 and early, "the test needs late-band and early points"

    out = tmp_path / "seeded"
    seeder = sweep.Bisector(settings(base, out, tol=0.05), 1, FakeLaunch())
    for k, value in enumerate(late):
        _seed(seeder, monkeypatch, value, 8.0, 6.5 if k == 0 else None)
    _seed(seeder, monkeypatch, early[0], T_END, 1.2)
    launch = FakeLaunch()
    _, summary2 = sweep.bisect(settings(base, out, tol=0.05), 1, launch)
    assert bracket(summary2) == bracket(summary)
    rows = [r for r in csv.DictReader((out / "bisect.csv").open()) if r["row"] == "run"]
    files = len({r["dir"] for r in rows})
    assert files < len(rows) and summary2.endswith(
        f", {len(rows)} verdicts from {files} runs (longer runs read up to earlier end "
        f"times)"), summary2
    ran = [(value, t_end) for call in launch.calls for value, t_end, _ in call]
    assert not [v for v, _ in ran if v in late], ran
    assert (early[0], T_END) in ran
    second = _run_rows(out)
    assert second.keys() == first.keys()
    for key, row in first.items():
        got = second[key]
        assert [got[c] for c in ("pattern", "episodes", "first_kiss_t", "settled")] == [
            row[c] for c in ("pattern", "episodes", "first_kiss_t", "settled")], (key, got)
    for value in late:
        cut = second[(f"{value:.8g}", "4")]
        assert Path(cut["dir"]).name == f"g{value:.8g}_t8" and cut["wall_s"] == ""
        assert (cut["pattern"], cut["settled"]) == ("once", "no")
    stopped = second[(f"{late[0]:.8g}", "8")]
    assert (stopped["status"], stopped["pattern"], stopped["settled"]) == (
        "signal", "repeated", "yes")
    assert second[(f"{early[0]:.8g}", "4")]["status"] == "finished"


def test_kiss_mode_reuses_a_run_stopped_after_its_kiss(
    tmp_path: Path, base: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """With --kiss, a run stopped by a signal after its first kiss settles its point
    ('kisses'; episodes only add): every kissing point of a fresh search, seeded as a run
    stopped at 1.1 s (its kiss starts at 1.0), is not run again, while a 'never' point
    stopped at 1.1 s (no kiss yet: it may still come) is run again. The bracket is the fresh
    search's; collect shows each stopped run with its pattern so far ('once', not settled)."""
    monkeypatch.setenv("FAKE_NEVER", "1.95")
    fresh = tmp_path / "fresh"
    cfg = settings(base, fresh, tol=0.05)
    cfg.kiss = True
    _, summary = sweep.bisect(cfg, 1, FakeLaunch())
    values = sorted({float(v) for v, _ in _run_rows(fresh)})
    kissing = [v for v in values if v < 1.95]
    never = [v for v in values if v >= 1.95]
    assert kissing and never

    out = tmp_path / "seeded"
    cfg = settings(base, out, tol=0.05)
    cfg.kiss = True
    seeder = sweep.Bisector(cfg, 1, FakeLaunch())
    for value in kissing + never[:1]:
        _seed(seeder, monkeypatch, value, T_END, 1.1)
    launch = FakeLaunch()
    _, summary2 = sweep.bisect(cfg, 1, launch)
    assert bracket(summary2) == bracket(summary)
    ran = {value for call in launch.calls for value, _, _ in call}
    assert not ran & set(kissing) and never[0] in ran
    rows = _run_rows(out)
    for value in kissing:
        row = rows[(f"{value:.8g}", "4")]
        assert (row["status"], row["pattern"], row["settled"]) == ("signal", "once", "yes")

    proc = sweep_cli("collect", "--out", out, env=dict(os.environ))
    assert proc.returncode == 0, proc.stderr
    regime = {r["gamma"]: r for r in csv.DictReader((out / "regime.csv").open())}
    for value in kissing:
        r = regime[f"{value:g}"]
        assert (r["pattern"], r["status"], r["settled"]) == ("once", "signal", "no"), r


def _pair_state(t: list[float], gap: list[float], v_upper: float, v_lower: float):
    """A stand-in for read.Pair at its last sample: times t (s), gaps D_r (cm), and the
    particles' vertical velocities there (cm/s; particle 0 is the lower one)."""
    from types import SimpleNamespace

    import numpy as np

    n = len(t)
    series = {"y": np.tile([10.0, 12.0], (n, 1)), "v": np.tile([v_lower, v_upper], (n, 1))}
    return SimpleNamespace(run=SimpleNamespace(series=series), t=np.asarray(t),
                           dr=np.asarray(gap), d1=0.2)


def test_closing_in_sees_a_pair_that_has_turned_back() -> None:
    """The closing-in rule on the shape Case-1 at gamma = 1.1875, 16 per D, showed at
    t* = 100: the gap peaked at 90 % of the run (14.23 D_1) and is 0.3 % below it at the end,
    still above its value a quarter of the run before, with the upper disk 0.5 % faster. It
    kissed again at t* = 220, so the pair must count as closing in (a rule that asked for the
    gap to be below its value a quarter of the run before did not). A pair separating with
    the upper disk slower is not closing in; one whose gap shrinks over the last tenth while
    the upper disk is already slower is."""
    t = [0.1 * k for k in range(101)]
    turned = [0.2 * (13.2 + 1.03 * min(k, 90) / 90 - 0.0005 * max(k - 90, 0)) for k in range(101)]
    assert turned[-1] > turned[75] and turned[-1] < max(turned)
    closing, state = sweep.closing_in(_pair_state(t, turned, -1.180, -1.174))
    assert closing and "shrinking" in state, state
    apart = [0.2 * (2 + 0.12 * k) for k in range(101)]
    assert not sweep.closing_in(_pair_state(t, apart, -0.9, -1.17))[0]
    slowing = apart[:90] + [apart[89] - 0.001 * k for k in range(1, 12)]
    assert sweep.closing_in(_pair_state(t, slowing, -1.16, -1.17))[0]
