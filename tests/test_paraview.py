"""ParaView opens the run file right: the main job (input/case1.nml as shipped, the paper's
500 x 1250 lattice, 2 ranks, cut short to 0.02 s with fields every 0.005 s, i.e. 5 outputs) is
read back through its XDMF sidecar by the real client, pvpython with ParaView's XDMF reader
(tests/paraview_probe.py prints what ParaView sees as JSON).

Proves: the fields lie on a (500, 1250, 1) grid in the X-Y plane (z extent 0, x across the
2 cm channel, y along the window that follows the pair); `velocity` is a 3-component vector
equal to (ux, uy, 0) of the HDF5 file at sampled nodes; the particle grid has the 2 disks at
every output time with radius, velocity (3), omega and id, placed at the /particles state of
that time, and they move between outputs. Fails on a 2-D mesh read in the Y-Z plane, x and y
swapped, velocity as scalars only, a missing particle grid or disks frozen at their start.

Skipped when pvpython is missing, unless DKT_REQUIRE_PARAVIEW=1.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import h5py
import numpy as np
import pytest

from dkt_run import ROOT, pvpython_or_skip, run

PVPYTHON = pvpython_or_skip()

NAME = "case1"
T_END, FIELD_INTERVAL = 0.02, 0.005
NODES = [(0, 0), (249, 300), (250, 700), (499, 1249), (123, 1000)]


@pytest.fixture(scope="module")
def probe(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    assert PVPYTHON is not None, "DKT_REQUIRE_PARAVIEW=1 but pvpython is not on PATH"
    out = tmp_path_factory.mktemp("paraview")
    run(
        f"{NAME}.nml",
        2,
        [f"run.t_end={T_END}", f"output.field_interval={FIELD_INTERVAL}"],
        out,
        timeout=600.0,
    )
    args = [PVPYTHON, str(ROOT / "tests" / "paraview_probe.py"), str(out / f"{NAME}.xdmf")]
    args += [f"{i},{j}" for i, j in NODES]
    proc = subprocess.run(args, capture_output=True, text=True, timeout=300, cwd=out)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return out, json.loads(proc.stdout.strip().splitlines()[-1])


def test_fields_are_a_one_layer_grid_in_the_xy_plane(probe) -> None:
    out, seen = probe
    with h5py.File(out / f"{NAME}.h5", "r") as h5:
        dx = float(h5["run"].attrs["dx"])
        width = float(h5["run"].attrs["width"])
        groups = sorted(h5["fields"])
        offsets = [float(h5["fields"][g].attrs["window_offset"]) for g in groups]
        times = [float(h5["fields"][g].attrs["time"]) for g in groups]
        ny, nx = h5["fields"][groups[0]]["ux"].shape
    assert (nx, ny) == (500, 1250)
    assert len(seen["steps"]) == len(groups) >= 3
    assert seen["times"] == pytest.approx(times, rel=1e-12)
    for step, offset in zip(seen["steps"], offsets, strict=True):
        f = step["fields"]
        assert f["dimensions"] == [500, 1250, 1]
        x0, x1, y0, y1, z0, z1 = f["bounds"]
        assert z0 == z1 == 0.0
        assert 0.0 <= x0 < x1 <= width
        assert x1 - x0 == pytest.approx((nx - 1) * dx, rel=1e-12)
        assert y0 == pytest.approx(offset + dx / 2, rel=1e-12)
        assert y1 - y0 == pytest.approx((ny - 1) * dx, rel=1e-12)


def test_velocity_is_the_vector_ux_uy_0(probe) -> None:
    out, seen = probe
    with h5py.File(out / f"{NAME}.h5", "r") as h5:
        for step, group in zip(seen["steps"], sorted(h5["fields"]), strict=True):
            arrays = step["fields"]["arrays"]
            assert arrays["velocity"] == 3
            assert all(arrays[n] == 1 for n in ("ux", "uy", "vorticity", "rho", "pressure"))
            ux, uy = h5["fields"][group]["ux"][()], h5["fields"][group]["uy"][()]
            moving = 0
            for i, j in NODES:
                got = step["fields"]["velocity"][f"{i},{j}"]
                assert got == [ux[j, i], uy[j, i], 0.0], (group, i, j)
                moving += uy[j, i] != 0.0
            if group != sorted(h5["fields"])[0]:
                assert moving, f"{group}: every sampled node at rest, the check proves little"


def test_particle_grid_follows_the_disks(probe) -> None:
    out, seen = probe
    with h5py.File(out / f"{NAME}.h5", "r") as h5:
        t = h5["particles/t"][()]
        series = {n: h5[f"particles/{n}"][()] for n in ("x", "y", "u", "v", "omega")}
        radius = [float(h5["run"].attrs[f"diameter_{n}"]) / 2 for n in (1, 2)]
    previous = None
    for step in seen["steps"]:
        p = step["particles"]
        assert len(p["points"]) == 2
        assert p["arrays"] == {"velocity": 3, "radius": 1, "omega": 1, "id": 1}
        k = int(np.argmin(np.abs(t - step["time"])))
        assert t[k] == pytest.approx(step["time"], rel=1e-12, abs=1e-15)
        for n in range(2):
            assert p["points"][n] == [series["x"][k, n], series["y"][k, n], 0.0]
            assert p["velocity"][n] == [series["u"][k, n], series["v"][k, n], 0.0]
            assert p["omega"][n] == [series["omega"][k, n]]
            assert p["radius"][n][0] == pytest.approx(radius[n], rel=1e-12)
        if previous is not None:
            assert all(a[1] != b[1] for a, b in zip(p["points"], previous, strict=True))
        previous = p["points"]
