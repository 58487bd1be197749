#!/usr/bin/env python3
"""Scene files of many settling disks for dktlbm (docs/suspensions.md).

Writes one namelist scene of a suspension settling in a closed box (walls on all four
sides), in the physical units of every scene (cm, g, s), with the arrangement rule and the
literature set-up in its comment header:

- ``sediment504``: the 504 disks of Glowinski, Pan, Hesla, Joseph & Périaux (2001) in a
  closed 2 cm x 2 cm cavity, D = 0.0625 cm, rho_p = 1.01 g/cm^3, water (rho_f = 1 g/cm^3,
  nu = 0.01 cm^2/s), released at rest in a regular lattice under the lid;
- ``sediment504_dense``: the same 504 disks in the denser lattice of an independent
  reproduction of the test (18 rows of 28, 1.125 D apart, above 0.72 cm of clear fluid); its
  gaps of 0.125 D need 24 spacings per D with a contact range of 2;
- ``bidisperse``: 256 disks of two sizes (D = 0.125 and 0.0625 cm, ratio 2) alternating on a
  square lattice (a checkerboard) under the lid of a closed 2 cm x 6 cm box;
- ``sediment10k``: 10 032 disks of the 504-disk scene's size and density in the same lattice
  under the lid of a closed 4 cm x 24 cm box (at least 10 000 disks).

The lattice spacing is set by ``&lbm cells_per_diameter`` (the spacings across the smallest
disk, 10 by default); the arrangement does not depend on it. The fluid starts with the pressure
that holds up the disks' weight less buoyancy (``&initial pressure = 'hydrostatic'``), so that
the closed box does not ring when they start to fall, and a bulk viscosity ten times the
shear viscosity (``&lbm s_e = 0.5``) damps what sound remains. The scenes take the lubrication
correction (E13, ``&collision lubrication``; ``--no-lubrication`` leaves it out) and a contact
range (``&collision range``) of half a spacing, or ``--range``, so that a bed packs as close as
its disks allow (docs/suspensions.md). Every gap between two disk surfaces, and between a disk
and a wall, is at least one spacing plus the contact range. The script refuses a resolution
that is too coarse for this and names the smallest that works.

    python3 tools/suspension_scene.py --kind sediment504 --out input/sediment504.nml
    python3 tools/suspension_scene.py --kind bidisperse --out input/bidisperse.nml
    python3 tools/suspension_scene.py --kind sediment10k --out /tmp/sediment10k.nml
    python3 tools/suspension_scene.py --kind sediment504 --cells-per-diameter 16 --out s.nml

The first two files are kept in input/; the 10k scene is written on demand (its file holds
20 064 coordinates), e.g. then ``build/dktlbm /tmp/sediment10k.nml --check``.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass, replace
from pathlib import Path

KINDS = ("sediment504", "sediment504_dense", "bidisperse", "sediment10k")
RANGE = 0.5  # &collision range, in lattice spacings, the default (docs/suspensions.md)
TAU = 0.65  # the shipped particle scenes' relaxation time
S_E = 0.5  # &lbm s_e: the bulk rate of the suspension scenes (docs/suspensions.md, no ringing)
GRAVITY = 980.0  # cm/s^2
RHO_F = 1.0  # g/cm^3
MU = 0.01  # g/(cm s): nu = 0.01 cm^2/s
RHO_P = 1.01  # g/cm^3
D_SMALL = 0.0625  # cm, the disk of Glowinski et al. (2001)
GAP = 0.025  # cm, the surface gap of the arrangements: 0.4 D_SMALL, 3.2 spacings at 8 per D
DIGITS = 6  # decimals of the written centres (cm)

GLOWINSKI = (
    "R. Glowinski, T.W. Pan, T.I. Hesla, D.D. Joseph, J. Periaux, A fictitious domain approach",
    "to the direct numerical simulation of incompressible viscous flow past moving rigid",
    "bodies: application to particulate flow, J. Comput. Phys. 169 (2001) 363-426.",
)


@dataclass
class Disk:
    """One disk: centre (cm), diameter (cm) and density (g/cm^3)."""

    x: float
    y: float
    d: float
    rho: float = RHO_P


@dataclass
class Scene:
    """What one scene file holds."""

    name: str
    header: list[str]
    width: float
    height: float
    disks: list[Disk]
    t_end: float
    series_interval: float
    field_interval: float
    progress_every: int
    cells_per_diameter: float = 10.0
    contact_range: float = RANGE
    lubrication: bool = True


def nint(value: float) -> int:
    """Fortran's nint for the positive values used here (halves away from zero)."""
    return math.floor(value + 0.5)


def spacing(width: float, d_min: float, cells_per_diameter: float) -> float:
    """The lattice spacing dktlbm derives from &lbm cells_per_diameter: width over the
    nearest whole number of cells across the box (src/dkt_config_scene.f90, expand)."""
    return width / max(3, nint(width * cells_per_diameter / d_min))


def per_row(width: float, d: float, gap: float) -> int:
    """How many disks of diameter ``d`` a row of the hexagonal lattice holds across a box
    ``width`` wide, with ``gap`` between neighbours and to both walls when every second row is
    shifted by half a pitch."""
    return math.floor((width - d - 2.0 * gap) / (d + gap) - 0.5) + 1


def hexagonal(width: float, height: float, d: float, gap: float, columns: int,
              rows: int) -> list[Disk]:
    """``rows`` x ``columns`` disks of diameter ``d`` on a hexagonal lattice under the lid.

    Neighbours' centres are d + gap apart; rows are (d + gap) sqrt(3)/2 apart and every second
    row (counting from the top) is shifted right by half a pitch. The block is centred across
    the box and the top row's surfaces are ``gap`` below the lid."""
    if columns > per_row(width, d, gap):
        raise ValueError(f"{columns} disks of diameter {d} do not fit across {width} cm")
    pitch = d + gap
    rise = pitch * math.sqrt(3.0) / 2.0
    x0 = 0.5 * (width - (columns - 0.5) * pitch)
    y_top = height - gap - 0.5 * d
    return [Disk(x0 + (0.5 * pitch if j % 2 else 0.0) + i * pitch, y_top - j * rise, d)
            for j in range(rows) for i in range(columns)]


def checkerboard(width: float, height: float, d_large: float, d_small: float, gap: float,
                 columns: int, rows: int) -> list[Disk]:
    """``columns`` x ``rows`` disks on a square lattice under the lid, large and small
    alternating along every row and every column (a checkerboard, the large disk in the top
    left corner). Neighbours along a row or column are a large and a small disk whose
    surfaces are ``gap`` apart (pitch (d_large + d_small)/2 + gap); two large disks are
    diagonal neighbours. The block is centred across the box and the top row's large disks
    are ``gap`` below the lid."""
    pitch = 0.5 * (d_large + d_small) + gap
    x0 = 0.5 * (width - (columns - 1) * pitch)
    y_top = height - gap - 0.5 * d_large
    disks = []
    for j in range(rows):
        for i in range(columns):
            d = d_large if (i + j) % 2 == 0 else d_small
            disks.append(Disk(x0 + i * pitch, y_top - j * pitch, d))
    return disks


def rounded(disks: list[Disk]) -> list[Disk]:
    """The disks with their centres as written in the file."""
    return [Disk(round(k.x, DIGITS), round(k.y, DIGITS), k.d, k.rho) for k in disks]


def smallest_gaps(disks: list[Disk], width: float, height: float) -> tuple[float, float]:
    """The smallest surface gap between two disks and between a disk and a wall (cm). Pairs
    are found in a grid of cells one largest diameter plus a margin wide, so that 10 000 disks
    take a fraction of a second."""
    wall = min(min(k.x, width - k.x, k.y, height - k.y) - 0.5 * k.d for k in disks)
    size = max(k.d for k in disks) + 4.0 * GAP
    cells: dict[tuple[int, int], list[int]] = {}
    for n, k in enumerate(disks):
        cells.setdefault((int(k.x // size), int(k.y // size)), []).append(n)
    pair = math.inf
    for n, k in enumerate(disks):
        ci, cj = int(k.x // size), int(k.y // size)
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                for m in cells.get((ci + di, cj + dj), ()):
                    if m > n:
                        o = disks[m]
                        gap = math.hypot(k.x - o.x, k.y - o.y) - 0.5 * (k.d + o.d)
                        pair = min(pair, gap)
    return pair, wall


def gaps_at(scene: Scene) -> tuple[float, float, float, float]:
    """The spacing at the scene's resolution, the smallest gaps between disks and to a wall,
    and the gap the rule asks for (one spacing plus the contact range), all in cm."""
    dx = spacing(scene.width, min(k.d for k in scene.disks), scene.cells_per_diameter)
    pair, wall = smallest_gaps(scene.disks, scene.width, scene.height)
    return dx, pair, wall, (1.0 + scene.contact_range) * dx


def satisfied(gap: float, need: float) -> bool:
    """Whether a gap meets the rule, within 10^-5 cm (the written centres are rounded to
    10^-6 cm)."""
    return gap >= need - 1e-5


def check(scene: Scene) -> list[str]:
    """Check the rule of the arrangement at the scene's resolution; return the lines that
    report it, or raise ValueError naming the smallest resolution that satisfies it."""
    dx, pair, wall, need = gaps_at(scene)
    for length, key in ((scene.width, "width"), (scene.height, "height")):
        cells = length / dx
        if abs(cells - round(cells)) > 1e-6 * cells:
            raise ValueError(f"{key} {length} cm is not a whole number of spacings dx = {dx} cm")
    if not satisfied(min(pair, wall), need):
        d_min = min(k.d for k in scene.disks)
        least = math.floor(100.0 * scene.cells_per_diameter) / 100.0
        while not satisfied(min(pair, wall),
                            (1.0 + scene.contact_range) * spacing(scene.width, d_min, least)):
            least = round(least + 0.01, 2)
        raise ValueError(
            f"{scene.name}: the smallest surface gap ({min(pair, wall):.6f} cm) is below one "
            f"spacing plus the contact range ({need:.6f} cm = {1 + scene.contact_range:g} dx, "
            f"dx = {dx:.6g} cm "
            f"at {scene.cells_per_diameter:g} per D); use --cells-per-diameter {least:g} "
            f"or more")
    return [
        f"Lattice at {scene.cells_per_diameter:g} spacings per smallest D: dx = {dx:.7g} cm, "
        f"{nint(scene.width / dx)} x {nint(scene.height / dx)} cells.",
        f"Smallest surface gaps: {pair:.6f} cm between disks, {wall:.6f} cm to a wall",
        f"(at least {need:.6f} cm = {1 + scene.contact_range:g} dx: one spacing plus the contact "
        f"range of {scene.contact_range:g} spacings).",
    ]


def sediment504(cells_per_diameter: float) -> Scene:
    """The 504-disk cavity of Glowinski et al. (2001)."""
    width = height = 2.0
    across, rows = 21, 24  # 504 in full rows (22 would fit across, but 504 = 21 x 24)
    disks = hexagonal(width, height, D_SMALL, GAP, across, rows)
    low = min(k.y for k in disks) - 0.5 * D_SMALL
    header = [
        "sediment504: 504 disks settling in a closed 2 cm x 2 cm cavity (walls on all four",
        "sides), the many-disk test of",
        *GLOWINSKI,
        "taken up by later methods (Wan & Turek; Feng & Michaelides): docs/suspensions.md.",
        "Set-up: D = 0.0625 cm, rho_p = 1.01 g/cm^3, fluid rho_f = 1 g/cm^3, nu = 0.01 cm^2/s,",
        "g = 980 cm/s^2; the disks start at rest in a regular lattice in the upper part.",
        f"Arrangement rule here: {rows} rows of {across} on a hexagonal lattice; centres",
        "D + 0.4 D = 0.0875 cm apart along a row, rows 0.0758 cm apart, every second row from",
        "the top shifted right by half a pitch; the block centred across the cavity, the top",
        f"row's surfaces 0.4 D (0.025 cm) below the lid, the lowest at y = {low:.4f} cm. The",
        "gap of 0.4 D between surfaces and to the walls is at least one spacing plus the",
        "contact range of half a spacing from 3.75 spacings per D up. It is looser than the",
        "published lattice, whose rows, columns and spacing were not confirmed",
        "(docs/suspensions.md).",
        "Run length: one disk alone sinks at about 0.3-0.4 cm/s (Re about 2), the suspension",
        "much slower; the bed comes to rest within 40 s (docs/suspensions.md).",
    ]
    return Scene("sediment504", header, width, height, disks, t_end=40.0,
                 series_interval=0.02, field_interval=0.5, progress_every=5000,
                 cells_per_diameter=cells_per_diameter)


def sediment504_dense(cells_per_diameter: float) -> Scene:
    """The 504 disks in the lattice of an independent reproduction of the test: in units of
    1/256 cm, rows 18 apart from y = 498 (the top) down to 192, centres 18 apart along a row
    from x = 12, every second row from the top 2 further right (docs/suspensions.md)."""
    unit = 1.0 / 256.0
    disks = [Disk((12 + 18 * i + (2 if j % 2 == 0 else 0)) * unit, (498 - 18 * j) * unit,
                  D_SMALL) for j in range(18) for i in range(28)]
    header = [
        "sediment504_dense: the 504 disks of sediment504 (Glowinski et al., J. Comput. Phys.",
        "169 (2001) 363-426) in the closed 2 cm x 2 cm cavity, in the lattice of an independent",
        "lattice Boltzmann reproduction of the test (docs/suspensions.md, the literature set-up):",
        "18 rows of 28, centres 1.125 D = 0.0703 cm apart along a row and between rows, every",
        "second row from the top 0.0078 cm to the right, from y = 0.750 to 1.945 cm above 0.72 cm",
        "of clear fluid. D = 0.0625 cm, rho_p = 1.01 g/cm^3, rho_f = 1 g/cm^3, nu = 0.01 cm^2/s,",
        "g = 980 cm/s^2. The surface gaps of 0.125 D (0.0078 cm) ask for 12 spacings per D with",
        "the contact range of half a spacing (the rule of sediment504).",
        "Run length: the reproduction ran 24 s; the fingers and the first disks at the bottom",
        "come in the first seconds (docs/suspensions.md).",
    ]
    return Scene("sediment504_dense", header, 2.0, 2.0, disks, t_end=24.0,
                 series_interval=0.02, field_interval=0.5, progress_every=10000,
                 cells_per_diameter=cells_per_diameter)


def bidisperse(cells_per_diameter: float) -> Scene:
    """Two sizes, diameter ratio 2, mixed on a checkerboard."""
    width, height = 2.0, 6.0
    d_large = 2.0 * D_SMALL
    columns = rows = 16
    disks = checkerboard(width, height, d_large, D_SMALL, GAP, columns, rows)
    low = min(k.y - 0.5 * k.d for k in disks)
    header = [
        "bidisperse: 256 disks of two sizes settling in a closed 2 cm x 6 cm box (walls on all",
        "four sides): 128 of D = 0.125 cm and 128 of D = 0.0625 cm (diameter ratio 2), all of",
        "rho_p = 1.01 g/cm^3; fluid rho_f = 1 g/cm^3, nu = 0.01 cm^2/s; g = 980 cm/s^2: the disk,",
        "fluid and gravity of the 504-disk test of Glowinski et al., J. Comput. Phys. 169 (2001)",
        "363-426 (sediment504.nml), with every second disk twice as large.",
        f"Arrangement rule: {columns} x {rows} on a square lattice, large and small alternating",
        "along every row and column (a checkerboard, a large disk top left); neighbours along a",
        "row or column are a large and a small disk 0.025 cm apart (pitch 0.11875 cm), two large",
        "disks are diagonal neighbours (0.043 cm apart); the block centred across the box, the",
        f"top row's large disks 0.025 cm below the lid, the lowest surfaces at y = {low:.4f} cm.",
        "cells_per_diameter counts the spacings across the smaller disk.",
        "Run length: alone, a small disk sinks at about 0.3-0.4 cm/s (Re about 2), a large one at",
        "0.4-0.8 cm/s (Re 5-10); 40 s, as sediment504 (docs/suspensions.md).",
    ]
    return Scene("bidisperse", header, width, height, disks, t_end=40.0,
                 series_interval=0.02, field_interval=1.0, progress_every=5000,
                 cells_per_diameter=cells_per_diameter)


def sediment10k(cells_per_diameter: float) -> Scene:
    """At least 10 000 disks in a tall closed box."""
    width, height = 4.0, 24.0
    across = per_row(width, D_SMALL, GAP)
    rows = math.ceil(10000 / across)
    disks = hexagonal(width, height, D_SMALL, GAP, across, rows)
    low = min(k.y for k in disks) - 0.5 * D_SMALL
    header = [
        f"sediment10k: {len(disks)} disks settling in a closed 4 cm x 24 cm box (walls on all",
        "four sides): the disk, fluid and gravity of the 504-disk test of Glowinski et al.,",
        "J. Comput. Phys. 169 (2001) 363-426 (sediment504.nml), D = 0.0625 cm, rho_p = 1.01",
        "g/cm^3, rho_f = 1 g/cm^3, nu = 0.01 cm^2/s, g = 980 cm/s^2, with as many disks as the",
        "10 000-disk cavity of Wan & Turek (2007); their cavity and disks are not reproduced",
        "here (docs/suspensions.md).",
        f"Arrangement rule: {rows} rows of {across} on the hexagonal lattice of sediment504",
        "(centres 0.0875 cm apart along a row, rows 0.0758 cm apart, every second row from the",
        "top shifted right by half a pitch), centred across the box, the top row's surfaces",
        f"0.025 cm below the lid, the lowest at y = {low:.4f} cm above a layer of clear fluid.",
        "Written on demand (20 064 coordinates), not kept in input/:",
        "  python3 tools/suspension_scene.py --kind sediment10k --out /tmp/sediment10k.nml",
        "Run length: 120 s, an estimate from the settling speeds of sediment504",
        "(docs/suspensions.md); resume from a checkpoint with a larger run.t_end if the bed is",
        "not at rest by then.",
    ]
    return Scene("sediment10k", header, width, height, disks, t_end=120.0,
                 series_interval=0.25, field_interval=5.0, progress_every=10000,
                 cells_per_diameter=cells_per_diameter)


def number(value: float) -> str:
    """A real as the scene files write it: fixed point, no trailing zeros beyond one."""
    text = f"{value:.{DIGITS}f}".rstrip("0")
    return text + "0" if text.endswith(".") else text


def array(key: str, values: list[str], width: int = 96) -> list[str]:
    """``key = v1, v2, ...`` over lines of at most ``width`` columns; a run of three or more
    equal values is written r*value (Fortran's repeat count)."""
    items: list[str] = []
    start = 0
    while start < len(values):
        end = start
        while end < len(values) and values[end] == values[start]:
            end += 1
        n = end - start
        items += [f"{n}*{values[start]}"] if n >= 3 else values[start:end]
        start = end
    lead = f"  {key} = "
    lines: list[str] = []
    line = lead
    for item in items:
        if line not in (lead, " " * len(lead)) and len(line) + len(item) + 1 > width:
            lines.append(line.rstrip())
            line = " " * len(lead)
        line += item + ", "
    lines.append(line.rstrip().rstrip(","))
    return lines


def render(scene: Scene, command: str) -> str:
    """The scene file's text."""
    disks = rounded(scene.disks)
    report = check(replace(scene, disks=disks))
    sizes = sorted({k.d for k in disks}, reverse=True)
    lines = [f"! {text}" for text in scene.header]
    lines += [f"! {text}" for text in report]
    lines += [
        f"! Written by: {command}",
        "! Regenerate it with that command rather than editing the disk lists by hand.",
        "&domain",
        f"  width = {number(scene.width)}, height = {number(scene.height)}",
        "  sides = 'wall', lower = 'wall', upper = 'wall'",
        "/",
        "&fluid",
        f"  density = {number(RHO_F)}, viscosity = {number(MU)}",
        "/",
        "&lbm",
        f"  tau = {number(TAU)}, cells_per_diameter = {scene.cells_per_diameter:g}",
        f"  s_e = {number(S_E)}   ! a bulk viscosity that damps what sound the start still makes",
        "/",
        "&initial",
        "  pressure = 'hydrostatic'   ! holds up the disks' excess weight: no ringing at the start",
        "/",
        "&particles",
        f"  count = {len(disks)}",
        f"  gravity = {number(GRAVITY)}",
    ]
    if len(sizes) > 1:
        lines.append("  ! diameters " + " and ".join(f"{number(d)}" for d in sizes) + " cm")
    lines += array("diameter", [number(k.d) for k in disks])
    lines += array("density", [number(k.rho) for k in disks])
    lines += array("x", [number(k.x) for k in disks])
    lines += array("y", [number(k.y) for k in disks])
    lines += [
        "/",
        "&coupling",
        "  bounce_back = 'yu', momentum = 'galilean'",
        "/",
        "&collision",
        f"  range = {number(scene.contact_range)}, "
        f"lubrication = {'.true.' if scene.lubrication else '.false.'}",
        "/",
    ]
    lines += [
        "&run",
        f"  t_end = {number(scene.t_end)}, progress_every = {scene.progress_every}",
        "/",
        "&output",
        f"  series_interval = {number(scene.series_interval)}, "
        f"field_interval = {number(scene.field_interval)}",
        "/",
    ]
    return "\n".join(lines) + "\n"


BUILDERS = {"sediment504": sediment504, "sediment504_dense": sediment504_dense,
            "bidisperse": bidisperse, "sediment10k": sediment10k}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description="Write a dktlbm scene of many disks settling in a closed box.",
        epilog="e.g. python3 tools/suspension_scene.py --kind sediment504 "
               "--out input/sediment504.nml")
    parser.add_argument("--kind", choices=KINDS, required=True,
                        help="sediment504 (Glowinski et al. 2001), sediment504_dense (its "
                             "disks in a reproduction's denser lattice), bidisperse (two sizes, "
                             "ratio 2) or sediment10k (10 032 disks in a tall box)")
    parser.add_argument("--cells-per-diameter", type=float, default=10.0, metavar="N",
                        help="lattice spacings across the smallest disk (&lbm "
                             "cells_per_diameter; default 10)")
    parser.add_argument("--range", type=float, default=RANGE, metavar="XI",
                        help="&collision range, the contact range in lattice spacings "
                             f"(default {RANGE:g}; the DKT scenes take 2); the gaps must be "
                             "at least 1 + XI spacings")
    parser.add_argument("--no-lubrication", action="store_true",
                        help="leave out the lubrication correction (&collision lubrication, "
                             "E13), which the scenes take by default")
    parser.add_argument("--out", type=Path, metavar="PATH",
                        help="the scene file to write (default: standard output)")
    args = parser.parse_args(argv)
    if not 4.0 <= args.cells_per_diameter <= 1000.0:
        parser.error("--cells-per-diameter must lie within 4 and 1000 (&lbm cells_per_diameter)")
    if not args.range >= 0.0:
        parser.error("--range must be 0 or more (&collision range)")
    command = f"python3 tools/suspension_scene.py --kind {args.kind}"
    if args.cells_per_diameter != 10.0:
        command += f" --cells-per-diameter {args.cells_per_diameter:g}"
    if args.range != RANGE:
        command += f" --range {args.range:g}"
    if args.no_lubrication:
        command += " --no-lubrication"
    if args.out is not None:
        command += f" --out {args.out}"
    try:
        scene = replace(BUILDERS[args.kind](args.cells_per_diameter), contact_range=args.range,
                        lubrication=not args.no_lubrication)
        text = render(scene, command)
    except ValueError as err:
        print(f"suspension_scene.py: error: {err}", file=sys.stderr)
        return 2
    if args.out is None:
        sys.stdout.write(text)
    else:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text, encoding="utf-8")
        print(f"wrote {args.out}: {text.count(chr(10))} lines")
    return 0


if __name__ == "__main__":
    sys.exit(main())
