"""The DKT pattern of a run: repeated (two or more kissing episodes), once (one) or never
(none), with each episode's start and end (s and t*) and its smallest gap, the thresholds
used, gamma = D_1/D_2 and D_h/D_1.

A file with /diagnostics is reported as the program classified it. Giving any threshold
option classifies the gap again here, the options not given keeping the run's own settings
(stored in /run; for older files its namelist and dktlbm's defaults, asked of the executable):
enter = max(enter_cells dx, enter_d1 D_1), release = max(release_cells dx, release_d1 D_1).
A file without /diagnostics is classified here from /particles with its own settings. A run
that stopped early (a guard, a signal, the wall limit, an error) is classified up to where it
stopped, and the report says so and why (JSON: stop_reason, complete)."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

from .read import Pair, RunFileError, add_version, fmt, guarded, open_run, pair_of


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="dkt-pattern",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n  dkt-pattern runs/case1/case1.h5\n"
        "  dkt-pattern runs/case1/case1.h5 --json --enter-cells 1",
    )
    add_version(p)
    p.add_argument("run", type=Path, metavar="RUN.h5", help="a dktlbm run file")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    p.add_argument("--enter-cells", type=float, metavar="N",
                   help="an episode starts at D_r <= N lattice spacings (or --enter-d1)")
    p.add_argument("--enter-d1", type=float, metavar="F",
                   help="an episode starts at D_r <= F D_1 (or --enter-cells)")
    p.add_argument("--release-cells", type=float, metavar="N",
                   help="an episode ends at D_r > N lattice spacings (and --release-d1)")
    p.add_argument("--release-d1", type=float, metavar="F",
                   help="an episode ends at D_r > F D_1 (and --release-cells)")
    p.add_argument("--terminal", type=float, metavar="TSTAR",
                   help="also each particle's terminal Reynolds number: the mean of Re = "
                   "rho_f |U| D_p / mu over t* >= TSTAR, with its range there (refused when "
                   "the run ends before TSTAR)")
    return p


def terminal(pair: Pair, from_tstar: float) -> dict[str, Any]:
    """Each particle's Re over t* >= from_tstar: mean, min, max and the number of samples.
    A run that ended by window_escape lost its upper particle there, so its values are those
    up to the escape (the report's stop_reason says so)."""
    tstar = pair.tstar
    keep = tstar >= from_tstar
    if keep.sum() < 2:
        raise RunFileError(pair.run.path, f"the run ends at t* = {tstar[-1]:.4g}, before "
                           f"--terminal {from_tstar:g}: nothing to average")
    re = pair.re[keep]
    return {
        "from_tstar": from_tstar,
        "to_tstar": float(tstar[-1]),
        "samples": int(keep.sum()),
        "re_mean": [float(x) for x in re.mean(axis=0)],
        "re_min": [float(x) for x in re.min(axis=0)],
        "re_max": [float(x) for x in re.max(axis=0)],
        "diameter": [float(d) for d in pair.run.diameters[:2]],
    }


def _num(x: float) -> float | None:
    return x if math.isfinite(x) else None


def report(pair: Pair) -> dict[str, Any]:
    """The pattern of `pair` as a JSON-ready dictionary."""
    t_ref = pair.run.t_ref
    lim = pair.limits
    return {
        "file": str(pair.run.path),
        "pattern": pair.pattern,
        "episodes": len(pair.episodes),
        "open_episode": pair.open_episode,
        "gamma": _num(pair.gamma),
        "dh": _num(pair.dh),
        "d1": _num(pair.d1),
        "t_ref": t_ref,
        "thresholds": {
            "enter_cm": _num(lim.enter),
            "release_cm": _num(lim.release),
            "enter_cells": _num(lim.enter_cells),
            "release_cells": _num(lim.release_cells),
            "enter_d1": _num(lim.enter_d1),
            "release_d1": _num(lim.release_d1),
            "dx": _num(lim.dx),
            "rule": lim.rule,
        },
        "source": pair.source,
        "kissing": [
            {
                "start": e.start,
                "end": e.end,
                "start_tstar": e.start / t_ref,
                "end_tstar": e.end / t_ref,
                "min_gap": _num(e.min_gap),
                "min_gap_d1": _num(e.min_gap / pair.d1),
                "open": e.open,
            }
            for e in pair.episodes
        ],
        "t_end": float(pair.t[-1]) if pair.t.size else None,
        # why the run ended ('' for files that predate it); a pattern of a run that stopped
        # early covers only the part it computed
        "stop_reason": pair.run.stop_reason,
        "complete": pair.run.complete,
    }


def _s(value: float | None, digits: int = 4) -> str:
    return "nan" if value is None else fmt(value, digits)


def text(r: dict[str, Any]) -> str:
    th = r["thresholds"]
    n = r["episodes"]
    lines = [
        f"{r['file']}: pattern {r['pattern']} ({n} kissing episode{'s' if n != 1 else ''}"
        f"{', the last still open at the end' if r['open_episode'] else ''})",
        f"  gamma = D_1/D_2 = {_s(r['gamma'])}, D_h/D_1 = "
        f"{_s(r['dh'])}, D_1 = {_s(r['d1'])} cm",
        f"  thresholds ({th['rule']}): kissing starts at D_r <= {_s(th['enter_cm'])} cm "
        f"({_s(th['enter_cells'], 3)} lattice spacings, "
        f"{_s(th['enter_d1'], 3)} D_1),",
        f"    ends at D_r > {_s(th['release_cm'])} cm "
        f"({_s(th['release_cells'], 3)} lattice spacings, "
        f"{_s(th['release_d1'], 3)} D_1); lattice spacing "
        f"{_s(th['dx'])} cm",
        f"  classification: {r['source']}; run ends at t = {_s(r['t_end'])} s, "
        f"t_r = {fmt(r['t_ref'])} s",
    ]
    if not r["complete"]:
        lines.append(f"  incomplete: the run stopped early ({r['stop_reason']}); the pattern "
                     f"covers t <= {_s(r['t_end'])} s only")
    if "terminal" in r:
        t = r["terminal"]
        lines.append(f"  terminal Reynolds numbers, mean over t* = {t['from_tstar']:.4g} .. "
                     f"{t['to_tstar']:.4g} ({t['samples']} samples; range):")
        for k in range(2):
            lines.append(f"    particle {k + 1} (D = {_s(t['diameter'][k])} cm): Re = "
                         f"{t['re_mean'][k]:.4g} ({t['re_min'][k]:.4g} .. "
                         f"{t['re_max'][k]:.4g})")
    for k, e in enumerate(r["kissing"], 1):
        gap, gap_d1 = _s(e["min_gap"]), _s(e["min_gap_d1"], 3)
        lines.append(
            f"  episode {k}: t = {e['start']:.4f} .. {e['end']:.4f} s "
            f"(t* = {e['start_tstar']:.3f} .. {e['end_tstar']:.3f}), min D_r = {gap} cm "
            f"({gap_d1} D_1){', open at the end of the run' if e['open'] else ''}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    limits = {
        "enter_cells": args.enter_cells,
        "enter_d1": args.enter_d1,
        "release_cells": args.release_cells,
        "release_d1": args.release_d1,
    }
    given = {k: v for k, v in limits.items() if v is not None}

    def body() -> int:
        pair = pair_of(open_run(args.run, need_particles=2), given or None)
        r = report(pair)
        if args.terminal is not None:
            r["terminal"] = terminal(pair, args.terminal)
        print(json.dumps(r, indent=2) if args.json else text(r))
        return 0

    return guarded(body)


if __name__ == "__main__":
    sys.exit(main())
