"""The interior nodes of moving disks are reset only when the lattice is read whole.

Nothing in a step reads an interior node: a fluid node pulls from a solid one only over a link,
whose bounce-back overwrites that slot first, and the refill and the density sums read fluid
nodes only. So a run with moving disks and no window resets the interior nodes (equilibrium at
the disk's velocity, docs/model.md §3) only after a step whose lattice is written or measured:
fields, guards, progress, checkpoints (docs/performance.md). These tests show that this changes
no bit of the output, against runs that read the lattice after every step (and so reset it after
every step, as the code did before): if an interior value reached the fluid, a link or a
particle, or a reader came before the reset, a dataset would differ.

The scene is the 504-disk box (input/sediment504.nml) at 8 spacings per diameter, 256 x 256
nodes, 36 steps: 38 800 links and 25 400 interior nodes, disks in contact with each other.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from dkt_run import all_datasets, run

STEPS = 36
BASE = ["lbm.cells_per_diameter=8", f"run.steps={STEPS}"]


def sparse(dt: float) -> list[str]:
    """Fields every 7 steps, the guard every 100 steps, no progress lines."""
    return [
        *BASE,
        f"output.field_interval={7.2 * dt!r}",
        "run.guard_every=100",
        "run.progress_every=0",
    ]


def fields_by_step(h5file: Path) -> dict[str, dict[str, np.ndarray]]:
    """Every dataset of every field group (the disks' sub-group too), by group name (step)."""
    out: dict[str, dict[str, np.ndarray]] = {}
    with h5py.File(h5file, "r") as h5:
        for step, group in h5["fields"].items():
            data: dict[str, np.ndarray] = {}

            def take(name: str, obj: object, data: dict[str, np.ndarray] = data) -> None:
                if isinstance(obj, h5py.Dataset):
                    data[name] = obj[()]

            group.visititems(take)
            out[step] = data
    return out


def particle_series(h5file: Path) -> dict[str, np.ndarray]:
    with h5py.File(h5file, "r") as h5:
        return {n: d[()] for n, d in h5["particles"].items() if isinstance(d, h5py.Dataset)}


def dt_of(h5file: Path) -> float:
    with h5py.File(h5file, "r") as h5:
        return float(np.asarray(h5["run"].attrs["dt"]).ravel()[0])


def assert_same_at_common_steps(every: Path, sparse: Path, steps: list[str]) -> None:
    a = fields_by_step(every / "sediment504.h5")
    b = fields_by_step(sparse / "sediment504.h5")
    assert set(steps) <= set(b), f"steps {sorted(set(steps) - set(b))} missing in {sparse}"
    for s in steps:
        differ = [k for k in a[s] if not np.array_equal(a[s][k], b[s][k], equal_nan=True)]
        assert not differ, f"step {s}: {differ} differ"
    pa = particle_series(every / "sediment504.h5")
    pb = particle_series(sparse / "sediment504.h5")
    assert sorted(pa) == sorted(pb)
    differ = [k for k in pa if not np.array_equal(pa[k], pb[k], equal_nan=True)]
    assert not differ, f"particle series differ: {differ}"


@pytest.fixture(scope="module")
def every_step(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The reference on 1 rank: fields, guards and progress after every step, so the interior
    nodes are reset after every step."""
    out = tmp_path_factory.mktemp("every") / "run"
    run(
        "sediment504.nml",
        1,
        [
            *BASE,
            "output.field_interval=1e-9",
            "run.guard_every=1",
            "run.progress_every=1",
            "run.checkpoint_every=10",
        ],
        out,
        timeout=600,
    )
    assert len(fields_by_step(out / "sediment504.h5")) == STEPS + 1
    return out


@pytest.mark.parametrize("ranks", [2, 3])
def test_fields_every_seventh_step_equal_those_of_every_step(
    every_step: Path, tmp_path: Path, ranks: int
) -> None:
    """Fields every 7 steps, the guard every 100 and no progress lines: at steps 7, 14, ... the
    fields (rho, velocity, vorticity, pressure, the particle index at every node, the disks),
    and the particle series of every step, are those of the reference, bit for bit; on 2 and 3
    ranks (the rows split 128/128 and 86/85/85), so that the nodes reset on each slab and
    those written from a halo row come out the same too."""
    dt = dt_of(every_step / "sediment504.h5")
    out = tmp_path / "run"
    run("sediment504.nml", ranks, sparse(dt), out, timeout=600)
    written = sorted(fields_by_step(out / "sediment504.h5"))
    assert written == [f"{s:06d}" for s in (0, 7, 14, 21, 28, 35, 36)]
    assert_same_at_common_steps(every_step, out, written)


def test_a_checkpoint_off_the_field_schedule_resumes_to_the_same_bits(
    every_step: Path, tmp_path: Path
) -> None:
    """A checkpoint at step 20 (every 10 steps, the last two kept), which no field output or
    guard reads, holds the lattice of the reference's checkpoint at step 20 bit for bit,
    interior nodes included (checkpoint_poll settles the lattice first: without it they
    differ). Resumed on 3 ranks from this 2-rank
    checkpoint, the run's fields at 21, 28, 35, 36 and its particle series equal the
    reference."""
    dt = dt_of(every_step / "sediment504.h5")
    out = tmp_path / "run"
    sets = [*sparse(dt), "run.checkpoint_every=10"]
    run("sediment504.nml", 2, sets, out, timeout=600)
    resumed = tmp_path / "resumed"
    shutil.copytree(out, resumed)
    chk = resumed / "sediment504_chk_000000020.h5"
    assert chk.exists(), sorted(p.name for p in resumed.iterdir())
    ref, got = all_datasets(every_step / chk.name), all_datasets(chk)
    # the state: populations, their checksums, the particles (the input text, the run id and
    # the schedule's integers differ by design)
    state = ["f", "f_checksum", "particles", "precision", "state_real"]
    assert set(state) <= set(ref) and set(state) <= set(got)
    differ = [k for k in state if not np.array_equal(ref[k], got[k], equal_nan=True)]
    assert not differ, f"checkpoint datasets differ: {differ}"
    run("sediment504.nml", 3, sets, resumed, extra=["--restart", str(chk)], timeout=600)
    written = sorted(fields_by_step(resumed / "sediment504.h5"))
    assert_same_at_common_steps(every_step, resumed, written)
    assert written[-1] == f"{STEPS:06d}"
