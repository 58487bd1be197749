#!/usr/bin/env python3
"""Whole-run speed of a suspension against the flow alone in the same box (issue: suspensions at
the speed of the fluid).

Writes the 504-disk cavity of tools/suspension_scene.py at a given resolution and contact range
(default 8 per D, range 2, the issue's benchmark box: 256 x 256) and the same box without disks,
then runs each on each rank count, interleaved (box by box, rank count by rank count, repeat by
repeat) so that drift of a shared machine affects all alike. The figure is the `performance:`
line (lattice updates of the whole time loop per second). Prints the medians, the ratio of the
suspension to the flow alone on each rank count, and what two ranks gain over one for each.

    tests/perf/bench_suspension.py                          # build/dktlbm, 3 repeats, 1 and 2 ranks
    tests/perf/bench_suspension.py --steps 600 --repeats 5 --cells-per-diameter 10 --range 3
    tests/perf/bench_suspension.py --kind sediment10k --steps 40 --ranks 2   # 10 032 disks
    tests/perf/bench_suspension.py --kind bidisperse --cells-per-diameter 10 --fixed-slabs

With --fixed-slabs the suspension also runs with its rows split evenly (run.balance_every = 0)
on each rank count above 1, interleaved with the rest: what balanced slabs gain
(docs/performance.md, "Balanced slabs"). --t-end runs each to a simulated time instead of a
number of steps.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PERFORMANCE = re.compile(r"performance:\s*([0-9.]+(?:[eE][-+]?[0-9]+)?)\s*MLUPS")


def scenes(tmp: Path, kind: str, cells: float, contact: float) -> dict[str, Path]:
    """The suspension and the same box without particles."""
    disks = tmp / "suspension.nml"
    subprocess.run(
        [sys.executable, str(ROOT / "tools" / "suspension_scene.py"), "--kind", kind,
         "--cells-per-diameter", f"{cells:g}", "--range", f"{contact:g}", "--out", str(disks)],
        check=True, capture_output=True, text=True,
    )
    text = disks.read_text()
    # the box alone: the same groups but &particles, &coupling and &collision, and the lattice
    # spacing the disks set given as dx
    dx = 0.0625 / cells
    flow = re.sub(r"&particles.*?\n/\n|&coupling.*?\n/\n|&collision.*?\n/\n", "", text,
                  flags=re.S)
    flow = re.sub(r"cells_per_diameter = [0-9.]+", f"dx = {dx!r}", flow)
    (tmp / "flow.nml").write_text(flow)
    return {"suspension": disks, "flow": tmp / "flow.nml"}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--exe", default=os.environ.get("DKTLBM_EXE", str(ROOT / "build/dktlbm")))
    parser.add_argument("--mpiexec", default=shutil.which("mpiexec") or "mpiexec")
    parser.add_argument("--ranks", nargs="+", type=int, default=[1, 2])
    parser.add_argument("--steps", type=int, default=300, help="time steps per run")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--cells-per-diameter", type=float, default=8.0)
    parser.add_argument("--range", type=float, default=2.0, help="&collision range")
    parser.add_argument("--kind", default="sediment504",
                        choices=["sediment504", "sediment10k", "bidisperse"],
                        help="the scene of tools/suspension_scene.py (default sediment504)")
    parser.add_argument("--fixed-slabs", action="store_true",
                        help="also run the suspension with evenly split rows on 2+ ranks")
    parser.add_argument("--t-end", type=float, default=0.0,
                        help="simulated time of each run, s (instead of --steps)")
    args = parser.parse_args()
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    results: dict[tuple[str, int], list[float]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        files = scenes(Path(tmp), args.kind, args.cells_per_diameter, args.range)
        variants = {name: (scene, []) for name, scene in files.items()}
        if args.fixed_slabs:
            variants["fixed slabs"] = (files["suspension"], ["--set", "run.balance_every=0"])
        length = (["--set", f"run.t_end={args.t_end!r}"] if args.t_end > 0
                  else ["--set", f"run.steps={args.steps}"])
        for repeat in range(args.repeats):
            for name, (scene, extra) in variants.items():
                for ranks in args.ranks:
                    if name == "fixed slabs" and ranks == 1:
                        continue
                    cmd = [
                        args.mpiexec, "-n", str(ranks), args.exe, str(scene), *length,
                        "--set", "run.progress_every=0", "--set", "run.checkpoint_every=0",
                        "--set", "output.field_interval=0",
                        "--set", f"output.dir={tmp}/{name.replace(' ', '_')}-{ranks}-{repeat}",
                        *extra,
                    ]
                    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
                    match = PERFORMANCE.search(proc.stdout)
                    if proc.returncode != 0 or not match:
                        print(f"run failed: {' '.join(cmd)}\n{proc.stdout}\n{proc.stderr}",
                              file=sys.stderr)
                        return 1
                    results.setdefault((name, ranks), []).append(float(match.group(1)))
    median = {key: statistics.median(values) for key, values in results.items()}
    span = f"to t = {args.t_end:g} s" if args.t_end > 0 else f"{args.steps} steps"
    print(f"{args.kind}, {args.cells_per_diameter:g} per D, range {args.range:g}, {span}, "
          f"median of {args.repeats} interleaved runs (MLUPS)")
    print(f"{'ranks':>5} {'suspension':>11} {'flow alone':>11} {'ratio':>7}")
    for ranks in args.ranks:
        s, f = median[("suspension", ranks)], median[("flow", ranks)]
        print(f"{ranks:>5} {s:11.2f} {f:11.2f} {s / f:7.3f}")
    for ranks in args.ranks:
        if ("fixed slabs", ranks) in median:
            print(f"{ranks} ranks, the suspension with its rows split evenly: "
                  f"{median[('fixed slabs', ranks)]:.2f}")
    if 1 in args.ranks and 2 in args.ranks:
        gain = {name: median[(name, 2)] / median[(name, 1)] for name in files}
        print(f"2 ranks over 1: suspension {gain['suspension']:.2f}x, flow alone "
              f"{gain['flow']:.2f}x, ratio {gain['suspension'] / gain['flow']:.2f}")
        if ("fixed slabs", 2) in median:
            print(f"2 ranks over 1, rows split evenly: "
                  f"{median[('fixed slabs', 2)] / median[('suspension', 1)]:.2f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
