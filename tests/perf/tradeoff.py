#!/usr/bin/env python3
"""Accuracy against cost: a grid of configurations, each run on the validation scenes.

A configuration is one value of each axis: cells per diameter (lbm.cells_per_diameter), tau
(lbm.tau; 'scene' keeps the scene's own), the bounce-back scheme (coupling.bounce_back), the
momentum rule (coupling.momentum), the storage precision (lbm.precision), and any further input
key given with --axis KEY=V1,V2 (e.g. --axis lbm.streaming=in_place,two_lattice). Every
configuration runs on every scene asked for, with field output off:

- single: input/single.nml as shipped (to t = 0.8 s: later, the landed disk's contact spikes
  its speed and the Mach guard stops a run near 0.87-0.93 s); Re_max = rho_p D |U|max / mu
  (published 17.3, Glowinski et al. 2001) up to the landing, and the landing time, the first
  time the disk's surface is within 0.25 D of the bottom (published: it reaches the bottom
  near 0.8 s, docs/model.md §8);
- case0_box: input/case0_box.nml; the start of the first kissing episode (published about
  1.4 s) and the first time the trailing disk is below the leading one (published: tumbling
  done about 2.1 s);
- case1: input/case1.nml; the /diagnostics pattern, the first kissing window and each disk's
  particle Reynolds number at the end (no published numbers are compared);
- uhlmann: input/uhlmann.nml to t = 0.3 s; the peak settling speed of each disk (published: the
  maxima of Uhlmann 2005, Fig. 6b, tests/refdata/uhlmann2005_dkt).

The answers are computed with the functions of tests/perf/precision_accuracy.py (docs/accuracy.md's
validation rows). Each run lives in runs/tradeoff/<scene>/<configuration>/; a run whose
result.json exists is skipped (a run a guard stopped, e.g. the
Mach limit at too few cells per diameter, is a result: its answers come from the series up to the
stop, an event it did not reach is 'none'), so the sweep resumes where it stopped, and
a run another invocation has claimed (its run.lock exists) is left to it, so several sweeps may
run at once on one tree. Every finished run found under --out enters the CSV, whichever grid
started it: two invocations with different grids add up.

The reference of each quantity is its value in the finest configuration of the CSV (the most
cells per diameter; among equals the one with the scene's own settings and double precision),
named in the CSV's reference_configuration column and in the printed table. A configuration's
error is the largest relative error over the quantities of the scenes it ran (an event that did
not happen counts as 100 %); its cost is the sum of the wall times, its memory the largest peak
resident set of one rank (GNU time around each rank) and the start-up report's allocation per
rank. Writes <out>/tradeoff.csv, the figure (error against wall time, the Pareto front marked;
docs/tradeoff.png by default), and prints the recommended settings: the cheapest configuration
within each tolerance of the reference (preview, sweep, publication).

    tests/perf/tradeoff.py --quick                   # 8, 12, 16 per D, single and case0_box
    tests/perf/tradeoff.py --scenes single case0_box --cpd 8 12 16 20 25 --precision double
    tests/perf/tradeoff.py --cpd 16 25 --precision single --axis lbm.mach=0.05,0.1
    tests/perf/tradeoff.py --report-only                                 # CSV and figure again

The test helpers it imports are found through PYTHONPATH=postproc:tests (ctest sets it).
"""

from __future__ import annotations

import argparse
import csv
import itertools
import json
import os
import re
import shlex
import sys
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
from benchlib import Finished, run_measured
from precision_accuracy import (
    answers_case0_box,
    answers_case1,
    answers_single,
    relative,
)

from dkt_run import EXE, INPUT, ROOT, mpi_command, mpi_env
from test_particles import REFDATA, series

TIME = Path("/usr/bin/time")
# reads the answers, (quantity, value) pairs, of a finished run directory
Answer = Callable[[Path], list[tuple[str, object]]]
SCENES = ("single", "case0_box", "case1", "uhlmann")
# the grid; 'scene' keeps the scene's own value of the key
AXES = {
    "lbm.cells_per_diameter": ["8", "12", "16", "20", "25", "32", "40"],
    "lbm.tau": ["scene"],
    "coupling.bounce_back": ["yu", "halfway", "bfl"],
    "coupling.momentum": ["galilean", "paper"],
    "lbm.precision": ["double", "single"],
}
QUICK = {"lbm.cells_per_diameter": ["8", "12", "16"]}
SHORT = {
    "lbm.cells_per_diameter": "cpd",
    "lbm.tau": "tau",
    "coupling.bounce_back": "bb",
    "coupling.momentum": "mom",
    "lbm.precision": "prec",
}
# what the scenes set themselves (input/*.nml), for naming the reference
SCENE_DEFAULTS = {"coupling.bounce_back": "yu", "lbm.precision": "double", "lbm.tau": "scene"}
SCENE_SETS = {
    "single": [],
    "case0_box": [],
    "case1": [],
    "uhlmann": ["run.t_end=0.3"],
}
PUBLISHED = {
    "single disk Re_max (ref. 17.3)": 17.3,
    "single disk landing [s]": 0.8,
    "case0_box kissing begins [s]": 1.4,
    "case0_box passing [s]": 2.1,
}
# quantities whose error enters a configuration's error
MEASURED = {
    "single": ["single disk Re_max (ref. 17.3)", "single disk landing [s]"],
    "case0_box": ["case0_box kissing begins [s]", "case0_box passing [s]"],
    "case1": ["case1 pattern", "case1 kissing 1 begins [s]", "case1 kissing 1 ends [s]"]
    + [f"case1 Re_{k} at the end" for k in (1, 2)],
    "uhlmann": [f"uhlmann peak speed {n} [cm/s]" for n in ("leading", "trailing")],
}
TOLERANCES = {"preview": 0.10, "sweep": 0.03, "publication": 0.01}


def uhlmann_published() -> dict[str, float]:
    out = {}
    for name in ("leading", "trailing"):
        data = np.loadtxt(REFDATA / "uhlmann2005_dkt" / f"Uhlmann2005-fig6b-{name}-particle.csv")
        out[f"uhlmann peak speed {name} [cm/s]"] = float(data[:, 1].max())
    return out


def answers(scene: str, out: Path) -> list[tuple[str, object]]:
    h5file = out / f"{scene}.h5"
    if scene == "single":
        s = series(h5file)
        gap = s["y"][:, 0] - 0.25 - 0.25 * 0.25  # surface within D/4 of the bottom (D = 0.25)
        landed = s["t"][np.nonzero(gap <= 0.0)[0]]
        # Re_max of the fall, as the accuracy table's run to 0.75 s: not the contact after landing
        rows = answers_single(h5file, float(landed[0]) if landed.size else np.inf)
        rows.append(("single disk landing [s]", float(landed[0]) if landed.size else "none"))
        return rows
    if scene == "case0_box":
        return answers_case0_box(h5file)
    if scene == "case1":
        rows = answers_case1(h5file)
        with h5py.File(h5file, "r") as h5:
            re_end = h5["diagnostics/re"][()][-1]
        rows += [(f"case1 Re_{k} at the end", float(re_end[k - 1])) for k in (1, 2)]
        return rows
    s = series(h5file)
    return [
        (f"uhlmann peak speed {name} [cm/s]", float(-s["v"][:, k].min()))
        for k, name in enumerate(("leading", "trailing"))
    ]


def answers_or_none(
    scene: str, out: Path, status: str, answer: Answer | None = None
) -> list[tuple[str, object]]:
    """The answers; a run a guard stopped before its diagnostics were written answers 'none'."""
    try:
        return answer(out) if answer else answers(scene, out)
    except (KeyError, IndexError):
        if status == "finished":
            raise
        return [(quantity, "none") for quantity in MEASURED.get(scene, [])]


def config_name(config: dict[str, str]) -> str:
    parts = []
    for key, value in config.items():
        tag = SHORT.get(key, key.replace(".", "_"))
        parts.append(f"{tag}-{value}")
    return re.sub(r"[^A-Za-z0-9_.=-]", "_", "__".join(parts))


def peak_rss_wrapper(path: Path) -> list[str]:
    """GNU time around each rank, appending its peak resident set (KiB) to `path`."""
    return ["/usr/bin/time", "-a", "-o", str(path), "-f", "%M"] if TIME.exists() else []


def peak_rss_mib(path: Path, fallback_kib: int) -> float:
    """The largest rank's peak resident set; without GNU time, the launcher's (wait4)."""
    if path.exists():
        values = [int(w) for w in path.read_text().split() if w.isdigit()]
        if values:
            return round(max(values) / 1024, 1)
    return round(fallback_kib / 1024, 1)


def allocated_mib(line: str) -> float:
    """Lattices + particle arrays + output buffers of the start-up memory line, MiB per rank."""
    found = re.findall(r"(lattices|particle arrays|output buffers) ([0-9.]+) MiB", line)
    return round(sum(float(v) for _, v in found), 2)


def mlups(done: Finished) -> float:
    """The run's own speed line (lattice updates of the time loop per second), 0 if absent."""
    found = re.search(r"performance:\s*([0-9.]+)\s*MLUPS", done.output)
    return float(found.group(1)) if found else 0.0


def lattice_updates(output: str) -> int:
    """Cells times steps asked for: the work, whatever the machine's load."""
    found = re.search(r"^cells \d+ x \d+ = (\d+), steps (\d+)", output, re.MULTILINE)
    return int(found.group(1)) * int(found.group(2)) if found else 0


def memory_line(log: str) -> str:
    found = re.search(r"^memory per rank: (.*)$", log, re.MULTILINE)
    return found.group(1).strip() if found else ""


def run_one(
    scene: str,
    config: dict[str, str],
    out: Path,
    ranks: int,
    repeats: int = 1,
    *,
    scene_sets: list[str] | None = None,
    answer: Answer | None = None,
) -> dict | None:
    """Run `scene` (input/<scene>.nml) in `config` into `out` until it has `repeats` timed
    runs, unless another sweep claimed it; return its record. The answers are the first run's;
    the wall time is the fastest run's (the others only time it again: a shared machine slows a
    run, never speeds it up), the memory the largest. `scene_sets` (default SCENE_SETS[scene])
    are the scene's own --set values, `answer` (default `answers`) reads the answers of a run
    directory."""
    result = out / "result.json"
    old = json.loads(result.read_text()) if result.exists() else None
    if old and len(old["walls"]) >= repeats:
        print(f"  skip (done): {relative(out)}", flush=True)
        return old
    out.mkdir(parents=True, exist_ok=True)
    try:
        lock = os.open(out / "run.lock", os.O_CREAT | os.O_EXCL | os.O_WRONLY)
    except FileExistsError:
        print(f"  skip (claimed by another sweep; remove run.lock if stale): {out}", flush=True)
        return None
    try:
        os.write(lock, f"{os.getpid()}\n".encode())
        sets = [f"{k}={v}" for k, v in config.items() if v != "scene"]
        own = SCENE_SETS[scene] if scene_sets is None else scene_sets
        sets += [*own, "output.field_interval=0", "output.overwrite=.true."]
        sets.append(f"output.dir={out}")
        rss = out / "rank_peak_rss_kib.txt"
        rss.unlink(missing_ok=True)
        command = [
            *mpi_command(ranks),
            *peak_rss_wrapper(rss),
            str(EXE),
            str(INPUT / f"{scene}.nml"),
        ]
        for s in sets:
            command += ["--set", s]
        shown = " ".join(
            shlex.quote(relative(Path(w)) if w.startswith("/") else w) for w in command
        )
        print(f"  run: {shown}", flush=True)
        os.environ.update(mpi_env())
        done = run_measured(command)
        (out / "output.txt").write_text(done.output)
        guard = re.search(r"dktlbm: error: (.*)", done.output)
        status = "finished" if (out / f"{scene}.finished").exists() else "failed"
        if status == "failed" and "stopped by a guard" in done.output:
            status = "guard: " + (guard.group(1)[:90] if guard else "?")
        print(f"  {status}", flush=True)
        if status == "failed" or not (out / f"{scene}.h5").exists():
            print(f"  FAILED ({done.returncode}), output in {out / 'output.txt'}", flush=True)
            return None
        walls = [*(old["walls"] if old else []), round(done.wall, 2)]
        rss_mib = peak_rss_mib(rss, done.max_rss_kib)
        if old:
            old |= {"walls": walls, "wall_s": min(walls), "mlups": max(old["mlups"], mlups(done))}
            old["peak_rss_mib"] = max(old["peak_rss_mib"], rss_mib)
            result.write_text(json.dumps(old, indent=1) + "\n")
            return old
        record = {
            "scene": scene,
            "config": config,
            "ranks": ranks,
            "status": status,
            "wall_s": walls[0],
            "walls": walls,
            "mlups": mlups(done),
            "lattice_updates": lattice_updates(done.output),
            "peak_rss_mib": rss_mib,
            "allocated_mib": allocated_mib(memory_line((out / f"{scene}.log").read_text())),
            "memory_line": memory_line((out / f"{scene}.log").read_text()),
            "command": shown,
            "answers": answers_or_none(scene, out, status, answer),
        }
        result.write_text(json.dumps(record, indent=1) + "\n")
        return record
    finally:
        os.close(lock)
        (out / "run.lock").unlink(missing_ok=True)


def collect(root: Path) -> list[dict]:
    return [json.loads(p.read_text()) for p in sorted(root.glob("*/*/result.json"))]


def config_key(config: dict[str, str]) -> tuple:
    return tuple(sorted(config.items()))


def fineness(config: dict[str, str]) -> tuple:
    """Sort key of the reference: most cells per diameter, then the scene's own settings."""
    own = sum(config.get(k) == v for k, v in SCENE_DEFAULTS.items())
    return (float(config.get("lbm.cells_per_diameter", 0)), own)


def relative_error(value: object, ref: object) -> float:
    if isinstance(ref, str) or isinstance(value, str):
        return 0.0 if value == ref else 1.0
    return abs(float(value) - float(ref)) / abs(float(ref))


def analyse(
    records: list[dict], exclude: tuple[str, ...] = ()
) -> tuple[list[dict], dict[str, tuple[object, dict]], dict]:
    """Rows of the CSV, the reference per quantity, and one summary per configuration (whose
    error leaves out the quantities named in `exclude`)."""
    published = {**PUBLISHED, **uhlmann_published()}
    reference: dict[str, tuple[object, dict]] = {}
    for scene in SCENES:
        runs = [r for r in records if r["scene"] == scene]
        if runs:
            best = max(runs, key=lambda r: fineness(r["config"]))
            for quantity, value in best["answers"]:
                reference[quantity] = (value, best["config"])
    rows, summary = [], {}
    for r in records:
        key = config_key(r["config"])
        entry = summary.setdefault(
            key,
            {"config": r["config"], "wall_s": 0.0, "rss": 0.0, "error": 0.0, "error_pub": 0.0,
             "updates": 0, "scenes": [], "values": {}, "stops": []},
        )  # fmt: skip
        entry["wall_s"] += r["wall_s"]
        entry["rss"] = max(entry["rss"], r["peak_rss_mib"])
        entry["scenes"].append(r["scene"])
        entry["updates"] += r["lattice_updates"]
        if r["status"] != "finished":
            entry["stops"].append(r["scene"])
        answered = {quantity for quantity, _ in r["answers"]}
        for quantity in MEASURED[r["scene"]]:
            # an event the reference has and this run has not (no second kissing episode)
            if quantity in reference and quantity not in answered and quantity not in exclude:
                entry["error"] = 1.0
                entry["values"][quantity] = "none"
        for quantity, value in r["answers"]:
            ref, ref_config = reference.get(quantity, (None, {}))
            err_ref = relative_error(value, ref) if ref is not None else float("nan")
            pub = published.get(quantity)
            err_pub = relative_error(value, pub) if pub is not None else float("nan")
            if quantity in MEASURED[r["scene"]] and quantity not in exclude:
                entry["error"] = max(entry["error"], err_ref)
                entry["values"][quantity] = value
                if pub is not None:
                    entry["error_pub"] = max(entry["error_pub"], err_pub)
            rows.append({**r["config"], "scene": r["scene"], "ranks": r["ranks"],
                         "status": r["status"], "wall_s": r["wall_s"],
                         "walls": " ".join(map(str, r["walls"])),
                         "mlups": r["mlups"], "lattice_updates": r["lattice_updates"],
                         "peak_rss_mib": r["peak_rss_mib"], "allocated_mib": r["allocated_mib"],
                         "memory_line": r["memory_line"], "quantity": quantity,
                         "value": value, "reference": ref, "error_vs_reference": err_ref,
                         "reference_configuration": label(ref_config),
                         "published": pub, "error_vs_published": err_pub,
                         "command": r["command"]})  # fmt: skip
    return rows, reference, summary


def pareto(points: list[tuple[float, float]]) -> list[int]:
    """Indices of the points no other point beats in both wall time and error."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    front, best = [], float("inf")
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


def label(config: dict[str, str]) -> str:
    return ", ".join(f"{SHORT.get(k, k)} {v}" for k, v in config.items())


def point_label(config: dict[str, str], reference_cfg: dict[str, str]) -> str:
    """Cells per diameter and every other value that differs from the reference's."""
    words = [config.get("lbm.cells_per_diameter", "?")]
    words += [
        v for k, v in config.items() if k != "lbm.cells_per_diameter" and reference_cfg.get(k) != v
    ]
    return " ".join(words)


def figure(summary: dict, scenes: list[str], reference_cfg: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    entries = [e for e in summary.values() if sorted(e["scenes"]) == scenes]
    floor = 1e-4  # the reference itself has error 0: drawn at the floor
    points = [(e["wall_s"], max(e["error"], floor)) for e in entries]
    front = set(pareto(points))
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for i, (e, (x, y)) in enumerate(zip(entries, points, strict=True)):
        marker = {"single": "s", "single_arith": "^", "half": "v"}.get(
            e["config"].get("lbm.precision"), "o"
        )
        ax.plot(x, y, marker, ms=7, mfc="none" if i not in front else "C3",
                mec="C3" if i in front else "C0")  # fmt: skip
        ax.annotate(point_label(e["config"], reference_cfg), (x, y), textcoords="offset points",
                    xytext=(5, 4 if i in front else -9), fontsize=7 if i in front else 6,
                    color="black" if i in front else "grey")  # fmt: skip
    fx, fy = zip(*sorted(points[i] for i in front), strict=True)
    ax.step(fx, fy, where="post", color="C3", lw=1, label="Pareto front")
    for name, tol in TOLERANCES.items():
        ax.axhline(tol, color="grey", lw=0.6, ls=":")
        ax.text(max(p[0] for p in points), tol, f"{name} ", fontsize=7, va="bottom",
                ha="right", color="grey")  # fmt: skip
    ax.set_xscale("log")
    ax.set_yscale("log")
    ticks = [t for t in (1, 2, 5, 10, 20, 50, 100, 200, 500, 1000, 2000, 5000)
             if min(p[0] for p in points) / 2 <= t <= 2 * max(p[0] for p in points)]  # fmt: skip
    ax.set_xticks(ticks, [str(t) for t in ticks])
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_xlabel(f"wall time, sum over {' + '.join(scenes)} [s]")
    ax.set_ylabel("largest relative error vs the reference")
    ax.set_title(
        f"reference: {label(reference_cfg)} (drawn at {floor:g})\n"
        "labels: cells per diameter and the settings that differ from it; "
        "circles double, squares single, triangles single_arith",
        fontsize=8,
    )
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def recommend(summary: dict, scenes: list[str], reference_cfg: dict) -> list[str]:
    entries = [e for e in summary.values() if sorted(e["scenes"]) == scenes]
    lines = ["| use | tolerance vs reference | configuration | error | wall s | peak MiB |",
             "|---|---|---|---|---|---|"]  # fmt: skip
    for name, tol in TOLERANCES.items():
        fits = [e for e in entries if e["error"] <= tol and e["config"] != reference_cfg]
        if not fits:
            lines.append(f"| {name} | {tol:.0%} | none below the reference | — | — | — |")
            continue
        e = min(fits, key=lambda e: e["wall_s"])
        lines.append(f"| {name} | {tol:.0%} | {label(e['config'])} | {e['error']:.2%} | "
                     f"{e['wall_s']:.0f} | {e['rss']:.0f} |")  # fmt: skip
    return lines


def fmt(value: object) -> str:
    return f"{value:.4g}" if isinstance(value, float) else str(value)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenes", nargs="+", choices=SCENES, help="default: all four "
                        "(with --quick: single case0_box)")  # fmt: skip
    parser.add_argument("--cpd", nargs="+", help="cells per diameter")
    parser.add_argument("--tau", nargs="+", help="lbm.tau values ('scene': the scene's own)")
    parser.add_argument("--bounce-back", nargs="+", choices=["yu", "halfway", "bfl"])
    parser.add_argument("--momentum", nargs="+", choices=["galilean", "paper"])
    parser.add_argument(
        "--precision", nargs="+", choices=["double", "single", "single_arith", "half"]
    )
    parser.add_argument("--axis", action="append", default=[], metavar="KEY=V1,V2",
                        help="a further input key and its values (repeatable)")  # fmt: skip
    parser.add_argument("--quick", action="store_true",
                        help="8, 12, 16 per D, scene settings, single and case0_box")  # fmt: skip
    parser.add_argument("--ranks", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=1, help="timed runs of each (fastest)")
    parser.add_argument("--out", type=Path, default=ROOT / "runs" / "tradeoff")
    parser.add_argument("--figure", type=Path, default=ROOT / "docs" / "tradeoff.png")
    parser.add_argument(
        "--tolerances",
        nargs="+",
        metavar="USE=FRACTION",
        help="recommended-settings tolerances (default preview=0.1 sweep=0.03 publication=0.01)",
    )
    parser.add_argument(
        "--exclude",
        nargs="+",
        default=[],
        metavar="QUANTITY",
        help="quantities left out of a configuration's error (e.g. 'case0_box passing [s]')",
    )
    parser.add_argument("--report-only", action="store_true", help="no runs: CSV and figure")
    parser.add_argument(
        "--report-scenes",
        nargs="+",
        choices=SCENES,
        help="report on these scenes' runs only (a configuration run on them and not on the "
        "others is then compared too), e.g. single case0_box case1",
    )
    args = parser.parse_args()

    axes = dict(AXES)
    if args.quick:
        axes = {k: v[:1] for k, v in AXES.items()} | QUICK
    given = {"lbm.cells_per_diameter": args.cpd, "lbm.tau": args.tau,
             "coupling.bounce_back": args.bounce_back, "coupling.momentum": args.momentum,
             "lbm.precision": args.precision}  # fmt: skip
    axes |= {k: v for k, v in given.items() if v}
    for spec in args.axis:
        key, _, values = spec.partition("=")
        axes[key.strip()] = [v.strip() for v in values.split(",") if v.strip()]
    out = args.out.resolve()
    args.scenes = args.scenes or (["single", "case0_box"] if args.quick else list(SCENES))

    if not args.report_only:
        grid = [
            dict(zip(axes, values, strict=True)) for values in itertools.product(*axes.values())
        ]
        print(f"{len(grid)} configurations x {len(args.scenes)} scenes, {args.ranks} ranks each")
        for config in grid:
            for scene in args.scenes:
                print(f"{scene}, {label(config)}:", flush=True)
                path = out / scene / config_name(config)
                run_one(scene, config, path, args.ranks, args.repeats)

    records = collect(out)
    if not records:
        print("no finished runs under", out)
        return 1
    for spec in args.tolerances or []:
        use, _, fraction = spec.partition("=")
        TOLERANCES[use] = float(fraction)
    # the CSV holds every run; the tables and the figure those of --report-scenes
    rows, reference, summary = analyse(records, tuple(args.exclude))
    if args.report_scenes:
        chosen = [r for r in records if r["scene"] in args.report_scenes]
        _, reference, summary = analyse(chosen, tuple(args.exclude))
        print("reported scenes:", " ".join(args.report_scenes))
    if args.exclude:
        print("left out of the error:", "; ".join(args.exclude))
    fields = list(dict.fromkeys(k for row in rows for k in row))
    with open(out / "tradeoff.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=fields)
        writer.writeheader()
        writer.writerows({k: fmt(v) for k, v in row.items()} for row in rows)
    print(f"\n{relative(out / 'tradeoff.csv')}: {len(rows)} rows from {len(records)} runs\n")
    print("Reference of each quantity (the finest configuration run):\n")
    print("| quantity | reference value | configuration |\n|---|---|---|")
    for quantity, (value, config) in reference.items():
        print(f"| {quantity} | {fmt(value)} | {label(config)} |")
    complete = sorted({tuple(sorted(e["scenes"])) for e in summary.values()}, key=len)[-1]
    scenes = list(complete)
    ref_cfg = max(
        (e["config"] for e in summary.values() if sorted(e["scenes"]) == scenes), key=fineness
    )
    print(f"\nConfigurations that ran {' + '.join(scenes)}:\n")
    quantities = [q for scene in scenes for q in MEASURED[scene] if q not in args.exclude]
    head = ["configuration", "wall s", "10^9 updates", "peak MiB", *quantities,
            "largest error vs reference", "largest error vs published", "guard stop"]  # fmt: skip
    print("| " + " | ".join(head) + " |\n|" + "---|" * len(head))
    for e in sorted(summary.values(), key=lambda e: e["wall_s"]):
        if sorted(e["scenes"]) == scenes:
            cells = [label(e["config"]), f"{e['wall_s']:.1f}", f"{e['updates'] / 1e9:.2f}",
                     f"{e['rss']:.0f}", *(fmt(e["values"].get(q, "—")) for q in quantities),
                     f"{e['error']:.2%}", f"{e['error_pub']:.1%}",
                     ", ".join(e["stops"]) or "—"]  # fmt: skip
            print("| " + " | ".join(cells) + " |")
    args.figure.parent.mkdir(parents=True, exist_ok=True)
    figure(summary, scenes, ref_cfg, args.figure)
    print(f"\n{relative(args.figure.resolve())}\n\nRecommended settings:\n")
    print("\n".join(recommend(summary, scenes, ref_cfg)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
