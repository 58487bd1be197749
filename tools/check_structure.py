#!/usr/bin/env python3
"""Check the limits that keep the Fortran sources readable (docs/design.md, "Modules"):

- no source file over 800 lines;
- no procedure over 150 lines (a host procedure counts with the procedures it contains);
- no module outside the input layer uses an input module for anything but the types and
  named constants it is handed (names ending in ``_t``, or written in capitals); the main
  program, which reads the input and hands it on, is the one exception;
- every ``use`` of an input module names what it takes (``only:``).

Usage: check_structure.py [SRC_DIR]  (default: src/ beside this script's directory).
Prints one line per breach, ``file:line: what``, and exits 1 when there is any, else prints a
summary and exits 0.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

MAX_FILE_LINES = 800
MAX_PROCEDURE_LINES = 150

# The input layer: the modules that read, check and convert the input (docs/design.md).
INPUT_LAYER = re.compile(r"^dkt_(config\w*|cli|registry|namelist\w*|scene\w*|check_\w*|checks|"
                         r"units|lattice_units|input\w*)$")

_PREFIX = r"(?:(?:pure|impure|elemental|recursive|module|non_recursive|integer|logical|" \
          r"complex|real|double\s+precision|character|type|class)\b[^:]*?\s+)*"
START = re.compile(r"^\s*" + _PREFIX + r"(subroutine|function)\s+(\w+)", re.I)
END = re.compile(r"^\s*end\s*(subroutine|function|procedure)\b", re.I)
# a separate module procedure's body, in a submodule (outside an interface block)
MODULE_PROCEDURE = re.compile(r"^\s*module\s+procedure\s+(\w+)\s*$", re.I)
SUBMODULE = re.compile(r"^\s*submodule\s*\(\s*(\w+)[^)]*\)\s*(\w+)\s*$", re.I)
MODULE = re.compile(r"^\s*module\s+(\w+)\s*$", re.I)
PROGRAM = re.compile(r"^\s*program\s+(\w+)", re.I)
USE = re.compile(r"^\s*use\s*(?:,\s*\w+\s*)?(?:::)?\s*(\w+)\s*(,\s*only\s*:(.*))?$", re.I)


def statements(path: Path) -> list[tuple[int, str]]:
    """The statements of `path` as (number of their first line, text), without comments and
    with continuation lines joined."""
    out: list[tuple[int, str]] = []
    pending, first = "", 0
    for number, raw in enumerate(path.read_text(encoding="utf-8", errors="replace")
                                 .splitlines(), 1):
        text, quote = [], ""
        for ch in raw:
            if quote:
                if ch == quote:
                    quote = ""
                text.append(ch)
                continue
            if ch in "'\"":
                quote = ch
            elif ch == "!":
                break
            text.append(ch)
        line = "".join(text).strip()
        if pending:
            line = pending + " " + line.lstrip("&").lstrip()
        else:
            first = number
        if line.endswith("&"):
            pending = line[:-1].rstrip()
            continue
        pending = ""
        if line:
            for part in line.split(";"):
                if part.strip():
                    out.append((first, part.strip()))
    return out


def check_file(path: Path) -> list[str]:
    problems: list[str] = []
    raw_count = len(path.read_text(encoding="utf-8", errors="replace").splitlines())
    if raw_count > MAX_FILE_LINES:
        problems.append(f"{path}:1: {raw_count} lines, more than {MAX_FILE_LINES}")
    stack: list[tuple[str, int]] = []
    unit, unit_is_program, in_interface = "", False, 0
    for number, line in statements(path):
        low = line.lower()
        if re.match(r"^(abstract\s+)?interface\b", low):
            in_interface += 1
            continue
        if re.match(r"^end\s*interface\b", low):
            in_interface -= 1
            continue
        m = SUBMODULE.match(line)
        if m:
            # (a submodule is part of its parent: the parent's layer)
            unit, unit_is_program = m.group(1).lower(), False
            continue
        m = MODULE_PROCEDURE.match(line)
        if m and not in_interface:
            stack.append((m.group(1), number))
            continue
        m = MODULE.match(line)
        if m and not low.startswith("module procedure"):
            unit, unit_is_program = m.group(1).lower(), False
            continue
        m = PROGRAM.match(line)
        if m:
            unit, unit_is_program = m.group(1).lower(), True
            continue
        m = USE.match(line)
        if m:
            used = m.group(1).lower()
            if INPUT_LAYER.match(used) and not INPUT_LAYER.match(unit) and \
                    not unit_is_program:
                if not m.group(2):
                    problems.append(f"{path}:{number}: {unit} uses input module {used} "
                                    "without 'only:'")
                else:
                    for item in m.group(3).split(","):
                        name = item.split("=>")[-1].strip()
                        if name and not (name.lower().endswith("_t") or name.isupper()):
                            problems.append(
                                f"{path}:{number}: {unit} takes '{name}' from input module "
                                f"{used}; outside the input layer only types (*_t) and named "
                                "constants may be used")
            continue
        if in_interface:
            continue
        if END.match(line):
            if stack:
                name, start = stack.pop()
                length = number - start + 1
                if length > MAX_PROCEDURE_LINES:
                    problems.append(f"{path}:{start}: procedure {name} is {length} lines, "
                                    f"more than {MAX_PROCEDURE_LINES}")
            continue
        m = START.match(line)
        if m and not low.startswith("end"):
            stack.append((m.group(2), number))
    return problems


def main(argv: list[str]) -> int:
    src = Path(argv[1]) if len(argv) > 1 else Path(__file__).resolve().parent.parent / "src"
    files = sorted(src.glob("*.f90"))
    if not files:
        print(f"check_structure: no Fortran files in {src}", file=sys.stderr)
        return 2
    problems = [p for f in files for p in check_file(f)]
    for p in problems:
        print(p)
    if problems:
        print(f"check_structure: {len(problems)} breach(es) in {src}", file=sys.stderr)
        return 1
    print(f"check_structure: {len(files)} files within {MAX_FILE_LINES} lines, every "
          f"procedure within {MAX_PROCEDURE_LINES}, input modules used only for their types")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
