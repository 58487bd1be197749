"""Helpers for tests that run the dktlbm executable: launch it on N ranks, read its HDF5 file."""

from __future__ import annotations

import hashlib
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from dktlbm import launch

ROOT = Path(os.environ.get("DKTLBM_ROOT", Path(__file__).resolve().parents[1]))
EXE = Path(launch.find_exe() or ROOT / "build" / "dktlbm")
INPUT = ROOT / "input"
# the MPI launch prefix for N ranks and its environment: dktlbm.launch (postproc/dktlbm)
mpi_command = launch.mpi_prefix
mpi_env = launch.mpi_env


def dkt_command(name: str) -> list[str]:
    """The command dkt-<name> as its console script starts it (dktlbm.<name>:main), the package
    found through PYTHONPATH (ctest: <root>/postproc)."""
    return [sys.executable, "-c", f"import sys; from dktlbm.{name} import main; sys.exit(main())"]


def run(
    nml: str | Path,
    ranks: int = 1,
    sets: list[str] | None = None,
    outdir: Path | None = None,
    extra: list[str] | None = None,
    timeout: float = 300.0,
    check: bool = True,
) -> subprocess.CompletedProcess[str]:
    """Run dktlbm on `nml` (a name in input/ or a path) with --set overrides."""
    path = Path(nml)
    if not path.exists():
        path = INPUT / nml
    args = [str(EXE), str(path)]
    for s in sets or []:
        args += ["--set", s]
    if outdir is not None:
        args += ["--set", f"output.dir={outdir}"]
    args += extra or []
    proc = subprocess.run(
        mpi_command(ranks) + args,
        capture_output=True,
        text=True,
        timeout=timeout,
        env=mpi_env(),
    )
    if check and proc.returncode != 0:
        raise AssertionError(
            f"dktlbm failed ({proc.returncode}): {' '.join(args)}\n{proc.stdout}\n{proc.stderr}"
        )
    return proc


def last_fields(h5file: Path) -> tuple[dict[str, np.ndarray], dict[str, float]]:
    """The last field group of a run file: arrays (ny, nx) by name, and the group attributes."""
    import h5py

    with h5py.File(h5file, "r") as h5:
        groups = sorted(h5["fields"].keys())
        g = h5["fields"][groups[-1]]
        # the datasets (a sub-group `particles` holds the disks) and the numeric attributes
        # (each unit is a string attribute <name>_units)
        fields = {n: d[()] for n, d in g.items() if isinstance(d, h5py.Dataset)}
        attrs = {
            k: float(np.asarray(v).ravel()[0])
            for k, v in g.attrs.items()
            if not k.endswith("_units")
        }
    return fields, attrs


def all_datasets(h5file: Path) -> dict[str, np.ndarray]:
    """Every dataset of an HDF5 file, by its path."""
    import h5py

    out: dict[str, np.ndarray] = {}
    with h5py.File(h5file, "r") as h5:

        def take(name: str, obj: object) -> None:
            if isinstance(obj, h5py.Dataset):
                out[name] = obj[()]

        h5.visititems(take)
    return out


def run_attr(h5file: Path, name: str) -> float:
    import h5py

    with h5py.File(h5file, "r") as h5:
        return float(np.asarray(h5["run"].attrs[name]).ravel()[0])


def session_pids(sid: int, comm: str | None = None) -> list[int]:
    """Processes of session `sid` (Linux /proc), only those named `comm` if given (e.g.
    "dktlbm": the ranks, not mpiexec): mpiexec puts each rank in its own process group, but
    they stay in the session run_args starts."""
    pids = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        name = stat[stat.index("(") + 1 : stat.rindex(")")]
        fields = stat[stat.rindex(")") + 2 :].split()  # after "pid (comm) "
        if int(fields[3]) == sid and (comm is None or name == comm):
            pids.append(int(entry.name))
    return pids


def number_after(label: str, text: str) -> float:
    """The number printed right after `label` in `text` (a report line such as "dt = 1e-4")."""
    m = re.search(re.escape(label) + r"\s*([-+0-9.]+(?:[eE][-+]?[0-9]+)?)", text)
    assert m, f"{label!r} not found in:\n{text}"
    return float(m.group(1))


def run_args(
    args: list[str],
    ranks: int = 1,
    timeout: float = 300.0,
    cwd: Path | None = None,
    env: dict[str, str] | None = None,
) -> subprocess.CompletedProcess[str]:
    """Run dktlbm with the raw command-line `args` on `ranks` ranks (in directory `cwd`, with the
    extra environment variables `env`); return the finished process whatever its exit status.
    Output that is not UTF-8 (a scene of binary garbage echoed in a message) is decoded with
    replacement characters rather than failing the caller. A run still going after `timeout` s
    is a hang: mpiexec and every rank are killed and AssertionError is raised."""
    cmd = [*mpi_command(ranks), str(EXE), *args]
    proc = subprocess.Popen(
        cmd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        errors="replace",
        env={**mpi_env(), **(env or {})},
        cwd=cwd,
        start_new_session=True,
    )
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.terminate()  # mpiexec passes SIGTERM on to the ranks
        time.sleep(2.0)
        for pid in session_pids(proc.pid):
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        out, err = proc.communicate()
        raise AssertionError(
            f"hang: no exit within {timeout} s: {' '.join(cmd)}\n{out}\n{err}"
        ) from None
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err)


def tree_digest(path: Path) -> dict[str, str]:
    """sha256 of every file below path, by relative name (directories as 'dir')."""
    digest = {}
    for p in sorted(path.rglob("*")):
        rel = str(p.relative_to(path))
        digest[rel] = "dir" if p.is_dir() else hashlib.sha256(p.read_bytes()).hexdigest()
    return digest


def sigterm_when_logged(
    nml: str | Path,
    ranks: int,
    sets: list[str],
    outdir: Path,
    logged: str,
    timeout: float = 120.0,
    signum: int = signal.SIGTERM,
) -> subprocess.CompletedProcess[str]:
    """Run dktlbm (scene `nml` in input/ or a path) with output.dir = outdir, wait until its log
    holds `logged` (e.g. a progress line: the run is stepping), send SIGTERM (or `signum`, e.g.
    SIGKILL) to every rank as a batch system does, and return the finished process."""
    path = Path(nml)
    if not path.exists():
        path = INPUT / nml
    cmd = [*mpi_command(ranks), str(EXE), str(path)]
    for s in [*sets, f"output.dir={outdir}"]:
        cmd += ["--set", s]
    proc = subprocess.Popen(
        cmd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=mpi_env(),
        start_new_session=True,
    )
    deadline = time.time() + timeout
    log = outdir / f"{path.stem}.log"
    while time.time() < deadline:
        if log.exists() and logged in log.read_text():
            break
        time.sleep(0.05)
    for pid in session_pids(proc.pid, "dktlbm"):
        os.kill(pid, signum)
    stdout, stderr = proc.communicate(timeout=timeout)
    return subprocess.CompletedProcess(cmd, proc.returncode, stdout, stderr)


def pvpython_or_skip() -> str | None:
    """ParaView's pvpython on PATH; the calling test module is skipped without it, unless
    DKT_REQUIRE_PARAVIEW=1 (then None, and the test asserts on it)."""
    import shutil

    import pytest

    path = shutil.which("pvpython")
    if path is None and os.environ.get("DKT_REQUIRE_PARAVIEW") != "1":
        pytest.skip(
            "pvpython (ParaView) is not installed; set DKT_REQUIRE_PARAVIEW=1 to fail instead",
            allow_module_level=True,
        )
    return path
