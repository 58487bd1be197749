#!/usr/bin/env python3
"""Measure the speed of the fused stream-collide step in million lattice updates per second.

Runs the flow-only 500 x 1250 periodic channel (input/bench_channel.nml) with MRT and BGK
collision on 1 and 2 MPI ranks, several times each, reads the MLUPS figure that dktlbm prints at
the end of a run ("performance: <x> MLUPS ...") and prints the median, minimum and maximum of
each configuration. Only the Python standard library is used.

    tests/perf/bench_mlups.py                        # build/dktlbm, 3 repeats
    tests/perf/bench_mlups.py --steps 2000 --repeats 5 --json bench.json
    ctest --preset perf                              # the same, through ctest (label perf)
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
# The final line of a run; progress lines print "MLUPS <x>" and are not used.
PERFORMANCE = re.compile(r"performance:\s*([0-9]+(?:\.[0-9]*)?(?:[eE][-+]?[0-9]+)?)\s*MLUPS")
# "(<cells> cells x <steps> steps ...)" after the figure, when the program prints it.
WORK = re.compile(r"performance:.*?MLUPS\s*\((\d+)\s*cells\s*x\s*(\d+)\s*steps")


def parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--exe",
        default=os.environ.get("DKTLBM_EXE", str(ROOT / "build/dktlbm")),
        help="dktlbm executable (default: $DKTLBM_EXE or build/dktlbm)",
    )
    parser.add_argument(
        "--scene",
        default=str(ROOT / "input/bench_channel.nml"),
        help="namelist of the benchmark scene",
    )
    parser.add_argument(
        "--mpiexec",
        default=os.environ.get("MPIEXEC") or "mpiexec",
        help="MPI launcher (default: $MPIEXEC or mpiexec)",
    )
    parser.add_argument(
        "--ranks", type=int, nargs="+", default=[1, 2], help="rank counts to measure (default: 1 2)"
    )
    parser.add_argument(
        "--collisions",
        nargs="+",
        default=["mrt", "bgk"],
        choices=["mrt", "bgk"],
        help="collision operators (default: mrt bgk)",
    )
    parser.add_argument("--repeats", type=int, default=3, help="runs per configuration (>= 1)")
    parser.add_argument(
        "--steps", type=int, default=0, help="time steps per run (default: the scene's run.steps)"
    )
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="GROUP.KEY=VALUE",
        help="extra dktlbm --set override (repeatable)",
    )
    parser.add_argument("--json", help="also write the measurements to this JSON file")
    parser.add_argument("--keep", action="store_true", help="keep the runs' output directories")
    args = parser.parse_args()
    if args.repeats < 1:
        parser.error("--repeats must be at least 1")
    if any(r < 1 for r in args.ranks):
        parser.error("--ranks must be positive")
    return args


def launcher(mpiexec: str, ranks: int) -> list[str]:
    """The mpiexec prefix for `ranks` ranks; Open MPI needs --oversubscribe past the cores."""
    command = [mpiexec, "-n", str(ranks)]
    if ranks > (os.cpu_count() or 1):
        version = subprocess.run([mpiexec, "--version"], capture_output=True, text=True)
        if re.search(r"Open MPI|OpenRTE", version.stdout + version.stderr):
            command.append("--oversubscribe")
    return command


def run_once(
    args: argparse.Namespace, collision: str, ranks: int, outdir: Path
) -> tuple[float, str]:
    """One run; returns its MLUPS and what it computed ('625000 cells x 500 steps')."""
    command = launcher(args.mpiexec, ranks) + [
        args.exe,
        args.scene,
        "--set",
        f"lbm.collision={collision}",
        "--set",
        f"output.dir={outdir}",
        "--set",
        "output.overwrite=.true.",
    ]
    if args.steps > 0:
        command += ["--set", f"run.steps={args.steps}"]
    for override in args.overrides:
        command += ["--set", override]
    result = subprocess.run(command, capture_output=True, text=True)
    output = result.stdout + result.stderr
    if result.returncode != 0:
        sys.exit(
            f"bench_mlups: run failed (exit {result.returncode}): {' '.join(command)}\n{output}"
        )
    found = PERFORMANCE.findall(output)
    if not found:
        sys.exit(
            f"bench_mlups: no 'performance: <x> MLUPS' line in the output of "
            f"{' '.join(command)}\n{output}"
        )
    work = WORK.findall(output)
    what = f"{work[-1][0]} cells x {work[-1][1]} steps" if work else "steps of the scene"
    return float(found[-1]), what


def main() -> int:
    args = parse_args()
    for path in (args.exe, args.scene):
        if not Path(path).is_file():
            sys.exit(f"bench_mlups: {path} not found (build first: cmake --build --preset release)")
    if shutil.which(args.mpiexec) is None:
        sys.exit(f"bench_mlups: MPI launcher {args.mpiexec} not found")
    if os.geteuid() == 0:  # Open MPI refuses root unless told
        os.environ.setdefault("OMPI_ALLOW_RUN_AS_ROOT", "1")
        os.environ.setdefault("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")

    work = Path(tempfile.mkdtemp(prefix="dktlbm-bench-"))
    results = []
    what = ""
    try:
        for collision in args.collisions:
            for ranks in args.ranks:
                samples = []
                for repeat in range(args.repeats):
                    outdir = work / f"{collision}-{ranks}-{repeat}"
                    mlups, what = run_once(args, collision, ranks, outdir)
                    samples.append(mlups)
                    print(
                        f"  {collision} on {ranks} rank(s), run {repeat + 1}: "
                        f"{samples[-1]:.2f} MLUPS",
                        flush=True,
                    )
                results.append(
                    {
                        "collision": collision,
                        "ranks": ranks,
                        "mlups": samples,
                        "median": statistics.median(samples),
                    }
                )
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)

    print(
        f"\n{Path(args.scene).name}, {what}, {args.repeats} runs each, "
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores"
    )
    print(f"{'collision':<10}{'ranks':>6}{'median MLUPS':>14}{'min':>9}{'max':>9}{'speed-up':>10}")
    for row in results:
        base = next(
            (
                r["median"]
                for r in results
                if r["collision"] == row["collision"] and r["ranks"] == 1
            ),
            None,
        )
        speedup = f"{row['median'] / base:.2f}" if base else "-"
        print(
            f"{row['collision']:<10}{row['ranks']:>6}{row['median']:>14.2f}"
            f"{min(row['mlups']):>9.2f}{max(row['mlups']):>9.2f}{speedup:>10}"
        )
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
