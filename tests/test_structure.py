"""The structure limits of docs/design.md hold for src/, and tools/check_structure.py, which
checks them, finds each kind of breach: a file over 800 lines, a procedure over 150 lines (a
host counted with what it contains, a submodule's separate module procedure too, continuation
lines and strings with '!' handled), an input module used for more than its types and
constants or without 'only:'. The main program may use the input layer freely. No Python file
of postproc/, tests/ or tools/ edits sys.path: each finds the package and the test helpers on
PYTHONPATH, as ctest and the documented commands set it."""

import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(os.environ.get("DKTLBM_ROOT", Path(__file__).resolve().parent.parent))
SCRIPT = ROOT / "tools" / "check_structure.py"


def run(src: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(SCRIPT), str(src)], capture_output=True,
                          text=True, timeout=60)


def procedure(name: str, body_lines: int, inner: str = "") -> str:
    body = "".join(f"    x = x + {k}  ! '!' in a comment\n" for k in range(body_lines))
    contains = f"  contains\n{inner}" if inner else ""
    return (f"  subroutine {name}(x)\n    real, intent(inout) :: x\n{body}{contains}"
            f"  end subroutine {name}\n")


def module(name: str, uses: str = "", procs: str = "") -> str:
    return (f"module {name}\n{uses}  implicit none\n  private\ncontains\n{procs}"
            f"end module {name}\n")


def test_the_sources_keep_the_limits():
    result = run(ROOT / "src")
    assert result.returncode == 0, result.stdout + result.stderr


SYS_PATH_EDIT = re.compile(r"\bsys\.path\s*(\[[^\]]*\]\s*)?(=|\+=|\.(insert|append|extend)\b)")


def test_no_python_file_edits_sys_path():
    """An edit of sys.path (assignment, +=, insert, append, extend) in any .py file of
    postproc/, tests/ or tools/ is named; the pattern finds each form (checked on samples)."""
    for sample in ("sys.path.insert(0, d)", "sys.path[:0] = [d]", "sys.path += [d]",
                   "sys.path.append(d)", "sys.path = [d]"):
        assert SYS_PATH_EDIT.search(sample), sample
    assert not SYS_PATH_EDIT.search("print(sys.path)")
    found = [f"{path.relative_to(ROOT)}:{number}"
             for folder in ("postproc", "tests", "tools") for path in (ROOT / folder).rglob("*.py")
             if path.name != Path(__file__).name  # this file: the samples above
             for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
             if SYS_PATH_EDIT.search(line.split("#")[0])]
    assert not found, "sys.path edited (use PYTHONPATH): " + ", ".join(found)


def test_a_long_file_is_found(tmp_path):
    procs = "".join(procedure(f"p{k}", 100) for k in range(8))
    (tmp_path / "dkt_big.f90").write_text(module("dkt_big", procs=procs))
    result = run(tmp_path)
    assert result.returncode == 1
    assert "dkt_big.f90:1:" in result.stdout and "more than 800" in result.stdout
    assert "procedure" not in result.stdout          # each procedure is within its limit


def test_a_long_procedure_is_found_with_what_it_contains(tmp_path):
    inner = procedure("helper", 70)
    host = procedure("host", 80, inner)              # 80 + 70 + headers > 150
    short = procedure("short", 140)                  # 144 lines with its header: allowed
    continued = ("  subroutine cont(x, &\n      y)\n    real :: x, y\n    x = 'a!b' // &\n"
                 "      'c'\n  end subroutine cont\n")
    (tmp_path / "dkt_some.f90").write_text(module("dkt_some", procs=host + short + continued))
    result = run(tmp_path)
    assert result.returncode == 1
    lines = result.stdout.splitlines()
    assert len(lines) == 1, result.stdout
    assert "procedure host is" in lines[0] and "more than 150" in lines[0]


def test_a_long_separate_module_procedure_of_a_submodule_is_found(tmp_path):
    # the interface in the parent is not a body; the body in the submodule is measured, and a
    # generic interface's `module procedure` list is neither
    parent = ("module dkt_par\n  implicit none\n  interface\n    module subroutine p(x)\n"
              "      real, intent(inout) :: x\n    end subroutine p\n"
              "    module subroutine q(x)\n      real, intent(inout) :: x\n"
              "    end subroutine q\n  end interface\n  interface gen\n"
              "    module procedure r1, r2\n  end interface gen\nend module dkt_par\n")
    body = "".join(f"    x = x + {k}\n" for k in range(160))
    sub = ("submodule (dkt_par) dkt_par_impl\n  implicit none\ncontains\n"
           f"  module procedure p\n{body}  end procedure p\n"
           "  module procedure q\n    x = 1\n  end procedure q\nend submodule dkt_par_impl\n")
    (tmp_path / "dkt_par.f90").write_text(parent)
    (tmp_path / "dkt_par_impl.f90").write_text(sub)
    result = run(tmp_path)
    assert result.returncode == 1
    lines = result.stdout.splitlines()
    assert len(lines) == 1, result.stdout
    assert "dkt_par_impl.f90:4: procedure p is 162 lines" in lines[0]


def test_an_input_module_used_for_more_than_its_types_is_found(tmp_path):
    (tmp_path / "dkt_config.f90").write_text(module("dkt_config"))
    good = module("dkt_good", "  use dkt_config, only: config_t, COLLISION_MRT, lp => params_t\n")
    bad = module("dkt_bad", "  use dkt_config, only: config_t, &\n    kiss_thresholds\n"
                 "  use dkt_registry\n")
    main = ("program dktlbm\n  use dkt_config, only: config_load\n  use dkt_registry\n"
            "end program dktlbm\n")
    (tmp_path / "dkt_good.f90").write_text(good)
    (tmp_path / "dkt_bad.f90").write_text(bad)
    (tmp_path / "dktlbm.f90").write_text(main)
    result = run(tmp_path)
    assert result.returncode == 1
    lines = result.stdout.splitlines()
    assert len(lines) == 2, result.stdout
    assert "dkt_bad.f90:2:" in lines[0] and "'kiss_thresholds'" in lines[0]
    assert "dkt_bad.f90:4:" in lines[1] and "without 'only:'" in lines[1]


def test_an_empty_directory_is_an_error(tmp_path):
    assert run(tmp_path).returncode == 2
