#!/usr/bin/env python3
"""Memory-bandwidth roofline of the lattice sweep: the MLUPS each storage layout could reach.

Runs the STREAM-like benchmark build/tests/stream_copy (tests/perf/stream_copy.f90) on 1 and 2
ranks at once (each rank its own arrays, well above the last-level cache) and divides the
measured bandwidth by the bytes one node moves per step:

    layout                bytes read+written   + write-allocate   kernel with the same pattern
    double, two lattices  144                  72                 copy   (a = b)
    double, in place      144                  0                  update (a = a + s)
    single, two lattices   72                  36                 copy
    single, in place       72                  0                  update
    half, two lattices     36                  18                 copy
    half, in place         36                  0                  update

Two bounds are printed per rank count. "bus": the copy's bandwidth with its write-allocate
traffic counted (24 B per element) taken as what the memory delivers, divided by each layout's
bytes including write-allocate. "kernel": the bandwidth of the kernel with the layout's access
pattern (counted bytes, no write-allocate) divided by its counted bytes; for two lattices the two
are the same number by construction. The sweep cannot beat either by more than the noise; how
close it comes says how much of it is memory traffic. Standard library only.

    tests/perf/roofline.py                       # build/tests/stream_copy, 1 and 2 ranks
    tests/perf/roofline.py --repeats 20 --statistic median --json roofline.json
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import benchlib

KERNEL_ROW = re.compile(
    r"^(copy|update|sum)\s+(\d+)\s+(\d+)\s+([0-9.]+)\s+([0-9.]+)\s+([0-9.]+)\s+([0-9.]+)\s+([0-9.]+)",
    re.MULTILINE,
)
COLUMNS = ("best", "median", "worst")


def parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--exe",
        default=str(benchlib.ROOT / "build/tests/stream_copy"),
        help="the stream_copy executable (default: build/tests/stream_copy)",
    )
    parser.add_argument(
        "--mpiexec",
        default=os.environ.get("MPIEXEC") or "mpiexec",
        help="MPI launcher (default: $MPIEXEC or mpiexec)",
    )
    parser.add_argument(
        "--ranks", type=int, nargs="+", default=[1, 2], help="rank counts (default: 1 2)"
    )
    parser.add_argument(
        "--mib",
        type=int,
        default=0,
        help="MiB of both arrays per rank (default: the program's, 8 x the last-level cache)",
    )
    parser.add_argument("--repeats", type=int, default=10, help="timed runs of each kernel")
    parser.add_argument(
        "--statistic",
        choices=COLUMNS[:2],
        default="best",
        help="bandwidth to divide (default best: what the memory can deliver, as STREAM quotes)",
    )
    parser.add_argument("--json", help="also write the bandwidths and bounds to this JSON file")
    args = parser.parse_args()
    if args.repeats < 1 or args.mib < 0 or any(r < 1 for r in args.ranks):
        parser.error("--repeats and --ranks must be positive, --mib not negative")
    return args


def measure(args: argparse.Namespace, ranks: int) -> dict[str, dict[str, float]]:
    """stream_copy on `ranks` ranks: {kernel: {'best'|'median'|'worst': total GB/s, ...}}."""
    command = benchlib.launcher(args.mpiexec, ranks) + [args.exe, str(args.mib), str(args.repeats)]
    result = subprocess.run(command, capture_output=True, text=True)
    output = result.stdout + result.stderr
    print(output.rstrip(), flush=True)
    if result.returncode != 0:
        sys.exit(f"roofline: stream_copy failed (exit {result.returncode}): {' '.join(command)}")
    rows = {}
    for match in KERNEL_ROW.finditer(result.stdout):
        name = match.group(1)
        rows[name] = {
            "counted_bytes": int(match.group(2)),
            "write_allocate_bytes": int(match.group(3)),
            **{column: float(match.group(4 + i)) for i, column in enumerate(COLUMNS)},
        }
    if set(rows) != {"copy", "update", "sum"}:
        sys.exit(f"roofline: no copy/update/sum table in the output of {' '.join(command)}")
    return rows


def bounds(rows: dict[str, dict[str, float]], statistic: str) -> list[dict[str, float | str]]:
    """MLUPS bounds of every layout from one rank count's bandwidths (GB/s -> MLUPS: x 1000)."""
    copy = rows["copy"]
    bus = copy[statistic] * (copy["counted_bytes"] + copy["write_allocate_bytes"])
    bus /= copy["counted_bytes"]
    table = []
    for precision in benchlib.PRECISIONS:
        for streaming in benchlib.STREAMINGS:
            moved, allocate = benchlib.node_bytes(precision, streaming)
            kernel = "copy" if streaming == "two_lattice" else "update"
            table.append(
                {
                    "layout": f"{precision}/{streaming}",
                    "bytes": moved,
                    "write_allocate": allocate,
                    "bus_mlups": bus * 1000.0 / (moved + allocate),
                    "kernel": kernel,
                    "kernel_mlups": rows[kernel][statistic] * 1000.0 / moved,
                }
            )
    return table


def main() -> int:
    args = parse_args()
    if not Path(args.exe).is_file():
        sys.exit(
            f"roofline: {args.exe} not found (build it: cmake --build build --target stream_copy)"
        )
    if shutil.which(args.mpiexec) is None:
        sys.exit(f"roofline: MPI launcher {args.mpiexec} not found")
    benchlib.allow_root_mpi()

    measured = {}
    for ranks in args.ranks:
        measured[ranks] = measure(args, ranks)

    print(
        f"\nbandwidth, GB/s over all ranks ({args.statistic} of the repeats), "
        f"{benchlib.machine_line()}"
    )
    print(
        f"{'ranks':>5}{'copy':>9}{'copy+WA':>9}{'update':>9}{'sum':>9}"
        "   (copy+WA: its write-allocate traffic counted)"
    )
    for ranks, rows in measured.items():
        copy = rows["copy"]
        with_wa = copy[args.statistic] * (copy["counted_bytes"] + copy["write_allocate_bytes"])
        with_wa /= copy["counted_bytes"]
        print(
            f"{ranks:>5}{copy[args.statistic]:>9.2f}{with_wa:>9.2f}"
            f"{rows['update'][args.statistic]:>9.2f}{rows['sum'][args.statistic]:>9.2f}"
        )

    tables = {ranks: bounds(rows, args.statistic) for ranks, rows in measured.items()}
    print(
        "\nroofline, MLUPS: bus = copy's bus bandwidth / (bytes + write-allocate); "
        "kernel = the matching kernel's bandwidth / bytes"
    )
    header = f"{'layout':<20}{'B/node':>7}{'+WA':>5}"
    for ranks in tables:
        header += f"{f'bus {ranks}r':>11}{f'kernel {ranks}r':>11}"
    print(header)
    for i, row in enumerate(next(iter(tables.values()))):
        line = f"{row['layout']:<20}{row['bytes']:>7}{row['write_allocate']:>5}"
        for table in tables.values():
            line += f"{table[i]['bus_mlups']:>11.1f}{table[i]['kernel_mlups']:>11.1f}"
        print(line)
    if args.json:
        Path(args.json).write_text(
            json.dumps(
                {"statistic": args.statistic, "bandwidth_gbs": measured, "roofline": tables},
                indent=2,
            )
            + "\n"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
