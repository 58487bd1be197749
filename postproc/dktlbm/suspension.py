"""A settling suspension from its run file (docs/suspensions.md): the upper front's height, the
mean and rms settling velocity and, with two sizes, the segregation index against time (the
/suspension series), the area-fraction profile phi(y) at a few times, and snapshot panels of
the disks (from /particles) at the same times."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from .read import (
    Run,
    RunFileError,
    add_output_options,
    add_version,
    guarded,
    open_h5,
    open_run,
    output_path,
    save_figure,
)

SERIES = ("t", "v_mean", "v_rms", "front", "segregation", "phi")


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="dkt-suspension",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="example: dkt-suspension runs/sediment504/sediment504.h5 --panels 4",
    )
    add_version(p)
    p.add_argument("run", type=Path, metavar="RUN.h5", help="a dktlbm run file of 3+ disks")
    p.add_argument("--panels", type=int, default=4, metavar="N",
                   help="snapshot panels, evenly spaced in time from the first sample to the "
                        "last (1-8; default 4)")
    p.add_argument("--summary", action="store_true",
                   help="print the figures a suspension is compared by instead of drawing")
    add_output_options(p, "suspension")
    return p


def read_suspension(path: Path) -> dict[str, np.ndarray | float] | None:
    """The /suspension series and its bin height (cm); None in a file without them (written
    before they were, or of fewer than three disks)."""
    with open_h5(path) as h5:
        if "suspension" not in h5:
            return None
        g = h5["suspension"]
        missing = [name for name in SERIES if name not in g]
        if missing:
            raise RunFileError(path, f"/suspension lacks {', '.join(missing)}")
        out: dict[str, np.ndarray | float] = {name: g[name][()] for name in SERIES}
        out["bin"] = float(g.attrs["bin"])
    return out


def area_below(y: np.ndarray, r: np.ndarray, h: np.ndarray) -> np.ndarray:
    """The area (cm^2) of each disk (centre height y, radius r) below each height h: an array
    (disks, heights), exact (circular segments)."""
    t = np.clip((h[None, :] - y[:, None]) / r[:, None], -1.0, 1.0)
    return r[:, None] ** 2 * (np.arcsin(t) + t * np.sqrt(1.0 - t * t) + 0.5 * np.pi)


def surface_gaps(x: np.ndarray, y: np.ndarray, r: np.ndarray) -> np.ndarray:
    """The gap (cm) between the surfaces of every two disks (negative: an overlap), an array
    (disks, disks) with inf on its diagonal."""
    gap = np.hypot(x[:, None] - x[None, :], y[:, None] - y[None, :]) - (r[:, None] + r[None, :])
    np.fill_diagonal(gap, np.inf)
    return gap


def contacts(gap: np.ndarray, reach: float) -> np.ndarray:
    """The contact number of each disk: how many other disks have a surface gap (the array of
    surface_gaps) below `reach` (cm) from it (walls not counted)."""
    return (gap < reach).sum(axis=1)


def from_particles(run: Run) -> dict[str, np.ndarray | float]:
    """The /suspension series computed from /particles as dktlbm computes them
    (src/dkt_suspension.f90), for a run file written before it stored them: all disks counted
    as free, the box's height from &domain height, bins of the largest diameter."""
    y, v = run.series["y"], run.series["v"]
    r = 0.5 * run.diameters
    height = run.settings.number("domain", "height")
    bin_ = float(2.0 * r.max())
    nb = max(1, int(np.ceil(height / bin_ - 1e-9)))
    rank = max(1, int(np.ceil(0.95 * y.shape[1]))) - 1
    small, large = r.min(), r.max()
    two = large > small and bool(np.all((r == small) | (r == large)))
    lines = np.arange(nb + 1) * bin_
    phi = np.stack([np.diff(area_below(row, r, lines), axis=1).sum(axis=0) for row in y])
    return {
        "t": run.t,
        "v_mean": v.mean(axis=1),
        "v_rms": np.sqrt((v**2).mean(axis=1)),
        "front": np.sort(y, axis=1)[:, rank],
        "segregation": ((y[:, r == small].mean(axis=1) - y[:, r == large].mean(axis=1)) / height
                        if two else np.zeros(len(run.t))),
        "phi": phi / (bin_ * run.width),
        "bin": bin_,
    }


def plot(run: Run, s: dict[str, np.ndarray | float], panels: int):
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle

    t = np.asarray(s["t"])
    n = len(t)
    picks = sorted({int(round(k)) for k in np.linspace(0, n - 1, panels)})
    fig = Figure(figsize=(3.0 * len(picks), 9.0), layout="constrained")
    grid = fig.add_gridspec(3, len(picks))
    ax = fig.add_subplot(grid[0, :])
    ax.plot(t, s["front"], label="upper front (95 % of centres below)")
    ax.set_ylabel("height (cm)")
    ax.grid(True, alpha=0.3)
    ax2 = ax.twinx()
    ax2.plot(t, s["v_mean"], color="tab:red", label="mean v")
    ax2.plot(t, s["v_rms"], color="tab:red", linestyle="--", label="rms v")
    seg = np.asarray(s["segregation"])
    if seg.any():
        ax2.plot(t, seg, color="tab:green", label="segregation index")
    ax2.set_ylabel("cm/s (index: -)")
    lines = ax.get_lines() + ax2.get_lines()
    ax.legend(lines, [line.get_label() for line in lines], fontsize="small", loc="best")
    ax.set_xlabel("t (s)")
    phi = np.asarray(s["phi"])
    centres = (np.arange(phi.shape[1]) + 0.5) * float(s["bin"])
    height = phi.shape[1] * float(s["bin"])
    r = 0.5 * run.diameters
    for col, k in enumerate(picks):
        snap = fig.add_subplot(grid[1, col], aspect="equal")
        for x, y, rk in zip(run.series["x"][k], run.series["y"][k], r, strict=True):
            snap.add_patch(Circle((x, y), rk, color="0.3", linewidth=0))
        snap.set_xlim(0.0, run.width)
        snap.set_ylim(0.0, height)
        snap.set_title(f"t = {t[k]:.3g} s", fontsize="small")
        snap.tick_params(labelsize="x-small")
        prof = fig.add_subplot(grid[2, col])
        prof.plot(phi[k], centres)
        prof.set_xlim(0.0, max(0.05, float(phi.max()) * 1.05))
        prof.set_ylim(0.0, height)
        prof.set_xlabel(r"$\phi$", fontsize="small")
        prof.tick_params(labelsize="x-small")
        if col == 0:
            snap.set_ylabel("y (cm)")
            prof.set_ylabel("y (cm)")
    fig.suptitle(f"{run.name}: {run.count} disks, W = {run.width:g} cm")
    return fig


def summary(run: Run, s: dict[str, np.ndarray | float]) -> list[str]:
    """The figures a suspension is compared by, as lines: when the first disk reached the
    bottom (its surface within 2 lattice spacings), the front and the settling velocities at a
    few times, and at the last sample the fastest disk, the smallest gap between two surfaces
    (negative: an overlap) and the packed area fraction (the disks' area over the box's below
    the highest disk top)."""
    t = np.asarray(s["t"])
    x, y, v = run.series["x"], run.series["y"], run.series["v"]
    r = 0.5 * run.diameters
    lines = [f"{run.count} disks, {len(t)} samples to t = {t[-1]:.4g} s"]
    near = np.flatnonzero(((y - r) < 2.0 * run.dx).any(axis=1))
    lines.append("first disk at the bottom (surface within 2 spacings): "
                 + (f"t = {t[near[0]]:.4g} s" if near.size else "not by the end"))
    for k in sorted({int(round(k)) for k in np.linspace(0, len(t) - 1, 9)}):
        lines.append(f"t = {t[k]:8.4g} s  front {float(s['front'][k]):.4f} cm  v_mean "
                     f"{float(s['v_mean'][k]):+.4f} cm/s  v_rms {float(s['v_rms'][k]):.4f} cm/s")
    last = -1
    gap = surface_gaps(x[last], y[last], r)
    top = float((y[last] + r).max())
    packed = float((np.pi * r**2).sum()) / (run.width * top)
    lines.append(f"at t = {t[last]:.4g} s: fastest disk {np.abs(v[last]).max():.4g} cm/s, "
                 f"smallest surface gap {gap.min():.4g} cm ({gap.min() / run.dx:.3g} spacings), "
                 f"highest disk top {top:.4f} cm, packed area fraction {packed:.3f}")
    below = top - 2.0 * float(r.max())
    if below > 0.0:
        bulk = float(area_below(y[last], r, np.array([below])).sum()) / (run.width * below)
        lines.append(f"at t = {t[last]:.4g} s: bulk area fraction {bulk:.3f} (below {below:.4f} cm,"
                     " one largest diameter under the highest top)")
    xi = run.settings.number("collision", "range")
    if xi > 0.0:
        z = contacts(gap, xi * run.dx)
        walls = ((x[last] - r < xi * run.dx) | (run.width - x[last] - r < xi * run.dx)
                 | (y[last] - r < xi * run.dx))
        inner = f", {z[~walls].mean():.2f} away from the walls" if (~walls).any() else ""
        lines.append(f"at t = {t[last]:.4g} s: contacts per disk (surface gap below the contact "
                     f"range, {xi:g} spacings) {z.mean():.2f}{inner}")
    return lines


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    if not 1 <= args.panels <= 8:
        parser().error(f"--panels {args.panels}: allowed 1 to 8")

    def body() -> int:
        run = open_run(args.run)
        if run.count < 3:
            raise RunFileError(args.run, f"{run.count} particles; a suspension has three or "
                                         "more (and its run file /suspension)")
        s = read_suspension(args.run)
        if s is None:
            s = from_particles(run)
        if len(np.asarray(s["t"])) != len(run.t):
            raise RunFileError(args.run, "/suspension and /particles differ in length")
        if args.summary:
            print("\n".join(summary(run, s)))
            return 0
        save_figure(plot(run, s, args.panels), output_path(args.run, "suspension", args.output),
                    args.pdf)
        return 0

    return guarded(body)


if __name__ == "__main__":
    sys.exit(main())
