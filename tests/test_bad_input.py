"""Bad input (docs/design.md, "Input", "Errors and guards"; input/README.md "Errors").

Each invalid input is run on 2 ranks with a 10 s limit and must give: a non-zero exit, no hang,
exactly one message from rank 0 that names the file (and line, or the --set option), the group,
the key, the bad value and what is allowed, and no output (the output directory is not created,
nothing appears in the working directory, an earlier run's files stay byte for byte the same).

On "no hang": Open MPI's mpiexec ends the whole job as soon as one rank exits with a non-zero
status, so a rank left waiting while rank 0 stops is reaped by the launcher, not seen here. The
time limit catches a job in which no rank gets out (e.g. rank 0 blocked in MPI_Finalize while
another rank waits in a collective, or every rank waiting for a broadcast that never comes).

The scenes are small edits of input/poiseuille.nml (20 x 6 cells) written into tmp_path, or, for
the DKT keys (&pair, &window, lbm.cells_per_diameter), of input/case1.nml and input/single.nml;
the expected pieces of each message are derived from the edit, not copied from the program.
"""

from __future__ import annotations

import math
import os
import re
import resource
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import pytest

from dkt_run import EXE, INPUT, ROOT, mpi_env, number_after, run_args, tree_digest
from dktlbm.read import text_attr

RANKS = 2
TIMEOUT = 10.0  # s; every one of these stops before time-stepping, a hang fails the test
# Open MPI's mpiexec waits 1 s between SIGTERM and SIGKILL when it ends a job after a non-zero
# exit; the ranks here have already stopped, so the wait only slows the tests down.
ENV = {"OMPI_MCA_odls_base_sigkill_timeout": "0"}
BASE = (INPUT / "poiseuille.nml").read_text()
NUM = r"([-+]?[0-9.]+(?:[eE][-+]?[0-9]+)?)"
# The base scene runs 5 steps instead of t_end = 2000 s, so the valid runs below are instant.
BASE = BASE.replace("t_end = 2000.0", "steps = 5")
assert "steps = 5" in BASE


def dkt(args: list[str], cwd: Path, ranks: int = RANKS):
    """dktlbm `args` on `ranks` ranks in directory `cwd`, limited to TIMEOUT."""
    return run_args(args, ranks, TIMEOUT, cwd, ENV)


def write_scene(
    tmp_path: Path, old: str | None = None, new: str = "", base: str | None = None
) -> tuple[Path, int]:
    """The base scene (or the scene `base` of input/) with `old` replaced by `new` (once) as
    tmp_path/bad.nml, and the 1-based line number of the edit (0 when nothing was edited)."""
    text = BASE if base is None else (INPUT / base).read_text()
    line = 0
    if old is not None:
        assert text.count(old) == 1, f"{old!r} must occur once in the base scene"
        line = text[: text.index(old)].count("\n") + 1
        text = text.replace(old, new)
    path = tmp_path / "bad.nml"
    path.write_text(text)
    return path, line


def error_lines(stderr: str) -> list[str]:
    return [ln for ln in stderr.splitlines() if ln.startswith("dktlbm: error")]


def assert_clean_failure(proc, outdir: Path, cwd: Path) -> str:
    """Common contract of every bad input; returns the one error message."""
    assert proc.returncode != 0, f"exit status 0 for a bad input\n{proc.stdout}\n{proc.stderr}"
    lines = error_lines(proc.stderr)
    # one message from rank 0: a second rank printing too, or a rank-prefixed local message
    # (fatal_local instead of fatal_all), would break this
    assert len(lines) == 1, f"expected one error message, got {len(lines)}:\n{proc.stderr}"
    assert lines[0].startswith("dktlbm: error: "), lines[0]
    assert not outdir.exists(), f"output directory {outdir} was created by a bad input"
    assert list(cwd.iterdir()) == [], f"files written to the working directory: {cwd}"
    return lines[0]


@dataclass
class Case:
    """One bad input: an edit of the base scene and/or command-line arguments, and the pieces
    the message must contain (`{file}` and `{line}` are filled in)."""

    old: str | None = None
    new: str = ""
    args: list[str] = field(default_factory=list)
    pieces: list[str] = field(default_factory=list)
    no_file: bool = False  # pass no scene file on the command line
    base: str | None = None  # a scene of input/ to start from instead of the base scene
    whole: str | None = None  # the whole scene file (instead of an edit of a base scene)


LBM_KEYS = "dx, tau, collision, s_e, s_eps, s_q"  # input/README.md, &lbm
MAX_STEPS = 1000000000  # input/README.md: at most 10^9 time steps
DT_MIN = "1.0e-12"  # input/README.md: 1e-12 s <= dt <= 1e6 s
BASE_DT = (1.0 - 0.5) / 3.0 * 0.05**2 / (0.01 / 1.0)  # E3 for the base scene's tau, dx, nu
# input/single.nml's disk driven at a constant velocity, without gravity
PRESCRIBED = ["--set", "particles.motion=prescribed", "--set", "particles.gravity=0"]
# the fastest a prescribed particle may move on single.nml's lattice: mach_limit c_s dx/dt
SPEED = f"speed up to {0.3 * math.sqrt(1 / 3) * 0.01 / 5e-5:.3f}"
TAU_RANGE = "0.5 < tau <= 10"

CASES = {
    # &lbm has no key 'taux': the list of the group's keys and the near miss are offered
    "unknown-key": Case(
        "tau = 1.0",
        "tau = 1.0, taux = 0.7",
        pieces=["{file}:{line}:", "&lbm", "'taux'", "taux = 0.7", LBM_KEYS, "'tau'"],
    ),
    "misspelt-group-lbmm": Case(
        "&lbm",
        "&lbmm",
        pieces=["{file}:{line}:", "unknown group &lbmm", "&domain", "did you mean &lbm?"],
    ),
    "tau-equal-0.5": Case(
        "tau = 1.0", "tau = 0.5", pieces=["{file}:{line}:", "&lbm", "tau = 0.5", TAU_RANGE]
    ),
    "tau-0.3": Case(
        "tau = 1.0", "tau = 0.3", pieces=["{file}:{line}:", "&lbm", "tau = 0.3", TAU_RANGE]
    ),
    "negative-width": Case(
        "width = 1.0",
        "width = -2",
        pieces=["{file}:{line}:", "&domain", "width = -2", "width > 0"],
    ),
    "tau-not-a-number-abc": Case(
        "tau = 1.0",
        "tau = 'abc'",
        pieces=["{file}:{line}:", "&lbm", "tau", "abc", "not a real number", TAU_RANGE],
    ),
    "tau-not-a-number-0.6x": Case(
        "tau = 1.0",
        "tau = 0.6x",
        pieces=["{file}:{line}:", "&lbm", "tau", "0.6x", "not a real number", TAU_RANGE],
    ),
    "steps-not-an-integer": Case(
        "steps = 5",
        "steps = 1.5",
        pieces=["{file}:{line}:", "&run", "steps = 1.5", "not an integer", "0 <= steps"],
    ),
    "overwrite-not-a-logical": Case(
        args=["--set", "output.overwrite=maybe"],
        pieces=["{file}", "--set output.overwrite=maybe", "&output", "maybe", ".true."],
    ),
    "compress-above-9": Case(
        args=["--set", "output.compress=10"],
        pieces=["{file}", "--set output.compress=10", "&output", "compress", "10", "9"],
    ),
    "compress-negative": Case(
        args=["--set", "output.compress=-1"],
        pieces=["{file}", "--set output.compress=-1", "&output", "compress", "-1", "0"],
    ),
    "compress-not-an-integer": Case(
        args=["--set", "output.compress=2.5"],
        pieces=["{file}", "--set output.compress=2.5", "&output", "compress", "2.5"],
    ),
    "choice-not-in-list": Case(
        "tau = 1.0",
        "tau = 1.0, collision = 'xyz'",
        pieces=["{file}:{line}:", "&lbm", "collision", "'xyz'", "'mrt'", "'bgk'"],
    ),
    "choice-not-in-list-by-set": Case(
        args=["--set", "lbm.collision=xyz"],
        pieces=["{file}", "--set lbm.collision=xyz", "&lbm", "collision", "'xyz'", "'mrt'"],
    ),
    "interior-not-in-list-by-set": Case(
        args=["--set", "coupling.interior=ladd"],
        pieces=["{file}", "--set coupling.interior=ladd", "&coupling", "interior", "'ladd'"]
        + ["'solid'", "'fluid'"],
    ),
    "precision-not-in-list": Case(
        "tau = 1.0",
        "tau = 1.0, precision = 'quarter'",
        pieces=[
            "{file}:{line}:",
            "&lbm",
            "precision",
            "'quarter'",
            "'double'",
            "'single'",
            "'single_unshifted'",
            "'half'",
        ],
    ),
    "precision-not-in-list-by-set": Case(
        args=["--set", "lbm.precision=float"],
        pieces=["{file}", "--set lbm.precision=float", "&lbm", "precision", "'float'", "'single'"],
    ),
    # a valid file made invalid by an option: the message names the option, not a file line
    "range-by-set": Case(
        args=["--set", "lbm.tau=0.3"],
        pieces=["{file}", "--set lbm.tau=0.3", "&lbm", "tau = 0.3", TAU_RANGE],
    ),
    "mach-limit-above-1": Case(
        args=["--set", "run.mach_limit=1.5"],
        pieces=["{file}", "&run", "mach_limit = 1.5", "0 < mach_limit <= 1"],
    ),
    "guard-every-0": Case(
        args=["--set", "run.guard_every=0"],
        pieces=["{file}", "&run", "guard_every = 0", "guard_every >= 1"],
    ),
    "set-unknown-key": Case(
        args=["--set", "lbm.taux=0.7"],
        pieces=["{file}", "--set lbm.taux=0.7", "&lbm", "'taux'", LBM_KEYS, "'tau'"],
    ),
    "set-unknown-group": Case(
        args=["--set", "lbn.tau=0.7"],
        pieces=["{file}", "--set lbn.tau=0.7", "&lbn", "did you mean &lbm?"],
    ),
    "set-without-value": Case(
        args=["--set", "lbm.tau"], pieces=["--set lbm.tau", "group.key=value"]
    ),
    "unknown-option": Case(args=["--frobnicate"], pieces=["'--frobnicate'", "--set", "--check"]),
    "no-scene-file": Case(no_file=True, pieces=["no namelist file"]),
    # lower and upper are periodic together or not at all (input/README.md, rules)
    "periodic-one-end-only": Case(
        "upper = 'periodic'", "upper = 'wall'", pieces=["{file}", "lower", "upper", "periodic"]
    ),
    # 1.0 cm / 0.03 cm is not a whole number of cells: the message names both keys and a dx
    # that fits (1/33 or 1/34 cm)
    "dx-does-not-fit-width": Case(
        "dx = 0.05", "dx = 0.03", pieces=["{file}", "&domain", "width", "&lbm", "dx = 0.03"]
    ),
    # where lbm.cells_per_diameter sets dx (from the width), lbm.dx is not read: a height that
    # is not whole cells gets a height that is, never a dx to choose
    "height-does-not-fit-cells-per-diameter": Case(
        args=["--set", "window.enabled=.false.", "--set", "domain.height=20.01",
              "--set", "lbm.cells_per_diameter=12.05"],
        base="case1.nml",
        pieces=["{file}", "--set domain.height=20.01", "lbm.cells_per_diameter", "2411.21",
                "choose height = n*dx, e.g. height = 20.008298755186722 (2411 cells)"],
    ),
    # ---- the DKT keys (input/README.md, &pair, &window, &lbm cells_per_diameter)
    # the diameter ratio is D_1/D_2 with D_1 the larger: below 1 is a range error
    "pair-gamma-below-1": Case(
        args=["--set", "pair.gamma=0.5"],
        base="case1.nml",
        pieces=["{file}", "--set pair.gamma=0.5", "&pair", "gamma = 0.5", "1 <= gamma <= 100"],
    ),
    # a component or a second index after an element is not an element: named whole, not
    # read as an index with its last character cut off
    "element-with-a-component": Case(
        args=["--set", "particles.x(1)%re=1"],
        base="single.nml",
        pieces=["{file}", "--set particles.x(1)%re=1", "&particles",
                "'x(1)%re' is not an element of x", "x(i), x(a:b) or x(a:b:s)"],
    ),
    # with enter_cells = 0 the entry gap is collision.range + 1: the message names the range
    # that set it, and offers a smaller one
    "release-gap-below-the-range-rule": Case(
        args=["--set", "lbm.cells_per_diameter=8", "--set", "collision.range=3"],
        base="case1.nml",
        pieces=["{file}", "--set collision.range=3", "&diagnostics", "release_cells = 4.0",
                "collision.range + 1 = 4.0 spacings", "collision.range = 3.0",
                "a smaller entry gap (collision.range"],
    ),
    # a pair scene sets particles 1 and 2 from &pair: a key of theirs in &particles would be
    # range-checked and then discarded, so it is refused, from the command line or the file
    "pair-scene-particle-diameter": Case(
        args=["--set", "particles.diameter=1e308"],
        base="case1.nml",
        pieces=["{file}", "--set particles.diameter=1e308", "&particles", "diameter = 1.0e308",
                "&pair gamma = 2.0", "sets particles 1 and 2", "pair.gamma = 0"],
    ),
    "pair-scene-particle-motion-in-file": Case(
        "  gravity = 980.0",
        "  gravity = 980.0, motion = 'fixed'",
        base="case1.nml",
        pieces=["{file}:{line}:", "&particles", "motion = 'fixed'", "sets particles 1 and 2",
                "leave particles.motion out"],
    ),
    # D_h = 1.0 D_1 with gamma = 1: the centres start exactly one diameter apart, the disks
    # touch; the bound is checked in test_pair_dh_bound_is_the_contact_distance below
    "pair-dh-at-contact": Case(
        args=["--set", "pair.gamma=1", "--set", "pair.dh=1.0"],
        base="case1.nml",
        pieces=["{file}", "--set pair.dh=1.0", "&pair", "dh = 1.0", "contact", "allowed: dh >"],
    ),
    # D_h = 20 D_1 puts the upper disk 4 cm above the lower one, beyond the 15 D_1 (3 cm) the
    # window holds above the lowest centre
    "window-above-too-small": Case(
        args=["--set", "pair.dh=20", "--set", "window.above=15"],
        base="case1.nml",
        pieces=[
            "{file}",
            "--set window.above=15",
            "&window",
            "above = 15",
            "particle 1",
            "allowed: above >=",
        ],
    ),
    # a window's rows and particles are placed from y = 0 in double precision: at 10^12 cm the
    # spacing of doubles (1.2e-4 cm) is no longer small against a step's motion; the bound is
    # checked in test_window_position_bound_is_2_to_the_31_spacings_less_the_window below
    "window-particle-too-far-from-y-0": Case(
        args=["--set", "pair.y_upper=1e12"],
        base="case1.nml",
        pieces=[
            "{file}",
            "--set pair.y_upper=1e12",
            f"y(1) = {1e12:.1f} cm",
            "&pair y_upper",
            "window",
            "allowed: |y(1)| <=",
        ],
    ),
    # a 'velocity' end at rest is a wall for the particles (E11): a disk may not start on it
    "particle-overlapping-a-velocity-end-at-rest": Case(
        args=["--set", "domain.lower=velocity", "--set", "particles.y=0.1"],
        base="single.nml",
        pieces=[
            "{file}",
            "--set particles.y=0.1",
            "y(1) = 0.1",
            "lower = 'velocity'",
            "&inlet velocity = 0.0",
            "overlaps the wall at y = 0",
            "allowed: 0.125 < y(1)",
        ],
    ),
    # a pair scene writes particles 1 and 2 itself
    "pair-with-particles-count": Case(
        args=["--set", "particles.count=2"],
        base="case1.nml",
        pieces=[
            "{file}",
            "--set particles.count=2",
            "&pair",
            "gamma = 2.0",
            "count = 2",
            "count = 0",
        ],
    ),
    # dx from the smallest particle's diameter needs a particle
    "cells-per-diameter-without-particles": Case(
        args=["--set", "lbm.cells_per_diameter=12"],
        pieces=[
            "{file}",
            "--set lbm.cells_per_diameter=12",
            "&lbm",
            "cells_per_diameter = 12",
            "without particles",
            "allowed: 0",
        ],
    ),
    # ---- lbm.mach (input/README.md; docs/model.md §1 "Mach-aware set-up")
    # tau - 1/2 = mach nu/(c_s U dx): Ma 0.005 at 12 per D (U = 1.75 cm/s, dx = 1/120 cm) needs
    # tau = 0.506, inside the 0.01 margin above 1/2; a smaller dx would raise it
    "mach-needs-tau-below-the-margin": Case(
        args=["--set", "lbm.cells_per_diameter=12", "--set", "lbm.mach=0.005"],
        base="case1.nml",
        pieces=[
            "{file}",
            "--set lbm.mach=0.005",
            "&lbm",
            "mach = 0.005",
            "0.51 <= tau <= 10",
            "raise lbm.cells_per_diameter",
        ],
    ),
    # the Poiseuille peak 1e-5 cm/s^2 (1 cm)^2/(8 nu) = 1.25e-4 cm/s is so slow that Ma 0.01
    # needs tau = 28.2 on the 0.05 cm lattice; a larger dx would lower it
    "mach-needs-tau-above-the-maximum": Case(
        args=["--set", "lbm.mach=0.01"],
        pieces=[
            "{file}",
            "--set lbm.mach=0.01",
            "&lbm",
            "mach = 0.01",
            "0.51 <= tau <= 10",
            "make lbm.dx larger",
        ],
    ),
    # a fluid at rest has no velocity scale to take a Mach number of
    "mach-without-a-velocity-scale": Case(
        "body_force = 0.0, 1.0e-5",
        "body_force = 0.0, 0.0",
        args=["--set", "lbm.mach=0.05"],
        pieces=[
            "{file}",
            "--set lbm.mach=0.05",
            "&lbm",
            "mach = 0.05",
            "velocity scale",
            "allowed: lbm.mach = 0",
        ],
    ),
    # the guard would stop a run at its target at once
    "mach-above-mach-limit": Case(
        args=["--set", "lbm.mach=0.35"],
        base="case1.nml",
        pieces=["{file}", "--set lbm.mach=0.35", "&lbm", "mach = 0.35", "mach_limit = 0.3"],
    ),
    "mach-negative": Case(
        args=["--set", "lbm.mach=-0.1"],
        pieces=["{file}", "--set lbm.mach=-0.1", "&lbm", "mach = -0.1", "0 < mach <= 1"],
    ),
    # the window follows the lowest free particle: a fixed disk alone leaves nothing to follow
    "window-with-a-fixed-particle-only": Case(
        args=["--set", "particles.motion(1)=fixed", "--set", "window.enabled=.true."],
        base="single.nml",
        pieces=[
            "{file}",
            "--set window.enabled=.true.",
            "&window",
            "enabled = .true.",
            "0 free particles",
            "allowed:",
        ],
    ),
    # ---- derived quantities: every key in range, what follows from them is not ----
    # nu = 0.01/1e-320 overflows: dt = 0 and NaN everywhere (the run used to go on)
    "density-1e-320-gives-infinite-nu": Case(
        "density = 1.0",
        "density = 1e-320",
        pieces=["{file}:{line}:", "&fluid", "density = 1.0e-320", "nu =", "finite nu > 0"],
    ),
    # nu = 1e-320 (subnormal): dt = Infinity
    "viscosity-1e-320-gives-infinite-dt": Case(
        "viscosity = 0.01",
        "viscosity = 1e-320",
        pieces=["{file}:{line}:", "&fluid", "viscosity = 1.0e-320", "finite nu > 0"],
    ),
    # dt = 4e-312 s with steps = 5 ran and exited 0; a dt that small wants a LARGER dx (dt ~
    # dx^2), so advice to refine dx would be the wrong knob
    "viscosity-1e308-gives-subnormal-dt": Case(
        "viscosity = 0.01",
        "viscosity = 1e308",
        pieces=[
            "{file}:{line}:",
            "viscosity = 1.0e308",
            "time step dt",
            f"allowed: {DT_MIN} s <= dt",
            "make lbm.dx larger",
        ],
    ),
    # t_end = 1e9 s at dt = 0.25 dx^2/nu... gives more steps than the bound; the message names
    # the keys that set the count (t_end, and dx and tau through dt)
    "t-end-beyond-the-step-bound": Case(
        "steps = 5",
        "t_end = 1e9",
        pieces=[
            "{file}:{line}:",
            "&run t_end = 1000000000.0",
            f"{round(1e9 / BASE_DT)}",
            f"at most {MAX_STEPS}",
            "raise lbm.tau",
            "make lbm.dx larger",
        ],
    ),
    "steps-beyond-the-bound": Case(
        "steps = 5",
        f"steps = {2 * MAX_STEPS}",
        pieces=["{file}:{line}:", f"steps = {2 * MAX_STEPS}", f"steps <= {MAX_STEPS}"],
    ),
    # ---- scene files without any group: they used to run the 500 x 1250 default scene ----
    "empty-file": Case(
        whole="",
        pieces=["{file}: is empty", "namelist group", "&domain", "--print-defaults"],
    ),
    "comments-only": Case(
        whole="! a scene\n\n   ! that was never written\n",
        pieces=["{file}: holds only comments", "namelist group", "&lbm"],
    ),
    "keys-outside-any-group": Case(
        whole="tau = 0.7\n",
        pieces=["{file}:1:", "'tau'", "outside a group", "&name"],
    ),
    # ---- memory: checked before anything is allocated ----
    # gamma = 100 puts 25 spacings across D_2 = 0.002 cm: dx = 2/25000 cm, 25000 x 100000 cells
    # (hundreds of GiB); the run used to grow until it was killed
    "pair-gamma-100-needs-more-memory-than-the-node": Case(
        args=["--set", "pair.gamma=100"],
        base="case0_box.nml",
        pieces=[
            "{file}",
            "25000 x 100000 cells",
            "GiB per rank",
            "lattices",
            "MemAvailable",
            "lbm.cells_per_diameter",
            "run.memory_limit",
        ],
    ),
    # the base scene's 20 x 6 cells need far more than 1 KiB
    "memory-limit-below-the-need": Case(
        args=["--set", "run.memory_limit=1e-6"],
        pieces=["{file}", "GiB per rank", "20 x 6 cells", "allowed (run.memory_limit)"],
    ),
    # ---- prescribed particles: a constant velocity makes the path known at input ----
    # input/single.nml: D = 0.25 cm at x = 1 of a 2 cm channel; at u = -0.5 cm/s the surface
    # reaches x = 0 at (1 - 0.125)/0.5 = 1.75 s and the centre ends at x = -0.1 cm at t = 2.2 s
    "prescribed-particle-through-the-side-wall": Case(
        args=PRESCRIBED + ["--set", "particles.u=-0.5", "--set", "run.t_end=2.2"],
        base="single.nml",
        pieces=["{file}", "'prescribed'", "u(1) = -0.5", "wall at x = 0", "t = 1.75 s", "2.2 s"],
    ),
    # a fixed disk (D = 0.2) 2 cm below: contact at (2 - (0.25 + 0.2)/2)/2 = 0.8875 s
    "prescribed-particle-into-a-fixed-one": Case(
        args=PRESCRIBED
        + ["--set", "particles.v(1)=-2", "--set", "run.t_end=1.0", "--set", "particles.count=2"]
        + ["--set", "particles.motion(2)=fixed", "--set", "particles.diameter(2)=0.2"]
        + ["--set", "particles.x(2)=1.0", "--set", "particles.y(2)=2.0"],
        base="single.nml",
        pieces=["{file}", "runs into particle 2", "'fixed'", "t = 0.8875 s"],
    ),
    # 50 cm/s is Mach 50 dt/dx / c_s = 0.433 on single.nml's lattice (dx = 0.01, dt = 5e-5 s):
    # the guard would stop the run naming a node; the input check names the particle
    "prescribed-particle-faster-than-the-mach-limit": Case(
        args=PRESCRIBED + ["--set", "particles.v=-50", "--set", "run.t_end=0.001"],
        base="single.nml",
        pieces=["{file}", "particle 1 moves at 50.0 cm/s", "mach_limit = 0.3", SPEED, "lower u(1)"],
    ),
}


@pytest.mark.parametrize("case", CASES.values(), ids=CASES.keys())
def test_bad_input_stops_every_rank_with_one_clear_message_and_no_output(
    tmp_path: Path, case: Case
) -> None:
    """Catches: a missing or vague message (no file/line, group, key, value or range), a
    message per rank, exit status 0, a job that never ends (timeout), output written before the
    input was validated."""
    scene, line = write_scene(tmp_path, case.old, case.new, case.base)
    if case.whole is not None:
        scene.write_text(case.whole)
    outdir = tmp_path / "out"
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    args = [] if case.no_file else [str(scene)]
    args += [*case.args, "--set", f"output.dir={outdir}"]
    proc = dkt(args, cwd)
    msg = assert_clean_failure(proc, outdir, cwd)
    assert "error" in msg
    for piece in case.pieces:
        piece = piece.format(file=scene, line=line)
        assert piece in msg, f"{piece!r} missing from the message:\n{msg}"


def test_a_refused_long_list_is_not_echoed_whole(tmp_path: Path) -> None:
    """100 000 values for the one x of input/single.nml: refused, with the first values and the
    count, not the whole list (1 MB of message before)."""
    values = ", ".join(f"{0.5 + k * 1e-6:.6f}" for k in range(100_000))
    scene, line = write_scene(tmp_path, "  count = 1", f"  count = 1, x = {values}",
                              base="single.nml")
    outdir = tmp_path / "out"
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    proc = run_args([str(scene), "--set", f"output.dir={outdir}"], RANKS, TIMEOUT, cwd, ENV)
    message = assert_clean_failure(proc, outdir, cwd)
    for piece in [f"{scene}:{line}:", "&particles", "x = 0.500000, 0.500001",
                  "... (100000 values)", "too many values (100000)"]:
        assert piece in message, message
    assert len(message) < 1000, f"{len(message)} characters"


def test_misspelt_group_message_lists_lbm_as_a_known_group(tmp_path: Path) -> None:
    """'&lbm' is a prefix of '&lbmm': check the known-group list really names &lbm on its own
    (a message that only echoed the bad name would pass the substring test above)."""
    scene, _ = write_scene(tmp_path, "&lbm", "&lbmm")
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    proc = dkt([str(scene), "--set", f"output.dir={tmp_path / 'out'}"], cwd)
    msg = assert_clean_failure(proc, tmp_path / "out", cwd)
    known = msg.split("known groups:", 1)[1]
    assert re.search(r"&lbm(?![a-z])", known), msg


def test_dx_that_does_not_fit_gets_a_suggestion_that_fits(tmp_path: Path) -> None:
    """The message suggests a dx; width/dx must then be a whole number. Catches a suggestion
    computed with the wrong length or rounding."""
    scene, _ = write_scene(tmp_path, "dx = 0.05", "dx = 0.03")
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    proc = dkt([str(scene), "--set", f"output.dir={tmp_path / 'out'}"], cwd)
    msg = assert_clean_failure(proc, tmp_path / "out", cwd)
    m = re.search(r"e\.g\. dx = ([0-9.eEdD+-]+)", msg)
    assert m, msg
    suggested = float(m.group(1).replace("d", "e").replace("D", "e"))
    cells = 1.0 / suggested  # width = 1.0 cm in the base scene
    assert abs(cells - round(cells)) < 1e-6 and round(cells) >= 3, msg
    # and the suggestion is near the dx asked for (the nearest whole count of cells)
    assert round(cells) in (math.floor(1.0 / 0.03), math.ceil(1.0 / 0.03)), msg


def test_pair_dh_bound_is_the_contact_distance(tmp_path: Path) -> None:
    """The smallest D_h offered is (D_1 + D_2)/2 + collision.range dx, in D_1: with gamma = 1,
    D_1 = 0.2 cm, 25 spacings per diameter (dx = 2 cm/250) and range 1, that is 1 + 0.008/0.2
    = 1.04. Catches a bound computed with D_1 in place of the mean radius sum, or without the
    contact range; just above the bound the scene is accepted, just below it refused."""
    common = ["--set", "pair.gamma=1", "--set", "collision.range=1"]
    common += ["--set", "lbm.cells_per_diameter=25"]
    scene, _ = write_scene(tmp_path, base="case1.nml")
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    outdir = tmp_path / "out"
    proc = dkt([str(scene), *common, "--set", "pair.dh=1.0", "--set", f"output.dir={outdir}"], cwd)
    msg = assert_clean_failure(proc, outdir, cwd)
    bound = number_after("allowed: dh >", msg)
    dx = 2.0 / round(2.0 * 25 / 0.2)
    assert bound == pytest.approx((0.2 + 1.0 * dx) / 0.2, rel=1e-9), msg
    ok = dkt([str(scene), *common, "--set", f"pair.dh={bound * (1 + 1e-6)}", "--check"], cwd)
    assert ok.returncode == 0, ok.stderr
    low = dkt([str(scene), *common, "--set", f"pair.dh={bound * (1 - 1e-6)}", "--check"], cwd)
    assert low.returncode != 0 and "&pair" in low.stderr, low.stderr


def test_window_above_bound_holds_the_particles(tmp_path: Path) -> None:
    """The bound offered for window.above fits: case1 with D_h = 20 D_1 has the upper disk
    (D_1 = 0.2 cm) 20 D_1 above the lower one, so with the 1 D_1 margin the window needs
    20 + 0.5 + 1 = 21.5 D_1 above the lowest centre; the message says so, 21.5 (+ round-off)
    is accepted, 21.4 refused. Catches a bound that forgets the radius or the margin."""
    scene, _ = write_scene(tmp_path, base="case1.nml")
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    outdir = tmp_path / "out"
    common = [str(scene), "--set", "pair.dh=20", "--set", "pair.d1=0.2", "--set", "pair.gamma=2"]
    common += ["--set", "pair.upper=larger", "--set", "window.margin=1"]
    proc = dkt([*common, "--set", "window.above=15", "--set", f"output.dir={outdir}"], cwd)
    msg = assert_clean_failure(proc, outdir, cwd)
    bound = number_after("allowed: above >=", msg)
    assert bound == pytest.approx(20 + 0.5 + 1.0, rel=1e-9), msg
    fits = dkt([*common, "--set", "window.above=21.5001", "--check"], cwd)
    assert fits.returncode == 0, fits.stderr
    short = dkt([*common, "--set", "window.above=21.4", "--check"], cwd)
    assert short.returncode != 0 and "&window" in short.stderr, short.stderr


def test_window_position_bound_is_2_to_the_31_spacings_less_the_window(tmp_path: Path) -> None:
    """The largest |y| offered for a particle of a window scene is 2^31 dx less the window's
    length (docs/model.md §5): case1 with gamma = 1, D_1 = 0.2 cm and 10 spacings per diameter
    has dx = 2 cm/100 and a window of (10 + 15) D_1 = 5 cm. The bound printed (six digits,
    rounded down) holds and is within 1e-5 of that; a pair with its upper centre on the bound
    is accepted by --check, one just beyond it or far below y = 0 is refused. Catches a bound
    in cm instead of spacings, one that forgets the window (or the length a growing window
    may reach), or a check of y instead of |y|."""
    scene, _ = write_scene(tmp_path, base="case1.nml")
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    outdir = tmp_path / "out"
    common = [str(scene), "--set", "pair.gamma=1", "--set", "pair.d1=0.2"]
    common += ["--set", "lbm.cells_per_diameter=10", "--set", "window.below=10"]
    common += ["--set", "window.above=15", "--set", "window.max_above=0"]  # a fixed window
    proc = dkt([*common, "--set", "pair.y_upper=1e9", "--set", f"output.dir={outdir}"], cwd)
    msg = assert_clean_failure(proc, outdir, cwd)
    bound = number_after("2^31 dx - window length =", msg)
    exact = 2.0**31 * (2.0 / 100) - 25 * 0.2
    assert exact * (1 - 1e-5) <= bound <= exact, msg
    on = dkt([*common, "--set", f"pair.y_upper={bound!r}", "--check"], cwd)
    assert on.returncode == 0, on.stderr
    beyond = dkt([*common, "--set", f"pair.y_upper={exact * (1 + 1e-6)!r}", "--check"], cwd)
    assert beyond.returncode != 0 and "2^31 dx" in beyond.stderr, beyond.stderr
    below = dkt([*common, "--set", f"pair.y_upper={-2 * exact!r}", "--check"], cwd)
    assert below.returncode != 0 and "2^31 dx" in below.stderr, below.stderr
    # a window that may grow (window.max_above = 40 D_1) is bounded by its largest length,
    # (10 + 40) D_1 = 10 cm: an upper centre 2.5 cm inside the fixed window's bound is
    # accepted without the growth and refused with it
    inside = f"pair.y_upper={exact - 2.5!r}"
    assert dkt([*common, "--set", inside, "--check"], cwd).returncode == 0
    grown = dkt([*common, "--set", "window.max_above=40", "--set", inside, "--check"], cwd)
    assert grown.returncode != 0 and "window.max_above" in grown.stderr, grown.stderr
    largest = number_after("2^31 dx - window length =", grown.stderr)
    exact_grown = 2.0**31 * (2.0 / 100) - 50 * 0.2
    assert exact_grown * (1 - 1e-5) <= largest <= exact_grown, grown.stderr


def test_a_pair_run_too_short_to_classify_is_warned_about_but_allowed(tmp_path: Path) -> None:
    """--check of case1 with run.t_end = 0.1 s (the pair needs seconds to draft, kiss and
    tumble): exit 0, one warning naming the file, &run t_end and 'too short to classify', no
    error, nothing written. The case1 default t_end gives no such warning (the control)."""
    outdir = tmp_path / "out"
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    args = [str(INPUT / "case1.nml"), "--check", "--set", f"output.dir={outdir}"]
    proc = dkt([*args, "--set", "run.t_end=0.1"], cwd)
    assert proc.returncode == 0, proc.stderr
    assert error_lines(proc.stderr) == [], proc.stderr
    warnings = [ln for ln in proc.stderr.splitlines() if "too short to classify" in ln]
    assert len(warnings) == 1, proc.stderr
    assert warnings[0].startswith("dktlbm: warning"), warnings[0]
    for piece in [str(INPUT / "case1.nml"), "--set run.t_end=0.1", "&run", "t_end"]:
        assert piece in warnings[0], f"{piece!r} missing from the warning:\n{warnings[0]}"
    assert not outdir.exists() and list(cwd.iterdir()) == [], "--check wrote output"
    control = dkt(args, cwd)
    assert control.returncode == 0, control.stderr
    assert "too short to classify" not in control.stderr, control.stderr


def test_missing_namelist_file(tmp_path: Path) -> None:
    """Catches: a read error that hangs the ranks waiting for rank 0, or a message that does not
    say which file."""
    missing = tmp_path / "no_such_scene.nml"
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    outdir = tmp_path / "out"
    proc = dkt([str(missing), "--set", f"output.dir={outdir}"], cwd)
    msg = assert_clean_failure(proc, outdir, cwd)
    assert str(missing) in msg and "cannot open" in msg, msg


@pytest.mark.parametrize(
    "restart",
    [["--restart="], ["--restart", ""], ["--restart", "--set", "run.steps=3"]],
    ids=["equals", "apart", "an-option"],
)
def test_an_empty_restart_value_is_refused(tmp_path: Path, restart: list[str]) -> None:
    """Catches: `--restart=` or `--restart ''` (an unset shell variable) taken as no restart at
    all, which started a fresh run instead of the resumed one the user asked for; and
    `--restart --set ...` (the path forgotten), whose option was taken for the checkpoint."""
    scene, _ = write_scene(tmp_path)
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    outdir = tmp_path / "out"
    proc = dkt([str(scene), "--set", f"output.dir={outdir}", *restart], cwd)
    msg = assert_clean_failure(proc, outdir, cwd)
    assert "option --restart needs a checkpoint file" in msg, msg


def test_a_scene_read_from_a_pipe_is_the_scene_read_from_its_file(tmp_path: Path) -> None:
    """Catches: a scene given as /dev/stdin (or `<(...)`), which has no size, called empty. Its
    --check must print the same lattice as the file's (the output directory named apart)."""
    scene = INPUT / "case1.nml"

    def check(path: str, piped: str) -> str:
        args = [str(EXE), path, "--check", "--set", f"output.dir={tmp_path / 'o'}"]
        # input= makes standard input a pipe, which has no size
        proc = subprocess.run(args, input=piped, capture_output=True, text=True,
                              timeout=TIMEOUT, env=mpi_env(), cwd=tmp_path)
        assert proc.returncode == 0, proc.stderr
        return proc.stdout

    from_pipe = check("/dev/stdin", scene.read_text())
    from_file = check(str(scene), "")
    lattice = [ln for ln in from_file.splitlines() if ln.startswith(("lattice", "dx", "dt"))]
    assert lattice, from_file
    assert all(ln in from_pipe.splitlines() for ln in lattice), (from_pipe, lattice)


# ny = height/dx rows; a slab needs MIN_SLAB_ROWS = 2 rows (docs/design.md, "Data layout": slabs
# with one ghost row each side), so at most ny // 2 ranks can work.
@pytest.mark.parametrize(
    ("height", "ranks"),
    [(0.3, 4), (0.15, 2)],
    ids=["6-rows-on-4-ranks", "3-rows-on-2-ranks"],
)
def test_more_ranks_than_rows_allow_names_the_largest_rank_count(
    tmp_path: Path, height: float, ranks: int
) -> None:
    """Catches: a decomposition that silently gives a rank too few rows (wrong results or a
    crash), a hang, or a message that does not say how many ranks would work."""
    scene, _ = write_scene(tmp_path, "height = 0.3", f"height = {height}")
    ny = round(height / 0.05)
    assert ny // 2 < ranks
    outdir = tmp_path / "out"
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    proc = dkt([str(scene), "--set", f"output.dir={outdir}"], cwd, ranks)
    msg = assert_clean_failure(proc, outdir, cwd)
    assert str(scene) in msg, msg
    assert f"{ny} rows" in msg, msg
    assert re.search(rf"at most {ny // 2} ranks?\b", msg), msg


def test_unwritable_output_directory(tmp_path: Path) -> None:
    """output.dir below a regular file cannot be created (root ignores permissions, a file in
    the path does not). Catches: a hang (only rank 0 creates directories), a crash inside HDF5,
    or a message that does not name output.dir and its value; the file stays untouched."""
    blocker = tmp_path / "file.txt"
    blocker.write_text("not a directory\n")
    outdir = blocker / "out"
    scene, _ = write_scene(tmp_path)
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    proc = dkt([str(scene), "--set", f"output.dir={outdir}"], cwd)
    msg = assert_clean_failure(proc, outdir, cwd)
    assert "output.dir" in msg and str(outdir) in msg, msg
    assert blocker.read_text() == "not a directory\n"


def earlier_run(tmp_path: Path) -> tuple[Path, Path, Path]:
    """The base scene run once (valid, exit 0) into tmp_path/out from tmp_path/cwd: returns
    the scene, the output directory and the working directory."""
    scene, _ = write_scene(tmp_path)
    outdir = tmp_path / "out"
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    first = dkt([str(scene), "--set", f"output.dir={outdir}"], cwd)
    assert first.returncode == 0, first.stderr
    return scene, outdir, cwd


def test_existing_output_is_never_overwritten_without_output_overwrite(tmp_path: Path) -> None:
    """A second run into the same directory fails and leaves the first run's .h5, .xdmf and .log
    byte for byte the same; so does a bad input even with output.overwrite = .true. (validation
    comes before any write). The last run, valid and with output.overwrite = .true., succeeds:
    the control that the directory itself was writable all along."""
    scene, outdir, cwd = earlier_run(tmp_path)
    assert (outdir / "bad.h5").is_file()
    before = tree_digest(outdir)

    again = dkt([str(scene), "--set", f"output.dir={outdir}"], cwd)
    assert again.returncode != 0, "a second run replaced an existing output file"
    lines = error_lines(again.stderr)
    assert len(lines) == 1, again.stderr
    assert str(outdir / "bad.h5") in lines[0] and "output.overwrite" in lines[0], lines[0]
    assert tree_digest(outdir) == before, "the failed run changed the earlier run's files"

    bad = dkt(
        [str(scene), "--set", f"output.dir={outdir}", "--set", "output.overwrite=.true."]
        + ["--set", "lbm.tau=0.3"],
        cwd,
    )
    assert bad.returncode != 0
    assert len(error_lines(bad.stderr)) == 1, bad.stderr
    assert tree_digest(outdir) == before, "a bad input touched the earlier run's files"

    ok = dkt(
        [str(scene), "--set", f"output.dir={outdir}", "--set", "output.overwrite=.true."],
        cwd,
    )
    assert ok.returncode == 0, ok.stderr
    assert list(cwd.iterdir()) == []


def test_any_file_of_an_earlier_run_stops_a_new_one(tmp_path: Path) -> None:
    """Not only the .h5: an output directory holding another file of an earlier run of the
    same scene (here only its log, the .h5 removed) stops the run with one message naming the
    file and the ways out; the log stays byte for byte. output.overwrite lets the run go."""
    scene, outdir, cwd = earlier_run(tmp_path)
    (outdir / "bad.h5").unlink()
    before = tree_digest(outdir)
    again = dkt([str(scene), "--set", f"output.dir={outdir}"], cwd)
    assert again.returncode != 0
    lines = error_lines(again.stderr)
    assert len(lines) == 1, again.stderr
    assert "bad.log" in lines[0] and "output.overwrite" in lines[0] and "--restart" in lines[0]
    assert tree_digest(outdir) == before
    ok = dkt([str(scene), "--set", f"output.dir={outdir}", "--set", "output.overwrite=.true."], cwd)
    assert ok.returncode == 0, ok.stderr


def test_an_option_can_mend_a_bad_value_in_the_file(tmp_path: Path) -> None:
    """README: ranges are checked after the file and every --set are applied. Catches a check
    made while reading the file (the run would stop on tau = 0.3)."""
    scene, _ = write_scene(tmp_path, "tau = 1.0", "tau = 0.3")
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    proc = dkt([str(scene), "--check", "--set", "lbm.tau=0.9"], cwd)
    assert proc.returncode == 0, proc.stderr
    assert error_lines(proc.stderr) == []


@pytest.mark.parametrize("collision", ["mrt", "bgk"])
def test_check_prints_the_derived_lattice_and_writes_nothing(
    tmp_path: Path, collision: str
) -> None:
    """--check on input/inlet_channel.nml: exit 0, the printed dx, dt, tau, nine rates, lattice
    viscosity, Mach and Reynolds numbers, cells, steps, memory per rank and models agree with
    docs/model.md E3/E4 computed here from the scene, and nothing is written (no output directory,
    no runs/ in the working directory). Catches wrong unit conversions (dt, Mach), the wrong E3
    heat-flux rate, BGK not using 1/tau everywhere, and --check that writes or time-steps."""
    width, height, mu, rho, dx, tau, u_in, t_end = 1.0, 8.0, 0.05, 1.0, 0.05, 0.6, 0.5, 40.0
    nu = mu / rho
    nu_lb = (tau - 0.5) / 3.0
    dt = nu_lb * dx**2 / nu  # E3, diffusive scaling
    s_nu = 1.0 / tau
    s_q = 8.0 * (2.0 - s_nu) / (8.0 - s_nu)
    if collision == "mrt":
        rates = [0.0, 1.1, 1.25, 0.0, s_q, 0.0, s_q, s_nu, s_nu]
        free = range(9)
    else:
        rates = [s_nu] * 9
        free = [1, 2, 4, 6, 7, 8]  # rho, jx, jy are conserved: their rate has no effect
    mach = u_in * dt / dx / math.sqrt(1.0 / 3.0)
    reynolds = u_in * width / nu
    nx, ny = round(width / dx), round(height / dx)
    steps = round(t_end / dt)

    outdir = tmp_path / "out"
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    args = [str(INPUT / "inlet_channel.nml"), "--check", "--set", f"lbm.collision={collision}"]
    # s_q is an MRT rate: BGK must ignore it
    args += ["--set", "lbm.s_q=0.3" if collision == "bgk" else "lbm.s_q=0"]
    proc = dkt([*args, "--set", f"output.dir={outdir}"], cwd)
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    assert not outdir.exists() and list(cwd.iterdir()) == [], "--check wrote output"
    assert "performance:" not in out, "--check time-stepped"

    assert number_after("dx =", out) == pytest.approx(dx, rel=1e-5)
    assert number_after("dt =", out) == pytest.approx(dt, rel=1e-5)
    assert number_after("tau =", out) == pytest.approx(tau, abs=1e-5)
    assert number_after("nu =", out) == pytest.approx(nu_lb, rel=1e-5)
    line = next(ln for ln in out.splitlines() if ln.startswith("rates"))
    printed = [float(v) for v in line.split(":", 1)[1].split()]
    assert len(printed) == 9, line
    for k in free:
        assert printed[k] == pytest.approx(rates[k], abs=1e-4), f"s_{k}: {line}"
    assert number_after("Mach", out) == pytest.approx(mach, abs=1e-4)
    assert number_after("Reynolds", out) == pytest.approx(reynolds, rel=1e-3)
    m = re.search(r"cells (\d+) x (\d+) = (\d+), steps (\d+)", out)
    assert m, out
    assert [int(g) for g in m.groups()] == [nx, ny, nx * ny, steps]
    # one lattice (streamed in place, the default) of 9 doubles per node of this rank's ny/2
    # rows: a lower bound (padding, ghost rows and row buffers add a little); a factor 8 (bits),
    # 2 (a second lattice) or 2**10 (KiB) slip fails either bound
    assert "one lattice, streamed in place" in out, out
    lattice_mib = number_after("memory per rank: lattices", out)
    least = 9 * nx * (ny // RANKS) * 8 / 2**20
    assert least <= lattice_mib < 2 * least, out
    models = next(ln for ln in out.splitlines() if ln.startswith("models:"))
    assert ("BGK" if collision == "bgk" else "MRT") in models, models
    assert "velocity" in models and "outflow" in models and "parabolic" in models, models


def test_check_allocates_no_lattice(tmp_path: Path) -> None:
    """--check on a 5000 x 1500 lattice (two lattices of 1.08 GB) validates and reports without
    allocating them: the largest resident size of the process stays below a quarter of one
    lattice. Catches a --check that sets up (allocates and fills) the lattices before it
    prints anything. Run on one rank without mpiexec, so that the process measured is dktlbm."""
    scene, _ = write_scene(tmp_path)
    dx = 0.0002
    nx, ny = round(1.0 / dx), round(0.3 / dx)  # the base scene's 1.0 x 0.3 cm channel
    lattice_bytes = 9 * 8 * nx * ny
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    proc = subprocess.run(
        [str(EXE), str(scene), "--check", "--set", f"lbm.dx={dx}"]
        + ["--set", f"output.dir={tmp_path / 'out'}"],
        cwd=cwd,
        env={**os.environ, **mpi_env(), **ENV},
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 0, proc.stderr
    assert f"cells {nx} x {ny}" in proc.stdout, proc.stdout
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024  # KiB on Linux
    assert before * 1024 < lattice_bytes / 4, "an earlier child was already this large"
    assert peak < lattice_bytes / 4, f"--check reached {peak / 2**20:.0f} MiB resident"
    assert list(cwd.iterdir()) == []


def test_check_refuses_what_the_run_would_refuse_an_earlier_runs_files(tmp_path: Path) -> None:
    """After a run into output.dir, --check into the same directory exits non-zero with the
    run's message (naming the file and output.overwrite) and leaves the files byte for byte;
    with output.overwrite = .true. it passes. Catches a --check that returns 0 for a run that
    will be refused (command A's preview used to be refused only when it ran)."""
    scene, outdir, cwd = earlier_run(tmp_path)
    before = tree_digest(outdir)
    check = dkt([str(scene), "--check", "--set", f"output.dir={outdir}"], cwd)
    assert check.returncode != 0, "--check passed a run that the run itself refuses"
    lines = error_lines(check.stderr)
    assert len(lines) == 1, check.stderr
    assert str(outdir / "bad.h5") in lines[0] and "output.overwrite" in lines[0], lines[0]
    assert tree_digest(outdir) == before
    ok = dkt(
        [str(scene), "--check", "--set", f"output.dir={outdir}"]
        + ["--set", "output.overwrite=.true."],
        cwd,
    )
    assert ok.returncode == 0, ok.stderr
    assert tree_digest(outdir) == before


def resolved_values(text: str) -> dict[str, str]:
    """'key = value' of a --print-defaults listing, by 'group.key'."""
    values, group = {}, ""
    for line in text.splitlines():
        if line.startswith("&"):
            group = line[1:].strip()
        m = re.match(r"\s+(\w+) = (.*?)\s+!", line)
        if m:
            values[f"{group}.{m.group(1)}"] = m.group(2)
    return values


def test_print_defaults_of_a_file_prints_its_resolved_values(tmp_path: Path) -> None:
    """dktlbm FILE --print-defaults --set ... prints the file's values with the options applied
    (the base scene's tau = 1.0, dx from --set), the defaults for keys it leaves out, and the
    listing reads back as a scene; a bad FILE is refused like a run's. Catches the file and
    --set being silently ignored (the defaults printed instead)."""
    scene, _ = write_scene(tmp_path)
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    plain = dkt(["--print-defaults"], cwd, ranks=1)
    assert plain.returncode == 0, plain.stderr
    defaults = resolved_values(plain.stdout)
    given = dkt([str(scene), "--print-defaults", "--set", "lbm.dx=0.025"], cwd, ranks=1)
    assert given.returncode == 0, given.stderr
    values = resolved_values(given.stdout)
    assert values.keys() == defaults.keys()
    assert values["lbm.tau"] == "1.0" != defaults["lbm.tau"]  # from the file (tau = 1.0)
    assert values["lbm.dx"] == "0.025" != defaults["lbm.dx"]  # from --set
    assert values["domain.height"] == "0.3" != defaults["domain.height"]
    assert values["run.t_ref"] == defaults["run.t_ref"]  # not in the file
    back = tmp_path / "back.nml"
    back.write_text(given.stdout)
    again = dkt([str(back), "--print-defaults"], cwd, ranks=1)
    assert again.returncode == 0 and resolved_values(again.stdout) == values, again.stderr
    empty = tmp_path / "empty.nml"
    empty.write_text("")
    bad = dkt([str(empty), "--print-defaults"], cwd, ranks=1)
    assert bad.returncode != 0 and len(error_lines(bad.stderr)) == 1, bad.stderr
    assert list(cwd.iterdir()) == []


def test_a_prescribed_particle_leaving_the_window_stops_the_run_naming_it(
    tmp_path: Path,
) -> None:
    """A path the input cannot check: in a moving window (which follows the free particle 1)
    prescribed particle 2 sinks at 6 cm/s, faster than particle 1 settles, and passes the
    window's lower end. The run stops (exit status 3, one message) naming particle 2, its
    position, which lies on its straight path (x = 0.5, y = 4 - 6 t), and the time. Catches a
    particle that leaves the lattice silently (the run used to go on, exit 0), and a stop that
    loses the output computed before it."""
    outdir = tmp_path / "out"
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    sets = {
        "window.enabled": ".true.",
        "window.below": "3",
        "lbm.cells_per_diameter": "8",
        "particles.count": "2",
        "particles.x(1)": "1.4",
        "particles.motion(2)": "prescribed",
        "particles.diameter(2)": "0.25",
        "particles.x(2)": "0.5",
        "particles.y(2)": "4.0",
        "particles.v(2)": "-6",
        "run.progress_every": "0",
        "output.dir": str(outdir),
    }
    args = [str(INPUT / "single.nml")]
    for key, value in sets.items():
        args += ["--set", f"{key}={value}"]
    proc = run_args(args, RANKS, 120.0, cwd, ENV)
    assert proc.returncode == 3, proc.stderr
    lines = error_lines(proc.stderr)
    assert len(lines) == 1, proc.stderr
    msg = lines[0]
    m = re.search(
        rf"particle 2 \(motion = 'prescribed'\): its centre passed the lower end of the window "
        rf"at \(x, y\) = \(\s*{NUM},\s*{NUM}\) cm, step (\d+) \(t =\s*{NUM} s\)",
        msg,
    )
    assert m, msg
    x, y, t = float(m.group(1)), float(m.group(2)), float(m.group(4))
    assert t > 0.0
    assert x == pytest.approx(0.5, abs=1e-5)
    assert y == pytest.approx(4.0 - 6.0 * t, abs=1e-4)
    # the stop is collective like a guard's: the output is kept up to that step and says why
    with h5py.File(outdir / "single.h5", "r") as h5:
        reason = h5["run"].attrs["stop_reason"]
        reason = text_attr(reason)
        assert reason.startswith("particle: ") and "particle 2" in reason, reason
        assert h5["particles/t"][-1] == pytest.approx(t, rel=1e-9)


def test_readme_preview_has_an_output_dir_of_its_own() -> None:
    """Command A's preview (README and tools/run.sh) sets an output.dir other than the main
    run's runs/case1, so that running the preview first never makes the main run refuse an
    existing output directory. Catches the preview losing its output.dir."""
    for path in (ROOT / "README.md", ROOT / "tools" / "run.sh"):
        text = re.sub(r"\\?\n[#\s]*", " ", path.read_text())
        previews = re.findall(
            r"tools/run\.sh input/case1\.nml 2 --set lbm\.cells_per_diameter"
            r"=12[^`\n]*?output\.dir=(\S+?)[`\s]",
            text,
        )
        assert previews, f"no preview command with an output.dir in {path}"
        assert all(d.rstrip("/") not in ("runs/case1", "") for d in previews), previews


# ---- messages read as text: line breaks, numbers, singular and plural ---------------------------


@pytest.mark.parametrize("args", [[], ["--bogus"], ["-V"]], ids=["no-argument", "bogus", "-V"])
def test_usage_errors_break_lines_instead_of_printing_escapes(tmp_path: Path, args) -> None:
    """A usage error is an error line followed by the usage line, on lines of their own: no
    escaped line break (<0a>) in the text. Catches the message escaping its own line breaks."""
    proc = dkt(args, tmp_path, 1)
    assert proc.returncode != 0
    assert "<0a>" not in proc.stderr, proc.stderr
    lines = proc.stderr.splitlines()
    assert lines[0].startswith("dktlbm: error: "), proc.stderr
    assert any(ln.startswith("usage: dktlbm FILE") for ln in lines[1:]), proc.stderr


def test_computed_numbers_in_a_warning_show_no_round_off_tail(tmp_path: Path) -> None:
    """The too-short warning of case1 quotes the gap of the pair and the time it needs, both
    computed: each number in it has at most 10 significant digits (no 0.25000124999804724).
    Catches a computed value printed with every digit of its binary round-off."""
    args = [str(INPUT / "case1.nml"), "--check", "--set", "run.t_end=0.2"]
    proc = dkt(args, tmp_path, 1)
    assert proc.returncode == 0, proc.stderr
    warning = next(ln for ln in proc.stderr.splitlines() if "too short to classify" in ln)
    numbers = re.findall(r"\d+\.\d+(?:e[-+]?\d+)?", warning)
    assert len(numbers) >= 3, warning
    for n in numbers:
        digits = n.split("e")[0].replace(".", "").lstrip("0")
        assert len(digits) <= 10, f"{n} in: {warning}"


def test_counts_of_one_are_singular(tmp_path: Path) -> None:
    """A run on 1 rank says 'on 1 rank' in the scene and performance lines and '0 kissing
    episodes' (plural for zero) in the pattern line; on 2 ranks 'on 2 ranks'. Catches '1 ranks'."""
    for ranks, word in ((1, "rank"), (2, "ranks")):
        out = tmp_path / f"out{ranks}"
        cwd = tmp_path / f"cwd{ranks}"
        cwd.mkdir()
        args = [
            str(INPUT / "case1.nml"),
            "--set",
            "lbm.cells_per_diameter=6",
            "--set",
            "run.steps=2",
            "--set",
            f"output.dir={out}",
        ]
        proc = dkt(args, cwd, ranks)
        assert proc.returncode == 0, proc.stderr
        scene = next(ln for ln in proc.stdout.splitlines() if ln.startswith("scene "))
        perf = next(ln for ln in proc.stdout.splitlines() if ln.startswith("performance:"))
        assert scene.endswith(f" on {ranks} {word}"), scene
        assert perf.endswith(f" on {ranks} {word})"), perf
        assert re.search(r"\b1 ranks\b", proc.stdout) is None, proc.stdout
        pattern = next(ln for ln in proc.stdout.splitlines() if ln.startswith("DKT pattern"))
        assert "; 0 kissing episodes)" in pattern, pattern


def test_the_summary_prints_a_huge_mach_number_as_a_number(tmp_path: Path) -> None:
    """Catches: `compressibility: Ma^2 = **********` when Ma^2 needs a three-digit exponent (a
    gravity of 1e200 cm/s^2 passes the input checks and --check reports the run it would be)."""
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    proc = dkt([str(ROOT / "input" / "case1.nml"), "--check", "--set", "particles.gravity=1e200",
                "--set", f"output.dir={tmp_path / 'out'}"], cwd)
    line = next(ln for ln in proc.stdout.splitlines() if ln.startswith("compressibility:"))
    assert "*" not in line and "E+194" in line, line
