#!/usr/bin/env python3
"""Parameter sweeps over the diameter ratio gamma = D_1/D_2 and the initial distance D_h/D_1
of a pair scene, and the regime map of their DKT patterns.

    sweep.py plan BASE.nml [--gamma LIST] [--dh LIST] [--set group.key=value ...] --out DIR
    sweep.py run --out DIR [--jobs N] [--ranks R] [--force]      # here, N runs at a time
    sweep.py slurm --out DIR [--ntasks R] [--time HH:MM:SS] [--partition P]  # a job array
    sweep.py collect --out DIR                                   # regime.csv, regime.png

`plan` writes DIR/runs.csv (id, gamma, dh, dir, command): one run per combination of the
values, `dktlbm BASE --set pair.gamma=G --set pair.dh=H [--set ...] --set
output.dir=DIR/<id>`. LIST is comma-separated values or inclusive ranges start:stop:step,
e.g. `--gamma 1:3:0.5` or `--dh 1,2,4:10:2`. `run` and `slurm` run that plan; `collect`
reads each run's pattern (pattern.py) into DIR/regime.csv and draws DIR/regime.png.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import csv
import math
import os
import shlex
import shutil
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from dktread import RunFileError, guarded, open_run, pair_of, parse_namelist, run_status

ROOT = Path(__file__).resolve().parents[1]
RUNS_CSV = "runs.csv"
REGIME_CSV = "regime.csv"
COLUMNS = ("id", "gamma", "dh", "dir", "command")
REGIME_COLUMNS = ("gamma", "dh", "pattern", "episodes", "first_kiss_t", "dir")
# marker and colour of each pattern on the regime map
STYLE = {
    "repeated": ("o", "tab:red"),
    "once": ("s", "tab:orange"),
    "never": ("^", "tab:blue"),
    "missing": ("x", "tab:gray"),
    "stopped": ("P", "tab:purple"),
    "failed": ("X", "black"),
}


class SweepError(Exception):
    """A problem with the sweep's input: printed as `error: <text>`, exit status 2."""


# ---------------------------------------------------------------- value lists


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
            n = int(math.floor((stop - start) / step + 1e-9)) + 1
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
    """build/dktlbm of this source tree, else dktlbm on PATH, else the build path anyway."""
    built = ROOT / "build" / "dktlbm"
    if built.exists():
        return str(built)
    found = shutil.which("dktlbm")
    return found if found else str(built)


def _fmt(value: float) -> str:
    return f"{value:g}"


def _base_value(base: Path, sets: list[str], key: str) -> float | None:
    """pair.<key> as the run will see it: from --set, else from the scene file."""
    for s in reversed(sets):
        k, _, v = s.partition("=")
        if k.strip().lower() == f"pair.{key}":
            try:
                return float(v.lower().replace("d", "e"))
            except ValueError:
                return None
    try:
        values = parse_namelist(base.read_text()).get("pair", {}).get(key, [])
        return float(values[0].lower().replace("d", "e")) if values else None
    except (OSError, ValueError, UnicodeDecodeError):
        return None


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
        raise SweepError(f"{path}: no such file; write it first with `sweep.py plan`")
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


def launcher(ranks: int) -> tuple[list[str], dict[str, str]]:
    """The MPI launch prefix (MPIEXEC, default mpiexec) and environment: Open MPI as root
    needs the two OMPI_ALLOW_RUN_AS_ROOT variables, and --oversubscribe for more ranks than
    cores."""
    mpiexec = os.environ.get("MPIEXEC") or "mpiexec"
    env = dict(os.environ)
    prefix = [mpiexec, "-n", str(ranks)]
    try:
        version = subprocess.run([mpiexec, "--version"], capture_output=True, text=True,
                                 timeout=30)
        text = version.stdout + version.stderr
    except (OSError, subprocess.TimeoutExpired):
        text = ""
    if "Open MPI" in text or "OpenRTE" in text or "open-mpi" in text:
        prefix.append("--oversubscribe")
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        env["OMPI_ALLOW_RUN_AS_ROOT"] = "1"
        env["OMPI_ALLOW_RUN_AS_ROOT_CONFIRM"] = "1"
    return prefix, env


def run_plan(plan: list[PlannedRun], jobs: int, ranks: int, force: bool) -> int:
    """Run the plan, `jobs` runs at a time on `ranks` ranks each; the output of each goes to
    <dir>/run.log. Finished runs are skipped unless `force`. Returns the number of failures."""
    prefix, env = launcher(ranks)
    lock = threading.Lock()

    def say(text: str) -> None:
        with lock:
            print(text, flush=True)

    def one(r: PlannedRun) -> bool:
        status = run_status(r.h5)
        if status == "finished" and not force:
            say(f"skip   {r.id}: {r.h5} is finished (--force runs it again)")
            return True
        r.dir.mkdir(parents=True, exist_ok=True)
        args = r.args
        if r.h5.exists():
            args += ["--set", "output.overwrite=.true."]
        log = r.dir / "run.log"
        say(f"start  {r.id}")
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
            say(f"done   {r.id} ({seconds:.1f} s)")
            return True
        say(f"FAILED {r.id}: exit status {code} after {seconds:.1f} s; see {log}")
        return False

    with concurrent.futures.ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
        results = list(pool.map(one, plan))
    failed = results.count(False)
    print(f"{len(plan)} runs: {len(plan) - failed} finished or skipped, {failed} failed")
    return failed


# ---------------------------------------------------------------- Slurm

JOB_LIB = ROOT / "input" / "slurm" / "dkt_job.sh"
SLURM_TEMPLATE = """#!/bin/bash
# Slurm job array of a sweep: task k runs row k of runs.csv (after the header) in <dir>/<id>,
# the directory that holds this script and runs.csv (it may be moved). Submit it with
#   sbatch {script}                      # or: cd <dir> && sbatch sweep.slurm
# sbatch options (--ntasks=2 --time=30 ...) hold for every resubmission too. Each task skips a
# finished run, resumes an interrupted one from its checkpoint, appends to <dir>/<id>/run.log,
# and submits itself again when it stopped with a checkpoint (at most MAX_RESUBMITS times).
# Stop the whole sweep: scancel --name={job_name}. Exit status per task: 0 = finished, or
# stopped and resubmitted; 1 = stopped unfinished and not resubmitted; 2 = a setting is wrong;
# else dktlbm failed. `sweep.py collect` shows an unfinished run with a checkpoint as stopped.
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
        library=JOB_LIB.read_text(),
        written=shlex.quote(str(out)),
    )


# ---------------------------------------------------------------- collect


def collect(plan: list[PlannedRun]) -> list[dict[str, str]]:
    """One regime.csv row per planned run: its pattern, number of kissing episodes and the
    start of the first one (s); pattern 'missing' without a run file, 'stopped' when the run is
    not finished but has a checkpoint to resume from (<name>.checkpoint: stopped at a time
    limit, or still running), 'failed' when the file is not a finished run otherwise."""
    rows = []
    for r in plan:
        status = run_status(r.h5)
        if status == "failed" and r.h5.with_suffix(".checkpoint").is_file():
            status = "stopped"
        gamma, dh = r.gamma, r.dh
        pattern, episodes, first = status, "", ""
        if status == "finished":
            try:
                pair = pair_of(open_run(r.h5, need_particles=2))
                pattern, episodes = pair.pattern, str(len(pair.episodes))
                first = f"{pair.episodes[0].start:.6g}" if pair.episodes else ""
                gamma = gamma if gamma is not None else pair.gamma
                dh = dh if dh is not None else pair.dh
            except RunFileError:
                pattern = "failed"
        rows.append({
            "gamma": "" if gamma is None else _fmt(gamma),
            "dh": "" if dh is None else _fmt(dh),
            "pattern": pattern,
            "episodes": episodes,
            "first_kiss_t": first,
            "dir": str(r.dir),
        })
    return rows


def write_regime(rows: list[dict[str, str]], out: Path, pdf: bool) -> list[Path]:
    from matplotlib.figure import Figure

    csv_path = out / REGIME_CSV
    with csv_path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=REGIME_COLUMNS)
        w.writeheader()
        w.writerows(rows)

    fig = Figure(figsize=(6.5, 4.8), layout="constrained")
    ax = fig.subplots()
    placed = [r for r in rows if r["gamma"] and r["dh"]]
    for pattern, (marker, colour) in STYLE.items():
        pts = [(float(r["dh"]), float(r["gamma"])) for r in placed if r["pattern"] == pattern]
        if pts:
            xs, ys = zip(*pts, strict=True)
            ax.scatter(xs, ys, marker=marker, color=colour, s=60, label=f"{pattern} ({len(pts)})")
    dhs = [float(r["dh"]) for r in placed]
    if dhs and min(dhs) > 0 and max(dhs) / min(dhs) > 10:
        ax.set_xscale("log")
    ax.set_xlabel("$D_h/D_1$")
    ax.set_ylabel(r"$\gamma = D_1/D_2$")
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
        prog="sweep.py",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="example:\n"
        "  python3 postproc/sweep.py plan input/case1.nml --gamma 1:3:0.5 --dh 2,4,8 "
        "--out sweeps/case1\n"
        "  python3 postproc/sweep.py run --out sweeps/case1 --jobs 2 --ranks 2\n"
        "  python3 postproc/sweep.py collect --out sweeps/case1",
    )
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
    plan.add_argument("--exe", default=None,
                      help="the dktlbm executable (default: build/dktlbm of this source "
                      "tree, else dktlbm on PATH)")
    with_out(plan)

    run = sub.add_parser(
        "run", help="run the plan here",
        description="Run the plan here, N runs at a time, each on R MPI ranks (launcher: "
        "$MPIEXEC, default mpiexec). Each run's output goes to DIR/<id>/run.log. A run "
        "whose file is already finished is skipped. Exit status 1 if any run failed.")
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
    coll.add_argument("--pdf", action="store_true", help="also write DIR/regime.pdf")
    return p


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
    if args.command == "plan":
        plan = make_plan(args.base, args.gamma, args.dh, args.sets, out,
                         args.exe or default_exe())
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
