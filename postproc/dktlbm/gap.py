"""The separation of the pair against t*: D_x/D_1, D_y/D_1 and the surface gap D_r/D_1 in
three stacked panels, for one run or several overlaid (as the paper's gap figures)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from .read import (
    Pair,
    add_output_options,
    add_version,
    guarded,
    open_run,
    output_path,
    pair_of,
    save_figure,
    unique_names,
)

LABELS = ("auto", "gamma", "dh", "name")


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="dkt-gap",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="example: dkt-gap runs/case1/case1.h5 runs/case2/case2.h5 "
        "-o gaps.png --pdf",
    )
    add_version(p)
    p.add_argument("runs", nargs="+", type=Path, metavar="RUN.h5", help="dktlbm run files")
    add_output_options(p, "gap")
    p.add_argument(
        "--label", choices=LABELS, default="auto",
        help="legend entries: gamma (D_1/D_2), dh (initial D_h/D_1), name (file name); auto "
        "(default) takes whichever of gamma and dh differs between the runs, else the name")
    p.add_argument("--tmax", type=float, metavar="T*",
                   help="plot up to this t* (default: the whole run)")
    return p


def _distinct(values: list[float]) -> bool:
    return len({round(v, 6) for v in values}) > 1


def legend_labels(pairs: list[Pair], how: str) -> list[str]:
    """The legend entry of each run for --label `how`."""
    names = unique_names([p.run.path for p in pairs])
    gammas = [p.gamma for p in pairs]
    dhs = [p.dh for p in pairs]
    if how == "auto":
        g, h = _distinct(gammas), _distinct(dhs)
        if g and h:
            return [f"γ = {a:g}, $D_h/D_1$ = {b:g}" for a, b in zip(gammas, dhs, strict=True)]
        how = "gamma" if g else "dh" if h else "name"
    if how == "gamma":
        return [f"γ = {a:g}" for a in gammas]
    if how == "dh":
        return [f"$D_h/D_1$ = {b:g}" for b in dhs]
    return names


def plot(pairs: list[Pair], labels: list[str], tmax: float | None = None):
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.0, 8.0), layout="constrained")
    axes = fig.subplots(3, 1, sharex=True)
    for pair, label in zip(pairs, labels, strict=True):
        ts = pair.tstar
        keep = ts <= tmax if tmax is not None else np.ones(ts.size, bool)
        axes[0].plot(ts[keep], pair.dx[keep] / pair.d1, label=label)
        axes[1].plot(ts[keep], pair.dy[keep] / pair.d1, label=label)
        axes[2].plot(ts[keep], pair.dr_star[keep], label=label)
    if len(pairs) == 1:
        pair = pairs[0]
        lim = pair.limits
        axes[2].axhline(lim.enter_d1, color="k", lw=0.8, ls="--",
                        label=f"enter {lim.enter_d1:.3g} $D_1$")
        axes[2].axhline(lim.release_d1, color="k", lw=0.8, ls=":",
                        label=f"release {lim.release_d1:.3g} $D_1$")
        for ep in pair.episodes:
            axes[2].axvspan(ep.start / pair.run.t_ref, ep.end / pair.run.t_ref,
                            color="tab:orange", alpha=0.2, lw=0)
        fig.suptitle(f"{pair.run.name}: γ = {pair.gamma:g}, $D_h/D_1$ = {pair.dh:g}, "
                     f"pattern {pair.pattern}")
    else:
        patterns = ", ".join(sorted({p.pattern for p in pairs}))
        fig.suptitle(f"{len(pairs)} runs: the gap of particles 1 and 2 (patterns: {patterns})")
    axes[0].set_ylabel("$D_x/D_1$")
    axes[1].set_ylabel("$D_y/D_1$")
    axes[2].set_ylabel("$D_r/D_1$")
    axes[2].set_xlabel("$t^* = t/t_r$")
    for ax in axes:
        ax.grid(True, alpha=0.3)
    axes[2].legend(fontsize="small")
    return fig


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)

    def body() -> int:
        pairs = [pair_of(open_run(f, need_particles=2)) for f in args.runs]
        fig = plot(pairs, legend_labels(pairs, args.label), args.tmax)
        save_figure(fig, output_path(args.runs[0], "gap", args.output), args.pdf)
        return 0

    return guarded(body)


if __name__ == "__main__":
    sys.exit(main())
