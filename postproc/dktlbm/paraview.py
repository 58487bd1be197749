"""Render a run in ParaView to a PNG: the vorticity (or another field) of one output time with
the disks drawn as glyphs of their radius, the view a user builds by hand (docs/output.md,
"Open it in ParaView"). ParaView's `pvpython` draws it, from the run's XDMF sidecars
`<name>.xdmf` (the fields) and `<name>_particles.xdmf` (the disks); without a display it runs
under `xvfb-run -a`."""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
from pathlib import Path

from .read import RunFileError, add_version, guarded, output_path

RENDER = Path(__file__).resolve().with_name("paraview_scripts") / "render.py"


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="dkt-paraview",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="example: dkt-paraview runs/case1/case1.h5 --time 1.5 -o case1_paraview.png",
    )
    add_version(p)
    p.add_argument("run", type=Path, metavar="RUN.h5",
                   help="a dktlbm run file, or its sidecar <name>.xdmf")
    p.add_argument("--time", type=float, metavar="T",
                   help="time in s; the nearest output is drawn (default: the last)")
    p.add_argument("--field", default="vorticity",
                   help="the point field to colour by (default vorticity; also rho, ux, uy, "
                   "pressure, particle)")
    p.add_argument("--range", type=float, default=20.0, metavar="R",
                   help="colour range -R..R in the field's unit (default 20)")
    p.add_argument("--size", type=int, nargs=2, default=(760, 1400), metavar=("W", "H"),
                   help="image size in pixels (default 760 1400)")
    p.add_argument("-o", "--output", type=Path, metavar="OUT.png",
                   help="the PNG to write (default: beside the run file, <name>_paraview.png)")
    return p


def sidecar(run: Path) -> Path:
    """The main XDMF sidecar of the run file or sidecar `run`; RunFileError when it is not
    there."""
    name = run.name
    for ending in ("_particles.xdmf", ".xdmf", ".h5"):
        if name.endswith(ending):
            name = name[: -len(ending)]
            break
    xdmf = run.with_name(name + ".xdmf")
    if not xdmf.is_file():
        raise RunFileError(xdmf, "no such file (the XDMF sidecar a run writes beside "
                           "<name>.h5; give a dktlbm run file or its .xdmf)")
    return xdmf


def pvpython_command(attempt: int = 0) -> list[str]:
    """pvpython, under `xvfb-run -a` when there is no display; RunFileError when either is
    missing. xvfb-run -a takes the first free server number from the one given, and two that
    start together can take the same one: each process (and each attempt) starts from its own."""
    pvpython = shutil.which("pvpython")
    if pvpython is None:
        raise RunFileError("pvpython", "not found on PATH; install ParaView (Debian and "
                           "Ubuntu: apt install paraview) or put its bin directory on PATH")
    if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
        return [pvpython]
    xvfb = shutil.which("xvfb-run")
    if xvfb is None:
        raise RunFileError("display", "none (DISPLAY is not set) and xvfb-run is not on PATH "
                           "to make one; install xvfb (apt install xvfb) or run from a "
                           "desktop session")
    first = 100 + (os.getpid() * 7 + attempt * 101) % 5000
    return [xvfb, "-a", "-n", str(first), pvpython]


def render(arguments: list[str]) -> int:
    """Run the render script with `arguments`; a second and a third time under another virtual
    display when xvfb-run's server was lost to another one that started at the same moment
    (pvpython then reports a bad X server connection)."""
    attempt = 0
    while True:
        runner = pvpython_command(attempt)
        proc = subprocess.run([*runner, str(RENDER), *arguments], stderr=subprocess.PIPE,
                              text=True)
        # under xvfb-run (more than pvpython alone), its display refused pvpython
        lost = len(runner) > 1 and "bad X server connection" in proc.stderr
        if proc.returncode == 0 or not lost or attempt == 2:
            sys.stderr.write(proc.stderr)
            return proc.returncode
        attempt += 1


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)

    def body() -> int:
        xdmf = sidecar(args.run)
        png = output_path(xdmf, "paraview", args.output)
        arguments = [str(xdmf.resolve()), "--field", args.field, "--range", repr(args.range),
                     "--size", str(args.size[0]), str(args.size[1]), "-o", str(png.resolve())]
        if args.time is not None:
            arguments += ["--time", repr(args.time)]
        return render(arguments)

    return guarded(body)


if __name__ == "__main__":
    sys.exit(main())
