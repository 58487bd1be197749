"""input/README.md documents every input key exactly as `dktlbm --print-defaults` reports it.

`--print-defaults` prints the key registry that src/dkt_config_types.f90 builds (the one source
of defaults, units and ranges). For every key, the README table row and the printed line must
agree on the type, the unit, the default and the allowed values, and neither side may have a key
the other lacks. Numbers are compared by value (10 = 10.0 = 1.0e1), text after collapsing blanks.
The meaning column may say more than the one-line meaning and is not compared.

Environment: DKTLBM_EXE (default <repo>/build/dktlbm), DKTLBM_ROOT (default the repo).
"""

from __future__ import annotations

import os
import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(os.environ.get("DKTLBM_ROOT", Path(__file__).resolve().parents[1]))
EXE = Path(os.environ.get("DKTLBM_EXE", ROOT / "build" / "dktlbm"))
README = ROOT / "input" / "README.md"

HEADER = ["key", "type", "unit", "default", "allowed", "meaning"]
COMPARED = ["type", "unit", "default", "allowed"]

# A number not glued to a word (so the 3 of 'E3' and the 2 of 'x2' are not numbers).
NUMBER = re.compile(r"(?<![\w.])[-+]?(?:\d+\.?\d*|\.\d+)(?:[eEdD][-+]?\d+)?(?![\w.])")
# '  key = value   ! [unit] default: ..; allowed: ..; meaning'
LINE = re.compile(
    r"^\s*(?P<name>\w+)\s*=\s*(?P<value>.*?)\s*!\s*\[(?P<unit>[^\]]*)\]\s*"
    r"default:\s*(?P<default>.*?);\s*allowed:\s*(?P<allowed>.*?);\s*(?P<meaning>.*)$"
)

Entry = dict[str, str]
Table = dict[tuple[str, str], Entry]


def normalise(text: str) -> str:
    """Text as compared: no backticks, single blanks, every number in one canonical form."""
    text = " ".join(text.replace("`", "").split())
    return NUMBER.sub(lambda m: repr(float(m.group(0).replace("d", "e").replace("D", "e"))), text)


def value_type(value: str, allowed: str) -> str:
    """The type a namelist value is written as: quoted text, logical, integer or real."""
    if value[:1] in ("'", '"'):
        return "choice" if allowed.startswith("one of") else "string"
    if value.lower() in (".true.", ".false."):
        return "logical"
    first = value.split(",")[0].strip()
    if re.fullmatch(r"[-+]?\d+", first):
        return "integer"
    if NUMBER.fullmatch(first):
        return "real"
    raise ValueError(f"cannot tell the type of value {value!r}")


def split_values(value: str) -> list[str]:
    """The items of a namelist value list, split at the commas outside quotes."""
    items: list[str] = []
    current = ""
    quote = None
    for char in value:
        if quote:
            quote = None if char == quote else quote  # a doubled quote closes and reopens
        elif char in "'\"":
            quote = char
        elif char == ",":
            items.append(current.strip())
            current = ""
            continue
        current += char
    items.append(current.strip())
    return items


def parse_print_defaults(text: str) -> Table:
    """Keys of `dktlbm --print-defaults`; an array key is named key(n) as in the README."""
    table: Table = {}
    group = None
    for line in text.splitlines():
        stripped = line.strip()
        if not stripped or stripped.startswith("!"):
            continue
        if stripped.startswith("&"):
            group = stripped[1:].split()[0].lower()
            continue
        if stripped == "/":
            group = None
            continue
        match = LINE.match(line)
        assert group and match, f"--print-defaults line not understood: {line!r}"
        value = match["value"]
        n_values = len(split_values(value))
        key = match["name"].lower() + (f"({n_values})" if n_values > 1 else "")
        table[(group, key)] = {
            "type": value_type(value, match["allowed"]),
            "unit": match["unit"],
            "default": match["default"],
            "allowed": match["allowed"],
            "meaning": match["meaning"],
        }
    return table


def split_row(line: str) -> list[str]:
    return [cell.strip() for cell in line.strip().strip("|").split("|")]


def parse_readme(text: str) -> tuple[Table, list[str]]:
    """Rows of the tables under '### &group' headings, and what is malformed."""
    table: Table = {}
    problems: list[str] = []
    group = None
    header_seen = False
    for number, line in enumerate(text.splitlines(), start=1):
        heading = re.match(r"^#+\s*(.*)$", line)
        if heading:
            if group and not header_seen:
                problems.append(f"README: ### &{group} has no table with columns {HEADER}")
            named = re.fullmatch(r"###\s+&(\w+)\s*", line)
            group = named.group(1).lower() if named else None
            header_seen = False
            continue
        if group is None or not line.strip().startswith("|"):
            continue
        cells = split_row(line)
        if [c.lower() for c in cells] == HEADER:
            header_seen = True
            continue
        if all(re.fullmatch(r":?-+:?", c) for c in cells):
            continue
        if not header_seen or len(cells) != len(HEADER):
            problems.append(f"README line {number}: not a row of a {HEADER} table: {line!r}")
            continue
        key = cells[0].replace("`", "").strip().lower()
        if (group, key) in table:
            problems.append(f"README line {number}: &{group} {key} is documented twice")
        table[(group, key)] = dict(zip(HEADER[1:], cells[1:], strict=True))
    if group and not header_seen:
        problems.append(f"README: ### &{group} has no table with columns {HEADER}")
    return table, problems


def compare(readme: Table, program: Table) -> list[str]:
    """Every difference between the README tables and --print-defaults, one line each."""
    problems = []
    for group, key in sorted(program.keys() - readme.keys()):
        problems.append(f"&{group} {key}: printed by --print-defaults, missing from the README")
    for group, key in sorted(readme.keys() - program.keys()):
        problems.append(f"&{group} {key}: in the README, not a key of the program")
    for group, key in sorted(readme.keys() & program.keys()):
        for column in COMPARED:
            doc, real = readme[(group, key)][column], program[(group, key)][column]
            if normalise(doc) != normalise(real):
                problems.append(
                    f"&{group} {key}: {column} is {doc!r} in the README, "
                    f"{real!r} in --print-defaults"
                )
        if not readme[(group, key)]["meaning"].strip():
            problems.append(f"&{group} {key}: the README gives no meaning")
    return problems


@pytest.fixture(scope="module")
def printed() -> str:
    if not EXE.is_file():
        pytest.fail(f"{EXE} does not exist: build dktlbm first (or set DKTLBM_EXE)")
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    run = subprocess.run(
        [str(EXE), "--print-defaults"], capture_output=True, text=True, timeout=120, env=env
    )
    assert run.returncode == 0, f"dktlbm --print-defaults failed:\n{run.stderr}"
    return run.stdout


@pytest.fixture(scope="module")
def readme_text() -> str:
    return README.read_text(encoding="utf-8")


def test_readme_tables_are_well_formed(readme_text: str) -> None:
    table, problems = parse_readme(readme_text)
    assert not problems, "\n".join(problems)
    assert table, "input/README.md has no key table"


def test_readme_matches_print_defaults(readme_text: str, printed: str) -> None:
    program = parse_print_defaults(printed)
    assert program, "--print-defaults printed no key"
    readme, _ = parse_readme(readme_text)
    problems = compare(readme, program)
    assert not problems, "input/README.md and dktlbm --print-defaults differ:\n" + "\n".join(
        problems
    )


# The checker itself must catch each kind of drift, or the test above could never fail.


def _edit_row(text: str, key: str, replace: str | None) -> str:
    """README text with the first row of `key` replaced (None: removed)."""
    lines = text.splitlines()
    for i, line in enumerate(lines):
        if line.strip().startswith("|") and split_row(line)[0].strip("`") == key:
            if replace is None:
                del lines[i]
            else:
                lines[i] = replace
            return "\n".join(lines) + "\n"
    raise AssertionError(f"README has no row for {key}")


def _row(text: str, key: str) -> str:
    return next(line for line in text.splitlines() if split_row(line)[0].strip("`") == key)


def _problems(readme_text: str, printed: str) -> list[str]:
    readme, problems = parse_readme(readme_text)
    return problems + compare(readme, parse_print_defaults(printed))


def test_checker_catches_a_key_documented_but_not_in_the_program(
    readme_text: str, printed: str
) -> None:
    row = _row(readme_text, "tau")
    extra = row + "\n| `omega` | real | - | `1.0` | `omega > 0` | not a key |"
    problems = _problems(_edit_row(readme_text, "tau", extra), printed)
    assert any("omega" in p and "not a key of the program" in p for p in problems), problems


def test_checker_catches_a_key_missing_from_the_readme(readme_text: str, printed: str) -> None:
    problems = _problems(_edit_row(readme_text, "tau", None), printed)
    assert any("tau" in p and "missing from the README" in p for p in problems), problems


@pytest.mark.parametrize(
    ("column", "value"),
    [("type", "integer"), ("unit", "cm"), ("default", "`0.66`"), ("allowed", "`tau > 0.5`")],
)
def test_checker_catches_a_changed_column(
    readme_text: str, printed: str, column: str, value: str
) -> None:
    row = _row(readme_text, "tau")
    cells = split_row(row)
    cells[HEADER.index(column)] = value
    problems = _problems(_edit_row(readme_text, "tau", "| " + " | ".join(cells) + " |"), printed)
    assert any(f"tau: {column}" in p for p in problems), problems


def test_array_keys_are_named_with_their_size() -> None:
    """Lists of numbers and of quoted choices are arrays; a comma inside a string is not."""
    printed = "\n".join(
        [
            "&g",
            "  a = 1.0, 2.0 ! [cm] default: 0.0, 0.0; allowed: any; numbers",
            "  m = 'free', 'fixed' ! [-] default: 'free', 'free'; allowed: one of 'free', "
            "'fixed'; choices",
            "  s = 'a, b' ! [-] default: ''; allowed: text of at most 9 characters; one string",
            "  q = 'it''s, ok', 'x' ! [-] default: 'x', 'x'; allowed: one of 'x'; doubled quote",
            "/",
        ]
    )
    table = parse_print_defaults(printed)
    assert set(table) == {("g", "a(2)"), ("g", "m(2)"), ("g", "s"), ("g", "q(2)")}, table
    assert table[("g", "m(2)")]["type"] == "choice"
    assert table[("g", "s")]["type"] == "string"


def test_numbers_compare_by_value_and_text_exactly() -> None:
    assert normalise("`0.5 < tau <= 10`") == normalise("0.5 <  tau <= 10.0")
    assert normalise("1.0e-3, 2") == normalise("0.001, 2.0")
    assert normalise("0.5 < tau <= 10") != normalise("0.5 < tau <= 11")
    assert normalise("tau > 0") != normalise("tau >= 0")
    assert normalise("s_e") == "s_e" and normalise("(E3)") == "(E3)"
