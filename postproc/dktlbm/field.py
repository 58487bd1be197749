"""One flow field of a run at one time: the stored snapshot nearest to --time, drawn in
physical coordinates (x from 0 to W, y from the window offset up, cm, equal aspect) with the
particles as circles at their positions at that time (the nearest /particles sample). Nodes
inside a particle are left blank. Vorticity uses a diverging colour map centred on zero."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from .read import (
    FIELD_NAMES,
    RunFileError,
    Snapshot,
    add_output_options,
    guarded,
    open_run,
    output_path,
    read_field,
    run_t_ref,
    save_figure,
)

UNITS = {
    "vorticity": "1/s",
    "pressure": "g/(cm s$^2$)",
    "speed": "cm/s",
    "ux": "cm/s",
    "uy": "cm/s",
    "rho": "g/cm$^3$",
}


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="dkt-field",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="example: dkt-field runs/case1/case1.h5 --field vorticity "
        "--time 1.4 --ylim 10 14",
    )
    p.add_argument("run", type=Path, metavar="RUN.h5", help="a dktlbm run file")
    add_output_options(p, "field")
    p.add_argument("--field", choices=FIELD_NAMES, default="vorticity",
                   help="the field to draw (default vorticity; speed = |u|)")
    p.add_argument("--time", type=float, metavar="T",
                   help="time in s; the nearest stored snapshot is drawn (default: the last)")
    p.add_argument("--ylim", nargs=2, type=float, metavar=("Y0", "Y1"),
                   help="show only y0 <= y <= y1 (cm, absolute coordinates)")
    p.add_argument("--vmax", type=float,
                   help="colour range: -vmax..vmax for vorticity, up to vmax otherwise "
                   "(default: from the 99th percentile of the data)")
    p.add_argument("--cmap", help="matplotlib colour map (default RdBu_r for vorticity, "
                   "viridis otherwise)")
    return p


def particle_circles(path: Path, time: float) -> tuple[list[tuple[float, float, float]], float]:
    """(x, y, radius) of each particle at the /particles sample nearest to `time` (none for a
    run without particles), and t_ref of t* (s)."""
    try:
        run = open_run(path)
    except RunFileError as exc:
        if "no particles" in exc.what:
            return [], run_t_ref(path)
        raise
    i = int(np.argmin(np.abs(run.t - time)))
    circles = [(float(run.series["x"][i, k]), float(run.series["y"][i, k]),
                0.5 * float(run.diameters[k])) for k in range(run.count)]
    return circles, run.t_ref


def plot(snap: Snapshot, circles: list[tuple[float, float, float]], title: str,
         ylim: tuple[float, float] | None, vmax: float | None, cmap: str | None):
    import matplotlib
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle

    data = snap.data.copy()
    if snap.solid is not None:
        data[snap.solid] = np.nan
    x0, x1, y0, y1 = snap.extent
    if ylim is not None:
        y0, y1 = max(y0, min(ylim)), min(y1, max(ylim))
    finite = np.abs(data[np.isfinite(data)])
    vorticity = snap.name == "vorticity"
    if vorticity:
        top = vmax if vmax is not None else (float(np.percentile(finite, 99)) if finite.size
                                            else 1.0)
        top = top if top > 0 else 1.0
        limits = (-top, top)
    else:
        good = data[np.isfinite(data)]
        lo = float(np.percentile(good, 1)) if good.size else 0.0
        hi = vmax if vmax is not None else (float(np.percentile(good, 99)) if good.size else 1.0)
        limits = (lo, hi if hi > lo else lo + 1.0)
    colours = matplotlib.colormaps[cmap or ("RdBu_r" if vorticity else "viridis")].copy()
    colours.set_bad("lightgrey")

    aspect = (y1 - y0) / max(x1 - x0, 1e-12)
    width = 5.0
    fig = Figure(figsize=(width, min(max(width * aspect * 0.85, 3.5), 12.0)),
                 layout="constrained")
    ax = fig.subplots()
    image = ax.imshow(np.ma.masked_invalid(data), origin="lower", extent=snap.extent,
                      cmap=colours, vmin=limits[0], vmax=limits[1], interpolation="nearest")
    for x, y, r in circles:
        ax.add_patch(Circle((x, y), r, fill=False, edgecolor="k", linewidth=1.0))
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_xlabel("x (cm)")
    ax.set_ylabel("y (cm)")
    ax.set_title(title, fontsize="medium")
    fig.colorbar(image, ax=ax, label=f"{snap.name} ({UNITS[snap.name]})", shrink=0.8)
    return fig


def main(argv: list[str] | None = None) -> int:
    p = parser()
    args = p.parse_args(argv)
    if args.cmap is not None:
        import matplotlib

        if args.cmap not in matplotlib.colormaps:
            p.error(f"--cmap: unknown colour map {args.cmap!r}")

    def body() -> int:
        snap = read_field(args.run, args.field, args.time)
        circles, t_ref = particle_circles(args.run, snap.time)
        title = (f"{args.run.stem}: {snap.name} at t = {snap.time:.4g} s "
                 f"(t* = {snap.time / t_ref:.3g}, step {snap.step})")
        fig = plot(snap, circles, title, tuple(args.ylim) if args.ylim else None, args.vmax,
                   args.cmap)
        save_figure(fig, output_path(args.run, f"{args.field}", args.output), args.pdf)
        return 0

    return guarded(body)


if __name__ == "__main__":
    sys.exit(main())
