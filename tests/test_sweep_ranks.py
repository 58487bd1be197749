"""A gamma sweep on 2 ranks gives, at every point, bitwise the run on 1 rank.

The sweep a user runs first: `dkt-sweep plan input/case1.nml --gamma 1:2:0.05` at the paper's
resolution (25 spacings across the smaller disk), run with `dkt-sweep run --ranks 2`. Its row
counts are even at some points and odd at others, with odd and even nx, which is how the
uneven-split bug of the window (fixed in f7a9e9b) corrupted about half of such a sweep. Here
each point runs 750 steps, enough for the window to shift at every gamma (at gamma = 2 it
first shifts at step 608; asserted), and every dataset of the 2-rank run must equal the
1-rank run's.

The test also checks that every point's split (rows even or uneven on 2 ranks, nx odd or
even) is one that the rank-invariance matrix (test_rank_matrix.py) covers with the window on,
so the matrix, which runs on small grids, speaks for the sweep.
"""

from __future__ import annotations

import csv
import re
import subprocess
from pathlib import Path

import pytest

from dkt_run import EXE, INPUT, dkt_command, mpi_env
from test_rank_matrix import CASES, datasets

SWEEP = dkt_command("sweep")
SETS = ["run.steps=750", "output.field_interval=0.02", "output.series_interval=1e-9"]


def grid(nml: str, sets: list[str], outdir: Path) -> tuple[int, int]:
    """nx, ny of a scene, from `--check` (which allocates no lattice)."""
    args = [str(EXE), str(INPUT / nml), "--check", "--set", f"output.dir={outdir}"]
    for s in sets:
        args += ["--set", s]
    proc = subprocess.run(args, capture_output=True, text=True, env=mpi_env(), timeout=60)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    m = re.search(r"^cells (\d+) x (\d+)", proc.stdout, re.M)
    assert m, proc.stdout
    return int(m.group(1)), int(m.group(2))


def split_kind(nx: int, ny: int) -> tuple[str, str]:
    return ("rows even" if ny % 2 == 0 else "rows uneven", "nx even" if nx % 2 == 0 else "nx odd")


def sweep(tmp: Path, ranks: int) -> Path:
    out = tmp / f"sweep_r{ranks}"
    plan = [*SWEEP, "plan", str(INPUT / "case1.nml"), "--gamma", "1:2:0.05", "--out", str(out)]
    for s in SETS:
        plan += ["--set", s]
    subprocess.run(plan, check=True, capture_output=True, text=True)
    proc = subprocess.run(
        [*SWEEP, "run", "--out", str(out), "--jobs", "1", "--ranks", str(ranks)],
        capture_output=True,
        text=True,
        env=mpi_env(),
        timeout=1500,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return out


@pytest.fixture(scope="module")
def sweeps(tmp_path_factory: pytest.TempPathFactory) -> dict[int, Path]:
    tmp = tmp_path_factory.mktemp("sweep")
    return {ranks: sweep(tmp, ranks) for ranks in (1, 2)}


def test_every_gamma_is_bitwise_the_1_rank_run(sweeps: dict[int, Path]) -> None:
    with open(sweeps[2] / "runs.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 21
    kinds = set()
    bad = []
    for row in rows:
        one, _, attrs = datasets(sweeps[1] / row["id"] / "case1.h5")
        two, _, _ = datasets(sweeps[2] / row["id"] / "case1.h5")
        kinds.add(split_kind(int(attrs["nx"]), int(attrs["ny"])))
        offset = one["particles/window_offset"]
        assert offset[-1] < offset[0], f"gamma {row['gamma']}: the window never shifted"
        assert one.keys() == two.keys()
        differ = [k for k in one if one[k].tobytes() != two[k].tobytes()]
        if differ:
            bad.append(f"gamma {row['gamma']}: {', '.join(differ)}")
    assert not bad, "2 ranks differ from 1 rank:\n" + "\n".join(bad)
    # the sweep meets all four kinds of split; each must be one the matrix covers
    assert len(kinds) == 4, kinds


def test_the_matrix_covers_every_split_of_the_sweep(tmp_path: Path) -> None:
    covered = set()
    for case, spec in CASES.items():
        if spec["window"] and spec["nml"] == "case1.nml":
            nx, ny = grid(spec["nml"], spec["sets"], tmp_path / case)
            covered.add(split_kind(nx, ny))
    needed = set()
    for k in range(21):
        gamma = 1.0 + 0.05 * k
        nx, ny = grid("case1.nml", [f"pair.gamma={gamma:.2f}"], tmp_path / "g")
        needed.add(split_kind(nx, ny))
    assert needed <= covered, f"the matrix misses {needed - covered}"
