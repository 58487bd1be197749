"""Read back, with h5py, the files that tests/test_io.f90 writes through dkt_io on 1-4 ranks.

Proves that the parallel HDF5 writer puts every rank's rows where they belong (values checked
against their defining formula at every point, computed here from the indices), that uneven
slabs and a rank with no rows are handled, that the result does not depend on the rank count,
that the group and /run attributes are there, that overwrite replaces file and sidecar, and
that the XDMF sidecar names only datasets that exist, with the dimensions it states. For the
particle output: 2-D tables grow one (n_samples, ncols) row per sample beside a 1-D series in
the same group, both extendible and chunked, holding rank 0's values only; attributes written
through io_write_attribute keep rank 0's value and its type (integer, real, string), replace an
earlier attribute of the same name, and create missing groups; writing a row of another width
into a table, or a series row into a table, stops the program with a message naming the
dataset.

The program is found through the environment variable DKT_TEST_IO_EXE (set by ctest);
mpiexec through MPIEXEC (default: mpiexec), with MPIEXEC_NUMPROC_FLAG and MPIEXEC_PREFLAGS
(defaults: -n and --oversubscribe).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import h5py
import numpy as np
import pytest

from dktlbm import launch

# The contract with tests/test_io.f90: grid, spacing, field names and the two snapshots
# (step -> (time in s, window offset in cm)).
NX, NY = 5, 7
DX = 0.25
FIELDS = ("rho", "ux", "uy", "vorticity", "pressure")
SNAPSHOTS = {0: (0.0, 0.0), 10: (0.125, 0.5)}
RANKS = (1, 2, 3, 4)
# The particle output of tests/test_io.f90: 3-column tables over 600 samples beside the series
# t. The writer holds up to 256 rows of a dataset before writing them, so 600 rows are written
# in three parts (two full stores, then the rest when an attribute is set): a row lost,
# repeated or written out of order at a store's edge shows in the values.
TABLES = ("x", "y", "omega")
NCOL, NSAMPLES = 3, 600


def expected_field(k: int, step: int) -> np.ndarray:
    """Field k (1-based) at step: 1000 k + 10 j + i + step/4, i column and j row, 1-based.

    Returned in h5py's (row, column) order.
    """
    j, i = np.meshgrid(np.arange(1, NY + 1), np.arange(1, NX + 1), indexing="ij")
    return 1000.0 * k + 10.0 * j + i + 0.25 * step


def expected_table(k: int) -> np.ndarray:
    """Table k (1-based) at sample s, column c (1-based): 100 k + 10 s + c + 1/4.

    Returned in h5py's (sample, column) order.
    """
    s, c = np.meshgrid(np.arange(1, NSAMPLES + 1), np.arange(1, NCOL + 1), indexing="ij")
    return 100.0 * k + 10.0 * s + c + 0.25


def expected_t() -> np.ndarray:
    """The series /particles/t: sample s (1-based) at s/8."""
    return np.arange(1, NSAMPLES + 1) / 8.0


def exact_text(value: object) -> str:
    """A string attribute as written, byte for byte (dktlbm.read.text_attr trims blanks)."""
    return value.decode() if isinstance(value, (bytes, np.bytes_)) else str(value)


def run_writer(nranks: int, outdir: Path, *args: str) -> subprocess.CompletedProcess[str]:
    """Run the writer on nranks ranks into outdir (extra arguments after the directory)."""
    exe = os.environ.get("DKT_TEST_IO_EXE")
    if not exe:
        pytest.skip("DKT_TEST_IO_EXE is not set (run through ctest)")
    prefix = launch.mpi_prefix(nranks)
    if shutil.which(prefix[0]) is None:
        pytest.fail(f"mpiexec not found: {prefix[0]!r} (set MPIEXEC)")
    cmd = [*prefix, exe, str(outdir), *args]
    env = launch.mpi_env()
    return subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[int, Path]:
    """Run the writer once per rank count; map rank count -> output directory."""
    out = {}
    for n in RANKS:
        d = tmp_path_factory.mktemp(f"io_{n}ranks")
        proc = run_writer(n, d)
        assert proc.returncode == 0, (
            f"{' '.join(map(str, proc.args))} exited {proc.returncode}\n"
            f"stdout:\n{proc.stdout}\nstderr:\n{proc.stderr}"
        )
        out[n] = d
    return out


@pytest.mark.parametrize("nranks", RANKS)
def test_every_point_of_every_field_has_its_formula_value(runs, nranks):
    with h5py.File(runs[nranks] / "io_fields.h5", "r") as f:
        assert sorted(f["fields"].keys()) == ["000000", "000010"]
        for step in SNAPSHOTS:
            grp = f[f"fields/{step:06d}"]
            assert sorted(grp.keys()) == sorted(FIELDS)
            for k, name in enumerate(FIELDS, start=1):
                data = grp[name]
                assert data.shape == (NY, NX)
                assert data.dtype == np.float64
                np.testing.assert_array_equal(data[()], expected_field(k, step))


@pytest.mark.parametrize("nranks", RANKS)
def test_field_groups_carry_time_step_and_window_offset(runs, nranks):
    with h5py.File(runs[nranks] / "io_fields.h5", "r") as f:
        for step, (t, offset) in SNAPSHOTS.items():
            attrs = f[f"fields/{step:06d}"].attrs
            assert attrs["step"] == step
            assert attrs["time"] == t
            assert attrs["window_offset"] == offset


@pytest.mark.parametrize("nranks", RANKS)
def test_run_group_holds_configuration_provenance_and_parameters(runs, nranks):
    with h5py.File(runs[nranks] / "io_fields.h5", "r") as f:
        attrs = f["run"].attrs
        assert exact_text(attrs["namelist"]) == "&lbm\n  tau = 0.65\n/\n"
        assert exact_text(attrs["version"]) == "0.1.0"
        assert exact_text(attrs["git_revision"]) == "abc1234"
        assert attrs["ranks"] == nranks
        assert exact_text(attrs["compiler"]).strip()  # compiler_version(): never empty
        assert "compiler_flags" in attrs  # compiler_options() may be empty
        assert attrs["dx"] == DX
        assert exact_text(attrs["dx_units"]) == "cm"
        # integers as integers
        assert attrs["nx"] == NX and attrs.get_id("nx").dtype.kind == "i"
        assert attrs["ny"] == NY and attrs.get_id("ny").dtype.kind == "i"
        assert attrs.get_id("ranks").dtype.kind == "i"
        for name in ("namelist", "version", "git_revision", "compiler", "dx_units"):
            assert h5py.check_string_dtype(attrs.get_id(name).dtype).length is None, name


@pytest.mark.parametrize("nranks", RANKS)
def test_series_keeps_rank0_rows_in_order(runs, nranks):
    with h5py.File(runs[nranks] / "io_fields.h5", "r") as f:
        np.testing.assert_array_equal(f["diagnostics/a"][()], [1.0, 2.0, 3.0])
        np.testing.assert_array_equal(f["diagnostics/b"][()], [-1.0, -2.0, -3.0])


@pytest.mark.parametrize("nranks", RANKS)
def test_tables_grow_one_row_of_rank0_values_per_sample(runs, nranks):
    with h5py.File(runs[nranks] / "io_fields.h5", "r") as f:
        for k, name in enumerate(TABLES, start=1):
            data = f[f"particles/{name}"]
            assert data.shape == (NSAMPLES, NCOL)
            assert data.dtype == np.float64
            # extendible along the samples only, so chunked; the column count is fixed
            assert data.maxshape == (None, NCOL)
            assert data.chunks is not None and data.chunks[1] == NCOL
            # the other ranks passed -huge: any of their values stored would show here
            np.testing.assert_array_equal(data[()], expected_table(k))


@pytest.mark.parametrize("nranks", RANKS)
def test_series_and_tables_share_one_group(runs, nranks):
    with h5py.File(runs[nranks] / "io_fields.h5", "r") as f:
        assert sorted(f["particles"].keys()) == sorted((*TABLES, "t"))
        t = f["particles/t"]
        assert t.shape == (NSAMPLES,)
        assert t.maxshape == (None,)
        assert t.dtype == np.float64
        np.testing.assert_array_equal(t[()], expected_t())


@pytest.mark.parametrize("nranks", RANKS)
def test_attributes_keep_rank0_value_and_type(runs, nranks):
    def attr(f: h5py.File, path: str, name: str) -> tuple[object, np.dtype]:
        obj = f[path]
        assert obj.attrs.get_id(name).shape == (), f"{path} {name} is not a scalar"
        return obj.attrs[name], obj.attrs.get_id(name).dtype

    with h5py.File(runs[nranks] / "io_fields.h5", "r") as f:
        value, dtype = attr(f, "particles", "count")
        assert dtype.kind == "i" and value == NCOL  # 7 first, replaced by 3
        # strings are variable-length UTF-8: h5py gives str
        value, dtype = attr(f, "particles/x", "unit")  # on a dataset
        assert h5py.check_string_dtype(dtype).encoding == "utf-8" and value == "cm"
        value, dtype = attr(f, "diagnostics", "pattern")
        assert h5py.check_string_dtype(dtype).encoding == "utf-8" and value == "repeated"
        value, dtype = attr(f, "diagnostics", "note")
        assert h5py.check_string_dtype(dtype).length is None and value == ""
        # both groups created by the attribute; the string 'tbd' replaced by a real
        assert isinstance(f["checks"], h5py.Group) and isinstance(f["checks/nested"], h5py.Group)
        value, dtype = attr(f, "checks/nested", "ratio")
        assert dtype == np.float64 and value == 3.0 / 8.0
        # a replaced attribute is gone, not kept beside the new one
        assert sorted(f["particles"].attrs) == ["count"]
        assert sorted(f["particles/x"].attrs) == ["unit"]
        assert sorted(f["diagnostics"].attrs) == ["note", "pattern"]
        assert sorted(f["checks/nested"].attrs) == ["ratio"]


@pytest.mark.parametrize(
    ("mode", "words"),
    [
        ("bad_columns", ["has 3 columns", "new row has 4"]),
        ("bad_kind", ["has 2 dimensions", "write it with io_write_table"]),
    ],
)
def test_a_table_refuses_rows_of_another_shape_or_kind(tmp_path, mode, words):
    proc = run_writer(2, tmp_path, mode)
    assert proc.returncode != 0, f"{mode} went through:\n{proc.stderr}"
    assert "accepted the mistake" not in proc.stderr
    assert "particles/x" in proc.stderr
    for word in words:
        assert word in proc.stderr, f"{word!r} missing from the message:\n{proc.stderr}"


def test_rank_counts_give_identical_arrays(runs):
    def arrays(d: Path) -> dict[str, np.ndarray]:
        with h5py.File(d / "io_fields.h5", "r") as f:
            out = {
                f"{step:06d}/{name}": f[f"fields/{step:06d}/{name}"][()]
                for step in SNAPSHOTS
                for name in FIELDS
            }
            for group in ("particles", "diagnostics"):
                out.update({f"{group}/{n}": ds[()] for n, ds in f[group].items()})
            return out

    reference = arrays(runs[RANKS[0]])
    for n in RANKS[1:]:
        other = arrays(runs[n])
        assert other.keys() == reference.keys()
        for key, value in reference.items():
            assert np.array_equal(other[key], value), f"{key} differs on {n} ranks"


def test_rank_counts_give_identical_attributes(runs):
    def attributes(d: Path) -> dict[str, tuple[str, object]]:
        out = {}
        with h5py.File(d / "io_fields.h5", "r") as f:
            for path in ("particles", "particles/x", "diagnostics", "checks/nested"):
                for name, value in f[path].attrs.items():
                    out[f"{path} {name}"] = (f[path].attrs.get_id(name).dtype.str, value)
        return out

    reference = attributes(runs[RANKS[0]])
    assert len(reference) == 5
    for n in RANKS[1:]:
        assert attributes(runs[n]) == reference, f"attributes differ on {n} ranks"


@pytest.mark.parametrize("nranks", RANKS)
def test_overwrite_replaces_file_and_sidecar(runs, nranks):
    d = runs[nranks]
    with h5py.File(d / "io_overwrite.h5", "r") as f:
        assert list(f["fields"].keys()) == ["000010"]
        np.testing.assert_array_equal(f["fields/000010/rho"][()], expected_field(1, 10))
    items = [
        e.text
        for e in ET.parse(d / "io_overwrite.xdmf").iter("DataItem")
        if e.get("Format") == "HDF"
    ]
    assert items and all("/fields/000010/" in s for s in items)


@pytest.mark.parametrize("nranks", RANKS)
@pytest.mark.parametrize("name", ["io_fields", "io_overwrite"])
def test_xdmf_names_existing_datasets_with_their_dims(runs, nranks, name):
    d = runs[nranks]
    root = ET.parse(d / f"{name}.xdmf").getroot()
    collection = root.find("Domain/Grid")
    assert collection is not None
    assert collection.get("CollectionType") == "Temporal"
    grids = collection.findall("Grid")
    expected_steps = sorted(SNAPSHOTS) if name == "io_fields" else [10]
    assert len(grids) == len(expected_steps)
    with h5py.File(d / f"{name}.h5", "r") as f:
        for grid, step in zip(grids, expected_steps, strict=True):
            t, offset = SNAPSHOTS[step]
            assert float(grid.find("Time").get("Value")) == t
            assert grid.get("CollectionType") == "Spatial"
            fields = grid.find("Grid")
            assert fields.get("Name") == "fields"
            topo = fields.find("Topology")
            assert topo.get("TopologyType") == "3DCoRectMesh"
            assert [int(v) for v in topo.get("Dimensions").split()] == [1, NY, NX]
            geo = {
                e.get("Name"): [float(v) for v in e.text.split()]
                for e in fields.find("Geometry").findall("DataItem")
            }
            # slowest index first: (z, y, x); nodes at cell centres, y shifted by the window
            assert geo["Origin"] == [0.0, DX / 2 + offset, DX / 2]
            assert geo["Spacing"] == [DX, DX, DX]
            attrs = fields.findall("Attribute")
            assert sorted(a.get("Name") for a in attrs) == sorted((*FIELDS, "velocity"))
            for attr in attrs:
                assert attr.get("Center") == "Node"
                if attr.get("Name") == "velocity":
                    assert attr.get("AttributeType") == "Vector"
                    join = attr.find("DataItem")
                    assert join.get("Function") == "JOIN($0, $1, 0*$0)"
                    parts = [e.text.strip() for e in join.findall("DataItem")]
                    assert parts == [f"{name}.h5:/fields/{step:06d}/{c}" for c in ("ux", "uy")]
                    continue
                assert attr.get("AttributeType") == "Scalar"
                item = attr.find("DataItem")
                fname, dset = item.text.strip().split(":", 1)
                assert fname == f"{name}.h5"
                assert (d / fname).exists()
                assert dset in f, f"{dset} named by the XDMF is not in {fname}"
                dims = tuple(int(v) for v in item.get("Dimensions").split())
                assert (1, *f[dset].shape) == dims
                assert int(item.get("Precision")) == f[dset].dtype.itemsize
