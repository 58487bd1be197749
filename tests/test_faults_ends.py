"""A disk meets each end of the channel as documented (docs/model.md §4, E11 and "Open and
moving ends"; input/README.md).

- An end at rest (a 'velocity' end with &inlet velocity = 0, below or above, the other end an
  outflow) is a wall for the contact law: a disk dropped onto it (or rising to it) comes to rest
  with its surface less than half the contact range from the end (E11 acts on the mirror disk,
  at twice the gap), the run finishes, and 1 and 2 ranks give the same bits.
- An open end (outflow) or a moving one (a velocity end with fluid leaving through it) holds
  nothing back: the run stops at the first step at which the disk's surface is within the
  contact range (at least one spacing) of the end, before the flow through the end blows up,
  with stop_reason 'particle: ...', exit status 3 and one message naming the particle and the
  end; the series are complete up to that step.

The scenes are input/single.nml (a disk of D = 0.25 cm, rho_p = 1.25) in a 2 x 1 cm box at 10
spacings per diameter with the contact range of the DKT scenes (2 spacings): a few hundred
steps each. The expected numbers come from the scene's own keys, not from an earlier run.
"""

from __future__ import annotations

import re
from pathlib import Path

import h5py
import numpy as np
import pytest

from dkt_run import run
from dktlbm.read import text_attr

DX = 0.025  # cm
RADIUS = 0.125  # cm, input/single.nml's diameter 0.25
HEIGHT = 1.0  # cm
RANGE = 2.0  # collision.range, spacings
EXIT_PARTICLE = 3  # input/README.md: a particle out of place stops the run with exit status 3
BOX = [
    f"domain.height={HEIGHT}",
    f"lbm.dx={DX}",
    f"collision.range={RANGE}",
    "inlet.profile=uniform",
    "run.t_end=1.0",
    "run.progress_every=0",
]
# which end the disk reaches, the ends, the disk's density and start
AT_REST = {
    "lower-velocity-end-at-rest": (
        "lower",
        ["domain.lower=velocity", "domain.upper=outflow", "inlet.velocity=0"],
        ["particles.density=1.25", "particles.y=0.45"],
    ),
    "upper-velocity-end-at-rest": (
        "upper",
        ["domain.lower=outflow", "domain.upper=velocity", "inlet.velocity=0"],
        ["particles.density=0.8", "particles.y=0.55"],
    ),
}
OPEN = {
    "outflow": (["domain.lower=outflow", "domain.upper=wall"], "an open end"),
    "moving-velocity-end": (
        ["domain.lower=velocity", "domain.upper=outflow", "inlet.velocity=-0.5"],
        "a moving end",
    ),
}
STOP_RE = re.compile(
    r"dktlbm: error: .*particle 1 \(motion = 'free'\): its surface came within "
    r".* of the lower end .* step (\d+) \(t ="
)


def particles(h5file: Path) -> tuple[dict[str, np.ndarray], str, float]:
    """The /particles series, the stop_reason and dt of a run file (opening it proves it was
    closed cleanly)."""
    with h5py.File(h5file, "r") as h5:
        series = {name: h5["particles"][name][()] for name in h5["particles"]}
        return series, text_attr(h5["run"].attrs["stop_reason"]), float(h5["run"].attrs["dt"])


@pytest.mark.parametrize(("end", "ends", "disk"), AT_REST.values(), ids=AT_REST)
def test_a_disk_comes_to_rest_on_an_end_at_rest_with_the_same_bits_on_1_and_2_ranks(
    tmp_path: Path, end: str, ends: list[str], disk: list[str]
) -> None:
    """Catches: E11 applied only when both ends are walls (the disk sinks through the end and
    the Mach guard or the place check stops the run), a mirror across the wrong end, a wall
    force that depends on the slab split."""
    got = {}
    for ranks in (1, 2):
        out = tmp_path / f"n{ranks}"
        run("single.nml", ranks, BOX + ends + disk, out, timeout=120)
        got[ranks], reason, _ = particles(out / "single.h5")
        assert reason == "finished", reason
    for name in got[1]:
        assert got[1][name].tobytes() == got[2][name].tobytes(), f"/particles/{name} differs"
    s = got[1]
    y, v = s["y"][:, 0], s["v"][:, 0]
    gap = y - RADIUS if end == "lower" else HEIGHT - y - RADIUS
    # E11 acts while the mirror disk, at twice the gap, is within the range: at rest the gap
    # lies between 0 (contact) and half the range
    assert 0.0 < gap[-1] < 0.5 * RANGE * DX, f"gap {gap[-1]} cm to the {end} end"
    assert gap.min() > 0.0, f"the disk passed the {end} end: gap {gap.min()} cm"
    # at rest: the speed a small fraction of the largest on the way, the position steady over
    # the last tenth of the run
    assert abs(v[-1]) < 1e-3 * np.abs(v).max(), (v[-1], np.abs(v).max())
    tail = y[int(0.9 * len(y)) :]
    assert np.ptp(tail) < 0.01 * DX, f"still moving: {np.ptp(tail)} cm over the last tenth"


@pytest.mark.parametrize(("ends", "kind"), OPEN.values(), ids=OPEN)
def test_a_disk_reaching_an_open_or_moving_end_stops_the_run_with_its_series_complete(
    tmp_path: Path, ends: list[str], kind: str
) -> None:
    """Catches: a disk let through an open end until the Mach guard stops the run (stop_reason
    'guard: ...'), a stop before the disk is near the end or after it passed, a series cut short
    of the stop step or not closed."""
    out = tmp_path / "out"
    proc = run("single.nml", 2, BOX + ends + ["particles.y=0.45"], out, timeout=120, check=False)
    assert proc.returncode == EXIT_PARTICLE, (proc.returncode, proc.stderr)
    errors = [ln for ln in proc.stderr.splitlines() if ln.startswith("dktlbm: error")]
    assert len(errors) == 1, proc.stderr
    assert kind in errors[0], errors[0]
    m = STOP_RE.search(errors[0])
    assert m, errors[0]
    step = int(m.group(1))
    s, reason, dt = particles(out / "single.h5")
    assert reason.startswith("particle: "), reason
    t, y = s["t"], s["y"][:, 0]
    assert np.all(np.diff(t) > 0) and np.all(np.isfinite(y)), "series damaged"
    assert t[-1] == pytest.approx(step * dt, rel=1e-12), (t[-1], step * dt)
    # the first step with the surface within the range (at least one spacing) is the last one
    near = max(RANGE, 1.0) * DX
    gap = y - RADIUS
    assert 0.0 < gap[-1] < near, f"stopped with the gap {gap[-1]} cm"
    assert np.all(gap[:-1] >= near), "the run went on after the disk came near the end"
