#!/usr/bin/env python3
"""Accuracy cost of lbm.precision: the validation numbers of docs/accuracy.md, one run
per precision.

Each row is measured exactly as the test or docs/accuracy.md row it comes from computes it, with
that test's helpers (tests/dkt_run.py, tests/test_particles.py, tests/test_window.py), on the
default in-place streaming:

- single: input/single.nml at 12.5 spacings per D (lbm.dx = 0.02, t_end = 0.75 s), Re_max =
  rho_p D |U|max / mu (test_particles, docs/accuracy.md "single disk, Re_max");
- case0_box: input/case0_box.nml at the paper's resolution, the start of the first kissing
  episode and the first time the trailing disk is below the leading one (test_dkt_validation);
- case1: input/case1.nml as shipped (window, gamma = 2), the run's own /diagnostics pattern and
  kissing episodes (docs/running.md "Command A");
- window: one disk in the window (tau = 0.52, 16 D below, 15 D above) against the tall static
  channel, the largest |dx| and |dy| in % of D (test_window, the window table of docs/accuracy.md).

Field output is switched off (output.field_interval = 0): it does not change the particle
series. Every run uses --ranks MPI ranks, one after another. A run whose `<name>.finished` and
wall-time file exist is skipped, so an interrupted sweep resumes. Writes <out>/accuracy.csv and
prints a markdown table (the precisions side by side, each against the first one).

    tests/perf/precision_accuracy.py                                  # double and single
    tests/perf/precision_accuracy.py --precisions double single single_unshifted --rows single
    tests/perf/precision_accuracy.py --precisions double single single_arith

The test helpers it imports are found through PYTHONPATH=postproc:tests (ctest sets it).
"""

from __future__ import annotations

import argparse
import csv
import shlex
import sys
import time
from pathlib import Path

import h5py
import numpy as np

from dkt_run import EXE, INPUT, ROOT, mpi_command, run
from dktlbm.read import text_attr
from test_particles import series
from test_window import D, read_group, single_disk_scenes

ROWS = ("single", "case0_box", "case1", "window")
NO_FIELDS = ["output.field_interval=0"]


def relative(path: Path) -> str:
    """`path` relative to the repository root where it lies below it (for the printed command)."""
    return str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)


def timed_run(nml: Path, ranks: int, sets: list[str], out: Path) -> tuple[float, str]:
    """Run dktlbm unless `out` already holds a finished run; return (wall time s, command)."""
    sets = [*sets, "output.overwrite=.true."]
    words = [*mpi_command(ranks), relative(EXE), relative(nml)]
    words += [f"--set {s}" for s in [*sets, f"output.dir={relative(out)}"]]
    command = " ".join(shlex.quote(w) if " " not in w else w for w in words)
    wall_file = out / "wall_seconds.txt"
    if (out / f"{nml.stem}.finished").exists() and wall_file.exists():
        print(f"  skip (done): {out}", flush=True)
        return float(wall_file.read_text()), command
    print(f"  run: {command}", flush=True)
    start = time.perf_counter()
    run(nml, ranks, sets, out, timeout=6 * 3600)
    wall = time.perf_counter() - start
    wall_file.write_text(f"{wall:.1f}\n")
    return wall, command


def row_single(out: Path, precision: str, ranks: int) -> list[tuple[str, object, float, str]]:
    sets = ["lbm.dx=0.02", "run.t_end=0.75", f"lbm.precision={precision}", *NO_FIELDS]
    wall, cmd = timed_run(INPUT / "single.nml", ranks, sets, out)
    return [(q, v, wall, cmd) for q, v in answers_single(out / "single.h5")]


def answers_single(h5file: Path, t_max: float = np.inf) -> list[tuple[str, object]]:
    """Re_max = rho_p D |U|max / mu of input/single.nml's disk up to t_max, and when it is
    reached."""
    s = series(h5file)
    s = {name: values[s["t"] <= t_max] for name, values in s.items()}
    speed = np.hypot(s["u"][:, 0], s["v"][:, 0])
    return [
        ("single disk Re_max (ref. 17.3)", 1.25 * 0.25 * speed.max() / 0.1),
        ("single disk t(Re_max) [s]", float(s["t"][np.argmax(speed)])),
    ]


def row_case0_box(out: Path, precision: str, ranks: int) -> list[tuple[str, object, float, str]]:
    wall, cmd = timed_run(
        INPUT / "case0_box.nml", ranks, [f"lbm.precision={precision}", *NO_FIELDS], out
    )
    return [(q, v, wall, cmd) for q, v in answers_case0_box(out / "case0_box.h5")]


def episodes(diag: h5py.Group) -> tuple[np.ndarray, np.ndarray]:
    """Start and end times of the kissing episodes (none: the run writes no episodes group)."""
    if "episodes" not in diag:
        return np.empty(0), np.empty(0)
    return diag["episodes/start"][()], diag["episodes/end"][()]


def pair_run(h5file: Path) -> tuple[np.ndarray, ...]:
    """A pair run's sample times, heights y (one column per particle), surface gap D_r, the
    start and end times of its kissing episodes, and its pattern."""
    with h5py.File(h5file, "r") as h5:
        diag = h5["diagnostics"]
        starts, ends = episodes(diag)
        return (h5["particles/t"][()], h5["particles/y"][()], diag["dr"][()], starts, ends,
                text_attr(diag.attrs["pattern"]))  # fmt: skip


def answers_case0_box(h5file: Path) -> list[tuple[str, object]]:
    """The gap at 0.5 s, the first kissing episode, the first passing and the run's pattern."""
    t, y, dr, starts, ends, pattern = pair_run(h5file)
    passing = t[np.nonzero(y[:, 0] < y[:, 1])[0]]
    return [
        ("case0_box gap at 0.5 s [cm]", float(np.interp(0.5, t, dr))),
        ("case0_box kissing begins [s]", float(starts[0]) if starts.size else "none"),
        ("case0_box kissing ends [s]", float(ends[0]) if ends.size else "none"),
        ("case0_box passing [s]", float(passing[0]) if passing.size else "none"),
        ("case0_box pattern", pattern),
    ]


def row_case1(out: Path, precision: str, ranks: int) -> list[tuple[str, object, float, str]]:
    wall, cmd = timed_run(
        INPUT / "case1.nml", ranks, [f"lbm.precision={precision}", *NO_FIELDS], out
    )
    return [(q, v, wall, cmd) for q, v in answers_case1(out / "case1.h5")]


def answers_case1(h5file: Path) -> list[tuple[str, object]]:
    """The run's own /diagnostics pattern and the window of each kissing episode."""
    with h5py.File(h5file, "r") as h5:
        diag = h5["diagnostics"]
        starts, ends = episodes(diag)
        pattern = text_attr(diag.attrs["pattern"])
    rows: list[tuple[str, object]] = [("case1 pattern", pattern)]
    for k, (a, b) in enumerate(zip(starts, ends, strict=True), start=1):
        rows.append((f"case1 kissing {k} begins [s]", float(a)))
        rows.append((f"case1 kissing {k} ends [s]", float(b)))
    return rows


def row_window(out: Path, precision: str, ranks: int) -> list[tuple[str, object, float, str]]:
    out.mkdir(parents=True, exist_ok=True)
    window_nml, static_nml = single_disk_scenes(out)
    walls, cmds = [], []
    for nml in (window_nml, static_nml):
        wall, cmd = timed_run(nml, ranks, [f"lbm.precision={precision}"], out / nml.stem)
        walls.append(wall)
        cmds.append(cmd)
    w = read_group(out / "window" / "window.h5", "particles")
    s = read_group(out / "static" / "static.h5", "particles")
    assert np.array_equal(w["t"], s["t"])
    dx_max = 100 * np.max(np.abs(w["x"][:, 0] - s["x"][:, 0])) / D
    dy_max = 100 * np.max(np.abs(w["y"][:, 0] - s["y"][:, 0])) / D
    wall, cmd = sum(walls), " ; ".join(cmds)
    return [
        ("window vs static, largest x difference [% of D]", float(dx_max), wall, cmd),
        ("window vs static, largest y difference [% of D]", float(dy_max), wall, cmd),
        (
            "window vs static, largest position difference [% of D]",
            float(max(dx_max, dy_max)),
            wall,
            cmd,
        ),
    ]


MEASURE = {
    "single": row_single,
    "case0_box": row_case0_box,
    "case1": row_case1,
    "window": row_window,
}


def fmt(value: object) -> str:
    return f"{value:.6g}" if isinstance(value, float) else str(value)


def table(results: dict[str, dict[str, tuple[object, float]]], precisions: list[str]) -> str:
    """Markdown: quantity, the value per precision, each against the first, wall times."""
    base = precisions[0]
    head = ["quantity", *precisions]
    head += [f"{p} − {base}" for p in precisions[1:]]
    head += [f"wall {p} [s]" for p in precisions]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for quantity, by_prec in results.items():
        cells = [quantity] + [fmt(by_prec[p][0]) if p in by_prec else "—" for p in precisions]
        for p in precisions[1:]:
            a, b = by_prec.get(base, (None, 0))[0], by_prec.get(p, (None, 0))[0]
            if isinstance(a, float) and isinstance(b, float):
                cells.append(f"{b - a:+.3g}")
            elif a is None or b is None:
                cells.append("—")
            else:
                cells.append("same" if a == b else "differs")
        cells += [f"{by_prec[p][1]:.0f}" if p in by_prec else "—" for p in precisions]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--precisions",
        nargs="+",
        default=["double", "single"],
        choices=["double", "single", "single_unshifted", "single_arith"],
    )
    parser.add_argument("--rows", nargs="+", default=list(ROWS), choices=ROWS)
    parser.add_argument("--ranks", type=int, default=2)
    parser.add_argument("--out", type=Path, default=ROOT / "runs" / "precision_accuracy")
    args = parser.parse_args()
    out = args.out.resolve()
    out.mkdir(parents=True, exist_ok=True)

    results: dict[str, dict[str, tuple[object, float]]] = {}
    records = []
    for row in args.rows:
        for precision in args.precisions:
            print(f"{row}, {precision}:", flush=True)
            for quantity, value, wall, cmd in MEASURE[row](
                out / row / precision, precision, args.ranks
            ):
                results.setdefault(quantity, {})[precision] = (value, wall)
                records.append([row, quantity, precision, fmt(value), f"{wall:.1f}", cmd])
    with open(out / "accuracy.csv", "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["row", "quantity", "precision", "value", "wall_s", "command"])
        writer.writerows(records)
    print(f"\n{out / 'accuracy.csv'}\n")
    print(table(results, args.precisions))
    return 0


if __name__ == "__main__":
    sys.exit(main())
