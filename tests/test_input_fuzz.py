"""Fuzz test of the input: many classes of bad input, and seeded mutations of every scene.

The contract (input/README.md "Errors", README.md: "A bad input stops all ranks with one
message naming the file, line, group, key, value and allowed range, exit status 2, and nothing
written"), checked for every case here on 2 ranks:

- exit status 2 (the documented status for bad input; mpiexec passes the ranks' status on);
- exactly one line `dktlbm: error: ...` on standard error, printed by rank 0: no `[rank N]`
  message (that is fatal_local, for errors one rank sees alone, with MPI_Abort), no Fortran
  runtime error, backtrace or signal text, no MPI_ABORT text (input errors end every rank
  through MPI_Finalize; mpiexec's own "exited with non-zero status" banner is allowed);
- the message names the scene file (and the line or the --set option), the group and key, the
  offending value and, where a range exists, the allowed range as input/README.md states it
  (read from its key tables here, not copied from the program);
- the job ends within TIMEOUT (a rank left waiting in a collective is a hang);
- output.dir, pre-populated with a sentinel file and an earlier run's .h5/.xdmf/.log (of
  another scene name, so that they do not themselves stop the run), is byte for byte the same
  afterwards and holds no new file; the working directory stays empty.

Most cases use --check, which refuses whatever the run refuses at start without allocating
the lattices; cases only a run reaches (--restart) run 5 steps of a 20 x 6 cell scene.

A case the program gets wrong today is marked xfail(strict=True) with the defect as reason:
when the defect is fixed the test reports XPASS and fails, so the mark must be removed.

The generated part mutates each scene of input/ deterministically (seeded) and demands that
the program either accepts the result with --check (exit 0, nothing written) or refuses it
cleanly as above; never a crash (signal, runtime error text), never a hang.
"""

from __future__ import annotations

import random
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from dkt_run import INPUT, ROOT, run_args, tree_digest

RANKS = 2
TIMEOUT = 20.0  # s; each case stops during set-up (about 0.4 s), longer is a hang
EXIT_INPUT = 2  # README.md: bad input exits with status 2
# Open MPI's mpiexec waits 1 s between SIGTERM and SIGKILL when it ends a job after a
# non-zero exit; the ranks have already stopped, so the wait only slows the tests down.
ENV = {"OMPI_MCA_odls_base_sigkill_timeout": "0"}
# text that only a crash produces: gfortran runtime errors and backtraces, signals, a
# rank-local abort (fatal_local) or MPI_Abort where every rank should stop together
CRASH = re.compile(
    r"Fortran runtime error|Backtrace|Error termination|Program received signal|SIGSEGV"
    r"|SIGABRT|SIGFPE|Segmentation fault|core dumped|MPI_ABORT|\[rank \d+\]|^#\d+ ",
    re.MULTILINE,
)


def readme_allowed() -> dict[str, str]:
    """The 'allowed' column of input/README.md's key tables, by 'group.key' (array keys
    without their size), backticks removed."""
    allowed, group = {}, ""
    for line in (ROOT / "input" / "README.md").read_text().splitlines():
        m = re.match(r"### &(\w+)", line)
        if m:
            group = m.group(1)
        m = re.match(r"\| `(\w+)(?:\(\d+\))?` \|[^|]*\|[^|]*\|[^|]*\| ([^|]*) \|", line)
        if m and group:
            allowed[f"{group}.{m.group(1)}"] = m.group(2).replace("`", "").strip()
    return allowed


ALLOWED = readme_allowed()


def poiseuille() -> str:
    """input/poiseuille.nml (20 x 6 cells) running 5 steps instead of 2000 s."""
    text = (INPUT / "poiseuille.nml").read_text()
    assert "t_end = 2000.0" in text
    return text.replace("t_end = 2000.0", "steps = 5")


def populate(outdir: Path) -> dict[str, str]:
    """An output directory as a user has it: a sentinel and an earlier run's files (of a scene
    named 'earlier', so the runs here may write beside them). Returns its digest."""
    outdir.mkdir()
    (outdir / "sentinel.txt").write_text("keep me\n")
    (outdir / "earlier.h5").write_bytes(b"\x89HDF\r\n\x1a\n" + bytes(range(256)) * 4)
    (outdir / "earlier.xdmf").write_text('<?xml version="1.0" ?>\n<Xdmf Version="3.0"/>\n')
    (outdir / "earlier.log").write_text("dktlbm 0.1.0\nscene earlier.nml on 2 ranks\n")
    return tree_digest(outdir)


def prepare(tmp_path: Path, name: str, text: str | bytes) -> tuple[Path, Path, dict, Path]:
    """The scene `text` as tmp_path/name, a populated output directory tmp_path/out (and its
    digest) and an empty working directory tmp_path/cwd."""
    scene = tmp_path / name
    if isinstance(text, bytes):
        scene.write_bytes(text)
    else:
        scene.write_text(text)
    outdir = tmp_path / "out"
    before = populate(outdir)
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    return scene, outdir, before, cwd


def error_lines(stderr: str) -> list[str]:
    return [ln for ln in stderr.splitlines() if "error" in ln.lower() and "dktlbm" in ln]


def assert_no_crash(proc) -> None:
    text = proc.stdout + proc.stderr
    m = CRASH.search(text)
    assert m is None, f"crash text {m.group(0)!r}:\n{proc.stdout}\n{proc.stderr}"
    assert proc.returncode >= 0, f"killed by signal {-proc.returncode}\n{proc.stderr}"


def assert_clean_refusal(proc, outdir: Path, before: dict[str, str], cwd: Path, status: int):
    """The common contract of a refused input; returns the one error message."""
    assert_no_crash(proc)
    assert proc.returncode == status, (
        f"exit status {proc.returncode}, expected {status}\n{proc.stdout}\n{proc.stderr}"
    )
    lines = error_lines(proc.stderr)
    assert len(lines) == 1, f"expected one error message, got {len(lines)}:\n{proc.stderr}"
    assert lines[0].startswith("dktlbm: error: "), lines[0]
    assert tree_digest(outdir) == before, "output.dir was changed by a refused input"
    assert list(cwd.iterdir()) == [], f"files written to the working directory {cwd}"
    return lines[0]


@dataclass
class Bad:
    """One class of bad input: the scene (a text, by default the 5-step poiseuille; `base`
    a scene of input/ instead) with `edit` (old, new) applied once, the command-line `args`,
    and what the message must name. `key` 'group.key' puts '&group' and the key in `pieces`
    and, with `value`, the README's allowed range when `rng` is set. '{file}' and '{line}' in
    pieces are filled with the scene's path and the edited line."""

    edit: tuple[str, str] | None = None
    args: list[str] = field(default_factory=list)
    pieces: list[str] = field(default_factory=list)
    key: str | None = None
    rng: bool = False  # the key's README range must be in the message
    base: str | None = None
    whole: str | bytes | None = None
    check: bool = True  # add --check
    file: bool = True  # pass the scene file
    ranks: int = RANKS
    status: int = EXIT_INPUT
    xfail: str | None = None
    last: list[str] = field(default_factory=list)  # arguments after everything else
    extra: Callable[[str], None] | None = None  # further checks of the message


def need_exceeds_limit(msg: str, limit: float) -> None:
    """The memory message must show a need above the limit, and the limit as given (a
    message saying '0.0 GiB is more than 0.0 GiB' contradicts itself)."""
    m = re.search(r"= ([0-9.eE+-]+) GiB, more than the ([0-9.eE+-]+) GiB allowed", msg)
    assert m, msg
    need, allowed = float(m.group(1)), float(m.group(2))
    assert allowed == pytest.approx(limit, rel=0.01), f"the limit {limit} printed as {allowed}"
    assert need > allowed, msg


def no_control_bytes(msg: str) -> None:
    """A message must show every byte of the input it quotes: no raw control characters."""
    m = re.search(r"[\x00-\x08\x0b-\x1f\x7f]", msg)
    assert m is None, f"raw control byte {m.group(0)!r} in the message: {msg!r}"


def xfail_mark(reason: str | None):
    """A strict xfail for a known defect (reason), no mark without one."""
    if reason is None:
        return ()
    return pytest.mark.xfail(strict=True, reason=reason)


def S(key: str, value: str) -> list[str]:
    return ["--set", f"{key}={value}"]


PRESCRIBED = S("particles.motion", "prescribed") + S("particles.gravity", "0")

CASES: dict[str, Bad] = {
    # ---- values of the wrong kind ----
    "real-given-a-word": Bad(
        ("tau = 1.0", "tau = abc"), key="lbm.tau", rng=True, pieces=["{file}:{line}:", "abc"]
    ),
    "real-given-a-quoted-string": Bad(
        ("tau = 1.0", "tau = '0.7'"), key="lbm.tau", pieces=["{file}:{line}:", "0.7"]
    ),
    "integer-given-a-real": Bad(
        ("steps = 5", "steps = 2.5"), key="run.steps", rng=True, pieces=["{file}:{line}:", "2.5"]
    ),
    "integer-given-a-word": Bad(
        args=S("run.guard_every", "often"), key="run.guard_every", pieces=["often"]
    ),
    "logical-given-a-word": Bad(
        ("progress_every = 0", "progress_every = 0\n/\n&output overwrite = maybe"),
        key="output.overwrite",
        pieces=["maybe", ".true."],
    ),
    "choice-not-in-the-list": Bad(
        ("tau = 1.0", "tau = 1.0, collision = 'lbgk'"),
        key="lbm.collision",
        pieces=["{file}:{line}:", "'lbgk'", "'mrt'", "'bgk'"],
    ),
    "nan-value": Bad(("tau = 1.0", "tau = NaN"), key="lbm.tau", pieces=["{file}:{line}:", "NaN"]),
    "infinite-value": Bad(
        ("viscosity = 0.01", "viscosity = Inf"),
        key="fluid.viscosity",
        pieces=["{file}:{line}:", "Inf"],
    ),
    # in the debug build, which traps floating-point overflow, this also catches a reader that
    # dies (SIGFPE) inside its conversion of the literal instead of refusing it
    "real-overflowing-double": Bad(
        ("width = 1.0", "width = 1e999"),
        key="domain.width",
        pieces=["{file}:{line}:", "1e999"],
    ),
    "integer-overflowing-int32": Bad(
        ("steps = 5", "steps = 99999999999"),
        key="run.steps",
        pieces=["{file}:{line}:", "99999999999"],
    ),
    # ---- ranges of single keys (README's allowed column) ----
    "tau-equal-0.5": Bad(args=S("lbm.tau", "0.5"), key="lbm.tau", rng=True),
    "tau-above-10": Bad(args=S("lbm.tau", "10.5"), key="lbm.tau", rng=True),
    "negative-width": Bad(
        ("width = 1.0", "width = -1.0"), key="domain.width", rng=True, pieces=["width = -1.0"]
    ),
    "zero-height": Bad(
        ("height = 0.3", "height = 0"), key="domain.height", rng=True, pieces=["height = 0"]
    ),
    "mrt-rate-2": Bad(args=S("lbm.s_e", "2.0"), key="lbm.s_e", rng=True),
    "mach-limit-0": Bad(args=S("run.mach_limit", "0"), key="run.mach_limit", rng=True),
    "guard-every-0": Bad(args=S("run.guard_every", "0"), key="run.guard_every", rng=True),
    "negative-steps": Bad(args=S("run.steps", "-3"), key="run.steps", rng=True),
    "substeps-0": Bad(args=S("collision.substeps", "0"), key="collision.substeps", rng=True),
    "checkpoint-keep-0": Bad(
        args=S("run.checkpoint_keep", "0"), key="run.checkpoint_keep", rng=True
    ),
    "negative-ramp-time": Bad(args=S("inlet.ramp_time", "-1"), key="inlet.ramp_time", rng=True),
    "negative-density": Bad(args=S("fluid.density", "-1"), key="fluid.density", rng=True),
    "particle-count-above-the-checkpoint-limit": Bad(
        args=S("particles.count", "1000001"), base="single.nml", key="particles.count", rng=True
    ),
    "negative-diameter": Bad(
        args=S("particles.diameter(1)", "-0.25"),
        base="single.nml",
        pieces=["&particles", "diameter(1)", "-0.25", "> 0"],
    ),
    "cells-per-diameter-below-4": Bad(
        args=S("lbm.cells_per_diameter", "2"),
        base="single.nml",
        key="lbm.cells_per_diameter",
        rng=True,
    ),
    "output-dir-too-long": Bad(
        args=S("output.dir", "/tmp/" + "d" * 300), pieces=["&output", "dir", "256"]
    ),
    # ---- names ----
    "unknown-key": Bad(
        ("tau = 1.0", "tau = 1.0, tua = 0.7"),
        pieces=["{file}:{line}:", "&lbm", "'tua'", "did you mean 'tau'?"],
    ),
    "unknown-group": Bad(
        ("&fluid", "&fuild"), pieces=["{file}:{line}:", "&fuild", "did you mean &fluid?"]
    ),
    "unknown-group-by-set": Bad(
        args=S("fluids.density", "2"), pieces=["--set fluids.density=2", "&fluids", "&fluid"]
    ),
    "unknown-key-by-set": Bad(
        args=S("lbm.dt", "1e-3"), pieces=["--set lbm.dt=1e-3", "&lbm", "'dt'", "keys of &lbm"]
    ),
    # ---- command line ----
    "set-without-equals": Bad(args=["--set", "lbm.tau"], pieces=["--set lbm.tau", "group.key"]),
    "set-without-a-group": Bad(args=["--set", "tau=0.7"], pieces=["--set tau=0.7", "group.key"]),
    "set-as-last-argument": Bad(args=["--set"], pieces=["--set", "group.key=value"]),
    "set-with-empty-value": Bad(args=S("lbm.tau", ""), key="lbm.tau", pieces=["--set lbm.tau="]),
    "unknown-option": Bad(args=["--fast"], pieces=["'--fast'"]),
    "two-scene-files": Bad(args=[str(INPUT / "single.nml")], pieces=["single.nml"]),
    "no-scene-file": Bad(file=False, pieces=["no namelist file"]),
    "scene-file-missing": Bad(
        file=False, args=["/nonexistent/scene.nml"], pieces=["/nonexistent/scene.nml"]
    ),
    "scene-file-is-a-directory": Bad(file=False, args=[str(INPUT)], pieces=[str(INPUT)]),
    # ---- namelist syntax ----
    "index-out-of-range": Bad(
        args=S("particles.x(17)", "1.0"),
        base="single.nml",
        pieces=[
            "--set particles.x(17)=1.0",
            "&particles",
            "x(17)",
            "x(1) to x(1)",
            "particles.count",
        ],
    ),
    "index-zero-in-file": Bad(
        ("x = 1.0", "x(0) = 1.0"),
        base="single.nml",
        pieces=["{file}:{line}:", "&particles", "x(0)", "x(1) to x(1)"],
    ),
    "section-out-of-range": Bad(
        ("x = 1.0", "x(15:17) = 3*1.0"),
        base="single.nml",
        pieces=["{file}:{line}:", "&particles", "x(15:17)", "15", "x(1) to x(1)"],
    ),
    "section-stride-0": Bad(
        ("x = 1.0", "x(1:4:0) = 1.0"),
        base="single.nml",
        pieces=["{file}:{line}:", "&particles", "x(1:4:0)", "stride"],
    ),
    # 99999999999 is a whole number, too large for the index: the message must say out of range
    "index-beyond-the-integer-range": Bad(
        ("x = 1.0", "x(99999999999) = 1.0"),
        base="single.nml",
        pieces=["{file}:{line}:", "&particles", "x(99999999999)", "x(1) to x(1)"],
    ),
    "repeat-count-beyond-the-integer-range": Bad(
        ("diameter = 0.25", "diameter = 2147483648*0.25"),
        base="single.nml",
        pieces=["{file}:{line}:", "&particles", "diameter", "2147483648", "repeat count"],
    ),
    "index-not-whole": Bad(
        ("x = 1.0", "x(1.5) = 1.0"),
        base="single.nml",
        pieces=["{file}:{line}:", "&particles", "x(1.5)"],
    ),
    "unclosed-parenthesis": Bad(
        ("x = 1.0", "x(1 = 1.0"),
        base="single.nml",
        pieces=["{file}:{line}:", "&particles", "x(1", "("],
    ),
    "repeat-count-zero": Bad(
        ("diameter = 0.25", "diameter = 0*0.25"),
        base="single.nml",
        pieces=["{file}:{line}:", "&particles", "diameter", "0*", "repeat count"],
    ),
    "repeat-count-negative": Bad(
        ("diameter = 0.25", "diameter = -2*0.25"),
        base="single.nml",
        pieces=["{file}:{line}:", "&particles", "diameter", "-2*"],
    ),
    "repeat-count-not-whole": Bad(
        ("diameter = 0.25", "diameter = 1.5*0.25"),
        base="single.nml",
        pieces=["{file}:{line}:", "&particles", "diameter", "1.5*", "repeat count"],
    ),
    "more-values-than-the-array": Bad(
        ("body_force = 0.0, 1.0e-5", "body_force = 0.0, 1.0e-5, 2.0"),
        pieces=["{file}:{line}:", "&fluid", "body_force", "2"],
    ),
    "repeats-past-the-array": Bad(
        ("diameter = 0.25", "diameter = 17*0.25"),
        base="single.nml",
        pieces=["{file}:{line}:", "&particles", "diameter", "17", "takes 1 value"],
    ),
    "more-values-than-a-scalar": Bad(
        ("tau = 1.0", "tau = 1.0, 0.8"), pieces=["{file}:{line}:", "&lbm", "tau"]
    ),
    "more-values-than-the-array-by-set": Bad(
        args=S("fluid.body_force", "1,2,3"),
        pieces=["--set fluid.body_force=1,2,3", "&fluid", "body_force"],
    ),
    "unclosed-quote": Bad(
        ("sides = 'wall'", "sides = 'wall"),
        pieces=["{file}:{line}:", "&domain", "sides", "'wall"],
    ),
    "group-not-closed-at-end-of-file": Bad(
        ("t_end = 2000.0, progress_every = 0\n/", "t_end = 2000.0, progress_every = 0"),
        base="poiseuille.nml",
        pieces=["{file}", "&run", "/"],
    ),
    "key-without-equals": Bad(("tau = 1.0", "tau 1.0"), pieces=["{file}:{line}:", "&lbm", "tau"]),
    # a key given twice keeps the last value (README), so the bad last one is what is named
    "duplicate-key-the-last-bad": Bad(
        ("tau = 1.0", "tau = 1.0\n  tau = 0.2"),
        key="lbm.tau",
        rng=True,
        pieces=["tau = 0.2", "{file}:{next}:"],
    ),
    "keys-outside-any-group": Bad(whole="tau = 0.7\n", pieces=["{file}:1:", "'tau'", "group"]),
    "empty-file": Bad(whole="", pieces=["{file}", "empty", "&domain"]),
    "no-known-group": Bad(whole="&lmb tau = 0.7 /\n", pieces=["{file}:1:", "&lmb", "&lbm"]),
    "non-ascii-byte-in-a-key": Bad(
        ("tau = 1.0", "ta\u00e9 = 1.0"), pieces=["{file}:{line}:", "&lbm", "ta"]
    ),
    # an invisible byte shown raw makes the message read "tau = 1.0 is not a real number"
    "control-byte-in-a-value": Bad(
        ("tau = 1.0", "tau = 1.0\x1b"),
        key="lbm.tau",
        pieces=["{file}:{line}:", "not a real number"],
        extra=lambda msg: no_control_bytes(msg),
    ),
    "binary-garbage": Bad(
        whole=bytes(random.Random(7).randrange(256) for _ in range(400)), pieces=["{file}"]
    ),
    # ---- rules that join keys ----
    "periodic-one-end-only": Bad(
        ("upper = 'periodic'", "upper = 'wall'"), pieces=["{file}", "lower", "upper", "periodic"]
    ),
    "taylor-green-with-walls": Bad(
        args=S("initial.flow", "taylor_green"), pieces=["&initial", "taylor_green", "sides"]
    ),
    "dx-not-fitting-the-width": Bad(
        ("dx = 0.05", "dx = 0.03"), pieces=["{file}:{line}:", "&domain", "width", "dx = 0.03"]
    ),
    # 0.1 cm / 0.05 cm = 2 cells across, fewer than the 3 a channel needs
    "fewer-than-3-cells": Bad(
        args=S("domain.width", "0.1"),
        pieces=["--set domain.width=0.1", "&domain", "width = 0.1", "3"],
    ),
    "density-1e-320": Bad(
        ("density = 1.0", "density = 1e-320"),
        pieces=["{file}:{line}:", "&fluid", "density = 1.0e-320", "finite nu > 0"],
    ),
    "viscosity-1e-320": Bad(
        ("viscosity = 0.01", "viscosity = 1e-320"),
        pieces=["{file}:{line}:", "&fluid", "viscosity = 1.0e-320", "finite nu > 0"],
    ),
    "viscosity-1e308": Bad(
        ("viscosity = 0.01", "viscosity = 1e308"),
        pieces=["{file}:{line}:", "&fluid", "viscosity = 1.0e308", "1.0e-12 s <= dt"],
    ),
    "t-end-beyond-the-step-bound": Bad(
        args=S("run.t_end", "1e12") + S("run.steps", "0"),
        pieces=["--set run.t_end=1e12", "&run", "t_end", "at most 1000000000"],
    ),
    "memory-limit-below-the-need": Bad(
        args=S("run.memory_limit", "1e-6"),
        pieces=["{file}", "run.memory_limit", "GiB", "20 x 6 cells"],
        extra=lambda msg: need_exceeds_limit(msg, 1e-6),
    ),
    "pair-gamma-100-memory": Bad(
        args=S("pair.gamma", "100"),
        base="case0_box.nml",
        pieces=["{file}", "25000 x 100000 cells", "GiB per rank", "run.memory_limit"],
    ),
    # ---- particles ----
    "particle-outside-the-channel": Bad(
        args=S("particles.x(1)", "-1.0"),
        base="single.nml",
        pieces=["--set particles.x(1)=-1.0", "&particles", "x(1)", "-1.0", "width"],
    ),
    "particle-touching-a-wall": Bad(
        args=S("particles.x(1)", "0.125"),
        base="single.nml",
        pieces=["--set particles.x(1)=0.125", "&particles", "x(1)", "wall"],
    ),
    "particles-overlapping": Bad(
        args=S("particles.count", "2") + S("particles.x", "1.0,1.1") + S("particles.y", "4,4"),
        base="single.nml",
        pieces=["&particles", "overlap", "1", "2"],
    ),
    "particle-too-few-cells": Bad(
        args=S("particles.diameter(1)", "0.03"),
        base="single.nml",
        pieces=["--set particles.diameter(1)=0.03", "&particles", "diameter(1)", "4", "dx"],
    ),
    "fixed-particle-moving": Bad(
        args=S("particles.motion(1)", "fixed") + S("particles.v(1)", "-1"),
        base="single.nml",
        pieces=["&particles", "'fixed'", "v(1)", "-1"],
    ),
    "particles-with-periodic-ends": Bad(
        args=S("domain.lower", "periodic") + S("domain.upper", "periodic"),
        base="single.nml",
        pieces=["&domain", "periodic", "particle"],
    ),
    "prescribed-particle-leaving-the-channel": Bad(
        args=PRESCRIBED + S("particles.u", "-0.5") + S("run.t_end", "2.2"),
        base="single.nml",
        pieces=["{file}", "'prescribed'", "u(1) = -0.5", "wall at x = 0"],
    ),
    "prescribed-particle-entering-a-fixed-one": Bad(
        args=PRESCRIBED
        + S("particles.v(1)", "-2")
        + S("run.t_end", "1.0")
        + S("particles.count", "2")
        + S("particles.motion(2)", "fixed")
        + S("particles.diameter(2)", "0.2")
        + S("particles.x(2)", "1.0")
        + S("particles.y(2)", "2.0"),
        base="single.nml",
        pieces=["{file}", "runs into particle 2", "'fixed'"],
    ),
    # ---- the DKT pair and window ----
    "pair-gamma-below-1": Bad(
        args=S("pair.gamma", "0.5"), base="case1.nml", key="pair.gamma", rng=True
    ),
    "pair-dh-inside-contact": Bad(
        args=S("pair.dh", "0.7"),
        base="case1.nml",
        pieces=["--set pair.dh=0.7", "&pair", "dh = 0.7", "contact", "allowed: dh >"],
    ),
    "window-too-short": Bad(
        args=S("pair.dh", "20"),
        base="case1.nml",
        pieces=["{file}:", "&window", "above = 15.0", "particle 1", "allowed: above >="],
    ),
    "window-below-under-1": Bad(
        args=S("window.below", "0.5"), base="case1.nml", key="window.below", rng=True
    ),
    "diagnostics-release-below-enter": Bad(
        args=S("diagnostics.enter_d1", "0.5"),
        base="case1.nml",
        pieces=["--set diagnostics.enter_d1=0.5", "&diagnostics", "enter_d1 = 0.5", "release"],
    ),
    # ---- parallel layout and output ----
    # 0.15 cm / 0.05 cm = 3 rows; a slab needs 2 rows, so 2 ranks are too many
    "ranks-too-many-for-the-rows": Bad(
        args=S("domain.height", "0.15"), pieces=["{file}", "3 rows", "at most 1 rank"]
    ),
    "output-dir-below-a-file": Bad(
        args=S("output.dir", "{blocker}/out"), check=False, pieces=["output.dir", "{blocker}/out"]
    ),
    "check-with-an-earlier-runs-files": Bad(
        args=["{earlier}"], pieces=["bad.h5", "output.overwrite"]
    ),
    "restart-file-missing": Bad(
        args=["--restart", "/nonexistent/chk.h5"], check=False, pieces=["/nonexistent/chk.h5"]
    ),
    "restart-file-not-hdf5": Bad(
        args=["--restart", "{notes}"], check=False, pieces=["{notes}", "HDF5"]
    ),
    "restart-without-a-file": Bad(last=["--restart"], check=False, pieces=["--restart"]),
    # the option after --restart is taken for the file name: the message must say so
    "restart-followed-by-an-option": Bad(
        args=["--restart", "--check"], check=False, pieces=["--restart --check", "'--check'"]
    ),
}


@pytest.mark.parametrize(
    "case",
    [
        pytest.param(c, marks=xfail_mark(c.xfail))
        for c in CASES.values()
    ],
    ids=list(CASES),
)
def test_bad_input_class(tmp_path: Path, case: Bad) -> None:
    """One class of bad input: refused with exit status 2 and one message from rank 0 that
    names the file, group.key, value (and range), within TIMEOUT, nothing written. Catches a
    crash, a hang, a per-rank or missing message, a message without the key or value, and
    output written before the input was validated."""
    refuse(tmp_path, case, case.check)


def refuse(tmp_path: Path, case: Bad, check: bool) -> str:
    """Run `case` (with --check if `check`) in tmp_path, assert the whole contract; returns
    the message with tmp_path replaced by '<tmp>'."""
    text = (INPUT / case.base).read_text() if case.base else poiseuille()
    line = next_line = 0
    if case.edit is not None:
        old, new = case.edit
        assert text.count(old) == 1, f"{old!r} must occur once in the base scene"
        line = text[: text.index(old)].count("\n") + 1
        next_line = line + 1
        text = text.replace(old, new)
    if case.whole is not None:
        text = case.whole
    scene, outdir, before, cwd = prepare(tmp_path, "bad.nml", text)
    blocker = tmp_path / "file.txt"
    blocker.write_text("not a directory\n")
    notes = tmp_path / "notes.h5"
    notes.write_text("these are notes, not a checkpoint\n")
    earlier = outdir / "bad.h5"  # a file of an earlier run of this very scene
    subst = {"blocker": str(blocker), "notes": str(notes), "earlier": ""}
    args = [a.format(**subst) for a in case.args]
    if "{earlier}" in case.args:
        earlier.write_bytes(b"\x89HDF\r\n\x1a\n earlier run of bad.nml")
        before = tree_digest(outdir)
        args = [a for a in args if a]
    if case.file:
        args = [str(scene), *args]
    if check:
        args.append("--check")
    if not any(a.startswith("output.dir=") for a in args):
        args += ["--set", f"output.dir={outdir}"]

    if case.last:
        args += case.last
    proc = run_args(args, case.ranks, TIMEOUT, cwd, ENV)
    msg = assert_clean_refusal(proc, outdir, before, cwd, case.status)
    assert blocker.read_text() == "not a directory\n"

    pieces = [p.format(file=scene, line=line, next=next_line, **subst) for p in case.pieces]
    if case.key is not None:
        group, key = case.key.split(".")
        pieces += [f"&{group}", key]
        if case.rng:
            pieces.append(ALLOWED[case.key])
        # a value given by --set: the message names the option, and so the value
        pieces += [f"--set {a}" for a in case.args if a.startswith(f"{case.key}=")]
    for piece in pieces:
        assert piece in msg, f"{piece!r} missing from the message:\n{msg}"
    if case.extra is not None:
        case.extra(msg)
    return msg.replace(str(tmp_path), "<tmp>")


# a refusal of each kind: a range, a name, a syntax error, a joint rule, a particle path, the
# memory of gamma = 100 (the run would try to allocate hundreds of GiB without the check)
ALIKE = [
    "tau-equal-0.5",
    "unknown-group",
    "repeat-count-zero",
    "particles-overlapping",
    "pair-dh-inside-contact",
    "prescribed-particle-leaving-the-channel",
    "pair-gamma-100-memory",
]


@pytest.mark.parametrize("name", ALIKE)
def test_the_run_refuses_like_check(tmp_path: Path, name: str) -> None:
    """The classes above mostly use --check; the run itself must refuse the same input with
    the same message, before it writes anything (output.dir and the working directory stay
    as they were). Catches a check that only --check makes, or a run that writes its output
    files before validating."""
    (tmp_path / "check").mkdir()
    (tmp_path / "run").mkdir()
    by_check = refuse(tmp_path / "check", CASES[name], check=True)
    by_run = refuse(tmp_path / "run", CASES[name], check=False)
    # MemAvailable (the limit when run.memory_limit = 0) moves between the two runs
    free = re.compile(r"[0-9.]+ GiB allowed \(MemAvailable")
    assert free.sub("", by_run) == free.sub("", by_check)


def test_there_are_at_least_40_classes() -> None:
    """The brief of this file: at least 40 kinds of mistake, every one a distinct case."""
    assert len(CASES) >= 40


# ---- generated: seeded mutations of every scene of input/ ----

SEED = 20140301  # fixed, so a failure repeats; change it to explore other mutations
SCENES = sorted(p.name for p in INPUT.glob("*.nml"))
GARBAGE = ["1..2", "1e", "0x1F", "--3", "1.0.0", "+-1", "1e+", "NaN", "1d400", "abc", "3*", "'"]


def _drop_slash(text: str, rnd: random.Random) -> str:
    """Remove one group terminator '/'."""
    ends = [m.start() for m in re.finditer(r"^\s*/\s*$", text, re.MULTILINE)]
    i = rnd.choice(ends)
    return text[:i] + text[i:].replace("/", "", 1)


def _duplicate_key(text: str, rnd: random.Random) -> str:
    """Repeat one 'key = value' line right after itself (valid: the last one wins)."""
    lines = text.splitlines(keepends=True)
    items = [k for k, ln in enumerate(lines) if "=" in ln and not ln.lstrip().startswith("!")]
    k = rnd.choice(items)
    return "".join(lines[: k + 1] + [lines[k]] + lines[k + 1 :])


def _garbage_number(text: str, rnd: random.Random) -> str:
    """Replace one number by something that is not one."""
    nums = [m.span() for m in re.finditer(r"(?<![\w.])[-+]?\d+\.?\d*(?:[eEdD][-+]?\d+)?", text)]
    nums = [s for s in nums if not text[: s[0]].rsplit("\n", 1)[-1].lstrip().startswith("!")]
    a, b = rnd.choice(nums)
    return text[:a] + rnd.choice(GARBAGE) + text[b:]


def _truncate(text: str, rnd: random.Random) -> str:
    """Cut the file in the middle of a line of a group."""
    lines = [m.start() for m in re.finditer(r"^\s+\w+\s*=", text, re.MULTILINE)]
    start = rnd.choice(lines)
    end = text.index("\n", start)
    return text[: rnd.randrange(start + 1, end)]


def _unknown_group(text: str, rnd: random.Random) -> str:
    """Rename one group to a name the program does not know."""
    groups = [m.span(1) for m in re.finditer(r"^&(\w+)", text, re.MULTILINE)]
    a, b = rnd.choice(groups)
    name = text[a:b]
    return text[:a] + name[::-1] + "x" + text[b:]


def _non_ascii(text: str, rnd: random.Random) -> bytes:
    """Insert a non-ASCII or control byte (Latin-1 high byte, NUL, DEL, a UTF-8 sequence)."""
    data = text.encode()
    body = data.index(b"&")  # somewhere inside the groups, not only in the header comment
    i = rnd.randrange(body, len(data))
    byte = rnd.choice([b"\xe9", b"\x00", b"\x7f", b"\xff", "\u00b5".encode(), b"\x1b"])
    return data[:i] + byte + data[i:]


def _drop_equals(text: str, rnd: random.Random) -> str:
    """Remove one '=' of a key outside comments."""
    eqs = [m.start() for m in re.finditer(r"=", text)]
    eqs = [i for i in eqs if "!" not in text[:i].rsplit("\n", 1)[-1]]
    i = rnd.choice(eqs)
    return text[:i] + " " + text[i + 1 :]


def _punctuation(text: str, rnd: random.Random) -> str:
    """Replace one character of a group's body by namelist punctuation."""
    body = text.index("&")
    i = rnd.randrange(body, len(text))
    return text[:i] + rnd.choice("&/=,*()'\"!$:;") + text[i + 1 :]


MUTATIONS = {
    "drop-slash": _drop_slash,
    "duplicate-key": _duplicate_key,
    "garbage-number": _garbage_number,
    "truncate-mid-line": _truncate,
    "unknown-group": _unknown_group,
    "non-ascii-byte": _non_ascii,
    "drop-equals": _drop_equals,
    "punctuation": _punctuation,
}


# every scene gets half of the mutations and every mutation half of the scenes (alternating),
# which keeps the file's run time near a minute on 2 busy cores
PAIRS = [
    (scene, mutation)
    for i, scene in enumerate(SCENES)
    for j, mutation in enumerate(MUTATIONS)
    if (i + j) % 2 == 0
]


def mutate(scene: str, mutation: str) -> str | bytes:
    """input/<scene> changed by `mutation`, seeded by both names (the same on every run)."""
    return MUTATIONS[mutation](
        (INPUT / scene).read_text(), random.Random(f"{SEED}:{scene}:{mutation}")
    )


@pytest.mark.parametrize(
    ("scene", "mutation"),
    PAIRS,
    ids=[f"{s}-{m}" for s, m in PAIRS],
)
def test_mutated_scene_is_accepted_or_refused_cleanly(
    tmp_path: Path, scene: str, mutation: str
) -> None:
    """A seeded mutation of input/<scene>: --check either accepts it (exit 0, no error line) or
    refuses it as a bad input (exit 2, one message from rank 0 naming the mutated file);
    either way no crash, no hang and nothing written. Catches parser crashes (an index past
    a buffer, an unhandled I/O status), per-rank messages and hangs on input nobody wrote by
    hand. The scene and mutation seed the generator, so a failure repeats."""
    original = (INPUT / scene).read_text()
    mutated = mutate(scene, mutation)
    assert mutated not in (original, original.encode()), "the mutation changed nothing"
    path, outdir, before, cwd = prepare(tmp_path, f"m_{Path(scene).stem}.nml", mutated)
    args = [str(path), "--check", "--set", f"output.dir={outdir}"]
    proc = run_args(args, RANKS, TIMEOUT, cwd, ENV)
    assert_no_crash(proc)
    if proc.returncode == 0:
        assert error_lines(proc.stderr) == [], proc.stderr
        assert tree_digest(outdir) == before and list(cwd.iterdir()) == [], "--check wrote"
        return
    msg = assert_clean_refusal(proc, outdir, before, cwd, EXIT_INPUT)
    assert str(path) in msg, f"the message does not name the scene file:\n{msg}"


def test_a_byte_order_mark_is_skipped_or_named(tmp_path: Path) -> None:
    """input/poiseuille.nml saved with a UTF-8 byte-order mark: --check accepts it (the mark
    is not part of the namelist), or refuses it with one message that calls it a byte-order
    mark. Catches a refusal that echoes three invisible bytes as a key outside a group. The
    same file with CRLF line ends and tabs is the control: accepted."""
    text = (INPUT / "poiseuille.nml").read_text()
    control, outdir, before, cwd = prepare(tmp_path, "crlf.nml", text.replace("\n", "\r\n"))
    ok = run_args(
        [str(control), "--check", "--set", f"output.dir={outdir}"], RANKS, TIMEOUT, cwd, ENV
    )
    assert_no_crash(ok)
    assert ok.returncode == 0, ok.stderr
    scene = tmp_path / "bom.nml"
    scene.write_bytes(b"\xef\xbb\xbf" + text.encode())
    proc = run_args(
        [str(scene), "--check", "--set", f"output.dir={outdir}"], RANKS, TIMEOUT, cwd, ENV
    )
    assert_no_crash(proc)
    if proc.returncode != 0:
        msg = assert_clean_refusal(proc, outdir, before, cwd, EXIT_INPUT)
        assert "byte-order mark" in msg or "BOM" in msg, msg
    assert tree_digest(outdir) == before and list(cwd.iterdir()) == []
