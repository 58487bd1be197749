"""dkt-paraview (dktlbm.paraview): the picture of a run that ParaView draws, from the command
line of plain Python.

Proves: without pvpython on PATH, or without a display and without xvfb-run, the command stops
with one `error:` line naming what is missing and status 2 (a stand-in pvpython that would
succeed shows the check is made before it is started); a missing run file is one error line
too. With ParaView: from a real run (input/case1.nml, 8 spacings per D, to 0.2 s) it writes the
PNG of the size asked for beside the run file; the disks in it come from
`<name>_particles.xdmf` (the same picture when `<name>.xdmf` loses its particle grids), and a
run written before that file existed still shows them from `<name>.xdmf` (the same picture
without the particle file); without either the picture changes. Fails on a command that runs
the script from the source tree only, that draws no disks or draws them from one file only, or
that hangs without a display.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from dkt_run import pvpython_or_skip, run


def dkt_paraview(*args: str | Path, env: dict[str, str] | None = None):
    return subprocess.run([sys.executable, "-m", "dktlbm.paraview", *map(str, args)],
                          capture_output=True, text=True, timeout=300,
                          env={**os.environ, **(env or {})})


def error_lines(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if line.startswith("error:")]


@pytest.fixture
def sidecar(tmp_path: Path) -> Path:
    """A <name>.xdmf beside where <name>.h5 would be (the command checks only that it is there
    before it looks for ParaView)."""
    f = tmp_path / "r.xdmf"
    f.write_text('<?xml version="1.0" ?>\n<Xdmf Version="3.0"/>\n')
    return f


def stand_in(folder: Path, name: str) -> None:
    """An executable `name` in `folder` that would succeed."""
    folder.mkdir(exist_ok=True)
    (folder / name).write_text("#!/bin/sh\nexit 0\n")
    (folder / name).chmod(0o755)


def test_without_pvpython_one_error_line_and_status_2(sidecar: Path, tmp_path: Path) -> None:
    empty = tmp_path / "bin"
    empty.mkdir()
    proc = dkt_paraview(sidecar.with_suffix(".h5"), env={"PATH": str(empty)})
    assert proc.returncode == 2, proc.stderr
    assert len(error_lines(proc.stderr)) == 1 and "pvpython" in proc.stderr, proc.stderr


def test_without_display_or_xvfb_one_error_line_and_status_2(sidecar: Path,
                                                            tmp_path: Path) -> None:
    bin_dir = tmp_path / "bin"
    stand_in(bin_dir, "pvpython")
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env["PATH"] = str(bin_dir)
    proc = subprocess.run([sys.executable, "-m", "dktlbm.paraview", str(sidecar)],
                          capture_output=True, text=True, timeout=60, env=env)
    assert proc.returncode == 2, proc.stderr
    lines = error_lines(proc.stderr)
    assert len(lines) == 1 and "xvfb-run" in lines[0] and "DISPLAY" in lines[0], proc.stderr


def test_a_missing_run_is_one_error_line(tmp_path: Path) -> None:
    proc = dkt_paraview(tmp_path / "none.h5")
    assert proc.returncode == 2
    lines = error_lines(proc.stderr)
    assert len(lines) == 1 and str(tmp_path / "none.xdmf") in lines[0], proc.stderr


def test_renders_the_disks_of_the_particle_sidecar(tmp_path: Path) -> None:
    assert pvpython_or_skip() is not None, "DKT_REQUIRE_PARAVIEW=1 but pvpython is not on PATH"
    out = tmp_path / "run"
    run("case1.nml", 1, ["lbm.cells_per_diameter=8", "run.t_end=0.2",
                         "output.field_interval=0.1"], out)
    size = ["--size", "190", "350"]
    proc = dkt_paraview(out / "case1.h5", "--time", "0.1", *size)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    png = out / "case1_paraview.png"
    assert f"wrote {png}" in proc.stdout
    from PIL import Image

    with Image.open(png) as image:
        assert image.format == "PNG" and image.size == (190, 350)
        with_disks = image.convert("RGB").tobytes()
    assert len(set(with_disks)) > 2
    main = out / "case1.xdmf"
    whole = main.read_text()
    # the particle grids of every output time, taken out of the main sidecar
    fields_only = re.sub(r'[ ]*<Grid Name="particles".*?</Grid>\n', "", whole, flags=re.S)
    assert fields_only != whole and 'Name="particles"' not in fields_only

    def picture(name: str) -> bytes:
        proc = dkt_paraview(main, "--time", "0.1", *size, "-o", tmp_path / name)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        with Image.open(tmp_path / name) as image:
            return image.convert("RGB").tobytes()

    main.write_text(fields_only)
    assert picture("from_particle_file.png") == with_disks
    main.write_text(whole)
    (out / "case1_particles.xdmf").rename(tmp_path / "away.xdmf")
    assert picture("old_run.png") == with_disks
    main.write_text(fields_only)
    assert picture("no_disks.png") != with_disks
