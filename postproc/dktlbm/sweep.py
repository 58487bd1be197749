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
more than D_1/2 apart across the channel); otherwise the point runs again
with t_end doubled, up to --max-t-end. A run that ended by window_escape is never final by
itself: the point runs again with window.above doubled, up to --max-above. With a window that
grows (--grow, or window.max_above set in the scene or a --set) each run's window grows by
itself up to its limit (docs/model.md §5), so no point runs again for an escape: one at the
limit stops the bisection. `collect` reports both in regime.csv. With --kiss (a
once-to-never threshold) 'once' and 'repeated' are one class,
'kisses', final as soon as a run has a kissing episode.

`map` runs a grid over both keys and bisects, by the same rules, every grid edge whose ends
differ: DIR/map.csv, DIR/borders.csv and DIR/map.png (`dkt-sweep map --help`).
"""

from __future__ import annotations

import argparse
import concurrent.futures
import csv
import math
import os
import shlex
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from . import launch as mpi
from .read import (
    RunFileError,
    add_version,
    fortran_float,
    guarded,
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
REGIME_CSV = "regime.csv"
COLUMNS = ("id", "gamma", "dh", "dir", "command")
REGIME_COLUMNS = ("gamma", "dh", "pattern", "episodes", "first_kiss_t", "dir", "status",
                  "t_end", "settled", "left_window")
BISECT_CSV = "bisect.csv"
BISECT_STATE = "bisect.json"
BISECT_COLUMNS = ("row", "value", "pattern", "episodes", "first_kiss_t", "t_end", "end_t",
                  "status", "settled", "wall_s", "dir", "above")
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


class SweepError(Exception):
    """A problem with the sweep's input: printed as `error: <text>`, exit status 2."""


# ---------------------------------------------------------------- value lists


MAX_VALUES = 10_000  # values in one --gamma or --dh list
MAX_RUNS = 1000  # runs a plan holds unless --max-runs allows more


def parse_values(text: str) -> list[float]:
    """'1.5,2,2.5' or '1:3:0.5' (inclusive) or a mix ('1,2:4:1'): the values in order, each
    once. ValueError for anything else."""
    values: list[float] = []
    for item in text.split(","):
        item = item.strip()
        if not item:
            continue
        if ":" in item:
            parts = item.split(":")
            if len(parts) != 3:
                raise ValueError(f"range {item!r} is not start:stop:step")
            start, stop, step = (float(p) for p in parts)
            if step <= 0 or stop < start:
                raise ValueError(f"range {item!r} needs start <= stop and step > 0")
            count = (stop - start) / step + 1e-9
            if not math.isfinite(count) or count >= MAX_VALUES:
                raise ValueError(f"range {item!r} gives {count:.4g} values; a list takes at "
                                 f"most {MAX_VALUES}")
            n = int(math.floor(count)) + 1
            values += [round(start + k * step, 12) for k in range(n)]
        else:
            values.append(float(item))
    if not values:
        raise ValueError(f"no values in {text!r}")
    if any(not math.isfinite(v) or v <= 0 for v in values):
        raise ValueError(f"values must be positive numbers: {text!r}")
    return list(dict.fromkeys(values))


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


# ---------------------------------------------------------------- the plan


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


def _fmt(value: float) -> str:
    """A value as runs.csv, regime.csv and run ids write it: 10 significant digits, enough to
    read back every bisection point (8 digits) exactly."""
    return f"{value:.10g}"


def _scene_setting(base: Path, sets: list[str], dotted: str) -> str | None:
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


def _scene_number(base: Path, sets: list[str], dotted: str) -> tuple[float | None, str | None]:
    """group.key (dotted) as the run will see it (_scene_setting), as a number, and its text:
    (None, text) when the text is not a number, (None, None) when nothing gives it."""
    text = _scene_setting(base, sets, dotted)
    try:
        return (fortran_float(text) if text is not None else None), text
    except ValueError:
        return None, text


def _base_value(base: Path, sets: list[str], key: str) -> float | None:
    """pair.<key> as the run will see it: from --set, else from the scene file."""
    return _scene_number(base, sets, f"pair.{key}")[0]


def make_plan(base: Path, gammas: list[float] | None, dhs: list[float] | None,
              sets: list[str], out: Path, exe: str) -> list[PlannedRun]:
    """Every combination of `gammas` x `dhs` (one run of the base scene when neither is
    given), each with its own output directory out/<id>."""
    if not base.is_file():
        raise SweepError(f"{base}: no such scene file")
    base = base.resolve()
    out = out.resolve()
    g_default, h_default = _base_value(base, sets, "gamma"), _base_value(base, sets, "dh")
    plan = []
    for g in gammas or [None]:
        for h in dhs or [None]:
            parts = ([f"g{_fmt(g)}"] if g is not None else []) + (
                [f"h{_fmt(h)}"] if h is not None else [])
            run_id = "_".join(parts) if parts else "run"
            args = [exe, str(base)]
            if g is not None:
                args += ["--set", f"pair.gamma={_fmt(g)}"]
            if h is not None:
                args += ["--set", f"pair.dh={_fmt(h)}"]
            for s in sets:
                args += ["--set", s]
            args += ["--set", f"output.dir={out / run_id}"]
            plan.append(PlannedRun(run_id, g if g is not None else g_default,
                                   h if h is not None else h_default, out / run_id,
                                   shlex.join(args)))
    return plan


def check_plan(plan: list[PlannedRun]) -> None:
    """The program's own checks (`--check`) on the plan's corners: the runs of the smallest and
    largest gamma and D_h/D_1 (a key's allowed range is an interval, so a value out of range
    lies at a corner), with the plan's --set options. SweepError naming the run and quoting the
    program's message when one is refused; a note, and no check, when the executable is not
    on this machine (a plan written here for a cluster)."""
    gs = [r.gamma for r in plan if r.gamma is not None]
    hs = [r.dh for r in plan if r.dh is not None]
    ends_g = (min(gs), max(gs)) if gs else ()
    ends_h = (min(hs), max(hs)) if hs else ()
    corners = [r for r in plan if (r.gamma is None or r.gamma in ends_g)
               and (r.dh is None or r.dh in ends_h)]
    for run in corners:
        args = shlex.split(run.command)
        try:
            proc = subprocess.run([*args, "--check"], capture_output=True, text=True,
                                  timeout=300, env=mpi.mpi_env(), stdin=subprocess.DEVNULL)
        except (FileNotFoundError, PermissionError):
            print(f"note: {args[0]} is not on this machine; the plan is not checked (run "
                  "`dktlbm BASE --check` with a corner's options where it runs)",
                  file=sys.stderr)
            return
        if proc.returncode != 0:
            errors = [ln for ln in proc.stderr.splitlines() if "error:" in ln]
            why = errors[0] if errors else (proc.stderr.strip() or f"exit {proc.returncode}")
            raise SweepError(f"run {run.id} of the plan is refused by {args[0]} --check, so "
                             f"nothing is planned:\n{why}")


def write_plan(plan: list[PlannedRun], out: Path) -> Path:
    out.mkdir(parents=True, exist_ok=True)
    path = out / RUNS_CSV
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(COLUMNS)
        for r in plan:
            w.writerow([r.id, "" if r.gamma is None else _fmt(r.gamma),
                        "" if r.dh is None else _fmt(r.dh), str(r.dir), r.command])
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


# ---------------------------------------------------------------- run here


def clock_text(seconds: float) -> str:
    """Seconds as H:MM:SS (whole seconds, rounded up)."""
    whole = math.ceil(max(seconds, 0.0))
    return f"{whole // 3600}:{whole // 60 % 60:02d}:{whole % 60:02d}"


class Progress:
    """The progress line after each finished run of `total`, `jobs` at a time:

        progress: [step S: ]K of N runs finished, elapsed H:MM:SS, ETA H:MM:SS

    elapsed since `start` (clock() by default); ETA = the mean time of the runs that ran (a
    skipped run took none) times the runs left, over the runs that go on side by side
    (min(jobs, runs left)); 'unknown' before a run has ended."""

    def __init__(self, total: int, jobs: int, step: int | None = None,
                 start: float | None = None, clock=time.monotonic) -> None:
        self.total, self.jobs, self.step, self.clock = total, max(1, jobs), step, clock
        self.start = clock() if start is None else start
        self.done = 0
        self.seconds: list[float] = []

    def finished(self, seconds: float | None) -> str:
        """Count one finished run (`seconds` it took; None: skipped); the line to print."""
        self.done += 1
        if seconds is not None:
            self.seconds.append(seconds)
        left = self.total - self.done
        if left == 0:
            eta = "0:00:00"
        elif self.seconds:
            mean = sum(self.seconds) / len(self.seconds)
            eta = clock_text(mean * left / min(self.jobs, left))
        else:
            eta = "unknown"
        step = f"step {self.step}: " if self.step is not None else ""
        return (f"progress: {step}{self.done} of {self.total} runs finished, elapsed "
                f"{clock_text(self.clock() - self.start)}, ETA {eta}")


def checkpoint_of(h5: Path) -> Path | None:
    """The checkpoint that resumes the run of `h5`: the one its marker <name>.checkpoint
    names, when that file is there; else None."""
    marker = h5.with_suffix(".checkpoint")
    try:
        chk = Path(marker.read_text().strip())
    except OSError:
        return None
    if not chk.is_absolute():
        chk = h5.parent / chk
    return chk if chk.is_file() else None


def run_plan(plan: list[PlannedRun], jobs: int, ranks: int, force: bool,
             progress: Progress | None = None) -> int:
    """Run the plan, `jobs` runs at a time on `ranks` ranks each; the output of each goes to
    <dir>/run.log. Finished runs are skipped unless `force`. After each run a Progress line
    (`progress`, default one for this plan). Returns the number of failures."""
    prefix, env = mpi.mpi_prefix(ranks), mpi.mpi_env(jobs)
    lock = threading.Lock()
    progress = progress or Progress(len(plan), jobs)

    def say(text: str, seconds: float | None = None) -> None:
        with lock:
            print(text, flush=True)
            print(progress.finished(seconds), flush=True)

    def one(r: PlannedRun) -> bool:
        status = run_status(r.h5)
        if status == "running":  # even with --force: its output is not this sweep's to take
            say(f"skip   {r.id}: {r.h5} is being written by a live run")
            return True
        if status == "finished" and not force:
            say(f"skip   {r.id}: {r.h5} is finished (--force runs it again)")
            return True
        r.dir.mkdir(parents=True, exist_ok=True)
        args = r.args
        resume = checkpoint_of(r.h5) if status == "paused" and not force else None
        if resume is not None:
            args += ["--restart", str(resume)]
            with lock:
                print(f"resume {r.id} from {resume}", flush=True)
        elif r.h5.exists():
            args += ["--set", "output.overwrite=.true."]
        log = r.dir / "run.log"
        with lock:
            print(f"start  {r.id}", flush=True)
        t0 = time.monotonic()
        with log.open("w") as f:
            f.write(f"# {shlex.join(prefix + args)}\n")
            f.flush()
            try:
                code = subprocess.run(prefix + args, stdout=f, stderr=subprocess.STDOUT,
                                      env=env).returncode
            except OSError as exc:
                f.write(f"cannot start {prefix[0]}: {exc}\n")
                code = -1
        seconds = time.monotonic() - t0
        if code == 0:
            say(f"done   {r.id} ({seconds:.1f} s)", seconds)
            return True
        say(f"FAILED {r.id}: exit status {code} after {seconds:.1f} s; see {log}", seconds)
        return False

    with concurrent.futures.ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
        results = list(pool.map(one, plan))
    failed = results.count(False)
    print(f"{len(plan)} runs: {len(plan) - failed} finished or skipped, {failed} failed")
    return failed


# ---------------------------------------------------------------- Slurm

SLURM_TEMPLATE = """#!/bin/bash
# Slurm job array of a sweep: task k runs row k of runs.csv (after the header) in <dir>/<id>,
# the directory that holds this script and runs.csv (it may be moved). Submit it with
#   sbatch {script}                      # or: cd <dir> && sbatch sweep.slurm
# sbatch options (--ntasks=2 --time=30 ...) hold for every resubmission too. Each task skips a
# finished run, resumes an interrupted one from its checkpoint, appends to <dir>/<id>/run.log,
# and submits itself again when it stopped with a checkpoint (at most MAX_RESUBMITS times).
# Stop the whole sweep: scancel --name={job_name}. Exit status per task: 0 = finished, or
# stopped and resubmitted; 1 = stopped unfinished and not resubmitted; 2 = a setting is wrong;
# else dktlbm failed. `dkt-sweep collect` shows an unfinished run with a checkpoint as stopped.
#SBATCH --job-name={job_name}
#SBATCH --array=0-{last}{throttle}
#SBATCH --ntasks={ntasks}
#SBATCH --time={time}
#SBATCH --output=slurm-%x-%A_%a.out
{extra}# Slurm sends SIGUSR1 to this batch shell 120 s before the time limit (checked every 30 s);
# it is passed on to the run once the run has its handlers; the run writes a checkpoint and
# stops, and the task submits itself again.
#SBATCH --signal=B:USR1@120
trap 'early_usr1=1' USR1  # noted until the run has started (dkt_run); keep it first
set -u
{setup}MAX_RESUBMITS=${{MAX_RESUBMITS:-{max_resubmits}}}
RESUBMIT=${{RESUBMIT:-0}}
DKTLBM=${{DKTLBM:-}}          # empty = the executable in the plan's commands
SUBMIT_SCRIPT=${{SUBMIT_SCRIPT:-}}
# DKT_LAUNCHER=srun|mpirun|auto, DKT_SRUN_MPI, MPIRUN: how the ranks start (input/slurm/README.md)

# ---- the functions shared with input/slurm/run_one.slurm and sweep_array.slurm (dkt_job.sh)
{library}
# ---- the sweep directory: SWEEP_DIR, else the directory of the submitted script, else the
# ---- submit directory, else where this script was written
sweep=${{SWEEP_DIR:-}}
if [ -z "$sweep" ]; then
  for dir in "$(scontrol show job "${{SLURM_JOB_ID:-none}}" 2>/dev/null |
    sed -n 's/^[[:space:]]*Command=\\(.*\\)\\/[^/]*$/\\1/p')" \\
    "${{SLURM_SUBMIT_DIR:-$PWD}}" {written}; do
    if [ -f "$dir/runs.csv" ]; then sweep=$dir; break; fi
  done
fi
dkt_sweep_task "${{sweep:-.}}/runs.csv"
exit $?
"""


def slurm_script(plan: list[PlannedRun], out: Path, ntasks: int, time_limit: str,
                 partition: str | None, account: str | None, max_parallel: int | None,
                 setup: list[str], job_name: str, max_resubmits: int = 10) -> str:
    """DIR/sweep.slurm: the job array of the plan, with input/slurm/dkt_job.sh written in (so
    the sweep directory needs no source tree) and the sweep directory found at run time."""
    out = out.resolve()
    extra = ""
    if partition:
        extra += f"#SBATCH --partition={partition}\n"
    if account:
        extra += f"#SBATCH --account={account}\n"
    return SLURM_TEMPLATE.format(
        script=shlex.quote(str(out / "sweep.slurm")),
        job_name=job_name,
        last=len(plan) - 1,
        throttle=f"%{max_parallel}" if max_parallel else "",
        ntasks=ntasks,
        time=time_limit,
        extra=extra,
        setup="".join(f"{line}\n" for line in setup),
        max_resubmits=max_resubmits,
        library=(mpi.slurm_dir() / "dkt_job.sh").read_text(),
        written=shlex.quote(str(out)),
    )


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


UNSETTLED = "unsettled"  # a map point not settled within the limits (--keep-going)


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
    import re

    found = re.findall(r"^performance:.* in +([0-9.]+) s on", text, flags=re.M)
    return sum(float(x) for x in found) if found else None


# ---------------------------------------------------------------- bisect


def _value(x: float) -> float:
    """A value as the runs see it: 8 significant digits (the run id and the --set text)."""
    return float(f"{x:.8g}")


@dataclass
class BisectSettings:
    base: Path
    key: str  # 'gamma' or 'dh'
    lo: float
    hi: float
    tol: float
    sets: list[str]
    out: Path
    exe: str
    t_end: float  # s, the runs' first end time
    max_t_end: float  # s
    above: float  # D_1, the runs' first window.above
    max_above: float  # D_1
    kiss: bool = False  # tell 'kisses' (once or repeated) from 'never' only (judge)
    grow: float = 0.0  # D_1, the runs' window.max_above: their windows grow up to it; 0 = never

    def identity(self) -> dict[str, object]:
        """What a rerun in the same directory must repeat to reuse its runs: the base scene,
        the key and the --set options. A run is otherwise named by its value, t_end and
        window (its id), so another --lo, --hi or --tol (a tighter bracket of the same
        question) reuses every run it shares and runs only the new points."""
        import hashlib

        return {"base": str(self.base), "base_sha256": hashlib.sha256(
            self.base.read_bytes()).hexdigest(), "key": self.key, "sets": self.sets}


class Bisector:
    """The bisection over pair.<key>: `launch(todo, every_run)` runs the runs `todo` (all of
    them before it returns); `every_run` is the whole run set so far, DIR/runs.csv.

    A point ("value") is what `coords` turns into pair settings; here one number, the value of
    pair.<key>. A subclass with other points (sweepmap.MapBisector: (x, y) of two keys) gives
    its own coords, name, label and point_of, and settles its points by the same rules."""

    # a point not settled within the limits is a SweepError; a map with --keep-going
    # (sweepmap.MapBisector) keeps it as a Verdict with pattern UNSETTLED and goes on
    keep_going = False

    def __init__(self, cfg: BisectSettings, jobs: int, launch) -> None:
        self.cfg, self.jobs, self.launch = cfg, max(1, jobs), launch
        self.runs: dict[str, PlannedRun] = {}
        self.rows: list[dict[str, str]] = []
        self.launches = 0
        # the values run before in this directory (an earlier --tol, --lo or --hi): runs.csv
        # keeps them, and those already settled narrow the bracket before any new point runs
        self.earlier: set[float] = set()
        if (cfg.out / RUNS_CSV).is_file():
            for r in read_plan(cfg.out):
                self.runs[r.id] = r
                value = self.point_of(r)
                if value is not None:
                    self.earlier.add(value)

    def coords(self, value: float) -> dict[str, float]:
        """The pair settings of a point: {key: value}, key 'gamma' or 'dh'."""
        return {self.cfg.key: value}

    def point_of(self, r: PlannedRun):
        """The point a run of runs.csv is at (None: the run has no value of the key)."""
        return r.gamma if self.cfg.key == "gamma" else r.dh

    def name(self, value: float) -> str:
        """The point as the messages name it: 'gamma = 1.5'."""
        return f"{self.cfg.key} = {value:.8g}"

    def label(self, value: float) -> dict[str, str]:
        """The columns that name the point in a row of bisect.csv."""
        return {"row": "run", "value": f"{value:.8g}"}

    def planned(self, value: float, t_end: float, above: float) -> PlannedRun:
        c = self.cfg
        at = self.coords(value)
        keys = [k for k in ("gamma", "dh") if k in at]  # ids as plan names them: g<G>_h<H>
        run_id = "_".join(f"{'g' if k == 'gamma' else 'h'}{at[k]:.8g}" for k in keys)
        run_id += f"_t{t_end:g}" if t_end != c.t_end else ""
        run_id += f"_a{above:g}" if above != c.above else ""
        args = [c.exe, str(c.base)]
        for k in keys:
            args += ["--set", f"pair.{k}={at[k]:.8g}"]
        for s in c.sets:
            args += ["--set", s]
        args += ["--set", f"run.t_end={t_end:g}"]
        args += ["--set", f"window.above={above:g}"] if above != c.above else []
        args += ["--set", f"output.dir={c.out / run_id}"]
        g = at["gamma"] if "gamma" in at else _base_value(c.base, c.sets, "gamma")
        h = at["dh"] if "dh" in at else _base_value(c.base, c.sets, "dh")
        return PlannedRun(run_id, g, h, c.out / run_id, shlex.join(args))

    def _record(self, value: float, r: PlannedRun, v: Verdict, above: float,
                cut: bool = False) -> None:
        """One bisect.csv row per run and end time, however often the search reads it (a point
        settled before is read by the narrowing pass, and again if it becomes a step's point);
        a longer run read up to an earlier end time (known) has a row for each."""
        if any(row["dir"] == str(r.dir) and row["t_end"] == f"{v.t_end:.6g}"
               for row in self.rows):
            return
        wall = None if cut else wall_seconds(r)  # a cut's time is its longer run's
        self.rows.append({
            **self.label(value), "pattern": v.run_pattern or v.status,
            "episodes": str(v.episodes) if v.classified else "",
            "first_kiss_t": "" if v.first_kiss is None else f"{v.first_kiss:.6g}",
            "t_end": f"{v.t_end:.6g}" if math.isfinite(v.t_end) else "",
            "end_t": f"{v.end_t:.6g}" if math.isfinite(v.end_t) else "",
            "status": v.status, "settled": "yes" if v.settled else "no",
            "wall_s": "" if wall is None else f"{wall:.3g}", "dir": str(r.dir),
            "above": f"{above:g}"})

    def known(self, value: float, t_end: float,
              above: float) -> tuple[Verdict, PlannedRun] | None:
        """The Verdict of `value` at (t_end, above) from the runs already in the directory,
        without running anything, or None: its own run when finished, or when stopped after
        the episodes that settle it (judge); else the shortest longer run of the value (same
        window, another t_end in its id) whose samples reach t_end, read up to t_end (the
        run to t_end would have given the same samples)."""
        c, r = self.cfg, self.planned(value, t_end, above)
        if r.h5.exists():
            v = judge(verdict(r.h5), c.kiss)
            if v.status in ("finished", "window_escape"):
                print(f"reuse  {r.id}: {r.h5} is finished", flush=True)
                return v, r
            if v.partial and v.settled:
                print(f"reuse  {r.id}: {r.h5} {v.why}", flush=True)
                return v, r
        stem = self.planned(value, c.t_end, c.above).id  # the ids: stem[_t<t_end>][_a<above>]
        longer = []
        for d in c.out.glob(f"{stem}_t*"):
            try:
                t_long = float(d.name[len(stem) + 2:].partition("_a")[0])
            except ValueError:
                continue
            if t_long > t_end and d.name == self.planned(value, t_long, above).id:
                longer.append(t_long)
        for t_long in sorted(longer):
            other = self.planned(value, t_long, above)
            v = judge(verdict(other.h5, until=t_end), c.kiss)
            if v.status == "finished":
                print(f"reuse  {other.id} up to t_end = {t_end:g} s (for {r.id})", flush=True)
                return v, other
        return None

    def settle(self, values: list[float],
               known_only: bool = False) -> dict[float, tuple[Verdict, PlannedRun]]:
        """Run each value until its pattern is settled (Verdict): at the first t_end and
        window.above; with t_end doubled while a finished run is not settled, up to max_t_end;
        with window.above doubled after a window escape, up to max_above. SweepError for a run
        that failed and for a point not settled within either limit. A point the directory's
        runs already answer (known) is not run again. With `known_only`, run nothing: return
        the values that the runs in the directory settle."""
        c = self.cfg
        target = {v: (c.t_end, c.above) for v in values}
        done: dict[float, tuple[Verdict, PlannedRun]] = {}
        while target:
            have = {v: self.known(v, t, a) for v, (t, a) in target.items()}
            if known_only:
                target = {v: ta for v, ta in target.items() if have[v] is not None}
            asked = {v: self.planned(v, t, a) for v, (t, a) in target.items()}
            # the run that answers each value: one already in the directory, else its own
            runs = {v: have[v][1] if have[v] is not None else asked[v] for v in target}
            for r in runs.values():
                self.runs.setdefault(r.id, r)
            todo = [asked[v] for v in target if have[v] is None]
            if todo:
                self.launches += 1
                self.launch(todo, list(self.runs.values()))
            for value, r in runs.items():
                t_end, above = target[value]
                v = have[value][0] if have[value] is not None else judge(verdict(r.h5), c.kiss)
                self._record(value, r, v, above, cut=r.id != asked[value].id)
                name = self.name(value)
                at = f"t_end = {t_end:g} s, window.above = {above:g} D_1"
                if not v.classified or v.partial and not v.settled:
                    raise SweepError(
                        f"run {r.dir} ({name}, {at}) gave no pattern: "
                        f"{v.status}: {v.why}; see {r.dir / 'run.log'}")
                if v.settled:
                    print(f"  {name}: {v.pattern} ({v.episodes} episode"
                          f"{'s' if v.episodes != 1 else ''}), settled at {at}: {v.why}",
                          flush=True)
                    done[value] = (v, r)
                    del target[value]
                elif v.status == "window_escape" and c.grow > 0:
                    # the window grew as far as it may: a larger one is a larger limit, which
                    # the user chooses (a run again would only repeat this one)
                    self._give_up(done, target, value, v, r, (
                        f"run {r.dir} ({name}, {at}): {v.why}, in a window grown to its limit "
                        f"window.max_above = {c.grow:g} D_1; its pattern ({v.pattern} so far) "
                        f"is not final: raise --max-above (or window.max_above), or bracket "
                        f"away from this value"))
                elif v.status == "window_escape":
                    if 2 * above > c.max_above * (1 + 1e-12):
                        self._give_up(done, target, value, v, r, (
                            f"run {r.dir} ({name}, {at}): {v.why}; its pattern ({v.pattern} so "
                            f"far) is not final, and doubling window.above would pass "
                            f"--max-above {c.max_above:g} D_1: raise --max-above, or bracket "
                            f"away from this value"))
                        continue
                    print(f"  {name}: not settled at {at}: {v.why}; running it again with "
                          f"window.above = {2 * above:g} D_1", flush=True)
                    target[value] = (t_end, 2 * above)
                elif 2 * t_end > c.max_t_end * (1 + 1e-12):
                    self._give_up(done, target, value, v, r, (
                        f"run {r.dir} ({name}): the pattern is not settled at {at} "
                        f"({v.why}) and doubling t_end would pass --max-t-end "
                        f"{c.max_t_end:g} s"))
                else:
                    print(f"  {name}: not settled at {at} ({v.why}); running it to "
                          f"{2 * t_end:g} s", flush=True)
                    target[value] = (2 * t_end, above)
        return done

    def _give_up(self, done: dict, target: dict, value, v: Verdict, r: PlannedRun,
                 message: str) -> None:
        """A point not settled within the limits (`message` says which): SweepError, or with
        keep_going its Verdict, pattern UNSETTLED and `why` the message, is the point's answer
        in `done` (its run's own pattern stays in run_pattern)."""
        if not self.keep_going:
            raise SweepError(message)
        print(f"  {self.name(value)}: unsettled: {message}; the map goes on around it",
              flush=True)
        v.pattern, v.settled, v.why = UNSETTLED, False, message
        done[value] = (v, r)
        del target[value]

    def search(self) -> tuple[tuple[float, str], tuple[float, str]]:
        """The bracket (value, pattern) at each end, hi - lo <= tol. With jobs N, each step
        runs up to N points spaced evenly inside the bracket (no more than needed to reach
        tol) and keeps the first sub-interval, from lo, whose ends differ."""
        c = self.cfg
        first = self.settle([c.lo, c.hi])
        lo, hi = (c.lo, first[c.lo][0].pattern), (c.hi, first[c.hi][0].pattern)
        if lo[1] == hi[1]:
            raise SweepError(
                f"{c.key} = {c.lo:.8g} and {c.key} = {c.hi:.8g} give the same pattern, "
                f"{lo[1]} and {hi[1]}: --lo and --hi must bracket a change of pattern")
        while hi[0] - lo[0] > c.tol * (1 + 1e-9):
            inside = sorted(v for v in self.earlier if lo[0] < v < hi[0])
            self.earlier -= set(inside)  # each earlier point is read once
            known = self.settle(inside, known_only=True) if inside else {}
            if known:  # settled before (another --tol): narrow with them, running nothing
                lo, hi = _first_change(lo, hi, known)
                continue
            width = hi[0] - lo[0]
            n = min(self.jobs, max(1, math.ceil(width / c.tol - 1e-9) - 1))
            xs = sorted({_value(lo[0] + k * width / (n + 1)) for k in range(1, n + 1)}
                        - {lo[0], hi[0]})
            if not xs:
                raise SweepError(f"--tol {c.tol:g} is finer than 8 significant digits of "
                                 f"{c.key} resolve")
            lo, hi = _first_change(lo, hi, self.settle(xs))
        return lo, hi


def _first_change(lo: tuple[float, str], hi: tuple[float, str],
                  got: dict[float, tuple[Verdict, PlannedRun]]) -> tuple[tuple[float, str],
                                                                         tuple[float, str]]:
    """The first sub-interval, from lo, of lo < the settled points `got` < hi whose two ends
    have different patterns, as the new (lo, hi)."""
    seq = [lo] + [(x, got[x][0].pattern) for x in sorted(got)] + [hi]
    return next((a, b) for a, b in zip(seq, seq[1:], strict=False) if a[1] != b[1])


def bisect_state(cfg: BisectSettings, state: str = BISECT_STATE,
                 what_it_is: str = "bisection") -> None:
    """Refuse a directory that holds a bisection (DIR/`state`: a map's is map.json) with other
    settings (cfg.identity()); record ours."""
    import json

    path = cfg.out / state
    ours = cfg.identity()
    if path.is_file():
        try:
            theirs = json.loads(path.read_text())
        except (OSError, ValueError) as exc:
            raise SweepError(f"{path}: unreadable ({exc}); remove it or use another --out") \
                from None
        changed = [k for k in ours if theirs.get(k) != ours[k]]
        if changed:
            what = "; ".join(f"{k}: {theirs.get(k)!r} there, {ours[k]!r} now" for k in changed
                             if k != "base_sha256") or "the base scene's text changed"
            raise SweepError(f"{cfg.out} holds a {what_it_is} with other settings ({what}); "
                             f"its runs do not answer this one: use another --out, or remove "
                             f"{path} to reuse the runs anyway")
    elif (cfg.out / RUNS_CSV).exists():
        raise SweepError(f"{cfg.out} holds a sweep plan or another search, not a {what_it_is}: "
                         f"use another --out")
    cfg.out.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(ours, indent=1) + "\n")


def write_bisect(b: Bisector, lo: tuple[float, str], hi: tuple[float, str]) -> Path:
    """DIR/bisect.csv: every run, then the bracket's rows 'lo' and 'hi' (each the settled
    run of that value); DIR/runs.csv: every run, as a plan."""
    ends = []
    for name, (value, pattern) in (("lo", lo), ("hi", hi)):
        settled = [r for r in b.rows if r["value"] == f"{value:.8g}" and r["settled"] == "yes"]
        ends.append({**settled[-1], "row": name, "pattern": pattern})
    path = b.cfg.out / BISECT_CSV
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=BISECT_COLUMNS)
        w.writeheader()
        w.writerows(b.rows + ends)
    write_plan(list(b.runs.values()), b.cfg.out)
    return path


def slurm_launcher(out: Path, ntasks: int, time_limit: str, partition: str | None,
                   setup: list[str]):
    """Each call writes DIR/runs.csv (every run so far) and DIR/sweep.slurm (slurm_script), and
    submits the rows of `todo` as one job array, `sbatch --wait --array=i,j,...`, which
    returns when the array has ended."""

    def launch(todo: list[PlannedRun], every: list[PlannedRun]) -> None:
        write_plan(every, out)
        script = out / "sweep.slurm"
        script.write_text(slurm_script(every, out, ntasks, time_limit, partition, None, None,
                                       setup, "dkt-bisect"))
        script.chmod(0o755)
        index = {r.id: k for k, r in enumerate(every)}
        array = ",".join(str(index[r.id]) for r in todo)
        command = [os.environ.get("SBATCH") or "sbatch", "--wait", f"--array={array}",
                   str(script)]
        print(f"submit {shlex.join(command)}", flush=True)
        try:
            proc = subprocess.run(command, capture_output=True, text=True)
        except OSError as exc:
            raise SweepError(f"cannot run {command[0]}: {exc}") from None
        sys.stdout.write(proc.stdout)
        if "Submitted batch job" not in proc.stdout:
            raise SweepError(f"{shlex.join(command)} failed (exit status {proc.returncode}): "
                             f"{proc.stderr.strip()}")

    return launch


def local_launcher(jobs: int, ranks: int):
    """Each call runs the rows of `todo` here (run_plan); the progress lines count the runs of
    that step (the n-th call) and the time since the first call."""
    start = time.monotonic()
    steps = 0

    def launch(todo: list[PlannedRun], every: list[PlannedRun]) -> None:
        nonlocal steps
        steps += 1
        write_plan(every, todo[0].dir.parent)
        run_plan(todo, jobs, ranks, force=False, progress=Progress(len(todo), jobs, steps, start))

    return launch


def bisect(cfg: BisectSettings, jobs: int, launch) -> tuple[Bisector, str]:
    """Run the bisection; write DIR/bisect.csv and DIR/runs.csv; return the summary line."""
    bisect_state(cfg)
    b = Bisector(cfg, jobs, launch)
    try:
        lo, hi = b.search()
    finally:
        if b.runs:
            write_plan(list(b.runs.values()), cfg.out)
    write_bisect(b, lo, hi)
    n, files = len(b.rows), len({row["dir"] for row in b.rows})
    count = (f"{n} run{'s' if n != 1 else ''}" if files == n else
             f"{n} verdicts from {files} run{'s' if files != 1 else ''} (longer runs read up "
             f"to earlier end times)")
    return b, (f"{cfg.key} threshold between {lo[0]:.8g} ({lo[1]}) and {hi[0]:.8g} ({hi[1]}), "
               f"{count}")


# ---------------------------------------------------------------- collect


def collect(plan: list[PlannedRun]) -> list[dict[str, str]]:
    """One regime.csv row per planned run: its pattern, number of kissing episodes and the
    start of the first one (s); pattern 'missing' without a run file, 'running' while a live
    run writes it, 'paused' when it stopped cleanly to be resumed (stop_reason 'signal' or
    'wall_limit'), 'stopped' when it was killed but has a checkpoint to resume from
    (<name>.checkpoint), or, after a clean stop with a kissing episode, the pattern so far
    (status the stop reason; settled only when 'repeated': episodes only add), 'failed' when
    the file is not a finished run otherwise."""
    rows = []
    for r in plan:
        status = run_status(r.h5)
        if status == "failed" and r.h5.with_suffix(".checkpoint").is_file():
            status = "stopped"  # killed, but resumable from its last checkpoint
        v = verdict(r.h5)  # pattern and settling columns both come from this one verdict
        gamma, dh = r.gamma, r.dh
        pattern, episodes, first = status, "", ""
        if status == "finished":
            if v.classified:
                pattern, episodes = v.pattern, str(v.episodes)
                first = f"{v.first_kiss:.6g}" if v.first_kiss is not None else ""
                gamma = gamma if gamma is not None else v.gamma
                dh = dh if dh is not None else v.dh
            else:
                pattern = "failed"
        elif status in ("stopped", "paused") and v.partial:  # after a kiss: the pattern so far
            pattern, episodes = v.pattern, str(v.episodes)
            first = f"{v.first_kiss:.6g}" if v.first_kiss is not None else ""
        rows.append({
            "gamma": "" if gamma is None else _fmt(gamma),
            "dh": "" if dh is None else _fmt(dh),
            "pattern": pattern,
            "episodes": episodes,
            "first_kiss_t": first,
            "dir": str(r.dir),
            **_settling_columns(v, pattern),
            # for the map only (not a regime.csv column): how far the run got, in t*
            "end_tstar": (f"{v.end_t / v.t_ref:.6g}"
                          if v.classified and math.isfinite(v.end_t / v.t_ref) else ""),
        })
    return rows


def _settling_columns(v: Verdict, pattern: str) -> dict[str, str]:
    """regime.csv's last columns: status (finished, window_escape, or why the run stopped),
    t_end (s, the run's planned end), settled (yes/no: the bisect rule, Verdict), left_window
    (yes when a particle left the window: the run ended early and only the particle still in
    it has late-time values), from the run's Verdict `v`."""
    if pattern == "missing":
        return {"status": "missing", "t_end": "", "settled": "", "left_window": ""}
    classified = v.classified and pattern in ("repeated", "once", "never")
    return {"status": v.status,
            "t_end": f"{v.t_end:.6g}" if math.isfinite(v.t_end) else "",
            "settled": ("yes" if v.settled else "no") if classified else "",
            "left_window": "yes" if v.status == "window_escape" else "no"}


def regime_layout(placed: list[dict[str, str]]):
    """How the regime map places runs (rows with gamma and dh): returns (line, point). Along
    one key (a bisection, or a sweep of gamma at one D_h or of D_h at one gamma), line is that
    key and point(row) = (its value, how far the run got in t*), so the runs of one point
    (longer, or with a taller window) stand apart; a run without a pattern (failed, missing)
    sits at t* = 0. Otherwise line is None and point(row) = (D_h/D_1, gamma)."""
    line = next((k for k, other in (("gamma", "dh"), ("dh", "gamma"))
                 if len({float(r[k]) for r in placed}) > 1
                 and len({float(r[other]) for r in placed}) == 1), None)

    def point(r: dict[str, str]) -> tuple[float, float]:
        if line is not None:
            return float(r[line]), float(r.get("end_tstar") or 0.0)
        return float(r["dh"]), float(r["gamma"])

    return line, point


def write_regime(rows: list[dict[str, str]], out: Path, pdf: bool) -> list[Path]:
    from matplotlib.figure import Figure

    csv_path = out / REGIME_CSV
    with csv_path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=REGIME_COLUMNS, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)

    fig = Figure(figsize=(6.5, 4.8), layout="constrained")
    ax = fig.subplots()
    placed = [r for r in rows if r["gamma"] and r["dh"]]
    line, point = regime_layout(placed)

    for pattern, (marker, colour) in STYLE.items():
        for settled in (False, True):
            pts = [point(r) for r in placed
                   if r["pattern"] == pattern and (r.get("settled") == "no") != settled]
            if not pts:
                continue
            xs, ys = zip(*pts, strict=True)
            label = f"{pattern} ({len(pts)})" if settled else f"{pattern}, not settled ({len(pts)})"
            ax.scatter(xs, ys, marker=marker, s=60 if settled else 110, label=label, zorder=3,
                       **({"color": colour} if settled else {"facecolors": "none",
                                                             "edgecolors": colour}))
    dhs = [float(r["dh"]) for r in placed]
    if line != "gamma" and dhs and min(dhs) > 0 and max(dhs) / min(dhs) > 10:
        ax.set_xscale("log")
    if line is None:
        ax.set_xlabel("$D_h/D_1$")
        ax.set_ylabel(r"$\gamma = D_1/D_2$")
    else:
        fixed = (("D_h/D_1", placed[0]["dh"]) if line == "gamma"
                 else ("\\gamma", placed[0]["gamma"]))
        ax.set_xlabel(r"$\gamma = D_1/D_2$" if line == "gamma" else "$D_h/D_1$")
        ax.set_ylabel("end of the run, $t^*$ (hollow: not settled)")
        ax.text(0.02, 0.98, f"${fixed[0]} = {fixed[1]}$", transform=ax.transAxes, va="top")
    ax.set_title(f"DKT regimes: {len(rows)} runs"
                 + (f" ({len(rows) - len(placed)} without gamma or D_h not drawn)"
                    if len(placed) < len(rows) else ""), fontsize="medium")
    ax.grid(True, alpha=0.3)
    ax.margins(0.08)
    if placed:
        ax.legend(fontsize="small", loc="upper left", bbox_to_anchor=(1.01, 1.0))
    png = out / "regime.png"
    written = [csv_path, png]
    fig.savefig(png, dpi=150)
    if pdf:
        written.append(png.with_suffix(".pdf"))
        fig.savefig(written[-1])
    return written


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
        "run file) and draw DIR/regime.png: D_h/D_1 across, gamma up, one marker per pattern.")
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
        "channel), at t_end is not settled. A run ended by window_escape is "
        "never final: the point runs again with window.above doubled, up to --max-above; with "
        "--grow (or window.max_above in the scene) each run's window grows by itself up to its "
        "limit instead, and an escape at the limit stops the bisection. With "
        "--kiss only a kiss is told from none: a run with a kissing episode is final at once. A "
        "run stopped by a guard or an error stops the bisection. Every run is DIR/<id> and a row "
        "of DIR/runs.csv (collect and plot as a sweep); DIR/bisect.csv lists every run and "
        "the final bracket. Rerunning the command reuses the finished runs (also with another "
        "--lo, --hi or --tol: only new points run); another base scene or --set list for "
        "the same DIR is refused. Here, after each run a line 'progress: step S: K of N runs "
        "finished, elapsed H:MM:SS, ETA H:MM:SS' (elapsed since the bisection started, ETA "
        "of step S).")
    bis.add_argument("base", type=Path, metavar="BASE.nml", help="the base scene (namelist)")
    bis.add_argument("--key", choices=("gamma", "dh"), required=True,
                     help="pair.gamma (D_1/D_2) or pair.dh (D_h/D_1)")
    bis.add_argument("--lo", type=float, required=True, metavar="A", help="one end")
    bis.add_argument("--hi", type=float, required=True, metavar="B", help="the other end")
    bis.add_argument("--tol", type=float, required=True, metavar="T",
                     help="stop when the bracket is at most T wide")
    search_options(bis, "runs at the same time, and points per step (default 1)")
    with_out(bis)
    from .sweepmap import add_parser as add_map  # the map uses this module: imported late

    add_map(sub, with_out)
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
                   help="the largest window.above (in D_1) a point may need to hold both "
                   "particles (default: 4 times the first, the scene's or --set's)")
    q.add_argument("--grow", action="store_true",
                   help="let each run's window grow up to --max-above (window.max_above, "
                   "docs/model.md section 5) instead of running a point again with "
                   "window.above doubled after a window escape")
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
    lo, hi = sorted((_value(args.lo), _value(args.hi)))
    if not (0 < lo < hi) or not (math.isfinite(args.tol) and args.tol > 0):
        raise SweepError(f"--lo and --hi must be two different positive values and --tol "
                         f"positive (got {args.lo:g}, {args.hi:g}, {args.tol:g})")
    base = args.base.resolve()
    limits = settling_limits(args, base)
    sets, grow = growth(args, base, limits[3])
    cfg = BisectSettings(base, args.key, lo, hi, args.tol, sets, args.out.resolve(),
                         args.exe or default_exe(), *limits, args.kiss, grow)
    b, summary = bisect(cfg, args.jobs, search_launcher(args, cfg.out))
    print(f"wrote {cfg.out / BISECT_CSV}, {cfg.out / RUNS_CSV}")
    print(summary)
    return 0


def settling_limits(args: argparse.Namespace,
                    base: Path) -> tuple[float, float, float, float]:
    """(t_end, max_t_end, above, max_above) of a search (search_options) of the scene `base`:
    the first run.t_end and window.above (the scene's or --set's; the program's window.above
    when neither gives it) and the largest a point may use. SweepError for a bad one, and for
    --jobs, --ranks or --ntasks below 1."""
    if args.jobs < 1 or args.ranks < 1 or args.ntasks < 1:
        raise SweepError("--jobs, --ranks and --ntasks must be at least 1")
    t_end, text = _scene_number(base, args.sets, "run.t_end")
    if not (t_end is not None and math.isfinite(t_end) and t_end > 0):
        raise SweepError(f"{base}: &run t_end is not given (or not a positive number: "
                         f"{text!r}); the settling rule needs it: --set run.t_end=SECONDS")
    max_t_end = args.max_t_end if args.max_t_end is not None else 8 * t_end
    if max_t_end < t_end:
        raise SweepError(f"--max-t-end {max_t_end:g} is below run.t_end = {t_end:g} s")
    above, text = _scene_number(base, args.sets, "window.above")
    if not text:  # the program's default
        above = fortran_float(program_settings(None)["window"]["above"][0])
    if not (above is not None and math.isfinite(above) and above >= 1):
        raise SweepError(f"{base}: &window above is not a number >= 1 ({text!r}); set it with "
                         f"--set window.above=D (in D_1)")
    max_above = args.max_above if args.max_above is not None else 4 * above
    if not max_above >= above:
        raise SweepError(f"--max-above {max_above:g} is below window.above = {above:g} D_1")
    return t_end, max_t_end, above, max_above


def growth(args: argparse.Namespace, base: Path, max_above: float) -> tuple[list[str], float]:
    """The --set list of a search's runs and the window.max_above they grow to (0: their
    windows do not grow): the scene's or --set's window.max_above, else with --grow the
    search's --max-above, added to the --set list so that a rerun's identity includes it."""
    sets = list(args.sets)
    grow, _ = _scene_number(base, sets, "window.max_above")
    if grow is None or not math.isfinite(grow) or grow <= 0:
        grow = 0.0
        if args.grow:
            grow = max_above
            sets.append(f"window.max_above={max_above:g}")
    return sets, grow


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
        from .sweepmap import map_command

        return map_command(args)
    if args.command == "plan":
        runs = len(args.gamma or [None]) * len(args.dh or [None])
        if runs > args.max_runs:
            raise SweepError(f"the plan would hold {runs} runs, more than --max-runs "
                             f"{args.max_runs}: narrow --gamma or --dh, or pass --max-runs "
                             f"{runs} to plan them all")
        plan = make_plan(args.base, args.gamma, args.dh, args.sets, out,
                         args.exe or default_exe())
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
    return 0


if __name__ == "__main__":
    sys.exit(main())
