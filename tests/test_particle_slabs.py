"""Particles owned by slabs (docs/design.md, "Particles across slabs"): a box of many settling
disks gives the same bits on every rank count and split, with either transport, across the
migrations of disks from slab to slab and across a restart on another rank count; and the
particles' messages per step do not grow with the number of disks. Each test's name says what
it proves."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from dkt_run import EXE, mpi_command, mpi_env

ROOT = Path(__file__).resolve().parents[1]

# 80 x 97 nodes at 8 per D: 97 rows split unevenly on 2, 3 and 4 ranks (24-25 rows, the least a
# slab of these disks may have is 12)
DX = 0.0125
NX, NY = 80, 97
STEPS = 240


def box_scene(path: Path, columns: int, rows: list[float]) -> Path:
    """A closed box (walls at all four sides) with rows of `columns` disks of D = 0.1 cm (rho_p =
    1.02) at the heights `rows` (cm), every other row shifted by a quarter pitch, released at
    rest."""
    d, width, height = 0.1, NX * DX, NY * DX
    margin = 0.5 * d + 2 * DX  # two spacings from the side walls
    pitch_x = (width - 2 * margin) / columns
    xs, ys = [], []
    for j, y in enumerate(rows):
        for i in range(columns):
            shift = (0.25 * (j % 2) - 0.125) * pitch_x
            xs.append(margin + pitch_x * (i + 0.5) + shift)
            ys.append(y)
    n = len(xs)
    path.write_text(
        f"""&domain
  width = {width}, height = {height}
  sides = 'wall', lower = 'wall', upper = 'wall'
/
&fluid
  density = 1.0, viscosity = 0.01
/
&lbm
  tau = 0.65, cells_per_diameter = 8
/
&particles
  count = {n}, gravity = 980.0
  diameter = {n}*{d}
  density = {n}*1.02
  x = {", ".join(f"{v:.6f}" for v in xs)}
  y = {", ".join(f"{v:.6f}" for v in ys)}
/
&collision
  range = 2.0
/
&run
  steps = {STEPS}, progress_every = 0, checkpoint_every = {STEPS // 2}
/
&output
  series_interval = 0.01, field_interval = 0.1
/
"""
    )
    return path


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> Path:
    # each row starts a spacing and a half above a slab face of the 4-rank split (y = 0.3125,
    # 0.6125 and 0.9125 cm), and one row above those
    return box_scene(tmp_path_factory.mktemp("scene") / "box.nml", 6, [1.13, 0.93, 0.63, 0.33])


def launch(
    scene: Path, ranks: int, out: Path, extra: list[str] | None = None, tcp: bool = False
) -> str:
    env = mpi_env()
    if tcp:
        # no shared memory between the ranks: they talk as ranks on different nodes do
        env["OMPI_MCA_btl"] = "self,tcp"
    cmd = [*mpi_command(ranks), str(EXE), str(scene), "--set", f"output.dir={out}", *(extra or [])]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=env)
    assert proc.returncode == 0, f"{' '.join(cmd)}\n{proc.stdout}\n{proc.stderr}"
    return proc.stdout


def datasets(h5file: Path) -> dict[str, bytes]:
    """Every dataset outside /run, as bytes."""
    found: dict[str, bytes] = {}
    with h5py.File(h5file, "r") as h5:

        def visit(name: str, obj: object) -> None:
            if isinstance(obj, h5py.Dataset) and not name.startswith("run"):
                found[name] = np.asarray(obj[()]).tobytes()

        h5.visititems(visit)
    return found


@pytest.fixture(scope="module")
def one_rank(scene: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("one") / "run"
    launch(scene, 1, out)
    return out


def slab_of(y_cm: np.ndarray, ranks: int) -> np.ndarray:
    """The rank whose rows hold each centre, as dktlbm splits NY rows over `ranks`."""
    base, extra = divmod(NY, ranks)
    starts = [r * base + min(r, extra) for r in range(ranks)]
    rows = np.clip(np.floor(y_cm / DX).astype(int), 0, NY - 1)
    return np.searchsorted(starts, rows, side="right") - 1


def test_disks_migrate_across_every_slab_face_of_four_ranks(one_rank: Path) -> None:
    """The scene is a real test of migration: on 4 ranks, disks change slab during the run,
    across each of the three faces."""
    with h5py.File(one_rank / "box.h5", "r") as h5:
        y = h5["particles/y"][()]
    owners = np.stack([slab_of(row, 4) for row in y])
    crossed = {
        (int(a), int(b))
        for row0, row1 in zip(owners[:-1], owners[1:], strict=True)
        for a, b in zip(row0, row1, strict=True)
        if a != b
    }
    faces = {min(a, b) for a, b in crossed}
    assert faces == {0, 1, 2}, f"slab changes seen: {sorted(crossed)}"


@pytest.mark.parametrize("ranks,tcp", [(2, False), (3, False), (4, False), (3, True), (4, True)])
def test_many_disks_give_the_same_bits_on_every_rank_count(
    scene: Path, one_rank: Path, tmp_path: Path, ranks: int, tcp: bool
) -> None:
    """24 settling disks, 97 rows (uneven on 2, 3, 4 ranks): every dataset of the run file,
    particles and fields, equals the 1-rank run's byte for byte, also without shared memory."""
    out = tmp_path / "run"
    launch(scene, ranks, out, tcp=tcp)
    want, got = datasets(one_rank / "box.h5"), datasets(out / "box.h5")
    assert want.keys() == got.keys()
    differ = [name for name in want if want[name] != got[name]]
    assert not differ, f"differ on {ranks} ranks: {differ[:5]}"


def test_a_restart_on_another_rank_count_during_migrations_gives_the_same_bits(
    scene: Path, one_rank: Path, tmp_path: Path
) -> None:
    """Half the run on 3 ranks with a checkpoint at the end, then the rest on 4 ranks: the
    particles' series and the last fields equal the uninterrupted 1-rank run's."""
    out = tmp_path / "run"
    launch(scene, 3, out, ["--set", f"run.steps={STEPS // 2}"])
    checkpoint = out / f"box_chk_{STEPS // 2:09d}.h5"
    assert checkpoint.exists()
    launch(scene, 4, out, ["--restart", str(checkpoint)])
    with h5py.File(one_rank / "box.h5", "r") as a, h5py.File(out / "box.h5", "r") as b:
        for name in ("x", "y", "u", "v", "omega", "fx", "fy"):
            assert a["particles"][name][()].tobytes() == b["particles"][name][()].tobytes(), name
        last = sorted(a["fields"])[-1]
        want, got = a["fields"][last], b["fields"][last]
        for name in ("rho", "ux", "uy", "particle", "particles/position", "particles/velocity"):
            assert want[name][()].tobytes() == got[name][()].tobytes(), name


# the suspension scenes' models (docs/suspensions.md): the lubrication films (E13) with a contact
# range of half a spacing, and the fluid started with the pressure that holds up the disks
MODELS = [
    "--set",
    "collision.lubrication=.true.",
    "--set",
    "collision.range=0.5",
    "--set",
    "initial.pressure=hydrostatic",
]


@pytest.fixture(scope="module")
def one_rank_models(scene: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("models") / "run"
    launch(scene, 1, out, MODELS)
    return out


@pytest.mark.parametrize("ranks,tcp", [(3, True), (4, False)])
def test_the_suspension_models_give_the_same_bits_on_every_rank_count(
    scene: Path, one_rank: Path, one_rank_models: Path, tmp_path: Path, ranks: int, tcp: bool
) -> None:
    """With lubrication, a contact range of half a spacing and the hydrostatic start, every
    dataset equals the 1-rank run's byte for byte, and that run is not the one without them."""
    out = tmp_path / "run"
    launch(scene, ranks, out, MODELS, tcp=tcp)
    want, got = datasets(one_rank_models / "box.h5"), datasets(out / "box.h5")
    assert want.keys() == got.keys()
    differ = [name for name in want if want[name] != got[name]]
    assert not differ, f"differ on {ranks} ranks: {differ[:5]}"
    plain = datasets(one_rank / "box.h5")
    first = min(name for name in want if name.endswith("/rho"))
    assert plain[first] != want[first], "the models changed nothing"


MESSAGES = re.compile(
    r"particle messages per step: ([0-9.]+) messages to neighbouring slabs, "
    r"([0-9.]+) collectives"
)


@pytest.mark.parametrize("ranks", [1, 3])
def test_particle_messages_per_step_do_not_grow_with_the_number_of_disks(
    tmp_path: Path, ranks: int
) -> None:
    """The same box with 2 and with 36 disks: the MPI calls the particles make per step are the
    same, 4 messages to neighbouring slabs (one each way for the states and one each way for
    the force sums) and 1 collective, a reduction of ten numbers that holds the place and speed
    guards and the centres of the pair both scenes name; no call per particle, as there once
    was, and no reduction per guard."""
    seen = []
    for columns, rows in ((2, [1.1]), (6, [1.1, 0.97, 0.84, 0.71, 0.58, 0.45])):
        n = columns * len(rows)
        scene = box_scene(tmp_path / f"box{n}.nml", columns, rows)
        log = launch(
            scene,
            ranks,
            tmp_path / f"run{n}",
            [
                "--set",
                "run.steps=40",
                "--set",
                "run.checkpoint_every=0",
                "--set",
                "diagnostics.pair=.true.",
            ],
        )
        found = MESSAGES.search(log)
        assert found, log
        seen.append((float(found[1]), float(found[2])))
    assert seen[0] == seen[1] == (4.0, 1.0), seen


@pytest.mark.parametrize("ranks", [1, 3])
def test_a_window_adds_one_reduction_per_step(tmp_path: Path, ranks: int) -> None:
    """case1 follows its pair with a window: to the 4 neighbour messages and the one reduction of
    the guards and the pair, the window adds one reduction, the lowest free centre that decides
    its shift (the place checks are made on the shifted lattice, so the two cannot be one)."""
    log = launch(
        ROOT / "input" / "case1.nml",
        ranks,
        tmp_path / "run",
        [
            "--set",
            "lbm.cells_per_diameter=8",
            "--set",
            "run.steps=60",
            "--set",
            "run.checkpoint_every=0",
        ],
    )
    found = MESSAGES.search(log)
    assert found, log
    assert (float(found[1]), float(found[2])) == (4.0, 2.0), found[0]


def test_a_suspension_follows_no_pair_unless_it_names_one(tmp_path: Path) -> None:
    """Twelve disks and no &pair: no pair diagnostics (no DKT pattern in the log, no
    /diagnostics group, no CSV file); with diagnostics.pair = .true. particles 1 and 2 are
    followed as a pair; diagnostics.pair with one particle is refused, naming the key."""
    scene = box_scene(tmp_path / "susp.nml", 6, [1.1, 0.9])
    steps = ["--set", "run.steps=20", "--set", "run.checkpoint_every=0"]
    log = launch(scene, 2, tmp_path / "plain", steps)
    assert "DKT pattern" not in log and "pair diagnostics" not in log
    with h5py.File(tmp_path / "plain" / "susp.h5", "r") as h5:
        assert "diagnostics" not in h5 and h5["particles/x"].shape[1] == 12
    assert not (tmp_path / "plain" / "susp_diagnostics.csv").exists()
    log = launch(scene, 2, tmp_path / "pair", [*steps, "--set", "diagnostics.pair=.true."])
    assert "pair diagnostics: particles 1 and 2" in log and "DKT pattern" in log
    with h5py.File(tmp_path / "pair" / "susp.h5", "r") as h5:
        assert "diagnostics" in h5
    single = box_scene(tmp_path / "one.nml", 1, [1.1])
    one = subprocess.run(
        [str(EXE), str(single), "--set", "diagnostics.pair=.true.", "--check"],
        capture_output=True,
        text=True,
        timeout=60,
        env=mpi_env(),
    )
    assert one.returncode == 2
    assert "diagnostics.pair" in one.stderr and "at least 2 particles" in one.stderr


def test_the_suspension_series_agree_with_the_particle_series(one_rank: Path) -> None:
    """/suspension, written with /particles for a scene of three disks or more: v_mean and
    v_rms are the mean and root mean square of the disks' v, the front is the height below
    which 95 % of the centres lie, the segregation index is 0 for one size, and phi(y) holds
    the disks' whole area (its integral over the box equals N pi r^2 at every sample)."""
    with h5py.File(one_rank / "box.h5", "r") as h5:
        p, s = h5["particles"], h5["suspension"]
        y, v = p["y"][()], p["v"][()]
        assert np.array_equal(s["t"][()], p["t"][()])
        assert np.allclose(s["v_mean"][()], v.mean(axis=1), rtol=1e-12, atol=1e-15)
        assert np.allclose(s["v_rms"][()], np.sqrt((v**2).mean(axis=1)), rtol=1e-12, atol=1e-15)
        rank = int(np.ceil(0.95 * y.shape[1])) - 1
        assert np.array_equal(s["front"][()], np.sort(y, axis=1)[:, rank])
        assert not s["segregation"][()].any()
        bin_ = s.attrs["bin"]
        assert bin_ == pytest.approx(0.1)
        area = s["phi"][()].sum(axis=1) * bin_ * NX * DX
        assert np.allclose(area, y.shape[1] * np.pi * 0.05**2, rtol=1e-9)
        assert s["phi"].shape[1] == int(np.ceil(NY * DX / bin_ - 1e-9))


def test_dkt_suspension_draws_a_suspension_and_refuses_a_pair_in_one_line(
    one_rank: Path, tmp_path: Path
) -> None:
    """dkt-suspension draws the box's run file (a PNG) and prints its summary; a file without
    /suspension (a scene of two disks) gets one line naming what is missing and exit status 2,
    not a traceback."""
    env = dict(os.environ, PYTHONPATH=str(ROOT / "postproc"))
    png = tmp_path / "s.png"
    done = subprocess.run(
        [sys.executable, "-m", "dktlbm.suspension", str(one_rank / "box.h5"), "-o", str(png)],
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
    )
    assert done.returncode == 0, done.stderr
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    told = subprocess.run(
        [sys.executable, "-m", "dktlbm.suspension", str(one_rank / "box.h5"), "--summary"],
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
    )
    assert told.returncode == 0, told.stderr
    assert told.stdout.startswith("24 disks") and "smallest surface gap" in told.stdout
    pair = box_scene(tmp_path / "pair.nml", 2, [1.1])
    launch(pair, 1, tmp_path / "pair", ["--set", "run.steps=10", "--set", "run.checkpoint_every=0"])
    refused = subprocess.run(
        [sys.executable, "-m", "dktlbm.suspension", str(tmp_path / "pair" / "pair.h5")],
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
    )
    assert refused.returncode == 2
    assert "Traceback" not in refused.stderr and "2 particles" in refused.stderr
    assert len(refused.stderr.strip().splitlines()) == 1, refused.stderr


def test_the_segregation_index_of_two_sizes_is_their_mean_heights_apart(tmp_path: Path) -> None:
    """Two sizes (the upper row D = 0.05 cm, the lower 0.1 cm): /suspension/segregation is
    (mean y of the small disks - mean y of the large ones)/H at every sample, H the box's
    height, positive with the small ones above."""
    scene = box_scene(tmp_path / "two.nml", 6, [1.1, 0.9])
    sizes = ", ".join("0.05" if k < 6 else "0.1" for k in range(12))
    scene.write_text(re.sub(r"diameter = 12\*0\.1", f"diameter = {sizes}", scene.read_text()))
    launch(scene, 2, tmp_path / "run", ["--set", "run.steps=20", "--set", "run.checkpoint_every=0"])
    with h5py.File(tmp_path / "run" / "two.h5", "r") as h5:
        y = h5["particles/y"][()]
        small = np.arange(12) < 6
        want = (y[:, small].mean(axis=1) - y[:, ~small].mean(axis=1)) / (NY * DX)
        got = h5["suspension/segregation"][()]
    assert got[0] == pytest.approx(0.2 / (NY * DX), rel=1e-9)
    assert np.allclose(got, want, rtol=1e-9, atol=1e-15)


WORK = re.compile(
    r"work per step: (\d+) cells, (\d+) boundary links, (\d+) interior nodes, (\d+) particles "
    r"held x (\d+) sub-steps, (\d+) bytes to neighbouring slabs"
)


def test_work_per_step_is_each_slabs_own(tmp_path: Path) -> None:
    """The `work per step` line (the figures of the cost model, docs/performance.md) counts a
    slab's own work: on 1 rank the whole lattice, every disk and no bytes to neighbours; on 3
    ranks the largest slab (33 of the 97 rows, the rows split evenly), fewer links, interior
    nodes and disks than the whole, and bytes sent across the slab faces."""
    scene = box_scene(tmp_path / "box.nml", 6, [1.1, 0.97, 0.84, 0.71, 0.58, 0.45])
    seen = {}
    for ranks in (1, 3):
        log = launch(
            scene,
            ranks,
            tmp_path / f"run{ranks}",
            ["--set", "run.steps=20", "--set", "run.checkpoint_every=0",
             "--set", "run.balance_every=0"],
        )
        found = WORK.search(log)
        assert found, log
        seen[ranks] = [int(v) for v in found.groups()]
    cells, links, interior, held, _, sent = seen[1]
    assert (cells, held, sent) == (NX * NY, 36, 0)
    assert links > 0 and interior > 0
    cells3, links3, interior3, held3, _, sent3 = seen[3]
    assert cells3 == NX * -(-NY // 3)
    assert 0 < links3 < links and 0 < interior3 < interior and 0 < held3 < held
    assert sent3 > 0
