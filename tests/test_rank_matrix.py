"""Rank invariance over a matrix of splits: every run is bitwise the run on one rank.

Each case is a short run of a small scene, chosen so that together the cases cover
- the moving window on and off;
- row counts that split evenly, unevenly and that are prime, and odd and even nx;
- 1, 2, 3 and 4 ranks (oversubscribed on a 2-core machine);
- particles whose centres cross a slab face while the window shifts, and in a box;
- open ends (velocity and outflow, E5), closed ends (walls) and periodic ends;
- populations stored in 8 bytes (the default) and in 4 (lbm.precision = 'single'), and
  stored and collided in 4 (lbm.precision = 'single_arith', with 4-byte row buffers), and
  stored in 16-bit codes and collided in 4 (lbm.precision = 'half', HALF_CASES);
- in-place streaming (the default) against two lattices (lbm.streaming = 'two_lattice');
- interior nodes solid (the default) and fluid (coupling.interior = 'fluid').

For every case and every rank count, every dataset under /particles, /diagnostics and /fields
(fields written several times during the run) must be bitwise equal to the 1-rank run, and the
pattern attributes of /diagnostics must agree; and the run with two lattices must be bitwise the
in-place run, on 1 rank and on 4 (where slabs are thinnest, and a slab of fewer than 6 rows is
swept whole after the halo exchange instead of in three parts around it). Each case also
asserts the property it was chosen for (the split is uneven, ny is prime, the window shifted, a
centre crossed a face on that rank count, a slab is thin), so that a change of defaults cannot
quietly turn it into a friendly case.

This test fails on the code before the uneven-split fix (commit f7a9e9b): there the padded x
extent of a slab depended on its row count, and the window shift sent a row of the sender's
padded length, so every window case whose rows do not split evenly differed (gamma = 1.3 on
2 ranks by 2.6 cm/s), and some corrupted the heap.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from dkt_run import run

RANKS = (1, 2, 3, 4)

# Window scenes: case1 at 6 spacings across the smaller disk (D_1 = 12 spacings, 120 x ~300
# cells). The window keeps the lowest centre between below - 1 and below spacings above the
# lower end; window.below puts a slab face of the rank counts named in `crosses` half a
# spacing inside that band, so the centre crosses the face and back with every shift.
WINDOW = ["lbm.cells_per_diameter=6", "run.steps=300", "output.field_interval=0.07"]
CASES: dict[str, dict] = {
    # 300 rows split evenly on 1-4 ranks, 121 columns; the 2- and 4-rank faces in the band
    "window_even_rows_odd_nx": {
        "nml": "case1.nml",
        "sets": WINDOW
        + ["window.below=12.5416667", "window.above=12.4583333", "domain.width=2.0166667"],
        "rows": "even",
        "nx": "odd",
        "window": True,
        "crosses": (2, 4),
    },
    # 307 rows (prime) and 121 columns (odd)
    "window_prime_rows_odd_nx": {
        "nml": "case1.nml",
        "sets": WINDOW
        + ["window.below=12.875", "window.above=12.7083333", "domain.width=2.0166667"],
        "rows": "prime",
        "nx": "odd",
        "window": True,
        "crosses": (2,),
    },
    # 289 rows: 145/144, 97/96/96, 73/72/72/72
    "window_uneven_rows_3": {
        "nml": "case1.nml",
        "sets": WINDOW + ["window.below=8.125", "window.above=15.9583333"],
        "rows": "uneven",
        "window": True,
        "crosses": (3,),
    },
    # gamma = 1.5 (D_1 = 9 spacings), 218 rows: 109/109, 73/73/72, 55/55/54/54
    "window_uneven_rows_4": {
        "nml": "case1.nml",
        "sets": WINDOW + ["window.below=6.1666667", "window.above=18.0555556", "pair.gamma=1.5"],
        "rows": "uneven",
        "window": True,
        "crosses": (4,),
    },
    # Open ends without the window, 317 rows: dense disks fall across the faces near y = 4 cm
    "open_box_crossing": {
        "nml": "case0_box.nml",
        "sets": [
            "lbm.cells_per_diameter=8",
            "domain.height=7.925",
            "pair.y_upper=4.06",
            "pair.dh=1.5",
            "pair.density=1.05",
            "lbm.tau=0.55",
            "run.steps=200",
            "output.field_interval=0.015",
        ],
        "rows": "prime",
        "window": False,
        "crosses": (2, 4),
    },
    # Closed ends (walls), 242 rows (81/81/80 and 61/61/60/60), a disk across the 3-rank face
    "closed_box_crossing": {
        "nml": "case0_box.nml",
        "sets": [
            "lbm.cells_per_diameter=8",
            "domain.lower=wall",
            "domain.upper=wall",
            "domain.height=6.05",
            "domain.width=2.025",
            "pair.y_upper=2.07",
            "pair.dh=1.5",
            "pair.density=1.05",
            "lbm.tau=0.55",
            "run.steps=200",
            "output.field_interval=0.015",
        ],
        "rows": "uneven",
        "nx": "odd",
        "window": False,
        "crosses": (3,),
    },
    # Periodic ends with a body force (flow only: particles are refused in a periodic channel);
    # 23 rows, a slab of 5 on 4 ranks (swept whole in place after the halo exchange)
    "periodic_ends_prime_rows": {
        "nml": "poiseuille.nml",
        "sets": [
            "domain.width=1.05",
            "domain.height=1.15",
            "run.steps=150",
            "output.field_interval=1e-9",
        ],
        "rows": "prime",
        "nx": "odd",
        "window": False,
        "crosses": (),
        "thin_on": 4,
    },
    # The reported repro at the paper's resolution: gamma = 1.3, a 325 x 813 window
    "repro_gamma_1_3": {
        "nml": "case1.nml",
        "sets": ["pair.gamma=1.3", "run.steps=300", "output.field_interval=0.01"],
        "rows": "uneven",
        "nx": "odd",
        "window": True,
        "crosses": (),
    },
}

# lbm.precision = 'single' (4-byte populations holding f_i - w_i): the same cases, a window
# with uneven rows and a closed box with a disk across a slab face. Every path that moves
# stored values between slabs (halo rows, the window's row shift) or reads them point-wise
# (bounce-back, E5, refill) has its own 4-byte branch, which these cases put on 1-4 ranks.
for _case in ("window_uneven_rows_3", "closed_box_crossing"):
    CASES[f"{_case}_single"] = {
        **CASES[_case],
        "sets": CASES[_case]["sets"] + ["lbm.precision=single"],
        "double_twin": _case,
    }

# lbm.precision = 'single_arith' (stored as 'single', collided in 4 bytes with 4-byte row
# buffers, src/dkt_mrt_sp.f90): the same two cases. The sweep's parts around the halo exchange
# hand 4-byte rows to each other (kept_dn4, kept_up_s); a part that took the wrong row would
# differ between rank counts. "double_twin" asserts the 4-byte run really differs from the
# 8-byte one, "single_twin" that it differs from the 8-byte arithmetic on the same storage.
for _case in ("window_uneven_rows_3", "closed_box_crossing"):
    CASES[f"{_case}_single_arith"] = {
        **CASES[_case],
        "sets": CASES[_case]["sets"] + ["lbm.precision=single_arith"],
        "double_twin": _case,
        "single_twin": f"{_case}_single",
    }

# lbm.precision = 'half' (16-bit codes, halo rows as 2-byte integers, collided in 4 bytes from
# decoded rows, src/dkt_mrt_half.f90): the same two cases. Kept apart from CASES, which
# tools/compare_builds.py runs on a reference build that may predate 'half'; the tests here
# run both. "single_twin" asserts the 16-bit run differs from 'single_arith', so the codes
# really round.
HALF_CASES = {
    f"{_case}_half": {
        **CASES[_case],
        "sets": CASES[_case]["sets"] + ["lbm.precision=half"],
        "double_twin": _case,
        "single_twin": f"{_case}_single_arith",
    }
    for _case in ("window_uneven_rows_3", "closed_box_crossing")
}

# coupling.interior = 'fluid': the interior nodes are fluid, bounced from both sides of the
# surface, and an interior link whose outer node lies in a halo row takes that node's density
# from its owner. The closed box (a disk across the 3-rank face, uneven rows) and a window case
# (interior fluid carried along by the row shifts, a centre across the 3-rank face).
for _case in ("closed_box_crossing", "window_uneven_rows_3"):
    CASES[f"{_case}_fluid"] = {
        **CASES[_case],
        "sets": CASES[_case]["sets"] + ["coupling.interior=fluid"],
    }


ALL_CASES = {**CASES, **HALF_CASES}


def rows_for(ny: int, n: int) -> list[int]:
    """Rows of each rank, as the program splits them (lower ranks take the extra rows)."""
    return [ny // n + (1 if r < ny % n else 0) for r in range(n)]


def faces(ny: int, n: int) -> np.ndarray:
    """The global row index (1-based) of the top row of every slab but the last."""
    return np.cumsum(rows_for(ny, n))[:-1]


def is_prime(n: int) -> bool:
    return n > 1 and all(n % k for k in range(2, int(n**0.5) + 1))


def datasets(h5file: Path) -> tuple[dict[str, np.ndarray], dict[str, object], dict]:
    """Every dataset outside /run, the /diagnostics attributes, and the /run attributes."""
    out: dict[str, np.ndarray] = {}
    with h5py.File(h5file, "r") as h5:

        def visit(name: str, obj: object) -> None:
            if isinstance(obj, h5py.Dataset) and not name.startswith("run"):
                out[name] = obj[()]

        h5.visititems(visit)
        diag = dict(h5["diagnostics"].attrs) if "diagnostics" in h5 else {}
        runattrs = {k: v for k, v in h5["run"].attrs.items() if k != "namelist"}
    return out, diag, runattrs


class Runs:
    """The runs of the matrix, each made once when a test first asks for it (a deselected test
    costs no run): (datasets, diagnostics attrs, run attrs), or the failed run's exit status
    and output as a string."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.done: dict[tuple[str, int], tuple | str] = {}

    def get(self, case: str, ranks: int, streaming: str = "in_place") -> tuple:
        key = (case, ranks, streaming)
        if key not in self.done:
            spec = ALL_CASES[case]
            d = self.root / f"{case}_r{ranks}_{streaming}"
            sets = spec["sets"] + ["output.series_interval=1e-9", f"lbm.streaming={streaming}"]
            proc = run(spec["nml"], ranks, sets, d, check=False)
            if proc.returncode != 0:
                self.done[key] = f"exit {proc.returncode}:\n{proc.stdout[-2000:]}{proc.stderr}"
            else:
                self.done[key] = datasets(d / f"{Path(spec['nml']).stem}.h5")
        got = self.done[key]
        assert not isinstance(got, str), f"{case} ({streaming}) on {ranks} ranks failed: {got}"
        return got


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> Runs:
    return Runs(tmp_path_factory.mktemp("matrix"))


@pytest.mark.parametrize("case", sorted(ALL_CASES))
def test_case_hits_the_split_it_claims(runs: Runs, case: str) -> None:
    spec = ALL_CASES[case]
    data, _, runattrs = runs.get(case, 1)
    nx, ny = int(runattrs["nx"]), int(runattrs["ny"])
    uneven = [n for n in RANKS[1:] if ny % n]
    if spec["rows"] == "even":
        assert not uneven, f"{case}: ny = {ny} should split evenly on {RANKS}"
    elif spec["rows"] == "prime":
        assert is_prime(ny), f"{case}: ny = {ny} is not prime"
    else:
        assert uneven, f"{case}: ny = {ny} splits evenly on every rank count"
    if "nx" in spec:
        assert (nx % 2 == 1) == (spec["nx"] == "odd"), f"{case}: nx = {nx}"
    if "thin_on" in spec:
        slabs = rows_for(ny, spec["thin_on"])
        assert min(slabs) < 6, f"{case}: no slab thinner than 6 rows ({slabs})"
    if "particles/window_offset" in data:
        offset = data["particles/window_offset"]
        assert (offset[-1] != offset[0]) == spec["window"], f"{case}: window shifts {offset}"
    else:
        assert not spec["window"]
    # a 4-byte case really stored 4 bytes: its fields are not its 8-byte twin's bits
    if "double_twin" in spec:
        twin, _, _ = runs.get(spec["double_twin"], 1)
        last = sorted(k for k in data if k.startswith("fields/") and k.endswith("/ux"))[-1]
        assert data[last].tobytes() != twin[last].tobytes(), f"{case}: {last} is the 8-byte run's"
    if "single_twin" in spec:
        twin, _, _ = runs.get(spec["single_twin"], 1)
        last = sorted(k for k in data if k.startswith("fields/") and k.endswith("/ux"))[-1]
        assert data[last].tobytes() != twin[last].tobytes(), f"{case}: {last} is 'single''s"
    # a centre crossed a slab face: its row (1-based, in the window) was on both sides of it
    for n in spec["crosses"]:
        dx = float(runattrs["dx"])
        y = data["particles/y"]
        origin = data["particles/window_offset"][:, None] if spec["window"] else 0.0
        row = (y - origin) / dx + 0.5  # centre in cell units, row j covers [j - 1/2, j + 1/2)
        crossed = [
            face
            for face in faces(ny, n)
            for k in range(y.shape[1])
            if (row[:, k] < face + 0.5).any() and (row[:, k] > face + 0.5).any()
        ]
        assert crossed, f"{case}: no centre crossed a slab face on {n} ranks (faces {faces(ny, n)})"


def assert_same_bits(ref: tuple, other: tuple, what: str) -> None:
    ref_data, ref_diag, _ = ref
    data, diag, _ = other
    assert data.keys() == ref_data.keys(), f"{what}: the datasets differ"
    bad = []
    for key, arr in ref_data.items():
        # bytes, not values: NaN (C_d of a disk at rest) must match NaN, and -0.0 only -0.0
        if arr.dtype != data[key].dtype or arr.tobytes() != data[key].tobytes():
            diff = np.nanmax(np.abs(arr.astype(float) - data[key].astype(float)))
            bad.append(f"{key} (max |diff| {diff:.3e})")
    assert not bad, f"{what}: " + ", ".join(bad)
    assert {k: str(v) for k, v in diag.items()} == {k: str(v) for k, v in ref_diag.items()}


@pytest.mark.parametrize("ranks", (1, 4))
@pytest.mark.parametrize("case", sorted(ALL_CASES))
def test_two_lattices_give_the_in_place_bits(runs: Runs, case: str, ranks: int) -> None:
    fields = [k for k in runs.get(case, ranks)[0] if k.startswith("fields/")]
    assert len(fields) >= 2 * 5, f"{case}: too few field snapshots to compare the run's course"
    assert_same_bits(
        runs.get(case, ranks),
        runs.get(case, ranks, "two_lattice"),
        f"{case} on {ranks} ranks: two lattices against in place",
    )


@pytest.mark.parametrize("ranks", RANKS[1:])
@pytest.mark.parametrize("case", sorted(ALL_CASES))
def test_every_dataset_is_bitwise_the_1_rank_run(runs: Runs, case: str, ranks: int) -> None:
    ref = runs.get(case, 1)
    fields = [k for k in ref[0] if k.startswith("fields/")]
    assert len(fields) >= 2 * 5, f"{case}: too few field snapshots to compare the run's course"
    assert_same_bits(ref, runs.get(case, ranks), f"{case}: differs on {ranks} ranks from 1 rank")
