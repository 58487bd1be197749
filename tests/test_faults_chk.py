"""Checkpoints that cannot lie: a damaged or altered checkpoint is refused, and a good one
resumes without losing or repeating a sample.

The reference is the pair of case1 (gamma 1.3, 10 spacings per diameter, in the moving
window) run for STEPS steps on 2 ranks with a checkpoint half way and one at the end. Each
damage below is applied to a copy of the half-way checkpoint, and the run is resumed from it:

- with the checksums the checkpoint carries (/f_checksum, /state_checksum), one flipped byte
  of /f, /f stored as float32, and an altered step are refused by their digests;
- with the checksums removed (a checkpoint of an earlier version), each value is still checked
  against its bounds: a NaN or Inf population, a particle outside the lattice, an overlapping
  pair, a particle faster than run.particle_speed_limit, a negative or huge window shift, a step
  that is not the one of the file name, a sample count the run file contradicts.

Each refusal must come within a timeout (a NaN in /f used to hang every rank in the window's
shift loop), with exit status 2 and one error line naming the checkpoint file and the dataset,
and must leave every file of the run as it was (before this check the run file was already cut
back when the run failed). An intact checkpoint without checksums resumes, with a warning.
Extending the finished run from its last checkpoint must give the series of the run that went
that far at once, sample for sample, bit for bit: no sample at the checkpoint's step twice.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
import pytest

from dkt_run import INPUT, run, run_args, tree_digest

RANKS = 2
STEPS = 400
C1 = [
    "pair.gamma=1.3",
    "lbm.cells_per_diameter=10",
    "run.progress_every=0",
    f"run.checkpoint_every={STEPS // 2}",
    "run.checkpoint_keep=10",
]
HALF = f"case1_chk_{STEPS // 2:09d}.h5"
TIMEOUT = 90


def fletcher(values: np.ndarray) -> tuple[int, int]:
    """The digest of checkpoint_read (src/dkt_checkpoint.f90): two sums modulo 2^32 - 5 over
    the 32-bit words (low word first) of the 8-byte values, in order."""
    p = 4294967291
    a, b = 1, 0
    for w in np.ascontiguousarray(values, dtype="<f8").view("<u4").tolist():
        a = (a + w) % p
        b = (b + a) % p
    return a, b


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """STEPS steps of the pair on 2 ranks: checkpoints at STEPS/2 and STEPS."""
    out = tmp_path_factory.mktemp("faults_chk") / "run"
    run("case1.nml", RANKS, [*C1, f"run.steps={STEPS}"], out, timeout=300)
    assert (out / HALF).exists()
    return out


def resume(out: Path, checkpoint: Path, steps: int, ranks: int = RANKS):
    args = [str(INPUT / "case1.nml")]
    for s in [*C1, f"run.steps={steps}", f"output.dir={out}"]:
        args += ["--set", s]
    return run_args([*args, "--restart", str(checkpoint)], ranks, timeout=TIMEOUT)


def without_checksums(h5: h5py.File) -> None:
    """The checkpoint as an earlier version wrote it."""
    for name in ("f_checksum", "state_checksum"):
        if name in h5:
            del h5[name]


def set_f(value: float) -> Callable[[h5py.File], None]:
    def harm(h5: h5py.File) -> None:
        without_checksums(h5)
        h5["f"][3, 40, 7] = value

    return harm


def set_particle(k: int, column: int, value: float) -> Callable[[h5py.File], None]:
    def harm(h5: h5py.File) -> None:
        without_checksums(h5)
        h5["particles"][k, column] = value

    return harm


def set_state(index: int, value: int, keep_checksums: bool = False) -> Callable[[h5py.File], None]:
    # /state_int: step, shift, samples, nx, ny, particles, episodes, in_episode, len(given)
    def harm(h5: h5py.File) -> None:
        if not keep_checksums:
            without_checksums(h5)
        h5["state_int"][index] = value

    return harm


def overlap(h5: h5py.File) -> None:
    without_checksums(h5)
    p = h5["particles"][()]
    p[1, 0:2] = p[0, 0:2] + 0.5  # the centres half a spacing apart: deeply overlapping
    h5["particles"][...] = p


def f_as_float32(h5: h5py.File) -> None:
    f = h5["f"][()]
    del h5["f"]
    h5["f"] = f.astype(np.float32)


def flip_byte(path: Path) -> None:
    """One byte of /f in the middle of the file's data, flipped on disk (not through HDF5)."""
    with h5py.File(path, "r") as h5:
        start = h5["f"].id.get_offset()
        size = h5["f"].id.get_storage_size()
    assert start is not None and size > 0
    data = bytearray(path.read_bytes())
    data[start + size // 2 + 3] ^= 0x10
    path.write_bytes(bytes(data))


DAMAGE = {
    # (applied to the h5py file, or to the path when it takes a Path; what the error names)
    "flipped-byte-in-f": (flip_byte, "does not match its digest in /f_checksum"),
    "f-as-float32": (f_as_float32, "does not match its digest in /f_checksum"),
    "step-altered": (set_state(0, STEPS // 2 + 1, keep_checksums=True), "/state_checksum"),
    "nan-in-f": (set_f(np.nan), "/f holds the value NaN"),
    "inf-in-f": (set_f(np.inf), "/f holds the value Infinity"),
    "particle-left-of-the-channel": (set_particle(0, 0, -50.0), "outside the lattice"),
    "particle-far-above": (set_particle(1, 1, 1e6), "outside the lattice"),
    "particle-too-fast": (set_particle(0, 2, 50.0), "run.particle_speed_limit"),
    "overlapping-pair": (overlap, "overlapping"),
    "negative-window-shift": (set_state(1, -10), "window shift of -10"),
    "huge-window-shift": (set_state(1, 2**31 - 1), "window shift of 2147483647"),
    "step-not-the-file-name's": (set_state(0, STEPS // 2 + 1), "written at step"),
    "fewer-samples-than-the-run-file": (set_state(2, 20), "counts 20 samples of /particles"),
}


@pytest.mark.parametrize(("damage", "says"), DAMAGE.values(), ids=DAMAGE)
def test_a_damaged_checkpoint_is_refused_before_anything_is_cut(
    reference: Path, tmp_path: Path, damage, says: str
) -> None:
    out = tmp_path / "run"
    shutil.copytree(reference, out)
    bad = tmp_path / HALF
    shutil.copy(out / HALF, bad)
    if damage is flip_byte:
        damage(bad)
    else:
        with h5py.File(bad, "r+") as h5:
            damage(h5)
    before = tree_digest(out)
    proc = resume(out, bad, STEPS + 100)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    errors = [ln for ln in proc.stderr.splitlines() if ln.startswith("dktlbm: error")]
    assert len(errors) == 1 and "[rank" not in errors[0], proc.stderr
    assert str(bad) in errors[0] and says in errors[0], errors[0]
    assert tree_digest(out) == before, "a refused restart changed the run's files"


@pytest.mark.parametrize("ranks", [1, 2])
def test_a_nan_checkpoint_with_a_matching_digest_is_refused_on_any_rank_count(
    reference: Path, tmp_path: Path, ranks: int
) -> None:
    """NaN in /f with the row's digest recomputed (an altered file, not a damaged one): the
    finiteness check refuses it on 1 and 2 ranks, within the timeout. The issue's hang."""
    out = tmp_path / "run"
    shutil.copytree(reference, out)
    bad = tmp_path / HALF
    shutil.copy(out / HALF, bad)
    row = 40
    with h5py.File(bad, "r+") as h5:
        h5["f"][3, row, 7] = np.nan
        if "f_checksum" in h5:
            h5["f_checksum"][row, :] = fletcher(h5["f"][:, row, :].ravel())
    before = tree_digest(out)
    proc = resume(out, bad, STEPS + 100, ranks)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert f"/f holds the value NaN at x = 8, row {row + 1}, population 3" in proc.stderr
    assert tree_digest(out) == before


def test_an_intact_checkpoint_without_checksums_resumes_with_a_warning(
    reference: Path, tmp_path: Path
) -> None:
    out = tmp_path / "run"
    shutil.copytree(reference, out)
    with h5py.File(out / HALF, "r+") as h5:
        without_checksums(h5)
    proc = resume(out, out / HALF, STEPS)
    assert proc.returncode == 0, proc.stderr
    assert "has no checksums" in proc.stderr, proc.stderr
    with h5py.File(reference / "case1.h5") as a, h5py.File(out / "case1.h5") as b:
        for name in ("t", "x", "y", "u", "v", "omega"):
            assert np.array_equal(a["particles"][name][()], b["particles"][name][()]), name


def test_extending_a_finished_run_repeats_no_sample(reference: Path, tmp_path: Path) -> None:
    """The finished run resumed from its last checkpoint to 1.5 STEPS equals one run of 1.5
    STEPS in /particles, /diagnostics and the CSV, bit for bit: no sample twice."""
    longer = STEPS + STEPS // 2
    whole = tmp_path / "whole"
    run("case1.nml", RANKS, [*C1, f"run.steps={longer}"], whole, timeout=300)
    out = tmp_path / "run"
    shutil.copytree(reference, out)
    proc = resume(out, out / f"case1_chk_{STEPS:09d}.h5", longer)
    assert proc.returncode == 0, proc.stderr
    with h5py.File(whole / "case1.h5") as a, h5py.File(out / "case1.h5") as b:
        t = b["particles/t"][()]
        assert np.all(np.diff(t) > 0), f"repeated sample times: {t[:-1][np.diff(t) <= 0]}"
        for group in ("particles", "diagnostics"):
            for name, d in a[group].items():
                if isinstance(d, h5py.Dataset):
                    assert np.array_equal(d[()], b[group][name][()], equal_nan=True), name
    csv_a = (whole / "case1_diagnostics.csv").read_text()
    csv_b = (out / "case1_diagnostics.csv").read_text()
    assert csv_a == csv_b


def spoil_csv(how: str) -> Callable[[Path], None]:
    """What can become of the pair's CSV file between a run and its restart."""

    def spoil(path: Path) -> None:
        if how == "missing":
            path.unlink()
        elif how == "empty":
            path.write_text("")
        elif how == "short":
            path.write_text("".join(path.read_text().splitlines(keepends=True)[:3]))
        else:  # another run's rows, or garbage
            path.write_text("t,tstar\n1,2\nnot,a,row\n")

    return spoil


@pytest.mark.parametrize("how", ["missing", "empty", "short", "garbage"])
def test_a_restart_rebuilds_the_csv_from_the_run_file(
    reference: Path, tmp_path: Path, how: str
) -> None:
    """The CSV file of the pair removed, emptied, cut short or replaced before a restart: the
    restart rebuilds it from the run file (/diagnostics and /particles hold every value of its
    rows) and the finished run's CSV and run file are those of the run that went through at
    once, bit for bit. Before, the restart cut the run file back (/particles from 44 to 21
    samples, a snapshot and the pattern gone, stop_reason still `finished`) and then aborted on
    the missing CSV."""
    out = tmp_path / "run"
    shutil.copytree(reference, out)
    spoil_csv(how)(out / "case1_diagnostics.csv")
    proc = resume(out, out / HALF, STEPS)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (out / "case1_diagnostics.csv").read_text() == (
        reference / "case1_diagnostics.csv"
    ).read_text()
    with h5py.File(reference / "case1.h5") as a, h5py.File(out / "case1.h5") as b:
        for group in ("particles", "diagnostics"):
            for name, d in a[group].items():
                if isinstance(d, h5py.Dataset):
                    assert np.array_equal(d[()], b[group][name][()], equal_nan=True), name
        assert a["diagnostics"].attrs["pattern"] == b["diagnostics"].attrs["pattern"]
        assert b["run"].attrs["stop_reason"] == "finished"


def test_a_checkpoint_is_not_spliced_onto_another_runs_file(
    reference: Path, tmp_path: Path
) -> None:
    """The run file of another run (here the same scene with another pair.dh, run longer)
    copied over the reference's: resuming from the reference's checkpoint is refused, naming
    both identities (/run run_id of the file, /run_id of the checkpoint), with exit status 2
    and every file as it was. Before, the restart cut the other run's file back and continued
    it, and the series jumped from one run to the other."""
    other = tmp_path / "other"
    run("case1.nml", RANKS, [*C1, "pair.dh=3", f"run.steps={STEPS + 100}"], other, timeout=300)
    out = tmp_path / "run"
    shutil.copytree(reference, out)
    shutil.copy(other / "case1.h5", out / "case1.h5")
    before = tree_digest(out)
    proc = resume(out, out / HALF, STEPS)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    errors = [ln for ln in proc.stderr.splitlines() if ln.startswith("dktlbm: error")]
    assert len(errors) == 1, proc.stderr
    with h5py.File(other / "case1.h5") as h5, h5py.File(out / HALF) as chk:
        theirs, ours = int(h5["run"].attrs["run_id"]), int(chk["run_id"][0])
    assert theirs != ours
    assert "another run's" in errors[0] and str(theirs) in errors[0] and str(ours) in errors[0]
    assert tree_digest(out) == before, "a refused restart changed the run's files"


def test_a_resumed_run_keeps_its_files_identity(reference: Path, tmp_path: Path) -> None:
    """A run resumed from the half-way checkpoint writes its checkpoints with the run file's
    identity, so that it can be resumed in its turn: half-way to the end, then the end to 1.5
    STEPS, gives the series of the reference extended at once (no refusal, no sample twice)."""
    out = tmp_path / "run"
    shutil.copytree(reference, out)
    with h5py.File(out / "case1.h5") as h5:
        run_id = h5["run"].attrs["run_id"]
    assert resume(out, out / HALF, STEPS).returncode == 0
    with h5py.File(out / f"case1_chk_{STEPS:09d}.h5") as chk:
        assert chk["run_id"][0] == run_id
    longer = STEPS + STEPS // 2
    proc = resume(out, out / f"case1_chk_{STEPS:09d}.h5", longer)
    assert proc.returncode == 0, proc.stderr
    with h5py.File(out / "case1.h5") as h5:
        assert h5["run"].attrs["run_id"] == run_id
        assert np.all(np.diff(h5["particles/t"][()]) > 0)
