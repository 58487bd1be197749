#!/usr/bin/env python3
"""Stability map: the outcome of one settling disk over a grid of tau x particle Reynolds number.

The scene is input/single.nml (D = 0.25 cm, rho_p/rho_f = 1.25, g = 980 cm/s^2, a closed
2 x 6 cm box) at a preview resolution (--cells spacings per diameter, 10 by default). The
particle Reynolds number is set through the viscosity: with the settling speed scale
u_g = sqrt(pi D/2 (rho_p/rho_f - 1) g) of docs/model.md (the velocity scale the input check
and the start-up report use), nu = u_g D / Re_p. The lattice speed of the particle is then
u_g dt/dx = Re_p (tau - 1/2) / (3 N), N spacings per diameter: at a fixed N a large tau reaches
only a small Re_p before the Mach guard, and a tau near 1/2 reaches a large one on a fluid of
lattice viscosity (tau - 1/2)/3 that may not hold it.

Each run lasts long enough for the disk to reach its settling speed from rest (about
pi N r / u_lb steps, r the density ratio, capped at --max-steps) and ends in one of:

- stable: exit 0, stop_reason 'finished', every particle value finite;
- guard: <name>: a run-time guard stopped it (Mach, non-finite, particle speed, particle place);
- refused: the input check refused it (exit status non-zero, no run file);
- NaN: exit 0 but a non-finite value in the output (a guard missed it: a bug);
- hang: no exit within --timeout s (a bug).

Writes <out>/stability_map.csv (one row per run, with the measured Re_max = max |U| D / nu) and
plots tau against Re_p, one marker per outcome, into --png. The table REYNOLDS_MAX of
src/dkt_config_checks_run.f90 (--check warns outside it) is the rule `safe_region` prints from
the CSV.

    tests/perf/stability_map.py                        # the committed grid (docs/stability.md)
    tests/perf/stability_map.py --taus 0.6 --reynolds 10 100 --out /tmp/map

The test helpers it imports are found through PYTHONPATH=postproc:tests (ctest sets it).
"""

from __future__ import annotations

import argparse
import csv
import math
import time
from pathlib import Path

from dkt_run import INPUT, ROOT, run_args

SCENE = INPUT / "single.nml"
# input/single.nml
DIAMETER, RATIO, GRAVITY, WIDTH = 0.25, 1.25, 980.0, 2.0
TAUS = (0.501, 0.505, 0.51, 0.52, 0.55, 0.6, 0.65, 0.8, 1.0, 1.5, 2.0)
REYNOLDS = (1.0, 3.0, 10.0, 30.0, 100.0, 300.0, 600.0, 1200.0)
FIELDS = (
    "tau", "re_p", "cells_per_diameter", "viscosity", "dt", "u_lb", "steps", "outcome",
    "re_measured", "stop_step", "wall_s", "message",
)  # fmt: skip


def settling_scale() -> float:
    """u_g = sqrt(pi D/2 (rho_p/rho_f - 1) g), cm/s (docs/model.md; dkt_config lattice_from)."""
    return math.sqrt(0.5 * math.pi * DIAMETER * (RATIO - 1.0) * GRAVITY)


def scene_for(tau: float, re_p: float, cells: int, max_steps: int) -> dict[str, float]:
    """Viscosity, dt, lattice speed and step count of the grid point (tau, Re_p)."""
    u_g = settling_scale()
    nu = u_g * DIAMETER / re_p
    dx = WIDTH / round(WIDTH * cells / DIAMETER)  # lbm.cells_per_diameter (dkt_config)
    dt = (tau - 0.5) / 3.0 * dx * dx / nu  # E3
    u_lb = u_g * dt / dx
    steps = min(max_steps, max(200, math.ceil(math.pi * cells * RATIO / u_lb)))
    return {"viscosity": nu, "dt": dt, "u_lb": u_lb, "steps": steps}


def classify(proc, h5file: Path) -> tuple[str, float, int, str]:
    """(outcome, measured Re_max, step the run stopped at, message) of a finished process."""
    import h5py
    import numpy as np

    errors = [ln for ln in proc.stderr.splitlines() if ln.startswith("dktlbm: error")]
    message = errors[0].removeprefix("dktlbm: error: ") if errors else ""
    if not h5file.exists():
        return ("refused" if proc.returncode != 0 else "no output"), math.nan, 0, message
    with h5py.File(h5file, "r") as h5:
        reason = h5["run"].attrs["stop_reason"]
        reason = reason.decode() if isinstance(reason, bytes) else str(reason)
        u, v = h5["particles/u"][()], h5["particles/v"][()]
        finite = bool(np.all(np.isfinite(u)) and np.all(np.isfinite(v)))
        for name in h5["fields"]:
            for field in h5["fields"][name].values():
                finite = finite and bool(np.all(np.isfinite(field[()])))
        stop = int(sorted(h5["fields"].keys())[-1]) if len(h5["fields"]) else 0
        speed = float(np.nanmax(np.hypot(u, v))) if u.size else math.nan
    if proc.returncode == 0 and reason == "finished":
        return ("stable" if finite else "NaN"), speed, stop, message
    return guard_name(reason), speed, stop, message


def guard_name(reason: str) -> str:
    """The short name of the guard a stop_reason names."""
    if reason.startswith("particle:"):
        return "guard: particle place"
    if "particle_speed_limit" in reason:
        return "guard: particle speed"
    if "non-finite" in reason:
        return "guard: non-finite"
    if "Mach number" in reason:
        return "guard: Mach"
    return reason.split(":")[0] or "unknown"


def run_point(tau: float, re_p: float, args, out: Path) -> dict[str, object]:
    """Run one grid point and return its CSV row."""
    p = scene_for(tau, re_p, args.cells, args.max_steps)
    run_dir = out / f"tau{tau:g}_re{re_p:g}"
    sets = {
        "lbm.tau": f"{tau:.6g}",
        "lbm.cells_per_diameter": str(args.cells),
        "fluid.viscosity": f"{p['viscosity']:.9g}",
        "run.steps": str(p["steps"]),
        "run.progress_every": "0",
        "output.series_interval": f"{p['dt'] * max(1, p['steps'] // 200):.9g}",
        "output.field_interval": "0",
        "output.overwrite": ".true.",
        "output.dir": str(run_dir),
    }
    cmd = [str(SCENE)]
    for key, value in sets.items():
        cmd += ["--set", f"{key}={value}"]
    start = time.perf_counter()
    try:
        proc = run_args(cmd, args.ranks, args.timeout, out)
        outcome, speed, stop, message = classify(proc, run_dir / "single.h5")
    except AssertionError as hang:
        outcome, speed, stop, message = "hang", math.nan, 0, str(hang).splitlines()[0]
    wall = time.perf_counter() - start
    return {
        "tau": tau,
        "re_p": re_p,
        "cells_per_diameter": args.cells,
        "viscosity": f"{p['viscosity']:.6g}",
        "dt": f"{p['dt']:.6g}",
        "u_lb": f"{p['u_lb']:.6g}",
        "steps": p["steps"],
        "outcome": outcome,
        "re_measured": f"{speed * DIAMETER / p['viscosity']:.4g}",
        "stop_step": stop,
        "wall_s": f"{wall:.2f}",
        "message": message[:200],
    }


def safe_region(rows: list[dict[str, str]]) -> dict[float, float]:
    """Re_max(tau): per tau, the largest Re_p below which every run of the grid was stable
    (0 when the smallest already was not). The rule --check applies
    (src/dkt_config_checks_run.f90)."""
    region = {}
    for tau in sorted({float(r["tau"]) for r in rows}):
        best = 0.0
        for r in sorted(
            (r for r in rows if float(r["tau"]) == tau), key=lambda r: float(r["re_p"])
        ):
            if r["outcome"] != "stable":
                break
            best = float(r["re_p"])
        region[tau] = best
    return region


MARKERS = {
    "stable": ("o", "tab:green"),
    "guard: Mach": ("^", "tab:orange"),
    "guard: non-finite": ("X", "tab:red"),
    "guard: particle speed": ("s", "tab:purple"),
    "guard: particle place": ("D", "tab:brown"),
    "refused": ("v", "tab:gray"),
    "NaN": ("*", "black"),
    "hang": ("P", "black"),
}


def plot(rows: list[dict[str, str]], png: Path, cells: int) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.0, 4.5))
    for outcome, (marker, colour) in MARKERS.items():
        pts = [(float(r["tau"]) - 0.5, float(r["re_p"])) for r in rows if r["outcome"] == outcome]
        if pts:
            x, y = zip(*pts, strict=True)
            ax.scatter(x, y, marker=marker, color=colour, s=60, label=outcome)
    # the Mach bound of the start-up check: u_g dt/dx = mach_limit c_s
    taus = [t - 0.5 for t in sorted({float(r["tau"]) for r in rows})]
    ax.plot(taus, [0.3 * math.sqrt(1 / 3) * 3 * cells / t for t in taus], "k--", lw=0.8,
            label="expected Mach 0.3")  # fmt: skip
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("tau - 1/2")
    ax.set_ylabel("particle Reynolds number u_g D / nu")
    ax.set_title(f"single disk (input/single.nml), {cells} spacings per diameter")
    ax.legend(fontsize=8, loc="lower left")
    fig.tight_layout()
    fig.savefig(png, dpi=110)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--taus", type=float, nargs="+", default=TAUS)
    ap.add_argument("--reynolds", type=float, nargs="+", default=REYNOLDS)
    ap.add_argument("--cells", type=int, default=10, help="spacings per diameter")
    ap.add_argument("--max-steps", type=int, default=20000)
    ap.add_argument("--ranks", type=int, default=1)
    ap.add_argument("--timeout", type=float, default=120.0, help="s per run; longer is a hang")
    ap.add_argument("--out", type=Path, default=Path("stability_map"))
    ap.add_argument("--png", type=Path, default=ROOT / "docs" / "img" / "stability_map.png")
    ap.add_argument("--csv", type=Path, default=None, help="default <out>/stability_map.csv")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    csv_path = args.csv or args.out / "stability_map.csv"
    rows = []
    for tau in args.taus:
        for re_p in args.reynolds:
            row = run_point(tau, re_p, args, args.out.resolve())
            print(f"tau {tau:<6g} Re_p {re_p:<6g} {row['outcome']:<24} "
                  f"Re_meas {row['re_measured']:<8} {row['wall_s']} s", flush=True)  # fmt: skip
            rows.append(row)
    with csv_path.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=FIELDS)
        writer.writeheader()
        writer.writerows(rows)
    rows = [{k: str(v) for k, v in r.items()} for r in rows]
    plot(rows, args.png, args.cells)
    print("Re_max(tau), the largest Re_p below which every run was stable:")
    for tau, re_max in safe_region(rows).items():
        print(f"  tau {tau:g}: {re_max:g}")


if __name__ == "__main__":
    main()
