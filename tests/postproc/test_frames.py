"""Run.to_dataframe() and Run.to_xarray(): the particle series with their units.

- Every series of /particles (and window_offset) of a synthetic two-particle run is in the
  DataFrame, indexed by (particle from 1, t), and in the Dataset over (particle, t), value for
  value as Run holds it; the Dataset also has the diameters.
- Each column, index level, variable and coordinate carries a unit, and those of the series
  equal the `units` attributes dktlbm writes on /particles (a short real run).
- Without pandas or xarray, the method raises an ImportError that names the pip package.
The pandas and xarray checks are skipped where those packages are not installed.
"""

from __future__ import annotations

import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
import synthetic as syn

from dkt_run import run as run_dktlbm
from dktlbm import read
from dktlbm.frames import UNITS


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> read.Run:
    path = tmp_path_factory.mktemp("frames") / "pair.h5"
    syn.write_run(path, syn.SHAPES["once"], (0.2, 0.1), fields=False)
    return read.open_run(path)


def test_dataframe_holds_every_series_with_its_unit(run: read.Run) -> None:
    """(particle, t) rows, the series and window_offset as columns, units in df.attrs."""
    pd = pytest.importorskip("pandas")
    df = run.to_dataframe()
    assert isinstance(df, pd.DataFrame)
    assert list(df.index.names) == ["particle", "t"]
    assert list(df.columns) == [*read.SERIES, "window_offset"]
    assert len(df) == run.count * run.t.size
    for k in range(run.count):
        one = df.loc[k + 1]
        np.testing.assert_array_equal(one.index.to_numpy(), run.t)
        for name in read.SERIES:
            np.testing.assert_array_equal(one[name].to_numpy(), run.series[name][:, k])
        np.testing.assert_array_equal(one["window_offset"].to_numpy(), run.window_offset)
    assert df.attrs["units"] == {name: UNITS[name] for name in ("particle", "t", *df.columns)}
    assert df.attrs["units"]["x"] == "cm" and df.attrs["units"]["t"] == "s"


def test_dataset_holds_every_series_with_its_unit(run: read.Run) -> None:
    """The series over (particle, t), window_offset over t, diameters; units in attrs."""
    xr = pytest.importorskip("xarray")
    ds = run.to_xarray()
    assert isinstance(ds, xr.Dataset)
    assert dict(ds.sizes) == {"particle": run.count, "t": run.t.size}
    np.testing.assert_array_equal(ds["particle"].to_numpy(), np.arange(1, run.count + 1))
    np.testing.assert_array_equal(ds["t"].to_numpy(), run.t)
    for name in read.SERIES:
        assert ds[name].dims == ("particle", "t")
        np.testing.assert_array_equal(ds[name].to_numpy(), run.series[name].T)
    assert ds["window_offset"].dims == ("t",)
    np.testing.assert_array_equal(ds["window_offset"].to_numpy(), run.window_offset)
    np.testing.assert_array_equal(ds["diameter"].to_numpy(), run.diameters)
    for name in (*ds.data_vars, *ds.coords):
        assert ds[name].attrs.get("units") == UNITS[name], name


def test_the_units_are_the_programs(tmp_path: Path) -> None:
    """The units of the series, time and window offset are the `units` attributes of
    /particles in a run file written by dktlbm (case1, 8 per D, 0.05 s)."""
    run_dktlbm("case1.nml", sets=["lbm.cells_per_diameter=8", "run.t_end=0.05"],
               outdir=tmp_path)
    with h5py.File(tmp_path / "case1.h5") as h5:
        written = {name: read.text_attr(d.attrs["units"]) for name, d in h5["particles"].items()}
    assert set(written) == {"t", "window_offset", *read.SERIES}
    assert written == {name: UNITS[name] for name in written}


@pytest.mark.parametrize(("method", "package"), [("to_dataframe", "pandas"),
                                                 ("to_xarray", "xarray")])
def test_a_missing_package_is_named(run: read.Run, monkeypatch: pytest.MonkeyPatch,
                                    method: str, package: str) -> None:
    """With the package unimportable, the ImportError says which one and how to install it."""
    monkeypatch.setitem(sys.modules, package, None)  # import raises ImportError
    with pytest.raises(ImportError, match=rf"needs {package}.*pip install {package}"):
        getattr(run, method)()
