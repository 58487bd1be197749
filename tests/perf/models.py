#!/usr/bin/env python3
"""Which model reproduces what: the particle-interior model, the momentum rule and the contact
range, every combination, on three scenes.

Variants: coupling.interior (solid, fluid) x coupling.momentum (paper, galilean) x
collision.range (1, 2 spacings); everything else as the scene ships (25 spacings per D, tau =
0.65 for the paper's scenes). Scenes and the answers read from each run:

- case0_box (input/case0_box.nml, to 3.5 s): the start of kissing (the run's own episodes, D_r
  at most 3 spacings, and D_r < 0.02 cm as the HLBM code reports it), the end of kissing, the
  first time the trailing disk passes the leading one, the surface gap at the end and the
  pattern. Published: kissing about 1.4 s and tumbling done about 2.1 s (the paper); HLBM
  1.17 s (D_r < 0.02 cm) and 1.87 s.
- uhlmann (input/uhlmann.nml, to 0.4 s): the kissing and passing times (tests/test_particles.py
  uhlmann_events) and each disk's peak settling speed, against Uhlmann (2005) Fig. 6.
- case0 (input/case0.nml, two equal disks in the infinite channel, D_h = 2 D_1, to t* = 200.7,
  27.2 s): the pattern, the number of kissing episodes, their start times in t* and the longest
  episode (a pair that never lets go is locked), and each disk's Reynolds number at the end.
  The paper reports repeated DKT.

Each run lives in runs/models/<scene>/<variant>/ and is skipped when its result.json exists
(tests/perf/tradeoff.py run_one). Prints the table of docs/accuracy.md and
writes runs/models/models.csv.

    export PYTHONPATH=postproc:tests            # the dktlbm package and dkt_run, as ctest sets it
    python3 tests/perf/models.py                      # all 8 variants x 3 scenes, 2 ranks
    python3 tests/perf/models.py --scenes case0_box --interior fluid
    python3 tests/perf/models.py --report-only
"""

from __future__ import annotations

import argparse
import csv
import itertools
import json
import sys
from pathlib import Path

import h5py
import numpy as np
from precision_accuracy import episodes, pair_run
from tradeoff import config_name, fmt, run_one

from dkt_run import ROOT
from dktlbm.read import text_attr
from test_particles import REFDATA, series, uhlmann_events

T_REF = 0.135526  # s, sqrt(H/g) for H = 18 cm (docs/model.md §6)
SCENES = {
    "case0_box": ["run.t_end=3.5"],
    "uhlmann": ["run.t_end=0.4"],
    "case0": ["run.t_end=27.2"],
}
AXES = {
    "coupling.interior": ["solid", "fluid"],
    "coupling.momentum": ["paper", "galilean"],
    "collision.range": ["1", "2"],
}
HLBM_GAP = 0.02  # cm: the HLBM code's kissing criterion


def first(times: np.ndarray) -> object:
    return float(times[0]) if times.size else "none"


def answers_case0_box(out: Path) -> list[tuple[str, object]]:
    t, y, dr, starts, ends, pattern = pair_run(out / "case0_box.h5")
    return [
        ("kissing begins (3 spacings) [s]", first(starts)),
        (f"kissing begins (D_r < {HLBM_GAP} cm) [s]", first(t[dr < HLBM_GAP])),
        ("kissing ends [s]", first(ends)),
        ("passing [s]", first(t[y[:, 0] < y[:, 1]])),
        ("gap at the end [cm]", float(dr[-1])),
        ("end [s]", float(t[-1])),
        ("pattern", pattern),
    ]


def answers_uhlmann(out: Path) -> list[tuple[str, object]]:
    s = series(out / "uhlmann.h5")
    ev = uhlmann_events(s["t"], 8.0 - s["y"][:, 0], 8.0 - s["y"][:, 1])
    rows: list[tuple[str, object]] = [
        (f"{name} [s]", "none" if np.isnan(ev[key]) else ev[key])
        for key, name in (("kiss", "kissing"), ("pass", "passing"))
    ]
    rows += [
        (f"peak speed {name} [cm/s]", float(-s["v"][:, k].min()))
        for k, name in enumerate(("leading", "trailing"))
    ]
    rows.append(("end [s]", float(s["t"][-1])))
    return rows


def answers_case0(out: Path) -> list[tuple[str, object]]:
    with h5py.File(out / "case0.h5", "r") as h5:
        diag = h5["diagnostics"]
        t = h5["particles/t"][()]
        starts, ends = episodes(diag)
        pattern = text_attr(diag.attrs["pattern"])
        re_end = diag["re"][()][-1]
    end = float(t[-1])
    closed = np.where(np.isfinite(ends), ends, end)
    return [
        ("pattern", pattern),
        ("episodes", int(starts.size)),
        ("kisses begin [t*]", " ".join(f"{a / T_REF:.0f}" for a in starts) or "none"),
        ("longest episode [t*]", float(np.max(closed - starts)) / T_REF if starts.size else 0.0),
        ("Re_1, Re_2 at the end", f"{re_end[0]:.2f}, {re_end[1]:.2f}"),
        ("end [t*]", end / T_REF),
    ]


ANSWERS = {"case0_box": answers_case0_box, "uhlmann": answers_uhlmann, "case0": answers_case0}


def published() -> dict[tuple[str, str], str]:
    peaks = {}
    for name in ("leading", "trailing"):
        data = np.loadtxt(REFDATA / "uhlmann2005_dkt" / f"Uhlmann2005-fig6b-{name}-particle.csv")
        peaks[name] = float(data[:, 1].max())
    return {
        ("case0_box", "kissing begins (3 spacings) [s]"): "about 1.4 (paper)",
        ("case0_box", f"kissing begins (D_r < {HLBM_GAP} cm) [s]"): "1.17 (HLBM)",
        ("case0_box", "passing [s]"): "about 2.1 (paper), 1.87 (HLBM)",
        ("uhlmann", "peak speed leading [cm/s]"): f"{peaks['leading']:.2f}",
        ("uhlmann", "peak speed trailing [cm/s]"): f"{peaks['trailing']:.2f}",
        ("case0", "pattern"): "repeated (paper)",
    }


def label(config: dict[str, str]) -> str:
    return (
        f"{config['coupling.interior']}, {config['coupling.momentum']}, "
        f"ξ = {config['collision.range']}"
    )


def gap_figure(out: Path, path: Path) -> None:
    """The surface gap of the case0_box pair in lattice spacings against time, one curve per
    variant: with a one-spacing contact range the pair comes to rest less than a spacing
    apart, so no fluid node lies between the surfaces."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.8))
    for result in sorted((out / "case0_box").glob("*/result.json")):
        config = json.loads(result.read_text())["config"]
        with h5py.File(result.parent / "case0_box.h5", "r") as h5:
            t = h5["particles/t"][()]
            dr = h5["diagnostics/dr"][()]
            dx = float(h5["diagnostics"].attrs["kiss_enter"]) / float(
                h5["diagnostics"].attrs["kiss_enter_cells"]
            )
        style = "-" if config["collision.range"] == "2" else "--"
        ax.plot(t, dr / dx, style, lw=1, label=label(config))
    ax.axhline(1, color="grey", lw=0.6, ls=":")
    ax.set_yscale("log")
    ax.set_xlim(0.8, 3.5)
    ax.set_ylim(0.3, 60)
    ax.set_xlabel("t [s]")
    ax.set_ylabel("surface gap D_r / δx")
    ax.set_title("case0_box, 25 spacings per D: the gap during kissing", fontsize=9)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenes", nargs="+", choices=list(SCENES), default=list(SCENES))
    parser.add_argument("--interior", nargs="+", choices=AXES["coupling.interior"])
    parser.add_argument("--momentum", nargs="+", choices=AXES["coupling.momentum"])
    parser.add_argument("--range", nargs="+", choices=AXES["collision.range"])
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a further input value of every run, e.g. pair.x_offset=0.01",
    )
    parser.add_argument("--ranks", type=int, default=2)
    parser.add_argument("--out", type=Path, default=ROOT / "runs" / "models")
    parser.add_argument("--report-only", action="store_true")
    parser.add_argument("--figure", type=Path, default=ROOT / "docs" / "img" / "models_gap.png")
    args = parser.parse_args()
    axes = dict(AXES)
    for key, given in (("coupling.interior", args.interior), ("coupling.momentum", args.momentum),
                       ("collision.range", args.range)):  # fmt: skip
        if given:
            axes[key] = given
    extra = dict(s.split("=", 1) for s in args.set)
    out = args.out.resolve()
    if not args.report_only:
        for values in itertools.product(*axes.values()):
            config = dict(zip(axes, values, strict=True)) | extra
            for scene in args.scenes:
                print(f"{scene}, {label(config)}:", flush=True)
                run_one(scene, config, out / scene / config_name(config), args.ranks,
                        scene_sets=SCENES[scene], answer=ANSWERS[scene])  # fmt: skip
    records = [json.loads(p.read_text()) for p in sorted(out.glob("*/*/result.json"))]
    if not records:
        print("no finished runs under", out)
        return 1
    pub = published()
    rows = []
    for r in records:
        for quantity, value in r["answers"]:
            rows.append({**r["config"], "scene": r["scene"], "status": r["status"],
                         "wall_s": r["wall_s"], "quantity": quantity, "value": fmt(value),
                         "published": pub.get((r["scene"], quantity), ""),
                         "command": r["command"]})  # fmt: skip
    fields = list(dict.fromkeys(k for row in rows for k in row))
    with open(out / "models.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=fields)
        writer.writeheader()
        writer.writerows(rows)
    print(f"\n{out / 'models.csv'}: {len(rows)} rows from {len(records)} runs")
    for scene in SCENES:
        runs = [r for r in records if r["scene"] == scene]
        if not runs:
            continue
        quantities = list(dict.fromkeys(q for r in runs for q, _ in r["answers"]))
        print(f"\n{scene}:\n")
        head = ["interior, momentum, range", *quantities, "wall s", "status"]
        print("| " + " | ".join(head) + " |\n|" + "---|" * len(head))
        ref = ["published", *(pub.get((scene, q), "") for q in quantities), "", ""]
        print("| " + " | ".join(ref) + " |")
        for r in sorted(runs, key=lambda r: label(r["config"])):
            values = dict(r["answers"])
            cells = [label(r["config"]), *(fmt(values.get(q, "—")) for q in quantities),
                     f"{r['wall_s']:.0f}", r["status"][:40]]  # fmt: skip
            print("| " + " | ".join(cells) + " |")
    if (out / "case0_box").is_dir():
        gap_figure(out, args.figure)
        print(f"\n{args.figure}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
