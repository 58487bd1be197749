"""Per-particle trajectories against t*: x/W, y/H, u/sqrt(Hg), v/sqrt(Hg) and
Omega/(2 pi/t_r) in stacked panels (docs/model.md §6 normalisation; H = 18 cm, t_r = sqrt(H/g))."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .read import Run, add_output_options, add_version, guarded, open_run, output_path, save_figure


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="dkt-trajectories",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="example: dkt-trajectories runs/case1/case1.h5 --pdf",
    )
    add_version(p)
    p.add_argument("run", type=Path, metavar="RUN.h5", help="a dktlbm run file")
    add_output_options(p, "trajectories")
    return p


def plot(run: Run):
    from matplotlib.figure import Figure

    s = run.series
    u0 = run.velocity_scale
    panels = [
        (s["x"] / run.width, "$x/W$"),
        (s["y"] / run.h_ref, "$y/H$"),
        (s["u"] / u0, r"$u/\sqrt{Hg}$"),
        (s["v"] / u0, r"$v/\sqrt{Hg}$"),
        (s["omega"] / run.omega_scale, r"$\Omega/(2\pi/t_r)$"),
    ]
    fig = Figure(figsize=(7.0, 11.0), layout="constrained")
    axes = fig.subplots(len(panels), 1, sharex=True)
    ts = run.tstar
    for ax, (values, ylabel) in zip(axes, panels, strict=True):
        for k in range(run.count):
            d = run.diameters[k]
            ax.plot(ts, values[:, k], label=f"particle {k + 1} (D = {d:.3g} cm)")
        ax.set_ylabel(ylabel)
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize="small")
    axes[-1].set_xlabel("$t^* = t/t_r$")
    # H is the reference length of the time scale (docs/model.md §6), not the box's height
    fig.suptitle(f"{run.name}: W = {run.width:g} cm, "
                 f"$t_r = \\sqrt{{H/g}}$ = {run.t_ref:.4g} s with H = {run.h_ref:g} cm")
    return fig


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)

    def body() -> int:
        run = open_run(args.run)
        save_figure(plot(run), output_path(args.run, "trajectories", args.output), args.pdf)
        return 0

    return guarded(body)


if __name__ == "__main__":
    sys.exit(main())
