"""The Mach-aware set-up (docs/model.md §1, "Mach-aware set-up"; input/README.md, &lbm mach).

lbm.mach > 0 sets tau from the target Mach number, the spacing and the scene's velocity scale
(acoustic scaling): u_lb = U dt/dx = Ma c_s stays fixed as dx changes, so dt is proportional to
dx and tau - 1/2 to 1/dx. The start-up report (also printed by --check) gives every scene its
Ma^2 and compressibility error class. Every expected number here is computed from the scene's
keys and the formulas of docs/model.md, not copied from a run; each run is a --check on one
rank (no time-stepping), a second or less.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from dkt_run import INPUT, number_after, run_args

CS = math.sqrt(1.0 / 3.0)  # lattice speed of sound, c = 1
# input/case1.nml: water, the larger disk D_1 = 0.2 cm of density 1.01 g/cm^3 under g = 980
NU, D1, RHO_P, G = 0.01, 0.2, 1.01, 980.0
# its velocity scale (docs/model.md §1): the settling speed scale of the larger, free disk
U_SCALE = math.sqrt(0.5 * math.pi * D1 * (RHO_P - 1.0) * G)
WIDTH, D2 = 2.0, 0.1  # cm: channel width and the smaller disk, which sets dx
# docs/model.md §1: the upper ends of the negligible, small and noticeable classes in Ma^2
CLASSES = [(1e-3, "negligible"), (1e-2, "small"), (5e-2, "noticeable"), (math.inf, "large")]


def check(tmp_path: Path, scene: str, *sets: str) -> str:
    """The report of `dktlbm input/<scene> --check --set ...` (exit 0 asserted)."""
    args = [str(INPUT / scene), "--check", "--set", f"output.dir={tmp_path / 'out'}"]
    for s in sets:
        args += ["--set", s]
    proc = run_args(args, 1, 30.0, tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc.stdout


def expected_class(mach: float) -> str:
    return next(name for top, name in CLASSES if mach**2 < top)


@pytest.mark.parametrize("mach", [0.03, 0.0608])
def test_a_mach_target_sets_tau_by_acoustic_scaling_at_two_spacings(
    tmp_path: Path, mach: float
) -> None:
    """case1 at 12 and 16 spacings across the smaller disk with lbm.mach set (lbm.tau = 0.65 of
    the file is not used): the report's expected Mach number is the target, tau is
    1/2 + 3 Ma c_s nu/(U dx), dt/dx is the same at both spacings (acoustic scaling: Ma c_s/U)
    and the class line names the target's class and the Mach source. Fails if tau still came
    from lbm.tau (Mach 0.127 / 0.095), if the velocity scale of the conversion differed from the
    report's, or if dt kept diffusive scaling (dt/dx halving when dx halves)."""
    ratios = []
    for n in (12, 16):
        out = check(tmp_path, "case1.nml", f"lbm.cells_per_diameter={n}", f"lbm.mach={mach}")
        dx = WIDTH / round(WIDTH * n / D2)
        tau = 0.5 + 3.0 * mach * CS * NU / (U_SCALE * dx)
        assert number_after("dx =", out) == pytest.approx(dx, rel=1e-5)
        assert number_after("tau =", out) == pytest.approx(tau, abs=1e-5)
        assert number_after("velocity scale", out) == pytest.approx(U_SCALE, rel=1e-4)
        assert number_after("expected max Mach", out) == pytest.approx(mach, rel=1e-4)
        dt = number_after("dt =", out)
        assert dt / dx == pytest.approx(mach * CS / U_SCALE, rel=1e-4)
        ratios.append(dt / dx)
        line = next(ln for ln in out.splitlines() if ln.startswith("compressibility:"))
        assert number_after("Ma^2 =", line) == pytest.approx(mach**2, rel=1e-3), line
        assert f"error class {expected_class(mach)} (" in line, line
        assert "from lbm.mach" in line and "lbm.tau not used" in line, line
    assert ratios[0] == pytest.approx(ratios[1], rel=1e-4)


@pytest.mark.parametrize(
    ("scene", "sets"),
    [
        ("case1.nml", ["lbm.cells_per_diameter=12"]),  # tau = 0.65: Ma 0.127
        ("case1.nml", []),  # the paper's 25 per D, tau = 0.65: Ma 0.061
        ("case1.nml", ["lbm.cells_per_diameter=12", "lbm.tau=0.52"]),  # Ma 0.017
        ("poiseuille.nml", []),  # a body-force flow: Ma ~ 1e-4
        ("single.nml", ["lbm.tau=1.6"]),  # Ma 0.3, above the last class boundary
    ],
)
def test_every_scene_reports_its_ma2_and_class(tmp_path: Path, scene: str, sets: list) -> None:
    """Without lbm.mach the report still prints Ma^2 of the expected Mach number and its class
    for scenes of different velocity scales, the class chosen by the thresholds of
    docs/model.md; tau comes from lbm.tau (no Mach-source note). Fails if the class line is
    missing, if Ma^2 is not the square of the printed Mach number, or if a threshold moved."""
    out = check(tmp_path, scene, *sets)
    mach = number_after("expected max Mach", out)
    line = next((ln for ln in out.splitlines() if ln.startswith("compressibility:")), None)
    assert line is not None, out
    assert number_after("Ma^2 =", line) == pytest.approx(mach**2, rel=2e-3), line
    assert f"error class {expected_class(mach)} (" in line, line
    assert "lbm.mach" not in line, line
