#!/usr/bin/env python3
"""Whole-run particle cost per step of a crowd of disks, with dktlbm as users run it.

The scene is lattice_scene of tests/test_faults_scale.py (side x side free disks in a closed box
that just holds them). For each count, four runs, repeated and interleaved: 2 and 2 + K steps
with the disks, and the same with particles.count = 0 (the same lattice, flow only). The
particle cost per step is

    [T(2 + K) - T(2)]_with disks / K  -  [T(2 + K) - T(2)]_flow only / K,

set-up, validation and output of the first two steps cancelling. Prints the median, minimum
and maximum over the repeats (ms per step). The parts of it (contact forces, link search) are
timed apart by build/tests/bench_particles.

    PYTHONPATH=postproc:tests tests/perf/bench_particle_steps.py    # 1024 and 10^4 disks
    PYTHONPATH=postproc:tests tests/perf/bench_particle_steps.py --sides 32 --steps 40 \
        --repeats 5 --ranks 1

(build/dktlbm; like the other scripts here it finds the package and the test helpers on
PYTHONPATH, as ctest sets it.)
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import benchlib

from test_faults_scale import lattice_scene  # tests/ on PYTHONPATH: the scene


def timed(command: list[str]) -> float:
    done = benchlib.run_measured(command)
    if done.returncode != 0:
        sys.exit(f"failed ({done.returncode}): {' '.join(command)}\n{done.output}")
    return done.wall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--exe", default="build/dktlbm")
    parser.add_argument("--mpiexec", default="mpiexec")
    parser.add_argument("--ranks", type=int, default=2)
    parser.add_argument(
        "--sides",
        type=int,
        nargs="+",
        default=[32, 100],
        help="disks per side of the lattice (count = side^2)",
    )
    parser.add_argument("--steps", type=int, default=4, help="K, the steps timed")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    benchlib.allow_root_mpi()
    prefix = benchlib.launcher(args.mpiexec, args.ranks)
    print(f"{benchlib.machine_line()}; {args.ranks} ranks, K = {args.steps}")
    with tempfile.TemporaryDirectory() as tmp:
        for side in args.sides:
            scene = Path(tmp) / f"crowd{side}.nml"
            scene.write_text(lattice_scene(side))
            per_step = []
            for _ in range(args.repeats):
                t = {}
                for flow_only in (False, True):
                    for steps in (2, 2 + args.steps):
                        out = Path(tmp) / f"run{side}_{int(flow_only)}_{steps}"
                        sets = [
                            "--set",
                            f"run.steps={steps}",
                            "--set",
                            f"output.dir={out}",
                            "--set",
                            "output.overwrite=.true.",
                        ]
                        if flow_only:
                            sets += ["--set", "particles.count=0"]
                        t[flow_only, steps] = timed(prefix + [args.exe, str(scene)] + sets)
                with_disks = t[False, 2 + args.steps] - t[False, 2]
                flow = t[True, 2 + args.steps] - t[True, 2]
                per_step.append(1e3 * (with_disks - flow) / args.steps)
            med, lo, hi = benchlib.spread(per_step)
            print(
                f"{side * side:7d} disks: particle cost {med:10.1f} ms/step "
                f"(min {lo:.1f}, max {hi:.1f}, {args.repeats} repeats)"
            )


if __name__ == "__main__":
    main()
