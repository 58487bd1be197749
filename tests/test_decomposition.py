"""The same scene on 1, 2 and 3 ranks writes bitwise-identical fields (docs/design.md,
"Data layout").

Each case exercises a different set of boundary rules across the slab faces: open ends (E5)
with side walls, periodic ends with a body force, periodic sides with wall ends (the corner
ghosts), closed box, and a fully periodic Taylor–Green vortex.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from dkt_run import run

CASES = {
    "open_ends": ("inlet_channel.nml", ["run.steps=120", "inlet.ramp_time=0.2"]),
    "periodic_ends_force": ("poiseuille.nml", ["run.steps=120"]),
    "periodic_sides_wall_ends": (
        "poiseuille.nml",
        [
            "run.steps=120",
            "domain.sides=periodic",
            "domain.lower=wall",
            "domain.upper=wall",
            "fluid.body_force(1)=1.0e-4",
            "fluid.body_force(2)=0.0",
        ],
    ),
    "closed_box": (
        "poiseuille.nml",
        ["run.steps=120", "domain.lower=wall", "domain.upper=wall", "fluid.body_force(1)=2e-4"],
    ),
    "taylor_green": ("taylor_green.nml", ["run.steps=60"]),
}


def all_fields(h5file: Path) -> dict[str, np.ndarray]:
    out = {}
    with h5py.File(h5file, "r") as h5:
        for step in h5["fields"]:
            for name, ds in h5["fields"][step].items():
                out[f"{step}/{name}"] = ds[()]
    return out


@pytest.mark.parametrize("case", sorted(CASES))
def test_fields_are_bitwise_identical_on_1_2_and_3_ranks(tmp_path: Path, case: str) -> None:
    nml, sets = CASES[case]
    name = Path(nml).stem
    results = {}
    for ranks in (1, 2, 3):
        out = tmp_path / f"r{ranks}"
        # fields at several times, so every step's halo exchange is compared, not only the end
        run(nml, ranks, sets + ["output.field_interval=1e-9"], out)
        results[ranks] = all_fields(out / f"{name}.h5")
    ref = results[1]
    assert len(ref) >= 5 * 2
    for ranks in (2, 3):
        assert results[ranks].keys() == ref.keys()
        for key, arr in ref.items():
            other = results[ranks][key]
            assert np.array_equal(arr, other), (
                f"{case}: {key} differs on {ranks} ranks, max |diff| "
                f"{np.max(np.abs(arr - other)):.3e}"
            )
    # the run did something: the flow is not still at rest
    last = sorted(k for k in ref if k.endswith("/uy") or k.endswith("/ux"))
    assert max(np.max(np.abs(ref[k])) for k in last) > 0.0
