"""dktlbm post-processing: read dktlbm run files, plot and classify them, run sweeps.

Modules: read (the run-file reader), launch (starting dktlbm on MPI ranks), gap,
trajectories, drag, field, pattern, sweep, paraview (each also a console command
dkt-<name>; paraview runs paraview_scripts/render.py under ParaView's pvpython).
postproc/README.md documents them.
"""


def _version() -> str:
    """The installed package's version, else (run from the source tree) the one in the tree's
    pyproject.toml, else 'unknown'."""
    from importlib import metadata
    from pathlib import Path

    try:
        return metadata.version("dktlbm")
    except metadata.PackageNotFoundError:
        pass
    project = Path(__file__).resolve().parents[2] / "pyproject.toml"
    try:
        for line in project.read_text().splitlines():
            if line.startswith("version = "):
                return line.split("=", 1)[1].strip().strip('"')
    except OSError:
        pass
    return "unknown"


__version__ = _version()
