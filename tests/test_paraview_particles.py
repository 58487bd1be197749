"""The disks in ParaView, the way a user draws them by hand: input/case1.nml at 8 spacings per
D, fields every 0.1 s, run to step 256 on 2 ranks with a checkpoint there, then resumed to step
512 (5 outputs), and its particle sidecar `case1_particles.xdmf` opened with ParaView's XDMF
reader, one Glyph filter applied once and the time stepped through
(tests/paraview_particles_probe.py, pvpython).

Proves: the particle sidecar offers every output time of the run file; at each time the one
glyph made at the first shows both disks, each at the centre /particles holds for that time
and with its radius, and the disks move from time to time. Fails on a sidecar whose grids ParaView
names per time (the Extract Block of a `particles` block picked at the first time, on
`case1.xdmf`, is empty at every later time), on a glyph that draws the lattice nodes instead
of the disks, on a sidecar that a restart leaves with the cut snapshots or without the new ones,
and on centres of another time. Also: the resumed run's sidecar is byte for byte the one an
uninterrupted run writes; a particle sidecar left by an earlier run stops a new run of the
scene as the other files do, and output.overwrite replaces it. (A run without disks writes none:
tests/test_output_contract.py lists every file of such a run.)

The ParaView tests are skipped when pvpython is missing, unless DKT_REQUIRE_PARAVIEW=1.
"""

from __future__ import annotations

import json
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import h5py
import numpy as np
import pytest

from dkt_run import ROOT, pvpython_or_skip, run

NAME = "case1"
# /particles sampled at every step, so that it holds the state of each output time
SETS = ["lbm.cells_per_diameter=8", "output.field_interval=0.1", "output.series_interval=0"]
HALF, STEPS = 256, 512  # 128 steps per 0.1 s at 8 spacings per D


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """(an uninterrupted run, the same run stopped at HALF and resumed from its checkpoint)."""
    base = tmp_path_factory.mktemp("paraview_particles")
    whole, resumed = base / "whole", base / "resumed"
    run(f"{NAME}.nml", 2, [*SETS, f"run.steps={STEPS}"], whole)
    run(f"{NAME}.nml", 2, [*SETS, f"run.steps={HALF}", f"run.checkpoint_every={HALF}"], resumed)
    checkpoint = resumed / f"{NAME}_chk_{HALF:09d}.h5"
    run(f"{NAME}.nml", 2, [*SETS, f"run.steps={STEPS}"], resumed,
        extra=["--restart", str(checkpoint)])
    return whole, resumed


@pytest.fixture(scope="module")
def seen(runs: tuple[Path, Path]) -> dict:
    """What the probe saw in the resumed run's particle sidecar."""
    pvpython = pvpython_or_skip()
    assert pvpython is not None, "DKT_REQUIRE_PARAVIEW=1 but pvpython is not on PATH"
    out = runs[1]
    proc = subprocess.run(
        [pvpython, str(ROOT / "tests" / "paraview_particles_probe.py"),
         str(out / f"{NAME}_particles.xdmf")],
        capture_output=True, text=True, timeout=300, cwd=out,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_one_glyph_shows_the_disks_at_their_centres_at_every_time(runs, seen) -> None:
    out = runs[1]
    with h5py.File(out / f"{NAME}.h5", "r") as h5:
        times = sorted(float(g.attrs["time"]) for g in h5["fields"].values())
        t = h5["particles/t"][()]
        x, y = h5["particles/x"][()], h5["particles/y"][()]
        radius = [float(h5["run"].attrs[f"diameter_{n}"]) / 2 for n in (1, 2)]
    assert len(times) == STEPS // 128 + 1
    assert seen["times"] == pytest.approx(times, rel=1e-12, abs=1e-15)
    previous = None
    for step in seen["steps"]:
        k = int(np.argmin(np.abs(t - step["time"])))
        assert t[k] == pytest.approx(step["time"], rel=1e-12, abs=1e-15)
        assert step["disks"] == 2, step
        assert step["glyph_points"] > 0 and "centre" in step, step
        # the glyph points are 4-byte reals
        np.testing.assert_allclose(step["centre"], np.c_[x[k], y[k]], rtol=0, atol=1e-5)
        np.testing.assert_allclose(step["radius"], radius, rtol=1e-6)
        if previous is not None:
            assert all(abs(a[1] - b[1]) > 1e-4 for a, b in zip(step["centre"], previous,
                                                                 strict=True)), step["time"]
        previous = step["centre"]


def test_a_resumed_run_writes_the_particle_sidecar_of_an_uninterrupted_one(runs) -> None:
    whole, resumed = runs
    a = (whole / f"{NAME}_particles.xdmf").read_bytes()
    assert a == (resumed / f"{NAME}_particles.xdmf").read_bytes()
    # it names the datasets the main sidecar names for the disks, and only those
    def disk_items(path: Path) -> list[str]:
        return [e.text for e in ET.parse(path).iter("DataItem") if "/particles/" in e.text]
    assert disk_items(whole / f"{NAME}_particles.xdmf") == disk_items(whole / f"{NAME}.xdmf")
    assert len(disk_items(whole / f"{NAME}.xdmf")) == 5 * (STEPS // 128 + 1)


def test_a_particle_sidecar_of_an_earlier_run_stops_a_new_one(tmp_path: Path) -> None:
    """As every file of a run: --check (which refuses what the run would refuse) names it, and
    with output.overwrite the run goes ahead and writes its own."""
    stale = tmp_path / f"{NAME}_particles.xdmf"
    stale.write_text("stale\n")
    proc = run(f"{NAME}.nml", 1, [*SETS, "run.steps=2"], tmp_path, extra=["--check"],
               check=False)
    assert proc.returncode != 0
    assert str(stale) in proc.stderr and "output.overwrite" in proc.stderr, proc.stderr
    assert stale.read_text() == "stale\n"
    run(f"{NAME}.nml", 1, [*SETS, "run.steps=2", "output.overwrite=.true."], tmp_path)
    grids = ET.parse(stale).getroot().find("Domain/Grid")
    assert grids.get("CollectionType") == "Temporal"
    assert len(grids.findall("Grid")) == 2  # step 0 and the final step 2
