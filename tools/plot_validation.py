#!/usr/bin/env python3
"""The validation figures of docs/accuracy.md, from two runs and the digitised reference curves.

    python3 tools/plot_validation.py UHLMANN.h5 CASE0_BOX.h5 [-o DIR]

UHLMANN.h5: a run of input/uhlmann.nml (to 0.3 s); its settling speeds and positions along
gravity against Uhlmann (2005), Fig. 6 (tests/refdata/uhlmann2005_dkt, or $DKTLBM_REFDATA).
CASE0_BOX.h5: a run of input/case0_box.nml; its surface gap against time, with the published
kissing and tumbling times of docs/model.md §8 marked. Writes DIR/uhlmann_validation.png and
DIR/case0_box_validation.png (DIR default docs/img).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import h5py
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
REFDATA = Path(os.environ.get("DKTLBM_REFDATA", ROOT / "tests" / "refdata"))


def series(path: Path) -> dict[str, np.ndarray]:
    with h5py.File(path, "r") as h5:
        return {k: h5["particles"][k][()] for k in ("t", "x", "y", "v")}


def uhlmann(path: Path, out: Path) -> None:
    s = series(path)
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.6), constrained_layout=True)
    for k, (name, colour) in enumerate((("leading", "C0"), ("trailing", "C3"))):
        base = REFDATA / "uhlmann2005_dkt" / "Uhlmann2005-fig6"
        ref_x = np.loadtxt(f"{base}a-{name}-particle.csv")
        ref_u = np.loadtxt(f"{base}b-{name}-particle.csv")
        axes[0].plot(s["t"], 8.0 - s["y"][:, k], color=colour, label=f"{name}, dktlbm")
        axes[0].plot(*ref_x.T, "o", ms=3, color=colour, mfc="none", label=f"{name}, Uhlmann")
        axes[1].plot(s["t"], -s["v"][:, k], color=colour, label=f"{name}, dktlbm")
        axes[1].plot(*ref_u.T, "o", ms=3, color=colour, mfc="none", label=f"{name}, Uhlmann")
    axes[0].set(xlabel="t (s)", ylabel="depth below the top (cm)", title="position along g")
    axes[1].set(xlabel="t (s)", ylabel="settling speed (cm/s)", title="velocity along g")
    axes[1].legend(fontsize=7)
    fig.suptitle("Uhlmann (2005) DKT pair: dktlbm (20 spacings per D) and the reference")
    fig.savefig(out / "uhlmann_validation.png", dpi=90)


def case0_box(path: Path, out: Path) -> None:
    s = series(path)
    dr = np.hypot(s["x"][:, 0] - s["x"][:, 1], s["y"][:, 0] - s["y"][:, 1]) - 0.2
    fig, ax = plt.subplots(figsize=(6.5, 3.4), constrained_layout=True)
    ax.plot(s["t"], dr, label="surface gap $D_r$, dktlbm (25 per D)")
    passing = s["t"][np.nonzero(s["y"][:, 0] < s["y"][:, 1])[0]]
    if passing.size:
        ax.axvline(passing[0], color="C0", ls=":", label=f"passing, dktlbm ({passing[0]:.2f} s)")
    ax.axvspan(1.21, 1.79, color="C1", alpha=0.2, label="HLBM: gap < 1 cell (1.21-1.79 s)")
    ax.axvline(1.87, color="C1", ls="--", label="HLBM: passing (1.87 s)")
    ax.axvline(1.4, color="C2", ls="-.", label="paper: kissing (about 1.4 s)")
    ax.axvline(2.1, color="C2", ls=":", label="paper: tumbling done (about 2.1 s)")
    ax.set(xlabel="t (s)", ylabel="$D_r$ (cm)", ylim=(-0.01, 0.45),
           title="case0_box: two equal disks in a 2 x 8 cm box")
    ax.legend(fontsize=7)
    fig.savefig(out / "case0_box_validation.png", dpi=90)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("uhlmann", type=Path)
    parser.add_argument("case0_box", type=Path)
    parser.add_argument("-o", "--out", type=Path, default=ROOT / "docs" / "img")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    uhlmann(args.uhlmann, args.out)
    case0_box(args.case0_box, args.out)
    print(f"wrote {args.out}/uhlmann_validation.png, {args.out}/case0_box_validation.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
