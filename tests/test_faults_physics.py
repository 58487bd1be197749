"""A restart continues the physics it started with.

The reference is the pair of case1 (gamma 1.3, 10 spacings per diameter, in the moving
window) run for STEPS steps on 2 ranks with a checkpoint half way. It is resumed from that
checkpoint with a changed input:

- each change of the physics the issue found accepted silently (particles.gravity,
  lbm.collision, coupling.bounce_back, fluid.viscosity with lbm.tau at the same dt,
  pair.density) is refused within a timeout, with exit status 2 and one error line naming the
  checkpoint, each changed key, its value in the checkpoint (read from the run file's stored
  namelist) and its new one, and every file of the run is left byte for byte as it was;
- the same change named in run.restart_changes runs, records the change in the /run attribute
  restart_changes_step_<step>, and the stored namelist shows the new value;
- a key run.restart_changes names that is not an input key is refused as bad input;
- changing only the run length and output keys resumes bit for bit;
- a checkpoint written on 2 ranks resumes on 3, whose rows do not split evenly (ny is checked
  not to be a multiple of 3), through the per-row digests, and ends bitwise equal to the run
  that never stopped.
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from dkt_run import INPUT, run, run_args, tree_digest
from test_faults_chk import C1 as CHECKPOINTED
from test_faults_chk import HALF, RANKS, STEPS

C1 = [*CHECKPOINTED, f"run.steps={STEPS}"]
TIMEOUT = 120

CHANGES = {
    "gravity": ["particles.gravity=500.0"],
    "collision-model": ["lbm.collision=bgk"],
    "bounce-back": ["coupling.bounce_back=halfway"],
    "viscosity-at-the-same-dt": ["fluid.viscosity=0.02", "lbm.tau=0.8"],
    "pair-density": ["pair.density=1.5"],
}


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """STEPS steps of the pair on 2 ranks, with checkpoints at STEPS/2 and STEPS."""
    out = tmp_path_factory.mktemp("faults_physics") / "run"
    run("case1.nml", RANKS, C1, out, timeout=300)
    assert (out / HALF).exists()
    return out


def namelist(h5file: Path) -> str:
    with h5py.File(h5file, "r") as h5:
        text = h5["run"].attrs["namelist"]
    return text.decode() if isinstance(text, bytes) else str(text)


def stored_value(text: str, key: str) -> str:
    """The value of group.key in a stored namelist ('  name = value  ! ...' under &group)."""
    group, name = key.split(".")
    block = text.split(f"&{group}\n", 1)[1].split("\n/", 1)[0]
    m = re.search(rf"^\s*{re.escape(name)} = (.*?)\s*!", block, re.MULTILINE)
    assert m, f"{key} not in the stored namelist"
    return m.group(1)


def resume(out: Path, sets: list[str], ranks: int = RANKS):
    args = [str(INPUT / "case1.nml")]
    for s in [*C1, *sets, f"output.dir={out}"]:
        args += ["--set", s]
    return run_args([*args, "--restart", str(out / HALF)], ranks, timeout=TIMEOUT)


def same_series(a: Path, b: Path) -> None:
    with h5py.File(a / "case1.h5") as ha, h5py.File(b / "case1.h5") as hb:
        for group in ("particles", "diagnostics"):
            for name, d in ha[group].items():
                if isinstance(d, h5py.Dataset):
                    assert np.array_equal(d[()], hb[group][name][()], equal_nan=True), name
        last = sorted(ha["fields"])[-1]
        for name, d in ha["fields"][last].items():
            if isinstance(d, h5py.Dataset):
                assert np.array_equal(d[()], hb["fields"][last][name][()]), name


@pytest.mark.parametrize("sets", CHANGES.values(), ids=CHANGES)
def test_a_change_of_the_physics_is_refused_and_nothing_is_touched(
    reference: Path, tmp_path: Path, sets: list[str]
) -> None:
    out = tmp_path / "run"
    shutil.copytree(reference, out)
    stored = namelist(out / "case1.h5")
    before = tree_digest(out)
    proc = resume(out, sets)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    errors = [ln for ln in proc.stderr.splitlines() if ln.startswith("dktlbm: error")]
    assert len(errors) == 1 and "[rank" not in errors[0], proc.stderr
    assert str(out / HALF) in errors[0], errors[0]
    for s in sets:
        key, new = s.split("=")
        old = stored_value(stored, key)
        assert old.strip("'") != new, f"{key} is not changed by {s}"
        assert f"{key} = {old} in the checkpoint" in errors[0], errors[0]
        assert new in errors[0].split(f"{key} = {old} in the checkpoint, ")[1], errors[0]
        assert key in errors[0].split("run.restart_changes=")[1], errors[0]
    assert tree_digest(out) == before, "a refused restart changed the run's files"


def test_an_allowed_change_runs_and_is_recorded(reference: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    shutil.copytree(reference, out)
    old = stored_value(namelist(out / "case1.h5"), "particles.gravity")
    proc = resume(out, ["particles.gravity=500.0", "run.restart_changes=particles.gravity"])
    assert proc.returncode == 0, proc.stderr
    with h5py.File(out / "case1.h5") as h5:
        record = h5["run"].attrs[f"restart_changes_step_{STEPS // 2:09d}"]
        y = h5["particles/y"][()]
    assert f"particles.gravity {old} -> 500.0" in str(record), record
    assert stored_value(namelist(out / "case1.h5"), "particles.gravity") == "500.0"
    with h5py.File(reference / "case1.h5") as h5:
        assert not np.array_equal(h5["particles/y"][()], y), "the change changed nothing"


def test_an_unknown_key_in_restart_changes_is_bad_input(reference: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    shutil.copytree(reference, out)
    before = tree_digest(out)
    proc = resume(out, ["particles.gravity=500.0", "run.restart_changes=particles.gravty"])
    assert proc.returncode == 2, proc.stderr
    assert "'particles.gravty' is not an input key" in proc.stderr, proc.stderr
    assert tree_digest(out) == before


def test_run_length_and_output_keys_resume_bit_for_bit(reference: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    shutil.copytree(reference, out)
    proc = resume(out, ["run.t_end=5.0", "output.compress=1", "run.checkpoint_keep=3"])
    assert proc.returncode == 0, proc.stderr
    same_series(reference, out)


def test_a_two_rank_checkpoint_resumes_on_three_uneven_ranks(
    reference: Path, tmp_path: Path
) -> None:
    with h5py.File(reference / "case1.h5") as h5:
        ny = int(h5["run"].attrs["ny"])
    assert ny % 3 != 0, f"ny = {ny} splits evenly on 3 ranks"
    out = tmp_path / "run"
    shutil.copytree(reference, out)
    with h5py.File(out / HALF) as h5:
        assert "f_checksum" in h5, "the checkpoint has no per-row digests"
    proc = resume(out, [], ranks=3)
    assert proc.returncode == 0, proc.stderr
    assert "checksums" not in proc.stderr, proc.stderr
    same_series(reference, out)
