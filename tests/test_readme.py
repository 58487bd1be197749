"""The README stays short, and every link, command and example in it works.

What it proves, each check able to fail:
- README.md has at most 300 lines.
- Every relative link and image of README.md, CHANGELOG.md and the docs pages it owns names a
  file of the repository, and an anchor names a heading of its page.
- Every command of the README's ```sh blocks is taken apart and checked: a dktlbm run gets
  --check appended, with its own options and rank count (tools/run.sh's dktlbm options too),
  from a directory that holds no earlier run; --help, --version and --print-defaults run (what
  --print-defaults writes passes --check as a scene); tools/*.sh exist and are executable; the
  cmake presets exist, and `cmake --install` of this build puts dktlbm and the share/dktlbm
  directories the README names under a fresh prefix; `pip install .` finds a pyproject.toml
  that declares each dkt-* command the README uses; each dkt-* command answers --help with
  every option the README gives it, and the plot commands and `dkt-sweep plan` run as written
  on a small real run this test makes. A command of another kind fails: add its check here.
- The README's scene file (its ```fortran block) passes --check, and its ```python example
  runs on the small real run.
- The version in CMakeLists.txt equals the newest CHANGELOG.md section's, CITATION.cff's, the
  README's citation line's and pyproject.toml's.

A dkt-X command runs as `python3 -m dktlbm.X` when the package `dktlbm` of this tree is on
PYTHONPATH (ctest puts <root>/postproc there), else as the console script on PATH, else as
`python3 -m dktlbm.X` with PYTHONPATH=<root>/postproc, the form the README gives for a
checkout without pip install.
"""

from __future__ import annotations

import importlib.util
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from dkt_run import EXE, ROOT, mpi_command, mpi_env
from markdown_links import broken_links

README = ROOT / "README.md"
MAX_LINES = 300
TIMEOUT = 120
# Markdown pages whose links this test keeps working (the README and the pages beside it).
LINKED_PAGES = [
    "README.md",
    "CHANGELOG.md",
    "docs/running.md",
    "docs/accuracy.md",
    "docs/performance.md",
    "docs/regime.md",
]
# dkt-* commands that run as written on the test's small run; the others (they would start
# runs or submit jobs) show --help with every option the README gives them.
RUN_FOR_REAL = {
    "dkt-gap",
    "dkt-trajectories",
    "dkt-drag",
    "dkt-field",
    "dkt-pattern",
    "dkt-sweep plan",
}
LAUNCHERS = {"mpirun", "mpiexec"}
SHELL_OPERATORS = {"&&", "||", ";", "|"}


def readme_text() -> str:
    return README.read_text(encoding="utf-8")


def fenced_blocks(text: str, language: str) -> list[str]:
    """The bodies of the ```language blocks of a Markdown text (indented ones too)."""
    pattern = rf"^([ \t]*)```{language}[ \t]*\n(.*?)^\1```"
    return [
        dedent_by(body, indent) for indent, body in re.findall(pattern, text, flags=re.S | re.M)
    ]


def dedent_by(body: str, indent: str) -> str:
    return "\n".join(
        line[len(indent) :] if line.startswith(indent) else line for line in body.splitlines()
    )


def sh_commands(text: str) -> list[list[str]]:
    """Every command of the ```sh blocks as its words: continuations joined, comments dropped,
    commands joined by && or ; split apart."""
    commands = []
    for block in fenced_blocks(text, "sh"):
        for line in re.sub(r"\\\n", " ", block).splitlines():
            words = shlex.split(line, comments=True)
            command: list[str] = []
            for word in words + [";"]:
                if word in SHELL_OPERATORS:
                    if command:
                        commands.append(command)
                    command = []
                else:
                    command.append(word)
    return commands


COMMANDS = sh_commands(readme_text())


def run(args: list[str], cwd: Path, **kwargs) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        args, cwd=cwd, env=mpi_env(), capture_output=True, text=True, timeout=TIMEOUT, **kwargs
    )


def assert_ok(proc: subprocess.CompletedProcess[str], what: str) -> None:
    assert proc.returncode == 0, (
        f"README command `{what}` failed with status {proc.returncode}:\n"
        f"{proc.stdout[-2000:]}\n{proc.stderr[-2000:]}"
    )


# ---- fixtures: a directory to check commands from, and one with a small real run ----


@pytest.fixture(scope="module")
def check_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An empty working directory where input/ is the repository's and the README's own scene
    files exist (written from its ```fortran blocks that start with `! NAME.nml`)."""
    work = tmp_path_factory.mktemp("readme_checks")
    (work / "input").symlink_to(ROOT / "input")
    for block in fenced_blocks(readme_text(), "fortran"):
        name = re.match(r"!\s*([\w.-]+\.nml)\b", block)
        if name:
            (work / name.group(1)).write_text(block + "\n")
    return work


@pytest.fixture(scope="module")
def results_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A working directory holding runs/case1/case1.h5, a short coarse run of the main job."""
    work = tmp_path_factory.mktemp("readme_results")
    (work / "input").symlink_to(ROOT / "input")
    proc = run(
        mpi_command(1)
        + [
            str(EXE),
            "input/case1.nml",
            "--set",
            "lbm.cells_per_diameter=8",
            "--set",
            "run.t_end=0.3",
            "--set",
            "output.dir=runs/case1",
        ],
        work,
    )
    assert_ok(proc, "the small case1 run the examples read")
    assert (work / "runs" / "case1" / "case1.h5").is_file()
    return work


# ---- length and links ----


def test_readme_is_at_most_300_lines() -> None:
    lines = len(readme_text().splitlines())
    assert lines <= MAX_LINES, f"README.md has {lines} lines, more than {MAX_LINES}"


@pytest.mark.parametrize("page", LINKED_PAGES)
def test_every_relative_link_resolves(page: str) -> None:
    problems = broken_links(ROOT / page)
    assert not problems, f"{page}: broken links:\n" + "\n".join(problems)


# ---- commands ----


def split_launcher(words: list[str]) -> tuple[int, list[str]]:
    """(ranks, the command after `mpirun -n N [options]`); 1 rank without a launcher."""
    if words[0] not in LAUNCHERS:
        return 1, words
    rest, ranks = words[1:], 1
    while rest and rest[0].startswith("-"):
        option = rest.pop(0)
        if option in ("-n", "-np", "--np", "-c"):
            ranks = int(rest.pop(0))
    return ranks, rest


def is_dktlbm(program: str) -> bool:
    return program in ("dktlbm", "build/dktlbm")


def check_dktlbm(ranks: int, args: list[str], cwd: Path, what: str) -> None:
    """A dktlbm command line: informational options run, a run is --check'ed."""
    redirect = None
    if ">" in args:
        at = args.index(">")
        args, redirect = args[:at], args[at + 1]
    if {"--help", "--version", "--print-defaults"} & set(args):
        proc = run([str(EXE), *args], cwd)
        assert_ok(proc, what)
        if "--help" in args:
            assert proc.stdout.startswith("usage: dktlbm"), proc.stdout[:200]
        if "--version" in args:
            assert proc.stdout.startswith("dktlbm "), proc.stdout[:200]
        if redirect:  # what it printed is a scene that --check accepts
            (cwd / redirect).write_text(proc.stdout)
            assert_ok(run([str(EXE), redirect, "--check"], cwd), f"{what}; dktlbm {redirect}")
        return
    assert redirect is None, f"`{what}`: a run's output redirected, which this test cannot check"
    check = [] if "--check" in args else ["--check"]
    assert_ok(run(mpi_command(ranks) + [str(EXE), *args, *check], cwd), what)


def check_tool_script(words: list[str], cwd: Path, what: str) -> None:
    script = ROOT / words[0]
    assert script.is_file(), f"`{what}`: {words[0]} does not exist"
    assert os.access(script, os.X_OK), f"`{what}`: {words[0]} is not executable"
    if script.name == "run.sh":  # tools/run.sh [scene] [ranks] [dktlbm options...]
        args = words[1:]
        scene = args[0] if args else "input/case1.nml"
        ranks = int(args[1]) if len(args) > 1 else 2
        check_dktlbm(ranks, [scene, *args[2:]], cwd, what)


def check_cmake(args: list[str], what: str, tmp_path: Path) -> None:
    presets = json.loads((ROOT / "CMakePresets.json").read_text())
    configure = {p["name"]: p for p in presets["configurePresets"]}
    if "--install" in args:
        build = args[args.index("--install") + 1]
        binary_dirs = {
            p.get("binaryDir", "").replace("${sourceDir}/", "") for p in configure.values()
        }
        assert build in binary_dirs, f"`{what}`: {build} is no preset's build directory"
        check_install(tmp_path / "prefix", what)
        return
    assert "--preset" in args, f"`{what}`: a cmake command this test does not know"
    name = args[args.index("--preset") + 1]
    kind = "buildPresets" if "--build" in args else "configurePresets"
    names = [p["name"] for p in presets.get(kind, [])]
    assert name in names, f"`{what}`: no {kind} entry {name!r} in CMakePresets.json: {names}"


def check_install(prefix: Path, what: str) -> None:
    """Install this build into a fresh prefix: dktlbm runs from it, and every share/dktlbm
    directory the README names is there (doc/ with the files it names)."""
    build = EXE.parent
    assert (build / "cmake_install.cmake").is_file(), f"{build} is not a CMake build directory"
    proc = run(["cmake", "--install", str(build), "--prefix", str(prefix)], build)
    assert_ok(proc, what)
    assert_ok(run([str(prefix / "bin" / "dktlbm"), "--version"], prefix), "installed --version")
    text = readme_text()
    for sub in sorted(set(re.findall(r"share/dktlbm/(\w+)/", text))):
        assert (prefix / "share" / "dktlbm" / sub).is_dir(), f"no share/dktlbm/{sub}/ installed"
    for name in ("README.md", "LICENSE", "CHANGELOG.md", "CITATION.cff"):
        assert (prefix / "share" / "dktlbm" / "doc" / name).is_file(), f"doc/{name} not installed"


def check_pip_install(args: list[str], what: str) -> None:
    """`pip install .` needs a pyproject.toml at the root declaring every dkt-* command the
    README uses, each pointing at a module of this tree."""
    assert args[:2] == ["install", "."], f"`{what}`: a pip command this test does not know"
    pyproject = ROOT / "pyproject.toml"
    assert pyproject.is_file(), f"`{what}`: no pyproject.toml at the repository root"
    project = tomllib.loads(pyproject.read_text())["project"]
    assert project["name"] == "dktlbm", project["name"]
    scripts = project.get("scripts", {})
    used = sorted({words[0] for words in COMMANDS if words[0].startswith("dkt-")})
    for name in used:
        assert name in scripts, f"pyproject.toml declares no console script {name}"
        module = scripts[name].split(":")[0]
        parts = module.split(".")
        assert (ROOT / "postproc" / Path(*parts)).with_suffix(".py").is_file(), (
            f"{name} = {scripts[name]}: no postproc/{'/'.join(parts)}.py"
        )


def tool_runner(name: str) -> list[str]:
    """How to start the dkt-* command `name` (see the module docstring)."""
    module = "dktlbm." + name.removeprefix("dkt-")
    package = importlib.util.find_spec("dktlbm")
    if package and package.origin and Path(package.origin).is_relative_to(ROOT / "postproc"):
        if importlib.util.find_spec(module):
            return [sys.executable, "-m", module]
    console = shutil.which(name)
    if console:
        return [console]
    return ["env", f"PYTHONPATH={ROOT / 'postproc'}", sys.executable, "-m", module]


def check_tool(runner: list[str], name: str, args: list[str], cwd: Path, what: str) -> None:
    """--help lists every option the README gives; the cheap commands run as written."""
    sub = [args[0]] if args and not args[0].startswith("-") and "." not in args[0] else []
    proc = run([*runner, *sub, "--help"], cwd)
    assert_ok(proc, f"{name} {' '.join(sub)} --help")
    for option in {a.split("=")[0] for a in args if a.startswith("--")}:
        assert re.search(rf"(?<![\w-]){re.escape(option)}(?![\w-])", proc.stdout), (
            f"`{what}`: {option} is not among the options of {name} {' '.join(sub)}"
        )
    if " ".join([name, *sub]) in RUN_FOR_REAL:
        assert_ok(run([*runner, *args], cwd), what)


@pytest.mark.parametrize("words", COMMANDS, ids=[" ".join(w)[:60] for w in COMMANDS])
def test_readme_command_works(
    words: list[str], check_dir: Path, results_dir: Path, tmp_path: Path
) -> None:
    what = " ".join(words)
    ranks, command = split_launcher(words)
    program, args = command[0], command[1:]
    if is_dktlbm(program):
        check_dktlbm(ranks, args, check_dir, what)
    elif re.fullmatch(r"tools/[\w-]+\.sh", program):
        check_tool_script(command, check_dir, what)
    elif program == "cmake":
        check_cmake(args, what, tmp_path)
    elif program in ("pip", "pip3"):
        check_pip_install(args, what)
    elif program.startswith("dkt-"):
        check_tool(tool_runner(program), program, args, results_dir, what)
    elif (program == "PYTHONPATH=postproc" and args[:2] == ["python3", "-m"]
          and re.fullmatch(r"dktlbm\.\w+", args[2])):
        runner = ["env", f"PYTHONPATH={ROOT / 'postproc'}", sys.executable, "-m", args[2]]
        check_tool(runner, "dkt-" + args[2].removeprefix("dktlbm."), args[3:], results_dir, what)
    else:
        pytest.fail(f"README command `{what}` is of a kind tests/test_readme.py does not check")


def test_readme_commands_were_found() -> None:
    """The parser sees the README's commands (a broken fence would hide them all)."""
    programs = {split_launcher(w)[1][0] for w in COMMANDS}
    assert {"tools/run.sh", "tools/test.sh", "build/dktlbm", "cmake"} <= programs, programs


# ---- the examples ----


def test_readme_python_example_runs(results_dir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    blocks = fenced_blocks(readme_text(), "python")
    assert blocks, "README.md has no ```python example"
    monkeypatch.chdir(results_dir)
    for block in blocks:
        exec(compile(block, "README.md python example", "exec"), {"__name__": "readme"})


def test_readme_scene_passes_check(check_dir: Path) -> None:
    scenes = [re.match(r"!\s*([\w.-]+\.nml)\b", b) for b in fenced_blocks(readme_text(), "fortran")]
    names = [m.group(1) for m in scenes if m]
    assert names, "README.md has no scene (a ```fortran block starting `! NAME.nml`)"
    for name in names:
        assert_ok(run([str(EXE), name, "--check"], check_dir), f"dktlbm {name} --check")


# ---- one version everywhere ----


def test_version_is_the_same_everywhere() -> None:
    cmake = re.search(
        r"project\(\s*dktlbm\s+VERSION\s+([\w.]+)", (ROOT / "CMakeLists.txt").read_text()
    )
    changelog = re.search(
        r"^## \[(\d+\.\d+\.\d+)\]", (ROOT / "CHANGELOG.md").read_text(), flags=re.M
    )
    citation = re.search(
        r"^version:\s*[\"']?([\w.]+)", (ROOT / "CITATION.cff").read_text(), flags=re.M
    )
    cited = re.search(r"\*dktlbm\*, version ([\w.]+)", readme_text())
    assert cmake and changelog and citation and cited, (cmake, changelog, citation, cited)
    versions = {
        "CMakeLists.txt project(VERSION)": cmake.group(1),
        "CHANGELOG.md newest section": changelog.group(1),
        "CITATION.cff version": citation.group(1),
        "README.md citation": cited.group(1).rstrip("."),
    }
    pyproject = ROOT / "pyproject.toml"
    if pyproject.is_file():
        project = tomllib.loads(pyproject.read_text())["project"]
        assert "version" in project, "pyproject.toml: the version must be written in [project]"
        versions["pyproject.toml version"] = project["version"]
    assert len(set(versions.values())) == 1, f"versions differ: {versions}"
