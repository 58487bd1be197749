#!/usr/bin/env python3
"""Compare two dktlbm executables bitwise on the scenes of the rank matrix.

A change that restructures the code must change no result. This runs every case of
tests/test_rank_matrix.py (window scenes with even, uneven and prime row counts, open, closed
and periodic ends, 4-byte storage, fluid interiors) with executable A and executable B on the
rank counts asked for, and compares every dataset of the run files outside /run (fields,
particles, diagnostics), byte for byte, and the /diagnostics attributes (the pattern). The /run
group is left out: it holds the version, the git revision and the build flags, which differ
between builds by design.

    PYTHONPATH=postproc:tests tools/compare_builds.py OLD/build/dktlbm build/dktlbm \
        [--ranks 1 3] [--case window_uneven_rows_3 ...] [--workdir DIR]

Prints one line per case and rank count (`same` or what differs) and exits 1 when anything
differs or a run fails, else 0.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

# the package and the rank matrix's cases: postproc/ and tests/ on PYTHONPATH (usage above)
from dktlbm import launch
from test_rank_matrix import CASES, datasets

ROOT = Path(__file__).resolve().parents[1]


def run_case(exe: Path, case: str, ranks: int, outdir: Path) -> tuple | str:
    """The case's datasets with `exe` on `ranks` ranks, or why the run failed."""
    spec = CASES[case]
    args = [str(exe), str(ROOT / "input" / spec["nml"])]
    for s in spec["sets"] + ["output.series_interval=1e-9", f"output.dir={outdir}"]:
        args += ["--set", s]
    proc = subprocess.run(launch.mpi_prefix(ranks) + args, capture_output=True, text=True,
                          stdin=subprocess.DEVNULL,
                          timeout=900, env=launch.mpi_env())
    if proc.returncode != 0:
        return f"exit {proc.returncode}: {(proc.stdout + proc.stderr)[-800:]}"
    return datasets(outdir / f"{Path(spec['nml']).stem}.h5")


def differences(a: tuple, b: tuple) -> list[str]:
    """What differs between two runs' datasets and /diagnostics attributes."""
    data_a, diag_a, _ = a
    data_b, diag_b, _ = b
    out = [f"only in A: {k}" for k in sorted(data_a.keys() - data_b.keys())]
    out += [f"only in B: {k}" for k in sorted(data_b.keys() - data_a.keys())]
    for key in sorted(data_a.keys() & data_b.keys()):
        x, y = data_a[key], data_b[key]
        if x.dtype != y.dtype or x.shape != y.shape:
            out.append(f"{key}: {x.dtype}{x.shape} against {y.dtype}{y.shape}")
        elif x.tobytes() != y.tobytes():  # bytes: NaN matches NaN, -0.0 only -0.0
            diff = np.nanmax(np.abs(x.astype(float) - y.astype(float)))
            out.append(f"{key}: max |diff| {diff:.3e}")
    if {k: str(v) for k, v in diag_a.items()} != {k: str(v) for k, v in diag_b.items()}:
        out.append("/diagnostics attributes")
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("exe_a", type=Path, help="the executable before the change")
    parser.add_argument("exe_b", type=Path, help="the executable after the change")
    parser.add_argument("--ranks", type=int, nargs="+", default=[1, 2, 3, 4])
    parser.add_argument("--case", nargs="+", choices=sorted(CASES), default=sorted(CASES))
    parser.add_argument("--workdir", type=Path, help="where the runs go (default: a temporary "
                        "directory, removed at the end)")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="dkt-compare-") as tmp:
        work = args.workdir or Path(tmp)
        failed = 0
        for case in args.case:
            for ranks in args.ranks:
                tag = f"{case}_r{ranks}"
                a = run_case(args.exe_a.resolve(), case, ranks, work / f"A_{tag}")
                b = run_case(args.exe_b.resolve(), case, ranks, work / f"B_{tag}")
                if isinstance(a, str) or isinstance(b, str):
                    failed += 1
                    why_a = a if isinstance(a, str) else "ok"
                    why_b = b if isinstance(b, str) else "ok"
                    print(f"{case} on {ranks} ranks: run failed: A {why_a}; B {why_b}", flush=True)
                    continue
                diff = differences(a, b)
                failed += bool(diff)
                n = len(a[0])
                print(f"{case} on {ranks} ranks: " + ("; ".join(diff) if diff else
                      f"same ({n} datasets)"), flush=True)
    print(f"{failed} of {len(args.case) * len(args.ranks)} comparisons differ or failed")
    return 1 if failed else 0


if __name__ == "__main__":
    os.environ.setdefault("OMPI_ALLOW_RUN_AS_ROOT", "1")
    os.environ.setdefault("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
    sys.exit(main())
