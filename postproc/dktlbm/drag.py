"""The drag coefficient of each particle against t*: C_d = F_y / (rho_f U_p^2 D_p / 2)
(docs/model.md E12), from /diagnostics/cd for the pair when the file has it, else from /particles
(U_p = |U|). C_d is undefined (not drawn) while a particle is at rest, and very large just
after release, so the default vertical range follows the bulk of the values (--ylim to set
it)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from .read import (
    Run,
    add_output_options,
    add_version,
    guarded,
    open_run,
    output_path,
    reynolds_and_drag,
    save_figure,
)


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="dkt-drag",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="example: dkt-drag runs/case1/case1.h5 --ylim 0 20",
    )
    add_version(p)
    p.add_argument("run", type=Path, metavar="RUN.h5", help="a dktlbm run file")
    add_output_options(p, "drag")
    p.add_argument("--ylim", nargs=2, type=float, metavar=("LOW", "HIGH"),
                   help="vertical range of the plot")
    p.add_argument("--log", action="store_true", help="logarithmic C_d axis")
    return p


def drag_series(run: Run) -> tuple[np.ndarray, np.ndarray]:
    """(t in s (n,), C_d (n, particles)): /diagnostics t and cd for the pair when present and
    the run has exactly two particles, else computed from /particles for every particle."""
    diag = run.diagnostics
    if diag is not None and run.count == 2 and "cd" in diag and "t" in diag:
        return diag["t"].ravel(), np.atleast_2d(diag["cd"]).reshape(diag["t"].size, -1)
    return run.t, reynolds_and_drag(run)[1]


def default_ylim(cd: np.ndarray) -> tuple[float, float] | None:
    good = cd[np.isfinite(cd)]
    if good.size < 2:
        return None
    lo, hi = (float(v) for v in np.percentile(good, [5.0, 95.0]))
    span = max(hi - lo, 1e-12)
    return (lo - 0.2 * span if lo < 0 else 0.0, hi + 0.2 * span)


def plot(run: Run, ylim: tuple[float, float] | None, log: bool):
    from matplotlib.figure import Figure

    t, cd = drag_series(run)
    fig = Figure(figsize=(7.0, 4.5), layout="constrained")
    ax = fig.subplots()
    for k in range(cd.shape[1]):
        ax.plot(t / run.t_ref, cd[:, k], label=f"particle {k + 1} (D = {run.diameters[k]:.3g} cm)")
    if log:
        ax.set_yscale("log")
    limits = ylim if ylim is not None else (None if log else default_ylim(cd))
    if limits is not None:
        ax.set_ylim(*limits)
    ax.set_xlabel("$t^* = t/t_r$")
    ax.set_ylabel(r"$C_d = F_y / (\frac{1}{2}\rho_f U_p^2 D_p)$")
    ax.set_title(f"{run.name}: drag coefficient")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize="small")
    return fig


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)

    def body() -> int:
        run = open_run(args.run)
        fig = plot(run, tuple(args.ylim) if args.ylim else None, args.log)
        save_figure(fig, output_path(args.run, "drag", args.output), args.pdf)
        return 0

    return guarded(body)


if __name__ == "__main__":
    sys.exit(main())
