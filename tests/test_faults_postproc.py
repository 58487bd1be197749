"""Postprocessing on broken, running, paused and killed runs: a documented status or one clear
error, never a hang, never a stale pattern, and nothing of the run changed.

The runs are the pair of case1 (gamma 1.3, 10 spacings per diameter) on 2 ranks:

- broken: a finished run file cut to half its size. run_status says 'failed', `sweep collect`
  'failed', dkt-pattern and dkt-gap exit 2 with one `error:` line naming the file; the file is
  left as it was;
- running: a long run started in the background and read while it steps. run_status says
  'running', `sweep collect` 'running', dkt-pattern and dkt-gap refuse it with one error line
  that says a live run writes it, and `sweep run` skips it (it neither starts the run again nor
  overwrites its file); the run is not disturbed: SIGTERM then stops it with its checkpoint;
- paused: that run after SIGTERM (stop_reason 'signal'): run_status 'paused', `sweep collect`
  'paused' (or, after a kiss, its pattern so far with status 'signal'), dkt-pattern classifies
  it up to where it stopped and says it is incomplete;
- killed while extended: a finished run resumed from its last checkpoint with a later end and
  SIGKILLed mid-way. The run file must no longer carry the finished run's `pattern` (the
  program removes the report of the finished run when it continues it), and the reader must not
  report a pattern 'as written' for a file whose stop_reason is still 'running';
- NaN: a finished run file whose gap turns NaN at one sample, with a kiss after it: the reader
  warns on stderr naming the file and the time of the first NaN, and classifies the samples
  before it only (pattern 'never', where the kiss after the NaN would make it 'once').
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from dkt_run import EXE, INPUT, mpi_command, mpi_env, run, session_pids, tree_digest
from dktlbm import read, sweep
from test_faults_chk import C1, RANKS, STEPS  # the same runs: checkpoints at STEPS/2, STEPS

TIMEOUT = 60


def command(out: Path, sets: list[str], restart: Path | None = None) -> list[str]:
    args = [str(EXE), str(INPUT / "case1.nml")]
    for s in [*C1, *sets, f"output.dir={out}"]:
        args += ["--set", s]
    return args + (["--restart", str(restart)] if restart else [])


def planned(out: Path) -> sweep.PlannedRun:
    return sweep.PlannedRun("r", 1.3, 2.0, out, " ".join(command(out, [f"run.steps={STEPS}"])))


def cli(name: str, *args: str | Path) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "MPLBACKEND": "Agg"}
    return subprocess.run([sys.executable, "-m", f"dktlbm.{name}", *map(str, args)],
                          capture_output=True, text=True, timeout=TIMEOUT, env=env)


def assert_refused(h5: Path, why: str = "") -> None:
    """dkt-pattern and dkt-gap on `h5` exit 2 with one error line naming it (and `why`)."""
    for name in ("pattern", "gap"):
        proc = cli(name, h5)
        assert proc.returncode == 2, proc.stderr
        lines = [line for line in proc.stderr.splitlines() if line.startswith("error:")]
        assert len(lines) == 1 and str(h5) in lines[0] and why in lines[0], proc.stderr


def start(out: Path, sets: list[str], restart: Path | None = None) -> subprocess.Popen[str]:
    return subprocess.Popen(mpi_command(RANKS) + command(out, sets, restart),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=mpi_env(), start_new_session=True)


def wait_for(path: Path, text: str, proc: subprocess.Popen[str]) -> None:
    deadline = time.time() + TIMEOUT
    while time.time() < deadline:
        if path.exists() and text in path.read_text():
            return
        assert proc.poll() is None, f"the run ended early: {proc.communicate()}"
        time.sleep(0.05)
    raise AssertionError(f"{path} never said {text!r}")


def signal_ranks(proc: subprocess.Popen[str], signum: int) -> subprocess.CompletedProcess:
    for pid in session_pids(proc.pid, "dktlbm"):
        os.kill(pid, signum)
    out, err = proc.communicate(timeout=TIMEOUT)
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


@pytest.fixture(scope="module")
def finished(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("faults_postproc") / "run"
    run("case1.nml", RANKS, [*C1, f"run.steps={STEPS}"], out, timeout=300)
    return out


def test_broken_run_file(finished: Path, tmp_path: Path) -> None:
    out = tmp_path / "broken"
    out.mkdir()
    h5 = out / "case1.h5"
    data = (finished / "case1.h5").read_bytes()
    h5.write_bytes(data[: len(data) // 2])
    before = tree_digest(out)
    assert read.run_status(h5) == "failed"
    assert sweep.collect([planned(out)])[0]["pattern"] == "failed"
    assert_refused(h5)
    assert tree_digest(out) == before


def test_running_then_paused_run(tmp_path: Path) -> None:
    out = tmp_path / "live"
    proc = start(out, ["run.steps=200000"])
    try:
        wait_for(out / "case1.log", f"checkpoint {out}/case1_chk_{STEPS // 2:09d}.h5", proc)
        h5 = out / "case1.h5"
        assert read.run_status(h5) == "running"
        assert sweep.collect([planned(out)])[0]["pattern"] == "running"
        assert_refused(h5, "live run")
        failures = sweep.run_plan([planned(out)], jobs=1, ranks=RANKS, force=True)
        assert failures == 0
        assert proc.poll() is None, "the sweep disturbed the live run"
        assert h5.exists()
    finally:
        stopped = signal_ranks(proc, signal.SIGTERM)
    assert stopped.returncode == 0, stopped.stderr  # documented: a signal stop exits 0 (README)
    assert read.run_status(h5) == "paused"
    row = sweep.collect([planned(out)])[0]
    # 'paused', or after a kiss the pattern so far, with the stop reason as its status
    assert row["pattern"] in ("paused", "once", "repeated") and row["status"] == "signal", row
    assert sweep.checkpoint_of(h5) is not None
    p = cli("pattern", h5)
    assert p.returncode == 0, p.stderr
    assert "incomplete: the run stopped early (signal)" in p.stdout, p.stdout


def test_killed_extension_of_a_finished_run_keeps_no_pattern(finished: Path,
                                                             tmp_path: Path) -> None:
    out = tmp_path / "extended"
    shutil.copytree(finished, out)
    with h5py.File(out / "case1.h5", "r") as f:
        assert "pattern" in f["diagnostics"].attrs  # the finished run wrote its report
    last = out / f"case1_chk_{STEPS:09d}.h5"
    proc = start(out, ["run.steps=200000"], restart=last)
    try:
        wait_for(out / "case1.log", f"checkpoint {out}/case1_chk_{STEPS + STEPS // 2:09d}.h5",
                 proc)
    finally:
        signal_ranks(proc, signal.SIGKILL)
    h5 = out / "case1.h5"
    with h5py.File(h5, "r") as f:
        assert "pattern" not in f["diagnostics"].attrs
        assert read.text_attr(f["run"].attrs["stop_reason"]) == "running"
    old = time.time() - 2 * read.RUNNING_QUIET  # as seen later: nobody writes it any more
    for f in out.iterdir():
        os.utime(f, (old, old))
    assert read.run_status(h5) == "failed"
    assert sweep.collect([planned(out)])[0]["pattern"] == "stopped"  # resumable
    pair = read.pair_of(read.open_run(h5, warn=False))
    assert pair.source != "as written in /diagnostics", pair.source


def test_nan_gap_is_classified_up_to_it_with_a_warning(finished: Path, tmp_path: Path,
                                                       capsys: pytest.CaptureFixture) -> None:
    h5 = tmp_path / "case1.h5"
    shutil.copy(finished / "case1.h5", h5)
    with h5py.File(h5, "r+") as f:
        dr = f["diagnostics/dr"]
        k = dr.shape[0] // 2
        t_nan = float(f["diagnostics/t"][k])
        dr[k] = np.nan
        dr[k + 2: k + 6] = 0.0  # a kiss after the NaN
    pair = read.pair_of(read.open_run(h5, warn=False))
    err = capsys.readouterr().err
    assert "warning:" in err and str(h5) in err and f"{t_nan:.6g}" in err, err
    assert pair.pattern == "never" and not pair.episodes
    p = cli("pattern", h5)
    assert p.returncode == 0 and str(h5) in p.stderr and "NaN" in p.stderr, p.stderr


@pytest.mark.parametrize("attr", ["dx", "dt", "steps", "d1", "gamma", "t_ref", "kiss_enter"])
def test_a_garbage_run_attribute_is_one_error_line(finished: Path, tmp_path: Path,
                                                   attr: str) -> None:
    """An attribute of /run (and /diagnostics) that must be a number and holds text (a damaged
    or foreign file): every reader that needs it (dkt-pattern, dkt-gap, dkt-trajectories,
    dkt-field) exits 2 with one `error:` line naming the file and the attribute, never a
    traceback; the file is unchanged."""
    h5 = tmp_path / "case1.h5"
    shutil.copy(finished / "case1.h5", h5)
    with h5py.File(h5, "a") as f:
        groups = [g for g in ("run", "diagnostics") if attr in f[g].attrs]
        assert groups, attr
        for g in groups:
            del f[g].attrs[attr]
            f[g].attrs[attr] = "garbage"
    before = tree_digest(tmp_path)
    failed = 0
    for name, args in (("pattern", []), ("gap", ["-o", tmp_path / "g.png"]),
                       ("trajectories", ["-o", tmp_path / "t.png"]),
                       ("field", ["-o", tmp_path / "f.png"])):
        proc = cli(name, h5, *args)
        assert "Traceback" not in proc.stderr, f"dkt-{name}:\n{proc.stderr}"
        if proc.returncode == 0:
            continue  # this reader does not need the attribute
        failed += 1
        lines = [line for line in proc.stderr.splitlines() if line.startswith("error:")]
        assert proc.returncode == 2 and len(lines) == 1, f"dkt-{name}:\n{proc.stderr}"
        assert str(h5) in lines[0] and f"attribute {attr} = 'garbage'" in lines[0], lines[0]
    # at least one reader needs each of these attributes
    assert failed > 0
    for png in tmp_path.glob("*.png"):
        png.unlink()
    assert tree_digest(tmp_path) == before
