"""A full disk stops a run cleanly and loses nothing that was written.

The pair of case1 (gamma 1.3, 10 spacings per diameter) runs on 2 ranks with output.dir on a
small tmpfs (mounted here; that needs root, so the test is skipped otherwise, with the
reason). Each checkpoint is some 3 MiB: the first fits, the second does not. The run must then

- stop within a timeout (parallel HDF5 used to hang every rank in the close of the checkpoint
  whose write failed), with exit status 3 and one error line that names the checkpoint file
  being written and says the disk is full (the system's reason);
- leave no partial `<checkpoint>.tmp` behind;
- close its run file with stop_reason 'error: ...' and the /particles series up to the step
  that failed;
- leave the previous checkpoint intact: the marker names it and a run resumes from it (its
  digests are checked on reading).

A full disk during field output (the run file's own write fails) must stop the run within the
timeout with an error that names the run file.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path

import h5py
import numpy as np
import pytest

from dkt_run import INPUT, run_args

RANKS = 2
EVERY = 200
C1 = [
    "pair.gamma=1.3",
    "lbm.cells_per_diameter=10",
    "run.progress_every=0",
    f"run.checkpoint_every={EVERY}",
    "run.checkpoint_keep=10",
]
TIMEOUT = 120


@pytest.fixture
def small_disk(tmp_path: Path, request: pytest.FixtureRequest) -> Iterator[Path]:
    """A tmpfs of request.param MiB at tmp_path/disk, unmounted afterwards."""
    if os.geteuid() != 0:
        pytest.skip("mounting a small tmpfs needs root (CI runs as root)")
    disk = tmp_path / "disk"
    disk.mkdir()
    mount = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={request.param}m", "tmpfs",
                            str(disk)], capture_output=True, text=True)
    if mount.returncode != 0:
        # root in a container without the right to mount (no CAP_SYS_ADMIN)
        pytest.skip(f"root cannot mount a tmpfs here: {mount.stderr.strip()}")
    try:
        yield disk
    finally:
        subprocess.run(["umount", str(disk)], check=False)


def dktlbm(out: Path, sets: list[str], restart: Path | None = None):
    args = [str(INPUT / "case1.nml")]
    for s in [*C1, *sets, f"output.dir={out}"]:
        args += ["--set", s]
    if restart is not None:
        args += ["--restart", str(restart)]
    return run_args(args, RANKS, timeout=TIMEOUT)


def errors(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if line.startswith("dktlbm: error")]


@pytest.mark.parametrize("small_disk", [8], indirect=True)
def test_full_disk_at_a_checkpoint_stops_cleanly(small_disk: Path, tmp_path: Path) -> None:
    out = small_disk / "run"
    # no fields before the end: the run file stays small, the checkpoints fill the disk
    proc = dktlbm(out, ["run.steps=2000", "output.field_interval=100"])
    assert proc.returncode == 3, proc.stderr
    lines = errors(proc.stderr)
    assert len(lines) == 1, proc.stderr
    failed = next(s for s in range(EVERY, 2001, EVERY) if not (out / chk_name(s)).exists())
    assert failed > EVERY, "the first checkpoint must fit on the disk"
    assert str(out / chk_name(failed)) in lines[0], lines[0]
    assert "space" in lines[0].lower(), lines[0]
    assert not list(out.glob("*.tmp")), sorted(p.name for p in out.iterdir())

    with h5py.File(out / "case1.h5", "r") as h5:
        reason = h5["run"].attrs["stop_reason"]
        reason = reason.decode() if isinstance(reason, bytes) else str(reason)
        t = h5["particles/t"][()]
        dt = float(h5["run"].attrs["dt"])
    assert reason.startswith("error: ") and chk_name(failed) in reason, reason
    assert np.all(np.diff(t) > 0)
    # the series reach the step whose checkpoint failed (sampled every few steps)
    assert t[-1] >= (failed - 10) * dt, (t[-1], failed * dt)

    before = out / chk_name(failed - EVERY)
    assert (out / "case1.checkpoint").read_text().strip() == str(before)
    # intact: a copy of the run (off the small disk) resumes from it
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    resumed = dktlbm(copy, [f"run.steps={failed - EVERY + 10}", "output.field_interval=100"],
                     restart=copy / before.name)
    assert resumed.returncode == 0, resumed.stderr


@pytest.mark.parametrize("small_disk", [3], indirect=True)
def test_full_disk_during_field_output_names_the_run_file(small_disk: Path) -> None:
    """Field snapshots fill the disk: the run stops before the snapshot that does not fit
    (exit 3, one error line naming the run file and the full disk), and closes its run file
    with the series written so far and stop_reason naming the full disk. Before, an HDF5 write
    failed: exit 3 with HDF5 stack dumps, stop_reason left at 'running' and no /particles."""
    out = small_disk / "run"
    proc = dktlbm(out, ["run.steps=2000", "run.checkpoint_every=0"])
    assert proc.returncode == 3, proc.stdout + proc.stderr
    lines = errors(proc.stderr)
    assert len(lines) == 1, proc.stderr
    assert str(out / "case1.h5") in lines[0] and "disk" in lines[0], lines[0]
    assert "HDF5-DIAG" not in proc.stderr
    with h5py.File(out / "case1.h5", "r") as h5:
        reason = h5["run"].attrs["stop_reason"]
        assert reason.startswith("error: ") and "field snapshot" in reason, reason
        t = h5["particles/t"][()]
        assert t.size > 1 and np.all(np.diff(t) > 0)


def chk_name(step: int) -> str:
    return f"case1_chk_{step:09d}.h5"
