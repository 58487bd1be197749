"""The output contract (docs/design.md, "Output") on a real run of input/inlet_channel.nml
on 2 ranks.

The run is shortened (run.steps = 250, output.field_interval = 0.1 s = 60 steps) and its fluid
changed to density 1.2 g/cm^3, viscosity 0.06 g/(cm s) (the same nu = 0.05 cm^2/s, so the same
dt, but rho_f != 1 shows whether the density scale is applied). The inlet, 0.1 cm/s ramped up
over 0.15 s (90 steps), starts a sound wave down the channel (c_s = dx/dt/sqrt(3) = 17 cm/s)
whose density jump is about the mean inlet Mach number, 0.4 %, plus the viscous pressure drop:
well inside the 1 % of a nearly incompressible run (the scene's 0.5 cm/s would jump by 2 %).

Every expected value is derived here from the scene and docs/model.md E3/E5: the lattice (dx, dt,
tau, rates, nx, ny), the field steps and times, the equation of state, the vorticity of the stored
velocity, the imposed inlet profile.
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import h5py
import numpy as np
import pytest

from dkt_run import INPUT, ROOT, run_args
from dktlbm.read import text_attr

RANKS = 2
TIMEOUT = 120.0
NAME = "inlet_channel"
# input/inlet_channel.nml and the overrides below
WIDTH, HEIGHT, DX, TAU, U_IN = 1.0, 8.0, 0.05, 0.6, 0.1
RHO_F, MU = 1.2, 0.06
STEPS, FIELD_INTERVAL, RAMP_TIME = 250, 0.1, 0.15
SETS = [
    f"run.steps={STEPS}",
    f"output.field_interval={FIELD_INTERVAL}",
    f"fluid.density={RHO_F}",
    f"fluid.viscosity={MU}",
    f"inlet.ramp_time={RAMP_TIME}",
    f"inlet.velocity={U_IN}",
]
NU_LB = (TAU - 0.5) / 3.0
DT = NU_LB * DX**2 / (MU / RHO_F)  # docs/model.md E3, diffusive scaling
NX, NY = round(WIDTH / DX), round(HEIGHT / DX)
CS2 = 1.0 / 3.0
FIELDS = {"rho", "ux", "uy", "vorticity", "pressure"}


@pytest.fixture(scope="module")
def result(tmp_path_factory: pytest.TempPathFactory):
    """One run for the whole module: (output directory, stdout)."""
    base = tmp_path_factory.mktemp("contract")
    outdir = base / "out"
    args = [str(INPUT / f"{NAME}.nml")]
    for s in [*SETS, f"output.dir={outdir}"]:
        args += ["--set", s]
    proc = run_args(args, RANKS, TIMEOUT, base)
    assert proc.returncode == 0, f"{proc.stdout}\n{proc.stderr}"
    return outdir, proc.stdout


@pytest.fixture(scope="module")
def h5(result):
    with h5py.File(result[0] / f"{NAME}.h5", "r") as f:
        yield f


def expected_steps() -> list[int]:
    every = round(FIELD_INTERVAL / DT)
    return sorted({*range(0, STEPS + 1, every), STEPS})


def run_text(h5, name: str) -> str:
    return text_attr(h5["run"].attrs[name])


def num_attr(obj, name: str) -> float:
    return float(np.asarray(obj.attrs[name]).ravel()[0])


def test_field_groups_are_written_at_0_every_interval_and_the_end(h5) -> None:
    """/fields/NNNNNN (six digits) at steps 0, 60, 120, 180, 240 and 250. Catches a missing
    first or last snapshot, an interval rounded the wrong way, a duplicate last group."""
    names = sorted(h5["fields"].keys())
    assert all(re.fullmatch(r"\d{6}", n) for n in names), names
    assert [int(n) for n in names] == expected_steps()


def test_every_snapshot_has_five_fields_of_shape_ny_nx_and_its_time(h5) -> None:
    """Shapes (ny, nx) = (height/dx, width/dx) = (160, 20), attributes step, time = step dt and
    window_offset (0: this scene has no moving window). Catches transposed arrays, rows missing
    from one rank's slab, time in steps or in t*."""
    for name, g in h5["fields"].items():
        assert set(g.keys()) == FIELDS, name
        for f in FIELDS:
            assert g[f].shape == (NY, NX), f"{name}/{f}: {g[f].shape}"
            assert np.all(np.isfinite(g[f][()])), f"{name}/{f}"
        step = int(np.asarray(g.attrs["step"]).ravel()[0])
        assert step == int(name)
        assert num_attr(g, "time") == pytest.approx(step * DT, rel=1e-12, abs=1e-15)
        assert num_attr(g, "window_offset") == 0.0


def test_run_attributes_describe_the_run(h5, tmp_path: Path) -> None:
    """/run holds the full namelist with the --set values, version and git revision (the same as
    --version and the project version in CMakeLists.txt), ranks = 2, compiler and flags, and the
    lattice parameters of docs/model.md E3. Catches a namelist of the file instead of the run, a
    missing attribute, wrong ranks, a dt or rate that is not the one the run used."""
    run = h5["run"]
    for key in ("namelist", "version", "git_revision", "compiler", "compiler_flags", "ranks"):
        assert key in run.attrs, key
    nml = run_text(h5, "namelist")
    # the values given by --set, in their groups
    groups = dict(re.findall(r"&(\w+)(.*?)\n/", nml, re.S))
    for setting in SETS:
        key, value = setting.split("=")
        group, name = key.split(".")
        m = re.search(rf"^\s*{name}\s*=\s*([^\s!,]+)", groups[group], re.M)
        assert m and float(m.group(1).replace("d", "e")) == float(value), (setting, nml)
    # the stored namelist is itself a valid scene of the same lattice (input/README.md)
    scene = tmp_path / f"{NAME}.nml"
    scene.write_text(nml)
    # (into a fresh output.dir: --check refuses the run's own directory, which holds its files)
    fresh = f"output.dir={tmp_path / 'check'}"
    check = run_args([str(scene), "--check", "--set", fresh], 1, 60.0, tmp_path)
    assert check.returncode == 0, check.stderr
    m = re.search(r"cells (\d+) x (\d+) = \d+, steps (\d+)", check.stdout)
    assert m and [int(g) for g in m.groups()] == [NX, NY, STEPS], check.stdout

    version = run_args(["--version"], 1, 60.0, tmp_path).stdout.strip()
    cmake = (ROOT / "CMakeLists.txt").read_text()
    project = re.search(r"project\(\s*dktlbm\s+VERSION\s+([0-9.]+)", cmake)
    assert project and run_text(h5, "version") == project.group(1)
    assert version == f"dktlbm {run_text(h5, 'version')} ({run_text(h5, 'git_revision')})"
    assert int(np.asarray(run.attrs["ranks"]).ravel()[0]) == RANKS
    assert run_text(h5, "compiler").strip() and re.search(r"\d", run_text(h5, "compiler"))
    assert run_text(h5, "compiler_flags").strip()

    s_nu = 1.0 / TAU
    lattice = {
        "dx": DX,
        "dt": DT,
        "tau": TAU,
        "nu_lb": NU_LB,
        "s_nu": s_nu,
        "s_q": 8.0 * (2.0 - s_nu) / (8.0 - s_nu),  # docs/model.md E3
        "nx": NX,
        "ny": NY,
        "steps": STEPS,
        "mach": U_IN * DT / DX / math.sqrt(CS2),
    }
    for key, value in lattice.items():
        assert num_attr(run, key) == pytest.approx(value, rel=1e-12), key


def test_density_and_pressure_follow_the_equation_of_state(h5) -> None:
    """rho stays within 1 % of rho_f (a nearly incompressible run) and the stored pressure is
    p = c_s^2 (rho/rho_f - 1) rho_f (dx/dt)^2 with c_s^2 = 1/3 to round-off. Catches rho in
    lattice units (1 instead of 1.2), p without rho_f or the velocity scale, or the full p."""
    scale = CS2 * RHO_F * (DX / DT) ** 2
    for name, g in h5["fields"].items():
        rho, p = g["rho"][()], g["pressure"][()]
        assert np.max(np.abs(rho / RHO_F - 1.0)) < 0.01, name
        expected = scale * (rho / RHO_F - 1.0)
        np.testing.assert_allclose(p, expected, rtol=0, atol=1e-13 * scale, err_msg=name)
    # not vacuous: the flow has a pressure field by the end
    assert np.ptp(h5["fields"][f"{STEPS:06d}"]["pressure"][()]) > 1e-6 * scale


def test_vorticity_is_the_curl_of_the_stored_velocity(h5) -> None:
    """In the interior, vorticity = d(uy)/dx - d(ux)/dy by central differences of the stored
    ux, uy with spacing dx, in 1/s, across the slab seam of the two ranks (rows 80/81). Catches a
    sign error, a missing 1/dt or 1/(2 dx), x and y swapped, a stale halo row at the seam."""
    for name, g in h5["fields"].items():
        ux, uy, w = g["ux"][()], g["uy"][()], g["vorticity"][()]
        dvdx = (uy[1:-1, 2:] - uy[1:-1, :-2]) / (2.0 * DX)
        dudy = (ux[2:, 1:-1] - ux[:-2, 1:-1]) / (2.0 * DX)
        np.testing.assert_allclose(
            w[1:-1, 1:-1], dvdx - dudy, rtol=0, atol=1e-12 * U_IN / DX, err_msg=name
        )
    # not vacuous: the walls shear the developing flow (the Poiseuille wall shear is 4 U/W)
    w_end = h5["fields"][f"{STEPS:06d}"]["vorticity"][()]
    assert np.max(np.abs(w_end[1:-1, 1:-1])) > 0.5 * U_IN / WIDTH


def test_inlet_row_carries_the_parabolic_profile(h5) -> None:
    """docs/model.md E5: the velocity end row takes u = (0, r U 4 xi (1 - xi)), xi = (i - 1/2)/nx,
    with the ramp factor 0 < r < 1 during inlet.ramp_time and r = 1 after it, to round-off; at step
    0 the fluid is at rest. Catches a profile on the wrong nodes (walls instead of cell centres),
    a ramp that never finishes or overshoots, velocities in lattice units."""
    xi = (np.arange(NX) + 0.5) / NX
    profile = U_IN * 4.0 * xi * (1.0 - xi)
    ramping = 0
    for name, g in h5["fields"].items():
        step = int(name)
        uy0, ux0 = g["uy"][0], g["ux"][0]
        if step == 0:
            assert np.all(g["uy"][()] == 0.0) and np.all(g["ux"][()] == 0.0)
            continue
        r = 1.0
        if step * DT < RAMP_TIME:
            ramping += 1
            r = uy0[NX // 2] / profile[NX // 2]
            assert 0.0 < r < 1.0, f"{name}: ramp factor {r}"
        np.testing.assert_allclose(uy0, r * profile, rtol=0, atol=1e-12 * U_IN, err_msg=name)
        np.testing.assert_allclose(ux0, 0.0, rtol=0, atol=1e-12 * U_IN, err_msg=name)
    assert ramping == 1  # step 60; steps 120 to 250 come after the ramp


def test_xdmf_names_only_datasets_that_exist(result, h5) -> None:
    """The .xdmf sidecar parses as XML; it has one spatial collection per snapshot with its
    time, holding the `fields` grid: a one-layer 3DCoRectMesh (1, ny, nx) in the X-Y plane,
    origin (0, dx/2, dx/2) and spacing dx (z, y, x order); every HDF DataItem names an existing
    dataset of the stated dimensions, with a leading 1 for the layer. Catches a stale or partial
    sidecar, x/y swapped, wrong paths, a mesh ParaView lays in the Y-Z plane."""
    outdir = result[0]
    root = ET.parse(outdir / f"{NAME}.xdmf").getroot()
    steps = [g for g in root.iter("Grid") if g.get("CollectionType") == "Spatial"]
    assert len(steps) == len(h5["fields"]), "one collection per snapshot"
    times = sorted(float(g.find("Time").get("Value")) for g in steps)
    assert times == pytest.approx([s * DT for s in expected_steps()], rel=1e-12, abs=1e-15)
    items = 0
    for step in steps:
        grids = [g.get("Name") for g in step.findall("Grid")]
        assert grids == ["fields"], "a scene without particles has no particle grid"
        grid = step.find("Grid")
        topo = grid.find("Topology")
        assert topo.get("TopologyType") == "3DCoRectMesh"
        assert [int(v) for v in topo.get("Dimensions").split()] == [1, NY, NX]
        geometry = grid.find("Geometry").iter("DataItem")
        geo = {d.get("Name"): [float(v) for v in d.text.split()] for d in geometry}
        assert geo["Origin"] == pytest.approx([0.0, DX / 2, DX / 2], rel=1e-12)
        assert geo["Spacing"] == pytest.approx([DX, DX, DX], rel=1e-12)
        for item in grid.iter("DataItem"):
            if item.get("Format") != "HDF":
                continue
            items += 1
            file, path = item.text.strip().split(":", 1)
            assert (outdir / file).is_file(), item.text
            with h5py.File(outdir / file, "r") as f:
                assert path in f, item.text
                dims = [int(v) for v in item.get("Dimensions").split()]
                assert [1, *f[path].shape] == dims, item.text
    # each field, and ux and uy once more for the joined velocity vector
    assert items == (len(FIELDS) + 2) * len(steps)


def test_log_copy_has_the_performance_line_of_stdout(result) -> None:
    """<dir>/<name>.log is a copy of the run log: it exists, holds the same 'performance:' line
    as standard output and every other line of it, in order. Catches a log that stops being
    written once the file is open (only the lines from before survive)."""
    outdir, stdout = result
    log = (outdir / f"{NAME}.log").read_text()
    perf = [ln for ln in stdout.splitlines() if ln.startswith("performance:")]
    assert len(perf) == 1, stdout
    assert perf[0] in log.splitlines(), f"no performance line in the log copy:\n{log}"
    assert log.splitlines() == stdout.splitlines()


PART_NAMES = ["flow", "links", "particles", "window", "guards", "output", "checkpoints", "other"]
PARTS_LINE = re.compile(r"^time per part: (.*) \(mean over (\d+) ranks?\)$")


def time_per_part(stdout: str) -> dict[str, float]:
    """The `time per part:` line (the line after `performance:`) as {part: percent}."""
    lines = stdout.splitlines()
    at = next(i for i, ln in enumerate(lines) if ln.startswith("performance:"))
    match = PARTS_LINE.match(lines[at + 1])
    assert match, f"no time-per-part line after the performance line: {lines[at + 1]!r}"
    assert int(match.group(2)) == RANKS
    parts = {}
    for item in match.group(1).split(", "):
        name, value, unit = item.rsplit(" ", 2)
        assert unit == "%", item
        parts[name] = float(value)
    return parts


def test_time_per_part_line_splits_the_loop_without_overlap(result) -> None:
    """After the performance line, the time per part: every part named once, in order, each a
    share of the loop's wall time. The parts are timed disjointly, so their shares and `other`
    add up to 100 % (within the rounding of eight one-decimal figures); a part timed inside
    another would count twice and push the sum above. This scene has no particles and no
    window: no time goes to them. The flow sweep is timed, so its share is not zero."""
    _, stdout = result
    parts = time_per_part(stdout)
    assert list(parts) == PART_NAMES
    assert all(0.0 <= v <= 100.0 for v in parts.values()), parts
    assert abs(sum(parts.values()) - 100.0) <= 0.45, parts
    assert parts["links"] == parts["particles"] == parts["window"] == 0.0, parts
    assert parts["flow"] > 0.0, parts


def test_default_output_directory_is_runs_slash_the_scene_name(tmp_path: Path) -> None:
    """With output.dir = '' everything goes to runs/<namelist basename>/ below the working
    directory: <name>.h5, <name>.xdmf, <name>.log, the marker <name>.finished (for batch
    scripts), the lock <name>.lock (held while the run writes there, left empty) and nothing
    else."""
    args = [str(INPUT / f"{NAME}.nml"), "--set", "run.steps=2"]
    proc = run_args(args, RANKS, TIMEOUT, tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert [p.name for p in tmp_path.iterdir()] == ["runs"]
    made = sorted(p.name for p in (tmp_path / "runs" / NAME).iterdir())
    assert made == [
        f"{NAME}.finished", f"{NAME}.h5", f"{NAME}.lock", f"{NAME}.log", f"{NAME}.xdmf"
    ]
    assert (tmp_path / "runs" / NAME / f"{NAME}.lock").read_text() == ""


# ---- metadata of a run with particles (input/case1.nml, coarse and short) ----------------------
PAIR_SETS = ["lbm.cells_per_diameter=8", "run.t_end=0.02", "output.field_interval=0.01"]


def run_pair(out: Path, sets: list[str], extra: tuple[str, ...] = ()) -> Path:
    """input/case1.nml on RANKS ranks with the --set overrides `sets` (and the further
    arguments `extra`) into `out`; returns its run file."""
    args = [str(INPUT / "case1.nml"), "--set", f"output.dir={out}", *extra]
    for s in sets:
        args += ["--set", s]
    proc = run_args(args, RANKS, TIMEOUT)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return out / "case1.h5"


@pytest.fixture(scope="module")
def pair_runs(tmp_path_factory: pytest.TempPathFactory) -> dict[int, Path]:
    """The pair run twice on 2 ranks: output.compress = 0 (the default) and 6."""
    return {
        level: run_pair(
            tmp_path_factory.mktemp(f"compress{level}"), [*PAIR_SETS, f"output.compress={level}"]
        )
        for level in (0, 6)
    }


def test_time_per_part_of_a_pair_run_counts_the_particles(pair_runs) -> None:
    """In a run with moving particles the force sums and the motion (and the pair's sample)
    are timed as `particles`: a share above zero, and still a sum of 100 %."""
    log = (pair_runs[0].parent / "case1.log").read_text()
    parts = time_per_part(log)
    assert list(parts) == PART_NAMES
    assert abs(sum(parts.values()) - 100.0) <= 0.45, parts
    assert parts["particles"] > 0.0 and parts["flow"] > 0.0, parts


def datasets(f: h5py.File) -> list[str]:
    names: list[str] = []
    f.visititems(lambda n, o: names.append(n) if isinstance(o, h5py.Dataset) else None)
    return names


def test_every_dataset_and_quantity_attribute_has_units(pair_runs) -> None:
    """Every dataset carries a string attribute `units`; every real attribute A of /run,
    /diagnostics and the field groups has its companion A_units. Catches a new dataset or
    quantity written without its unit."""
    with h5py.File(pair_runs[0], "r") as f:
        names = datasets(f)
        assert any(n.endswith("/particles/position") for n in names)
        missing = [n for n in names if "units" not in f[n].attrs]
        assert not missing, f"datasets without units: {missing}"
        assert f["particles/x"].attrs["units"] == "cm"
        assert f["fields/000000/pressure"].attrs["units"] == "g/(cm s^2)"
        groups = ["run", "diagnostics", *(f"fields/{g}" for g in f["fields"])]
        for g in groups:
            attrs = f[g].attrs
            for key in attrs:
                if attrs.get_id(key).dtype.kind == "f":
                    assert f"{key}_units" in attrs, f"/{g} {key} has no {key}_units"
        assert f["run"].attrs["dx_units"] == "cm" and f["run"].attrs["gravity_units"] == "cm/s^2"


def test_integers_are_integers_and_strings_variable_length_utf8(pair_runs) -> None:
    """/run nx, ny, steps, ranks are integer attributes (they were reals); stop_reason, version,
    pattern and namelist are variable-length UTF-8 strings (h5py: str); the particle index
    field is int16 with the particle numbers 0, 1, 2."""
    with h5py.File(pair_runs[0], "r") as f:
        run = f["run"].attrs
        for key in ("nx", "ny", "steps", "ranks"):
            assert run.get_id(key).dtype.kind == "i", key
        assert run["ranks"] == RANKS
        for path, key in (
            ("run", "stop_reason"),
            ("run", "version"),
            ("run", "namelist"),
            ("diagnostics", "pattern"),
        ):
            info = h5py.check_string_dtype(f[path].attrs.get_id(key).dtype)
            assert info is not None and info.length is None and info.encoding == "utf-8", key
        assert run["stop_reason"] == "finished"
        for g in f["fields"]:
            particle = f["fields"][g]["particle"]
            assert particle.dtype == np.int16
            assert set(np.unique(particle[()])) == {0, 1, 2}


def test_compressed_snapshots_hold_the_same_values_in_fewer_bytes(pair_runs) -> None:
    """output.compress = 6 deflates every field dataset (chunked, shuffled, gzip level 6) and
    changes no value: each dataset equals the uncompressed run's bit for bit, and the field
    datasets take fewer bytes on disk."""
    with h5py.File(pair_runs[0], "r") as a, h5py.File(pair_runs[6], "r") as b:
        assert datasets(a) == datasets(b)
        stored = {0: 0, 6: 0}
        for n in datasets(a):
            assert a[n].dtype == b[n].dtype and a[n][()].tobytes() == b[n][()].tobytes(), n
            if n.startswith("fields/") and "/particles/" not in n:
                assert a[n].compression is None, n
                assert b[n].compression == "gzip" and b[n].compression_opts == 6, n
                assert b[n].shuffle, n
                stored[0] += a[n].id.get_storage_size()
                stored[6] += b[n].id.get_storage_size()
        assert stored[6] < stored[0] / 2, stored


def make_old_style(path: Path) -> None:
    """Rewrite a run file as version 0.1.0 wrote it: integer /run attributes as reals, strings
    as fixed-length bytes, no units attributes, the `particle` field float64 and no
    `particles` sub-group in the field groups."""
    with h5py.File(path, "r+") as f:

        def plain(obj) -> None:
            for key in list(obj.attrs):
                value = obj.attrs[key]
                if key == "units" or key.endswith("_units"):
                    del obj.attrs[key]
                elif isinstance(value, str):
                    obj.attrs[key] = np.bytes_(value.encode())

        f.visititems(lambda _, o: plain(o))
        plain(f["run"])
        for key in ("nx", "ny", "steps"):
            f["run"].attrs[key] = float(f["run"].attrs[key])
        for g in f["fields"].values():
            del g["particles"]
            particle = g["particle"][()].astype(np.float64)
            del g["particle"]
            g["particle"] = particle


def test_restart_continues_a_run_file_of_version_0_1(tmp_path: Path) -> None:
    """A run of the pair stopped at step 20 with a checkpoint, its run file rewritten as
    version 0.1.0 wrote it (make_old_style), resumed to step 40: the resume succeeds, every
    dataset equals the uninterrupted run's (the old `particle` fields by value), the old
    snapshots keep their float64 `particle` and the new ones are int16 with their disks, and
    the sidecar describes each snapshot with the dtype it has. Catches a restart that reads
    /run or a field group only in the new layout, or a sidecar that lists absent disks."""
    sets = ["lbm.cells_per_diameter=8", "output.field_interval=0.0078125"]  # 10 steps

    def go(out: Path, steps: int, extra: tuple[str, ...] = ()) -> None:
        run_pair(out, [*sets, f"run.steps={steps}"], extra)

    whole = tmp_path / "whole"
    go(whole, 40)
    out = tmp_path / "resumed"
    go(out, 20, ("--set", "run.checkpoint_every=20"))
    make_old_style(out / "case1.h5")
    go(out, 40, ("--restart", str(out / "case1_chk_000000020.h5")))
    with h5py.File(whole / "case1.h5", "r") as a, h5py.File(out / "case1.h5", "r") as b:
        names = datasets(a)
        assert sorted(b["fields"]) == sorted(a["fields"]) == [f"{s:06d}" for s in range(0, 41, 10)]
        for n in names:
            if n.endswith("/particle"):
                np.testing.assert_array_equal(a[n][()], b[n][()], err_msg=n)
            elif "/particles/" in n and n.startswith("fields/") and int(n[7:13]) <= 20:
                assert n not in b, f"{n}: an old snapshot got disks"
            else:
                assert a[n][()].tobytes() == b[n][()].tobytes(), n
        for step, dtype in ((0, np.float64), (10, np.float64), (30, np.int16), (40, np.int16)):
            assert b[f"fields/{step:06d}/particle"].dtype == dtype, step
    root = ET.parse(out / "case1.xdmf").getroot()
    collections = [g for g in root.iter("Grid") if g.get("CollectionType") == "Spatial"]
    assert len(collections) == 5
    for coll in collections:
        step = int(coll.get("Name").split()[1])
        grids = [g.get("Name") for g in coll.findall("Grid")]
        assert grids == (["fields"] if step <= 20 else ["fields", "particles"]), (step, grids)
        item = next(a for a in coll.iter("Attribute") if a.get("Name") == "particle")
        item = item.find("DataItem")
        expect = ("Float", "8") if step <= 20 else ("Int", "2")
        assert (item.get("NumberType"), item.get("Precision")) == expect, step
