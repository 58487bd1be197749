#!/usr/bin/env python3
"""The pressure wave of a closed box of settling disks, seen in the mean settling velocity.

    tools/suspension_ringing.py RUN.h5 [RUN.h5 ...]

For each run file of a suspension (its /suspension series, sampled a few times per acoustic
period or faster: `--set output.series_interval=0.001` at 16 per D) it prints

- the box's acoustic period T_box = 2 H / c_s, c_s = dx / (dt sqrt 3) the lattice's sound speed,
  and the damping rate of the fluid's fundamental vertical mode, Gamma_fluid = (k^2/2)(nu + zeta),
  k = pi/H, with nu and zeta = c_s^2 (1/s_e - 1/2) dx^2/dt the shear and bulk viscosities (E3);
- the measured period T of the swing of /suspension/v_mean: the strongest peak of the spectrum
  of v_mean less its running mean over T_box, between T_box/2 and 2 T_box (the settling speed's
  slow changes lie below); the trend is then v_mean's running mean over T, which removes the
  swing;
- the swing over the second period, [T, 2T]: half its peak-to-peak, and that over the mean
  settling speed |v_mean| there (docs/suspensions.md, "No ringing box": below 5 %);
- the decay rate of the swing, from a straight line through the logarithm of its half
  peak-to-peak period by period (`nan` when fewer than three periods exceed the noise).

Python 3 with numpy and h5py.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import h5py
import numpy as np


def run_attrs(h5: h5py.File) -> dict[str, float]:
    a = h5["run"].attrs
    return {k: float(np.asarray(a[k]).ravel()[0]) for k in ("dx", "dt", "s_e", "nu_lb", "ny")}


def spectrum_period(t: np.ndarray, x: np.ndarray, shortest: float, longest: float) -> float:
    """The period of the strongest peak of x's spectrum between two periods (x finite)."""
    x = x - x.mean()
    dt = float(np.mean(np.diff(t)))
    n = 16 * (1 << math.ceil(math.log2(len(x))))
    power = np.abs(np.fft.rfft(x * np.hanning(len(x)), n))
    freq = np.fft.rfftfreq(n, dt)
    power[(freq < 1.0 / longest) | (freq > 1.0 / shortest)] = 0.0
    return 1.0 / float(freq[int(np.argmax(power))])


def running_mean(v: np.ndarray, width: int) -> np.ndarray:
    """The centred mean of `width` samples (odd), NaN where it runs off the ends."""
    width = max(1, width | 1)
    out = np.full(len(v), np.nan)
    if width <= len(v):
        c = np.cumsum(np.insert(v, 0, 0.0))
        h = width // 2
        out[h : len(v) - h] = (c[width:] - c[:-width]) / width
    return out


def analyse(path: Path) -> dict[str, float]:
    with h5py.File(path, "r") as h5:
        if "suspension" not in h5:
            raise ValueError(f"{path}: no /suspension series (a scene of three disks or more)")
        t = h5["suspension/t"][()]
        v = h5["suspension/v_mean"][()]
        a = run_attrs(h5)
    if len(t) < 16:
        raise ValueError(f"{path}: {len(t)} samples; sample faster or run longer")
    c_s = a["dx"] / (a["dt"] * math.sqrt(3.0))
    height = a["ny"] * a["dx"]
    nu = a["nu_lb"] * a["dx"] ** 2 / a["dt"]
    zeta = (1.0 / a["s_e"] - 0.5) / 3.0 * a["dx"] ** 2 / a["dt"]
    k = math.pi / height
    t_box = 2.0 * height / c_s
    sample = float(np.mean(np.diff(t)))
    rough = v - running_mean(v, round(t_box / sample))
    ok = np.isfinite(rough)
    period = spectrum_period(t[ok], rough[ok], 0.5 * t_box, 2.0 * t_box)
    trend = running_mean(v, round(period / sample))
    swing = v - trend
    second = (t >= period) & (t < 2 * period) & np.isfinite(swing)
    amplitude = 0.5 * float(np.ptp(swing[second])) if second.sum() > 2 else math.nan
    settling = abs(float(np.mean(v[second]))) if second.sum() > 2 else math.nan
    # half peak-to-peak period by period, then a straight line through their logarithms
    times, amps = [], []
    start = 0.5 * period
    while start + period <= t[-1] - 0.5 * period:
        m = (t >= start) & (t < start + period) & np.isfinite(swing)
        if m.sum() > 2:
            times.append(start + 0.5 * period)
            amps.append(0.5 * float(np.ptp(swing[m])))
        start += period
    decay = math.nan
    amps_a = np.array(amps)
    if len(amps) >= 3 and np.all(amps_a > 0):
        decay = -float(np.polyfit(times, np.log(amps_a), 1)[0])
    return {
        "T_box": t_box,
        "gamma_fluid": 0.5 * k * k * (nu + zeta),
        "T": period,
        "swing": amplitude,
        "settling": settling,
        "ratio": amplitude / settling if settling > 0 else math.nan,
        "gamma": decay,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="+", type=Path, help="run files (RUN.h5)")
    args = parser.parse_args(argv)
    print(
        "run  T_box[s]  T[s]  swing[T,2T][cm/s]  settling[cm/s]  swing/settling  "
        "Gamma[1/s]  Gamma_fluid[1/s]"
    )
    for path in args.runs:
        try:
            r = analyse(path)
        except (OSError, KeyError, ValueError) as err:
            print(f"suspension_ringing.py: {err}", file=sys.stderr)
            return 2
        print(
            f"{path}  {r['T_box']:.4f}  {r['T']:.4f}  {r['swing']:.5f}  {r['settling']:.5f}  "
            f"{100 * r['ratio']:.1f} %  {r['gamma']:.3f}  {r['gamma_fluid']:.3f}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
