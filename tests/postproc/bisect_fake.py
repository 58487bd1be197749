#!/usr/bin/env python3
"""A stand-in for dktlbm in the bisection tests: called with dktlbm's arguments (`SCENE --set
pair.gamma=V|pair.dh=V ... --set run.t_end=T --set output.dir=DIR`), it writes DIR/<scene
name>.h5 after the output contract (/run, /particles, /diagnostics with its episodes) and a
log with a `performance:` line, for a pair whose pattern is a known function of V and T:

- V >= THRESHOLD: one kissing episode, at 1.0 s ('once');
- V < THRESHOLD: two, at 1.0 s and at 1.5 s, or at 6.0 s when THRESHOLD - V < LATE_BAND (the
  second kiss comes late near the threshold, and the upper particle gains on the lower one
  from the start: with T = 4 the pattern is 'once' by T/2 and by T, with the pair closing in,
  not settled; with T = 8 it is 'repeated');
- otherwise the upper particle sinks slower than the lower one (separating);
- V >= ESCAPE: the upper particle leaves the window at 0.75 T A / 30 (A = window.above, in
  D_1, default 15) when that is before T: by window_escape at 0.375 T with A = 15, at
  0.75 T with A = 30; with A = 60 the run finishes. With window.max_above = M > 0 the window
  grows by itself up to M (docs/model.md §5), so A is M for this rule;
- V >= GUARD: stopped by a guard at 0.5 T, exit status 3;
- V >= FAKE_NEVER (from the environment; default: no such band): no episode ('never');
- FAKE_SIGNAL_AT (s, from the environment): a run that would go on past it stops there by
  a signal, as a run does at SIGUSR1 or SIGTERM (exit status 0, the episodes so far written,
  <name>.checkpoint naming a checkpoint, which is not written).

An episode counts when it starts within the run. The environment may move THRESHOLD
(FAKE_THRESHOLD). `python3 bisect_fake.py ARGS...` acts as the program.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import h5py
import numpy as np

THRESHOLD = 1.37
LATE_BAND = 0.1
ESCAPE = 1.9
GUARD = 10.0
DT = 0.01  # s, the time step written to /run
SAMPLE = 0.05  # s


def settings(argv: list[str]) -> dict[str, str]:
    return {
        a.partition("=")[0]: a.partition("=")[2]
        for k, a in enumerate(argv)
        if k > 0 and argv[k - 1] == "--set"
    }


def late(value: float) -> bool:
    """Whether the second kiss comes late (the band below the threshold)."""
    return 0 < float(os.environ.get("FAKE_THRESHOLD", THRESHOLD)) - value < LATE_BAND


def behaviour(value: float, t_end: float, above: float) -> tuple[list[float], str, float, float]:
    """(episode starts, stop_reason, time the run ends, velocity of the upper particle)."""
    threshold = float(os.environ.get("FAKE_THRESHOLD", THRESHOLD))
    if value >= float(os.environ.get("FAKE_NEVER", "inf")):
        starts = []
    elif value >= threshold:
        starts = [1.0]
    else:
        starts = [1.0, 6.0 if late(value) else 1.5]
    reason, t_stop, v_upper = "finished", t_end, -1.05 if late(value) else -0.8
    if value >= GUARD:
        reason, t_stop = "guard: non-finite velocity", 0.5 * t_end
    elif value >= ESCAPE and 0.75 * t_end * above / 30.0 < t_end:
        reason, t_stop = "window_escape", 0.75 * t_end * above / 30.0
    signal_at = float(os.environ.get("FAKE_SIGNAL_AT", "inf"))
    if signal_at < t_stop:
        reason, t_stop = "signal", signal_at
    return [s for s in starts if s <= t_stop], reason, t_stop, v_upper


def write(out: Path, name: str, key: str, value: float, t_end: float, above: float) -> int:
    return write_run(out, name, {key: value}, behaviour(value, t_end, above), t_end)


# the scales a run file of dktlbm 0.1 on stores in /run (read.open_run needs the executable for
# a file without them): H = 18 cm, g = 981 cm/s^2, t_ref = sqrt(H/g)
SCALES = {"t_ref": (18.0 / 981.0) ** 0.5, "h_ref": 18.0, "gravity": 981.0, "width": 2.0,
          "rho_f": 1.0, "mu": 0.01}


def write_run(out: Path, name: str, pair: dict[str, float],
              behaved: tuple[list[float], str, float, float], t_end: float,
              scales: bool = False) -> int:
    """Write the run file and log of a run to `t_end` of the pair settings `pair` that
    behaves as `behaved` (behaviour's tuple); the program's exit status. With `scales` the
    file stores SCALES as the program does (else, as the bisection tests' files, it does not,
    and reading it asks the executable for them)."""
    starts, reason, t_stop, v_upper = behaved
    out.mkdir(parents=True, exist_ok=True)
    t = np.arange(0.0, t_stop + 1e-9, SAMPLE)
    n = t.size
    d1, d2 = 0.2, 0.1
    y_low = 10.0 - 1.0 * t  # the lower particle sinks at 1 cm/s
    y_up = 10.6 + v_upper * t
    series = {
        "x": np.ones((n, 2)),
        "y": np.stack([y_up, y_low], axis=1),
        "u": np.zeros((n, 2)),
        "v": np.tile([v_upper, -1.0], (n, 1)),
        "omega": np.zeros((n, 2)),
        "fx": np.zeros((n, 2)),
        "fy": np.zeros((n, 2)),
        "torque": np.zeros((n, 2)),
    }
    dr = y_up - y_low - 0.5 * (d1 + d2)
    pattern = "repeated" if len(starts) >= 2 else "once" if starts else "never"
    with h5py.File(out / f"{name}.h5", "w") as h5:
        run = h5.create_group("run")
        given = ", ".join(f"{k} = {v}" for k, v in pair.items())
        run.attrs["namelist"] = np.bytes_(f"&pair\n  {given}, d1 = {d1}\n/\n".encode())
        run.attrs["stop_reason"] = np.bytes_(reason.encode())
        for k, v in (
            ("dt", DT),
            ("dx", 0.01),
            ("steps", round(t_end / DT)),
            ("diameter_1", d1),
            ("diameter_2", d2),
            *(SCALES.items() if scales else ()),
        ):
            run.attrs[k] = float(v)
        p = h5.create_group("particles")
        p.attrs["count"] = np.int32(2)
        p["t"] = t
        for k, v in series.items():
            p[k] = v
        d = h5.create_group("diagnostics")
        d["t"], d["dr"] = t, dr
        d["dx"], d["dy"] = np.zeros(n), y_up - y_low
        d.attrs["pattern"] = np.bytes_(pattern.encode())
        d.attrs["episodes"] = np.int32(len(starts))
        d.attrs["open_episode"] = np.int32(0)
        for k, v in (
            ("d1", d1),
            ("gamma", d1 / d2),
            ("dh", 2.5),
            ("kiss_enter", 0.02),
            ("kiss_release", 0.05),
        ):
            d.attrs[k] = float(v)
        if starts:
            e = d.create_group("episodes")
            e["start"] = np.asarray(starts)
            e["end"] = np.asarray(starts) + 0.2
    if reason == "signal":  # the program names its last checkpoint in <name>.checkpoint
        (out / f"{name}.checkpoint").write_text(
            f"{out / f'{name}_chk_{round(t_stop / DT):09d}.h5'}\n")
    (out / f"{name}.log").write_text(
        f"stand-in dktlbm\nperformance:      1.00 MLUPS (1 cells x 1 steps in     "
        f"{0.01 * t_stop:.3f} s on 1 ranks)\n"
    )
    return 3 if reason.startswith("guard") else 0


def main(argv: list[str]) -> int:
    s = settings(argv)
    key = "gamma" if "pair.gamma" in s else "dh"
    return write(
        Path(s["output.dir"]),
        Path(argv[0]).stem,
        key,
        float(s[f"pair.{key}"]),
        float(s["run.t_end"]),
        max(float(s.get("window.above", 15.0)), float(s.get("window.max_above", 0.0))),
    )


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
