"""A window that grows instead of losing a particle (window.max_above, docs/model.md §5).

The scene is case2 (the smaller disk above the larger one, so the larger falls away from it) at
6 spacings across the smaller disk (D_1 = 12 spacings) in a short window: window.below = 4.0833
and above = 4 D_1 give 97 rows (a prime), and the smaller disk reaches the 1 D_1 margin under
the upper end at step 535. With window.max_above = 8 the window grows there by above/2 = 2 D_1
to 121 rows (uneven on 2, 3 and 4 ranks) and the run goes on.

Proves:
- the growth happens and the run goes on: snapshots before it have 97 rows, after it 121, the
  run finishes (stop_reason 'finished') past the step where a window of fixed length ends it;
- every dataset of the run on 2, 3 and 4 ranks, and with two lattices, is bitwise the 1-rank
  in-place run (the rows move between ranks and the slabs are split anew when it grows);
- a run resumed from a checkpoint written before the growth, and one from a checkpoint written
  after it (a lattice of 121 rows, on another rank count), equal the uninterrupted run, bit for
  bit, XDMF sidecar included; a checkpoint of a row count the scene cannot grow to is refused;
- a checkpoint after the growth resumes on a rank count that only the grown lattice allows (its
  slabs are judged on the checkpoint's rows, not the first window's);
- each snapshot's XDMF grid has that snapshot's rows, the Python reader reads both sizes, and
  ParaView (when pvpython is installed) sees both;
- a window grown to its limit still ends the run with window_escape and a warning naming
  window.max_above;
- by default (window.max_above = -1) the window grows as the run needs: the run grows where the
  one with max_above = 8 grows and gives its bits (on 2 ranks against 1), and the limit the
  start-up summary states is window.above plus the settling-speed scale times the run's
  length, counted in whole growths; only max_above = 0 keeps a window of fixed length;
- the start-up summary states the memory of the largest window, the figure the memory check
  takes;
- the growth does not jolt the disk nearest the upper end (the added rows continue the outflow).

Each fails on the code before window.max_above existed (the key is refused), and the bitwise
ones on a growth that leaves rows on the wrong rank, sizes a message from one side only or
keeps the old slab in the run file.
"""

from __future__ import annotations

import json
import math
import re
import shutil
import subprocess
from pathlib import Path

import h5py
import pytest

from dkt_run import ROOT, run
from dktlbm.read import read_field
from test_rank_matrix import assert_same_bits, datasets, rows_for

NML = "case2.nml"
STEPS = 864  # 1.2 s at dt = 1/720 s: the growth at step 535, five snapshots after it
GROWS_AT = 535
SETS = [
    "lbm.cells_per_diameter=6",
    "window.below=4.0833333",
    "window.above=4",
    "window.max_above=8",
    f"run.steps={STEPS}",
    "output.field_interval=0.1",
    "output.series_interval=1e-9",
]
NY0, NY1 = 97, 121  # rows at the start and after the growth


def field_rows(h5file: Path) -> dict[int, int]:
    """The rows of each field snapshot, by step."""
    with h5py.File(h5file, "r") as h5:
        return {int(h5["fields"][g].attrs["step"]): h5["fields"][g]["ux"].shape[0]
                for g in h5["fields"]}


def stop_reason(h5file: Path) -> str:
    with h5py.File(h5file, "r") as h5:
        value = h5["run"].attrs["stop_reason"]
    return value.decode() if isinstance(value, bytes) else str(value)


class Runs:
    """The runs of the scene, each made once: ranks and streaming -> output directory."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.done: dict[tuple[int, str, str], Path] = {}

    def get(self, ranks: int, streaming: str = "in_place", precision: str = "double") -> Path:
        key = (ranks, streaming, precision)
        if key not in self.done:
            out = self.root / f"r{ranks}_{streaming}_{precision}"
            sets = [*SETS, f"lbm.streaming={streaming}", f"lbm.precision={precision}"]
            proc = run(NML, ranks, sets, out, timeout=600)
            assert f"window grown to {NY1} rows" in proc.stdout, proc.stdout
            self.done[key] = out
        return self.done[key]


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> Runs:
    return Runs(tmp_path_factory.mktemp("grow"))


def test_the_window_grows_where_a_fixed_one_ends_the_run_and_the_run_goes_on(runs: Runs) -> None:
    h5file = runs.get(1) / "case2.h5"
    rows = field_rows(h5file)
    assert {n for s, n in rows.items() if s < GROWS_AT} == {NY0}, rows
    assert {n for s, n in rows.items() if s > GROWS_AT} == {NY1}, rows
    assert sum(s > GROWS_AT for s in rows) >= 5, rows
    assert stop_reason(h5file) == "finished"
    with h5py.File(h5file, "r") as h5:
        assert int(h5["run"].attrs["ny"]) == NY0  # /run holds the rows at the start
        assert h5["particles/t"].shape[0] == STEPS + 1
    # the splits the bitwise tests claim: prime before, uneven on every rank count after
    assert all(NY0 % k for k in range(2, NY0))
    assert all(len(set(rows_for(NY1, n))) == 2 for n in (2, 3, 4))
    # the same scene with a window of fixed length ends where this one grew
    fixed = runs.root / "fixed"
    proc = run(NML, 1, [*SETS[:3], "window.max_above=0", *SETS[4:]], fixed, timeout=600)
    assert "window.above" in proc.stderr
    assert stop_reason(fixed / "case2.h5") == "window_escape"
    with h5py.File(fixed / "case2.h5", "r") as h5:
        assert h5["particles/t"].shape[0] == GROWS_AT + 1


def test_the_growth_does_not_jolt_the_disk_near_the_upper_end(runs: Runs) -> None:
    """The rows a growth adds continue the outflow (copies of the old upper end row), so the
    smaller disk, 1 D_1 under the upper end and speeding up when the window grows, goes on
    speeding up: within no 60 steps after the growth does its speed drop by more than 1 %, and
    its force stays within 10 % of its largest before. Rows added at rest stopped the fluid
    leaving through the upper end at once and sent a pressure wave down onto the disks: a drop
    of 10.2 % and a force 1.71 times its largest before (0.3 % and 1.05 now; with a fixed
    8-D_1 window 0.1 % and 1.04)."""
    with h5py.File(runs.get(1) / "case2.h5", "r") as h5:
        speed = [abs(v) for v in h5["particles/v"][:, 1]]
        force = h5["particles/fy"][:, 1]
    after = speed[GROWS_AT:]
    drop = max(a - min(after[i : i + 60]) for i, a in enumerate(after))
    assert drop < 0.01 * after[0], (drop, after[0])
    assert max(force[GROWS_AT:]) < 1.1 * max(force[GROWS_AT - 135 : GROWS_AT])


@pytest.mark.parametrize("precision", ["single", "single_arith", "half"])
def test_a_growing_window_of_4_byte_populations_is_bitwise_the_1_rank_run(
    runs: Runs, precision: str
) -> None:
    """The rows a growth moves between ranks travel as stored 4-byte values (or 16-bit codes,
    'half'), and a lattice that grows keeps its precision ('single_arith' and 'half' collide in
    4 bytes after the growth as before it): 3 uneven ranks give the bits of 1."""
    ref = datasets(runs.get(1, precision=precision) / "case2.h5")
    assert_same_bits(ref, datasets(runs.get(3, precision=precision) / "case2.h5"),
                     f"{precision}, 3 ranks against 1")


def test_the_performance_line_counts_the_rows_of_each_step(runs: Runs) -> None:
    """The closing speed counts each step's lattice: 97 rows up to the growth, 121 after it (a
    count of the final rows for every step would be 12 % high). Checked on the printed figures:
    MLUPS x seconds against the node updates made, so the machine's speed does not enter."""
    log = (runs.get(1) / "case2.log").read_text()
    m = re.search(r"performance:\s*([0-9.]+) MLUPS \(\d+ cells x (\d+) steps in\s*([0-9.]+) s", log)
    assert m, log[-2000:]
    mlups, steps, seconds = float(m[1]), int(m[2]), float(m[3])
    assert steps == STEPS
    nx = 120
    made = nx * (NY0 * (GROWS_AT - 1) + NY1 * (STEPS - GROWS_AT + 1))
    # the printed figures are rounded (MLUPS to 0.01, seconds to 0.001): the updates they
    # imply lie within those roundings, and a step either way of the growth (0.3 %) is allowed
    lo = (mlups - 0.005) * (seconds - 0.0005) * 1e6
    hi = (mlups + 0.005) * (seconds + 0.0005) * 1e6
    assert lo * (1 - 0.003) <= made <= hi * (1 + 0.003), (mlups, seconds, made)


@pytest.mark.parametrize("ranks", (2, 3, 4))
def test_a_growing_window_is_bitwise_the_1_rank_run(runs: Runs, ranks: int) -> None:
    assert_same_bits(datasets(runs.get(1) / "case2.h5"),
                     datasets(runs.get(ranks) / "case2.h5"), f"{ranks} ranks against 1")


@pytest.mark.parametrize("ranks", (1, 3))
def test_a_growing_window_with_two_lattices_is_bitwise_the_in_place_run(runs: Runs,
                                                                       ranks: int) -> None:
    assert_same_bits(datasets(runs.get(1) / "case2.h5"),
                     datasets(runs.get(ranks, "two_lattice") / "case2.h5"),
                     f"two lattices on {ranks} ranks against in place on 1")


def test_each_snapshot_s_xdmf_grid_and_the_reader_have_its_rows(runs: Runs) -> None:
    out = runs.get(2)
    rows = field_rows(out / "case2.h5")
    xml = (out / "case2.xdmf").read_text()
    grids = re.findall(r'<Grid Name="step (\d+)".*?Dimensions="1 (\d+) (\d+)"', xml, re.S)
    assert {int(s): int(n) for s, n, _ in grids} == rows
    assert {int(nx) for _, _, nx in grids} == {120}
    with h5py.File(out / "case2.h5", "r") as h5:
        times = {int(h5["fields"][g].attrs["step"]): float(h5["fields"][g].attrs["time"])
                 for g in h5["fields"]}
    for step in (min(rows), max(rows)):
        snap = read_field(out / "case2.h5", "uy", times[step])
        assert snap.data.shape == (rows[step], 120)
        assert snap.extent[3] - snap.extent[2] == pytest.approx(rows[step] * snap.dx)


@pytest.mark.skipif(shutil.which("pvpython") is None, reason="pvpython (ParaView) is not installed")
def test_paraview_reads_the_snapshots_before_and_after_the_growth(runs: Runs) -> None:
    out = runs.get(2)
    args = [shutil.which("pvpython"), str(ROOT / "tests" / "paraview_probe.py"),
            str(out / "case2.xdmf"), "0,0", f"60,{NY0 - 7}"]
    proc = subprocess.run(args, capture_output=True, text=True, timeout=300, cwd=out)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    seen = json.loads(proc.stdout.strip().splitlines()[-1])
    rows = field_rows(out / "case2.h5")
    dims = [step["fields"]["dimensions"] for step in seen["steps"]]
    assert dims == [[120, rows[s], 1] for s in sorted(rows)]
    # the values where the file has them: a grid of the wrong rows would shift them
    with h5py.File(out / "case2.h5", "r") as h5:
        for step, group in zip(seen["steps"], sorted(h5["fields"]), strict=True):
            ux, uy = h5["fields"][group]["ux"][()], h5["fields"][group]["uy"][()]
            j = NY0 - 7
            assert step["fields"]["velocity"][f"60,{j}"] == [ux[j, 60], uy[j, 60], 0.0], group


@pytest.fixture(scope="module")
def checkpointed(runs: Runs) -> Path:
    """The scene on 2 ranks with a checkpoint every 288 steps: at 288 (97 rows, before the
    growth), 576 (121 rows, after it) and 864; its output is the uninterrupted run's."""
    out = runs.root / "checkpointed"
    run(NML, 2, [*SETS, "run.checkpoint_every=288", "run.checkpoint_keep=3"], out, timeout=600)
    for step in (288, 576):
        assert (out / f"case2_chk_{step:09d}.h5").exists()
    with h5py.File(out / "case2_chk_000000576.h5", "r") as h5:
        assert h5["f"].shape[1] == NY1  # the checkpoint after the growth holds the grown lattice
    return out


def assert_same_output(a: Path, b: Path) -> None:
    assert_same_bits(datasets(a / "case2.h5"), datasets(b / "case2.h5"), f"{b} against {a}")
    for name in ("case2_diagnostics.csv", "case2.xdmf"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name


@pytest.mark.parametrize("step", (288, 576))
def test_a_restart_before_or_after_the_growth_equals_the_uninterrupted_run(
    runs: Runs, checkpointed: Path, tmp_path: Path, step: int
) -> None:
    """Resumed on 3 ranks (another split than the 2 that wrote it) from the checkpoint before
    the growth (which must grow again on its way) or after it (which must start at 121 rows)."""
    out = tmp_path / "resumed"
    shutil.copytree(checkpointed, out)
    proc = run(NML, 3, SETS, out, extra=["--restart", str(out / f"case2_chk_{step:09d}.h5")],
               timeout=600)
    assert ("window grown" in proc.stdout) == (step < GROWS_AT), proc.stdout
    assert_same_output(runs.get(1), out)


def test_a_checkpoint_after_the_growth_resumes_on_ranks_only_the_grown_lattice_allows(
    runs: Runs, checkpointed: Path, tmp_path: Path
) -> None:
    """A slab of this scene needs 16 rows: 97 rows allow at most 6 ranks, 121 allow 7. The
    checkpoint written after the growth holds 121 rows, and the run resumes from it on 7 ranks
    (it was refused there, judged by the first window's 97 rows), equal to the uninterrupted
    run bit for bit. A new run on 7 ranks is still refused, naming the 97 rows."""
    fresh = run(NML, 7, SETS, tmp_path / "fresh", check=False, timeout=600)
    assert fresh.returncode != 0 and "the channel has 97 rows" in fresh.stderr, fresh.stderr
    out = tmp_path / "resumed"
    shutil.copytree(checkpointed, out)
    run(NML, 7, SETS, out, extra=["--restart", str(out / "case2_chk_000000576.h5")], timeout=600)
    assert_same_output(runs.get(1), out)


def test_a_checkpoint_of_rows_the_scene_cannot_grow_to_is_refused(checkpointed: Path,
                                                                  tmp_path: Path) -> None:
    """121 rows from a scene that starts at 94 and grows by 22 (window.above = 3.75), or
    from one that never grows: another lattice, refused before anything is cut."""
    out = tmp_path / "resumed"
    shutil.copytree(checkpointed, out)
    before = (out / "case2.h5").read_bytes()
    for change in ("window.above=3.75", "window.max_above=0"):
        sets = [*SETS, change]
        proc = run(NML, 2, sets, out, extra=["--restart", str(out / "case2_chk_000000576.h5")],
                   check=False, timeout=600)
        assert proc.returncode != 0, change
        assert "the checkpoint holds a lattice of 120 x 121 cells" in proc.stderr, proc.stderr
    assert (out / "case2.h5").read_bytes() == before


def test_a_window_grown_to_its_limit_still_ends_the_run_with_window_escape(
    tmp_path: Path,
) -> None:
    """window.max_above = 4.25: the window grows once, to 100 rows, and the disk reaches the
    margin of that window later; the run ends there (exit 0) with a warning naming the limit."""
    out = tmp_path / "limit"
    sets = [s for s in SETS if not s.startswith("window.max_above")]
    proc = run(NML, 2, [*sets, "window.max_above=4.25"], out, timeout=600)
    assert "window grown to 100 rows" in proc.stdout, proc.stdout
    warnings = [ln for ln in proc.stderr.splitlines() if "window.max_above" in ln]
    assert len(warnings) == 1 and warnings[0].startswith("dktlbm: warning"), proc.stderr
    h5file = out / "case2.h5"
    assert stop_reason(h5file) == "window_escape"
    rows = field_rows(h5file)
    assert set(rows.values()) == {NY0, 100}, rows
    with h5py.File(h5file, "r") as h5:
        assert GROWS_AT < h5["particles/t"].shape[0] - 1 < STEPS


GROWN_MIB = re.compile(r"\(up to ([0-9.]+) MiB in all once the window has grown to (\d+) rows\)")


@pytest.mark.parametrize("ranks", [1, 3])
def test_the_summary_states_the_memory_of_the_largest_window_the_check_takes(
    tmp_path: Path, ranks: int
) -> None:
    """The start-up summary states what rank 0 holds once the window has grown to its limit
    (8 D_1 above: 12 x 12.0833 = 145 rows), and that figure is the one the memory check
    takes: run.memory_limit just above the ranks' sum of it passes --check, just below it
    stops with the memory message. On 3 ranks 145 rows split 49/48/48, so rank 0's slab is the
    largest. A summary that printed the window's first size, or a check that took it, fails."""
    proc = run(NML, ranks, SETS, tmp_path / "a", extra=["--check"], timeout=120, check=False)
    assert proc.returncode == 0, proc.stderr
    m = GROWN_MIB.search(proc.stdout)
    assert m, proc.stdout
    assert int(m.group(2)) == 145
    grown = float(m.group(1))
    first = re.search(r"lattices ([0-9.]+) MiB", proc.stdout)
    assert first and float(first.group(1)) < grown
    for margin, passes in ((0.02, True), (-0.02, False)):
        limit = (ranks * grown + margin) / 1024.0
        proc = run(NML, ranks, [*SETS, f"run.memory_limit={limit:.9f}"], tmp_path / "b",
                   extra=["--check"], timeout=120, check=False)
        assert (proc.returncode == 0) == passes, (margin, proc.stdout + proc.stderr)
        if not passes:
            assert "145 cells" in proc.stderr and "run.memory_limit" in proc.stderr, proc.stderr


def test_by_default_the_window_grows_as_the_run_needs_and_gives_the_same_bits(
    runs: Runs, tmp_path: Path
) -> None:
    """Without window.max_above (-1, the default) the window grows at the step the run with
    max_above = 8 grows and to the same 121 rows; a growth changes nothing before it, so the run
    gives that run's every bit, here on 2 ranks against its 1-rank run. A default that never
    grows ends the run at step 535 and fails."""
    out = tmp_path / "auto"
    sets = [s for s in SETS if not s.startswith("window.max_above")]
    proc = run(NML, 2, sets, out, timeout=600)
    assert f"window grown to {NY1} rows" in proc.stdout, proc.stdout
    assert stop_reason(out / "case2.h5") == "finished"
    assert_same_bits(datasets(runs.get(1) / "case2.h5"), datasets(out / "case2.h5"),
                     "window.max_above = -1 on 2 ranks against = 8 on 1")


def test_the_default_limit_is_above_plus_the_velocity_scale_times_the_run(
    tmp_path: Path,
) -> None:
    """The limit of window.max_above = -1, from the scene's numbers (input/case2.nml: the larger
    disk D = d1 = 0.2 cm, 12 spacings, rho_p = 1.01, g = 980 cm/s^2; dt = 1/720 s): the
    settling-speed scale U = sqrt(pi D/2 (rho_p/rho_f - 1) g), the run's length t = steps dt,
    above + U t/D D_1, rounded up to a whole number of growths of above/2 from the first 97
    rows. Doubling run.steps lengthens it, up to 20 x above; window.max_above = 0 states a
    window that never grows."""
    d, dt, grow = 0.2, 1.0 / 720.0, 24
    u = math.sqrt(math.pi * d / 2.0 * 0.01 * 980.0)
    sets = [s for s in SETS if not s.startswith(("window.max_above", "run.steps"))]
    for steps in (STEPS, 2 * STEPS, 10**7):  # the last at the cap, 20 x above = 80 D_1
        limit = 4.0 + min(u * steps * dt / d, 19 * 4.0)
        rows = round((4.0833333 + limit) * d / (d / 12.0))
        expect = NY0 + grow * math.ceil((rows - NY0) / grow)
        proc = run(NML, 1, [*sets, f"run.steps={steps}"], tmp_path / "a", extra=["--check"],
                   timeout=120)
        m = GROWN_MIB.search(proc.stdout)
        assert m and int(m.group(2)) == expect, (expect, proc.stdout)
        assert "window.max_above = -1" in proc.stdout, proc.stdout
    proc = run(NML, 1, [*sets, "window.max_above=0"], tmp_path / "b", extra=["--check"],
               timeout=120)
    assert not GROWN_MIB.search(proc.stdout) and "never grows" in proc.stdout, proc.stdout
