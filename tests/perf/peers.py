#!/usr/bin/env python3
"""dktlbm beside its peers on the same lattice and core count: lbmpy's generated kernel, OpenLB.

lbmpy (pip install lbmpy==1.4.1): a D2Q9 MRT kernel with Guo's body force, generated and
compiled by pystencils in this process, in 4 and 8 bytes, checked against lbmpy's own scalar
kernel, against dktlbm's flow step on the channel of input/bench_channel.nml (D2Q9 MRT with a
body force, walls at the sides, periodic ends) at the same size, both on one core. lbmpy is
given the settings that make its CPU kernel fastest:

  - vectorised for the widest instruction set the CPU has (AVX-512, else AVX2, else none), with
    `assume_inner_stride_one` so that the innermost loop is the contiguous x direction;
  - structure-of-arrays storage (`fzyx`: each population a contiguous plane), which the
    vectoriser needs;
  - global common-subexpression elimination of the collision (`cse_global`);
  - two fields (read one, write the other) and no OpenMP: one core, as the dktlbm run;
  - no boundary kernels: its figure is the stream-collide kernel alone (dktlbm's includes its
    side walls, periodic ends and halo bookkeeping).

  Non-temporal stores gained nothing measurable here. C-ordered arrays (y contiguous) run fast
  and wrong under `assume_inner_stride_one`, which the check against the scalar kernel catches.

OpenLB (--openlb-dkt2d PATH): its examples/particles/dkt2d executable, built from its source
(docs/performance.md, "Whole runs, and OpenLB"), run as a whole process with VTK and gnuplot off,
against dktlbm's case0_box at 20 spacings per diameter to 6 s (the same 200 x 800 lattice and
number of steps) on the same number of ranks.

Every repeat runs each configuration once, one after the other, so that a slower spell of a
shared machine hits all alike; ratios are taken within a repeat and then medianed.

    PYTHONPATH=postproc:tests python3 tests/perf/peers.py --repeats 5
    PYTHONPATH=postproc:tests python3 tests/perf/peers.py --peers openlb \\
        --openlb-dkt2d /path/to/olb/examples/particles/dkt2d/dkt2d --ranks 2
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import tempfile
import time
from pathlib import Path

import benchlib
from benchlib import ROOT

NOT_RUN = 77  # exit status when the peer is not installed (ctest's SKIP_RETURN_CODE)
PERFORMANCE = re.compile(r"performance:\s+([0-9.]+)\s+MLUPS")
# lbmpy's type names for dktlbm's precisions
LBMPY_TYPES = {"single_arith": "float32", "double": "float64"}


def cpu_flags() -> set[str]:
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return set()
    match = re.search(r"^flags\s*:(.*)$", text, re.M)
    return set(match.group(1).split()) if match else set()


def lbmpy_kernel(dtype: str, tau: float, force: float, vectorise: bool = True):
    """lbmpy's D2Q9 MRT stream-collide kernel with Guo forcing, compiled, and its settings.

    Written for lbmpy 1.4 (pystencils 1.3/1.4): its cpu_vectorize_info names the instruction set.
    """
    import pystencils as ps
    from lbmpy import (
        ForceModel,
        LBMConfig,
        LBMOptimisation,
        LBStencil,
        Method,
        Stencil,
        create_lb_update_rule,
    )

    stencil = LBStencil(Stencil.D2Q9)
    src, dst = ps.fields(f"src(9), dst(9): {dtype}[2D]", layout="fzyx")
    # dktlbm's rates (docs/model.md E2): 1/tau for the stress moments, 1.1 for energy, 1.25 for
    # its square, 1.1 for the heat fluxes
    config = LBMConfig(
        stencil=stencil,
        method=Method.MRT,
        relaxation_rates=[1.0 / tau, 1.1, 1.25, 1.0, 1.1],
        force_model=ForceModel.GUO,
        force=(0.0, force),
        compressible=True,
    )
    optimisation = LBMOptimisation(
        symbolic_field=src, symbolic_temporary_field=dst, cse_global=True
    )
    rule = create_lb_update_rule(lbm_config=config, lbm_optimisation=optimisation)
    flags = cpu_flags()
    lanes = "avx512" if "avx512f" in flags else "avx" if "avx2" in flags else None
    options = {"target": ps.Target.CPU, "data_type": dtype, "default_number_float": dtype}
    if vectorise and lanes:
        options["cpu_vectorize_info"] = {
            "instruction_set": lanes,
            "assume_inner_stride_one": True,
            "assume_aligned": False,
            "nontemporal": False,
        }
    kernel = ps.create_kernel(rule, config=ps.CreateKernelConfig(**options)).compile()
    settings = (
        f"D2Q9 MRT, Guo force, compressible, {dtype}, layout fzyx (x contiguous), cse_global, "
        f"vectorised: {lanes if vectorise else 'no'}, one thread, two fields"
    )
    return kernel, settings


def lbmpy_state(dtype: str, nx: int, ny: int, seed: int = 1):
    """Two nx x ny fields (one ghost layer) near rest, x contiguous as the kernel assumes."""
    import numpy as np

    weights = [4 / 9] + [1 / 9] * 4 + [1 / 36] * 4
    noise = np.random.default_rng(seed).standard_normal((nx + 2, ny + 2))
    a = np.empty((nx + 2, ny + 2, 9), dtype=dtype, order="F")
    for i, w in enumerate(weights):
        a[:, :, i] = w * (1.0 + 0.01 * noise)
    return a, a.copy(order="F")


def check_lbmpy(kernel, dtype: str, tau: float, force: float) -> float:
    """The vectorised kernel against lbmpy's own scalar kernel, 50 steps on 37 x 23 nodes (odd,
    so that the vector remainders run): the largest difference, or exit when it is no rounding.

    A vectorised kernel that assumes another memory order than the arrays have runs fast and
    wrong; this refuses such a comparison."""
    import numpy as np

    scalar, _ = lbmpy_kernel(dtype, tau, force, vectorise=False)
    results = []
    for k in (scalar, kernel):
        a, b = lbmpy_state(dtype, 37, 23)
        for _ in range(50):
            k(src=a, dst=b)
            a, b = b, a
        results.append(a[1:-1, 1:-1])
    difference = float(np.abs(results[0] - results[1]).max())
    limit = 1e-5 if dtype == "float32" else 1e-12
    if not difference <= limit:
        sys.exit(
            f"peers: lbmpy's vectorised {dtype} kernel differs from its scalar kernel by "
            f"{difference:.3g} (> {limit:g}): not a valid comparison (lbmpy 1.4 is supported)"
        )
    return difference


def time_lbmpy(kernel, dtype: str, nx: int, ny: int, steps: int) -> float:
    """MLUPS of `steps` calls of the kernel on nx x ny nodes (one ghost layer), near rest."""
    import numpy as np

    a, b = lbmpy_state(dtype, nx, ny)
    kernel(src=a, dst=b)  # the first call pays for loading the module
    start = time.perf_counter()
    for _ in range(steps):
        kernel(src=a, dst=b)
        a, b = b, a
    wall = time.perf_counter() - start
    if not np.isfinite(a).all():
        sys.exit("peers: lbmpy's populations are not finite: its kernel is not a valid comparison")
    return nx * ny * steps / wall / 1e6


def run_dktlbm(command: list[str], label: str) -> tuple[float, float]:
    """(its own MLUPS figure, wall s of the whole process)."""
    done = benchlib.run_measured(command)
    if done.returncode != 0:
        why = benchlib.first_error(done.output)
        sys.exit(f"peers: {label} failed (exit {done.returncode}): {why}")
    match = PERFORMANCE.search(done.output)
    return (float(match.group(1)) if match else float("nan")), done.wall


def side_by_side(args, peer: str, measure, lead, unit: str) -> dict:
    """Every repeat measures each precision once, peer then dktlbm: measure(precision, repeat)
    gives (peer's figure, dktlbm's); lead(peer's, dktlbm's) is dktlbm's lead, >1 when faster."""
    results = {p: {peer: [], "dktlbm": [], "lead": []} for p in args.precisions}
    for repeat in range(args.repeats):
        for precision in args.precisions:
            theirs, ours = measure(precision, repeat)
            row = results[precision]
            row[peer].append(theirs)
            row["dktlbm"].append(ours)
            row["lead"].append(lead(theirs, ours))
            print(
                f"  repeat {repeat + 1}: {precision}: {peer} {theirs:8.2f}  dktlbm {ours:8.2f}"
                f" {unit}  dktlbm's lead {row['lead'][-1]:5.2f}",
                flush=True,
            )
    return results


def print_table(title: str, peer: str, unit: str, results: dict) -> None:
    """Medians (min-max) of each figure and of the per-repeat lead, as a Markdown table."""
    print(f"\n{title}")
    print(f"| precision | {peer} {unit} | dktlbm {unit} | dktlbm's lead (per repeat) |")
    print("|---|---|---|---|")
    for precision, row in results.items():
        cells = []
        for key in (peer, "dktlbm", "lead"):
            middle, low, high = benchlib.spread(row[key])
            cells.append(f"{middle:.2f} ({low:.2f}-{high:.2f})")
        print(f"| {precision} | {cells[0]} | {cells[1]} | **{cells[2]}** |")


def lbmpy_rows(args, work: Path) -> list[dict]:
    scene = ROOT / "input/bench_channel.nml"
    nx, ny, tau, force = 500, 1250, 0.65, -1.0e-6
    kernels = {}
    for precision in args.precisions:
        dtype = LBMPY_TYPES[precision]
        kernels[precision] = lbmpy_kernel(dtype, tau, force)
        difference = check_lbmpy(kernels[precision][0], dtype, tau, force)
        print(
            f"lbmpy {precision}: {kernels[precision][1]}; against its scalar kernel: "
            f"largest difference {difference:.2g}",
            flush=True,
        )
    prefix = benchlib.launcher(args.mpiexec, 1) + [args.exe, str(scene)]

    def measure(precision: str, repeat: int) -> tuple[float, float]:
        peer = time_lbmpy(kernels[precision][0], LBMPY_TYPES[precision], nx, ny, args.steps)
        command = prefix + [
            "--set", f"run.steps={args.steps}",
            "--set", f"lbm.precision={precision}",
            "--set", "lbm.streaming=in_place",
            "--set", f"output.dir={work / f'lbmpy-{precision}-{repeat}'}",
        ]  # fmt: skip
        return peer, run_dktlbm(command, f"dktlbm {precision}")[0]

    results = side_by_side(args, "lbmpy", measure, lambda peer, ours: ours / peer, "MLUPS")
    title = f"lbmpy against dktlbm's flow step, {nx} x {ny}, {args.steps} steps, 1 core:"
    print_table(title, "lbmpy", "MLUPS", results)
    return [
        {"peer": "lbmpy", "precision": p, "settings": kernels[p][1], **row}
        for p, row in results.items()
    ]


def openlb_rows(args, work: Path) -> list[dict]:
    dkt2d = Path(args.openlb_dkt2d).resolve()
    if not dkt2d.is_file():
        sys.exit(f"peers: --openlb-dkt2d {dkt2d}: no such executable")
    launcher = benchlib.launcher(args.mpiexec, args.ranks)
    peer_command = launcher + [str(dkt2d), "--VTK_ENABLED", "0", "--GNUPLOT_ENABLED", "0"]

    def measure(precision: str, repeat: int) -> tuple[float, float]:
        done = benchlib.run_measured(peer_command, cwd=dkt2d.parent)
        if done.returncode != 0:
            sys.exit(f"peers: OpenLB dkt2d failed (exit {done.returncode})")
        command = launcher + [
            args.exe, str(ROOT / "input/case0_box.nml"),
            "--set", "lbm.cells_per_diameter=20", "--set", "run.t_end=6",
            "--set", f"lbm.precision={precision}",
            "--set", f"output.dir={work / f'openlb-{precision}-{repeat}'}",
        ]  # fmt: skip
        return done.wall, run_dktlbm(command, f"dktlbm case0_box {precision}")[1]

    results = side_by_side(args, "OpenLB", measure, lambda peer, ours: peer / ours, "wall s")
    title = f"OpenLB dkt2d against case0_box at 20 per D to 6 s, {args.ranks} ranks:"
    print_table(title, "OpenLB", "wall s", results)
    return [{"peer": "openlb", "precision": p, **row} for p, row in results.items()]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--peers", nargs="+", choices=("lbmpy", "openlb"), default=["lbmpy"])
    parser.add_argument("--exe", default=str(ROOT / "build/dktlbm"), help="dktlbm executable")
    parser.add_argument("--mpiexec", default="mpiexec", help="MPI launcher")
    parser.add_argument(
        "--precisions", nargs="+", choices=tuple(LBMPY_TYPES), default=list(LBMPY_TYPES),
        help="dktlbm's lbm.precision (lbmpy runs the same width)",
    )  # fmt: skip
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--steps", type=int, default=300, help="steps of the lbmpy comparison")
    parser.add_argument("--ranks", type=int, default=2, help="ranks of the OpenLB comparison")
    parser.add_argument("--openlb-dkt2d", help="OpenLB's built dkt2d executable")
    parser.add_argument("--json", help="also write the measurements here")
    args = parser.parse_args(argv)
    if args.repeats < 1 or args.steps < 1 or args.ranks < 1:
        parser.error("--repeats, --steps and --ranks must be at least 1")
    if "openlb" in args.peers and not args.openlb_dkt2d:
        parser.error("--peers openlb needs --openlb-dkt2d PATH (its built dkt2d)")
    benchlib.allow_root_mpi()
    print(f"machine: {benchlib.machine_line()}", flush=True)
    rows = []
    with tempfile.TemporaryDirectory(prefix="dkt-peers-") as tmp:
        if "lbmpy" in args.peers:
            try:
                import lbmpy  # noqa: F401
            except ImportError:
                print("peers: lbmpy is not installed (pip install lbmpy==1.4.1)", file=sys.stderr)
                return NOT_RUN
            rows += lbmpy_rows(args, Path(tmp))
        if "openlb" in args.peers:
            rows += openlb_rows(args, Path(tmp))
    print(f"machine: {benchlib.machine_line()}")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
