"""A run's particle series as a pandas DataFrame or an xarray Dataset (Run.to_dataframe,
Run.to_xarray), each value with its unit.

pandas and xarray are optional (`pip install 'dktlbm[frames]'`); each is imported only here,
when asked for, and its absence is an ImportError that names the pip package.

Layout, the same in both: one row (pandas) or element (xarray) per particle and sample,
`particle` numbered from 1 as in the run file and input, `t` in s; the series of /particles
(x, y, u, v, omega, fx, fy, torque), and window_offset (the window's bottom, the same for
every particle) when the file has it. Units, as the program writes them in the datasets'
`units` attributes (docs/output.md): pandas `df.attrs["units"]` ({column or index name:
unit}), xarray each variable's and coordinate's `attrs["units"]`.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from .read import Run

UNITS = {
    "t": "s",
    "particle": "1",
    "x": "cm",
    "y": "cm",
    "u": "cm/s",
    "v": "cm/s",
    "omega": "1/s",
    "fx": "g/s^2",
    "fy": "g/s^2",
    "torque": "g cm/s^2",
    "window_offset": "cm",
    "diameter": "cm",
}


def _module(name: str, method: str) -> Any:
    """The module `name`, or an ImportError that says how to install it."""
    try:
        return importlib.import_module(name)
    except ImportError:
        raise ImportError(f"Run.{method}() needs {name}, which is not installed: "
                          f"pip install {name}  (or: pip install 'dktlbm[frames]')") from None


def _series(run: Run) -> dict[str, np.ndarray]:
    """Each series of /particles as (count, n): particle first, then time."""
    return {name: np.asarray(values, dtype=float).T for name, values in run.series.items()}


def to_dataframe(run: Run) -> Any:
    """The run's particle series as a pandas DataFrame indexed by (particle, t)."""
    pd = _module("pandas", "to_dataframe")
    index = pd.MultiIndex.from_product([np.arange(1, run.count + 1), run.t],
                                       names=["particle", "t"])
    columns = {name: a.ravel() for name, a in _series(run).items()}
    if run.window_offset is not None:  # the same for every particle
        columns["window_offset"] = np.tile(np.asarray(run.window_offset, dtype=float), run.count)
    df = pd.DataFrame(columns, index=index)
    df.attrs["units"] = {name: UNITS[name] for name in ("particle", "t", *df.columns)}
    df.attrs["run"] = str(run.path)
    return df


def to_xarray(run: Run) -> Any:
    """The run's particle series as an xarray Dataset over (particle, t), with the particles'
    diameters."""
    xr = _module("xarray", "to_xarray")
    data = {name: (("particle", "t"), a, {"units": UNITS[name]})
            for name, a in _series(run).items()}
    if run.window_offset is not None:
        data["window_offset"] = ("t", np.array(run.window_offset, dtype=float),
                                 {"units": UNITS["window_offset"]})
    data["diameter"] = ("particle", np.asarray(run.diameters, dtype=float),
                        {"units": UNITS["diameter"]})
    coords = {"particle": ("particle", np.arange(1, run.count + 1), {"units": UNITS["particle"]}),
              "t": ("t", run.t, {"units": UNITS["t"]})}
    return xr.Dataset(data, coords=coords, attrs={"run": str(run.path)})
