"""A run that stops before its last step keeps everything it computed.

Every stop (a guard, a signal, the wall limit, an error found by all ranks) must leave the
particle series, /diagnostics, the CSV file and the log up to the last completed step, and a
closed, readable run file whose /run attribute stop_reason says why it ended. A damaged
checkpoint is refused before anything is allocated from it, and a marker file that cannot be
written stops the run with a message naming it. The post-processing scripts say that such a
run ended early, and why, instead of failing with a misleading message.

The guard cases are the two scenes where the stop once lost the data: case0_box with heavy
particles (the guard fires at step 100 of 200) and with a lowered Mach limit (it fires long
after the last field snapshot, which used to be where the series ended).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from dkt_run import INPUT, run, run_args, sigterm_when_logged
from dktlbm.read import text_attr

RANKS = 2
GUARD_RE = re.compile(
    r"dktlbm: error: ((?:Mach number .*|non-finite value) at step (\d+) \(t = .*)$", re.MULTILINE
)
GUARD_CASES = {
    "heavy-particles": ["run.steps=200", "pair.density=100"],
    "lowered-limit": ["run.steps=3000", "run.mach_limit=0.05", "output.field_interval=0.1"],
}
# case0 (the pair in the moving window) small enough to stop within seconds; at this coarse
# resolution the settling pair passes Mach 0.3 after about 1 s, so the limit is raised for the
# stops that are not the guard's
CASE0 = ["lbm.cells_per_diameter=10", "output.series_interval=0.01", "output.field_interval=0.1",
         "run.mach_limit=0.6"]


def read_output(out: Path, name: str) -> dict[str, object]:
    """stop_reason, dt, /particles/t, /diagnostics/t of the run file, the CSV rows (header
    excluded) and the log. Opening the file with h5py proves that it was closed cleanly."""
    with h5py.File(out / f"{name}.h5", "r") as h5:
        got = {
            "stop_reason": text_attr(h5["run"].attrs["stop_reason"]),
            "dt": float(h5["run"].attrs["dt"]),
            "t": h5["particles/t"][()],
            "diag_t": h5["diagnostics/t"][()],
            "fields": sorted(h5["fields"]),
        }
    got["csv"] = (out / f"{name}_diagnostics.csv").read_text().splitlines()[1:]
    got["log"] = (out / f"{name}.log").read_text()
    return got


def assert_series_reach(got: dict[str, object], step: int) -> None:
    """The particle series, the pair's series and the CSV all end at `step`, sample for
    sample."""
    t_stop = step * got["dt"]
    t = got["t"]
    assert t.size > 1 and t[-1] == pytest.approx(t_stop, rel=1e-12), (
        f"/particles/t ends at {t[-1]} s, the run stopped at step {step} (t = {t_stop} s)"
    )
    assert np.array_equal(got["diag_t"], t), "/diagnostics/t and /particles/t differ"
    assert len(got["csv"]) == t.size, f"CSV has {len(got['csv'])} rows, the series {t.size}"
    assert float(got["csv"][-1].split(",")[0]) == pytest.approx(t_stop, rel=1e-12)
    assert got["fields"][-1] == f"{step:06d}", f"last field snapshot {got['fields'][-1]}"


@pytest.fixture(scope="module", params=list(GUARD_CASES), ids=list(GUARD_CASES))
def guard_run(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory):
    out = tmp_path_factory.mktemp(request.param) / "g"
    args = [str(INPUT / "case0_box.nml"), "--set", f"output.dir={out}"]
    for s in GUARD_CASES[request.param]:
        args += ["--set", s]
    return out, run_args(args, RANKS, timeout=300)


def test_a_guard_stop_keeps_the_series_csv_and_log_up_to_the_guard_step(guard_run) -> None:
    """Catches a guard that aborts the job (the series buffered since the last field snapshot,
    the CSV rows and the log lost; an unreadable .h5), a guard stop that writes the series
    only up to the last snapshot, a missing stop_reason, and warnings or the guard message
    that reach standard error but not the log."""
    out, proc = guard_run
    assert proc.returncode == 3, proc.stdout + proc.stderr
    m = GUARD_RE.search(proc.stderr)
    assert m, proc.stderr
    message, step = m.group(1), int(m.group(2))
    got = read_output(out, "case0_box")
    assert got["stop_reason"] == "guard: " + message
    assert_series_reach(got, step)
    assert "error: " + message in got["log"], got["log"][-2000:]
    # the start-up warning that predicted the stop, printed before the log file was open
    assert "warning: the expected Mach number" in got["log"]


def test_postproc_says_why_a_guard_stopped_run_ended(guard_run, tmp_path: Path) -> None:
    """dkt-pattern and dkt-gap on the guard-stopped run: they classify and plot what there is
    and say that the run ended early and why. Catches the old 'the run has no particles' and
    a report that passes a truncated run off as complete."""
    out, _ = guard_run
    env = {**os.environ, "MPLBACKEND": "Agg"}
    h5 = out / "case0_box.h5"
    pattern = subprocess.run([sys.executable, "-m", "dktlbm.pattern", str(h5)],
                             capture_output=True, text=True, timeout=120, env=env)
    assert pattern.returncode == 0, pattern.stderr
    assert "incomplete: the run stopped early (guard: " in pattern.stdout
    assert "ended early (stopped: guard: " in pattern.stderr
    png = tmp_path / "gap.png"
    gap = subprocess.run([sys.executable, "-m", "dktlbm.gap", str(h5),
                          "-o", str(png)], capture_output=True, text=True, timeout=120, env=env)
    assert gap.returncode == 0, gap.stderr
    assert png.is_file() and "ended early" in gap.stderr


def test_a_wall_limit_stop_keeps_the_output_up_to_its_step(tmp_path: Path) -> None:
    """run.wall_limit: the series, CSV and fields reach the step of the stop (not only the last
    scheduled sample), the file says 'wall_limit', the log says how to resume."""
    out = tmp_path / "w"
    proc = run("case0.nml", RANKS, [*CASE0, "run.steps=120000", "run.wall_limit=2"], out)
    m = re.search(r"stopped at run\.wall_limit after step (\d+) of", proc.stdout)
    assert m, proc.stdout
    got = read_output(out, "case0")
    assert got["stop_reason"] == "wall_limit"
    assert_series_reach(got, int(m.group(1)))
    assert "stopped at run.wall_limit" in got["log"] and "--restart" in got["log"]


def test_a_signal_stop_keeps_the_output_up_to_its_step(tmp_path: Path) -> None:
    """SIGTERM mid-run: as the wall limit, with stop_reason 'signal'."""
    out = tmp_path / "s"
    sets = [*CASE0, "run.steps=120000", "run.progress_every=100"]
    proc = sigterm_when_logged("case0.nml", RANKS, sets, out, "step 100/")
    stdout, stderr = proc.stdout, proc.stderr
    assert proc.returncode == 0, stderr
    m = re.search(r"stopped on signal SIGTERM after step (\d+) of", stdout)
    assert m, stdout
    got = read_output(out, "case0")
    assert got["stop_reason"] == "signal"
    assert_series_reach(got, int(m.group(1)))
    assert "stopped on signal SIGTERM" in got["log"]


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    out = tmp_path_factory.mktemp("chk") / "run"
    run("case0.nml", RANKS, [*CASE0, "run.steps=100", "run.checkpoint_every=100"], out)
    return out, out / "case0_chk_000000100.h5"


def _state(path: Path, index: int, value: int) -> None:
    with h5py.File(path, "r+") as h5:
        h5["state_int"][index] = value


def _small_f(path: Path) -> None:
    with h5py.File(path, "r+") as h5:
        f = h5["f"][()]
        del h5["f"]
        h5["f"] = f[:, : f.shape[1] // 2, :]


def _truncate(path: Path) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


# /state_int: step, shift, samples, nx, ny, particles, episodes, in_episode, len(given)
DAMAGE = {
    "populations-smaller-than-the-header": (_small_f, "/f does not hold"),
    "huge-particle-count": (lambda p: _state(p, 5, 2_000_000_000), "particle count"),
    "negative-particle-count": (lambda p: _state(p, 5, -7), "particle count"),
    "negative-episode-count": (lambda p: _state(p, 6, -1), "episode count"),
    "negative-samples": (lambda p: _state(p, 2, -3), "samples"),
    "truncated-file": (_truncate, ""),
}


@pytest.mark.parametrize(("damage", "says"), DAMAGE.values(), ids=DAMAGE)
def test_a_damaged_checkpoint_is_refused_before_it_is_used(
    checkpoint: tuple[Path, Path], tmp_path: Path, damage, says: str
) -> None:
    """Each damage is refused on every rank with one message naming the file (and what is
    wrong where the header says it), no crash or abort, no hang, and the run file of the run
    to resume untouched. Catches sizes and counts used before they are checked (a garbage
    allocation, a read past a dataset, a crash in HDF5)."""
    out, good = checkpoint
    bad = tmp_path / good.name
    shutil.copy(good, bad)
    damage(bad)
    before = (out / "case0.h5").read_bytes()
    args = [str(INPUT / "case0.nml")]
    for s in [*CASE0, "run.steps=200", f"output.dir={out}"]:
        args += ["--set", s]
    proc = run_args([*args, "--restart", str(bad)], RANKS, timeout=60)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    errors = [ln for ln in proc.stderr.splitlines() if ln.startswith("dktlbm: error")]
    assert len(errors) == 1 and "[rank" not in errors[0], proc.stderr
    assert str(bad) in errors[0] and says in errors[0], errors[0]
    assert (out / "case0.h5").read_bytes() == before


@pytest.mark.parametrize("marker", ["finished", "checkpoint"])
def test_a_marker_that_cannot_be_written_stops_the_run_loudly(tmp_path: Path, marker: str) -> None:
    """The batch scripts act on <name>.finished and <name>.checkpoint; here the marker's name
    is taken by a directory, so it cannot be replaced. The run must exit non-zero with a
    message naming the marker, and still close a readable run file. Catches a marker write
    whose failure is ignored (the scripts would resubmit a finished run, or resume from an
    older checkpoint)."""
    out = tmp_path / "m"
    (out / f"case0.{marker}").mkdir(parents=True)
    sets = [*CASE0, "run.steps=100", "output.overwrite=.true.", "run.checkpoint_every=50"]
    proc = run("case0.nml", RANKS, sets, out, check=False)
    assert proc.returncode == 3, proc.stdout + proc.stderr
    errors = [ln for ln in proc.stderr.splitlines() if ln.startswith("dktlbm: error")]
    assert len(errors) == 1 and f"{out}/case0.{marker}" in errors[0], proc.stderr
    with h5py.File(out / "case0.h5", "r") as h5:
        reason = text_attr(h5["run"].attrs["stop_reason"])
    if marker == "checkpoint":
        assert reason.startswith("error: cannot write the marker file"), reason
    else:
        assert reason == "finished", reason


def test_the_eta_after_a_restart_counts_only_the_steps_of_this_process(
    checkpoint: tuple[Path, Path], tmp_path: Path
) -> None:
    """The first progress line after resuming at step 100 (at step 150): its MLUPS and its ETA
    are measured over the same 50 steps and wall time, so ETA = cells x steps left / MLUPS.
    Catches an ETA that divides the time by the absolute step number (here 150 instead of 50:
    three times too short)."""
    out, good = checkpoint
    copy = tmp_path / "run"
    shutil.copytree(out, copy)
    args = [str(INPUT / "case0.nml")]
    for s in [*CASE0, "run.steps=120000", "run.progress_every=50", "run.wall_limit=2",
              f"output.dir={copy}"]:
        args += ["--set", s]
    proc = run_args([*args, "--restart", str(copy / good.name)], RANKS, timeout=120)
    assert proc.returncode == 0, proc.stderr
    cells = re.search(r"cells (\d+) x (\d+) = (\d+)", proc.stdout)
    line = re.search(r"step 150/120000 .* MLUPS\s+([0-9.]+)\s+ETA (\d+):(\d\d):(\d\d)",
                     proc.stdout)
    assert cells and line, proc.stdout
    mlups = float(line.group(1))
    eta = int(line.group(2)) * 3600 + int(line.group(3)) * 60 + int(line.group(4))
    expected = int(cells.group(3)) * (120000 - 150) / (mlups * 1e6)
    assert expected > 10, "too fast a machine for this check"
    assert eta == pytest.approx(expected, rel=0.05, abs=1.0), (eta, expected)
