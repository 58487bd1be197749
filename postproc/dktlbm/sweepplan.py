"""A sweep's plan, its runs and its regime map: `dkt-sweep plan`, `run`, `slurm` and `collect`.

`plan` writes DIR/runs.csv, one run of the base scene per combination of the values of
pair.gamma and pair.dh (make_plan, write_plan); `run` runs them here, N at a time (run_plan),
and `slurm` writes DIR/sweep.slurm, a job array of them (slurm_script); `collect` reads each
run's pattern and whether it is settled into DIR/regime.csv, draws DIR/regime.png and says
what the runs still need (collect, write_regime, collect_summary).
"""

from __future__ import annotations

import concurrent.futures
import csv
import math
import os
import shlex
import subprocess
import sys
import threading
import time
from pathlib import Path

import h5py

from . import launch as mpi
from .read import run_status
from .sweepcommon import (
    STOPPED_CLEANLY,
    STYLE,
    PlannedRun,
    SweepError,
    Verdict,
    base_value,
    clock_text,
    default_exe,
    fmt_value,
    scene_number,
    verdict,
    window_above,
)

REGIME_CSV = "regime.csv"
REGIME_COLUMNS = ("gamma", "dh", "pattern", "episodes", "first_kiss_t", "dir", "status",
                  "t_end", "settled", "left_window")


# ---------------------------------------------------------------- the plan


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



def make_plan(base: Path, gammas: list[float] | None, dhs: list[float] | None,
              sets: list[str], out: Path, exe: str) -> list[PlannedRun]:
    """Every combination of `gammas` x `dhs` (one run of the base scene when neither is
    given), each with its own output directory out/<id>."""
    if not base.is_file():
        raise SweepError(f"{base}: no such scene file")
    base = base.resolve()
    out = out.resolve()
    g_default, h_default = base_value(base, sets, "gamma"), base_value(base, sets, "dh")
    plan = []
    for g in gammas or [None]:
        for h in dhs or [None]:
            parts = ([f"g{fmt_value(g)}"] if g is not None else []) + (
                [f"h{fmt_value(h)}"] if h is not None else [])
            run_id = "_".join(parts) if parts else "run"
            args = [exe, str(base)]
            if g is not None:
                args += ["--set", f"pair.gamma={fmt_value(g)}"]
            if h is not None:
                args += ["--set", f"pair.dh={fmt_value(h)}"]
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


# ---------------------------------------------------------------- run here


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
            "gamma": "" if gamma is None else fmt_value(gamma),
            "dh": "" if dh is None else fmt_value(dh),
            "pattern": pattern,
            "episodes": episodes,
            "first_kiss_t": first,
            "dir": str(r.dir),
            **_settling_columns(v, pattern),
            # for the map only (not a regime.csv column): how far the run got, in t*
            "end_tstar": (f"{v.end_t / v.t_ref:.6g}"
                          if v.classified and math.isfinite(v.end_t / v.t_ref) else ""),
            "why": v.why,  # for collect_summary only
        })
    return rows


def collect_summary(plan: list[PlannedRun], rows: list[dict[str, str]],
                    out: Path) -> list[str]:
    """What `collect` says after the table (`rows`, one per run of `plan`, from collect; `out`
    the sweep directory as the user named it): how many runs are settled, unsettled or
    without a pattern, the runs that stopped before their t_end, and what to do next:

    - unsettled runs that finished: plan them again with run.t_end doubled (rerun_plans);
    - unsettled runs that left the window: plan them again in a window that grows
      (window.max_above: twice the runs' own limit, else 4 times window.above);
    - runs without a file, still running or stopped cleanly: `dkt-sweep run` runs or resumes
      them; runs that failed: their run.log."""
    settled = [k for k, row in enumerate(rows) if row["settled"] == "yes"]
    unsettled = [k for k, row in enumerate(rows) if row["settled"] == "no"]
    none = [k for k, row in enumerate(rows) if row["settled"] == ""]
    kinds = _count(rows[k]["pattern"] for k in none)
    lines = [f"{len(rows)} run{'s' if len(rows) != 1 else ''}: {len(settled)} settled, "
             f"{len(unsettled)} unsettled, {len(none)} without a pattern"
             + (f" ({kinds})" if kinds else "")]
    early = [k for k, row in enumerate(rows)
             if row["status"] not in ("finished", "missing", "running")]
    if early:
        lines.append(f"{len(early)} stopped before t_end: " + ", ".join(
            f"{plan[k].id} ({rows[k]['status']})" for k in early))
    later = [k for k in unsettled if rows[k]["status"] == "finished"]
    if later:
        t_end = 2 * max(float(rows[k]["t_end"]) for k in later)
        lines.append(
            f"{_runs(len(later))} unsettled: the pattern may still change after t_end "
            f"(postproc/README.md, 'Settled patterns'); rerun with a later run.t_end:")
        lines += rerun_plans([plan[k] for k in later], f"run.t_end={t_end:g}",
                             Path(f"{out}_t{t_end:g}"), out)
    escaped = [k for k in unsettled if rows[k]["status"] == "window_escape"]
    if escaped:
        limit = max(_window_limit(plan[k]) for k in escaped)
        lines.append(
            f"{_runs(len(escaped))} unsettled after a particle left the window: rerun in a "
            f"window that grows up to {limit:g} D_1 (window.max_above, docs/model.md section 5):")
        lines += rerun_plans([plan[k] for k in escaped], f"window.max_above={limit:g}",
                             Path(f"{out}_a{limit:g}"), out)
    waiting = [k for k in none + unsettled
               if rows[k]["pattern"] in ("missing", "paused", "stopped")
               or rows[k]["status"] in STOPPED_CLEANLY]
    if waiting:
        lines.append(f"{_runs(len(waiting))} not run to its end yet: `dkt-sweep run --out "
                     f"{out}` runs {'them' if len(waiting) > 1 else 'it'} (a paused or "
                     f"stopped run resumes from its checkpoint)")
    failed = [k for k in none if rows[k]["pattern"] == "failed"]
    for k in failed:
        lines.append(f"run {plan[k].id} failed ({rows[k]['status']}: {rows[k]['why']}); "
                     f"see {plan[k].dir / 'run.log'}")
    return lines


def _count(names) -> str:
    """'failed: 1, missing: 2' for the names given."""
    counts: dict[str, int] = {}
    for name in names:
        counts[name] = counts.get(name, 0) + 1
    return ", ".join(f"{k}: {v}" for k, v in sorted(counts.items()))


def _runs(n: int) -> str:
    return f"{n} run{'s' if n != 1 else ''}"


def _window_limit(r: PlannedRun) -> float:
    """The window.max_above to rerun the run `r` with after it left its window: twice its own
    limit when its window could grow (the limit its --set options or scene give, else the one
    its run file states, that of the default window.max_above = -1), else 4 times its
    window.above (a window that never grew)."""
    base, sets = Path(r.args[1]), _sets_of(r)
    grown = scene_number(base, sets, "window.max_above")[0]
    if grown is not None and grown > 0:
        return 2 * grown
    above, text = window_above(base, sets)
    if above is None:  # the run could not have started with it
        raise SweepError(f"run {r.id}: window.above = {text!r} is not a number")
    reached = _limit_of_run(r.h5, above) if grown != 0 else None
    return 2 * reached if reached is not None else 4 * above


def _limit_of_run(h5: Path, above: float) -> float | None:
    """The D_1 above the lowest centre a run's window could grow to, from its run file: it
    starts `above` D_1 over that centre with /run ny rows of dx and may reach /run ny_max rows
    (D_1 = /run d1). None when the file or its ny_max (files of earlier versions) is missing or
    the window could not grow."""
    try:
        with h5py.File(h5, "r") as f:
            a = f["run"].attrs
            ny, ny_max = int(a["ny"]), int(a["ny_max"])
            step = float(a["dx"]) / float(a["d1"])
    except (OSError, KeyError, ValueError):
        return None
    return round(above + (ny_max - ny) * step, 2) if ny_max > ny else None


def _sets_of(r: PlannedRun) -> list[str]:
    """The run's --set options, in order."""
    args = r.args
    return [v for flag, v in zip(args, args[1:], strict=False) if flag == "--set"]


def rerun_plans(runs: list[PlannedRun], change: str, new: Path, out: Path) -> list[str]:
    """The commands that run `runs` again with the --set `change` (group.key=value) into the
    sweep directory `new` and collect them with the sweep `out`: a `dkt-sweep plan` of the
    runs' scene and --set options (but pair.gamma, pair.dh, output.dir and the changed key)
    with --gamma and --dh lists that give exactly those runs; when one plan cannot (runs with
    other options, or not a full grid: then one plan per gamma), plans into new_1, new_2, ...
    Then `dkt-sweep run` of each, and one `dkt-sweep collect`."""
    key = change.partition("=")[0]
    groups: dict[tuple[str, ...], list[PlannedRun]] = {}
    for r in runs:
        kept = [s for s in _sets_of(r) if s.partition("=")[0].strip().lower()
                not in ("pair.gamma", "pair.dh", "output.dir", key)]
        groups.setdefault((r.args[0], r.args[1], *kept), []).append(r)
    plans: list[list[str]] = []  # the words of each plan but --out
    for (exe, base, *kept), members in groups.items():
        points = {(r.gamma, r.dh) for r in members}
        gammas = sorted({g for g, _ in points}, key=lambda g: -1.0 if g is None else g)
        dhs = sorted({h for _, h in points}, key=lambda h: -1.0 if h is None else h)
        grid = len(points) == len(gammas) * len(dhs)
        for lists in ([(gammas, dhs)] if grid else
                      [([g], sorted(h for g2, h in points if g2 == g)) for g in gammas]):
            words = ["dkt-sweep", "plan", _shown(base)]
            for flag, values in zip(("--gamma", "--dh"), lists, strict=True):
                if None not in values:
                    words += [flag, ",".join(fmt_value(v) for v in values)]
            for s in [*kept, change]:
                words += ["--set", s]
            plans.append(words + (["--exe", exe] if exe != default_exe() else []))
    dirs = [new] if len(plans) == 1 else [Path(f"{new}_{k}") for k in range(1, len(plans) + 1)]
    lines = [f"  {shlex.join([*words, '--out', str(d)])}" for words, d in zip(plans, dirs,
                                                                               strict=True)]
    lines += [f"  dkt-sweep run --out {shlex.quote(str(d))} --jobs N" for d in dirs]
    lines.append("  dkt-sweep collect --out " + shlex.join(
        [str(out), *(w for d in dirs for w in ("--with", str(d)))]))
    return lines


def _shown(path: str) -> str:
    """`path` relative to the working directory when it lies below it."""
    rel = os.path.relpath(path)
    return path if rel.startswith("..") else rel


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
