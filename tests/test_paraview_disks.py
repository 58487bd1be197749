"""ParaView shows ten thousand disks with their radius: the 10 032-disk box of
tools/suspension_scene.py (`--kind sediment10k`, at 8 spacings per D: 512 x 3072), every third
disk widened from D = 0.0625 to 0.064 cm so that the radii differ, 2 ranks, one step with a
snapshot before and after it, is read back through its particle sidecar by pvpython with
ParaView's XDMF reader and drawn with a Glyph filter scaled by the `radius` array
(tests/paraview_disks_probe.py).

Proves: the particle grid of the last snapshot has every disk once, at its /particles centre of
that time, with its own radius; the glyph drawn from `radius` for each disk has that disk's
radius and centre. Fails on a particle grid that holds only one slab's disks or a disk twice, on
centres of another time, on a radius array of diameters or of one value, and on glyphs that do
not scale.

Skipped when pvpython is missing, unless DKT_REQUIRE_PARAVIEW=1.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from dkt_run import ROOT, pvpython_or_skip, run

PVPYTHON = pvpython_or_skip()
N = 10032  # the disks of tools/suspension_scene.py --kind sediment10k


def diameter(k: int) -> float:
    """Disk k's diameter (cm) in the test's scene."""
    return 0.064 if k % 3 == 0 else 0.0625


@pytest.fixture(scope="module")
def probe(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    assert PVPYTHON is not None, "DKT_REQUIRE_PARAVIEW=1 but pvpython is not on PATH"
    out = tmp_path_factory.mktemp("paraview_disks")
    scene = out / "sediment10k.nml"
    subprocess.run(
        [sys.executable, str(ROOT / "tools" / "suspension_scene.py"), "--kind", "sediment10k",
         "--out", str(scene)],
        check=True, capture_output=True, text=True,
    )
    # every third disk wider: the gaps of the arrangement (0.4 D) stay wider than the contact
    # range of 3 spacings
    text = scene.read_text()
    diameters = ", ".join(f"{diameter(k)!r}" for k in range(1, N + 1))
    assert f"diameter = {N}*0.0625" in text
    scene.write_text(text.replace(f"diameter = {N}*0.0625", f"diameter = {diameters}"))
    run(scene, 2, ["lbm.cells_per_diameter=8", "run.steps=1", "output.field_interval=1e-9"],
        out, timeout=600.0)
    proc = subprocess.run([PVPYTHON, str(ROOT / "tests" / "paraview_disks_probe.py"),
                           str(out / "sediment10k_particles.xdmf")],
                          capture_output=True, text=True, timeout=600, cwd=out)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return out, json.loads(proc.stdout.strip().splitlines()[-1])


def last_state(out: Path, time: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centres (x, y) at `time` from /particles and each disk's radius as the scene sets it."""
    with h5py.File(out / "sediment10k.h5", "r") as h5:
        t = h5["particles/t"][()]
        k = int(np.argmin(np.abs(t - time)))
        assert t[k] == pytest.approx(time, rel=1e-12, abs=1e-15)
        x, y = h5["particles/x"][k], h5["particles/y"][k]
    return x, y, np.array([diameter(k) / 2 for k in range(1, N + 1)])


def test_every_disk_once_at_its_centre_with_its_radius(probe) -> None:
    out, seen = probe
    x, y, r = last_state(out, seen["time"])
    assert x.size == N
    points = np.array(seen["points"])
    assert points.shape == (x.size, 2)
    # the snapshot is after the move: not the start of the run
    assert seen["time"] > 0
    np.testing.assert_array_equal(points[:, 0], x)
    np.testing.assert_array_equal(points[:, 1], y)
    np.testing.assert_allclose(seen["radius"], r, rtol=1e-12)


def test_glyphs_scaled_by_radius_have_the_disks_size(probe) -> None:
    out, seen = probe
    x, y, r = last_state(out, seen["time"])
    glyphs = seen["glyphs"]
    assert glyphs["points"] > 0 and glyphs["points"] % N == 0
    # each disk's sphere has the disk's radius (the glyph points are 4-byte reals) and sits
    # at its centre
    np.testing.assert_allclose(glyphs["radius"], r, rtol=1e-6)
    centre = np.array(glyphs["centre"])
    np.testing.assert_allclose(centre[:, 0], x, rtol=0, atol=1e-5)
    np.testing.assert_allclose(centre[:, 1], y, rtol=0, atol=1e-5)
