#!/usr/bin/env python3
"""Measure the speed of the fused stream-collide step in million lattice updates per second.

Runs the flow-only 500 x 1250 periodic channel (input/bench_channel.nml) with MRT and BGK
collision, in each storage layout (lbm.precision double/single x lbm.streaming
two_lattice/in_place), on 1 and 2 MPI ranks, reads the MLUPS figure that dktlbm prints at the end
of a run ("performance: <x> MLUPS ...") and prints the median, minimum and maximum of each
configuration. Every repeat runs all configurations once, one after the other (interleaved), so
that a slower spell of a shared machine hits all of them alike; the ratio of a layout to double
on two lattices is taken within each repeat and then medianed. Layouts the executable refuses
(asked with --check first) are skipped with its message, so the script runs on builds without
the keys too (the baseline then runs without them).

Then the memory of each layout: the peak resident set of one rank started without mpiexec, on
the scene and on a tiny lattice of it (the fixed cost: program, MPI, HDF5), divided by the
difference in cells; the output buffers of the final field write are part of the peak. Beside
it, the lattice memory dktlbm itself reports. Only the Python standard library is used.

    tests/perf/bench_mlups.py                        # build/dktlbm, 3 repeats
    tests/perf/bench_mlups.py --steps 2000 --repeats 5 --json bench.json
    tests/perf/bench_mlups.py --collisions mrt --precisions double single --streaming in_place
    ctest --preset perf                              # the same, through ctest (label perf)
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import sys
import tempfile
from pathlib import Path

import benchlib
from benchlib import ROOT

# The final line of a run; progress lines print "MLUPS <x>" and are not used.
PERFORMANCE = re.compile(r"performance:\s*([0-9]+(?:\.[0-9]*)?(?:[eE][-+]?[0-9]+)?)\s*MLUPS")
# "(<cells> cells x <steps> steps ...)" after the figure, when the program prints it.
WORK = re.compile(r"performance:.*?MLUPS\s*\((\d+)\s*cells\s*x\s*(\d+)\s*steps")
# The start-up summary: "cells 500 x 1250 = 625000, ..." and "memory per rank: lattices 86.31 MiB"
CELLS = re.compile(r"^cells\s+\d+\s*x\s*\d+\s*=\s*(\d+)", re.MULTILINE)
LATTICE_MIB = re.compile(r"memory per rank:\s*lattices\s*([0-9.]+)\s*MiB")
# The fixed cost of a run: the benchmark scene cut to 50 x 50 cells (0.2 cm at dx = 0.004 cm)
TINY = ["domain.width=0.2", "domain.height=0.2"]
KIB = 1024


def parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--scene",
        default=str(ROOT / "input/bench_channel.nml"),
        help="namelist of the benchmark scene",
    )
    benchlib.add_common_arguments(parser)
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
        "--tiny",
        nargs="+",
        default=TINY,
        metavar="GROUP.KEY=VALUE",
        help="--set options that cut the scene to a tiny lattice, the fixed cost of the memory "
        "figure (default: %(default)s)",
    )
    parser.add_argument(
        "--no-memory", action="store_true", help="skip the memory measurement of each layout"
    )
    parser.add_argument("--json", help="also write the measurements to this JSON file")
    parser.add_argument("--keep", action="store_true", help="keep the runs' output directories")
    args = parser.parse_args()
    if args.repeats < 1:
        parser.error("--repeats must be at least 1")
    if any(r < 1 for r in args.ranks):
        parser.error("--ranks must be positive")
    return args


def run_once(
    args: argparse.Namespace, collision: str, layout: benchlib.Layout, ranks: int, outdir: Path
) -> tuple[float, str]:
    """One run; returns its MLUPS and what it computed ('625000 cells x 500 steps')."""
    command = benchlib.launcher(args.mpiexec, ranks) + [
        args.exe,
        args.scene,
        *layout.options,
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
    result = benchlib.run_measured(command)
    output = result.output
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


def peak_memory(args: argparse.Namespace, layout: benchlib.Layout, outdir: Path) -> dict:
    """Peak resident memory per cell of one rank in `layout`: the scene minus its tiny cut.

    Both runs start dktlbm directly (an MPI singleton), so that wait4 reports its own peak and
    not the launcher's.
    """
    sizes = {}
    for name, cut in (("scene", []), ("tiny", args.tiny)):
        command = [args.exe, args.scene, *layout.options]
        for option in [*args.overrides, *cut, "run.steps=10", f"output.dir={outdir}/{name}"]:
            command += ["--set", option]
        command += ["--set", "output.overwrite=.true."]
        result = benchlib.run_measured(command)
        cells = CELLS.search(result.output)
        lattices = LATTICE_MIB.search(result.output)
        if result.returncode != 0 or not cells:
            sys.exit(
                f"bench_mlups: memory run failed (exit {result.returncode}): "
                f"{' '.join(command)}\n{result.output}"
            )
        sizes[name] = (
            int(cells.group(1)),
            result.max_rss_kib * KIB,
            float(lattices.group(1)) if lattices else float("nan"),
        )
    (cells, rss, lattice_mib), (tiny_cells, tiny_rss, _) = sizes["scene"], sizes["tiny"]
    per_cell = (rss - tiny_rss) / (cells - tiny_cells)
    return {
        "layout": layout.name,
        "cells": cells,
        "peak_rss_bytes": rss,
        "tiny_cells": tiny_cells,
        "tiny_peak_rss_bytes": tiny_rss,
        "bytes_per_cell": per_cell,
        "reported_lattice_bytes_per_cell": lattice_mib * KIB * KIB / cells,
    }


def ratio_to_baseline(results: dict, key: tuple[str, str, int]) -> list[float]:
    """Per-repeat ratios of one configuration's MLUPS to double/two_lattice of the same kind."""
    collision, _, ranks = key
    base = results.get((collision, "/".join(benchlib.BASELINE), ranks))
    if not base:
        return []
    return [run / ref for run, ref in zip(results[key], base, strict=True)]


def main() -> int:
    args = parse_args()
    for path in (args.exe, args.scene):
        if not Path(path).is_file():
            sys.exit(f"bench_mlups: {path} not found (build first: cmake --build --preset release)")
    if shutil.which(args.mpiexec) is None:
        sys.exit(f"bench_mlups: MPI launcher {args.mpiexec} not found")
    benchlib.allow_root_mpi()

    work = Path(tempfile.mkdtemp(prefix="dktlbm-bench-"))
    results: dict[tuple[str, str, int], list[float]] = {}
    memory = []
    what = ""
    try:
        print("storage layouts:", flush=True)
        layouts = {
            ranks: benchlib.probe_layouts(
                benchlib.launcher(args.mpiexec, ranks) + [args.exe],
                [args.scene, *(part for o in args.overrides for part in ("--set", o))],
                args.precisions,
                args.streaming,
                work,
                label=f"{ranks} rank(s), ",
            )
            for ranks in args.ranks
        }
        if not any(layouts.values()):
            sys.exit("bench_mlups: the executable refuses every storage layout asked for")
        for repeat in range(args.repeats):
            for collision in args.collisions:
                for ranks in args.ranks:
                    for layout in layouts[ranks]:
                        outdir = work / f"{collision}-{layout.precision}-{layout.streaming}-{ranks}"
                        mlups, what = run_once(args, collision, layout, ranks, outdir)
                        results.setdefault((collision, layout.name, ranks), []).append(mlups)
                        print(
                            f"  run {repeat + 1}: {collision} {layout.name} on {ranks} rank(s): "
                            f"{mlups:.2f} MLUPS",
                            flush=True,
                        )
        if not args.no_memory:
            one_rank = layouts.get(1) or next(v for v in layouts.values() if v)
            for layout in one_rank:
                memory.append(
                    peak_memory(
                        args, layout, work / f"memory-{layout.precision}-{layout.streaming}"
                    )
                )
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)

    print(
        f"\n{Path(args.scene).name}, {what}, {args.repeats} interleaved runs each, "
        f"{benchlib.machine_line()}"
    )
    print(
        f"{'collision':<10}{'layout':<20}{'ranks':>6}{'median MLUPS':>14}{'min':>9}{'max':>9}"
        f"{'speed-up':>10}{'ratio':>8}{'min':>7}{'max':>7}"
    )
    rows = []
    for key, samples in results.items():
        collision, layout, ranks = key
        median, low, high = benchlib.spread(samples)
        one = results.get((collision, layout, 1))
        speedup = f"{median / benchlib.spread(one)[0]:.2f}" if one else "-"
        ratios = ratio_to_baseline(results, key)
        ratio = "".join(f"{r:>7.3f}" for r in benchlib.spread(ratios)) if ratios else "      -"
        print(
            f"{collision:<10}{layout:<20}{ranks:>6}{median:>14.2f}{low:>9.2f}{high:>9.2f}"
            f"{speedup:>10} {ratio}"
        )
        rows.append(
            {
                "collision": collision,
                "layout": layout,
                "ranks": ranks,
                "mlups": samples,
                "median": median,
                "ratio_to_baseline": ratios,
            }
        )
    print("(ratio: to double/two_lattice of the same collision and ranks, per run, then medianed)")

    if memory:
        print(
            f"\nmemory of one rank, peak resident set ({memory[0]['cells']} cells) minus the tiny "
            f"lattice's ({memory[0]['tiny_cells']} cells), per cell"
        )
        print(f"{'layout':<20}{'B/cell':>9}{'MiB per 1e6 cells':>19}{'lattices (reported)':>21}")
        for row in memory:
            print(
                f"{row['layout']:<20}{row['bytes_per_cell']:>9.1f}"
                f"{row['bytes_per_cell'] * 1e6 / KIB / KIB:>19.1f}"
                f"{row['reported_lattice_bytes_per_cell']:>17.1f} B/cell"
            )
    if args.json:
        Path(args.json).write_text(json.dumps({"runs": rows, "memory": memory}, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
