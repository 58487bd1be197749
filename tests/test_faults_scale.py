"""Scale in input and output, and --check refuses what the run refuses (docs/running.md).

What this proves, each case with a time limit that only guards against a hang:
- a scene of 10 000 disks (a lattice of small disks in a wide closed box) passes --check and
  runs a few steps on 2 ranks; its run file holds the namelist (as the dataset /run/namelist,
  too long for an attribute) and all 10 000 particle series, and dktlbm.read reads it back;
- a scene of 700 disks writes its run file too (it failed with "is the disk full?" before);
- parsing and validation are linear: 10^5 disks are read and checked in seconds, and an
  overlap between the last two of 10 000 disks is found and named;
- a string value of 1 MB is tokenized in linear time: refused as too long within seconds;
- 20 000 --set options are read in linear time, in order;
- --check refuses (exit 2, a message naming output.dir) an output.dir that is a regular file,
  a read-only directory (not as root: root may write anywhere), and one whose checkpoint paths
  are longer than MPI-IO takes; a run with the longest accepted path writes its checkpoints;
- --check refuses a contact law so stiff that the particle update needs more sub-steps than
  the documented maximum, and one so stiff that the count overflows an integer;
- nothing is written by a refused --check, and nothing already there is changed.

The timings printed (pytest -s) are the measured figures quoted in docs/running.md.
"""

from __future__ import annotations

import os
import re
import subprocess
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from dkt_run import EXE, mpi_env, run_args, tree_digest
from dktlbm.read import parse_namelist, run_namelist

RANKS = 2
ENV = {"OMPI_MCA_odls_base_sigkill_timeout": "0"}
D = 0.1  # cm, disk diameter
DX = D / 4  # 4 spacings per diameter: the fewest allowed, so the lattice stays small
PITCH = 1.5 * D  # centre spacing: surfaces half a diameter (2 spacings) apart
MAX_SUBSTEPS = 10000  # docs/running.md


def lattice_scene(side: int, steps: int = 2, last_overlap: bool = False) -> str:
    """side x side free disks on a square lattice in a closed box that just holds them (each
    outer surface one spacing from its wall); `last_overlap` moves the last disk onto the one
    before it (half a diameter apart)."""
    width = side * PITCH
    i, j = np.meshgrid(np.arange(side), np.arange(side), indexing="xy")
    x = (PITCH * (i.ravel() + 0.5)).tolist()
    y = (PITCH * (j.ravel() + 0.5)).tolist()
    if last_overlap:
        x[-1] = x[-2] + 0.5 * D
    n = side * side
    return (
        "&domain\n"
        f"  width = {width:.6f}, height = {width:.6f}\n"
        "  sides = 'wall', lower = 'wall', upper = 'wall'\n/\n"
        "&fluid\n  density = 1.0, viscosity = 0.01\n/\n"
        f"&lbm\n  dx = {DX}, tau = 0.65\n/\n"
        "&particles\n"
        f"  count = {n}, gravity = 980.0\n"
        f"  diameter = {n}*{D}, density = {n}*1.01\n"
        "  x = " + ", ".join(f"{v:.6f}" for v in x) + "\n"
        "  y = " + ", ".join(f"{v:.6f}" for v in y) + "\n/\n"
        # a soft contact law: one particle sub-step per fluid step (the default needs 50 here)
        "&collision\n  stiffness = 1e-3, stiffness_overlap = 1e-3\n/\n"
        f"&run\n  steps = {steps}, progress_every = 0\n/\n"
    )


def dkt(args: list[str], cwd: Path, timeout: float, ranks: int = RANKS):
    t0 = time.monotonic()
    proc = run_args(args, ranks, timeout, cwd, ENV)
    return proc, time.monotonic() - t0


def refused(proc, *words: str) -> None:
    """Exit status 2 and one message naming every one of `words`."""
    assert proc.returncode == 2, f"exit {proc.returncode}\n{proc.stdout}\n{proc.stderr}"
    for w in words:
        assert w in proc.stderr, f"{w!r} not in the message:\n{proc.stderr}"


def test_10000_disks_check_and_run(tmp_path: Path) -> None:
    scene = tmp_path / "many.nml"
    scene.write_text(lattice_scene(100))
    out = tmp_path / "out"
    proc, dt = dkt([str(scene), "--check", "--set", f"output.dir={out}"], tmp_path, 120)
    print(f"--check of 10000 disks: {dt:.2f} s")
    assert proc.returncode == 0, proc.stderr
    assert not out.exists(), "--check wrote output"
    # the per-particle warnings are summed up, not printed 10 000 times
    assert proc.stderr.count("\n") < 20, proc.stderr[:2000]

    proc, dt = dkt([str(scene), "--set", f"output.dir={out}"], tmp_path, 600)
    print(f"2 steps of 10000 disks on {RANKS} ranks (setup included): {dt:.2f} s")
    assert proc.returncode == 0, proc.stderr
    with h5py.File(out / "many.h5", "r") as h5:
        assert "namelist" not in h5["run"].attrs  # too long for the object header
        text = run_namelist(h5)
        x = h5["particles/x"][()]
        stop = h5["run"].attrs["stop_reason"]
    assert int(parse_namelist(text)["particles"]["count"][0]) == 10000
    assert x.shape[1] == 10000 and x.shape[0] >= 2
    assert np.all(np.isfinite(x))
    assert "finished" in str(stop)


def test_700_disks_write_their_run_file(tmp_path: Path) -> None:
    """700 disks: a namelist beyond 64 KiB; the run exited 3 with a 0-byte file before."""
    scene = tmp_path / "seven.nml"
    scene.write_text(lattice_scene(27))  # 729 disks
    out = tmp_path / "out"
    proc, _ = dkt([str(scene), "--set", f"output.dir={out}"], tmp_path, 300)
    assert proc.returncode == 0, proc.stderr
    with h5py.File(out / "seven.h5", "r") as h5:
        text = run_namelist(h5)
        assert h5["particles/x"].shape[1] == 729
    assert int(parse_namelist(text)["particles"]["count"][0]) == 729


def test_100000_disks_parsed_and_validated_in_seconds(tmp_path: Path) -> None:
    """--print-defaults parses and validates the scene (every key, the overlap of every pair of
    neighbours) and prints it back, without the set-up of the lattice (see docs/running.md for
    --check, which also finds the boundary links)."""
    scene = tmp_path / "huge.nml"
    scene.write_text(lattice_scene(317, steps=1))  # 100 489 disks
    proc, dt = dkt([str(scene), "--print-defaults"], tmp_path, 120, ranks=1)
    print(f"parse and validate 100489 disks: {dt:.2f} s")
    assert proc.returncode == 0, proc.stderr
    assert re.search(r"count = 100489\b", proc.stdout)
    assert dt < 60, f"{dt:.1f} s"


def test_overlap_among_10000_disks_is_named(tmp_path: Path) -> None:
    scene = tmp_path / "overlap.nml"
    scene.write_text(lattice_scene(100, last_overlap=True))
    proc, _ = dkt([str(scene), "--check"], tmp_path, 120)
    refused(proc, "particles 9999 and 10000 overlap")


def test_megabyte_string_is_parsed_in_linear_time(tmp_path: Path) -> None:
    scene = tmp_path / "long.nml"
    scene.write_text("&output\n  dir = '" + "a" * 1_000_000 + "'\n/\n")
    proc, dt = dkt([str(scene), "--check"], tmp_path, 60, ranks=1)
    print(f"a 1 MB string value refused in {dt:.2f} s")
    refused(proc, "too long")
    assert dt < 30, f"{dt:.1f} s for 1 MB"


def test_many_set_options_are_read_in_linear_time(tmp_path: Path) -> None:
    """20 000 --set options (each `--set run.steps=k`, k = 1..20 000) are all read, in order
    (the last one wins), within a limit that only guards against a hang: the list of options
    was copied at every one appended, quadratic (8 000 options took 17 s, 20 000 would take
    two minutes); in linear time they take well under a second more than one."""
    scene = tmp_path / "small.nml"
    scene.write_text(lattice_scene(4, steps=4))
    options = [a for k in range(1, 20_001) for a in ("--set", f"run.steps={k}")]
    # started without mpiexec (a singleton): mpiexec passes on fewer arguments than execve takes
    t0 = time.monotonic()
    proc = subprocess.run([str(EXE), str(scene), "--print-defaults", *options], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120, env=mpi_env())
    dt = time.monotonic() - t0
    print(f"20000 --set options read in {dt:.2f} s")
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert re.search(r"\bsteps = 20000\b", proc.stdout), proc.stdout[-2000:]
    assert dt < 30, f"{dt:.1f} s for 20000 options"


def small_scene(tmp_path: Path) -> Path:
    scene = tmp_path / "small.nml"
    scene.write_text(lattice_scene(4, steps=4))
    return scene


def test_check_refuses_output_dir_that_is_a_file(tmp_path: Path) -> None:
    target = tmp_path / "taken"
    target.write_text("keep me\n")
    before = tree_digest(tmp_path)
    proc, _ = dkt([str(small_scene(tmp_path)), "--check", "--set", f"output.dir={target}"],
                  tmp_path, 30)
    refused(proc, "output.dir", str(target), "not a directory")
    after = tree_digest(tmp_path)
    after.pop("small.nml")
    before.pop("small.nml", None)
    assert after == before


def test_check_refuses_output_dir_below_a_file(tmp_path: Path) -> None:
    (tmp_path / "taken").write_text("keep me\n")
    proc, _ = dkt([str(small_scene(tmp_path)), "--check", "--set",
                   f"output.dir={tmp_path / 'taken' / 'run'}"], tmp_path, 30)
    refused(proc, "output.dir", "not a directory")


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write into a read-only directory")
def test_check_refuses_read_only_output_dir(tmp_path: Path) -> None:
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        proc, _ = dkt([str(small_scene(tmp_path)), "--check", "--set",
                       f"output.dir={ro / 'run'}"], tmp_path, 30)
        refused(proc, "output.dir", "not writable")
        assert list(ro.iterdir()) == []
    finally:
        ro.chmod(0o755)


def limit_from_message(text: str) -> int:
    m = re.search(r"allowed: at most (\d+)", text)
    assert m, text
    return int(m.group(1))


def test_long_output_dir_refused_by_check_and_the_limit_holds(tmp_path: Path) -> None:
    """An output.dir of 250 characters (within the 256 of the key) is refused by --check; a
    run whose checkpoint path is exactly as long as allowed writes its run file and a
    checkpoint (the limit is not stricter than needed for a run to work)."""
    scene = small_scene(tmp_path)
    base = str(tmp_path / "o")
    long_dir = base + "/" + "d" * (250 - len(base) - 1)
    proc, _ = dkt([str(scene), "--check", "--set", f"output.dir={long_dir}"], tmp_path, 30)
    refused(proc, "output.dir", "MPI-IO")
    assert not Path(base).exists()
    limit = limit_from_message(proc.stderr)
    # the checkpoint path is <dir>/small_chk_000000000.h5.tmp
    fit = limit - len("/small_chk_000000000.h5.tmp")
    ok_dir = base + "/" + "e" * (fit - len(base) - 1)
    assert len(ok_dir) == fit
    sets = ["--set", f"output.dir={ok_dir}", "--set", "run.checkpoint_every=2"]
    proc, _ = dkt([str(scene), "--check", *sets], tmp_path, 30)
    assert proc.returncode == 0, proc.stderr
    proc, _ = dkt([str(scene), *sets], tmp_path, 120)
    assert proc.returncode == 0, proc.stderr
    assert (Path(ok_dir) / "small.h5").stat().st_size > 0
    assert list(Path(ok_dir).glob("small_chk_*.h5")), list(Path(ok_dir).iterdir())
    proc, _ = dkt([str(scene), "--check", "--set", f"output.dir={ok_dir}e"], tmp_path, 30)
    refused(proc, "output.dir")


@pytest.mark.parametrize("stiffness", ["1e-22", "1e-30"])
def test_check_refuses_sub_step_counts_out_of_range(tmp_path: Path, stiffness: str) -> None:
    out = tmp_path / "out"
    proc, _ = dkt([str(small_scene(tmp_path)), "--check", "--set", f"output.dir={out}",
                   "--set", f"collision.stiffness={stiffness}"], tmp_path, 30)
    refused(proc, "collision stiffness", "sub-steps", f"at most {MAX_SUBSTEPS}")
    assert not out.exists()


def test_stiff_contact_within_the_maximum_is_accepted(tmp_path: Path) -> None:
    """The maximum refuses only what is out of range: 100 times the default stiffness needs a
    few sub-steps and passes (docs/stability.md); the summary notes them after its banner."""
    proc, _ = dkt([str(small_scene(tmp_path)), "--check", "--set",
                   f"output.dir={tmp_path / 'out'}", "--set", "collision.stiffness=1e-9",
                   "--set", "collision.stiffness_overlap=1e-9"], tmp_path, 30)
    assert proc.returncode == 0, proc.stderr
    # the sub-steps it takes are said in the start-up summary, after the banner, as a note
    lines = proc.stdout.splitlines()
    assert lines[0].startswith("dktlbm "), lines[:3]
    notes = [ln for ln in lines if "collision stiffness" in ln]
    assert len(notes) == 1 and notes[0].startswith("note: collision stiffness: "), notes
    assert "sub-steps per fluid step" in notes[0]

