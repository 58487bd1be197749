"""Slabs that follow the load (docs/design.md, "Balanced slabs"): a box whose disks all start in
its upper part moves its slab borders at the first step, says so in the log, and gives the bits
of the 1-rank run and of fixed slabs on 2, 3 and 4 ranks (uneven rows), also without shared
memory; the rank matrix's window scene (shifts, uneven rows) and closed box in 4-byte arithmetic
with the borders checked every 7 steps and moved at any imbalance give the 1-rank bits; a run
resumed on another rank count from a checkpoint written after the borders moved, with
balancing on or off, gives the bits of the uninterrupted run; the balance settings out of range
are refused with the key, the value and the allowed range. Each test's name says what it
proves."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

from dkt_run import EXE
from test_particle_slabs import STEPS, box_scene, datasets, launch
from test_rank_matrix import CASES

ROOT = Path(__file__).resolve().parents[1]

# a check at the first step and every 40 steps after; a small threshold so that the borders
# also move again while the disks settle
BALANCE = ["--set", "run.balance_every=40", "--set", "run.balance_threshold=1.05"]
FIXED = ["--set", "run.balance_every=0"]
MOVED = re.compile(r"balance at step (\d+): rows per rank ([\d ]+) -> ([\d ]+) \(")


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> Path:
    # 12 disks in two rows near the lid of a 97-row box: the top slab holds every link
    return box_scene(tmp_path_factory.mktemp("scene") / "box.nml", 6, [1.13, 0.95])


@pytest.fixture(scope="module")
def one_rank(scene: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("one") / "run"
    launch(scene, 1, out)
    return out


def same_bits(a: Path, b: Path) -> list[str]:
    want, got = datasets(a / "box.h5"), datasets(b / "box.h5")
    assert want.keys() == got.keys()
    return [name for name in want if want[name] != got[name]]


@pytest.mark.parametrize("ranks,tcp", [(2, False), (3, True), (4, False)])
def test_balanced_slabs_give_the_bits_of_one_rank_and_of_fixed_slabs(
    scene: Path, one_rank: Path, tmp_path: Path, ranks: int, tcp: bool
) -> None:
    log = launch(scene, ranks, tmp_path / "balanced", BALANCE, tcp=tcp)
    moves = MOVED.findall(log)
    assert moves and moves[0][0] == "1", f"no move of the borders at step 1:\n{log}"
    before = [int(v) for v in moves[0][1].split()]
    after = [int(v) for v in moves[0][2].split()]
    assert sum(before) == sum(after) == 97 and after != before and len(after) == ranks
    # the upper slab, which holds the disks, is the one that shrinks
    assert after[-1] < before[-1]
    assert not same_bits(one_rank, tmp_path / "balanced")
    launch(scene, ranks, tmp_path / "fixed", FIXED, tcp=tcp)
    assert not same_bits(tmp_path / "fixed", tmp_path / "balanced")


@pytest.mark.parametrize("case,ranks", [("window_uneven_rows_3", 3),
                                        ("closed_box_crossing_single_arith", 4)])
def test_borders_moved_every_few_steps_give_the_bits_of_one_rank(
    tmp_path: Path, case: str, ranks: int
) -> None:
    spec = CASES[case]
    scene = ROOT / "input" / spec["nml"]
    sets = [arg for key in spec["sets"] for arg in ("--set", key)]
    launch(scene, 1, tmp_path / "one", sets)
    log = launch(scene, ranks, tmp_path / "moved",
                 [*sets, "--set", "run.balance_every=7", "--set", "run.balance_threshold=1.0"])
    assert len(MOVED.findall(log)) >= 2, log
    one = {p.name: p for p in (tmp_path / "one").glob("*.h5")}
    moved = {p.name: p for p in (tmp_path / "moved").glob("*.h5")}
    assert one.keys() == moved.keys() and len(one) == 1
    want, got = datasets(next(iter(one.values()))), datasets(next(iter(moved.values())))
    assert want.keys() == got.keys()
    assert not [name for name in want if want[name] != got[name]]


@pytest.mark.parametrize("second,setting", [(2, FIXED), (4, BALANCE)])
def test_a_restart_after_the_borders_moved_on_another_rank_count_gives_the_same_bits(
    scene: Path, one_rank: Path, tmp_path: Path, second: int, setting: list[str]
) -> None:
    out = tmp_path / "run"
    log = launch(scene, 3, out, [*BALANCE, "--set", f"run.steps={STEPS // 2}"])
    assert MOVED.search(log), log
    checkpoint = out / f"box_chk_{STEPS // 2:09d}.h5"
    assert checkpoint.exists(), sorted(p.name for p in out.iterdir())
    launch(scene, second, out, [*setting, "--restart", str(checkpoint)])
    assert not same_bits(one_rank, out)


@pytest.mark.parametrize("key,value,allowed", [
    ("balance_every", "-5", "balance_every >= 0"),
    ("balance_threshold", "0.5", "1 <= balance_threshold <= 100"),
])
def test_balance_settings_out_of_range_are_refused(
    scene: Path, key: str, value: str, allowed: str
) -> None:
    proc = subprocess.run([str(EXE), str(scene), "--set", f"run.{key}={value}", "--check"],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode != 0
    assert f"&run {key} = {value} is out of range; allowed: {allowed}" in proc.stderr
