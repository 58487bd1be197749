"""Checkpoint and restart: a resumed run is indistinguishable from one that never stopped.

The scene is case0 (two disks in the moving window, 10 spacings per diameter) so that the
checkpoint must carry the populations, both particles, the window offset and the kissing
episodes. "Indistinguishable" is checked on the whole output: every dataset of the HDF5 file
(fields, /particles, /diagnostics, episodes) compared with np.array_equal, the /diagnostics
attributes, the CSV file and the XDMF sidecars byte for byte.
"""

from __future__ import annotations

import shutil
import signal
import subprocess
from pathlib import Path

import h5py
import numpy as np
import pytest

from dkt_run import INPUT, all_datasets, run, run_args, sigterm_when_logged

STEPS = 1200
SETS = [
    "lbm.cells_per_diameter=10",
    f"run.steps={STEPS}",
    "output.series_interval=0.01",
    "output.field_interval=0.1",
]


def diagnostics_attrs(h5file: Path) -> dict[str, object]:
    with h5py.File(h5file, "r") as h5:
        return dict(h5["diagnostics"].attrs)


LONG = 6000  # steps of the signal test: a few seconds, so that the signal lands mid-run
LONG_SETS = [*SETS, f"run.steps={LONG}", "output.field_interval=0.5"]


def assert_same_output(a: Path, b: Path) -> None:
    """Every dataset, the /diagnostics attributes, the CSV and the XDMF sidecars of two output
    dirs."""
    da, db = all_datasets(a / "case0.h5"), all_datasets(b / "case0.h5")
    assert sorted(da) == sorted(db), set(da) ^ set(db)
    differ = [k for k in da if not np.array_equal(da[k], db[k], equal_nan=True)]
    assert not differ, f"datasets differ: {differ}"
    assert diagnostics_attrs(a / "case0.h5") == diagnostics_attrs(b / "case0.h5")
    for name in ("case0_diagnostics.csv", "case0.xdmf", "case0_particles.xdmf"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    assert b"\0" not in (b / "case0.xdmf").read_bytes()


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The reference: STEPS steps on 2 ranks without a stop (more than 8 field snapshots, so
    the XDMF sidecar grows its frame list)."""
    out = tmp_path_factory.mktemp("full") / "run"
    run("case0.nml", 2, SETS, out, timeout=600)
    with h5py.File(out / "case0.h5", "r") as h5:
        assert len(h5["fields"]) > 8
        # the window moved and the pair kissed: the checkpoint must carry both
        offset = h5["particles/window_offset"][()]
        assert offset[0] - offset[-1] > 0.5
        assert h5["diagnostics"].attrs["episodes"] >= 1
    return out


@pytest.mark.parametrize("ranks", [2, 3])
def test_half_a_run_then_a_restart_equals_the_whole_run(
    uninterrupted: Path, tmp_path: Path, ranks: int
) -> None:
    """STEPS/2 steps on 2 ranks with a checkpoint at the end, then a restart from it on
    `ranks` ranks to STEPS: the output equals the uninterrupted run's, bit for bit (the first
    half's final snapshot, which an uninterrupted run does not write, is removed), and the
    file's /run `steps` is the resumed run's length, STEPS, not the first half's."""
    out = tmp_path / "run"
    half = STEPS // 2
    run("case0.nml", 2, [*SETS, f"run.steps={half}", f"run.checkpoint_every={half}"], out)
    checkpoint = out / f"case0_chk_{half:09d}.h5"
    assert checkpoint.exists()
    assert (out / "case0.checkpoint").read_text().strip() == str(checkpoint)
    proc = run("case0.nml", ranks, SETS, out, extra=["--restart", str(checkpoint)])
    assert "DKT pattern" in proc.stdout
    assert (out / "case0.finished").exists()
    assert_same_output(uninterrupted, out)
    with h5py.File(out / "case0.h5", "r") as h5:
        assert int(h5["run"].attrs["steps"]) == STEPS


# the 4-byte precisions, the /precision code of each, and the other one that stores alike
FOUR_BYTES = {"single": (1, "single_arith"), "single_arith": (3, "single")}


@pytest.mark.parametrize("precision", sorted(FOUR_BYTES))
def test_a_single_precision_run_restarts_bit_for_bit(tmp_path: Path, precision: str) -> None:
    """lbm.precision = 'single' or 'single_arith': the checkpoint holds the 4-byte stored values
    exactly (every value of /f is a float32, /precision gives the precision's own code: 1 =
    'single', 3 = 'single_arith') and a run resumed from it on 3 ranks ends bitwise equal to
    the run that never stopped. Fails if the checkpoint rounds the stored values, unshifts
    them, or stores 8-byte values the 4-byte lattice cannot hold. The two store alike but
    collide differently, so a resume with the other one is refused: it would not continue bit
    for bit."""
    code, other = FOUR_BYTES[precision]
    steps = STEPS // 2
    sets = [*SETS, f"run.steps={steps}", f"lbm.precision={precision}"]
    reference = tmp_path / "reference"
    run("case0.nml", 2, sets, reference, timeout=600)
    out = tmp_path / "run"
    half = steps // 2
    run("case0.nml", 2, [*sets, f"run.steps={half}", f"run.checkpoint_every={half}"], out)
    checkpoint = out / f"case0_chk_{half:09d}.h5"
    with h5py.File(checkpoint, "r") as h5:
        assert h5["precision"][()].tolist() == [code]
        f = h5["f"][()]
    assert np.array_equal(f, f.astype(np.float32).astype(f.dtype))
    # stored as f_i - w_i: the rest population (w_0 = 4/9) is near 0, not near 4/9
    assert np.abs(f[0]).max() < 0.1
    refused = run(
        "case0.nml", 3, [*sets, f"lbm.precision={other}"], out,
        extra=["--restart", str(checkpoint)], check=False,
    )  # fmt: skip
    assert refused.returncode != 0
    assert f"--set lbm.precision={precision}" in refused.stderr, refused.stderr
    run("case0.nml", 3, sets, out, extra=["--restart", str(checkpoint)])
    assert_same_output(reference, out)


def decode_half(codes: np.ndarray) -> np.ndarray:
    """The deviations f_i - w_i that 16-bit codes (as integers) stand for."""
    u = codes.astype(np.int64) & 0xFFFF
    e, m = (u >> 11) & 15, u & 2047
    value = np.where(e > 0, (2048 + m) * 2.0 ** (e - 26.0), m * 2.0**-25)
    return np.where(u >> 15 == 1, -value, value)


def test_a_16_bit_run_restarts_bit_for_bit_and_refuses_other_precisions(tmp_path: Path) -> None:
    """lbm.precision = 'half': the checkpoint holds the 16-bit codes exactly (every value of /f
    is an integer in -32768..32767, /precision is 4, the rest state is code 0, so the rest
    population of a fluid at rest is near 0, not near 4/9) and a run resumed from it on 3 ranks
    ends bitwise equal to the run that never stopped. Fails if the checkpoint decodes the codes,
    rounds them or drops the sign. A resume with 'single_arith' (which collides alike but
    stores 4 bytes) is refused, and so is a 'single_arith' checkpoint resumed in 'half'."""
    steps = STEPS // 2
    sets = [*SETS, f"run.steps={steps}", "lbm.precision=half"]
    reference = tmp_path / "reference"
    run("case0.nml", 2, sets, reference, timeout=600)
    out = tmp_path / "run"
    part = steps // 2
    run("case0.nml", 2, [*sets, f"run.steps={part}", f"run.checkpoint_every={part}"], out)
    checkpoint = out / f"case0_chk_{part:09d}.h5"
    with h5py.File(checkpoint, "r") as h5:
        assert h5["precision"][()].tolist() == [4]
        f = h5["f"][()]
    assert np.array_equal(f, np.round(f)) and f.min() >= -32768 and f.max() <= 32767
    assert (f < 0).any(), "no negative code: the sign bit is lost"
    # codes of f_i - w_i (1 sign, 4 exponent, 11 mantissa bits, docs/model.md §1): decoded, the
    # rest population is near 0, not near 4/9
    assert np.abs(decode_half(f[0])).max() < 0.1
    refused = run(
        "case0.nml", 3, [*sets, "lbm.precision=single_arith"], out,
        extra=["--restart", str(checkpoint)], check=False,
    )  # fmt: skip
    assert refused.returncode != 0
    assert "--set lbm.precision=half" in refused.stderr, refused.stderr
    run("case0.nml", 3, sets, out, extra=["--restart", str(checkpoint)])
    assert_same_output(reference, out)
    # the other way: a 4-byte checkpoint into a 16-bit lattice
    other = tmp_path / "single_arith"
    four = [*SETS, f"run.steps={part}", "lbm.precision=single_arith"]
    run("case0.nml", 1, [*four, f"run.checkpoint_every={part}"], other)
    refused = run(
        "case0.nml", 1, [*four, "lbm.precision=half"], other,
        extra=["--restart", str(other / f"case0_chk_{part:09d}.h5")], check=False,
    )  # fmt: skip
    assert refused.returncode != 0
    assert "--set lbm.precision=single_arith" in refused.stderr, refused.stderr


def test_sigterm_checkpoints_exits_zero_and_the_resumed_run_matches(tmp_path: Path) -> None:
    """SIGTERM to the ranks (what a batch system sends before the time limit) mid-run: the run
    writes a checkpoint within two steps (at a step boundary), says how to resume, exits 0 and
    leaves the newest checkpoint named in case0.checkpoint; resumed on 3 ranks it ends equal to
    the run that never stopped."""
    reference = tmp_path / "reference"
    run("case0.nml", 2, LONG_SETS, reference, timeout=600)
    out = tmp_path / "run"
    # SIGTERM once the run is stepping (its first progress line is in the log)
    proc = sigterm_when_logged("case0.nml", 2, [*LONG_SETS, "run.progress_every=100"], out,
                               f"step 100/{LONG}")
    stdout, stderr = proc.stdout, proc.stderr
    assert proc.returncode == 0, stderr
    assert "stopped on signal SIGTERM" in stdout
    assert "--restart" in stdout
    checkpoint = Path((out / "case0.checkpoint").read_text().strip())
    assert checkpoint.exists()
    assert not (out / "case0.finished").exists()
    step = int(checkpoint.stem.split("_")[-1])
    assert 100 <= step < LONG, f"stopped at step {step}: the signal came too late"
    run("case0.nml", 3, LONG_SETS, out, extra=["--restart", str(checkpoint)])
    assert_same_output(reference, out)


def test_a_run_killed_after_a_checkpoint_resumes_to_the_same_bits(tmp_path: Path) -> None:
    """SIGKILL to the ranks (no chance to write anything: a node failure, the OOM killer) after
    the run has written a checkpoint: resumed from the checkpoint its marker names, the run ends
    equal to the run that never stopped. The series is sampled every step and fields are
    written only at the end, so the samples (held in memory up to 256 per dataset) reach the
    file only through the write before each checkpoint. Without that write, measured: the
    killed run's file had no /particles group, and the resumed run exited 0 with only the
    samples after the checkpoint."""
    sets = [
        *SETS,
        "run.steps=3000",
        "output.series_interval=1e-9",
        "output.field_interval=0",
        "run.checkpoint_every=700",
    ]
    reference = tmp_path / "reference"
    run("case0.nml", 2, sets, reference, timeout=600)
    out = tmp_path / "run"
    proc = sigterm_when_logged("case0.nml", 2, sets, out, "checkpoint ", signum=signal.SIGKILL)
    assert proc.returncode != 0, "the run ended before it was killed"
    assert not (out / "case0.finished").exists()
    checkpoint = Path((out / "case0.checkpoint").read_text().strip())
    step = int(checkpoint.stem.split("_")[-1])
    assert step % 700 == 0 and 700 <= step < 3000, step
    run("case0.nml", 3, sets, out, extra=["--restart", str(checkpoint)])
    assert_same_output(reference, out)


def test_a_run_file_short_of_the_checkpoints_samples_is_refused_and_left_alone(
    tmp_path: Path,
) -> None:
    """The run file must hold every sample the checkpoint counts. A file without /particles,
    and one whose /particles/t is shorter (what a run killed before its file was flushed can
    leave), are refused on every rank with one message naming the file and what it lacks, a
    non-zero status, and nothing in the file cut back. Before this check, the first resumed
    with exit 0 and kept only the samples after the checkpoint."""
    sets = [*SETS, "run.steps=200", "run.checkpoint_every=100", "output.series_interval=1e-9"]
    run("case0.nml", 2, sets, tmp_path / "run")
    damage = {
        "has no /particles": lambda h5: h5.__delitem__("particles"),
        "holds 50 samples of /particles/t": lambda h5: h5["particles/t"].resize((50,)),
    }
    for k, (expected, harm) in enumerate(damage.items()):
        out = tmp_path / f"damaged{k}"
        shutil.copytree(tmp_path / "run", out)
        with h5py.File(out / "case0.h5", "r+") as h5:
            harm(h5)
        before = all_datasets(out / "case0.h5")
        args = [str(INPUT / "case0.nml")]
        for s in [*sets, f"output.dir={out}"]:
            args += ["--set", s]
        checkpoint = out / "case0_chk_000000100.h5"
        proc = run_args([*args, "--restart", str(checkpoint)], ranks=2, timeout=60)
        assert proc.returncode != 0, f"{expected}: resumed\n{proc.stdout}"
        message = proc.stderr
        assert expected in message and str(out / "case0.h5") in message, message
        assert "the checkpoint counts 101 samples" in message, message
        after = all_datasets(out / "case0.h5")
        assert after.keys() == before.keys()
        assert all(np.array_equal(after[n], before[n], equal_nan=True) for n in before)


def test_wall_limit_checkpoints_and_stops_by_itself(tmp_path: Path) -> None:
    """run.wall_limit: the run checkpoints and stops with exit 0 when its wall time reaches the
    limit, before its last step."""
    out = tmp_path / "run"
    proc = run("case0.nml", 2, [*SETS, f"run.steps={100 * STEPS}", "run.wall_limit=2"], out)
    assert "stopped at run.wall_limit" in proc.stdout
    checkpoint = Path((out / "case0.checkpoint").read_text().strip())
    assert checkpoint.exists() and not (out / "case0.finished").exists()


def test_older_checkpoints_are_removed_beyond_checkpoint_keep(tmp_path: Path) -> None:
    out = tmp_path / "run"
    run("case0.nml", 1, [*SETS, "run.checkpoint_every=200", "run.checkpoint_keep=2"], out)
    kept = sorted(p.name for p in out.glob("case0_chk_*.h5"))
    assert kept == [f"case0_chk_{s:09d}.h5" for s in (STEPS - 200, STEPS)]


def test_a_failed_checkpoint_write_stops_cleanly_and_keeps_the_previous_one(
    tmp_path: Path,
) -> None:
    """A checkpoint that cannot be written (here its temporary file name is taken by a
    directory, as a disk error would refuse it): the run stops with a message naming the file
    and the last good checkpoint, exits non-zero without hanging, and the previous checkpoint
    is complete and resumes."""
    out = tmp_path / "run"
    out.mkdir()
    (out / "case0_chk_000000400.h5.tmp").mkdir()
    proc = run("case0.nml", 2, [*SETS, "run.checkpoint_every=200"], out, timeout=300, check=False)
    assert proc.returncode != 0
    assert "case0_chk_000000400.h5.tmp" in proc.stderr
    assert "case0_chk_000000200.h5" in proc.stderr
    resumed = run(
        "case0.nml",
        1,
        [*SETS, "run.steps=300"],
        out,
        extra=["--restart", str(out / "case0_chk_000000200.h5")],
        check=False,
    )
    assert resumed.returncode == 0, resumed.stderr


def test_a_bad_restart_file_is_refused_with_a_clear_message(tmp_path: Path) -> None:
    """A missing file, a file that is not a checkpoint, a checkpoint of another lattice and
    one of another lbm.precision each stop every rank with one message naming the file, a
    non-zero status, and leave the output as it was."""
    out = tmp_path / "run"
    run("case0.nml", 2, [*SETS, "run.steps=100", "run.checkpoint_every=100"], out)
    before = (out / "case0.h5").read_bytes()
    foreign = tmp_path / "foreign.h5"
    with h5py.File(foreign, "w") as h5:
        h5["x"] = np.zeros(3)

    def resume(path: str, *sets: str) -> subprocess.CompletedProcess[str]:
        args = [str(INPUT / "case0.nml")]
        for s in [*SETS, *sets, f"output.dir={out}"]:
            args += ["--set", s]
        return run_args([*args, "--restart", path], ranks=2, timeout=60)

    cases = {
        str(tmp_path / "missing.h5"): "not found",
        str(foreign): "is not a dktlbm checkpoint",
    }
    for path, expected in cases.items():
        proc = resume(path)
        assert proc.returncode != 0
        assert expected in proc.stderr and path in proc.stderr, proc.stderr
    proc = resume(str(out / "case0_chk_000000100.h5"), "lbm.cells_per_diameter=12")
    assert proc.returncode != 0
    assert "the checkpoint holds a lattice of" in proc.stderr, proc.stderr
    # an 8-byte checkpoint into a 4-byte lattice: refused, naming the precision to resume with
    proc = resume(str(out / "case0_chk_000000100.h5"), "lbm.precision=single")
    assert proc.returncode != 0
    assert "lbm.precision = 'double'" in proc.stderr, proc.stderr
    assert "--set lbm.precision=double" in proc.stderr, proc.stderr
    assert (out / "case0.h5").read_bytes() == before
