"""Starting dktlbm: the executable, the MPI launch prefix for N ranks and the environment it
needs, and the installed Slurm scripts. The post-processing commands, the tests and the
benchmarks all start runs through these functions.

    from dktlbm import launch
    cmd = launch.mpi_prefix(2) + [launch.exe(), "input/case1.nml"]
    subprocess.run(cmd, env=launch.mpi_env())

Settings read from the environment (ctest sets them, see tests/CMakeLists.txt):
DKTLBM_EXE (the executable), MPIEXEC (default mpiexec), MPIEXEC_NUMPROC_FLAG (default -n),
MPIEXEC_PREFLAGS (flags before the executable; unset: --oversubscribe for Open MPI),
DKTLBM_SHARE (the installed share/dktlbm directory).
"""

from __future__ import annotations

import functools
import os
import shlex
import shutil
import subprocess
from pathlib import Path

# The source tree this package sits in (postproc/dktlbm/launch.py), when it is run from one.
SOURCE_ROOT = Path(__file__).resolve().parents[2]


class LaunchError(Exception):
    """Something needed to start dktlbm is missing; str() says what and how to fix it."""


def _source_tree() -> Path | None:
    root = SOURCE_ROOT
    return root if (root / "CMakeLists.txt").is_file() and (root / "src").is_dir() else None


def find_exe() -> Path | None:
    """The dktlbm executable: $DKTLBM_EXE, else `dktlbm` on PATH, else build/dktlbm of the
    source tree this package is in; None when there is none."""
    given = os.environ.get("DKTLBM_EXE")
    if given:
        return Path(given)
    on_path = shutil.which("dktlbm")
    if on_path:
        return Path(on_path)
    tree = _source_tree()
    if tree is not None and (tree / "build" / "dktlbm").is_file():
        return tree / "build" / "dktlbm"
    return None


def exe() -> str:
    """find_exe() as a string; LaunchError when there is none."""
    found = find_exe()
    if found is None:
        raise LaunchError("the dktlbm executable is not found: set DKTLBM_EXE=/path/to/dktlbm, "
                          "put dktlbm on PATH, or build it (cmake --preset release && cmake "
                          "--build --preset release)")
    return str(found)


@functools.cache
def is_open_mpi(mpiexec: str) -> bool:
    """Whether `mpiexec --version` names Open MPI (which needs --oversubscribe to start more
    ranks than cores, and two variables to run as root)."""
    try:
        proc = subprocess.run([mpiexec, "--version"], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired):
        return False
    text = proc.stdout + proc.stderr
    return any(name in text for name in ("Open MPI", "OpenRTE", "open-mpi"))


def mpiexec() -> str:
    """$MPIEXEC, default mpiexec."""
    return os.environ.get("MPIEXEC") or "mpiexec"


def mpi_prefix(ranks: int, launcher: str | None = None, past_cores_only: bool = False) -> list[str]:
    """The command prefix that starts `ranks` ranks: `launcher` (default mpiexec()), the rank
    flag ($MPIEXEC_NUMPROC_FLAG, default -n) and the flags before the executable
    ($MPIEXEC_PREFLAGS when set; else --oversubscribe for Open MPI, always or, with
    `past_cores_only` (benchmarks: binding ranks to cores matters), only for more ranks than
    cores)."""
    launcher = launcher or mpiexec()
    flag = os.environ.get("MPIEXEC_NUMPROC_FLAG") or "-n"
    prefix = [launcher, flag, str(ranks)]
    if "MPIEXEC_PREFLAGS" in os.environ:
        return prefix + shlex.split(os.environ["MPIEXEC_PREFLAGS"])
    crowded = ranks > (os.cpu_count() or 1)
    if (crowded or not past_cores_only) and is_open_mpi(launcher):
        prefix.append("--oversubscribe")
    return prefix


def root_env() -> dict[str, str]:
    """The variables Open MPI needs to run as root (CI and containers); none for other users."""
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        return {"OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1"}
    return {}


def mpi_env(jobs: int = 1) -> dict[str, str]:
    """The environment of an MPI run: this one, with root_env(). With several runs side by side
    (`jobs` > 1), Open MPI's binding is switched off unless the environment sets a policy: each
    mpiexec binds its ranks from the first core on, without knowing of the others."""
    env = dict(os.environ)
    for key, value in root_env().items():
        env.setdefault(key, value)
    if jobs > 1:
        env.setdefault("OMPI_MCA_hwloc_base_binding_policy", "none")
    return env


def share_dirs() -> list[Path]:
    """Where the installed share/dktlbm may be, in order: $DKTLBM_SHARE, then
    <directory of the dktlbm executable>/../share/dktlbm."""
    places = []
    if os.environ.get("DKTLBM_SHARE"):
        places.append(Path(os.environ["DKTLBM_SHARE"]))
    found = find_exe()
    if found is not None:
        places.append(found.resolve().parent.parent / "share" / "dktlbm")
    return places


def slurm_dir() -> Path:
    """The directory of the Slurm scripts (dkt_job.sh, run_one.slurm, sweep_array.slurm):
    $DKTLBM_SHARE/slurm, else <dir of the dktlbm executable>/../share/dktlbm/slurm, else the
    source tree's input/slurm. LaunchError naming the places tried when none holds them."""
    places = [p / "slurm" for p in share_dirs()]
    tree = _source_tree()
    if tree is not None:
        places.append(tree / "input" / "slurm")
    for place in places:
        if (place / "dkt_job.sh").is_file():
            return place
    tried = ", ".join(str(p) for p in places) or "nowhere (no dktlbm executable found)"
    raise LaunchError(f"the Slurm scripts (dkt_job.sh) are not found; looked in {tried}: set "
                      f"DKTLBM_SHARE to the installed share/dktlbm directory")
