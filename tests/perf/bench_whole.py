#!/usr/bin/env python3
"""Wall time of whole runs of the DKT scenes in each storage layout, optionally against a build.

A case is a scene file with its own --set options. The defaults are the two the speed figures
quote:

    input/case0_box.nml --set lbm.cells_per_diameter=20 --set run.t_end=6
        two disks in the box (200 x 800, 12 000 steps): particles, contact, series and fields
    input/case1.nml
        the paper's Case 1 in the moving window (500 x 1250, 37 500 steps)

Each run is timed as a whole process (launcher start-up, input, output and finalisation included),
with its CPU time (all ranks) and the largest resident set of one process; where the program
prints its `time per part:` line, the median share of each part follows the table. Every repeat
runs all cases, layouts and executables once, one after the other, so that a slower spell of a
shared machine hits all alike; the ratios are taken within each repeat and then medianed: to the
same executable's double/two_lattice run, and with --baseline-exe to that executable's
double/two_lattice run (an older build that has no storage keys runs without them). Layouts an
executable refuses (asked with --check) are skipped with its message. Standard library only.

    tests/perf/bench_whole.py                                  # build/dktlbm, 2 ranks, 3 repeats
    tests/perf/bench_whole.py --baseline-exe /path/to/old/dktlbm --repeats 5
    tests/perf/bench_whole.py --set run.t_end=0.05 --repeats 1  # a short trial of the tooling
    tests/perf/bench_whole.py --case 'input/case2.nml --set run.t_end=1' --ranks 1 2
"""

from __future__ import annotations

import argparse
import json
import re
import shlex
import shutil
import sys
import tempfile
from pathlib import Path

import benchlib
from benchlib import ROOT

PERFORMANCE = re.compile(r"performance:\s*([0-9.]+(?:[eE][-+]?[0-9]+)?)\s*MLUPS")
PARTS = re.compile(r"^time per part: (.*) \(mean over", re.MULTILINE)
CASES = [
    "input/case0_box.nml --set lbm.cells_per_diameter=20 --set run.t_end=6",
    "input/case1.nml",
]
KIB = 1024


def parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--baseline-exe", help="a second dktlbm to compare with (its double/two_lattice runs)"
    )
    parser.add_argument(
        "--case",
        dest="cases",
        action="append",
        metavar="'FILE [--set GROUP.KEY=VALUE ...]'",
        help="a case, scene file and its options as one string, relative to the repository "
        "root or absolute (repeatable; default: the two above)",
    )
    benchlib.add_common_arguments(parser)
    parser.add_argument(
        "--ranks", type=int, nargs="+", default=[2], help="rank counts (default: 2)"
    )
    parser.add_argument("--repeats", type=int, default=3, help="runs of each (default 3)")
    parser.add_argument("--json", help="also write every run's figures to this JSON file")
    parser.add_argument("--keep", action="store_true", help="keep the runs' output directories")
    args = parser.parse_args()
    args.cases = args.cases or CASES
    if args.repeats < 1 or any(r < 1 for r in args.ranks):
        parser.error("--repeats and --ranks must be positive")
    return args


def case_arguments(case: str, overrides: list[str]) -> tuple[str, list[str]]:
    """(a short name, the scene path and options) of a case string."""
    words = shlex.split(case)
    scene = Path(words[0])
    if not scene.is_absolute():
        scene = ROOT / scene
    if not scene.is_file():
        sys.exit(f"bench_whole: scene {scene} not found")
    options = words[1:] + [part for o in overrides for part in ("--set", o)]
    return case, [str(scene), *options]


def part_shares(output: str) -> dict[str, float]:
    """The `time per part:` line of a run's output as {part: percent of the loop}, or {}."""
    found = PARTS.findall(output)
    if not found:
        return {}
    shares = {}
    for item in found[-1].split(", "):
        name, value, _ = item.rsplit(" ", 2)
        shares[name] = float(value)
    return shares


def print_parts(runs: dict[tuple, list[benchlib.Finished]]) -> None:
    """The median share of the loop's wall time of each part, per case, executable and
    layout (runs whose program prints no such line are left out)."""
    rows = []
    for (case, ranks, which, layout), results in runs.items():
        shares = [s for r in results if (s := part_shares(r.output))]
        if shares:
            names = list(shares[0])
            medians = [benchlib.spread([s[n] for s in shares])[0] for n in names]
            rows.append((case, ranks, which, layout, names, medians))
    if not rows:
        return
    print("\ntime per part, % of the time loop (median of the runs; the program's own line)")
    for case, ranks, which, layout, names, medians in rows:
        parts = ", ".join(f"{n} {m:.1f}" for n, m in zip(names, medians, strict=True))
        print(f"  {which} {layout} {ranks} rank(s) {case}: {parts}")


def main() -> int:
    args = parse_args()
    executables = {"exe": args.exe}
    if args.baseline_exe:
        executables["baseline"] = args.baseline_exe
    for path in executables.values():
        if not Path(path).is_file():
            sys.exit(f"bench_whole: {path} not found (build first: cmake --build --preset release)")
    if shutil.which(args.mpiexec) is None:
        sys.exit(f"bench_whole: MPI launcher {args.mpiexec} not found")
    benchlib.allow_root_mpi()
    cases = [case_arguments(case, args.overrides) for case in args.cases]

    work = Path(tempfile.mkdtemp(prefix="dktlbm-whole-"))
    runs: dict[tuple, list[benchlib.Finished]] = {}
    try:
        # what each executable accepts, per case and rank count
        plan = []
        for case, scene_args in cases:
            for ranks in args.ranks:
                for which, exe in executables.items():
                    if which == "baseline":  # only its double/two_lattice run is compared with
                        precisions, streamings = [benchlib.BASELINE[0]], [benchlib.BASELINE[1]]
                    else:
                        precisions, streamings = args.precisions, args.streaming
                    prefix = benchlib.launcher(args.mpiexec, ranks) + [exe]
                    label = f"{which}, {Path(scene_args[0]).name}, {ranks} rank(s), "
                    for layout in benchlib.probe_layouts(
                        prefix, scene_args, precisions, streamings, work, label
                    ):
                        plan.append((case, scene_args, ranks, which, prefix, layout))
        for repeat in range(args.repeats):
            for number, (case, scene_args, ranks, which, prefix, layout) in enumerate(plan):
                outdir = work / f"run-{repeat}-{number}"
                command = prefix + scene_args + list(layout.options)
                command += ["--set", f"output.dir={outdir}"]
                result = benchlib.run_measured(command)
                if result.returncode != 0:
                    sys.exit(
                        f"bench_whole: run failed (exit {result.returncode}): "
                        f"{shlex.join(command)}\n{result.output[-3000:]}"
                    )
                runs.setdefault((case, ranks, which, layout.name), []).append(result)
                print(
                    f"  run {repeat + 1}: {which} {layout.name} {ranks} rank(s) {case}: "
                    f"{result.wall:.2f} s wall, {result.cpu:.2f} s CPU",
                    flush=True,
                )
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)

    baseline_name = "/".join(benchlib.BASELINE)
    print(f"\nwhole runs, {args.repeats} interleaved runs each, {benchlib.machine_line()}")
    for name, exe in executables.items():
        print(f"  {name}: {exe}")
    rows = []
    for case, _ in cases:
        print(f"\n{case}")
        print(
            f"{'exe':<9}{'layout':<20}{'ranks':>6}{'wall s':>9}{'min':>8}{'max':>8}"
            f"{'CPU s':>8}{'MLUPS':>8}{'peak MiB':>9}{'/ double 2-lat':>16}{'/ baseline':>12}"
        )
        for (run_case, ranks, which, layout), results in runs.items():
            if run_case != case:
                continue
            walls = [r.wall for r in results]
            median, low, high = benchlib.spread(walls)
            cpu = benchlib.spread([r.cpu for r in results])[0]
            mlups = [float(m[-1]) for r in results if (m := PERFORMANCE.findall(r.output))]
            rate = f"{benchlib.spread(mlups)[0]:.1f}" if mlups else "-"
            peak = max(r.max_rss_kib for r in results) / KIB
            ratios = {}
            own = runs.get((case, ranks, which, baseline_name))
            base = runs.get((case, ranks, "baseline", baseline_name))
            for column, ref in (("layout", own), ("baseline", base if which == "exe" else None)):
                if ref:
                    ratios[column] = [r.wall / b.wall for r, b in zip(results, ref, strict=True)]
            text = {
                column: f"{benchlib.spread(values)[0]:.3f}" if values else "-"
                for column, values in ratios.items()
            }
            print(
                f"{which:<9}{layout:<20}{ranks:>6}{median:>9.2f}{low:>8.2f}{high:>8.2f}"
                f"{cpu:>8.2f}{rate:>8}{peak:>9.1f}{text.get('layout', '-'):>16}"
                f"{text.get('baseline', '-'):>12}"
            )
            rows.append(
                {
                    "case": case,
                    "exe": executables[which],
                    "role": which,
                    "layout": layout,
                    "ranks": ranks,
                    "wall_s": walls,
                    "cpu_s": [r.cpu for r in results],
                    "mlups": mlups,
                    "peak_rss_kib": [r.max_rss_kib for r in results],
                    "ratios": ratios,
                }
            )
    print_parts(runs)
    print(
        "\n(wall: median of the runs; ratios of wall times, per repeat then medianed: to the same "
        "executable's double/two_lattice run, and to the baseline executable's; peak: the largest "
        "resident set of one process)"
    )
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
