"""What the benchmark scripts of tests/perf share: launching, storage layouts, statistics.

Standard library and dktlbm.launch (the MPI launch prefix). The scripts import it by plain name
(their own directory is first on sys.path when they run); dktlbm comes from PYTHONPATH=postproc
(ctest sets it) or from the installed package.

Storage layouts are chosen with the input keys lbm.precision ('double' | 'single' |
'single_arith', the last stored as 'single' and collided in 4 bytes) and
lbm.streaming ('two_lattice' | 'in_place'). An executable that refuses a layout (an older build
without the keys, or a combination it does not implement) is asked with --check before any run,
and the layout is skipped with its message. A key the executable does not know is left out when
its value is the default (double, two_lattice), so a build with one of the keys runs both of its
layouts and a build with neither runs the baseline.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

from dktlbm import launch

ROOT = Path(__file__).resolve().parents[2]

PRECISIONS = ("double", "single", "single_arith", "half")
STREAMINGS = ("two_lattice", "in_place")
BASELINE = ("double", "two_lattice")
# the layout of a build without the keys, and the keys' defaults
DEFAULTS = {"precision": BASELINE[0], "streaming": BASELINE[1]}

# Bytes one lattice node moves per time step through memory: 9 populations read and 9 written,
# 8, 4 or 2 bytes each. With two lattices the written lattice is not the read one, and a plain
# store first reads the cache line it writes (write-allocate): another 9 populations read.
# In place, each population is written back where it was read: no extra traffic.
POPULATIONS = 9
VALUE_BYTES = {"double": 8, "single": 4, "single_arith": 4, "half": 2}


def node_bytes(precision: str, streaming: str) -> tuple[int, int]:
    """(bytes read and written per node and step, write-allocate bytes on top)."""
    moved = 2 * POPULATIONS * VALUE_BYTES[precision]
    allocate = POPULATIONS * VALUE_BYTES[precision] if streaming == "two_lattice" else 0
    return moved, allocate


@dataclass(frozen=True)
class Layout:
    """One storage layout and the --set options that select it on a given executable."""

    precision: str
    streaming: str
    options: tuple[str, ...]
    note: str = ""

    @property
    def name(self) -> str:
        return f"{self.precision}/{self.streaming}"

    @property
    def is_baseline(self) -> bool:
        return (self.precision, self.streaming) == BASELINE


def add_common_arguments(parser: argparse.ArgumentParser) -> None:
    """--exe, --mpiexec, --precisions, --streaming and --set, as every dktlbm benchmark takes
    them."""
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="GROUP.KEY=VALUE",
        help="a dktlbm --set option for every run, after the scene's own (repeatable), "
        "e.g. run.t_end=0.05",
    )
    parser.add_argument(
        "--exe",
        default=os.environ.get("DKTLBM_EXE", str(ROOT / "build/dktlbm")),
        help="dktlbm executable (default: $DKTLBM_EXE or build/dktlbm)",
    )
    parser.add_argument(
        "--mpiexec",
        default=os.environ.get("MPIEXEC") or "mpiexec",
        help="MPI launcher (default: $MPIEXEC or mpiexec)",
    )
    parser.add_argument(
        "--precisions",
        nargs="+",
        default=list(PRECISIONS),
        choices=PRECISIONS,
        help="lbm.precision values (default: double single single_arith)",
    )
    parser.add_argument(
        "--streaming",
        nargs="+",
        default=list(STREAMINGS),
        choices=STREAMINGS,
        help="lbm.streaming values (default: two_lattice in_place)",
    )


def allow_root_mpi() -> None:
    """Open MPI refuses to run as root unless told (CI and containers run as root)."""
    for key, value in launch.root_env().items():
        os.environ.setdefault(key, value)


def launcher(mpiexec: str, ranks: int) -> list[str]:
    """The mpiexec prefix for `ranks` ranks; --oversubscribe (Open MPI) only past the cores, so
    that the ranks stay bound to cores."""
    return launch.mpi_prefix(ranks, mpiexec, past_cores_only=True)


def first_error(output: str) -> str:
    """The line of a refused run that says why (dktlbm prefixes it with 'error')."""
    lines = [line.strip() for line in output.splitlines() if line.strip()]
    for line in lines:
        if "error" in line.lower():
            return line
    return lines[-1] if lines else "(no output)"


def probe_layouts(
    prefix: list[str],
    scene_args: list[str],
    precisions: list[str],
    streamings: list[str],
    probe_dir: Path,
    label: str = "",
) -> list[Layout]:
    """The layouts `prefix + scene_args` accepts, asked with --check; prints each one refused.

    prefix is the launcher and executable; scene_args the scene and its own --set options.
    """
    accepted = []
    for precision in precisions:
        for streaming in streamings:
            # Both keys first; then without a key whose value is its default, for an executable
            # that knows one of the keys only (the layout is then still the one asked for).
            keys = {"precision": precision, "streaming": streaming}
            dropped = [k for k, v in keys.items() if DEFAULTS[k] == v]
            tries = [[]] + [[k] for k in dropped] + ([dropped] if len(dropped) == 2 else [])
            failure = None
            for omit in tries:
                options = [
                    part
                    for key, value in keys.items()
                    if key not in omit
                    for part in ("--set", f"lbm.{key}={value}")
                ]
                target = probe_dir / f"probe-{len(list(probe_dir.glob('probe-*')))}"
                check = ["--check", "--set", f"output.dir={target}"]
                result = subprocess.run(
                    prefix + scene_args + options + check, capture_output=True, text=True
                )
                if result.returncode == 0:
                    note = ""
                    if omit:
                        names = " and ".join(f"lbm.{k}" for k in omit)
                        note = f"the executable has no {names}: run without, its default"
                        print(f"  {label}{precision}/{streaming}: {note}", flush=True)
                    accepted.append(Layout(precision, streaming, tuple(options), note))
                    break
                failure = failure or result
            else:
                print(
                    f"  {label}{precision}/{streaming}: skipped, the executable refuses it "
                    f"(exit {failure.returncode}): {first_error(failure.stdout + failure.stderr)}",
                    flush=True,
                )
    return accepted


@dataclass
class Finished:
    """A finished child process: its output, exit status, wall time and resource use."""

    output: str
    returncode: int
    wall: float
    cpu: float
    max_rss_kib: int


def run_measured(command: list[str], cwd: Path | None = None) -> Finished:
    """Run a command to its end; wall time around it, CPU time and peak memory from wait4.

    ru_maxrss of wait4 is the largest resident set of the child and of the descendants it waited
    for (KiB on Linux), so a directly started dktlbm gives its own peak.
    """
    start = time.perf_counter()
    with subprocess.Popen(
        command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=cwd
    ) as proc:
        # one pipe (stderr joined to stdout): reading it to its end cannot block the child.
        # Reaped by wait4, not by Popen, so that its resource use is ours to read.
        output = proc.stdout.read()
        _, status, usage = os.wait4(proc.pid, 0)
        proc.returncode = os.waitstatus_to_exitcode(status)
    wall = time.perf_counter() - start
    return Finished(output, proc.returncode, wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss)


def spread(values: list[float]) -> tuple[float, float, float]:
    """(median, minimum, maximum)."""
    return statistics.median(values), min(values), max(values)


def machine_line() -> str:
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return (
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"load average {load:.2f} at the end"
    )
