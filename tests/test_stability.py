"""Stability at the extremes: short preview runs at the edges of the input ranges, each ending in
one of three outcomes the test names and checks (docs/stability.md):

- stable: exit status 0, stop_reason 'finished', every field and particle value finite, and a
  stated bound on a measured quantity;
- guard: a non-zero exit with one error line naming the guard and what to change, the run file
  closed with stop_reason 'guard: <the same message>' (the guards stop all ranks together);
- refused: a non-zero exit at input, with no run file, naming the key, its value and the range.

Never a non-finite value without a guard stop, never a hang: every run has a timeout, and a run
still going after it fails the test (dkt_run.run_args kills it).

The scenes are input/single.nml (one disk, D = 0.25 cm, rho_p/rho_f = 1.25, in a closed 2 x 6 cm
box), input/case0_box.nml, input/case1.nml and input/uhlmann.nml at preview resolutions of 8-20
spacings per diameter and a few hundred to a few thousand steps. The particle Reynolds number
Re_p = u_g D / nu is set through the viscosity, u_g = sqrt(pi D/2 (rho_p/rho_f - 1) g) being the
velocity scale of the input check. The cheap cases run by default; the rest (marked `extreme`)
run when DKTLBM_STABILITY=all (ctest -L stability runs both).
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np
import pytest

from dkt_run import INPUT, run_args
from dktlbm.read import text_attr

TIMEOUT = 60.0  # s per run; each below takes a few seconds on 2 busy cores
ALL = os.environ.get("DKTLBM_STABILITY") == "all"
extreme = pytest.mark.skipif(not ALL, reason="set DKTLBM_STABILITY=all (ctest -L stability)")

# input/single.nml
D, RATIO, G, NU_SINGLE, WIDTH = 0.25, 1.25, 980.0, 0.1, 2.0
CELLS = 10  # spacings per diameter of the previews
DX = WIDTH / round(WIDTH * CELLS / D)
ERROR_RE = re.compile(r"^dktlbm: error: (.*)$", re.MULTILINE)


def u_g(ratio: float = RATIO, d: float = D) -> float:
    """Settling speed scale sqrt(pi D/2 |rho_p/rho_f - 1| g), cm/s."""
    return math.sqrt(0.5 * math.pi * d * abs(ratio - 1.0) * G)


def dt_of(tau: float, nu: float, dx: float = DX) -> float:
    """E3: dt = (tau - 1/2)/3 dx^2 / nu."""
    return (tau - 0.5) / 3.0 * dx * dx / nu


@dataclass
class Outcome:
    returncode: int
    stderr: str
    h5: Path

    @property
    def errors(self) -> list[str]:
        return ERROR_RE.findall(self.stderr)

    def attr(self, name: str) -> str:
        with h5py.File(self.h5, "r") as h5:
            value = h5["run"].attrs[name]
        return text_attr(value)

    def particles(self) -> dict[str, np.ndarray]:
        with h5py.File(self.h5, "r") as h5:
            return {k: h5["particles"][k][()] for k in h5["particles"]}

    def all_finite(self) -> bool:
        """Every field of every written step and every particle series finite."""
        with h5py.File(self.h5, "r") as h5:
            arrays: list[np.ndarray] = []
            # every dataset below /fields, the particle state of each snapshot included
            h5["fields"].visititems(
                lambda _, obj: arrays.append(obj[()]) if isinstance(obj, h5py.Dataset) else None
            )
            arrays += [h5["particles"][k][()] for k in h5["particles"]]
        return all(np.all(np.isfinite(a)) for a in arrays)


def run(tmp_path: Path, scene: str, sets: list[str], ranks: int = 1) -> Outcome:
    """Run `scene` with --set `sets` (output in tmp_path/o); a hang fails the test."""
    tmp_path.mkdir(parents=True, exist_ok=True)
    args = [str(INPUT / scene)]
    for s in [*sets, "run.progress_every=0", f"output.dir={tmp_path / 'o'}"]:
        args += ["--set", s]
    proc = run_args(args, ranks, TIMEOUT, tmp_path)
    return Outcome(proc.returncode, proc.stderr, tmp_path / "o" / f"{Path(scene).stem}.h5")


def assert_stable(out: Outcome) -> None:
    """Outcome 'stable': exit 0, finished, nothing non-finite in the output."""
    assert out.returncode == 0 and not out.errors, out.stderr
    assert out.attr("stop_reason") == "finished"
    assert out.all_finite(), "a non-finite value in the output of a run that finished"


def assert_guard(out: Outcome, *pieces: str) -> str:
    """Outcome 'guard': exit 3 (a run-time stop), one error line holding `pieces`, the run file
    closed with stop_reason 'guard: ' + that line. Returns the message."""
    assert out.returncode == 3, f"not a run-time stop ({out.returncode}):\n{out.stderr}"
    assert len(out.errors) == 1, f"expected one error line:\n{out.stderr}"
    msg = out.errors[0]
    for piece in pieces:
        assert piece in msg, f"{piece!r} not in the guard's message:\n{msg}"
    assert out.attr("stop_reason") == "guard: " + msg
    return msg


def assert_refused(out: Outcome, *pieces: str) -> str:
    """Outcome 'refused': a non-zero exit before any output, one message holding `pieces`."""
    assert out.returncode != 0, out.stderr
    assert not out.h5.exists(), "a refused input wrote a run file"
    assert len(out.errors) == 1, out.stderr
    for piece in pieces:
        assert piece in out.errors[0], f"{piece!r} not in:\n{out.errors[0]}"
    return out.errors[0]


def single(tau: float, re_p: float | None = None, steps: int = 400, **keys: str) -> list[str]:
    """--set list of the single-disk preview at `tau` and Re_p (the scene's viscosity if None)."""
    sets = [f"lbm.tau={tau}", f"lbm.cells_per_diameter={CELLS}", f"run.steps={steps}",
            "output.field_interval=0"]  # fmt: skip
    if re_p is not None:
        sets.append(f"fluid.viscosity={u_g() * D / re_p:.9g}")
    return sets + [f"{k.replace('__', '.')}={v}" for k, v in keys.items()]


def max_reynolds(out: Outcome, nu: float, d: float = D) -> float:
    p = out.particles()
    return float(np.max(np.hypot(p["u"], p["v"]))) * d / nu


# ---- tau: 1/2 + 1e-3 to 2, refused outside ------------------------------------------------


@pytest.mark.parametrize("tau", ["0.5", "10.5"])
def test_tau_outside_its_range_is_refused(tmp_path: Path, tau: str) -> None:
    """Refused: tau = 1/2 gives zero viscosity and dt = 0, tau > 10 is outside the key's range;
    the message names the key, the value and the range. Catches a run started with dt = 0."""
    out = run(tmp_path, "single.nml", [f"lbm.tau={tau}"])
    assert_refused(out, "tau", tau, "0.5")


@pytest.mark.parametrize(("tau", "re_p", "steps"), [(0.501, 300.0, 2000), (2.0, 1.0, 400)])
def test_tau_extremes_at_a_reachable_reynolds_number_are_stable(
    tmp_path: Path, tau: float, re_p: float, steps: int
) -> None:
    """Stable: tau = 1/2 + 1e-3 at Re_p = 300 (E3 s_q = 0.005, lattice speed 0.01) and tau = 2
    at Re_p = 1 (lattice speed 0.05). Bound: the measured max |U| D/nu stays at or below Re_p,
    since u_g is the terminal speed at a drag coefficient of 1 and a disk's exceeds 1 at these
    Reynolds numbers (walls add more); a larger speed is energy the scheme made. Near tau = 1/2
    the start-up warns that s_q leaves the q moments almost undamped."""
    out = run(tmp_path, "single.nml", single(tau, re_p, steps))
    assert_stable(out)
    nu = u_g() * D / re_p
    assert 0.0 < max_reynolds(out, nu) <= re_p
    if tau < 0.51:
        assert "heat-flux rate s_q" in out.stderr


def test_large_tau_at_the_scenes_reynolds_number_stops_at_the_mach_guard(tmp_path: Path) -> None:
    """Guard: tau = 2 at single.nml's own viscosity (Re_p = 24.5, expected lattice speed 2.1
    c_s at 10 spacings per D). The input check warns that the scene lies outside the measured
    stable region (docs/stability_map.csv) and that the expected Mach number is above the limit;
    the run is stopped by the Mach guard (or by the particle speed guard, which then reports the
    fluid's Mach number: the fluid check comes first), with what to change."""
    out = run(tmp_path, "single.nml", single(2.0))
    assert "measured stable" in out.stderr and "expected Mach number" in out.stderr
    assert_guard(out, "Mach number", "run.mach_limit", "lbm.tau", "lbm.cells_per_diameter")


@pytest.mark.parametrize("scene", ["single.nml", "case0_box.nml", "case1.nml", "uhlmann.nml"])
def test_check_is_quiet_for_the_shipped_scenes_and_warns_outside_the_map(
    tmp_path: Path, scene: str
) -> None:
    """--check: the validation scenes as shipped (Re_p/N from 0.5 to 17 at their tau) lie inside
    the measured stable region and get no map warning; the same scene at tau = 1.6 (measured
    Re_p/N <= 0.3 there, docs/stability_map.csv) gets one that names tau, Re_p and the map, and
    at tau = 2.5 (beyond the measured taus) one that says so. Catches a warning that fires on
    every scene (noise) or never."""
    base = ["--check", "--set", f"output.dir={tmp_path / 'o'}"]
    quiet = run_args([str(INPUT / scene), *base], 1, TIMEOUT, tmp_path)
    assert quiet.returncode == 0, quiet.stderr
    assert "measured" not in quiet.stderr, quiet.stderr
    for tau, piece in (("1.6", "above the measured stable Re_p/N"), ("2.5", "measured tau range")):
        proc = run_args(
            [str(INPUT / scene), *base, "--set", f"lbm.tau={tau}"], 1, TIMEOUT, tmp_path
        )
        warning = [ln for ln in proc.stderr.splitlines() if piece in ln]
        assert len(warning) == 1, proc.stderr
        assert f"tau = {tau}" in warning[0] and "Re_p" in warning[0], warning[0]
        assert "docs/stability.md" in warning[0], warning[0]


# ---- density ratio: 1.001 to 10, and below 1 ------------------------------------------------


def test_nearly_neutral_disk_is_stable_and_slow(tmp_path: Path) -> None:
    """Stable: rho_p/rho_f = 1.001. Bound: max |U| <= u_g = 0.62 cm/s, the settling scale (see
    above); a near-neutral disk driven faster is a spurious force."""
    out = run(tmp_path, "single.nml", single(0.65, steps=1500, particles__density="1.001"))
    assert_stable(out)
    p = out.particles()
    assert np.max(np.hypot(p["u"], p["v"])) <= u_g(1.001)


def test_light_disk_rises(tmp_path: Path) -> None:
    """Stable (a density ratio below 1 is supported: E9 turns the net weight upwards):
    rho_p/rho_f = 0.8. Bound: the disk moves up (v > 0 at the end, y above the start) and not
    faster than u_g; a sign error in the buoyancy would make it sink."""
    out = run(tmp_path, "single.nml", single(0.65, steps=1500, particles__density="0.8"))
    assert_stable(out)
    p = out.particles()
    assert p["v"][-1, 0] > 0.0 and p["y"][-1, 0] > p["y"][0, 0]
    assert np.max(np.hypot(p["u"], p["v"])) <= u_g(0.8)


def test_heavy_disk_at_small_tau_is_stable(tmp_path: Path) -> None:
    """Stable: rho_p/rho_f = 10 (Re_p = u_g D/nu = 147) at tau = 0.52, lattice speed scale
    0.10 at 10 spacings per D. Bound: max |U| D/nu <= Re_p (see above)."""
    out = run(tmp_path, "single.nml", single(0.52, steps=2000, particles__density="10"))
    assert_stable(out)
    assert max_reynolds(out, NU_SINGLE) <= u_g(10.0) * D / NU_SINGLE


def test_heavy_disk_faster_than_the_particle_limit_is_stopped_by_its_guard(
    tmp_path: Path,
) -> None:
    """Guard (particle speed): rho_p/rho_f = 10 at tau = 0.65 and 10 spacings per D, with the
    Mach limit raised to 1 and the fluid guard every 1000 steps, so that only the particle
    guard (every step) can stop it when the disk passes 0.3 spacings per step. Bounds from free
    fall: the particle gains at most a = (1 - 1/ratio) g dt^2/dx per step (drag only slows
    it), so the reported speed lies in (0.3, 0.3 + a] and the step is at least 0.3/a. On 2
    ranks: one message, all ranks stopped. Catches a missing guard, one that checks only every
    guard_every steps, and a speed in cm/s."""
    ratio = 10.0
    sets = single(0.65, steps=1000, particles__density=f"{ratio}")
    sets += ["run.mach_limit=1", "run.guard_every=1000"]
    out = run(tmp_path, "single.nml", sets, ranks=2)
    msg = assert_guard(out, "particle 1 moves", "run.particle_speed_limit", "lbm.tau")
    m = re.search(r"moves\s+(\S+) lattice spacings per step.*at step (\d+)", msg)
    assert m, msg
    speed, step = float(m.group(1)), int(m.group(2))
    dt = dt_of(0.65, NU_SINGLE)
    a = (1.0 - 1.0 / ratio) * G * dt * dt / DX
    assert 0.3 < speed <= 0.3 + a * (1 + 1e-9)
    assert step >= 0.3 / a


def test_particle_started_faster_than_the_limit_is_refused(tmp_path: Path) -> None:
    """Refused: a disk started at 40 cm/s = 0.5 spacings per step (dx = 0.025 cm, dt = 3.1e-4 s)
    with the particle limit 0.3: the message names the keys and the allowed speed, 24 cm/s."""
    out = run(tmp_path, "single.nml", single(0.65, particles__v="-40", run__mach_limit="1"))
    assert_refused(out, "v(1) = -40", "&run particle_speed_limit = 0.3", "23.99")


# ---- walls and contacts ---------------------------------------------------------------------


def test_release_half_a_spacing_from_a_wall_warns_and_ends_in_a_named_outcome(
    tmp_path: Path,
) -> None:
    """A disk whose surface starts half a spacing from the side wall (x = r + dx/2). The input
    check warns (the gap's flow was measured to run away). Measured outcome at 10 spacings per D:
    the Mach guard stops it, naming the node next to the wall. Either outcome is accepted,
    stable or that guard, but never a non-finite value or a silent finish with one."""
    sets = single(0.65, steps=1500, particles__x=f"{D / 2 + DX / 2}", run__guard_every="10")
    out = run(tmp_path, "single.nml", sets)
    assert "0.5 lattice spacings from the wall at x = 0" in out.stderr
    if out.returncode == 0:
        assert_stable(out)
    else:
        assert_guard(out, "Mach number", "node (1,")


def test_fast_approach_to_a_wall_keeps_the_disk_out_of_it(tmp_path: Path) -> None:
    """Stable: a disk thrown at 40 cm/s (0.17 spacings per step, Mach 0.29, Re_p = 100) at the
    bottom wall from 0.375 cm away, tau = 0.55. Bounds: its surface never goes deeper than half
    a spacing into the wall (deeper, a wall node lies inside the disk and the links break), and
    it never moves faster than its start speed plus what gravity adds over the run (a contact
    that adds energy would)."""
    v0, steps = 40.0, 600
    sets = single(0.55, steps=steps, particles__y="0.5", particles__v=f"-{v0}")
    out = run(tmp_path, "single.nml", sets)
    assert_stable(out)
    p = out.particles()
    assert np.min(p["y"][:, 0]) - D / 2 > -DX / 2
    gain = (1 - 1 / RATIO) * G * steps * dt_of(0.55, NU_SINGLE)
    assert np.max(np.hypot(p["u"], p["v"])) <= v0 + gain


def test_fast_approach_to_another_disk_keeps_them_apart(tmp_path: Path) -> None:
    """Stable: a disk thrown at 40 cm/s onto an equal one at rest 0.25 cm (one diameter) below,
    tau = 0.55. Bounds as above: the two overlap by less than half a spacing, and no disk moves
    faster than the start speed plus gravity's gain over the run."""
    v0, steps = 40.0, 600
    sets = single(0.55, steps=steps)
    sets += ["particles.count=2", "particles.x=1.0,1.0", "particles.y=4.0,3.5",
             f"particles.v=-{v0},0", "particles.diameter=0.25,0.25",
             "particles.density=1.25,1.25"]  # fmt: skip
    out = run(tmp_path, "single.nml", sets)
    assert_stable(out)
    p = out.particles()
    gap = np.hypot(p["x"][:, 0] - p["x"][:, 1], p["y"][:, 0] - p["y"][:, 1]) - D
    assert np.min(gap) > -DX / 2
    gain = (1 - 1 / RATIO) * G * steps * dt_of(0.55, NU_SINGLE)
    assert np.max(np.hypot(p["u"], p["v"])) <= v0 + gain


# ---- the long subset (DKTLBM_STABILITY=all) -------------------------------------------------


@extreme
@pytest.mark.parametrize("tau", [0.505, 0.52, 0.6, 1.0])
@pytest.mark.parametrize("re_p", [30.0, 300.0])
def test_reynolds_sweep_is_stable_or_stopped_by_the_mach_guard(
    tmp_path: Path, tau: float, re_p: float
) -> None:
    """Re_p 30 and 300 at four taus. The expected lattice speed is u_lb = Re_p (tau - 1/2)/(3 N);
    the disk's real peak speed is lower (its drag coefficient exceeds 1). Under the Mach limit
    (u_lb < 0.3 c_s) the run must be stable with max |U| D/nu <= Re_p; above three times it,
    the Mach guard must stop it (the particle guard may trigger the check first); in between,
    either, each checked as such."""
    limit = 0.3 * math.sqrt(1 / 3)
    u_lb = re_p * (tau - 0.5) / (3 * CELLS)
    steps = min(4000, max(200, math.ceil(math.pi * CELLS * RATIO / u_lb)))
    out = run(tmp_path, "single.nml", single(tau, re_p, steps))
    if u_lb > 3 * limit or (u_lb >= limit and out.returncode != 0):
        assert_guard(out, "Mach number")
    else:
        assert_stable(out)
        assert max_reynolds(out, u_g() * D / re_p) <= re_p


@extreme
def test_undamped_heat_flux_near_tau_one_half_is_stopped_by_a_guard_that_names_s_q(
    tmp_path: Path,
) -> None:
    """Guard: the Uhlmann DKT pair (input/uhlmann.nml, tau = 0.512, Re_p up to ~500) at 20
    spacings per D with the E3 heat-flux rate (s_q = 0: 0.062) was measured to run away: the
    Mach guard stops it, and its message names s_q and the fix, s_q = 1.2. The control with the
    scene's own s_q = 1.2 runs the same 0.3 s through (stable). On 2 ranks."""
    sets = ["output.field_interval=0", "run.guard_every=20"]
    out = run(tmp_path / "e3", "uhlmann.nml", [*sets, "lbm.s_q=0"], ranks=2)
    assert_guard(out, "Mach number", "s_q = 0.062", "lbm.s_q = 1.2")
    out = run(tmp_path / "s12", "uhlmann.nml", sets, ranks=2)
    assert_stable(out)


@extreme
def test_stiff_contact_law_is_sub_stepped(tmp_path: Path) -> None:
    """The contact law's time step: case0_box at 12 spacings per D with a stiffness 100 times
    the default needs more than one particle sub-step per fluid step; the set-up raises
    collision.substeps to what the explicit update needs (omega h <= 1) and logs it, and the
    run is stable. With that many given (or more), it is kept and not logged."""
    sets = ["lbm.cells_per_diameter=12", "run.steps=600", "output.field_interval=0",
            "collision.stiffness=1e-9", "collision.stiffness_overlap=1e-9"]  # fmt: skip
    out = run(tmp_path / "a", "case0_box.nml", sets)
    log = (tmp_path / "a" / "o" / "case0_box.log").read_text()
    m = re.search(r"needs (\d+) sub-steps per fluid step", log)
    assert m and int(m.group(1)) > 1, log
    assert_stable(out)
    n = int(m.group(1))
    out = run(tmp_path / "b", "case0_box.nml", [*sets, f"collision.substeps={n + 2}"])
    assert_stable(out)
    assert "sub-steps per fluid step" not in (tmp_path / "b" / "o" / "case0_box.log").read_text()


@extreme
@pytest.mark.parametrize("tau", [0.501, 0.65])
def test_pair_at_preview_resolution_is_as_the_map_warns(tmp_path: Path, tau: float) -> None:
    """The case0_box pair (rho_p = 1.01, Re_p = u_g D/nu = 35) at 8 spacings per D, 3000 steps.
    At tau = 1/2 + 1e-3 Re_p/N = 4.4 lies inside the measured stable region (no warning) and the
    run is stable: no disk faster than u_g = 1.75 cm/s, no overlap of half a spacing. At
    tau = 0.65 it lies above the region's 3 (docs/stability_map.csv): the input check warns,
    and the run is stopped by the Mach guard (measured), by name."""
    sets = ["lbm.cells_per_diameter=8", f"lbm.tau={tau}", "run.steps=3000",
            "output.field_interval=0"]  # fmt: skip
    out = run(tmp_path, "case0_box.nml", sets)
    warned = "measured stable Re_p/N" in out.stderr
    assert warned == (tau > 0.6), out.stderr
    if warned:
        assert_guard(out, "Mach number", "lbm.tau")
        return
    assert_stable(out)
    p = out.particles()
    assert np.max(np.hypot(p["u"], p["v"])) <= u_g(1.01, 0.2)
    gap = np.hypot(p["x"][:, 0] - p["x"][:, 1], p["y"][:, 0] - p["y"][:, 1]) - 0.2
    assert np.min(gap) > -(0.2 / 8) / 2


@extreme
def test_diameter_ratio_five_is_stable(tmp_path: Path) -> None:
    """Stable: case1 with gamma = 5 (D_2 = 0.04 cm at 8 spacings, window on), 300 steps.
    Bound: no disk faster than the larger disk's u_g (1.75 cm/s)."""
    sets = ["lbm.cells_per_diameter=8", "pair.gamma=5", "run.steps=300",
            "output.field_interval=0"]  # fmt: skip
    out = run(tmp_path, "case1.nml", sets)
    assert_stable(out)
    p = out.particles()
    assert np.max(np.hypot(p["u"], p["v"])) <= u_g(1.01, 0.2)
