#!/usr/bin/env python3
"""The speed/accuracy trade of the curved bounce-back (docs/model.md E6), measured: Schafer-Turek
2D-1 (input/cylinder.nml) at several resolutions for each scheme, with the drag error against
C_D = 5.5795, the observed convergence order between successive resolutions and the wall time.

Diffusive scaling: tau stays 0.55, so dt ~ dx^2 and the Mach number falls with dx. The width
(4.1 D) must be a whole number of cells, so D is resolved by a multiple of 10 spacings.

    tests/perf/bench_cylinder.py                       # D = 10, 20, 30 cells; 3 schemes
    tests/perf/bench_cylinder.py --cells 10 20 --schemes yu --ranks 2
"""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np

ROOT = Path(__file__).resolve().parents[2]
CD_REF, CL_REF = 5.5795, 0.0106
D, U_MEAN = 0.1, 0.2


def run_case(
    exe: str, scheme: str, cells: int, ranks: int, out: Path
) -> tuple[float, float, float]:
    dx = D / cells
    cmd = [
        "mpiexec",
        "-n",
        str(ranks),
        exe,
        str(ROOT / "input/cylinder.nml"),
        "--set",
        f"lbm.dx={dx!r}",
        "--set",
        f"coupling.bounce_back={scheme}",
        "--set",
        f"output.dir={out}",
        "--set",
        "run.progress_every=0",
    ]
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    start = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True, env=env)
    wall = time.perf_counter() - start
    with h5py.File(out / "cylinder.h5", "r") as h5:
        t = h5["particles/t"][()]
        fy = h5["particles/fy"][:, 0]
        fx = h5["particles/fx"][:, 0]
    scale = 2.0 / (U_MEAN**2 * D)
    late = t > 0.8 * t[-1]
    return float(np.mean(fy[late]) * scale), float(np.mean(fx[late]) * scale), wall


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--exe", default=str(ROOT / "build/dktlbm"))
    ap.add_argument("--cells", type=int, nargs="+", default=[10, 20, 30])
    ap.add_argument("--schemes", nargs="+", default=["halfway", "bfl", "yu"])
    ap.add_argument("--ranks", type=int, default=1)
    args = ap.parse_args()
    print("| scheme | cells/D | C_D | error | order | C_L | wall s |")
    print("|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for scheme in args.schemes:
            prev = None
            for cells in args.cells:
                cd, cl, wall = run_case(
                    args.exe, scheme, cells, args.ranks, Path(tmp) / f"{scheme}{cells}"
                )
                err = abs(cd - CD_REF) / CD_REF
                order = ""
                if prev is not None and err > 0 and prev[1] > 0:
                    order = f"{math.log(prev[1] / err) / math.log(cells / prev[0]):.2f}"
                print(
                    f"| {scheme} | {cells} | {cd:.4f} | {100 * err:.2f} % | {order} | "
                    f"{cl:.5f} | {wall:.1f} |",
                    flush=True,
                )
                prev = (cells, err)


if __name__ == "__main__":
    main()
