#!/usr/bin/env python3
"""Whole-run speed of the DKT scenes: MLUPS with particles, window and output included.

Runs each scene (default input/case0_box.nml and input/case1.nml at the paper's resolution) for
a fixed number of steps on each rank count, several times, interleaved (scene by scene, rank
count by rank count, repeat by repeat) so that drift of a shared machine affects all alike. The
figure is the "performance:" line dktlbm prints at the end: lattice updates of the whole time
loop (boundary links, momentum exchange, particle update, window shifts, the /particles and
/diagnostics series and field output) per second of wall time. Prints median, minimum and
maximum per scene and rank count. Standard library only.

    tests/perf/bench_scenes.py                         # build/dktlbm, 3 repeats, 1 and 2 ranks
    tests/perf/bench_scenes.py --steps 3000 --repeats 5
    tests/perf/bench_scenes.py --ranks 1 --scenes input/cylinder.nml \
        'input/cylinder.nml --set particles.count=0'      # a scene with its own --set options
"""

from __future__ import annotations

import argparse
import os
import re
import shlex
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PERFORMANCE = re.compile(r"performance:\s*([0-9.]+(?:[eE][-+]?[0-9]+)?)\s*MLUPS")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--exe", default=os.environ.get("DKTLBM_EXE", str(ROOT / "build/dktlbm")))
    parser.add_argument("--mpiexec", default=shutil.which("mpiexec") or "mpiexec")
    parser.add_argument(
        "--scenes", nargs="+", default=["input/case0_box.nml", "input/case1.nml"]
    )
    parser.add_argument("--ranks", nargs="+", type=int, default=[1, 2])
    parser.add_argument("--steps", type=int, default=2000, help="time steps per run")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    results: dict[tuple[str, int], list[float]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for repeat in range(args.repeats):
            for index, scene in enumerate(args.scenes):
                path, *options = shlex.split(scene)
                for ranks in args.ranks:
                    # series every 10 steps and fields at the end: output is part of the run
                    cmd = [
                        args.mpiexec, "-n", str(ranks), args.exe, str(ROOT / path),
                        *options,
                        "--set", f"run.steps={args.steps}",
                        "--set", "run.progress_every=0",
                        "--set", f"output.dir={tmp}/{Path(path).stem}-{index}-{ranks}-{repeat}",
                    ]
                    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
                    match = PERFORMANCE.search(proc.stdout)
                    if proc.returncode != 0 or not match:
                        print(f"run failed: {' '.join(cmd)}\n{proc.stderr}", file=sys.stderr)
                        return 1
                    results.setdefault((scene, ranks), []).append(float(match.group(1)))
    width = max(24, *(len(scene) for scene in args.scenes))
    print(f"{'scene':<{width}} {'ranks':>5} {'median':>8} {'min':>8} {'max':>8}  MLUPS, "
          f"{args.steps} steps, {args.repeats} runs")
    for (scene, ranks), values in results.items():
        print(f"{scene:<{width}} {ranks:>5} {statistics.median(values):8.1f} {min(values):8.1f} "
              f"{max(values):8.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
