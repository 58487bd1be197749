"""Parameter sweeps over the diameter ratio gamma = D_1/D_2 and the initial distance D_h/D_1
of a pair scene, and the regime map of their DKT patterns.

    dkt-sweep plan BASE.nml [--gamma LIST] [--dh LIST] [--set group.key=value ...] --out DIR
    dkt-sweep run --out DIR [--jobs N] [--ranks R] [--force]      # here, N runs at a time
    dkt-sweep slurm --out DIR [--ntasks R] [--time HH:MM:SS] [--partition P]  # a job array
    dkt-sweep collect --out DIR                                   # regime.csv, regime.png
    dkt-sweep bisect BASE.nml --key gamma|dh --lo A --hi B --tol T --out DIR [--jobs N]
                                                                 # where the pattern changes
    dkt-sweep map BASE.nml --x gamma --x-range A:B --x-tol T --y dh --y-range C:D --y-tol U
                  --out DIR [--jobs N]       # the borders between patterns (dktlbm.sweepmap)

`plan` writes DIR/runs.csv (id, gamma, dh, dir, command): one run per combination of the
values, `dktlbm BASE --set pair.gamma=G --set pair.dh=H [--set ...] --set
output.dir=DIR/<id>`. LIST is comma-separated values or inclusive ranges start:stop:step,
e.g. `--gamma 1:3:0.5` or `--dh 1,2,4:10:2`. `run` and `slurm` run that plan; `collect`
reads each run's pattern (dkt-pattern) into DIR/regime.csv and draws DIR/regime.png.

`bisect` narrows [A, B] to a bracket of width <= T around the value of pair.gamma or pair.dh
where the pattern changes, N runs per step; its runs are rows of DIR/runs.csv like a plan's.
A pattern counts only when it is settled. 'repeated' is final as soon as a run has it (episodes
only add). 'once' and 'never' are settled when the episodes that start by t_end/2 give the same
pattern as all of them and the pair is neither closing in nor out of line at t_end (centres
more than D_1/2 apart across the channel); otherwise the point runs again with t_end
doubled, up to --max-t-end. --max-above means what the key window.max_above means: the longest
the window may be above the lowest particle's centre, in D_1 (default: the runs'
window.max_above, else 4 times window.above). By default each run's window grows as far as
the run needs (window.max_above = -1: window.above plus the velocity scale times run.t_end,
docs/model.md §5), so an escape is rare. A run that ended by window_escape is never final
by itself: the point runs again with window.above doubled, up to --max-above. With a window
whose limit is given (--grow, or window.max_above > 0 in the scene or a --set) each run's
window grows by itself up to that limit, so no point runs again for an escape: one at
the limit stops the bisection. `collect` reports both in regime.csv. With --kiss (a
once-to-never threshold) 'once' and 'repeated' are one class, 'kisses', final as soon as a
run has a kissing episode.

`map` runs a grid over both keys and bisects, by the same rules, every grid edge whose ends
differ: DIR/map.csv, DIR/borders.csv and DIR/map.png (`dkt-sweep map --help`).

The modules: dktlbm.sweepplan (plan, run, slurm, collect), dktlbm.sweepbisect (bisect),
dktlbm.sweepmap (map), dktlbm.sweepcommon (what they share); this one is the command line and
gives the names callers import from dktlbm.sweep.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from . import sweepmap
from .read import add_version, guarded
from .sweepbisect import (
    BISECT_COLUMNS,
    BISECT_CSV,
    BISECT_STATE,
    Bisector,
    BisectSettings,
    SearchSettings,
    bisect,
    bisect_estimate,
    bisect_state,
    local_launcher,
    round_points,
    rounds_left,
    slurm_launcher,
    write_bisect,
)
from .sweepcommon import (
    COLUMNS,
    RUNS_CSV,
    STYLE,
    UNSETTLED,
    PlannedRun,
    SweepError,
    Verdict,
    base_value,
    clock_text,
    closing_in,
    default_exe,
    first_change,
    fmt_value,
    judge,
    out_of_line,
    point_value,
    read_plan,
    scene_number,
    scene_setting,
    verdict,
    wall_seconds,
    window_above,
    with_sweep_precision,
    write_plan,
)
from .sweepplan import (
    MAX_RUNS,
    MAX_VALUES,
    REGIME_COLUMNS,
    REGIME_CSV,
    Progress,
    check_plan,
    checkpoint_of,
    collect,
    collect_summary,
    make_plan,
    parse_values,
    regime_layout,
    rerun_plans,
    run_plan,
    slurm_script,
    write_regime,
)

# the names callers import from dktlbm.sweep (tests, tools, older scripts)
__all__ = [
    "BISECT_COLUMNS", "BISECT_CSV", "BISECT_STATE", "COLUMNS", "MAX_RUNS", "MAX_VALUES",
    "REGIME_COLUMNS", "REGIME_CSV", "RUNS_CSV", "STYLE", "UNSETTLED", "BisectSettings",
    "Bisector", "PlannedRun", "Progress", "SearchSettings", "SweepError", "Verdict",
    "base_value", "bisect", "bisect_estimate", "bisect_state", "check_plan", "checkpoint_of",
    "clock_text", "closing_in", "collect", "collect_summary", "default_exe", "first_change",
    "fmt_value", "judge", "local_launcher", "main", "make_plan", "out_of_line", "parse_values",
    "parser", "point_value", "read_plan", "regime_layout", "rerun_plans", "round_points",
    "rounds_left", "run_plan", "scene_number", "scene_setting", "search_fields",
    "search_options", "slurm_launcher", "slurm_script", "verdict", "wall_seconds",
    "window_above", "write_bisect", "write_plan", "write_regime",
]


def _values_arg(text: str) -> list[float]:
    try:
        return parse_values(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _set_arg(text: str) -> str:
    key, eq, _ = text.partition("=")
    if not eq or "." not in key:
        raise argparse.ArgumentTypeError(f"{text!r} is not group.key=value")
    return text



# ---------------------------------------------------------------- command line


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="dkt-sweep",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="example:\n"
        "  dkt-sweep plan input/case1.nml --gamma 1:3:0.5 --dh 2,4,8 "
        "--out sweeps/case1\n"
        "  dkt-sweep run --out sweeps/case1 --jobs 2 --ranks 2\n"
        "  dkt-sweep collect --out sweeps/case1",
    )
    add_version(p)
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def with_out(q: argparse.ArgumentParser) -> None:
        q.add_argument("--out", type=Path, required=True, metavar="DIR",
                       help="the sweep directory (holds runs.csv and one directory per run)")

    plan = sub.add_parser(
        "plan", help="write DIR/runs.csv, the run set",
        description="Write DIR/runs.csv: id, gamma, dh, dir, command of each run.")
    plan.add_argument("base", type=Path, metavar="BASE.nml", help="the base scene (namelist)")
    plan.add_argument("--gamma", type=_values_arg, metavar="LIST",
                      help="values of pair.gamma = D_1/D_2: '1.5,2,2.5' or '1:3:0.5' "
                      "(inclusive); default: the base scene's")
    plan.add_argument("--dh", type=_values_arg, metavar="LIST",
                      help="values of pair.dh = D_h/D_1, same forms; default: the base scene's")
    plan.add_argument("--set", dest="sets", action="append", default=[], type=_set_arg,
                      metavar="group.key=value", help="passed to every run (repeatable)")
    plan.add_argument("--max-runs", type=int, default=MAX_RUNS, metavar="N",
                      help=f"plan at most N runs (default {MAX_RUNS})")
    plan.add_argument("--no-check", action="store_true",
                      help="do not run `dktlbm --check` on the plan's corners")
    plan.add_argument("--exe", default=None,
                      help="the dktlbm executable (default: build/dktlbm of this source "
                      "tree, else dktlbm on PATH)")
    with_out(plan)

    run = sub.add_parser(
        "run", help="run the plan here",
        description="Run the plan here, N runs at a time, each on R MPI ranks (launcher: "
        "$MPIEXEC, default mpiexec). Each run's output goes to DIR/<id>/run.log. A run "
        "whose file is already finished is skipped. After each run a line 'progress: K of N "
        "runs finished, elapsed H:MM:SS, ETA H:MM:SS' (ETA: the mean time per run so far, "
        "the runs left, N at a time). Exit status 1 if any run failed.")
    with_out(run)
    run.add_argument("--jobs", type=int, default=1, metavar="N",
                     help="runs at the same time (default 1)")
    run.add_argument("--ranks", type=int, default=1, metavar="R",
                     help="MPI ranks per run (default 1)")
    run.add_argument("--force", action="store_true", help="run finished runs again too")

    slurm = sub.add_parser(
        "slurm", help="write DIR/sweep.slurm, a Slurm job array of the plan",
        description="Write DIR/sweep.slurm: a job array with one task per run of the plan; "
        "submit it with sbatch.")
    with_out(slurm)
    slurm.add_argument("--ntasks", type=int, default=4, metavar="R",
                       help="MPI ranks per run (default 4)")
    slurm.add_argument("--time", default="24:00:00", metavar="HH:MM:SS",
                       help="time limit per run (default 24:00:00)")
    slurm.add_argument("--partition", help="Slurm partition (default: the cluster's)")
    slurm.add_argument("--account", help="Slurm account to charge (default: yours)")
    slurm.add_argument("--max-parallel", type=int, metavar="M",
                       help="at most M runs at the same time (--array=...%%M)")
    slurm.add_argument("--setup", action="append", default=[], metavar="LINE",
                       help="a shell line run before each run, e.g. 'module load openmpi' "
                       "(repeatable)")
    slurm.add_argument("--job-name", default="dkt-sweep", help="default dkt-sweep")

    coll = sub.add_parser(
        "collect", help="write DIR/regime.csv and the regime map DIR/regime.png",
        description="Read each planned run's DKT pattern into DIR/regime.csv (gamma, dh, "
        "pattern, episodes, first_kiss_t, dir; pattern missing or failed without a finished "
        "run file) and draw DIR/regime.png: D_h/D_1 across, gamma up, one marker per pattern. "
        "Then it says how many runs are settled, unsettled (their pattern may still change: "
        "postproc/README.md, 'Settled patterns') or without a pattern, names the runs that "
        "stopped before their t_end (window_escape or another stop reason), and what to do "
        "next: the dkt-sweep plan, run and collect commands that run the unsettled runs again "
        "with run.t_end doubled, or in a window that grows (window.max_above) when a particle "
        "left the window, and `dkt-sweep run` for runs not run to their end.")
    with_out(coll)
    coll.add_argument("--with", dest="also", action="append", default=[], type=Path,
                      metavar="DIR2", help="also the runs of this sweep or bisection directory "
                      "(repeatable): one table and one map of all of them, written to DIR")
    coll.add_argument("--pdf", action="store_true", help="also write DIR/regime.pdf")

    bis = sub.add_parser(
        "bisect", help="find where the pattern changes between two values of gamma or dh",
        description="Narrow [--lo, --hi] to a bracket no wider than --tol around the value of "
        "pair.gamma or pair.dh where the DKT pattern changes. Each step runs up to --jobs "
        "points inside the bracket (here, or as one Slurm job array with --slurm). A point "
        "counts only with a settled pattern: the episodes that start by t_end/2 give the same "
        "pattern as all of them; otherwise it runs again with run.t_end doubled, up to "
        "--max-t-end; 'repeated' is final as soon as it is reached, and a 'once' or 'never' "
        "whose pair is closing in, or out of line (centres more than D_1/2 apart across the "
        "channel), at t_end is not settled. Each run's window grows as far as the run needs "
        "by default (window.max_above = -1). A run ended by window_escape is "
        "never final: the point runs again with window.above doubled, up to --max-above (the "
        "longest the window may be above the lowest particle's centre, as window.max_above); "
        "with --grow (or window.max_above in the scene or a --set) each run's window grows by "
        "itself up to that limit instead, and an escape at the limit stops the bisection. With "
        "--kiss only a kiss is told from none: a run with a kissing episode is final at once. A "
        "run stopped by a guard or an error stops the bisection. Every run is DIR/<id> and a row "
        "of DIR/runs.csv (collect and plot as a sweep); DIR/bisect.csv lists every run and "
        "the final bracket. Rerunning the command reuses the finished runs (also with another "
        "--lo, --hi or --tol: only new points run); another base scene or --set list for "
        "the same DIR is refused. Here, after each run a line 'progress: step S: K of N runs "
        "finished, elapsed H:MM:SS, ETA H:MM:SS' (elapsed since the bisection started, ETA "
        "of step S), and after each round that leaves the bracket wider than --tol an estimate "
        "of the time the whole bisection has left: 'estimate: about H:MM:SS left for the whole "
        "bisection: R more rounds narrow [A, B] to --tol T (...)', the rounds that halving (or "
        "cutting into --jobs + 1 parts) still needs times the mean time of a round so far.")
    bis.add_argument("base", type=Path, metavar="BASE.nml", help="the base scene (namelist)")
    bis.add_argument("--key", choices=("gamma", "dh"), required=True,
                     help="pair.gamma (D_1/D_2) or pair.dh (D_h/D_1)")
    bis.add_argument("--lo", type=float, required=True, metavar="A", help="one end")
    bis.add_argument("--hi", type=float, required=True, metavar="B", help="the other end")
    bis.add_argument("--tol", type=float, required=True, metavar="T",
                     help="stop when the bracket is at most T wide")
    search_options(bis, "runs at the same time, and points per step (default 1)")
    with_out(bis)
    _map_parser(sub, with_out)
    return p


def search_options(q: argparse.ArgumentParser, jobs_help: str) -> None:
    """The options of a search (bisect, map): the runs' settings, the settling limits, and
    where the runs go (here, or Slurm job arrays)."""
    q.add_argument("--set", dest="sets", action="append", default=[], type=_set_arg,
                   metavar="group.key=value", help="passed to every run (repeatable)")
    q.add_argument("--max-t-end", type=float, metavar="S",
                   help="the longest run.t_end (s) a point may need to settle (default: 8 "
                   "times the first)")
    q.add_argument("--max-above", type=float, metavar="D",
                   help="the longest the window may be above the lowest particle's centre, "
                   "in D_1, as the key window.max_above: a point that leaves the window runs "
                   "again with window.above doubled up to it, or, when the runs' windows grow "
                   "(--grow, or window.max_above in the scene or a --set), each run's window "
                   "grows up to it (default: the runs' window.max_above when they set one, "
                   "else 4 times window.above)")
    q.add_argument("--grow", action="store_true",
                   help="let each run's window grow up to --max-above (added to every run as "
                   "window.max_above, docs/model.md section 5) instead of running a point "
                   "again with window.above doubled after a window escape")
    q.add_argument("--kiss", action="store_true",
                   help="tell only whether the pair kisses: 'once' and 'repeated' are one "
                   "class, 'kisses', final as soon as a run has a kissing episode (for a once "
                   "to never threshold; 'never' settles as without it)")
    q.add_argument("--exe", default=None, help="the dktlbm executable (as for plan)")
    q.add_argument("--jobs", type=int, default=1, metavar="N", help=jobs_help)
    q.add_argument("--ranks", type=int, default=1, metavar="R",
                   help="MPI ranks per run here (default 1)")
    q.add_argument("--slurm", action="store_true",
                   help="submit each step as a Slurm job array (sbatch --wait) instead")
    q.add_argument("--ntasks", type=int, default=4, metavar="R",
                   help="with --slurm: MPI ranks per run (default 4)")
    q.add_argument("--time", default="24:00:00", metavar="HH:MM:SS",
                   help="with --slurm: time limit per run (default 24:00:00)")
    q.add_argument("--partition", help="with --slurm: Slurm partition")
    q.add_argument("--setup", action="append", default=[], metavar="LINE",
                   help="with --slurm: a shell line run before each run (repeatable)")


def _bisect_command(args: argparse.Namespace) -> int:
    if not args.base.is_file():
        raise SweepError(f"{args.base}: no such scene file")
    lo, hi = sorted((point_value(args.lo), point_value(args.hi)))
    if not (0 < lo < hi) or not (math.isfinite(args.tol) and args.tol > 0):
        raise SweepError(f"--lo and --hi must be two different positive values and --tol "
                         f"positive (got {args.lo:g}, {args.hi:g}, {args.tol:g})")
    base = args.base.resolve()
    cfg = BisectSettings(base=base, key=args.key, lo=lo, hi=hi, tol=args.tol,
                         **search_fields(args, base))
    b, summary = bisect(cfg, args.jobs, search_launcher(args, cfg.out))
    print(f"wrote {cfg.out / BISECT_CSV}, {cfg.out / RUNS_CSV}")
    print(summary)
    return 0


def search_fields(args: argparse.Namespace, base: Path) -> dict[str, object]:
    """The SearchSettings fields of a search (search_options) of the scene `base`. t_end and
    above are the runs' first run.t_end and window.above (the scene's or a --set's; the
    program's window.above when neither gives it); max_t_end is --max-t-end, else 8 t_end.
    max_above means what the key window.max_above means, the longest the window may be above
    the lowest particle's centre (D_1): --max-above, else the runs' window.max_above when the
    scene or a --set gives one (> 0), else 4 above. When the runs' windows grow (that key, or
    --grow, which adds window.max_above=max_above to the --set list so that a rerun's identity
    includes it), grow = max_above, else 0. SweepError for a bad value, for --max-above and a
    window.max_above that differ (they are one limit), and for --jobs, --ranks or --ntasks
    below 1."""
    if args.jobs < 1 or args.ranks < 1 or args.ntasks < 1:
        raise SweepError("--jobs, --ranks and --ntasks must be at least 1")
    t_end, text = scene_number(base, args.sets, "run.t_end")
    if not (t_end is not None and math.isfinite(t_end) and t_end > 0):
        raise SweepError(f"{base}: &run t_end is not given (or not a positive number: "
                         f"{text!r}); the settling rule needs it: --set run.t_end=SECONDS")
    max_t_end = args.max_t_end if args.max_t_end is not None else 8 * t_end
    if max_t_end < t_end:
        raise SweepError(f"--max-t-end {max_t_end:g} is below run.t_end = {t_end:g} s")
    above, text = window_above(base, args.sets)
    if not (above is not None and math.isfinite(above) and above >= 1):
        raise SweepError(f"{base}: &window above is not a number >= 1 ({text!r}); set it with "
                         f"--set window.above=D (in D_1)")
    sets, mode = with_sweep_precision(base, args.sets)
    recorded = _recorded_sets(args.out)
    if recorded is not None and not any(s.startswith("lbm.precision=") for s in recorded) \
            and not scene_setting(base, args.sets, "lbm.precision"):
        # a search an earlier version started, its runs in the program's default: go on so
        sets = list(args.sets)
        mode = (f"precision: lbm.precision = double, as the runs {args.out} already holds "
                f"(begun without the sweep's default)")
    print(mode, flush=True)
    grown, text = scene_number(base, sets, "window.max_above")
    grows = grown is not None and math.isfinite(grown) and grown > 0
    if grows and args.max_above is not None and args.max_above != grown:
        raise SweepError(f"--max-above {args.max_above:g} and window.max_above = {text} (the "
                         f"scene's or a --set's) are one limit, the longest the window may be "
                         f"above the lowest particle: give one of them")
    max_above = args.max_above if args.max_above is not None else grown if grows else 4 * above
    if not max_above >= above:
        raise SweepError(f"--max-above {max_above:g} is below window.above = {above:g} D_1")
    if args.grow and not grows:
        sets.append(f"window.max_above={max_above:g}")
    return {"sets": sets, "out": args.out.resolve(), "exe": args.exe or default_exe(),
            "t_end": t_end, "max_t_end": max_t_end, "above": above, "max_above": max_above,
            "kiss": args.kiss, "grow": max_above if grows or args.grow else 0.0}


def _recorded_sets(out: Path) -> list[str] | None:
    """The --set list of the bisection or map that directory `out` holds (its bisect.json or
    map.json), None when it holds none or the file is unreadable (bisect_state says so)."""
    for name in (BISECT_STATE, sweepmap.MAP_STATE):
        try:
            return list(json.loads((out / name).read_text()).get("sets", []))
        except (OSError, ValueError, TypeError, AttributeError):
            continue
    return None


def search_launcher(args: argparse.Namespace, out: Path):
    """How a search (search_options) runs its points: Slurm job arrays with --slurm, else
    here."""
    if args.slurm:
        return slurm_launcher(out, args.ntasks, args.time, args.partition, args.setup)
    return local_launcher(args.jobs, args.ranks)


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)

    def body() -> int:
        try:
            return _dispatch(args)
        except SweepError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2

    return guarded(body)


def _dispatch(args: argparse.Namespace) -> int:
    out: Path = args.out
    if args.command == "bisect":
        return _bisect_command(args)
    if args.command == "map":
        return _map_command(args)
    if args.command == "plan":
        runs = len(args.gamma or [None]) * len(args.dh or [None])
        if runs > args.max_runs:
            raise SweepError(f"the plan would hold {runs} runs, more than --max-runs "
                             f"{args.max_runs}: narrow --gamma or --dh, or pass --max-runs "
                             f"{runs} to plan them all")
        if not args.base.is_file():
            raise SweepError(f"{args.base}: no such scene file")
        sets, mode = with_sweep_precision(args.base, args.sets)
        print(mode)
        plan = make_plan(args.base, args.gamma, args.dh, sets, out, args.exe or default_exe())
        if not args.no_check:
            check_plan(plan)
        path = write_plan(plan, out)
        print(f"wrote {path}: {len(plan)} run{'s' if len(plan) != 1 else ''}")
        return 0
    plan = read_plan(out)
    if not plan:
        raise SweepError(f"{out / RUNS_CSV}: the plan holds no runs")
    if args.command == "run":
        if args.jobs < 1 or args.ranks < 1:
            raise SweepError("--jobs and --ranks must be at least 1")
        return 1 if run_plan(plan, args.jobs, args.ranks, args.force) else 0
    if args.command == "slurm":
        if args.ntasks < 1:
            raise SweepError("--ntasks must be at least 1")
        script = out / "sweep.slurm"
        script.write_text(slurm_script(plan, out, args.ntasks, args.time, args.partition,
                                       args.account, args.max_parallel, args.setup,
                                       args.job_name))
        script.chmod(0o755)
        tasks = f"{len(plan)} array task{'s' if len(plan) != 1 else ''}"
        print(f"wrote {script}: {tasks}; submit with: sbatch {script}")
        return 0
    for other in args.also:
        plan += read_plan(other)
    rows = collect(plan)
    for path in write_regime(rows, out, args.pdf):
        print(f"wrote {path}")
    counts: dict[str, int] = {}
    for r in rows:
        counts[r["pattern"]] = counts.get(r["pattern"], 0) + 1
    print(", ".join(f"{k}: {v}" for k, v in sorted(counts.items())))
    print("\n".join(collect_summary(plan, rows, out)))
    return 0


def _range_arg(text: str) -> tuple[float, float]:
    try:
        lo, hi = (float(v) for v in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not A:B") from None
    if not (0 < lo < hi and math.isfinite(hi)):
        raise argparse.ArgumentTypeError(f"{text!r}: need 0 < A < B")
    return point_value(lo), point_value(hi)


def _cut_arg(text: str) -> tuple[str, float]:
    axis, eq, value = text.partition("=")
    try:
        number = float(value)
    except ValueError:
        number = math.nan
    if axis not in ("x", "y") or not eq or not math.isfinite(number):
        raise argparse.ArgumentTypeError(f"{text!r} is not x=VALUE or y=VALUE")
    return axis, number


def _map_parser(sub, with_out) -> None:
    """`dkt-sweep map` in the subcommands `sub` of dkt-sweep (with_out adds --out)."""
    q = sub.add_parser(
        "map", help="trace the borders between DKT patterns across gamma and dh",
        description=sweepmap.__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    q.add_argument("base", type=Path, metavar="BASE.nml", help="the base scene (namelist)")
    for a in ("x", "y"):
        q.add_argument(f"--{a}", choices=sweepmap.KEYS, required=True,
                       help=f"the key {'across' if a == 'x' else 'up'}: pair.gamma or pair.dh")
        q.add_argument(f"--{a}-range", type=_range_arg, required=True, metavar="A:B",
                       help="its range, ends included")
        q.add_argument(f"--{a}-points", type=int, default=5, metavar="N",
                       help="grid values along it, ends included (default 5)")
        q.add_argument(f"--{a}-tol", type=float, required=True, metavar="T",
                       help="bisect each edge along it to a bracket at most T wide")
    q.add_argument("--cut", action="append", default=[], type=_cut_arg, metavar="x=V|y=V",
                   help="draw the line x = V or y = V on map.png (repeatable), e.g. a 1-D "
                   "search's line")
    q.add_argument("--pdf", action="store_true", help="also write DIR/map.pdf")
    q.add_argument("--keep-going", action="store_true",
                   help="a point not settled within --max-t-end and --max-above is marked "
                   "unsettled and the map goes on around it (default: the map stops there)")
    search_options(q, "runs at the same time (default 1); each step gives every edge "
                   "N / edges points, at least one")
    with_out(q)


def _map_command(args: argparse.Namespace) -> int:
    if not args.base.is_file():
        raise SweepError(f"{args.base}: no such scene file")
    if args.x == args.y:
        raise SweepError(f"--x and --y are both {args.x}: a map needs two keys")
    axes = []
    for a in ("x", "y"):
        (lo, hi), n, tol = getattr(args, f"{a}_range"), getattr(args, f"{a}_points"), \
            getattr(args, f"{a}_tol")
        if n < 2 or not (math.isfinite(tol) and tol > 0):
            raise SweepError(f"--{a}-points must be at least 2 and --{a}-tol positive "
                             f"(got {n}, {tol:g})")
        axes.append(sweepmap.Axis(getattr(args, a), lo, hi, n, tol))
    base = args.base.resolve()
    cfg = sweepmap.MapSettings(base=base, x=axes[0], y=axes[1], cuts=list(args.cut),
                               keep_going=args.keep_going, **search_fields(args, base))
    _, _, summary = sweepmap.trace_map(cfg, args.jobs, search_launcher(args, cfg.out),
                                       args.pdf)
    written = (sweepmap.MAP_CSV, sweepmap.BORDERS_CSV, sweepmap.MAP_PNG)
    print(f"wrote {', '.join(str(cfg.out / f) for f in written)}, {cfg.out / RUNS_CSV}")
    print(summary)
    return 0


if __name__ == "__main__":
    sys.exit(main())
