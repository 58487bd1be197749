#!/usr/bin/env python3
"""The figures of docs/regime.md from the tables in docs/regime/.

    python3 tools/plot_regime.py [--data docs/regime] [--out docs/img]

Each plane (Case-1, Case-2) is drawn from the `dkt-sweep map` tables of its maps
(<data>/<case>_<kind>/map.csv and borders.csv, kind `rep` for the pattern map of the
repeated-to-once border, `kiss` for the --kiss map of the kisses-to-never border): every
settled point coloured by its pattern (a --kiss map's `once` and `repeated` are `kisses`),
unsettled points as grey crosses, each map's border polylines through its brackets' midpoints,
and the paper's 1-D cuts with their brackets at 25 per D (docs/results.md) as short red bars.
The Reynolds-number cut (<data>/re_case1.csv) is the Case-1 threshold bracket in gamma against
the terminal Reynolds number of the larger disk. Writes <out>/regime_case1.png,
regime_case2.png and regime_re.png.
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
from matplotlib.figure import Figure  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
STYLE = {"repeated": ("s", "tab:blue"), "once": ("o", "tab:green"),
         "kisses": ("o", "tab:olive"), "never": ("^", "tab:orange"),
         "unsettled": ("x", "0.45")}
LINES = {"once|repeated": "-", "never|once": "--", "kisses|never": "--"}
# The 1-D cuts of docs/results.md at the paper's 25 per D: (key along the cut, fixed value,
# bracket lo, bracket hi), gamma across and dh up.
CUTS25 = {
    "case1": [("gamma", 2.0, 1.2222, 1.2396)],
    "case2": [("gamma", 2.0, 1.2639, 1.2778), ("gamma", 2.0, 2.21875, 2.234375),
              ("dh", 2.0, 2.46875, 2.5)],
}
# 16-per-D bracket ends run again at 25 per D (docs/regime.md): (fixed dh, gamma lo, gamma hi)
CHECKS25 = {"case1": [(4.5, 1.1875, 1.25), (1.5, 1.1875, 1.25)],
            "case2": [(3.0, 1.75, 1.875), (4.5, 1.5, 1.625), (1.5, 1.25, 1.3125),
                      (4.5, 1.25, 1.3125)]}


def rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


def points_of(table: list[dict[str, str]], kiss: bool) -> dict[tuple[float, float], str]:
    """A map's points and their patterns: the settled row's (a --kiss map's kisses), else
    unsettled."""
    got: dict[tuple[float, float], str] = {}
    for r in table:
        p = (float(r["x"]), float(r["y"]))
        if r["settled"] == "yes":
            name = r["pattern"]
            got[p] = "kisses" if kiss and name in ("once", "repeated") else name
        else:
            got.setdefault(p, "unsettled")
    return got


def draw_plane(case: str, data: Path, out: Path) -> Path | None:
    maps = [(kind, data / f"{case}_{kind}") for kind in ("kiss", "rep")]
    maps = [(k, d) for k, d in maps if (d / "map.csv").is_file()]
    if not maps:
        return None
    fig = Figure(figsize=(7.2, 5.0), layout="constrained")
    ax = fig.subplots()
    shown: set[str] = set()
    for kind, d in maps:
        pts = points_of(rows(d / "map.csv"), kind == "kiss")
        grid = {(float(r["x"]), float(r["y"])) for r in rows(d / "map.csv")
                if r["role"] == "grid"}
        for (x, y), name in sorted(pts.items()):
            marker, colour = STYLE.get(name, ("x", "black"))
            label = None if name in shown else name
            shown.add(name)
            ax.scatter([x], [y], marker=marker, color=colour, s=55 if (x, y) in grid else 14,
                       zorder=3, label=label)
        borders = rows(d / "borders.csv") if (d / "borders.csv").is_file() else []
        for b in borders:
            x0, x1, y0, y1 = (float(b[k]) for k in ("x_lo", "x_hi", "y_lo", "y_hi"))
            ax.plot([x0, x1], [y0, y1], color="0.55" if b["unsettled"] else "black",
                    linewidth=3, zorder=4)
        for key in sorted({(b["border"], b["piece"]) for b in borders}):
            line = sorted((b for b in borders if (b["border"], b["piece"]) == key),
                          key=lambda b: int(b["order"]))
            name = line[0]["patterns"]
            label = None if f"border {name}" in shown else f"border {name}"
            shown.add(f"border {name}")
            ax.plot([float(b["x"]) for b in line], [float(b["y"]) for b in line],
                    color="black", linestyle=LINES.get(name, ":"), linewidth=1.2, zorder=4,
                    label=label)
    for n, (along, fixed, lo, hi) in enumerate(CUTS25[case]):
        label = "1-D cut, its bracket at 25 per D" if n == 0 else None
        if along == "gamma":
            ax.axhline(fixed, color="tab:red", linestyle=":", linewidth=0.8, zorder=1)
            ax.plot([lo, hi], [fixed, fixed], color="tab:red", linewidth=5, zorder=5,
                    label=label)
        else:
            ax.axvline(fixed, color="tab:red", linestyle=":", linewidth=0.8, zorder=1)
            ax.plot([fixed, fixed], [lo, hi], color="tab:red", linewidth=5, zorder=5,
                    label=label)
    for n, (dh, lo, hi) in enumerate(CHECKS25[case]):
        ax.scatter([lo, hi], [dh, dh], marker="s", s=90, facecolors="none",
                   edgecolors="tab:red", linewidths=1.5, zorder=6,
                   label="bracket ends run again at 25 per D" if n == 0 else None)
    which = "larger disk above" if case == "case1" else "smaller disk above"
    ax.set_title(f"Case-{case[-1]} ({which}), 16 per D", fontsize="medium")
    ax.set_xlabel(r"$\gamma = D_1/D_2$")
    ax.set_ylabel("$D_h/D_1$")
    ax.set_xlim(0.95, 3.05)
    ax.set_ylim(1.35, 6.15)
    ax.legend(fontsize="small", loc="upper left", bbox_to_anchor=(1.01, 1.0))
    path = out / f"regime_{case}.png"
    fig.savefig(path, dpi=130)
    return path


def draw_re(data: Path, out: Path) -> Path | None:
    """re_case1.csv: density, tau, cells_per_diameter, re_large, re_small, gamma_small,
    gamma_lo, gamma_hi (the bracket; empty where no threshold was found)."""
    src = data / "re_case1.csv"
    if not src.is_file():
        return None
    fig = Figure(figsize=(5.6, 3.9), layout="constrained")
    ax = fig.subplots()
    for r in rows(src):
        re = float(r["re_large"])
        tag = f"{float(r['density']):g}, tau {float(r['tau']):g}"
        if not r["gamma_lo"]:
            ax.scatter([re], [1.3], marker="x", color="0.3")
            ax.annotate(f"{tag}: no threshold\n(a bound pair)", (re, 1.3),
                        textcoords="offset points", xytext=(-60, 8), fontsize="small")
            continue
        lo, hi = float(r["gamma_lo"]), float(r["gamma_hi"])
        shift = 1.03 if float(r["tau"]) != 0.65 and float(r["density"]) == 1.01 else 1.0
        ax.plot([re * shift] * 2, [lo, hi], color="black", linewidth=4)
        ax.annotate(tag, (re * shift, lo if shift != 1.0 else hi), textcoords="offset points",
                    xytext=(4, -10 if shift != 1.0 else 2), fontsize="small")
    ax.set_xscale("log")
    ax.set_xticks([15, 20, 30, 40, 60], ["15", "20", "30", "40", "60"])
    ax.set_xlabel("terminal Re of the larger disk")
    ax.set_ylabel(r"threshold $\gamma$: repeated below, once above")
    ax.set_title(r"Case-1, $D_h/D_1 = 2$; labels: $\rho_p/\rho_f$, $\tau$", fontsize="medium")
    path = out / "regime_re.png"
    fig.savefig(path, dpi=130)
    return path


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", type=Path, default=ROOT / "docs" / "regime")
    p.add_argument("--out", type=Path, default=ROOT / "docs" / "img")
    args = p.parse_args()
    for path in (draw_plane("case1", args.data, args.out),
                 draw_plane("case2", args.data, args.out), draw_re(args.data, args.out)):
        if path is not None:
            print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
