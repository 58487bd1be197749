"""The borders between DKT patterns across two keys: `dkt-sweep map`.

    dkt-sweep map BASE.nml --x gamma --x-range 1:3 --x-points 5 --x-tol 0.05 \\
        --y dh --y-range 1.5:6 --y-points 4 --y-tol 0.1 --out DIR [--jobs N] [--cut y=2]

runs a coarse grid of --x-points x --y-points points (pair.gamma and pair.dh, the ends
included), and wherever two neighbouring grid points (along x or along y) have different
settled patterns, bisects along that grid edge to the key's tolerance: the bracket [lo, hi]
of the edge's first change of pattern from its lower end, then the rest of the edge when the
pattern at hi is not the one at its upper end (so an edge across three patterns gives two
border points). Every point is settled by the rules of `dkt-sweep bisect` (sweepbisect.Bisector:
t_end doubled up to --max-t-end while 'once' or 'never' is not settled, window.above doubled
up to --max-above after a window escape, --kiss), and each step runs the new points of all
edges together: up to --jobs at a time here (each edge gets --jobs / edges points a step, at
least one), or one Slurm job array a step.
With --keep-going a point not settled within those limits is
'unsettled' instead of an error: edges from an unsettled grid point are not bisected, and an
edge whose bracket holds one stops there, its border point the bracket as it is.

Every run is DIR/<id> (`g<G>_h<H>`, `_t<T>` for a longer run, `_a<A>` for a taller window)
and a row of DIR/runs.csv, as plan and bisect write them, so `collect` reads a map as a
sweep. A point the directory's runs answer is never run again: the same command again (after
a kill, or with other ranges, grid sizes or tolerances) reuses every finished run, and a run
the directory holds inside an edge narrows that edge before any new point runs. DIR/map.json
keeps what defines the runs (base scene path and text, the two keys, the --set list); another
of these for the same DIR is refused.

Written to DIR: map.csv (a row per run: x, y, role grid or edge, pattern, episodes,
first_kiss_t, t_end, end_t, status, settled, wall_s, dir, above), borders.csv (a row per
border point: border id and its two patterns, piece and order along the polyline, the
edge's key, the midpoint x, y, the bracket x_lo, x_hi, y_lo, y_hi, the patterns at its
ends and the unsettled points inside it), map.png (the plane coloured by the grid's
patterns, every settled point, the border polylines, and the lines --cut x=V or y=V, e.g. the
paper's 1-D cuts).
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

from .sweepbisect import Bisector, Scene, SearchSettings, bisect_state, round_points
from .sweepcommon import (
    STYLE,
    UNSETTLED,
    PlannedRun,
    SweepError,
    Verdict,
    first_change,
    point_value,
    write_plan,
)

MAP_CSV = "map.csv"
BORDERS_CSV = "borders.csv"
MAP_PNG = "map.png"
MAP_STATE = "map.json"
MAP_COLUMNS = ("x", "y", "role", "pattern", "episodes", "first_kiss_t", "t_end", "end_t",
               "status", "settled", "wall_s", "dir", "above")
BORDER_COLUMNS = ("border", "patterns", "piece", "order", "along", "x", "y", "x_lo", "x_hi",
                  "y_lo", "y_hi", "pattern_lo", "pattern_hi", "unsettled")
KEYS = ("gamma", "dh")
LABELS = {"gamma": r"$\gamma = D_1/D_2$", "dh": "$D_h/D_1$"}

Point = tuple[float, float]
Settled = dict[float, tuple[Verdict, PlannedRun]]


@dataclass
class Axis:
    """One key of the map: pair.<key> from lo to hi in `points` grid values, bisected to
    `tol`."""

    key: str  # 'gamma' or 'dh'
    lo: float
    hi: float
    points: int
    tol: float

    def grid(self) -> list[float]:
        """The grid values, ends included, as the runs see them (8 significant digits)."""
        step = (self.hi - self.lo) / (self.points - 1)
        return [point_value(self.lo + k * step) for k in range(self.points)]


@dataclass
class Plane(Scene):
    """The points of a map: (x, y), pair.<x.key> and pair.<y.key>."""

    x: Axis
    y: Axis


@dataclass
class MapSettings(SearchSettings, Plane):
    """What a map runs: base, x, y, then SearchSettings' fields, then these."""

    cuts: list[tuple[str, float]] = field(default_factory=list)  # ('x' or 'y', value) to draw
    keep_going: bool = False  # a point not settled within the limits is UNSETTLED, not an error

    def keys(self) -> dict[str, object]:
        return {"x": self.x.key, "y": self.y.key}


class MapBisector(Bisector):
    """A Bisector whose points are (x, y): pair.<x key> and pair.<y key> together. Its rows
    (map.csv) name both and whether the point is on the grid."""

    cfg: MapSettings

    def __init__(self, cfg: MapSettings, jobs: int, launch) -> None:
        self.grid: set[Point] = set()
        self.unsettled: set[Point] = set()  # points not settled within the limits
        super().__init__(cfg, jobs, launch)

    @property
    def keep_going(self) -> bool:
        return self.cfg.keep_going

    def _give_up(self, done, target, value, v, r, message) -> None:
        super()._give_up(done, target, value, v, r, message)
        self.unsettled.add(value)

    def coords(self, value: Point) -> dict[str, float]:
        return {self.cfg.x.key: value[0], self.cfg.y.key: value[1]}

    def point_of(self, r: PlannedRun) -> Point | None:
        at = {"gamma": r.gamma, "dh": r.dh}
        x, y = at[self.cfg.x.key], at[self.cfg.y.key]
        return None if x is None or y is None else (x, y)

    def name(self, value: Point) -> str:
        return f"{self.cfg.x.key} = {value[0]:.8g}, {self.cfg.y.key} = {value[1]:.8g}"

    def label(self, value: Point) -> dict[str, str]:
        return {"x": f"{value[0]:.8g}", "y": f"{value[1]:.8g}",
                "role": "grid" if value in self.grid else "edge"}


# ---------------------------------------------------------------- edges and borders


@dataclass
class Edge:
    """A stretch of a grid line, from the grid point (i, j): along x (y fixed) when `along`
    is 0, along y (x fixed) when 1. lo and hi are (position along the line, pattern) of the
    bracket being narrowed; `end` the grid point at the far end, where the line goes on once
    the bracket is narrowed and the pattern at hi is not the end's."""

    along: int
    fixed: float
    index: tuple[int, int]
    lo: tuple[float, str]
    hi: tuple[float, str]
    end: tuple[float, str]

    def point(self, t: float) -> Point:
        return (t, self.fixed) if self.along == 0 else (self.fixed, t)

    def width(self) -> float:
        return self.hi[0] - self.lo[0]

    def cells(self) -> set[tuple[int, int]]:
        """The grid cells (indexed by their lower left grid point) this edge borders."""
        i, j = self.index
        return {(i, j - 1), (i, j)} if self.along == 0 else {(i - 1, j), (i, j)}


@dataclass
class Border:
    """A border point: the narrowed bracket of an edge, and where it lies on its polyline."""

    edge: Edge
    unsettled: list[float] = field(default_factory=list)  # unsettled points in the bracket
    patterns: str = ""  # the two patterns, sorted, joined by '|'
    border: int = 0  # one id per pair of patterns
    piece: int = 0  # the polyline of that border the point is on
    order: int = 0  # its place along that polyline

    def midpoint(self) -> Point:
        return self.edge.point(0.5 * (self.edge.lo[0] + self.edge.hi[0]))


def grid_edges(xs: list[float], ys: list[float], pattern: dict[Point, str]) -> list[Edge]:
    """Every edge between neighbouring grid points with different settled patterns (an edge
    with an UNSETTLED end has no known change to bisect)."""
    edges = []

    def differ(a: Point, b: Point) -> bool:
        return UNSETTLED not in (pattern[a], pattern[b]) and pattern[a] != pattern[b]

    for j, y in enumerate(ys):
        for i, x in enumerate(xs):
            if i + 1 < len(xs) and differ((x, y), (xs[i + 1], y)):
                far = (xs[i + 1], pattern[(xs[i + 1], y)])
                edges.append(Edge(0, y, (i, j), (x, pattern[(x, y)]), far, far))
            if j + 1 < len(ys) and differ((x, y), (x, ys[j + 1])):
                far = (ys[j + 1], pattern[(x, ys[j + 1])])
                edges.append(Edge(1, x, (i, j), (y, pattern[(x, y)]), far, far))
    return edges


class MapSearch:
    """The grid, then every differing edge narrowed step by step, all edges' points of a step
    settled together (MapBisector.settle)."""

    def __init__(self, m: MapBisector) -> None:
        self.m, self.cfg = m, m.cfg
        self.borders: list[Border] = []
        self.steps = 0

    def tol(self, e: Edge) -> float:
        return (self.cfg.x if e.along == 0 else self.cfg.y).tol

    def run(self) -> list[Border]:
        xs, ys = self.cfg.x.grid(), self.cfg.y.grid()
        points = [(x, y) for y in ys for x in xs]
        self.m.grid = set(points)
        print(f"grid: {len(xs)} x {len(ys)} points", flush=True)
        got = self.m.settle(points)
        edges = grid_edges(xs, ys, {p: got[p][0].pattern for p in points})
        while edges:
            edges = self.step(edges)
        return self.borders

    def step(self, edges: list[Edge]) -> list[Edge]:
        """Narrow every edge once: with the directory's earlier runs inside it when there are
        any (running nothing), else with new points; the edges still to narrow."""
        inside = {id(e): sorted(t for t in self._earlier(e) if e.lo[0] < t < e.hi[0])
                  for e in edges}
        if any(inside.values()):
            wanted = [e.point(t) for e in edges for t in inside[id(e)]]
            self.m.earlier -= set(wanted)  # each earlier point is read once
            got = self.m.settle(wanted, known_only=True)
        else:
            inside = {id(e): self._new_points(e, len(edges)) for e in edges}
            self.steps += 1
            total = sum(map(len, inside.values()))
            print(f"step {self.steps}: {len(edges)} edge{'s' if len(edges) != 1 else ''}, "
                  f"{total} point{'s' if total != 1 else ''}", flush=True)
            got = self.m.settle([e.point(t) for e in edges for t in inside[id(e)]])
        going = []
        for e in edges:
            mine = {t: got[e.point(t)] for t in inside[id(e)] if e.point(t) in got}
            stuck = sorted(t for t, (v, _) in mine.items() if v.pattern == UNSETTLED)
            e.lo, e.hi = first_change(e.lo, e.hi, {t: a for t, a in mine.items()
                                                    if t not in stuck})
            stuck = [t for t in stuck if e.lo[0] < t < e.hi[0]]
            going += self._narrowed(e, stuck)
        return going

    def _earlier(self, e: Edge) -> list[float]:
        """Positions along e's line of the points run before in this directory."""
        a = 1 - e.along
        return [p[e.along] for p in self.m.earlier if p[a] == e.fixed]

    def _new_points(self, e: Edge, edges: int) -> list[float]:
        """Up to --jobs / edges (at least one) points evenly inside e's bracket, no more than
        it needs to reach the tolerance."""
        width, tol = e.width(), self.tol(e)
        n = round_points(width, tol, max(1, self.m.jobs // edges))
        ts = sorted({point_value(e.lo[0] + k * width / (n + 1)) for k in range(1, n + 1)}
                    - {e.lo[0], e.hi[0]})
        if not ts:
            key = (self.cfg.x if e.along == 0 else self.cfg.y).key
            raise SweepError(f"the tolerance {tol:g} of {key} is finer than 8 significant "
                             f"digits resolve")
        return ts

    def _narrowed(self, e: Edge, stuck: list[float] | None = None) -> list[Edge]:
        """e if it is still wider than its tolerance; else its border point is kept, and the
        rest of its line to the grid point `end` goes on when the pattern changes there too.
        With unsettled points inside the bracket (`stuck`, --keep-going) the edge stops
        there: nothing tells on which side of them the pattern changes, so its border point
        is the bracket as it is, wider than the tolerance, with those points named."""
        if stuck or e.width() <= self.tol(e) * (1 + 1e-9):
            self.borders.append(Border(Edge(e.along, e.fixed, e.index, e.lo, e.hi, e.end),
                                       list(stuck or [])))
            if e.hi[1] != e.end[1]:
                return [Edge(e.along, e.fixed, e.index, e.hi, e.end, e.end)]
            return []
        return [e]


def link_borders(borders: list[Border], span: Point) -> None:
    """Number the borders (one id per pair of patterns, in sorted order) and order the points
    of each into polylines: two points are neighbours when their edges border the same grid
    cell; each piece starts at a point with at most one neighbour left when there is one, and
    goes on to the nearest neighbour not yet taken (distances in units of each axis's
    `span`)."""
    for b in borders:
        b.patterns = "|".join(sorted((b.edge.lo[1], b.edge.hi[1])))
    ids = {name: k + 1 for k, name in enumerate(sorted({b.patterns for b in borders}))}

    def far(a: Border, b: Border) -> float:
        (ax, ay), (bx, by) = a.midpoint(), b.midpoint()
        return math.hypot((ax - bx) / span[0], (ay - by) / span[1])

    for name, number in ids.items():
        mine = sorted((b for b in borders if b.patterns == name), key=lambda b: b.midpoint())
        near = {id(b): [c for c in mine if c is not b and b.edge.cells() & c.edge.cells()]
                for b in mine}
        left, piece = list(mine), 0
        while left:
            piece += 1
            free = [b for b in left if sum(c in left for c in near[id(b)]) <= 1]
            b, order = (free or left)[0], 0
            while b is not None:
                left.remove(b)
                order += 1
                b.border, b.piece, b.order = number, piece, order
                nxt = [c for c in near[id(b)] if c in left]
                b = min(nxt, key=lambda c, b=b: far(b, c)) if nxt else None


# ---------------------------------------------------------------- output


def write_map_csv(m: MapBisector) -> Path:
    path = m.cfg.out / MAP_CSV
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=MAP_COLUMNS, extrasaction="ignore")
        w.writeheader()
        w.writerows(m.rows)
    return path


def border_row(b: Border) -> dict[str, str]:
    e = b.edge
    x, y = b.midpoint()
    lo, hi = e.point(e.lo[0]), e.point(e.hi[0])
    return {"border": str(b.border), "patterns": b.patterns, "piece": str(b.piece),
            "order": str(b.order), "along": "x" if e.along == 0 else "y",
            "x": f"{x:.8g}", "y": f"{y:.8g}", "x_lo": f"{lo[0]:.8g}", "x_hi": f"{hi[0]:.8g}",
            "y_lo": f"{lo[1]:.8g}", "y_hi": f"{hi[1]:.8g}", "pattern_lo": e.lo[1],
            "pattern_hi": e.hi[1], "unsettled": " ".join(f"{t:.8g}" for t in b.unsettled)}


def write_borders(borders: list[Border], out: Path) -> Path:
    path = out / BORDERS_CSV
    rows = sorted(borders, key=lambda b: (b.border, b.piece, b.order))
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=BORDER_COLUMNS)
        w.writeheader()
        w.writerows(border_row(b) for b in rows)
    return path


def draw_map(cfg: MapSettings, grid: dict[Point, str], points: dict[Point, str],
             borders: list[Border], pdf: bool = False) -> list[Path]:
    """map.png: the plane coloured by the grid's patterns (each grid point's cell), every
    settled point (large: grid, small: edge points), each border's polylines through the
    midpoints of its brackets, and the --cut lines."""
    import numpy as np
    from matplotlib.colors import ListedColormap
    from matplotlib.figure import Figure

    style = {**STYLE, "kisses": ("o", "tab:red"), UNSETTLED: ("x", "0.45")}
    xs, ys = cfg.x.grid(), cfg.y.grid()
    names = sorted({p for p in grid.values()})
    code = np.array([[names.index(grid[(x, y)]) for x in xs] for y in ys], dtype=float)

    def cell_edges(v: list[float]) -> list[float]:
        mids = [0.5 * (a + b) for a, b in zip(v, v[1:], strict=False)]
        return [v[0]] + mids + [v[-1]]

    fig = Figure(figsize=(7.0, 5.0), layout="constrained")
    ax = fig.subplots()
    ax.pcolormesh(cell_edges(xs), cell_edges(ys), code, alpha=0.25, vmin=-0.5,
                  vmax=len(names) - 0.5, cmap=ListedColormap([style[n][1] for n in names]))
    for name in sorted(set(points.values())):
        marker, colour = style.get(name, ("x", "black"))
        label: str | None = name
        for on_grid, size in ((True, 60), (False, 14)):
            pts = [p for p, n in points.items() if n == name and (p in grid) == on_grid]
            if pts:
                ax.scatter(*zip(*pts, strict=True), marker=marker, s=size, color=colour,
                           zorder=3, label=label)
                label = None
    _draw_borders(ax, borders)
    for axis, value in cfg.cuts:
        line = ax.axvline if axis == "x" else ax.axhline
        line(value, color="0.3", linestyle="--", linewidth=1.0, zorder=1)
        ax.annotate(f"cut {(cfg.x if axis == 'x' else cfg.y).key} = {value:g}",
                    (value, ys[0]) if axis == "x" else (xs[-1], value), fontsize="small",
                    ha="right", va="bottom", color="0.3", rotation=90 if axis == "x" else 0)
    ax.margins(0.03)
    ax.set_xlabel(LABELS[cfg.x.key])
    ax.set_ylabel(LABELS[cfg.y.key])
    ax.set_title(f"DKT patterns: {len(xs)} x {len(ys)} grid, {len(borders)} border points",
                 fontsize="medium")
    ax.legend(fontsize="small", loc="upper left", bbox_to_anchor=(1.01, 1.0))
    png = cfg.out / MAP_PNG
    fig.savefig(png, dpi=150)
    written = [png]
    if pdf:
        written.append(png.with_suffix(".pdf"))
        fig.savefig(written[-1])
    return written


def _draw_borders(ax, borders: list[Border]) -> None:
    """Each border's pieces as lines through the midpoints (in order), each bracket as a
    short thick segment."""
    styles = ("-", "--", "-.", ":")
    for b in borders:
        e = b.edge
        (x0, y0), (x1, y1) = e.point(e.lo[0]), e.point(e.hi[0])
        ax.plot([x0, x1], [y0, y1], color="0.55" if b.unsettled else "black", linewidth=3,
                zorder=4)
    for number in sorted({b.border for b in borders}):
        mine = [b for b in borders if b.border == number]
        for piece in sorted({b.piece for b in mine}):
            line = sorted((b for b in mine if b.piece == piece), key=lambda b: b.order)
            ax.plot(*zip(*(b.midpoint() for b in line), strict=True), color="black",
                    linestyle=styles[(number - 1) % len(styles)], linewidth=1.2, zorder=4,
                    label=f"border {line[0].patterns}" if piece == 1 else None)


# ---------------------------------------------------------------- the map


def trace_map(cfg: MapSettings, jobs: int, launch,
              pdf: bool = False) -> tuple[MapBisector, list[Border], str]:
    """Run the map (MapSearch); write runs.csv and map.csv (also when it stops on an error),
    then borders.csv and map.png; return the summary line."""
    bisect_state(cfg, MAP_STATE, "map")
    m = MapBisector(cfg, jobs, launch)
    try:
        borders = MapSearch(m).run()
    finally:
        if m.runs:
            write_plan(list(m.runs.values()), cfg.out)
        write_map_csv(m)
    link_borders(borders, (cfg.x.hi - cfg.x.lo, cfg.y.hi - cfg.y.lo))
    write_borders(borders, cfg.out)
    draw_map(cfg, *map_points(m), borders, pdf)
    counts: dict[str, int] = {}
    for b in borders:
        counts[b.patterns] = counts.get(b.patterns, 0) + 1
    each = ", ".join(f"{k}: {v}" for k, v in sorted(counts.items())) or "no change of pattern"
    n, files = len(m.rows), len({row["dir"] for row in m.rows})
    loose = len(m.unsettled)
    return m, borders, (f"map of {cfg.x.key} x {cfg.y.key}: {len(m.grid)} grid points, "
                        f"{len(borders)} border points ({each}), {n} verdicts from {files} "
                        f"run{'s' if files != 1 else ''}"
                        + (f", {loose} unsettled point{'s' if loose != 1 else ''}"
                           if cfg.keep_going else ""))


def map_points(m: MapBisector) -> tuple[dict[Point, str], dict[Point, str]]:
    """The grid's patterns and every settled point's, from map.csv's rows (the last settled
    row of a point is its pattern; with --kiss its class), and the unsettled points."""
    points: dict[Point, str] = {p: UNSETTLED for p in m.unsettled}
    for row in m.rows:
        if row["settled"] == "yes":
            p = (float(row["x"]), float(row["y"]))
            points[p] = _class(row["pattern"], m.cfg.kiss)
    grid = {p: points.get(p, "missing") for p in m.grid}
    return grid, points


def _class(pattern: str, kiss: bool) -> str:
    return "kisses" if kiss and pattern in ("once", "repeated") else pattern
