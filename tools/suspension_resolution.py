#!/usr/bin/env python3
"""Compare runs of one suspension scene at several resolutions (docs/suspensions.md, "Resolution").

Reads the `/suspension` series (the upper front and the mean settling velocity) and `/particles`
of each run file, prints a table of both at the times asked for and the time at which the first
disk's surface comes within `--bottom` cm of the lower wall, and draws the front and the mean
settling velocity against time, one line per run.

    tools/suspension_resolution.py d8/sediment504.h5 d12/sediment504.h5 d16/sediment504.h5 \\
        --out docs/img/sediment504_resolution.png --times 0.5 1 2 3 4 5 6
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import h5py
import numpy as np

from dktlbm.read import open_run


def load(path: Path) -> dict:
    """The series of one run file, with its spacings per (smallest) diameter."""
    run = open_run(path)
    r = 0.5 * np.asarray(run.diameters)
    with h5py.File(path, "r") as h5:
        s = h5["suspension"]
        dx = float(h5["run"].attrs["dx"])
        y = h5["particles/y"][()]
        return {
            "label": f"{2 * r.min() / dx:.0f} per D",
            "cells": 2 * r.min() / dx,
            "t": s["t"][()],
            "front": s["front"][()],
            "v_mean": s["v_mean"][()],
            "pt": h5["particles/t"][()],
            "lowest": (y - r[None, :]).min(axis=1),
        }


def at(t: np.ndarray, v: np.ndarray, when: float) -> float:
    """The sample nearest to `when`."""
    return float(v[np.argmin(np.abs(t - when))])


def window_mean(t: np.ndarray, v: np.ndarray, when: float, width: float) -> float:
    """The mean of the samples in (when - width, when]: the mean settling velocity carries the
    closed box's pressure wave (a period of about 0.1-0.2 s) for seconds, which single samples
    alias."""
    sel = (t > when - width) & (t <= when + 1e-9)
    return float(v[sel].mean()) if sel.any() else float("nan")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--times", nargs="+", type=float, default=[0.5, 1, 2, 3, 4, 5, 6])
    ap.add_argument(
        "--bottom",
        type=float,
        default=0.0125,
        help="cm: a disk's surface this close to the lower wall has reached it",
    )
    ap.add_argument(
        "--smooth",
        type=float,
        default=0.5,
        help="s: v_mean is averaged over this window before each time",
    )
    ap.add_argument("--out", type=Path, help="PNG of the front and v_mean against time")
    args = ap.parse_args()
    runs = sorted((load(p) for p in args.runs), key=lambda r: r["cells"])
    head = " | ".join(f"{t:g}" for t in args.times)
    print(f"| run | quantity | {head} |")
    print("|---|---|" + "---|" * len(args.times))
    for r in runs:
        vals = " | ".join(f"{at(r['t'], r['front'], t):.4f}" for t in args.times)
        print(f"| {r['label']} | front (cm) | {vals} |")
        vals = " | ".join(
            f"{window_mean(r['t'], r['v_mean'], t, args.smooth):.4f}" for t in args.times
        )
        print(f"| {r['label']} | v_mean over the {args.smooth:g} s before (cm/s) | {vals} |")
    for r in runs:
        hit = np.nonzero(r["lowest"] <= args.bottom)[0]
        when = f"{r['pt'][hit[0]]:.2f} s" if hit.size else "not within the run"
        print(f"{r['label']}: first disk within {args.bottom} cm of the bottom at {when}")
    if args.out:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(1, 2, figsize=(10, 3.8), constrained_layout=True)
        for r in runs:
            ax[0].plot(r["t"], r["front"], label=r["label"])
            k = max(1, int(round(args.smooth / np.median(np.diff(r["t"])))))
            smooth = np.convolve(r["v_mean"], np.ones(k) / k, mode="valid")
            ax[1].plot(r["t"][k - 1 :], smooth, label=r["label"])
        ax[0].set(
            xlabel="t (s)", ylabel="upper front (cm)", title="front (95 % of the disks below)"
        )
        ax[1].set(
            xlabel="t (s)",
            ylabel="mean settling velocity (cm/s)",
            title=f"mean velocity, running mean over {args.smooth:g} s",
        )
        ax[0].legend()
        fig.savefig(args.out, dpi=110)
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
