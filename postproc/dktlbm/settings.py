"""What a run's input says, for what its run file does not store: the namelist text (a parser
that follows input/README.md) and what the dktlbm executable makes of it.

Run files since dktlbm 0.1.0 store the scales and the kissing thresholds the run used as /run
attributes, and dktlbm.read takes them from there. For a file written before (or a value the
file does not hold), RunSettings gives the stored namelist's value, else the program's
(`dktlbm FILE --print-defaults`), and kiss_cells the thresholds in spacings as
`dktlbm --check` reports them: the program's rules and defaults are asked for, never copied
here. The sweeps (dkt-sweep) read and edit scene files with the same parser.
"""

from __future__ import annotations

import functools
import math
import re
import subprocess
import tempfile
from pathlib import Path

from .launch import LaunchError, exe, mpi_env

# ---------------------------------------------------------------- namelist text

_TOKEN = re.compile(r"""'(?:[^']|'')*'|"(?:[^"]|"")*"|&\w+|/|=|,|[^\s,=/'"]+""")
_KEY = re.compile(r"^([A-Za-z_]\w*)(?:\((\d+)\))?$")


def _strip_comment(line: str) -> str:
    quote = ""
    for i, ch in enumerate(line):
        if quote:
            if ch == quote:
                quote = ""
        elif ch in "'\"":
            quote = ch
        elif ch == "!":
            return line[:i]
    return line


def _unquote(token: str) -> str:
    if len(token) >= 2 and token[0] == token[-1] and token[0] in "'\"":
        q = token[0]
        return token[1:-1].replace(q + q, q)
    return token


def parse_namelist(text: str) -> dict[str, dict[str, list[str]]]:
    """Namelist text as {group: {key: [values as text]}}, group and key names in lower case.
    `key(2) = v` sets element 2; a key given twice keeps the last value; strings unquoted."""
    tokens: list[str] = []
    for line in text.splitlines():
        tokens += _TOKEN.findall(_strip_comment(line))
    groups: dict[str, dict[str, list[str]]] = {}
    group: dict[str, list[str]] | None = None
    key: str | None = None
    index = 0
    i = 0
    while i < len(tokens):
        tok = tokens[i]
        nxt = tokens[i + 1] if i + 1 < len(tokens) else ""
        low = tok.lower()
        if low.startswith("&") and low != "&end":
            group = groups.setdefault(low[1:], {})
            key = None
        elif tok == "/" or low == "&end":
            group, key = None, None
        elif group is not None and nxt == "=" and _KEY.match(tok):
            m = _KEY.match(tok)
            assert m is not None
            key = m.group(1).lower()
            index = int(m.group(2)) - 1 if m.group(2) else 0
            if m.group(2) is None or key not in group:
                group[key] = [] if m.group(2) is None else group.get(key, [])
            i += 1  # the '='
        elif group is not None and key is not None and tok not in (",", "="):
            values = group[key]
            while len(values) <= index:
                values.append("")
            values[index] = _unquote(tok)
            index += 1
        elif tok == "," and group is not None and key is not None and nxt == ",":
            index += 1  # an empty item leaves its element unchanged
        i += 1
    return groups


def fortran_float(text: str) -> float:
    """A Fortran real literal (1.5, 2e3, 1.0d-2) as a float; ValueError when it is not one."""
    return float(text.lower().replace("d", "e"))


def nml_float(nml: dict[str, dict[str, list[str]]], group: str, key: str, default: float,
              index: int = 0) -> float:
    """Element `index` of `&group key` as a number, or `default` when absent or not a number."""
    values = nml.get(group, {}).get(key, [])
    if index < len(values) and values[index] != "":
        try:
            return fortran_float(values[index])
        except ValueError:
            return default
    return default


def nml_floats(nml: dict[str, dict[str, list[str]]], group: str, key: str) -> list[float]:
    out = []
    for v in nml.get(group, {}).get(key, []):
        try:
            out.append(fortran_float(v))
        except ValueError:
            out.append(math.nan)
    return out


# ---------------------------------------------------------------- the program's settings

def _dktlbm(args: list[str], scene: str | None, what: str) -> str:
    """stdout of `dktlbm [SCENE] args`, SCENE being namelist text written to a scratch file;
    LaunchError with the program's message when it cannot run or refuses."""
    program = exe()
    with tempfile.TemporaryDirectory(prefix="dktlbm-") as tmp:
        command = [program, *args]
        if scene is not None:
            path = Path(tmp) / "scene.nml"
            path.write_text(scene)
            command.insert(1, str(path))
        try:
            proc = subprocess.run(command, capture_output=True, text=True, cwd=tmp,
                                  env=mpi_env(), timeout=120)
        except (OSError, subprocess.TimeoutExpired) as exc:
            raise LaunchError(f"cannot run {program} for {what}: {exc}") from None
    if proc.returncode != 0:
        message = (proc.stderr.strip() or proc.stdout.strip()).splitlines()
        raise LaunchError(f"{program} refused {what} (exit status {proc.returncode}): "
                          f"{message[-1] if message else 'no message'}")
    return proc.stdout


def _overlay(values: list[str], given: list[str]) -> list[str]:
    """`values` with each element that `given` sets (not '') in its place."""
    out = list(values)
    for i, v in enumerate(given):
        if v != "":
            out.extend([""] * (i + 1 - len(out)))
            out[i] = v
    return out


@functools.cache
def program_settings(text: str | None = None) -> dict[str, dict[str, list[str]]]:
    """Every input key as dktlbm makes it of the namelist `text` (None: its defaults), from
    `dktlbm FILE --print-defaults`: {group: {key: [values as text]}}. When the program
    refuses the text (a scene it does not accept as a whole), its defaults with the text's
    own values over them. LaunchError when the executable (dktlbm.launch.exe) cannot say."""
    if text is not None:
        try:
            return parse_namelist(_dktlbm(["--print-defaults"], text, "the stored namelist"))
        except LaunchError:
            merged = {g: dict(keys) for g, keys in program_settings(None).items()}
            for group, keys in parse_namelist(text).items():
                into = merged.setdefault(group, {})
                for key, values in keys.items():
                    into[key] = _overlay(into.get(key, []), values)
            return merged
    return parse_namelist(_dktlbm(["--print-defaults"], None, "--print-defaults"))


_KISS_LINE = re.compile(r"kissing episode starts at D_r <=\s*([0-9.]+) spacings and ends at "
                        r"D_r >\s*([0-9.]+) spacings")


@functools.cache
def kiss_cells(enter_cells: float, release_cells: float,
               collision_range: float) -> tuple[float, float]:
    """The kissing thresholds in lattice spacings that dktlbm uses for &diagnostics
    enter_cells, release_cells and &collision range (enter_cells = 0 stands for a rule of the
    program's), as `dktlbm --check` reports them for a probe pair with enter_d1 = release_d1
    = 0. LaunchError when the executable cannot say."""
    probe = "&particles\n  count = 2, x = 0.5, 1.5, y = 2.5, 2.5\n/\n"
    sets = {"collision.range": collision_range, "diagnostics.enter_cells": enter_cells,
            "diagnostics.release_cells": release_cells, "diagnostics.enter_d1": 0.0,
            "diagnostics.release_d1": 0.0}
    with tempfile.TemporaryDirectory(prefix="dktlbm-") as out:
        args = ["--check", "--set", f"output.dir={out}/run"]
        for key, value in sets.items():
            args += ["--set", f"{key}={value!r}"]
        report = _dktlbm(args, probe, "the kissing-threshold probe")
    found = _KISS_LINE.search(report)
    if found is None:
        raise LaunchError("dktlbm --check printed no kissing thresholds for a probe pair")
    return float(found.group(1)), float(found.group(2))


class RunSettings:
    """The input of a run: the namelist text stored in /run, and for the keys it does not give
    what dktlbm makes of it (program_settings, asked once and only when needed)."""

    def __init__(self, text: str) -> None:
        self.text = text
        self.given = parse_namelist(text)

    def values(self, group: str, key: str) -> list[str]:
        """The values of `&group key` as text, element by element: the namelist's, else the
        program's."""
        given = self.given.get(group, {}).get(key, [])
        if given and all(v != "" for v in given):
            return given
        merged = _overlay(program_settings(self.text).get(group, {}).get(key, []), given)
        if not merged:
            raise LaunchError(f"dktlbm knows no input key {group}.{key}")
        return merged

    def number(self, group: str, key: str, index: int = 0) -> float:
        """Element `index` of `&group key` as a number (the last element for an index past
        the end: a default array shorter than the particle count)."""
        values = self.values(group, key)
        return fortran_float(values[min(index, len(values) - 1)])
