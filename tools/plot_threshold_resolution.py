#!/usr/bin/env python3
"""The regime thresholds against resolution (docs/convergence.md, "Thresholds against
resolution"): each bracket of docs/threshold_resolution.csv as a bar from its lower to its
upper end, against 1/N (N spacings across the smaller disk), one panel a threshold.

    python3 tools/plot_threshold_resolution.py docs/threshold_resolution.csv \
        -o docs/img/threshold_resolution.png
"""

from __future__ import annotations

import argparse
import csv
from collections import defaultdict
from pathlib import Path


def read(path: Path) -> dict[str, list[tuple[int, float, float]]]:
    """threshold -> [(N, lower end, upper end)] in file order."""
    out: dict[str, list[tuple[int, float, float]]] = defaultdict(list)
    with path.open(newline="") as f:
        for row in csv.DictReader(f):
            out[row["threshold"]].append((int(row["per_d"]), float(row["lo"]), float(row["hi"])))
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("csv", type=Path)
    p.add_argument("-o", "--output", type=Path, required=True)
    args = p.parse_args()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = read(args.csv)
    fig, axes = plt.subplots(1, len(data), figsize=(3.2 * len(data), 3.2), squeeze=False)
    for ax, (name, rows) in zip(axes[0], data.items(), strict=True):
        for n, lo, hi in rows:
            ax.plot([1 / n, 1 / n], [lo, hi], "-", color="C0", lw=4, solid_capstyle="butt")
        ns = sorted({n for n, _, _ in rows})
        ax.set_xticks([1 / n for n in ns], [f"1/{n}" for n in ns])
        ax.set_xlim(0, 1.15 / min(ns))
        ax.set_xlabel("1/N (N: spacings per smaller D)")
        ax.set_title(name, fontsize=9)
        ax.margins(y=0.6)
    fig.tight_layout()
    fig.savefig(args.output, dpi=110)
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
