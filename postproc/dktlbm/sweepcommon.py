"""What the sweep modules share: the errors, the plan's rows (DIR/runs.csv), the values as the
runs see them, the scene's settings as a run will see them, and the Verdict of a run file
(whether its DKT pattern is settled).

dktlbm.sweepplan (plan, run, slurm, collect), dktlbm.sweepbisect (bisect), dktlbm.sweepmap
(map) and the command line dktlbm.sweep all use this module, and it uses none of them.
"""

from __future__ import annotations

import csv
import math
import re
import shlex
from dataclasses import dataclass
from pathlib import Path

from . import launch as mpi
from .read import (
    RunFileError,
    fortran_float,
    open_h5,
    open_run,
    pair_of,
    parse_namelist,
    pattern_name,
    program_settings,
    run_status,
    run_until,
    stop_reason,
)

RUNS_CSV = "runs.csv"
COLUMNS = ("id", "gamma", "dh", "dir", "command")
# marker and colour of each pattern on the regime map
STYLE = {
    "repeated": ("o", "tab:red"),
    "once": ("s", "tab:orange"),
    "never": ("^", "tab:blue"),
    "missing": ("x", "tab:gray"),
    "stopped": ("P", "tab:purple"),
    "paused": ("P", "tab:purple"),
    "running": ("*", "tab:green"),
    "failed": ("X", "black"),
}
UNSETTLED = "unsettled"  # a map point not settled within the limits (--keep-going)


class SweepError(Exception):
    """A problem with the sweep's input: printed as `error: <text>`, exit status 2."""


# ---------------------------------------------------------------- the plan's rows


@dataclass
class PlannedRun:
    id: str
    gamma: float | None
    dh: float | None
    dir: Path
    command: str

    @property
    def args(self) -> list[str]:
        return shlex.split(self.command)

    @property
    def h5(self) -> Path:
        """The run file: <dir>/<scene basename>.h5 (the scene is the command's first
        argument)."""
        return self.dir / f"{Path(self.args[1]).stem}.h5"


def default_exe() -> str:
    """The executable the plan's commands start (dktlbm.launch.find_exe: $DKTLBM_EXE, dktlbm
    on PATH, this source tree's build/dktlbm); `dktlbm` when there is none yet."""
    found = mpi.find_exe()
    return str(found) if found is not None else "dktlbm"


def fmt_value(value: float) -> str:
    """A value as runs.csv, regime.csv and run ids write it: 10 significant digits, enough to
    read back every bisection point (8 digits) exactly."""
    return f"{value:.10g}"


def scene_setting(base: Path, sets: list[str], dotted: str) -> str | None:
    """The text of group.key (dotted) as the run will see it: the last --set of it, else the
    scene file's; None when neither gives it."""
    group, _, key = dotted.partition(".")
    given = [s.partition("=")[2] for s in sets if s.partition("=")[0].strip().lower() == dotted]
    if given:
        return given[-1].strip()
    try:
        found = parse_namelist(base.read_text()).get(group, {}).get(key, [])
    except (OSError, UnicodeDecodeError):
        return None
    return found[0] if found else None


#: The mode dkt-sweep runs in unless the scene or a --set names one: the fastest whose answers
#: stay within the sweep bound of docs/tradeoff.md (every pattern, kissing window and Re of its
#: rows equal double's to the bound; section "Arithmetic in 4 bytes").
SWEEP_PRECISION = "single_arith"


def with_sweep_precision(base: Path, sets: list[str]) -> tuple[list[str], str]:
    """`sets` with lbm.precision = SWEEP_PRECISION added when neither the scene nor a --set
    names a precision, and the line that says which mode the runs use and why."""
    given = scene_setting(base, sets, "lbm.precision")
    if given:
        return list(sets), f"precision: lbm.precision = {given.strip(chr(39) + chr(34))} (given)"
    return [*sets, f"lbm.precision={SWEEP_PRECISION}"], (
        f"precision: lbm.precision = {SWEEP_PRECISION}, the fastest mode within the sweep "
        f"bound of docs/tradeoff.md (--set lbm.precision=double runs in 8 bytes)")


def scene_number(base: Path, sets: list[str], dotted: str) -> tuple[float | None, str | None]:
    """group.key (dotted) as the run will see it (scene_setting), as a number, and its text:
    (None, text) when the text is not a number, (None, None) when nothing gives it."""
    text = scene_setting(base, sets, dotted)
    try:
        return (fortran_float(text) if text is not None else None), text
    except ValueError:
        return None, text


def window_above(base: Path, sets: list[str]) -> tuple[float | None, str | None]:
    """window.above as the run will see it (scene_number), the program's default when neither
    a --set nor the scene gives it: (number or None, the text given or None)."""
    above, text = scene_number(base, sets, "window.above")
    if not text:
        above = fortran_float(program_settings(None)["window"]["above"][0])
    return above, text


def base_value(base: Path, sets: list[str], key: str) -> float | None:
    """pair.<key> as the run will see it: from --set, else from the scene file."""
    return scene_number(base, sets, f"pair.{key}")[0]


def point_value(x: float) -> float:
    """A value as the runs see it: 8 significant digits (the run id and the --set text)."""
    return float(f"{x:.8g}")


def write_plan(plan: list[PlannedRun], out: Path) -> Path:
    out.mkdir(parents=True, exist_ok=True)
    path = out / RUNS_CSV
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(COLUMNS)
        for r in plan:
            w.writerow([r.id, "" if r.gamma is None else fmt_value(r.gamma),
                        "" if r.dh is None else fmt_value(r.dh), str(r.dir), r.command])
    return path


def read_plan(out: Path) -> list[PlannedRun]:
    """The plan in out/runs.csv; each run's directory is out/<id> (so the sweep directory may
    be moved or copied back from a cluster)."""
    path = out / RUNS_CSV
    if not path.is_file():
        raise SweepError(f"{path}: no such file; write it first with `dkt-sweep plan`")
    plan = []
    with path.open(newline="") as f:
        reader = csv.DictReader(f)
        if reader.fieldnames is None or any(c not in reader.fieldnames for c in COLUMNS):
            raise SweepError(f"{path}: not a sweep plan (columns {', '.join(COLUMNS)})")
        for row in reader:
            plan.append(PlannedRun(
                row["id"],
                float(row["gamma"]) if row["gamma"] else None,
                float(row["dh"]) if row["dh"] else None,
                out / row["id"],
                row["command"],
            ))
    return plan


def clock_text(seconds: float) -> str:
    """Seconds as H:MM:SS (whole seconds, rounded up)."""
    whole = math.ceil(max(seconds, 0.0))
    return f"{whole // 3600}:{whole // 60 % 60:02d}:{whole % 60:02d}"


# ---------------------------------------------------------------- settled patterns


@dataclass
class Verdict:
    """What one run file says about its pattern, and whether that pattern is final.

    `half` is the pattern of the episodes that start by t_end/2, `pattern` that of all of
    them. Episodes only add as a run goes on, so 'repeated' is final as soon as it is reached.
    A finished run with 'once' or 'never' is settled when the two agree and the pair is
    neither closing in (closing_in) nor out of line (out_of_line) at its end: its pattern
    would survive doubling t_end as far as this run can tell. A run that ended by
    window_escape is not settled: the pair was lost, and the upper particle may come back (a
    bigger window can tell). A run stopped cleanly before its end (`status` 'signal' or
    'wall_limit': it wrote a checkpoint) after a kissing episode is classified up to where it
    stopped (`partial`): its pattern so far, settled when 'repeated'. Anything else (a guard,
    an error, a run still going or killed, no file, a stopped run without an episode) is not
    a pattern at all: `status` says what."""

    status: str  # 'finished', 'window_escape', the file's other stop_reason, 'missing',
    # 'running' (a live run writes it), 'failed', 'short' (verdict with `until`: the samples
    # end before it)
    pattern: str = ""
    half: str = ""
    episodes: int = 0
    first_kiss: float | None = None
    t_end: float = math.nan  # s, the run's planned end (steps x dt)
    end_t: float = math.nan  # s, its last sample
    settled: bool = False
    why: str = ""
    gamma: float | None = None  # the pair's, as the run file gives them
    dh: float | None = None
    t_ref: float = math.nan  # s, t* = t / t_ref (the run file's)
    run_pattern: str = ""  # the run's own pattern, when `pattern` is a class of it (judge)
    partial: bool = False  # stopped early; classified by its episodes so far

    @property
    def classified(self) -> bool:
        return self.status in ("finished", "window_escape") or self.partial


def judge(v: Verdict, kiss: bool) -> Verdict:
    """The Verdict as a bisection compares it. By default patterns are compared as they are.
    With `kiss` (a `once` to `never` threshold), `once` and `repeated` are one class, 'kisses':
    a run with a kissing episode has it for good (episodes only add, as for `repeated`), so it
    is settled at once, also when the pair is out of line, closing in, or left the window
    after the kiss; a `never` settles as before. The run's own pattern stays in
    `run_pattern`."""
    v.run_pattern = v.pattern
    if kiss and v.classified and v.episodes > 0:
        v.pattern, v.settled = "kisses", True
        v.why = (f"kissed from t = {v.first_kiss:.4g} s ({v.run_pattern} by t = "
                 f"{v.end_t:.4g} s; episodes only add)")
    return v


def closing_in(pair) -> tuple[bool, str]:
    """Whether the pair is closing in at the run's last sample: the upper particle sinks faster
    than the lower one, or the gap D_r is smaller than a tenth of the run before. Such a pair
    may kiss again after the run's end (Case-1 at gamma = 1.1875: separated to 14 D_1 by
    t* = 100, kissed again at t* = 240). At 16 per D the same pair's gap peaks at t* = 90 and
    is 0.3 % below the peak at t* = 100, with the upper disk 0.5 % faster, and kisses again at
    t* = 220: a rule that also asked for the gap to be smaller than a quarter of the run before
    took that run as separating."""
    run = pair.run
    y, v = run.series["y"][-1, :2], run.series["v"][-1, :2]
    lower, upper = (0, 1) if y[0] < y[1] else (1, 0)
    back = int(pair.t.searchsorted(pair.t[-1] - 0.1 * (pair.t[-1] - pair.t[0])))
    shrinking = pair.dr.size > 1 and pair.dr[-1] < pair.dr[min(back, pair.dr.size - 1)]
    gaining = v[upper] < v[lower]
    state = (f"the lower particle sinks at {-v[lower]:.4g} cm/s, the upper at "
             f"{-v[upper]:.4g} cm/s, the gap is {pair.dr[-1] / pair.d1:.3g} D_1 and "
             f"{'shrinking' if shrinking else 'not shrinking'}")
    return bool(shrinking or gaining), state


def out_of_line(pair) -> tuple[bool, str]:
    """Whether the pair is out of line at the run's last sample: the particles' centres more
    than D_1/2 apart across the channel. The trailing particle is then not (yet) in the
    leader's wake; in this channel both drift back to the centreline, and once behind the
    leader it may draft and catch up (Case-2 at gamma = 1, 16 per D: 3.3 D_1 apart across the
    channel at t* = 50, kissing again at t* = 102)."""
    x = pair.run.series["x"][-1, :2]
    across = abs(float(x[0] - x[1]))
    return across > 0.5 * pair.d1, (f"the centres are {across / pair.d1:.3g} D_1 apart across "
                                    f"the channel")


STOPPED_CLEANLY = ("signal", "wall_limit")  # stop reasons after which a checkpoint is written


def verdict(h5: Path, until: float | None = None) -> Verdict:
    """The Verdict of the run file `h5` (see Verdict). With `until` (s), the Verdict the run
    would have had with t_end = `until`, judged on its samples up to there as if it had
    finished there (read.run_until); status 'short' when its samples do not reach that time."""
    status = run_status(h5)
    if status == "missing":
        return Verdict("missing", why="no run file")
    if status == "running":  # nothing is read from a file a live run is writing
        return Verdict("running", why="a live run is writing it")
    try:
        with open_h5(h5) as f:
            reason = stop_reason(f) or status
    except RunFileError as exc:
        return Verdict("failed", why=str(exc))
    stopped = status != "finished"
    if stopped and reason not in STOPPED_CLEANLY:
        return Verdict(reason if reason != "finished" else "failed",
                       why=f"the run did not finish (stop_reason: {reason})")
    try:
        run = open_run(h5, need_particles=2, warn=False)  # the Verdict says why
        if until is not None:
            if not run.t[-1] >= until - 0.5 * run.dt:
                return Verdict("short", why=f"its samples end at t = {run.t[-1]:.4g} s, "
                                            f"before {until:.4g} s")
            run, stopped, reason = run_until(run, until), False, "finished"
        pair = pair_of(run)
    except RunFileError as exc:
        return Verdict("failed", why=str(exc))
    end_t = float(pair.t[-1])
    t_end = run.steps * run.dt if run.steps > 0 and math.isfinite(run.dt) else end_t
    starts = [e.start for e in pair.episodes]
    if stopped:
        if not starts:
            return Verdict(reason, why=f"the run did not finish (stop_reason: {reason}) and "
                                       f"had no kissing episode by t = {end_t:.4g} s")
        return Verdict(reason, pair.pattern, "", len(starts), starts[0], t_end, end_t,
                       pair.pattern == "repeated",
                       f"stopped ({reason}) at t = {end_t:.4g} s of {t_end:.4g} s, "
                       f"{len(starts)} episode{'s' if len(starts) != 1 else ''} by then "
                       f"(episodes only add)", pair.gamma, pair.dh, run.t_ref, partial=True)
    half = pattern_name(sum(1 for s in starts if s <= 0.5 * t_end * (1 + 1e-12)))
    v = Verdict(reason if reason == "window_escape" else "finished", pair.pattern, half,
                len(starts), starts[0] if starts else None, t_end, end_t, gamma=pair.gamma,
                dh=pair.dh, t_ref=run.t_ref)
    closing, state = closing_in(pair)
    off, across = out_of_line(pair)
    if pair.pattern == "repeated":
        v.settled = True
        v.why = f"{len(starts)} episodes by t = {end_t:.4g} s (episodes only add)"
    elif v.status == "window_escape":
        v.why = f"a particle left the window at t = {end_t:.4g} s ({state})"
    else:
        v.settled = half == pair.pattern and not closing and not off
        v.why = (f"{half} by t_end/2 = {0.5 * t_end:.4g} s, {pair.pattern} by t_end = "
                 f"{t_end:.4g} s" + (f"; closing in at t_end: {state}" if closing else "")
                 + (f"; out of line at t_end: {across}" if off else ""))
    return v


def wall_seconds(r: PlannedRun) -> float | None:
    """The run's computing time: the sum of the `performance: ... in X s` lines of its log
    (a resumed run appends one per part); None without them."""
    log = r.dir / f"{r.h5.stem}.log"
    try:
        text = log.read_text(errors="replace")
    except OSError:
        return None
    found = re.findall(r"^performance:.* in +([0-9.]+) s on", text, flags=re.M)
    return sum(float(x) for x in found) if found else None


def first_change(lo: tuple[float, str], hi: tuple[float, str],
                 got: dict[float, tuple[Verdict, PlannedRun]]) -> tuple[tuple[float, str],
                                                                        tuple[float, str]]:
    """The first sub-interval, from lo, of lo < the settled points `got` < hi whose two ends
    have different patterns, as the new (lo, hi)."""
    seq = [lo] + [(x, got[x][0].pattern) for x in sorted(got)] + [hi]
    return next((a, b) for a, b in zip(seq, seq[1:], strict=False) if a[1] != b[1])
