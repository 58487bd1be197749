#!/usr/bin/env python3
"""A stand-in for dktlbm in the map tests: called with dktlbm's arguments (`SCENE --set
pair.gamma=G --set pair.dh=H ... --set run.t_end=T [--set window.above=A] --set
output.dir=DIR`), it writes DIR/<scene name>.h5 and its log as bisect_fake.py does, for a
pair whose pattern is a known function of (gamma, dh) with two straight borders:

- gamma < repeated_below(dh) = 1.23 + 0.1 dh: 'repeated' (kisses at 1.0 and 1.5 s; within
  LATE_BAND below the border at 1.0 and 6.0 s, with the upper particle gaining: 'once' and
  closing in at t_end = 4 s, not settled; 'repeated' at 8 s);
- else gamma < once_below(dh) = 1.97 + 0.13 dh: 'once' (one kiss at 1.0 s);
- else 'never', and the upper particle leaves the window at 0.75 T A / 15 (A = window.above,
  default 15) when that is before T: with A = 15 by window_escape, with A = 30 it finishes.

With FAKE_LOG in the environment each call appends a line `gamma dh t_end above` to that
file, so a test counts the runs the program was asked for. `python3 map_fake.py ARGS...`
acts as the program. Its files store the scales as the program does, so reading them needs no
executable.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import bisect_fake

LATE_BAND = 0.05


def repeated_below(dh: float) -> float:
    return 1.23 + 0.1 * dh


def once_below(dh: float) -> float:
    return 1.97 + 0.13 * dh


def pattern(gamma: float, dh: float) -> str:
    """The settled pattern at (gamma, dh): the truth the map must find."""
    if gamma < repeated_below(dh):
        return "repeated"
    return "once" if gamma < once_below(dh) else "never"


def late(gamma: float, dh: float) -> bool:
    """Whether the second kiss comes late (the band below the repeated-to-once border)."""
    return 0 < repeated_below(dh) - gamma < LATE_BAND


def behaviour(gamma: float, dh: float, t_end: float,
              above: float) -> tuple[list[float], str, float, float]:
    """(episode starts, stop_reason, time the run ends, velocity of the upper particle)."""
    kind = pattern(gamma, dh)
    starts = {"repeated": [1.0, 6.0 if late(gamma, dh) else 1.5], "once": [1.0],
              "never": []}[kind]
    reason, t_stop = "finished", t_end
    if kind == "never" and 0.75 * t_end * above / 15.0 < t_end:
        reason, t_stop = "window_escape", 0.75 * t_end * above / 15.0
    v_upper = -1.05 if late(gamma, dh) else -0.8
    return [s for s in starts if s <= t_stop], reason, t_stop, v_upper


def main(argv: list[str]) -> int:
    s = bisect_fake.settings(argv)
    gamma, dh = float(s["pair.gamma"]), float(s["pair.dh"])
    t_end, above = float(s["run.t_end"]), float(s.get("window.above", 15.0))
    if os.environ.get("FAKE_LOG"):
        with open(os.environ["FAKE_LOG"], "a") as f:
            f.write(f"{gamma:.8g} {dh:.8g} {t_end:g} {above:g}\n")
    return bisect_fake.write_run(Path(s["output.dir"]), Path(argv[0]).stem,
                                 {"gamma": gamma, "dh": dh},
                                 behaviour(gamma, dh, t_end, above), t_end, scales=True)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
