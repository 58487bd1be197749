"""Synthetic dktlbm run files for the post-processing tests, written with h5py after the output
contract (docs/design.md, "Output", the /diagnostics layout of the pair scenes).

The surface gap D_r(t) of the pair is a piecewise-linear curve through chosen knots, so the
times at which it crosses a threshold are known exactly (`crossing`), independently of the
code under test. Particle 2 sinks at a steady 0.8 cm/s on x = 1; particle 1 sits above it,
swaying slightly across (D_x = 0.02 sin 2t), at the centre distance that gives that gap.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

DX = 0.01  # cm, lattice spacing written to /run
DT = 0.001  # s, time step written to /run (= the sampling interval)
T_END = 3.0
T = np.linspace(0.0, T_END, 3001)  # s, one sample per step
D1 = 0.2  # cm
# the default thresholds for DX and D1 (docs/model.md §6): max(2 dx, 0.05 D_1), max(4 dx, 0.25 D_1)
ENTER = max(2 * DX, 0.05 * D1)  # 0.02 cm
RELEASE = max(4 * DX, 0.25 * D1)  # 0.05 cm
WIDTH = 2.0  # cm
NY_WINDOW = 300  # rows of the stored fields (3 cm)
FIELD_TIMES = (0.0, 1.5, 3.0)

Knots = list[tuple[float, float]]
# gap shapes (t in s, D_r in cm); comments give the pattern under ENTER/RELEASE
SHAPES: dict[str, Knots] = {
    # two dips below ENTER separated by a rise above RELEASE
    "repeated": [(0.0, 0.4), (1.0, 0.005), (1.3, 0.005), (1.6, 0.1), (2.0, 0.005), (2.3, 0.2),
                 (3.0, 0.6)],
    # two dips, but the rise between them (0.04) stays below RELEASE: one episode
    "once": [(0.0, 0.4), (1.0, 0.01), (1.2, 0.04), (1.4, 0.01), (1.8, 0.3), (3.0, 0.5)],
    # the gap closes to 0.03, never down to ENTER
    "never": [(0.0, 0.4), (1.5, 0.03), (3.0, 0.35)],
    # one dip that lasts to the end of the run: an open episode
    "open": [(0.0, 0.4), (2.5, 0.01), (3.0, 0.008)],
}


def gap(knots: Knots, t: np.ndarray = T) -> np.ndarray:
    ts, drs = zip(*knots, strict=True)
    return np.interp(t, ts, drs)


def crossing(knots: Knots, segment: int, level: float) -> float:
    """The time at which segment `segment` (knots[segment] to knots[segment + 1]) passes
    `level`."""
    (t0, d0), (t1, d1) = knots[segment], knots[segment + 1]
    assert min(d0, d1) < level < max(d0, d1), "the segment does not cross the level"
    return t0 + (level - d0) * (t1 - t0) / (d1 - d0)


def first_sample_at_or_after(time: float) -> float:
    return float(T[np.searchsorted(T, time - 1e-12)])


NAMELIST = """! synthetic run
&domain
  width = {width}, height = 3.0        ! cm
/
&fluid
  density = {rho}, viscosity = {mu}
/
&particles
  count = {count}
  diameter = {diameters}
  gravity = {gravity}
/
&run
  t_ref = {t_ref}
/
"""


def write_run(
    path: Path,
    knots: Knots,
    diameters: tuple[float, ...] = (D1, D1),
    *,
    diagnostics: dict | None = None,
    finished: bool = True,
    window: bool = True,
    fields: bool = True,
    t_ref: float = 0.135526,
    gravity: float = 980.0,
    width: float = WIDTH,
    rho: float = 1.0,
    mu: float = 0.01,
    across: float = 0.0,
) -> dict[str, np.ndarray]:
    """Write a run file at `path` whose pair gap follows `knots`; return its series (t, x, y,
    u, v, fy, dr, dx, dy). `diagnostics`: None for no /diagnostics group, else
    {"attrs": {...}, "episodes": [(start, end), ...]} written with the computed series.
    `across` (cm): particle 1 also moves aside, linearly from 0 at 2 s to `across` at the end
    (the gap stays as the knots say)."""
    count = len(diameters)
    n = T.size
    dr = gap(knots)
    r_sum = 0.5 * (diameters[0] + diameters[1]) if count > 1 else 0.0
    sway = 0.02 * np.sin(2.0 * T) + across * np.clip((T - 2.0) / (T_END - 2.0), 0.0, 1.0)
    x = np.empty((n, count))
    y = np.empty((n, count))
    x[:, -1] = 1.0
    y[:, -1] = 12.0 - 0.8 * T
    if count > 1:
        x[:, 0] = 1.0 + sway
        y[:, 0] = y[:, 1] + np.sqrt((dr + r_sum) ** 2 - sway**2)
    u = np.gradient(x, T, axis=0)
    v = np.gradient(y, T, axis=0)
    omega = 0.5 * np.sin(T)[:, None] * np.where(np.arange(count) % 2 == 0, 1.0, -1.0)
    fy = (0.02 + 0.01 * T)[:, None] * np.ones(count)
    nml = NAMELIST.format(
        width=width, rho=rho, mu=mu, count=count, gravity=gravity, t_ref=t_ref,
        diameters=", ".join(f"{d}" for d in diameters))
    steps = round(T_END / DT) * (1 if finished else 2)
    offset = 10.5 - 0.8 * T if window else np.zeros(n)

    path.parent.mkdir(parents=True, exist_ok=True)
    with h5py.File(path, "w") as h5:
        run = h5.create_group("run")
        run.attrs["namelist"] = np.bytes_(nml.encode())
        for key, value in (("dx", DX), ("dt", DT), ("nx", WIDTH / DX), ("ny", NY_WINDOW),
                           ("steps", steps), ("tau", 0.65)):
            run.attrs[key] = float(value)
        p = h5.create_group("particles")
        p.attrs["count"] = np.int32(count)
        p["t"] = T
        for name, data in (("x", x), ("y", y), ("u", u), ("v", v), ("omega", omega),
                           ("fx", np.zeros((n, count))), ("fy", fy),
                           ("torque", np.zeros((n, count)))):
            p[name] = data
        if window:
            p["window_offset"] = offset
        if fields:
            _write_fields(h5, x, y, np.asarray(diameters), offset)
        if diagnostics is not None:
            _write_diagnostics(h5, diagnostics, x, y, dr, u, v, fy, diameters, t_ref, rho, mu)
    return {"t": T, "x": x, "y": y, "u": u, "v": v, "fy": fy, "dr": dr,
            "dx": x[:, 0] - x[:, -1], "dy": y[:, 0] - y[:, -1]}


def _write_fields(h5: h5py.File, x: np.ndarray, y: np.ndarray, diameters: np.ndarray,
                  offset: np.ndarray) -> None:
    nx = round(WIDTH / DX)
    g = h5.create_group("fields")
    for t in FIELD_TIMES:
        i = int(np.argmin(np.abs(T - t)))
        xs = (np.arange(nx) + 0.5) * DX
        ys = (np.arange(NY_WINDOW) + 0.5) * DX + offset[i]
        xx, yy = np.meshgrid(xs, ys)  # (ny, nx)
        solid = np.zeros((NY_WINDOW, nx), dtype=np.int32)
        for k in range(x.shape[1]):
            inside = np.hypot(xx - x[i, k], yy - y[i, k]) <= 0.5 * diameters[k]
            solid[inside] = k + 1
        s = g.create_group(f"{i:06d}")
        s.attrs["time"] = float(T[i])
        s.attrs["step"] = np.int32(i)
        s.attrs["window_offset"] = float(offset[i])
        s["ux"] = np.sin(np.pi * xx / WIDTH) * 0.1
        s["uy"] = np.cos(yy) * 0.2
        s["vorticity"] = np.sin(2 * np.pi * xx / WIDTH) * np.cos(yy)
        s["rho"] = 1.0 + 0.001 * np.cos(yy)
        s["pressure"] = s["rho"][()] / 3.0
        s["particle"] = solid


def _write_diagnostics(h5: h5py.File, spec: dict, x: np.ndarray, y: np.ndarray,
                       dr: np.ndarray, u: np.ndarray, v: np.ndarray, fy: np.ndarray,
                       diameters: tuple[float, ...], t_ref: float, rho: float,
                       mu: float) -> None:
    d = h5.create_group("diagnostics")
    d1 = diameters[0]
    speed = np.hypot(u[:, :2], v[:, :2])
    dp = np.asarray(diameters[:2])[None, :]
    d["t"] = T
    d["tstar"] = T / t_ref
    d["dx"] = x[:, 0] - x[:, 1]
    d["dy"] = y[:, 0] - y[:, 1]
    d["dr"] = dr
    d["dr_star"] = dr / d1
    d["re"] = rho * speed * dp / mu
    with np.errstate(divide="ignore", invalid="ignore"):
        d["cd"] = np.where(speed > 0, fy[:, :2] / (0.5 * rho * speed**2 * dp), np.nan)
    attrs = {
        "d1": d1, "gamma": diameters[0] / diameters[1],
        "dh": abs(y[0, 0] - y[0, 1]) / d1, "t_ref": t_ref, "h_ref": 18.0,
        "gravity": 980.0, "width": WIDTH,
        "kiss_enter_cells": 2.0, "kiss_release_cells": 4.0,
        "kiss_enter": ENTER, "kiss_release": RELEASE,
    }
    attrs.update(spec.get("attrs", {}))
    for key, value in attrs.items():
        if key == "pattern":
            d.attrs[key] = np.bytes_(str(value).encode())
        elif isinstance(value, int):
            d.attrs[key] = np.int32(value)
        else:
            d.attrs[key] = float(value)
    episodes = spec.get("episodes", [])
    if episodes:
        e = d.create_group("episodes")
        e["start"] = np.array([a for a, _ in episodes], dtype=float)
        e["end"] = np.array([b for _, b in episodes], dtype=float)
