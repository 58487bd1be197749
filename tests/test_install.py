"""An installed dktlbm used as a new user would, away from the source tree.

`cmake --install` of this build into a scratch prefix gives bin/dktlbm, the example scenes, the
Slurm scripts (dkt_job.sh executable) and the documents, whose relative links all name
installed files; the Python package installs with pip into a scratch venv (system site
packages for numpy, h5py and matplotlib; offline, without build isolation, where setuptools
and wheel are there, else pip fetches them), from a copy of pyproject.toml and postproc/ so
that the tree stays clean. Then, from an empty directory with only the prefix's bin and the
venv's bin on PATH (and the MPI launcher's directory after them; no DKTLBM_EXE, DKTLBM_ROOT or
PYTHONPATH): an example scene runs on 2 ranks, `dkt-gap` draws its
PNG, `dkt-pattern` classifies it, and the package the commands import is the venv's, not the
tree's. `dkt-paraview` answers --help and --version from the install, its render script is the
venv's copy, and where pvpython is there it draws a PNG of a short run.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from dktlbm import launch
from markdown_links import broken_links

ROOT = Path(os.environ.get("DKTLBM_ROOT", Path(__file__).resolve().parents[1]))
BUILD = Path(os.environ.get("DKT_BUILD_DIR", ROOT / "build"))
CMAKE = os.environ.get("DKT_CMAKE", "cmake")
# what the user's shell would not have: the test environment's pointers into the tree
TREE_VARIABLES = ("DKTLBM_EXE", "DKTLBM_ROOT", "DKTLBM_SHARE", "PYTHONPATH")


def run(command: list[str | Path], **kwargs) -> subprocess.CompletedProcess[str]:
    proc = subprocess.run([str(c) for c in command], capture_output=True, text=True,
                          timeout=600, **kwargs)
    assert proc.returncode == 0, f"{command}\n{proc.stdout}\n{proc.stderr}"
    return proc


def install(base: Path) -> dict[str, Path]:
    """This build installed into base/prefix, the package into the venv base/venv."""
    prefix, venv, source = base / "prefix", base / "venv", base / "source"
    run([CMAKE, "--install", BUILD, "--prefix", prefix])
    source.mkdir()
    shutil.copy2(ROOT / "pyproject.toml", source)
    shutil.copytree(ROOT / "postproc", source / "postproc",
                    ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
    run([sys.executable, "-m", "venv", "--system-site-packages", venv])
    env = {k: v for k, v in os.environ.items() if k not in TREE_VARIABLES}
    pip = [venv / "bin" / "python", "-m", "pip", "install", "--no-input", "--quiet",
           "--disable-pip-version-check"]
    # offline where the venv can build a wheel (setuptools and wheel); else pip fetches them
    offline = subprocess.run([venv / "bin" / "python", "-c", "import setuptools, wheel"],
                             capture_output=True).returncode == 0
    run([*pip, *(["--no-build-isolation"] if offline else []), source], env=env, cwd=base)
    return {"prefix": prefix, "venv": venv}


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    return install(tmp_path_factory.mktemp("install"))


def mpi_launcher() -> Path:
    """The user's mpiexec (the system's), found before PATH is cut down."""
    found = shutil.which(launch.mpiexec())
    assert found, f"{launch.mpiexec()} not found"
    return Path(found)


def user_env(installed: dict[str, Path]) -> dict[str, str]:
    """PATH: the prefix's bin, the venv's bin, and last the MPI launcher's directory (Open MPI's
    mpiexec looks for ssh on PATH even for local ranks), which holds no dktlbm or dkt-*."""
    env = {k: v for k, v in os.environ.items() if k not in TREE_VARIABLES}
    env["PATH"] = os.pathsep.join(str(d) for d in (
        installed["prefix"] / "bin", installed["venv"] / "bin", mpi_launcher().parent))
    env["MPLBACKEND"] = "Agg"
    return env


def test_install_layout(installed: dict[str, Path]) -> None:
    """The prefix holds what the install section of README promises."""
    share = installed["prefix"] / "share" / "dktlbm"
    assert os.access(installed["prefix"] / "bin" / "dktlbm", os.X_OK)
    scenes = sorted(p.name for p in (ROOT / "input").glob("*.nml"))
    assert scenes and sorted(p.name for p in (share / "examples").glob("*.nml")) == scenes
    assert (share / "examples" / "README.md").is_file()
    for name in ("run_one.slurm", "sweep_array.slurm", "README.md"):
        assert (share / "slurm" / name).is_file(), name
    assert os.access(share / "slurm" / "dkt_job.sh", os.X_OK)
    assert (share / "doc" / "README.md").is_file()
    pages = sorted(p.name for p in (ROOT / "docs").glob("*.md"))
    assert pages and sorted(p.name for p in (share / "doc" / "docs").glob("*.md")) == pages
    for name in ("LICENSE", "CHANGELOG.md", "CITATION.cff"):
        assert (share / "doc" / name).is_file() == (ROOT / name).is_file(), name


def test_installed_pages_link_only_to_installed_files(installed: dict[str, Path]) -> None:
    """Every relative link and image of every installed Markdown page (the README, the docs,
    the examples' and the Slurm scripts' READMEs) names a file of the install, and an anchor
    names a heading of its page: the pages link to each other as installed, not as in the
    source tree."""
    share = installed["prefix"] / "share" / "dktlbm"
    pages = sorted(share.rglob("*.md"))
    assert share / "doc" / "README.md" in pages and len(pages) > len(list(ROOT.glob("docs/*.md")))
    problems = [f"{page.relative_to(share)}: {problem}"
                for page in pages for problem in broken_links(page, within=installed["prefix"])]
    assert not problems, "broken links in the install:\n" + "\n".join(problems)


def test_a_new_user_runs_an_example_and_plots_it(installed: dict[str, Path],
                                                 tmp_path: Path) -> None:
    """From an empty directory: case1 (8 cells per D, 0.3 s, 2 ranks) from the installed
    examples, then dkt-gap (a PNG of the figure's size) and dkt-pattern on its file."""
    env = user_env(installed)
    here = tmp_path / "empty"
    here.mkdir()
    scene = installed["prefix"] / "share" / "dktlbm" / "examples" / "case1.nml"
    assert shutil.which("dktlbm", path=env["PATH"]) == str(installed["prefix"] / "bin" /
                                                           "dktlbm")
    prefix = launch.mpi_prefix(2, str(mpi_launcher()))
    run([*prefix, "dktlbm", scene, "--set", "lbm.cells_per_diameter=8", "--set",
         "run.t_end=0.3", "--set", "output.dir=run"], env={**env, **launch.root_env()}, cwd=here)
    h5 = here / "run" / "case1.h5"
    assert h5.is_file()

    gap = run(["dkt-gap", h5], env=env, cwd=here)
    png = here / "run" / "case1_gap.png"
    assert f"wrote {png}" in gap.stdout or f"wrote {png.relative_to(here)}" in gap.stdout
    from PIL import Image

    with Image.open(png) as image:
        assert image.format == "PNG" and min(image.size) >= 300
        assert len(image.convert("RGB").getcolors(maxcolors=1 << 20)) > 2  # a drawn figure
    pattern = run(["dkt-pattern", h5, "--json"], env=env, cwd=here)
    assert '"pattern"' in pattern.stdout

    where = run(["python", "-c", "import dktlbm; print(dktlbm.__file__)"], env=env, cwd=here)
    assert Path(where.stdout.strip()).is_relative_to(installed["venv"])


def test_dkt_paraview_from_the_install(installed: dict[str, Path], tmp_path: Path) -> None:
    """dkt-paraview --help and --version from the venv; the script it gives pvpython is in the
    venv (an install that left it out, or that pointed into the tree, fails here); with pvpython
    on PATH, a PNG of case1 (8 cells per D, 0.1 s, 1 rank) at the size asked for."""
    env = user_env(installed)
    # ParaView and xvfb-run where the user has them: their directories after the install's
    for tool in ("pvpython", "xvfb-run"):
        found = shutil.which(tool)
        if found:
            env["PATH"] += os.pathsep + str(Path(found).parent)
    here = tmp_path / "empty"
    here.mkdir()
    assert run(["dkt-paraview", "--help"], env=env, cwd=here).stdout.startswith(
        "usage: dkt-paraview")
    assert run(["dkt-paraview", "--version"], env=env, cwd=here).stdout.startswith(
        "dkt-paraview ")
    where = run(["python", "-c", "import dktlbm.paraview as m; print(m.RENDER)"], env=env,
                cwd=here)
    render = Path(where.stdout.strip())
    assert render.is_file() and render.is_relative_to(installed["venv"]), render
    if shutil.which("pvpython", path=env["PATH"]) is None:
        return
    scene = installed["prefix"] / "share" / "dktlbm" / "examples" / "case1.nml"
    prefix = launch.mpi_prefix(1, str(mpi_launcher()))
    run([*prefix, "dktlbm", scene, "--set", "lbm.cells_per_diameter=8", "--set",
         "run.t_end=0.1", "--set", "output.dir=run"], env={**env, **launch.root_env()}, cwd=here)
    run(["dkt-paraview", "run/case1.h5", "--size", "190", "350"], env=env, cwd=here)
    from PIL import Image

    with Image.open(here / "run" / "case1_paraview.png") as image:
        assert image.format == "PNG" and image.size == (190, 350)
        assert len(image.convert("RGB").getcolors(maxcolors=1 << 20)) > 2
