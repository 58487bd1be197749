"""Analytic flows through the whole program (docs/model.md E1–E5): what each test proves is
its name.

Every run is compared with a closed-form solution computed here from the inputs, never with an
earlier output of the program.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from dkt_run import last_fields, run, run_attr


def centres(n: int, dx: float) -> np.ndarray:
    """Node positions: cell centres, walls half a spacing outside the first and last node."""
    return (np.arange(n) + 0.5) * dx


def poiseuille_error(tmp_path: Path, sets: list[str]) -> float:
    out = tmp_path / "run"
    run("poiseuille.nml", 1, sets, out)
    fields, _ = last_fields(out / "poiseuille.h5")
    uy = fields["uy"]
    dx = run_attr(out / "poiseuille.h5", "dx")
    width, g, nu = 1.0, 1.0e-5, 0.01  # input/poiseuille.nml
    x = centres(uy.shape[1], dx)
    exact = g * x * (width - x) / (2.0 * nu)
    assert np.max(np.abs(fields["ux"])) < 1e-10 * exact.max()
    return float(np.max(np.abs(uy - exact[None, :])) / exact.max())


def test_poiseuille_is_exact_with_the_e3_heat_flux_rate(tmp_path: Path) -> None:
    err = poiseuille_error(tmp_path, [])
    assert err < 1e-10, f"relative error {err:.3e}"


def test_poiseuille_is_measurably_wrong_without_the_e3_rate(tmp_path: Path) -> None:
    # s_q = s_nu (BGK-like odd moments): the wall is no longer exactly half-way, an O(dx^2)
    # slip appears; it must be far above the round-off level the E3 rate reaches.
    err = poiseuille_error(tmp_path, ["lbm.s_q=1.0"])
    assert err > 1e-5, f"relative error {err:.3e} is not measurably different from exact"


def taylor_green_error(tmp_path: Path, cells: int) -> float:
    out = tmp_path / f"tg{cells}"
    run("taylor_green.nml", 1, [f"lbm.dx={1.0 / cells!r}"], out)
    h5 = out / "taylor_green.h5"
    fields, attrs = last_fields(h5)
    t = attrs["time"]
    u0, nu, length = 0.1, 0.01, 1.0  # input/taylor_green.nml
    k = 2.0 * math.pi / length
    x = centres(cells, 1.0 / cells)
    xx, yy = np.meshgrid(x, x)  # arrays are (ny, nx)
    decay = math.exp(-2.0 * nu * k * k * t)
    ux = -u0 * np.cos(k * xx) * np.sin(k * yy) * decay
    uy = u0 * np.sin(k * xx) * np.cos(k * yy) * decay
    diff = (fields["ux"] - ux) ** 2 + (fields["uy"] - uy) ** 2
    return float(np.sqrt(diff.sum() / (ux**2 + uy**2).sum()))


def test_taylor_green_decay_converges_at_second_order(tmp_path: Path) -> None:
    errors = [taylor_green_error(tmp_path, n) for n in (16, 32, 64)]
    orders = [math.log2(errors[i] / errors[i + 1]) for i in range(2)]
    print("Taylor-Green L2 errors", errors, "orders", orders)
    assert all(o > 1.8 for o in orders), f"errors {errors}, observed orders {orders}"


def test_open_channel_with_parabolic_inlet_develops_the_poiseuille_profile(
    tmp_path: Path,
) -> None:
    out = tmp_path / "inlet"
    run("inlet_channel.nml", 2, [], out)
    fields, _ = last_fields(out / "inlet_channel.h5")
    uy, ux = fields["uy"], fields["ux"]
    ny, nx = uy.shape
    dx = 8.0 / ny
    umax = 0.5  # inlet centreline velocity, input/inlet_channel.nml
    xi = centres(nx, 1.0 / nx)
    exact = umax * 4.0 * xi * (1.0 - xi)
    row = int(0.75 * ny)  # 6 cm downstream of the inlet, 2 cm before the outflow
    err = np.max(np.abs(uy[row] - exact)) / umax
    assert err < 0.01, f"profile at y = {row * dx:.2f} cm differs by {err:.3e} of U"
    assert np.max(np.abs(ux[row])) < 0.01 * umax
    # mass: in the steady state the flux of rho*u is the same through every row between the
    # two end rows (whose density or velocity E5 sets)
    mass = (fields["rho"] * uy).sum(axis=1)[1:-1]
    spread = np.ptp(mass) / mass.mean()
    assert spread < 1e-5, f"mass flux varies by {spread:.3e} along the channel"
