"""dkt-sweep: the value lists, the plan (runs.csv), the Slurm job array (run with a
stand-in srun), collecting patterns into the regime map from synthetic run directories, and
running a one-run plan of a small real scene here. Each test's docstring says what it
proves."""

from __future__ import annotations

import csv
import itertools
import math
import os
import re
import shlex
import stat
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
import synthetic as syn

from dkt_run import EXE, ROOT, dkt_command, mpi_env
from dktlbm import sweep

SWEEP = dkt_command("sweep")
BASE_TEXT = """! a pair scene for the plan tests (never run; dkt-sweep plan checks its corners)
&pair
  gamma = 2.0, dh = 4.0, y_upper = 4.0
/
"""


def sweep_cli(*args: str | Path, env: dict[str, str] | None = None,
              timeout: float = 120.0) -> subprocess.CompletedProcess:
    return subprocess.run([*SWEEP, *map(str, args)], capture_output=True,
                          text=True, timeout=timeout,
                          env={**os.environ, "MPLBACKEND": "Agg", **(env or {})})


def read_csv(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


@pytest.fixture
def base(tmp_path: Path) -> Path:
    path = tmp_path / "pairscene.nml"
    path.write_text(BASE_TEXT)
    return path


def test_value_lists_and_inclusive_ranges() -> None:
    """--gamma/--dh values: comma lists, inclusive start:stop:step ranges (also when the step
    does not divide exactly in binary, 0.1:0.3:0.1 has three values), mixtures, each value
    once; nonsense is refused."""
    assert sweep.parse_values("1.5,2,2.5") == [1.5, 2.0, 2.5]
    assert sweep.parse_values("1:3:0.5") == [1.0, 1.5, 2.0, 2.5, 3.0]
    assert sweep.parse_values("0.1:0.3:0.1") == pytest.approx([0.1, 0.2, 0.3])
    assert sweep.parse_values("1,2:4:1,4") == [1.0, 2.0, 3.0, 4.0]
    assert sweep.parse_values("1:2.9:1") == [1.0, 2.0]
    for bad in ("", "a", "1:2", "3:1:0.5", "1:3:0", "-1", "1:3:-1"):
        with pytest.raises(ValueError):
            sweep.parse_values(bad)


def test_plan_writes_one_row_per_combination(tmp_path: Path, base: Path) -> None:
    """plan: runs.csv holds one row per (gamma, D_h/D_1) combination, with its own output
    directory <out>/<id> and the command `EXE BASE --set pair.gamma=G --set pair.dh=H --set
    <pass-through>... --set lbm.precision=single_arith --set output.dir=<out>/<id>`: a scene
    and --set list that name no precision run in the fastest mode within the sweep bound, and
    plan says so; one that names it keeps it."""
    out = tmp_path / "sw"
    proc = sweep_cli("plan", base, "--gamma", "1:2:0.5", "--dh", "2,4", "--set",
                     "lbm.cells_per_diameter=8", "--set", "run.t_end=0.3", "--out", out,
                     "--exe", "/opt/dkt/dktlbm")
    assert proc.returncode == 0, proc.stderr
    rows = read_csv(out / "runs.csv")
    assert list(rows[0]) == ["id", "gamma", "dh", "dir", "command"]
    combos = list(itertools.product([1.0, 1.5, 2.0], [2.0, 4.0]))
    assert [(float(r["gamma"]), float(r["dh"])) for r in rows] == combos
    assert len({r["id"] for r in rows}) == len(rows)
    for r, (g, h) in zip(rows, combos, strict=True):
        run_dir = out.resolve() / r["id"]
        assert Path(r["dir"]) == run_dir
        assert shlex.split(r["command"]) == [
            "/opt/dkt/dktlbm", str(base.resolve()),
            "--set", f"pair.gamma={g:g}", "--set", f"pair.dh={h:g}",
            "--set", "lbm.cells_per_diameter=8", "--set", "run.t_end=0.3",
            "--set", "lbm.precision=single_arith", "--set", f"output.dir={run_dir}"]
    assert "precision: lbm.precision = single_arith, the fastest mode" in proc.stdout
    given = tmp_path / "given"
    proc = sweep_cli("plan", base, "--gamma", "1", "--dh", "2", "--set", "lbm.precision=double",
                     "--out", given, "--exe", "/opt/dkt/dktlbm")
    assert proc.returncode == 0, proc.stderr
    (row,) = read_csv(given / "runs.csv")
    assert shlex.split(row["command"]).count("lbm.precision=double") == 1
    assert "lbm.precision=single_arith" not in row["command"]
    assert "precision: lbm.precision = double (given)" in proc.stdout


def test_plan_without_lists_is_one_run_with_the_scene_values(tmp_path: Path,
                                                               base: Path) -> None:
    """plan with neither --gamma nor --dh: one run of the base scene as it is (no pair.*
    overrides); its gamma and D_h/D_1 columns are the scene's (2 and 4), a --set of pair.dh
    taking precedence over the scene; the default executable is this tree's build/dktlbm (or
    dktlbm on PATH)."""
    out = tmp_path / "one"
    proc = sweep_cli("plan", base, "--set", "pair.dh=6", "--out", out)
    assert proc.returncode == 0, proc.stderr
    (row,) = read_csv(out / "runs.csv")
    assert (row["gamma"], row["dh"]) == ("2", "6")
    args = shlex.split(row["command"])
    assert args[0] == sweep.default_exe()
    assert "pair.gamma=2" not in args and args.count("--set") == 3
    assert "lbm.precision=single_arith" in args


def test_plan_refuses_a_missing_scene_and_bad_lists(tmp_path: Path, base: Path) -> None:
    """A missing base scene is one `error:` line with status 2; a bad range is refused by the
    command line (status 2); neither writes runs.csv."""
    out = tmp_path / "bad"
    proc = sweep_cli("plan", tmp_path / "nope.nml", "--out", out)
    assert proc.returncode == 2 and proc.stderr.startswith("error: ")
    assert str(tmp_path / "nope.nml") in proc.stderr and "Traceback" not in proc.stderr
    proc = sweep_cli("plan", base, "--gamma", "3:1:1", "--out", out)
    assert proc.returncode == 2 and "--gamma" in proc.stderr
    assert not (out / "runs.csv").exists()
    proc = sweep_cli("run", "--out", out)
    assert proc.returncode == 2 and proc.stderr.startswith("error: ")
    assert "runs.csv" in proc.stderr


def test_plan_is_bounded_and_checked_by_the_program(tmp_path: Path, base: Path) -> None:
    """plan refuses, writing nothing: a range of more values than a list takes (1:1e9:1e-9
    ran on), a plan of more runs than --max-runs (which lets them through when raised), and
    values the program refuses, found by its own --check on the plan's corners (gamma 0.5,
    lbm.tau=abc), quoting the program's message. --no-check plans without asking."""
    out = tmp_path / "plan"
    proc = sweep_cli("plan", base, "--gamma", "1:1e9:1e-9", "--out", out)
    assert proc.returncode == 2 and "a list takes at most 10000" in proc.stderr, proc.stderr
    proc = sweep_cli("plan", base, "--gamma", "1:3:0.01", "--dh", "2:6:0.1", "--out", out)
    assert proc.returncode == 2, proc.stderr
    assert f"{201 * 41} runs, more than --max-runs 1000" in proc.stderr
    assert not out.exists()
    proc = sweep_cli("plan", base, "--gamma", "1:3:0.5", "--dh", "2:6:1", "--max-runs", "25",
                     "--no-check", "--out", out)
    assert proc.returncode == 0 and len(read_csv(out / "runs.csv")) == 25, proc.stderr
    for bad in (["--gamma", "0.5,1.5"], ["--gamma", "1.5", "--set", "lbm.tau=abc"]):
        other = tmp_path / "refused"
        proc = sweep_cli("plan", base, *bad, "--out", other, "--exe", EXE)
        assert proc.returncode == 2, proc.stdout + proc.stderr
        lines = proc.stderr.splitlines()
        assert "refused by" in lines[0] and "--check" in lines[0], proc.stderr
        assert lines[1].startswith("dktlbm: error:"), proc.stderr
        assert not other.exists()


def test_slurm_array_runs_row_k_with_srun(tmp_path: Path, base: Path) -> None:
    """slurm: sweep.slurm is a job array 0..n-1 with the requested ranks, time and partition
    and the --signal=B:USR1@120 option with its reason; run by bash as array task k (with a
    stand-in srun that records its arguments) it runs exactly row k's command through srun
    (with the MPI plugin DKT_SRUN_MPI and the executable DKTLBM), appending to
    <out>/<id>/run.log; as the stand-in leaves neither a finished run nor a checkpoint, the
    task exits 1 and submits nothing; a task number beyond the plan fails."""
    out = tmp_path / "sw"
    assert sweep_cli("plan", base, "--gamma", "1,2,3", "--dh", "2,4", "--set",
                     "particles.x=0.9,1.1", "--out", out, "--exe", "/x/dktlbm").returncode == 0
    proc = sweep_cli("slurm", "--out", out, "--ntasks", "8", "--time", "02:00:00",
                     "--partition", "short")
    assert proc.returncode == 0, proc.stderr
    text = (out / "sweep.slurm").read_text()
    lines = text.splitlines()
    assert lines[0] == "#!/bin/bash"
    for option in ("--array=0-5", "--ntasks=8", "--time=02:00:00", "--partition=short",
                   "--signal=B:USR1@120"):
        assert f"#SBATCH {option}" in lines, option
    at = lines.index("#SBATCH --signal=B:USR1@120")
    reason = list(itertools.takewhile(lambda ln: ln.startswith("# "), reversed(lines[:at])))
    assert "SIGUSR1" in " ".join(reason) and "checkpoint" in " ".join(reason)

    fake = tmp_path / "bin"
    fake.mkdir()
    record = tmp_path / "srun.args"
    srun = fake / "srun"
    srun.write_text(f'#!/bin/bash\nprintf "%s\\n" "$@" > {shlex.quote(str(record))}\n'
                    'echo "stand-in srun ran"\n')
    srun.chmod(srun.stat().st_mode | stat.S_IEXEC)
    rows = read_csv(out / "runs.csv")
    exe = fake / "dktlbm"
    exe.write_text("#!/bin/sh\n")
    exe.chmod(0o755)
    env = {**os.environ, "PATH": f"{fake}:{os.environ['PATH']}", "SLURM_ARRAY_TASK_ID": "4",
           "DKT_LAUNCHER": "srun", "DKT_SRUN_MPI": "pmix", "DKTLBM": str(exe)}
    for key in [k for k in env if k.startswith("SLURM_") and k != "SLURM_ARRAY_TASK_ID"]:
        del env[key]
    proc = subprocess.run(["bash", str(out / "sweep.slurm")], capture_output=True, text=True,
                          env=env, timeout=60)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "without a checkpoint" in proc.stdout
    row_dir = out / rows[4]["id"]
    assert record.read_text().splitlines() == [
        "--mpi=pmix", str(exe), *shlex.split(rows[4]["command"])[1:],
        "--set", f"output.dir={row_dir}"]
    assert "stand-in srun ran" in (row_dir / "run.log").read_text()

    env["SLURM_ARRAY_TASK_ID"] = "6"
    proc = subprocess.run(["bash", str(out / "sweep.slurm")], capture_output=True, text=True,
                          env=env, timeout=60)
    assert proc.returncode != 0


def test_collect_writes_the_regime_table_and_map(tmp_path: Path, base: Path) -> None:
    """collect: one regime.csv row per planned run with the pattern read from the run file
    (from /diagnostics when written; computed from /particles for a finished file without
    it), the number of episodes and the first kissing time; 'failed' for a file that is not
    a finished run, 'missing' for a run without a file; after the original columns, the
    status, t_end, whether the pattern is settled (episodes by t_end/2 give the same
    pattern) and whether a particle left the window; regime.png is drawn. With --with DIR2
    the runs of another directory are added after them; a --with directory without a plan is
    refused."""
    out = tmp_path / "sw"
    assert sweep_cli("plan", base, "--gamma", "1:3:1", "--dh", "2,4", "--out",
                     out).returncode == 0
    plan = read_csv(out / "runs.csv")
    k = syn.SHAPES

    def file_of(row: dict[str, str]) -> Path:
        return out / row["id"] / "pairscene.h5"

    def written(pattern: str, episodes: list[tuple[float, float]]) -> dict:
        return {"attrs": {"pattern": pattern, "episodes": len(episodes), "open_episode": 0},
                "episodes": episodes}

    syn.write_run(file_of(plan[0]), k["repeated"], fields=False,
                  diagnostics=written("repeated", [(0.96, 1.45), (1.94, 2.07)]))
    syn.write_run(file_of(plan[1]), k["once"], fields=False,
                  diagnostics=written("once", [(0.97, 1.46)]))
    syn.write_run(file_of(plan[2]), k["never"], fields=False, diagnostics=written("never", []))
    syn.write_run(file_of(plan[3]), k["once"], fields=False)  # finished, no /diagnostics
    syn.write_run(file_of(plan[4]), k["repeated"], fields=False, finished=False)
    # plan[5]: never run

    proc = sweep_cli("collect", "--out", out)
    assert proc.returncode == 0, proc.stderr
    rows = read_csv(out / "regime.csv")
    assert list(rows[0])[:6] == ["gamma", "dh", "pattern", "episodes", "first_kiss_t", "dir"]
    assert [(r["gamma"], r["dh"]) for r in rows] == [(p["gamma"], p["dh"]) for p in plan]
    assert [r["pattern"] for r in rows] == ["repeated", "once", "never", "once", "failed",
                                            "missing"]
    assert [r["episodes"] for r in rows] == ["2", "1", "0", "1", "", ""]
    # the columns after `dir`: the runs end at 3 s; the second kiss of the first (1.94 s) comes
    # after t_end/2, but 'repeated' is final once reached (episodes only add); the others'
    # pairs are not closing in at the end; no run left a window
    assert [r["status"] for r in rows] == ["finished"] * 4 + ["failed", "missing"]
    assert [r["settled"] for r in rows] == ["yes", "yes", "yes", "yes", "", ""]
    assert [r["left_window"] for r in rows] == ["no"] * 5 + [""]
    assert [r["t_end"] for r in rows[:4]] == ["3"] * 4
    assert float(rows[0]["first_kiss_t"]) == pytest.approx(0.96)
    assert rows[2]["first_kiss_t"] == ""
    first = syn.first_sample_at_or_after(syn.crossing(k["once"], 0, syn.ENTER))
    assert float(rows[3]["first_kiss_t"]) == pytest.approx(first)
    assert [Path(r["dir"]).name for r in rows] == [p["id"] for p in plan]
    png = out / "regime.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 2000

    # --with: a second directory's runs join the table and the map written to the first
    other = tmp_path / "sw2"
    assert sweep_cli("plan", base, "--gamma", "1.5", "--dh", "3", "--out",
                     other).returncode == 0
    syn.write_run(other / "g1.5_h3" / "pairscene.h5", k["never"], fields=False,
                  diagnostics=written("never", []))
    proc = sweep_cli("collect", "--out", out, "--with", other)
    assert proc.returncode == 0, proc.stderr
    both = read_csv(out / "regime.csv")
    assert both[:6] == rows
    assert [(r["gamma"], r["dh"], r["pattern"], Path(r["dir"]).parent.name) for r in both[6:]] \
        == [("1.5", "3", "never", "sw2")]
    proc = sweep_cli("collect", "--out", out, "--with", tmp_path / "nothing")
    assert proc.returncode == 2 and "nothing" in proc.stderr


def set_stop_reason(h5: Path, reason: str) -> None:
    """Write /run stop_reason into a synthetic run file (as the program ends a run)."""
    with h5py.File(h5, "a") as f:
        f["run"].attrs["stop_reason"] = np.bytes_(reason.encode())


def test_collect_counts_settled_unsettled_and_escapes_and_says_what_next(
        tmp_path: Path, base: Path) -> None:
    """collect's summary after the table, for a 3 x 2 plan (--set run.t_end=3 --set
    window.above=15) of: a settled 'repeated', a settled 'once' in line, a 'once' out of line
    at its end (finished, unsettled), a 'once' whose particle left the window (unsettled), a
    run a guard stopped, and a run never started. It counts 2 settled, 2 unsettled and 2
    without a pattern (failed: 1, missing: 1); names the two runs that stopped before t_end
    with their stop reasons; gives the `dkt-sweep plan` command that plans the finished
    unsettled run again with run.t_end doubled (its own --set options kept, its gamma and dh
    only) into DIR_t6, and the one that plans the escaped run in a window that grows up to 4 x
    15 = 60 D_1 into DIR_a60, each followed by `dkt-sweep run` and `collect --with`; says that
    `dkt-sweep run` runs the missing run and names the failed run's run.log. Each printed plan
    command, run, plans exactly its run with the changed setting. Runs that are not a full
    grid get one plan per gamma; a sweep whose runs are all settled says so and asks for
    nothing."""
    out = tmp_path / "sw"
    assert sweep_cli("plan", base, "--gamma", "1:3:1", "--dh", "2,4", "--set", "run.t_end=3",
                     "--set", "window.above=15", "--no-check", "--out", out).returncode == 0
    plan = sweep.read_plan(out)
    k = syn.SHAPES
    syn.write_run(plan[0].h5, k["repeated"], fields=False)
    syn.write_run(plan[1].h5, k["once"], fields=False)
    syn.write_run(plan[2].h5, k["once"], fields=False, across=0.3)
    syn.write_run(plan[3].h5, k["once"], fields=False)
    set_stop_reason(plan[3].h5, "window_escape")
    syn.write_run(plan[4].h5, k["repeated"], fields=False, finished=False)
    set_stop_reason(plan[4].h5, "guard: overlap")
    # plan[5]: never run
    proc = sweep_cli("collect", "--out", out)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert "6 runs: 2 settled, 2 unsettled, 2 without a pattern (failed: 1, missing: 1)" in lines
    assert "2 stopped before t_end: g2_h4 (window_escape), g3_h2 (guard: overlap)" in lines
    later = f"{out}_t6"
    grown = f"{out}_a60"
    plans = [ln.strip() for ln in lines if ln.startswith("  dkt-sweep plan ")]
    assert plans == [
        f"dkt-sweep plan {base} --gamma 2 --dh 2 --set window.above=15 "
        f"--set lbm.precision=single_arith --set run.t_end=6 --out {later}",
        f"dkt-sweep plan {base} --gamma 2 --dh 4 --set run.t_end=3 --set window.above=15 "
        f"--set lbm.precision=single_arith --set window.max_above=60 --out {grown}"], lines
    for new in (later, grown):
        assert f"  dkt-sweep run --out {new} --jobs N" in lines
        assert f"  dkt-sweep collect --out {out} --with {new}" in lines
    assert any(ln.startswith(f"1 run not run to its end yet: `dkt-sweep run --out {out}`")
               for ln in lines), lines
    assert any(ln.startswith("run g3_h2 failed (guard: overlap")
               and ln.endswith(f"see {out / 'g3_h2' / 'run.log'}") for ln in lines), lines
    for command, change in zip(plans, ("run.t_end=6", "window.max_above=60"), strict=True):
        words = shlex.split(command)[1:]
        assert sweep_cli(*words, "--no-check").returncode == 0
        (row,) = read_csv(Path(words[-1]) / "runs.csv")
        assert change in shlex.split(row["command"])
    # runs that are not a full grid: one plan per gamma, each into its own directory
    text = sweep.rerun_plans([plan[0], plan[3]], "run.t_end=6", tmp_path / "re", out)
    assert [ln.split(" --out ")[-1] for ln in text if "dkt-sweep plan" in ln] == [
        str(tmp_path / "re_1"), str(tmp_path / "re_2")]
    assert ["--gamma 1 --dh 2" in text[0], "--gamma 2 --dh 4" in text[1]] == [True, True]
    # every run settled: nothing to do next
    done = tmp_path / "done"
    assert sweep_cli("plan", base, "--gamma", "1", "--dh", "2", "--no-check", "--out",
                     done).returncode == 0
    syn.write_run(sweep.read_plan(done)[0].h5, k["repeated"], fields=False)
    proc = sweep_cli("collect", "--out", done)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.splitlines()[-1] == "1 run: 1 settled, 0 unsettled, 0 without a pattern"


UHLMANN_SETS = ["lbm.dx=0.025", "lbm.tau=0.52", "run.t_end=0.05",
                "output.field_interval=0.025", "output.series_interval=0.005"]


def test_an_escape_from_the_default_growing_window_is_rerun_in_twice_its_limit(
        tmp_path: Path, base: Path) -> None:
    """A run of the default window.max_above = -1 whose particle still left the window: its run
    file states the rows its window could reach (/run ny_max = 500 of ny = 300, dx = 0.01 cm,
    d1 = 0.2 cm: 10 D_1 beyond window.above = 15), so collect plans it again in a window of
    twice that limit, 2 x 25 = 50 D_1, not in 4 x 15 = 60 taken blindly (smaller or larger
    than the limit the run already had). A file without ny_max, or a run with
    window.max_above = 0, keeps 4 x window.above."""
    out = tmp_path / "sw"
    assert sweep_cli("plan", base, "--gamma", "2", "--dh", "4", "--set", "window.above=15",
                     "--no-check", "--out", out).returncode == 0
    (run,) = sweep.read_plan(out)
    syn.write_run(run.h5, syn.SHAPES["once"], fields=False)
    set_stop_reason(run.h5, "window_escape")
    with h5py.File(run.h5, "a") as f:
        f["run"].attrs["ny_max"] = np.int32(500)
        f["run"].attrs["d1"] = 0.2
    lines = sweep_cli("collect", "--out", out).stdout.splitlines()
    assert any("window.max_above=50 " in ln for ln in lines), lines



def test_run_executes_the_plan_skips_finished_runs_and_reports_failures(tmp_path: Path) -> None:
    """run on a one-run plan of a small real scene (input/uhlmann.nml, about a second): the run
    finishes, its output is in <out>/<id>/run.log; a second `run` skips it (file untouched),
    --force runs it again (replacing the file). A plan whose run fails (tau = 0.4 is invalid)
    gives a non-zero exit, the failure reported, and the program's message in run.log."""
    out = tmp_path / "sw"
    sets = [a for s in UHLMANN_SETS for a in ("--set", s)]
    scene = ROOT / "input" / "uhlmann.nml"
    assert sweep_cli("plan", scene, *sets, "--out", out, "--exe", EXE).returncode == 0
    env = mpi_env()
    proc = sweep_cli("run", "--out", out, "--ranks", "1", env=env, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert re.search(r"^progress: 1 of 1 runs finished, elapsed \d+:\d\d:\d\d, ETA 0:00:00$",
                     proc.stdout, flags=re.M), proc.stdout
    (row,) = read_csv(out / "runs.csv")
    h5 = out / row["id"] / "uhlmann.h5"
    assert h5.is_file() and "performance" in (out / row["id"] / "run.log").read_text()
    stamp = h5.stat().st_mtime_ns

    proc = sweep_cli("run", "--out", out, env=env, timeout=300)
    assert proc.returncode == 0 and "skip" in proc.stdout
    assert "progress: 1 of 1 runs finished" in proc.stdout
    assert h5.stat().st_mtime_ns == stamp

    proc = sweep_cli("run", "--out", out, "--force", env=env, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert h5.stat().st_mtime_ns != stamp

    bad = tmp_path / "bad"
    # a run the program refuses: planned without the check, so that `run` meets it
    assert sweep_cli("plan", scene, *sets, "--set", "lbm.tau=0.4", "--out", bad, "--exe",
                     EXE, "--no-check").returncode == 0
    proc = sweep_cli("run", "--out", bad, env=env, timeout=300)
    assert proc.returncode != 0
    assert "FAILED" in proc.stdout and "1 failed" in proc.stdout
    (row,) = read_csv(bad / "runs.csv")
    assert "tau" in (bad / row["id"] / "run.log").read_text()


AFFINITY_PROBE = """#!{python}
# stand-in for dktlbm: records the cores this rank may run on in <output.dir>/cores.txt
import os, sys, time
out = [a.split("=", 1)[1] for a in sys.argv if a.startswith("output.dir=")][-1]
os.makedirs(out, exist_ok=True)
with open(os.path.join(out, "cores.txt"), "w") as f:
    f.write(" ".join(map(str, sorted(os.sched_getaffinity(0)))))
time.sleep(1)
"""


@pytest.mark.skipif(not hasattr(os, "sched_getaffinity") or len(os.sched_getaffinity(0)) < 2,
                    reason="needs two cores and sched_getaffinity")
def test_runs_side_by_side_are_not_bound_to_the_same_core(tmp_path: Path, base: Path) -> None:
    """`run --jobs 2 --ranks 1` with a stand-in program that records its cores: each run may use
    every core this test may use. Open MPI binds a one-rank run to the first core by default,
    so without the launcher's policy both runs would share core 0 and the sweep would take
    twice as long (the environment's own binding policy is removed for this test)."""
    probe = tmp_path / "probe.py"
    probe.write_text(AFFINITY_PROBE.format(python=sys.executable))
    probe.chmod(probe.stat().st_mode | stat.S_IXUSR)
    out = tmp_path / "sw"
    assert sweep_cli("plan", base, "--gamma", "1.5,2", "--out", out,
                     "--exe", probe).returncode == 0
    env = mpi_env()
    env.pop("OMPI_MCA_hwloc_base_binding_policy", None)
    proc = sweep_cli("run", "--out", out, "--jobs", "2", "--ranks", "1", env=env)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    allowed = " ".join(map(str, sorted(os.sched_getaffinity(0))))
    rows = read_csv(out / "runs.csv")
    assert len(rows) == 2
    for row in rows:
        assert (out / row["id"] / "cores.txt").read_text() == allowed


def test_regime_map_along_one_key_puts_each_run_at_its_end(tmp_path: Path, base: Path) -> None:
    """A sweep of gamma at one D_h (as a bisection makes): the map draws gamma across and how
    far each run got in t* up (collect's rows carry the run's last sample over the file's
    t_ref: 3 s / 0.135526 s for these synthetic runs; a run without a pattern sits at 0), so
    two runs of one point with different ends stand apart; a sweep over both keys keeps the
    D_h-gamma map."""
    out = tmp_path / "sw"
    assert sweep_cli("plan", base, "--gamma", "1,2", "--dh", "2", "--out", out).returncode == 0
    plan = sweep.read_plan(out)
    syn.write_run(plan[0].h5, syn.SHAPES["once"], fields=False)
    rows = sweep.collect(plan)
    assert float(rows[0]["end_tstar"]) == pytest.approx(3.0 / 0.135526, rel=1e-5)
    assert rows[1]["pattern"] == "missing" and rows[1]["end_tstar"] == ""
    line, point = sweep.regime_layout(rows)
    assert line == "gamma"
    assert point(rows[0]) == (1.0, pytest.approx(3.0 / 0.135526, rel=1e-5))
    assert point(rows[1]) == (2.0, 0.0)
    assert "regime.png" in sweep_cli("collect", "--out", out).stdout
    assert "end_tstar" not in (out / "regime.csv").read_text()  # not a regime.csv column

    grid = [{"gamma": g, "dh": h} for g in ("1", "2") for h in ("2", "4")]
    line, point = sweep.regime_layout(grid)
    assert line is None and point(grid[1]) == (4.0, 1.0)


def test_a_once_pair_out_of_line_at_the_end_is_not_settled(tmp_path: Path) -> None:
    """A `once` run whose pair is separating at the end is settled when the particles are in
    line (centres within D_1/2 across the channel), and not when the upper one has moved
    0.3 cm (1.5 D_1) aside: off the leader's wake it may still come back into it and draft
    (the Verdict says why). The same holds for `never`."""
    for shape in ("once", "never"):
        inline = tmp_path / f"{shape}_inline" / "pair.h5"
        aside = tmp_path / f"{shape}_aside" / "pair.h5"
        syn.write_run(inline, syn.SHAPES[shape], fields=False)
        syn.write_run(aside, syn.SHAPES[shape], fields=False, across=0.3)
        v = sweep.verdict(inline)
        assert (v.pattern, v.settled) == (shape, True), v.why
        v = sweep.verdict(aside)
        assert (v.pattern, v.settled) == (shape, False), v.why
        across = (0.3 + 0.02 * math.sin(2.0 * syn.T_END)) / syn.D1  # with the synthetic sway
        assert f"out of line at t_end: the centres are {across:.3g} D_1 apart across" in v.why


def test_progress_counts_runs_and_estimates_from_the_mean_time() -> None:
    """The progress line after each run: K of N, the time since the start, and an ETA of the
    mean time of the runs that ran (skipped ones took none) times the runs left, over the
    runs side by side (2 jobs, fewer at the end); 'unknown' before any run ran."""
    now = [100.0]
    progress = sweep.Progress(5, jobs=2, clock=lambda: now[0])
    line = re.compile(r"^progress: (\d+) of 5 runs finished, elapsed (\d+):(\d\d):(\d\d), "
                      r"ETA (unknown|(\d+):(\d\d):(\d\d))$")
    steps = [(0.0, None), (40.0, 40.0), (20.0, 80.0), (3600.0, 60.0), (10.0, 50.0)]
    ran: list[float] = []
    for k, (wait, took) in enumerate(steps, start=1):
        now[0] += wait
        m = line.match(progress.finished(took))
        assert m, progress.finished
        if took is not None:
            ran.append(took)
        assert int(m.group(1)) == k
        h, mi, se = (int(x) for x in m.group(2, 3, 4))
        assert 3600 * h + 60 * mi + se == round(now[0] - 100.0)
        left = 5 - k
        if not ran:
            assert m.group(5) == "unknown"
            continue
        eta = sum(ran) / len(ran) * left / max(1, min(2, left))
        h, mi, se = (int(x) for x in m.group(6, 7, 8))
        assert 3600 * h + 60 * mi + se == math.ceil(eta)
    assert sweep.Progress(2, 1, step=3).finished(None).startswith("progress: step 3: 1 of 2 ")
