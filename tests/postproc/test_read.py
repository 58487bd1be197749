"""dktlbm.read on both forms of the run file, and its defaults against the executable's.

- The same run written in the old form (integers as floats, fixed-length byte strings, a float
  `particle` mask) and in the new one (integer attributes, variable-length UTF-8 strings, an
  int16 `particle` mask, `*_units` companion attributes and `units` on datasets) reads to the
  same values: scales, series, thresholds, pattern, status, fields and the solid mask.
- For a file that lacks the scales in /run, the values the reader takes (t_ref, gravity,
  fluid density and viscosity, width, diameters, kissing thresholds) equal what the dktlbm
  executable reports for the stored namelist (`--print-defaults`, and `--check` for the
  thresholds), parsed here independently of the reader; when the executable refuses the
  stored namelist, its defaults with the namelist's values over them.
- For a file that stores the kissing thresholds in /run (every pair's file since 0.1.0), the
  reader takes them from there and never runs the executable, also with thresholds given by
  the user over some of them.
"""

from __future__ import annotations

import os
import re
import subprocess
from pathlib import Path

import h5py
import numpy as np
import pytest
import synthetic as syn

from dktlbm import read

EXE = os.environ.get("DKTLBM_EXE", "dktlbm")
UNITS = {"dx": "cm", "dt": "s", "t_ref": "s", "width": "cm", "time": "s", "window_offset": "cm"}
INTEGERS = ("nx", "ny", "steps", "ranks", "count", "step")


def to_new_form(path: Path) -> None:
    """Rewrite a synthetic (old-form) run file in the new form, keeping every value."""
    with h5py.File(path, "r+") as h5:
        objects: list[h5py.HLObject] = []
        h5.visit(lambda name: objects.append(h5[name]))
        for obj in objects:
            for key, value in list(obj.attrs.items()):
                a = np.asarray(value)
                if a.dtype.kind == "S":
                    del obj.attrs[key]
                    obj.attrs.create(key, a.item().decode(), dtype=h5py.string_dtype("utf-8"))
                elif key in INTEGERS:
                    obj.attrs[key] = np.int64(round(float(a)))
                if key in UNITS:
                    obj.attrs[f"{key}_units"] = UNITS[key]
            if isinstance(obj, h5py.Dataset):
                obj.attrs["units"] = "1"
        for snap in h5["fields"].values():
            mask = snap["particle"][()]
            del snap["particle"]
            snap["particle"] = mask.astype(np.int16)


def to_old_form(path: Path) -> None:
    """The oldest form: a float `particle` mask (synthetic writes integers)."""
    with h5py.File(path, "r+") as h5:
        for snap in h5["fields"].values():
            mask = snap["particle"][()]
            del snap["particle"]
            snap["particle"] = mask.astype(np.float64)


@pytest.fixture(scope="module")
def both(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    base = tmp_path_factory.mktemp("forms")
    old, new = base / "old.h5", base / "new.h5"
    for path in (old, new):
        syn.write_run(path, syn.SHAPES["repeated"], (0.2, 0.1))
        with h5py.File(path, "r+") as h5:
            h5["run"].attrs["stop_reason"] = np.bytes_(b"finished")
            h5["run"].attrs["version"] = np.bytes_(b"0.1.0")
    to_old_form(old)
    to_new_form(new)
    with h5py.File(new, "r") as h5:  # the conversion gave the new form
        assert h5["run"].attrs["nx"].dtype.kind == "i"
        assert isinstance(h5["run"].attrs["stop_reason"], str)
        assert h5["fields/000000/particle"].dtype == np.int16
        assert h5["run"].attrs["dx_units"] == "cm"
    with h5py.File(old, "r") as h5:
        assert h5["run"].attrs["nx"].dtype.kind == "f"
        assert isinstance(h5["run"].attrs["stop_reason"], np.bytes_)
    return old, new


def test_old_and_new_forms_read_alike(both: tuple[Path, Path]) -> None:
    """Scales, series, pattern and episodes, status and stop reason agree between the forms;
    the `*_units` companions are not taken for numeric attributes."""
    old, new = (read.open_run(p) for p in both)
    for name in ("dx", "dt", "steps", "count", "t_ref", "h_ref", "gravity", "width", "rho_f",
                 "mu", "stop_reason"):
        assert getattr(old, name) == getattr(new, name), name
    assert old.steps == round(syn.T_END / syn.DT) and isinstance(new.steps, int)
    assert new.stop_reason == "finished" and new.complete
    np.testing.assert_array_equal(old.diameters, new.diameters)
    for name in read.SERIES:
        np.testing.assert_array_equal(old.series[name], new.series[name])
    assert not any(k.endswith("_units") for k in new.run_attrs)
    assert set(old.run_attrs) == set(new.run_attrs)
    p_old, p_new = read.pair_of(old), read.pair_of(new)
    assert p_new.pattern == p_old.pattern == "repeated"
    assert (p_new.limits.enter, p_new.limits.release) == (p_old.limits.enter,
                                                          p_old.limits.release)
    assert [(e.start, e.end) for e in p_new.episodes] == [(e.start, e.end)
                                                          for e in p_old.episodes]
    assert read.run_status(both[0]) == read.run_status(both[1]) == "finished"


def test_fields_and_the_solid_mask_read_alike(both: tuple[Path, Path]) -> None:
    """Each stored field, its time and step, and the particle mask (float in the old form,
    int16 in the new) read the same; the mask marks nodes inside the disks."""
    assert read.field_times(both[0]) == read.field_times(both[1])
    for time in syn.FIELD_TIMES:
        old = read.read_field(both[0], "vorticity", time)
        new = read.read_field(both[1], "vorticity", time)
        assert (old.time, old.step, old.offset, old.dx) == (new.time, new.step, new.offset,
                                                            new.dx)
        np.testing.assert_array_equal(old.data, new.data)
        assert old.solid is not None and new.solid is not None
        np.testing.assert_array_equal(old.solid, new.solid)
        assert new.solid.any() and not new.solid.all()


def printed(text: str, group: str, key: str) -> list[float]:
    """The values of `&group key = ...` in --print-defaults output, read with a regex."""
    block = re.search(rf"^&{group}\n(.*?)^/", text, flags=re.M | re.S)
    assert block, f"&{group} not in --print-defaults"
    line = re.search(rf"^\s*{key}\s*=\s*([^!\n]*)", block.group(1), flags=re.M)
    assert line, f"{group}.{key} not in --print-defaults"
    return [float(v) for v in line.group(1).replace(",", " ").split()]


def test_scales_of_an_old_file_are_the_executables(tmp_path: Path) -> None:
    """A file with only the namelist in /run (which gives none of these keys): t_ref, g,
    rho_f, mu, W and the diameters are what `dktlbm --print-defaults` prints for it, and
    H = g t_ref^2."""
    f = tmp_path / "bare.h5"
    syn.write_run(f, syn.SHAPES["never"], (0.2, 0.1), fields=False)
    scene = "&particles\n  count = 2, x = 0.5, 1.5\n/\n"
    with h5py.File(f, "r+") as h5:
        h5["run"].attrs["namelist"] = np.bytes_(scene.encode())
    (tmp_path / "scene.nml").write_text(scene)
    out = subprocess.run([EXE, str(tmp_path / "scene.nml"), "--print-defaults"],
                         capture_output=True, text=True, check=True,
                         env={**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1",
                              "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1"}).stdout
    run = read.open_run(f)
    t_ref, g = printed(out, "run", "t_ref")[0], printed(out, "particles", "gravity")[0]
    assert (run.t_ref, run.gravity) == (t_ref, g)
    assert run.h_ref == pytest.approx(g * t_ref**2)
    assert run.rho_f == printed(out, "fluid", "density")[0]
    assert run.mu == printed(out, "fluid", "viscosity")[0]
    assert run.width == printed(out, "domain", "width")[0]
    np.testing.assert_array_equal(run.diameters, printed(out, "particles", "diameter")[:2])


@pytest.mark.parametrize(("collision_range", "enter_cells"), [(1.0, 0.0), (2.0, 0.0),
                                                              (2.0, 2.5)])
def test_thresholds_of_an_old_file_are_the_executables(tmp_path: Path, collision_range: float,
                                                        enter_cells: float) -> None:
    """The kissing thresholds the reader classifies an old file with (no kiss_* attributes,
    no /diagnostics) are those `dktlbm --check` reports for its namelist, including the rule
    for &diagnostics enter_cells = 0 on collision.range."""
    scene = (f"&lbm\n  dx = {syn.DX}\n/\n"
             "&particles\n  count = 2, diameter = 0.2, 0.1, x = 0.9, 1.1, y = 2.0, 2.6\n/\n"
             f"&collision\n  range = {collision_range}\n/\n"
             f"&diagnostics\n  enter_cells = {enter_cells}\n/\n")
    nml = tmp_path / "scene.nml"
    nml.write_text(scene)
    check = subprocess.run([EXE, str(nml), "--check", "--set", f"output.dir={tmp_path / 'o'}"],
                           capture_output=True, text=True, env={
                               **os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1",
                               "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1"})
    assert check.returncode == 0, check.stdout + check.stderr
    found = re.search(r"starts at D_r <=\s*([0-9.]+) spacings and ends at D_r >\s*([0-9.]+) "
                      r"spacings", check.stdout)
    assert found, check.stdout
    f = tmp_path / "old.h5"
    syn.write_run(f, syn.SHAPES["once"], (0.2, 0.1), fields=False)
    with h5py.File(f, "r+") as h5:
        h5["run"].attrs["namelist"] = np.bytes_(scene.encode())
    limits = read.pair_of(read.open_run(f)).limits
    assert limits.enter / syn.DX == pytest.approx(float(found.group(1)), abs=0.005)
    assert limits.release / syn.DX == pytest.approx(float(found.group(2)), abs=0.005)


def test_a_namelist_the_executable_refuses_takes_its_defaults_under_its_values(
        tmp_path: Path) -> None:
    """An old file whose stored namelist dktlbm refuses as a whole (two particles both at the
    default position): the values it gives (diameter(2)) over the executable's defaults
    (`dktlbm --print-defaults` without a file) for the rest (diameter(1), t_ref)."""
    f = tmp_path / "refused.h5"
    syn.write_run(f, syn.SHAPES["never"], (0.2, 0.1), fields=False)
    scene = "&particles\n  count = 2, diameter(2) = 0.1\n/\n"
    (tmp_path / "scene.nml").write_text(scene)
    env = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1"}
    refused = subprocess.run([EXE, str(tmp_path / "scene.nml"), "--print-defaults"],
                             capture_output=True, text=True, env=env)
    assert refused.returncode != 0, "the scene must be one the executable refuses"
    with h5py.File(f, "r+") as h5:
        h5["run"].attrs["namelist"] = np.bytes_(scene.encode())
    out = subprocess.run([EXE, "--print-defaults"], capture_output=True, text=True, check=True,
                         env=env).stdout
    run = read.open_run(f)
    assert run.t_ref == printed(out, "run", "t_ref")[0]
    np.testing.assert_array_equal(run.diameters, [printed(out, "particles", "diameter")[0], 0.1])


def test_stored_thresholds_need_no_executable(tmp_path: Path,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    """/run kiss_enter_cells, kiss_release_cells, kiss_enter_d1, kiss_release_d1 (values no
    namelist or default gives: 2.75, 5.5, 0.01, 0.3) are the thresholds of a file without
    /diagnostics (its scales stored too), classified from /particles with DKTLBM_EXE naming no
    program; a user's release_d1 replaces only its own value. Fails if any of them is looked
    up elsewhere."""
    f = tmp_path / "stored.h5"
    syn.write_run(f, syn.SHAPES["once"], (0.2, 0.1), fields=False)
    stored = {"enter_cells": 2.75, "release_cells": 5.5, "enter_d1": 0.01, "release_d1": 0.3}
    scales = {"t_ref": 0.135526, "gravity": 980.0, "h_ref": 18.0, "width": syn.WIDTH,
              "rho_f": 1.0, "mu": 0.01, "d1": 0.2, "diameter_1": 0.2, "diameter_2": 0.1}
    with h5py.File(f, "r+") as h5:
        for key, value in stored.items():
            h5["run"].attrs[f"kiss_{key}"] = value
        for key, value in scales.items():  # as a file of 0.1.0 stores them
            h5["run"].attrs[key] = value
    monkeypatch.setenv("DKTLBM_EXE", str(tmp_path / "no-such-dktlbm"))
    run = read.open_run(f)
    limits = read.pair_of(run).limits
    assert limits.enter == pytest.approx(max(2.75 * syn.DX, 0.01 * 0.2))
    assert limits.release == pytest.approx(max(5.5 * syn.DX, 0.3 * 0.2))
    given = read.pair_of(run, limits={"release_d1": 0.5}).limits
    assert (given.enter, given.release) == (limits.enter,
                                            pytest.approx(max(5.5 * syn.DX, 0.5 * 0.2)))
