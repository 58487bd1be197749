"""One flow field of a run at one time: the stored snapshot nearest to --time, drawn in
physical coordinates (x from 0 to W, y from the window offset up, cm, equal aspect) with the
particles as circles at their positions at that time (the nearest /particles sample). Nodes
inside a particle are left blank. Vorticity uses a diverging colour map centred on zero.

--movie draws every stored snapshot instead, one frame each, into an MP4 (ffmpeg), or a GIF
when ffmpeg is not found; the colour range is the same in every frame."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

from .read import (
    FIELD_NAMES,
    Run,
    RunFileError,
    Snapshot,
    add_output_options,
    add_version,
    field_times,
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
    add_version(p)
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
    p.add_argument("--movie", nargs="?", const="", metavar="OUT.mp4",
                   help="a movie of every stored snapshot instead of one picture: OUT.mp4 "
                   "(default: beside the run file, <name>_<field>.mp4), a GIF (.gif) when "
                   "ffmpeg is not found or OUT ends in .gif")
    p.add_argument("--fps", type=float, default=5.0,
                   help="with --movie: frames (snapshots) per second (default 5)")
    return p


def open_particles(path: Path) -> tuple[Run | None, float]:
    """The run's particles (None for a run without them) and t_ref of t* (s)."""
    try:
        run = open_run(path)
    except RunFileError as exc:
        if "no particles" in exc.what:
            return None, run_t_ref(path)
        raise
    return run, run.t_ref


def circles_at(run: Run | None, time: float) -> list[tuple[float, float, float]]:
    """(x, y, radius) of each particle at the /particles sample nearest to `time`."""
    if run is None:
        return []
    i = int(np.argmin(np.abs(run.t - time)))
    return [(float(run.series["x"][i, k]), float(run.series["y"][i, k]),
             0.5 * float(run.diameters[k])) for k in range(run.count)]


def title_of(path: Path, snap: Snapshot, t_ref: float) -> str:
    return (f"{path.stem}: {snap.name} at t = {snap.time:.4g} s "
            f"(t* = {snap.time / t_ref:.3g}, step {snap.step})")


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


def movie(path: Path, name: str, out: Path | None, ylim: tuple[float, float] | None,
          vmax: float | None, cmap: str | None, fps: float) -> Path:
    """Every stored snapshot of field `name`, in time order, one frame each, with the disks
    and the time in the title: an MP4 through ffmpeg, else (ffmpeg not on PATH) a GIF. The
    colour range is the first frame's, from the 99th percentile of all snapshots when `vmax`
    is not given. Returns the file written."""
    from matplotlib import animation
    from matplotlib.patches import Circle

    snaps = [read_field(path, name, t) for _, t in field_times(path)]
    run, t_ref = open_particles(path)
    if vmax is None:
        values = np.concatenate([np.abs(s.data[np.isfinite(s.data)]).ravel() for s in snaps])
        vmax = float(np.percentile(values, 99)) if values.size else None
    if out is not None and out.suffix.lower() == ".gif":
        writer, suffix = animation.PillowWriter(fps=fps), ".gif"  # asked for
    elif animation.FFMpegWriter.isAvailable():
        writer, suffix = animation.FFMpegWriter(fps=fps), ".mp4"
    else:
        writer, suffix = animation.PillowWriter(fps=fps), ".gif"
        print("ffmpeg not found: writing a GIF")
    out = out if out is not None else path.with_name(f"{path.stem}_{name}.mp4")
    out = out.with_suffix(suffix)
    out.parent.mkdir(parents=True, exist_ok=True)

    first = snaps[0]
    fig = plot(first, circles_at(run, first.time), title_of(path, first, t_ref), ylim, vmax,
               cmap)
    ax = fig.axes[0]
    image = ax.images[0]
    with writer.saving(fig, str(out), dpi=100):
        for snap in snaps:
            data = snap.data.copy()
            if snap.solid is not None:
                data[snap.solid] = np.nan
            image.set_data(np.ma.masked_invalid(data))
            image.set_extent(snap.extent)
            x0, x1, y0, y1 = snap.extent
            if ylim is not None:
                y0, y1 = max(y0, min(ylim)), min(y1, max(ylim))
            ax.set_ylim(y0, y1)
            for patch in list(ax.patches):
                patch.remove()
            for x, y, r in circles_at(run, snap.time):
                ax.add_patch(Circle((x, y), r, fill=False, edgecolor="k", linewidth=1.0))
            ax.set_title(title_of(path, snap, t_ref), fontsize="medium")
            writer.grab_frame()
    print(f"wrote {out} ({len(snaps)} frames)")
    return out


def main(argv: list[str] | None = None) -> int:
    p = parser()
    args = p.parse_args(argv)
    if not args.fps > 0:
        p.error(f"--fps must be positive (got {args.fps:g})")
    if args.cmap is not None:
        import matplotlib

        if args.cmap not in matplotlib.colormaps:
            p.error(f"--cmap: unknown colour map {args.cmap!r}")

    def body() -> int:
        ylim = tuple(args.ylim) if args.ylim else None
        if args.movie is not None:
            movie(args.run, args.field, Path(args.movie) if args.movie else None, ylim,
                  args.vmax, args.cmap, args.fps)
            return 0
        snap = read_field(args.run, args.field, args.time)
        if args.time is not None and not math.isclose(snap.time, args.time, rel_tol=1e-9,
                                                      abs_tol=1e-12):
            # the nearest snapshot is drawn: say which, so that a time past the run's end (or
            # between snapshots) is not taken for the one asked for
            print(f"note: {args.run}: no field snapshot at t = {args.time:g} s; drawing the "
                  f"nearest, {snap.group} at t = {snap.time:g} s", file=sys.stderr)
        run, t_ref = open_particles(args.run)
        fig = plot(snap, circles_at(run, snap.time), title_of(args.run, snap, t_ref), ylim,
                   args.vmax, args.cmap)
        save_figure(fig, output_path(args.run, f"{args.field}", args.output), args.pdf)
        return 0

    return guarded(body)


if __name__ == "__main__":
    sys.exit(main())
