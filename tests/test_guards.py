"""Run-time guards: every run.guard_every steps a non-finite value or a Mach number above
run.mach_limit stops all ranks together, with one message (rank 0's, the same on every rank)
that says what, where, when and what to change, and a non-zero exit; no rank is left waiting,
and the output is written up to the guard step and closed.

The scene is input/inlet_channel.nml (20 x 160 cells on 2 ranks: rows 1-80 on rank 0, 81-160 on
rank 1) started at rest with the inlet switched on at once (inlet.ramp_time = 0). Its velocity
end imposes u_b = U 4 xi (1 - xi) on the end row at every step (docs/model.md E5: the end node takes
the prescribed velocity), so from step 1 the end row holds Mach U_x dt/dx / c_s, computed here,
while every node more than n rows away is still at rest at step n (a population moves one node per
step). The expected step, row, position and value of each message follow from that.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

from dkt_run import INPUT, run_args
from dktlbm.read import text_attr

RANKS = 2
TIMEOUT = 20.0  # s; the runs below stop within a few steps
SCENE = INPUT / "inlet_channel.nml"
# input/inlet_channel.nml
WIDTH, HEIGHT, DX, TAU, NU, U_IN = 1.0, 8.0, 0.05, 0.6, 0.05, 0.5
NX, NY = round(WIDTH / DX), round(HEIGHT / DX)
DT = (TAU - 0.5) / 3.0 * DX**2 / NU  # docs/model.md E3
CS = math.sqrt(1.0 / 3.0)

NUM = r"([-+]?[0-9.]+(?:[eE][-+]?[0-9]+)?)"
MACH_RE = re.compile(
    rf"Mach number\s+{NUM} above run\.mach_limit =\s+{NUM} at step (\d+) \(t =\s+{NUM} s\), "
    rf"node \((\d+), (\d+)\) at \(\s*{NUM},\s+{NUM}\) cm\. (.*)"
)
NONFINITE_RE = re.compile(
    rf"non-finite value at step (\d+) \(t =\s+{NUM} s\), node \((\d+), (\d+)\) at "
    rf"\(\s*{NUM},\s+{NUM}\) cm\. (.*)"
)
ERROR_RE = re.compile(r"^dktlbm: error: (.*)$", re.MULTILINE)


def run_scene(tmp_path: Path, sets: list[str], scene: Path = SCENE, steps: int = 50):
    args = [str(scene), "--set", f"run.steps={steps}", "--set", f"output.dir={tmp_path / 'o'}"]
    for s in sets:
        args += ["--set", s]
    return run_args(args, RANKS, TIMEOUT, tmp_path)


def guard_message(stderr: str) -> str:
    """The one error message of a guard stop: the guard is collective, so exactly one line,
    printed once (by rank 0), and no per-rank abort message."""
    lines = [ln for ln in stderr.splitlines() if ln.startswith("dktlbm: error")]
    assert len(lines) == 1, f"expected one error line:\n{stderr}"
    found = ERROR_RE.findall(lines[0])
    assert found, f"not the collective error format:\n{stderr}"
    return found[0]


def y_of_rank(rank: int) -> range:
    """The global rows (1-based) of `rank`'s slab: NY rows split evenly over RANKS."""
    rows = NY // RANKS
    return range(rank * rows + 1, (rank + 1) * rows + 1)


def inlet_mach(x: int, u_in: float) -> float:
    """Mach number of the parabolic inlet profile at column x (1-based, centre (x - 1/2) dx)."""
    xi = (x - 0.5) / NX
    return abs(u_in * 4.0 * xi * (1.0 - xi)) * DT / DX / CS


UPPER_INLET = ["domain.lower=outflow", "domain.upper=velocity"]

MACH_CASES = {
    # the default limit 0.3 and a fast inlet: peak Mach 20 dt/dx / c_s = 1.15
    "fast-inlet-default-limit": (["inlet.velocity=20", "run.guard_every=1"], 20.0, 0.3, 1),
    # the scene's own inlet (peak Mach 0.029) against a lowered limit
    "lowered-limit": (["run.mach_limit=0.01", "run.guard_every=1"], U_IN, 0.01, 1),
    # first check at step 5: the guard must not run in between, and report step 5
    "lowered-limit-guard-every-5": (["run.mach_limit=0.01", "run.guard_every=5"], U_IN, 0.01, 5),
    # inlet at the top, in rank 1's slab: a rank other than 0 must report and stop the job
    "upper-inlet-on-rank-1": (
        [*UPPER_INLET, "inlet.velocity=-0.5", "run.mach_limit=0.01", "run.guard_every=1"],
        -U_IN,
        0.01,
        1,
    ),
}


@pytest.mark.parametrize(("sets", "u_in", "limit", "step"), MACH_CASES.values(), ids=MACH_CASES)
def test_mach_guard_stops_all_ranks_and_says_where_when_and_what_to_change(
    tmp_path: Path, sets: list[str], u_in: float, limit: float, step: int
) -> None:
    """Catches: no guard, a guard that runs at the wrong steps, a Mach number in the wrong units
    (cm/s, or |u|^2), a local instead of global row, a wrong position in cm, a message from the
    wrong rank or from every rank, a hang of the rank that did not fail, exit status 0."""
    upper = "domain.upper=velocity" in sets
    proc = run_scene(tmp_path, ["inlet.ramp_time=0", *sets])
    assert proc.returncode != 0, f"the run did not stop:\n{proc.stdout}\n{proc.stderr}"
    assert "performance:" not in proc.stdout, "the run went on to the end"
    msg = guard_message(proc.stderr)
    m = MACH_RE.search(msg)
    assert m, f"message does not say what, when and where:\n{msg}"
    value, shown_limit = float(m.group(1)), float(m.group(2))
    n, t = int(m.group(3)), float(m.group(4))
    x, y = int(m.group(5)), int(m.group(6))
    xc, yc = float(m.group(7)), float(m.group(8))
    advice = m.group(9)

    assert shown_limit == pytest.approx(limit, rel=1e-4)
    assert value > limit
    assert n == step, f"reported step {n}, the first guard step is {step}"
    assert t == pytest.approx(n * DT, rel=1e-4)
    inlet_row = NY if upper else 1
    assert 1 <= x <= NX and abs(y - inlet_row) <= n, f"node ({x}, {y}) cannot move by step {n}"
    # only the slab that holds the inlet row has a fast node: rank 1's message reached rank 0
    assert y in y_of_rank(1 if upper else 0), f"row {y} is not in the inlet's slab"
    if step == 1:
        assert y == inlet_row, f"at step 1 only the inlet row is fast, not row {y}"
    assert xc == pytest.approx((x - 0.5) * DX, rel=1e-4)
    assert yc == pytest.approx((y - 0.5) * DX, rel=1e-4)
    if y == inlet_row:
        assert value == pytest.approx(inlet_mach(x, u_in), rel=1e-4)
    # what to change: keys the user can act on
    assert "lbm.dx" in advice and "lbm.tau" in advice, advice


def test_no_guard_trips_below_the_limit(tmp_path: Path) -> None:
    """The control of the test above: the same inlet (peak Mach 0.029) with the limit 0.05,
    checked every step, runs to the end. Catches a guard that trips on a wrong measure (|u| in
    cm/s is 0.5, |u|/c_s in cm/s 0.87) or on the ghost or padding nodes."""
    assert inlet_mach(NX // 2, U_IN) < 0.05
    proc = run_scene(tmp_path, ["inlet.ramp_time=0", "run.mach_limit=0.05", "run.guard_every=1"])
    assert proc.returncode == 0, proc.stderr
    assert "performance:" in proc.stdout
    assert "dktlbm: error" not in proc.stderr


def test_the_last_step_is_always_checked(tmp_path: Path) -> None:
    """A run shorter than run.guard_every (3 steps, guard_every = 100) is still checked before
    its final fields are written: the message names step 3. Catches a final state that is never
    checked (the fields of a run gone wrong would be written as if valid)."""
    proc = run_scene(
        tmp_path, ["inlet.ramp_time=0", "run.mach_limit=0.01", "run.guard_every=100"], steps=3
    )
    assert proc.returncode != 0, proc.stdout
    msg = guard_message(proc.stderr)
    m = MACH_RE.search(msg)
    assert m and int(m.group(3)) == 3, msg


@pytest.mark.parametrize("end", ["lower", "upper"])
def test_non_finite_guard_stops_all_ranks_and_says_where_when_and_what_to_change(
    tmp_path: Path, end: str
) -> None:
    """An inlet of 1e200 cm/s is 3e196 in lattice units; its square in the equilibrium overflows
    double precision, so at step 1 the inlet row holds inf/NaN populations for real (no finite
    fast state comes first: the fluid is at rest before). With mach_limit = 1 and guard_every = 1
    the non-finite guard must be the one that reports. Catches: no NaN check (the run would go
    on, or the Mach test, false for NaN, would let it through), a check that reads only the
    velocity, the wrong row or rank, a hang, exit status 0."""
    sets = ["inlet.ramp_time=0", "run.mach_limit=1", "run.guard_every=1"]
    if end == "upper":
        sets += [*UPPER_INLET, "inlet.velocity=-1e200"]
    else:
        sets += ["inlet.velocity=1e200"]
    proc = run_scene(tmp_path, sets)
    assert proc.returncode != 0, f"the run did not stop:\n{proc.stdout}\n{proc.stderr}"
    assert "performance:" not in proc.stdout
    msg = guard_message(proc.stderr)
    m = NONFINITE_RE.search(msg)
    assert m, f"no non-finite message (what, when, where):\n{msg}"
    n, t, x, y = int(m.group(1)), float(m.group(2)), int(m.group(3)), int(m.group(4))
    xc, yc, advice = float(m.group(5)), float(m.group(6)), m.group(7)
    assert n == 1 and t == pytest.approx(DT, rel=1e-4)
    inlet_row = NY if end == "upper" else 1
    assert abs(y - inlet_row) <= 1 and 1 <= x <= NX, f"node ({x}, {y})"
    assert y in y_of_rank(1 if end == "upper" else 0), f"row {y} is not in the inlet's slab"
    assert xc == pytest.approx((x - 0.5) * DX, rel=1e-4)
    assert yc == pytest.approx((y - 0.5) * DX, rel=1e-4)
    assert "lbm.tau" in advice and "lbm.dx" in advice, advice


def test_a_guard_failing_on_every_rank_prints_once(tmp_path: Path) -> None:
    """Taylor-Green vortex at Mach 0.054 (U = 0.1 cm/s, dt/dx = 0.3125 s/cm) against the limit
    0.01: both slabs fail at step 1. One message (rank 0's slab: the lowest rank that failed),
    the job ends with status 3 (a run-time stop), the run file is closed and says why. Catches a
    deadlock of two ranks stopping together, messages repeated per node or per rank, and a
    guard stop that loses the output."""
    proc = run_scene(
        tmp_path,
        ["run.mach_limit=0.01", "run.guard_every=1"],
        scene=INPUT / "taylor_green.nml",
        steps=10,
    )
    assert proc.returncode == 3, proc.stdout + proc.stderr
    msg = guard_message(proc.stderr)
    m = MACH_RE.search(msg)
    assert m and int(m.group(3)) == 1, msg
    assert int(m.group(6)) in y_of_rank(0), msg
    import h5py

    with h5py.File(tmp_path / "o" / "taylor_green.h5", "r") as h5:
        reason = h5["run"].attrs["stop_reason"]
        reason = text_attr(reason)
        assert reason == "guard: " + msg, reason
        assert "000001" in h5["fields"], list(h5["fields"])
