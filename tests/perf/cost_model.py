#!/usr/bin/env python3
"""The cost model of a particle step, fitted and checked on measured runs (docs/performance.md,
"A cost model").

The model: a step on a rank costs

    T = a * cells + b * links + (c + e) * interior + d * held * substeps

with cells the slab's lattice nodes (the flow sweep, the guards), links the boundary links of
its disks (found, bounced), interior the nodes inside its disks (reset to the disk's
equilibrium: c; scanned for the refill: e), held the disks it holds (owned and ghosts) times the
contact sub-steps (moves, contacts). The ranks wait for the slowest at every step, so a run's
step costs the model's largest rank; dktlbm's `work per step` line gives each figure's largest
over the ranks.

The coefficients are fitted on 1-rank runs of the scenes whose lattice fits in the processor's
last-level cache, each part on the `time per part` share of the loop it measures (flow and
guards: a; links: b and c; particles: d and e). The bytes the particles send to neighbours
(printed) are left out: a few kB a step, against the lattice halo's, which the flow's part
already holds. The model is then checked against runs on more ranks (the same coefficients):
the measured and predicted time per step and their ratio. A lattice beyond the cache (the
10 032-disk box: 113 MB) is a check too: its cells and links cost more there, and the ratio
says how much.

Scenes: the 504-disk box of tools/suspension_scene.py at 8, 10, 12 and 16 per D (links grow
with the resolution, interior nodes with its square), the 10 032-disk box at 8 per D, the
bidisperse box, and case1 (2 disks, a window).

    tests/perf/cost_model.py                      # build/dktlbm, 3 repeats, checked on 2 ranks
    tests/perf/cost_model.py --check-ranks 2 3 4  # more ranks than cores: oversubscribed
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import benchlib
import numpy as np
from benchlib import ROOT

PERFORMANCE = re.compile(
    r"performance:\s*([0-9.eE+-]+) MLUPS \((\d+) cells x (\d+) steps in\s*([0-9.eE+-]+) s"
)
PARTS = re.compile(r"time per part: (.*?) \(mean")
WORK = re.compile(
    r"work per step: (\d+) cells, (\d+) boundary links, (\d+) interior nodes, (\d+) particles "
    r"held x (\d+) sub-steps, (\d+) bytes"
)


def scenes(tmp: Path) -> dict[str, tuple[Path, list[str], int]]:
    """name: (namelist, --set options, steps) of each scene the model is fitted and checked on."""
    out: dict[str, tuple[Path, list[str], int]] = {}
    for kind, cells, steps in [("sediment504", 8, 300), ("sediment504", 10, 200),
                               ("sediment504", 12, 120), ("sediment504", 16, 60),
                               ("sediment10k", 8, 12)]:
        path = tmp / f"{kind}_{cells}.nml"
        subprocess.run(
            [sys.executable, str(ROOT / "tools" / "suspension_scene.py"), "--kind", kind,
             "--cells-per-diameter", str(cells), "--range", "2", "--out", str(path)],
            check=True, capture_output=True, text=True,
        )
        out[f"{kind} {cells}/D"] = (path, [], steps)
    out["bidisperse 10/D"] = (ROOT / "input" / "bidisperse.nml", [], 100)
    out["case1 8/D"] = (ROOT / "input" / "case1.nml", ["lbm.cells_per_diameter=8"], 1500)
    return out


def run(exe: str, mpiexec: str, ranks: int, nml: Path, sets: list[str], steps: int,
        outdir: Path) -> dict:
    """One run's time per step (s), each part's seconds per step and the work figures."""
    cmd = [*benchlib.launcher(mpiexec, ranks), exe, str(nml)]
    for s in sets + [f"run.steps={steps}", "run.progress_every=0", "run.checkpoint_every=0",
                     "output.field_interval=0", f"output.dir={outdir}",
                     "output.overwrite=.true."]:
        cmd += ["--set", s]
    proc = subprocess.run(cmd, capture_output=True, text=True, stdin=subprocess.DEVNULL)
    perf, parts, work = (r.search(proc.stdout) for r in (PERFORMANCE, PARTS, WORK))
    if proc.returncode != 0 or not (perf and parts and work):
        raise SystemExit(f"run failed: {' '.join(cmd)}\n{proc.stdout[-2000:]}\n{proc.stderr}")
    step = float(perf.group(4)) / int(perf.group(3))
    share = {k: float(v) / 100 for k, v in re.findall(r"(\w+) ([0-9.]+) %", parts.group(1))}
    cells, links, interior, held, substeps, sent = (int(v) for v in work.groups())
    return {"step": step, "part": {k: v * step for k, v in share.items()}, "cells": cells,
            "links": links, "interior": interior, "held_sub": held * substeps, "bytes": sent}


def fit(runs: list[dict]) -> dict[str, float]:
    """a, b, c, d, e from 1-rank runs: each part's seconds per step against its work, least
    squares relative to the measured part (a scene of 10^4 disks weighs no more than one of 2)."""
    def solve(work: list[list[float]], seconds: list[float]) -> np.ndarray:
        w, t = np.array(work, float), np.array(seconds, float)
        coef, *_ = np.linalg.lstsq(w / t[:, None], np.ones_like(t), rcond=None)
        return coef

    (a,) = solve([[r["cells"]] for r in runs],
                 [r["part"]["flow"] + r["part"]["guards"] for r in runs])
    disks = [r for r in runs if r["links"] > 0]
    b, c = solve([[r["links"], r["interior"]] for r in disks], [r["part"]["links"] for r in disks])
    d, e = solve([[r["held_sub"], r["interior"]] for r in disks],
                 [r["part"]["particles"] for r in disks])
    return {"a": float(a), "b": float(b), "c": float(c), "d": float(d), "e": float(e)}


def predict(k: dict[str, float], r: dict) -> float:
    return k["a"] * r["cells"] + k["b"] * r["links"] + (k["c"] + k["e"]) * r["interior"] \
        + k["d"] * r["held_sub"]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--exe", default=os.environ.get("DKTLBM_EXE", str(ROOT / "build/dktlbm")))
    parser.add_argument("--mpiexec", default=shutil.which("mpiexec") or "mpiexec")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--check-ranks", nargs="+", type=int, default=[2])
    args = parser.parse_args()
    benchlib.allow_root_mpi()
    ranks_all = [1] + args.check_ranks
    measured: dict[tuple[str, int], list[dict]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        table = scenes(Path(tmp))
        for repeat in range(args.repeats):
            for name, (nml, sets, steps) in table.items():
                for ranks in ranks_all:
                    out = Path(tmp) / f"out-{repeat}"
                    measured.setdefault((name, ranks), []).append(
                        run(args.exe, args.mpiexec, ranks, nml, sets, steps, out))
    # the median run of each scene and rank count (by its time per step)
    med = {key: sorted(v, key=lambda r: r["step"])[len(v) // 2] for key, v in measured.items()}
    k = fit([med[(name, 1)] for name in table if not name.startswith("sediment10k")])
    print(f"coefficients (1-rank fit, median of {args.repeats} runs each): "
          f"a = {k['a'] * 1e9:.2f} ns per cell, b = {k['b'] * 1e9:.1f} ns per link, "
          f"c = {k['c'] * 1e9:.1f} ns per interior node, "
          f"d = {k['d'] * 1e9:.1f} ns per particle and sub-step, "
          f"e = {k['e'] * 1e9:.1f} ns per interior node (refill)")
    print(f"{'scene':<18} {'ranks':>5} {'cells':>8} {'links':>7} {'interior':>8} "
          f"{'held x S':>8} {'bytes':>7} {'ms/step':>8} {'model':>8} {'ratio':>6} "
          f"{'flow':>5}")
    for name in table:
        for ranks in ranks_all:
            r = med[(name, ranks)]
            model = predict(k, r)
            print(f"{name:<18} {ranks:>5} {r['cells']:>8} {r['links']:>7} {r['interior']:>8} "
                  f"{r['held_sub']:>8} {r['bytes']:>7} {r['step'] * 1e3:8.3f} "
                  f"{model * 1e3:8.3f} {r['step'] / model:6.2f} "
                  f"{r['part']['flow'] / r['step']:5.1%}")
    print("ratio: measured over model time per step; flow: the flow's share of the measured step "
          "(time per part)")
    print(f"machine: {benchlib.machine_line()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
