"""The module graph of docs/design.md ("Modules") is the graph of the `use` statements in src/.

What this proves:

- the table `| layer | module | uses | holds |` names every module (and the main program) of
  src/*.f90 and src/*.f90.in, and no other, each with exactly the project modules it uses,
  read from the sources (`use, intrinsic ::`, `only:` lists, continuation lines, comments and
  submodules handled; mpi_f08, hdf5 and the intrinsic modules left out);
- the layers point one way: every use goes to a module of the same layer or a lower one, and
  within a layer to a row above;
- the layer drawing (the mermaid block) has exactly the arrows the table gives, and the table's
  `input` layer is the input layer of tools/check_structure.py (INPUT_LAYER);
- the checker can fail: a design.md with a use left out, a module missing, a module put in too
  low a layer, rows out of order, a layer split in two, an arrow missing or the input layer
  changed, and a source with one more use, are each reported by name.
"""

from __future__ import annotations

import importlib.util
import os
import re
import shutil
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(os.environ.get("DKTLBM_ROOT", Path(__file__).resolve().parent.parent))
SRC = ROOT / "src"
DESIGN = ROOT / "docs" / "design.md"


def _load_check_structure():
    spec = importlib.util.spec_from_file_location("check_structure",
                                                  ROOT / "tools" / "check_structure.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


CHECK_STRUCTURE = _load_check_structure()

UNIT = re.compile(r"^(?:module|program)\s+(\w+)$", re.I)
SUBMODULE = re.compile(r"^submodule\s*\(\s*(\w+)\s*(?::\s*\w+\s*)?\)\s*\w+$", re.I)
USE = re.compile(r"^use\b\s*(?:,\s*(?:non_)?intrinsic\s*)?(?:::)?\s*(\w+)", re.I)
SPLIT_CELLS = re.compile(r"(?<!\\)\|")


# ---------------------------------------------------------------- the sources


def source_files(src: Path) -> list[Path]:
    return sorted([*src.glob("*.f90"), *src.glob("*.f90.in")])


def unit_uses(path: Path) -> dict[str, set[str]]:
    """Each program unit of `path` with the modules it uses; a submodule's uses count as its
    module's. Statements come from check_structure's reader: comments stripped, continuation
    lines joined."""
    uses: dict[str, set[str]] = {}
    unit = None
    for _, statement in CHECK_STRUCTURE.statements(path):
        start = UNIT.match(statement) or SUBMODULE.match(statement)
        if start:
            unit = start.group(1).lower()
            uses.setdefault(unit, set())
            continue
        use = USE.match(statement)
        if use and unit:
            uses[unit].add(use.group(1).lower())
    return uses


def source_graph(src: Path) -> dict[str, set[str]]:
    """Module -> the project modules it uses: those defined in `src`, so that mpi_f08, hdf5
    and the intrinsic modules drop out."""
    graph: dict[str, set[str]] = {}
    for path in source_files(src):
        for unit, used in unit_uses(path).items():
            graph.setdefault(unit, set()).update(used)
    return {unit: used & graph.keys() for unit, used in graph.items()}


# ---------------------------------------------------------------- docs/design.md


@dataclass
class Row:
    layer: str
    module: str
    uses: set[str]


def modules_section(markdown: str) -> str:
    match = re.search(r"^## Modules\n(.*?)(?=^## )", markdown, re.S | re.M)
    assert match, "docs/design.md has no section '## Modules'"
    return match.group(1)


def cells(line: str) -> list[str]:
    return [c.strip() for c in SPLIT_CELLS.split(line.strip().strip("|"))]


def table_rows(markdown: str) -> list[Row]:
    """The rows of the table headed | layer | module | uses | ... in section Modules."""
    lines = modules_section(markdown).splitlines()
    head = next((k for k, line in enumerate(lines) if line.startswith("|")
                 and cells(line)[:3] == ["layer", "module", "uses"]), None)
    assert head is not None, "Modules: no table headed | layer | module | uses |"
    rows = []
    for line in lines[head + 2:]:
        if not line.startswith("|"):
            break
        layer, module, uses = cells(line)[:3]
        rows.append(Row(layer, re.findall(r"\w+", module)[0], set(re.findall(r"\bdkt_\w+", uses))))
    return rows


def mermaid_edges(markdown: str) -> set[tuple[str, str]]:
    block = re.search(r"^```mermaid\n(.*?)^```", modules_section(markdown), re.S | re.M)
    assert block, "Modules: no mermaid block of the layers"
    return set(re.findall(r"^\s*(\w+)\s*-->\s*(\w+)\s*$", block.group(1), re.M))


# ---------------------------------------------------------------- the checks


def layer_order(rows: list[Row]) -> list[str]:
    """The layers from the bottom up, as the table lists them."""
    return list(dict.fromkeys(row.layer for row in rows))


def split_layers(rows: list[Row]) -> list[str]:
    """A layer's rows stand together, or the table does not say which layer is lower."""
    runs = [row.layer for k, row in enumerate(rows) if k == 0 or rows[k - 1].layer != row.layer]
    return [f"layer {layer}: its rows are not together" for layer in layer_order(rows)
            if runs.count(layer) > 1]


def graph_differences(src: dict[str, set[str]], doc: dict[str, set[str]]) -> list[str]:
    problems = [f"{m}: in src/ but not in docs/design.md" for m in sorted(src.keys() - doc)]
    problems += [f"{m}: in docs/design.md but not in src/" for m in sorted(doc.keys() - src)]
    for m in sorted(src.keys() & doc.keys()):
        problems += [f"{m} uses {u} in src/; docs/design.md does not list it"
                     for u in sorted(src[m] - doc[m])]
        problems += [f"{m} uses {u} in docs/design.md; src/ does not"
                     for u in sorted(doc[m] - src[m])]
    return problems


def upward_uses(rows: list[Row]) -> list[str]:
    """Uses of a module in a higher layer, or in a row below within the same layer."""
    level = {layer: k for k, layer in enumerate(layer_order(rows))}
    place = {row.module: k for k, row in enumerate(rows)}
    layer_of = {row.module: row.layer for row in rows}
    problems = []
    for row in rows:
        for used in sorted(row.uses & place.keys()):
            if level[layer_of[used]] > level[row.layer]:
                problems.append(f"{row.module} (layer {row.layer}) uses {used} of the higher "
                                f"layer {layer_of[used]}")
            elif place[used] > place[row.module]:
                problems.append(f"{row.module} uses {used}, which stands below it in layer "
                                f"{row.layer}")
    return problems


def drawing_differences(rows: list[Row], drawn: set[tuple[str, str]]) -> list[str]:
    layer_of = {row.module: row.layer for row in rows}
    table = {(row.layer, layer_of[u]) for row in rows for u in row.uses & layer_of.keys()
             if layer_of[u] != row.layer}
    return ([f"layer drawing: no arrow {a} --> {b}" for a, b in sorted(table - drawn)] +
            [f"layer drawing: arrow {a} --> {b}, which no use gives"
             for a, b in sorted(drawn - table)])


def input_layer_differences(rows: list[Row], modules: set[str]) -> list[str]:
    doc = {row.module for row in rows if row.layer == "input"}
    tool = {m for m in modules if CHECK_STRUCTURE.INPUT_LAYER.match(m)}
    return ([f"{m}: INPUT_LAYER of tools/check_structure.py, not layer input" for m in
             sorted(tool - doc)] +
            [f"{m}: layer input, not INPUT_LAYER of tools/check_structure.py" for m in
             sorted(doc - tool)])


def problems(src: Path, design: Path) -> list[str]:
    markdown = design.read_text(encoding="utf-8")
    rows = table_rows(markdown)
    graph = source_graph(src)
    doc = {row.module: row.uses for row in rows}
    return (split_layers(rows) + graph_differences(graph, doc) + upward_uses(rows) +
            drawing_differences(rows, mermaid_edges(markdown)) +
            input_layer_differences(rows, set(graph)))


# ---------------------------------------------------------------- the tests


def test_design_md_draws_the_graph_of_the_sources():
    found = problems(SRC, DESIGN)
    assert not found, "docs/design.md, Modules, against src/:\n" + "\n".join(found)


def test_the_table_holds_every_layer_and_module():
    rows = table_rows(DESIGN.read_text(encoding="utf-8"))
    assert layer_order(rows) == ["base", "solver", "io", "input", "run", "driver"]
    assert {"dkt_kinds", "dkt_version", "dktlbm"} <= {row.module for row in rows}


def test_the_reader_finds_every_form_of_use(tmp_path):
    (tmp_path / "dkt_a.f90").write_text(
        "! use dkt_c in a comment\n"
        "module dkt_a\n"
        "  use, intrinsic :: iso_fortran_env, only: int64\n"
        "  use mpi_f08, only: MPI_Comm\n"
        "  use :: dkt_b, only: x, & ! a comment after a continuation\n"
        "                      y\n"
        "  use &\n"
        "    dkt_d\n"
        "  implicit none\n"
        "  character(len=*), parameter :: s = 'use dkt_c' ! use dkt_c\n"
        "  interface\n"
        "    module subroutine p()\n"
        "    end subroutine p\n"
        "  end interface\n"
        "contains\n"
        "  subroutine q()\n"
        "    use dkt_e, only: z\n"
        "  end subroutine q\n"
        "end module dkt_a\n")
    (tmp_path / "dkt_a_impl.f90").write_text(
        "submodule (dkt_a) dkt_a_impl\n  use dkt_f\ncontains\n"
        "  module procedure p\n  end procedure p\nend submodule dkt_a_impl\n")
    for name in "bcdef":
        (tmp_path / f"dkt_{name}.f90").write_text(f"module dkt_{name}\nend module dkt_{name}\n")
    (tmp_path / "dkt_g.f90.in").write_text(
        "module dkt_g\n  use, non_intrinsic :: dkt_b\nend module dkt_g\n")
    (tmp_path / "main.f90").write_text("program main\n  use dkt_g\nend program main\n")
    graph = source_graph(tmp_path)
    assert graph["dkt_a"] == {"dkt_b", "dkt_d", "dkt_e", "dkt_f"}
    assert graph["dkt_g"] == {"dkt_b"}
    assert graph["main"] == {"dkt_g"}
    assert "dkt_a_impl" not in graph and "p" not in graph


# The checker fails: each test breaks design.md or a source in a copy and reads the message.


def broken_design(tmp_path: Path, old: str, new: str) -> Path:
    text = DESIGN.read_text(encoding="utf-8")
    assert text.count(old) == 1, f"docs/design.md: {old!r} is not there once"
    path = tmp_path / "design.md"
    path.write_text(text.replace(old, new), encoding="utf-8")
    return path


def row_of(module: str) -> str:
    return next(line for line in DESIGN.read_text(encoding="utf-8").splitlines()
                if line.startswith("|") and cells(line)[1:2] == [f"`{module}`"])


def test_a_use_left_out_of_the_table_is_named(tmp_path):
    row = row_of("dkt_config_lattice")
    design = broken_design(tmp_path, row, row.replace(" dkt_lattice,", ""))
    assert problems(SRC, design) == ["dkt_config_lattice uses dkt_lattice in src/; "
                                     "docs/design.md does not list it",
                                     "layer drawing: arrow input --> solver, which no use gives"]


def test_a_module_missing_from_the_table_is_named(tmp_path):
    design = broken_design(tmp_path, row_of("dkt_cells") + "\n", "")
    found = problems(SRC, design)
    assert "dkt_cells: in src/ but not in docs/design.md" in found, found


def test_a_module_in_too_low_a_layer_is_named(tmp_path):
    # dkt_simulation moved to the end of the input layer: it uses dkt_run_state and dkt_memory
    row = row_of("dkt_simulation")
    last_input = row_of("dkt_config_restart")
    text = DESIGN.read_text(encoding="utf-8").replace(row + "\n", "")
    text = text.replace(last_input, last_input + "\n" + row.replace("| run |", "| input |", 1))
    design = tmp_path / "design.md"
    design.write_text(text, encoding="utf-8")
    found = problems(SRC, design)
    for used in ("dkt_memory", "dkt_run_state"):
        assert (f"dkt_simulation (layer input) uses {used} of the higher layer run"
                in found), found


def test_rows_out_of_order_within_a_layer_are_named(tmp_path):
    kinds, text = row_of("dkt_kinds"), row_of("dkt_text")
    design = broken_design(tmp_path, kinds + "\n", "")
    design.write_text(design.read_text().replace(text, text + "\n" + kinds), encoding="utf-8")
    found = problems(SRC, design)
    assert "dkt_text uses dkt_kinds, which stands below it in layer base" in found, found


def test_a_layer_split_in_two_is_named(tmp_path):
    # dkt_version, which uses nothing, after the last solver row
    version, last_solver = row_of("dkt_version"), row_of("dkt_diagnostics")
    design = broken_design(tmp_path, version + "\n", "")
    design.write_text(design.read_text().replace(last_solver, last_solver + "\n" + version),
                      encoding="utf-8")
    assert problems(SRC, design) == ["layer base: its rows are not together"]


def test_an_arrow_missing_from_the_drawing_is_named(tmp_path):
    design = broken_design(tmp_path, "  io --> solver\n", "")
    assert problems(SRC, design) == ["layer drawing: no arrow io --> solver"]


def test_the_input_layer_follows_check_structure(tmp_path):
    # the last input row as the first run row: the layers stay together and point one way
    row = row_of("dkt_config_restart")
    design = broken_design(tmp_path, row, row.replace("| input |", "| run |", 1))
    assert problems(SRC, design) == ["dkt_config_restart: INPUT_LAYER of "
                                     "tools/check_structure.py, not layer input"]


def test_a_use_added_to_a_source_is_named(tmp_path):
    src = tmp_path / "src"
    shutil.copytree(SRC, src)
    kinds = src / "dkt_kinds.f90"
    text = kinds.read_text(encoding="utf-8")
    head = re.search(r"^module dkt_kinds\n", text, re.M).end()
    kinds.write_text(text[:head] + "  use dkt_run, only: run_t\n" + text[head:], encoding="utf-8")
    assert problems(src, DESIGN) == ["dkt_kinds uses dkt_run in src/; "
                                     "docs/design.md does not list it"]
