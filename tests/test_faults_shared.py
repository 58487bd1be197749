"""Shared output directories: a second run never writes over a live run's files.

The scene is case0_box (no window, so the first run goes on until it is stopped). A run
holds its output.dir for its scene while it writes there (`<name>.lock`, an flock the system
drops when the process ends, however it ends). A second run of the same scene into the
same directory, with output.overwrite = .true. or without, or resuming from one of its
checkpoints, is refused before it changes anything, with one error line that says a live run
holds the directory and names that process; the first run is not disturbed and ends as it
would have. A run killed outright (SIGKILL, no clean-up) leaves no stale hold: the next run
goes ahead. Before, the overwriting run replaced the live run's files and both exited 0.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from dkt_run import EXE, INPUT, mpi_command, mpi_env, run

SCENE = "case0_box"
SETS = [
    "lbm.cells_per_diameter=16",
    "run.progress_every=0",
    "run.checkpoint_every=200",
    "run.checkpoint_keep=1000",
]
CHK = f"{SCENE}_chk_000000200.h5"


def start(out: Path, ranks: int = 2) -> subprocess.Popen[str]:
    """A long run of the box into `out`, started in its own process group; returns once its lock
    is taken (the file names the holder)."""
    args = [str(EXE), str(INPUT / f"{SCENE}.nml")]
    for s in [*SETS, "run.t_end=100", f"output.dir={out}"]:
        args += ["--set", s]
    proc = subprocess.Popen(
        mpi_command(ranks) + args,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=mpi_env(),
        start_new_session=True,
    )
    lock = out / f"{SCENE}.lock"
    for _ in range(600):
        if lock.exists() and "pid" in lock.read_text() and (out / CHK).exists():
            return proc
        if proc.poll() is not None:
            break
        time.sleep(0.1)
    proc.kill()
    pytest.fail(f"the first run did not start: {proc.communicate()}")


def stop(proc: subprocess.Popen[str], how: signal.Signals) -> None:
    os.killpg(proc.pid, how)
    proc.communicate(timeout=120)


@pytest.mark.parametrize(
    ("sets", "resume"),
    [
        (["run.t_end=0.2", "output.overwrite=.true."], False),
        (["run.t_end=0.2"], False),
        (["run.t_end=100"], True),
    ],
    ids=["overwrite", "plain", "restart"],
)
def test_a_live_runs_directory_is_refused(tmp_path: Path, sets: list[str], resume: bool) -> None:
    out = tmp_path / "run"
    first = start(out)
    try:
        more = ["--restart", str(out / CHK)] if resume else []
        h5_before = (out / f"{SCENE}.h5").stat().st_ino
        proc = run(f"{SCENE}.nml", 1, [*SETS, *sets], out, extra=more, timeout=120, check=False)
        assert proc.returncode == 2, proc.stdout + proc.stderr
        errors = [ln for ln in proc.stderr.splitlines() if ln.startswith("dktlbm: error")]
        assert len(errors) == 1, proc.stderr
        assert "held by a live run" in errors[0] and "pid" in errors[0], errors[0]
        assert "earlier run" not in errors[0]
        assert (out / f"{SCENE}.h5").stat().st_ino == h5_before, "the run file was replaced"
        assert first.poll() is None, "the first run was disturbed"
    finally:
        stop(first, signal.SIGTERM)
    # the first run ended as a signalled run does, its series whole
    with h5py.File(out / f"{SCENE}.h5") as h5:
        assert h5["run"].attrs["stop_reason"] == "signal"
        t = h5["particles/t"][()]
        assert t.size > 2 and np.all(np.diff(t) > 0)
    assert "dktlbm pid" not in (out / f"{SCENE}.lock").read_text(), "the hold was not released"


def test_a_killed_run_leaves_no_stale_hold(tmp_path: Path) -> None:
    """The process that holds the directory (rank 0, named in the lock file) killed with
    SIGKILL: nothing of the run cleans up, yet the next run of the scene there goes ahead."""
    out = tmp_path / "run"
    first = start(out)
    holder = (out / f"{SCENE}.lock").read_text()
    pid = int(re.search(r"pid (\d+)", holder)[1])
    os.kill(pid, signal.SIGKILL)
    first.communicate(timeout=120)  # the launcher ends the other rank
    assert f"pid {pid}" in (out / f"{SCENE}.lock").read_text()  # killed: nothing cleaned up
    proc = run(
        f"{SCENE}.nml",
        2,
        [*SETS, "run.t_end=0.1", "output.overwrite=.true."],
        out,
        timeout=120,
        check=False,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
