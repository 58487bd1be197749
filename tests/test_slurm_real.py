"""input/slurm/ and `dkt-sweep slurm` against a real Slurm (tools/slurm-local.sh start): the jobs
are submitted with sbatch, signalled by Slurm, resubmitted by the scripts and run by srun or
mpirun as the launcher detection chooses (the local cluster has MpiDefault=none, so a plain
srun cannot start the Open MPI build). Skipped when no Slurm answers `sinfo`.

Short runs of input/case0.nml at 10 spacings per diameter; a few minutes in all.
"""

from __future__ import annotations

import csv
import os
import re
import shlex
import shutil
import subprocess
import time
from pathlib import Path

import pytest

from dkt_run import EXE, INPUT, ROOT, dkt_command, mpi_env, run
from dktlbm.read import run_status
from test_install import install, user_env
from test_restart import LONG_SETS, assert_same_output

SWEEP_PY = dkt_command("sweep")


def slurm_up() -> str:
    """Empty when a Slurm node answers, else why not."""
    if shutil.which("sinfo") is None:
        return "no sinfo on PATH (start one with: bash tools/slurm-local.sh start)"
    proc = subprocess.run(["sinfo", "-h", "-o", "%T"], capture_output=True, text=True, timeout=30)
    if proc.returncode != 0 or not re.search(r"idle|mix|alloc", proc.stdout):
        return f"sinfo does not reach a Slurm with a usable node: {proc.stderr.strip()}"
    return ""


WHY_NOT = slurm_up()
# CI starts a Slurm and sets DKT_REQUIRE_SLURM=1: there a Slurm that does not answer fails
if WHY_NOT and os.environ.get("DKT_REQUIRE_SLURM") == "1":
    raise RuntimeError(f"DKT_REQUIRE_SLURM=1 but {WHY_NOT}")
pytestmark = pytest.mark.skipif(bool(WHY_NOT), reason=WHY_NOT or "Slurm is up")


def job_env(**extra: str) -> dict[str, str]:
    """The submitting shell's environment: no SLURM_* of an enclosing job."""
    env = {k: v for k, v in {**os.environ, **mpi_env()}.items() if not k.startswith("SLURM_")}
    env.update(extra)
    return env


def sbatch(args: list[str], cwd: Path, env: dict[str, str]) -> str:
    proc = subprocess.run(
        ["sbatch", "--parsable", *args],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 0, proc.stderr
    return proc.stdout.strip().split(";")[0]


def squeue(name: str) -> list[tuple[str, str]]:
    proc = subprocess.run(
        ["squeue", "-h", "-n", name, "-o", "%i %T"], capture_output=True, text=True, timeout=60
    )
    assert proc.returncode == 0, proc.stderr
    return [tuple(line.split()) for line in proc.stdout.splitlines() if line.strip()]


def wait_running(job: str, name: str, timeout: float = 120) -> None:
    deadline = time.monotonic() + timeout
    while (job, "RUNNING") not in squeue(name):
        assert time.monotonic() < deadline, f"job {job} did not start: {squeue(name)}"
        time.sleep(0.2)


def wait_for(pattern: Path, timeout: float = 120) -> None:
    """Until a file matching `pattern` exists: the batch shell has started (and set its trap;
    a signal to a job whose shell has not started yet is lost by Slurm itself)."""
    deadline = time.monotonic() + timeout
    while not list(pattern.parent.glob(pattern.name)):
        assert time.monotonic() < deadline, f"no {pattern} after {timeout} s"
        time.sleep(0.05)


def wait_gone(name: str, timeout: float = 400) -> None:
    """Until no job of that name is pending or running (a chain included); a job left
    pending for a reason other than its dependency fails the test (and is cancelled)."""
    deadline = time.monotonic() + timeout
    while jobs := squeue(name):
        if time.monotonic() > deadline:
            subprocess.run(["scancel", "--name", name], timeout=60)
            detail = subprocess.run(
                ["squeue", "-n", name, "-o", "%i %T %r"], capture_output=True, text=True
            ).stdout
            raise AssertionError(f"jobs {name} still queued after {timeout} s:\n{detail}")
        del jobs
        time.sleep(1)


def job_field(job: str, field: str) -> str:
    text = subprocess.run(
        ["scontrol", "show", "job", job], capture_output=True, text=True, timeout=60
    ).stdout
    found = re.search(rf"(?:^|\s){re.escape(field)}=(\S*)", text)
    assert found, f"no {field} for job {job}:\n{text}"
    return found.group(1)


def gated_exe(tmp_path: Path, logs: Path, only: str = "", most: int = 120) -> Path:
    """A wrapper for dktlbm (written into tmp_path) that starts it only once a job log matching
    the glob `logs` says SIGUSR1, at most `most` s later: a signal sent right after
    the job's shell has started then always finds the run not yet finished, however fast
    the machine (the script holds it and passes it on once the run has its handlers). The
    resubmitted job finds the word already there and starts at once. With `only`, the
    wrapper waits only for the runs whose arguments contain that string."""
    wrapper = tmp_path / "dktlbm-gated"
    wrapper.write_text(
        "#!/bin/sh\n"
        f'case " $* " in *"{only}"*) ;; *) exec "{EXE}" "$@" ;; esac\n'
        "i=0\n"
        f"until cat {logs} 2>/dev/null | grep -q SIGUSR1 || [ $i -ge {5 * most} ]; do\n"
        "  sleep 0.2; i=$((i + 1))\n"
        "done\n"
        f'exec "{EXE}" "$@"\n'
    )
    wrapper.chmod(0o755)
    return wrapper


def test_run_one_chain_cut_by_a_signal_equals_a_direct_run(tmp_path: Path) -> None:
    """run_one.slurm submitted with sbatch --ntasks=2 --time=5 (the script says 4 tasks, 24 h)
    is sent SIGUSR1 by Slurm (scancel --batch, the same delivery as --signal=B:USR1 before the
    limit) as soon as its shell runs, before dktlbm has its handlers (a wrapper starts it only
    once the job log has the signal, see gated_exe): the run writes a checkpoint, the job
    submits its follow-up with the same 2 tasks and 5 min (not the script's 4, which this
    2-CPU node could never start), and the chain finishes with an output bitwise equal to
    one direct run. The job messages land in the output directory, not in the submit
    directory, and every job id of the chain is in OUTDIR/jobs."""
    name = "dkt-real-one"
    out = tmp_path / "chain"
    submit_dir = tmp_path / "submit"
    submit_dir.mkdir()
    env = job_env(
        SCENE=str(INPUT / "case0.nml"),
        OUTDIR=str(out),
        DKTLBM=str(gated_exe(tmp_path, out / "slurm-*.out")),
        DKT_SRUN_MPI="pmix",
        EXTRA=" ".join(f"--set {s}" for s in LONG_SETS),
        MAX_RESUBMITS="3",
        SBATCH_SIGNAL="B:USR1@10",
    )
    first = sbatch(
        [
            "--ntasks=2",
            "--time=5",
            f"--job-name={name}",
            str(ROOT / "input" / "slurm" / "run_one.slurm"),
        ],
        submit_dir,
        env,
    )
    wait_running(first, name)
    wait_for(out / "jobs")
    subprocess.run(["scancel", "--batch", "--signal=USR1", first], check=True, timeout=60)
    wait_gone(name)

    jobs = (out / "jobs").read_text().split()
    logs = "".join(p.read_text() for p in sorted(out.glob("slurm-*.out")))
    assert jobs[0] == first and len(jobs) >= 2, logs
    assert (out / "case0.finished").exists(), logs
    assert "SIGUSR1" in logs and "--restart" in logs, logs
    follow = jobs[1]
    assert job_field(follow, "NumTasks") == "2", logs
    assert job_field(follow, "TimeLimit") == "00:05:00", logs
    assert job_field(first, "ExitCode") == "0:0" and job_field(follow, "ExitCode") == "0:0"
    assert list(submit_dir.iterdir()) == [], "job output left in the submit directory"

    direct = tmp_path / "direct"
    run("case0.nml", 2, LONG_SETS, direct, timeout=600)
    assert_same_output(direct, out)


def test_run_one_chain_cut_by_slurms_time_limit_signal(tmp_path: Path) -> None:
    """The signal of Slurm's own time limit, not one sent by hand: run_one.slurm with
    --ntasks=1 --time=1 and SBATCH_SIGNAL=B:USR1@60 is due its SIGUSR1 from the start, and
    Slurm's timer, checked every 30 s, sends it within half a minute. So that the signal finds
    the first job still running on any machine, its dktlbm starts only once the job log
    records the signal, at most 45 s late (gated_exe; srun's plugin is named, since the wrapper
    is no Open MPI binary): the script holds the signal, passes it on once the run has its
    handlers, the run checkpoints and the job resubmits it. Each follow-up job gets a 10 min
    limit here (scontrol) so that the chain ends (it may be cut again if the timer comes
    first). The chain's output is bitwise that of a direct one-rank run, made at the same time
    on the other core."""
    name = "dkt-real-limit"
    sets = ["lbm.cells_per_diameter=16", "run.steps=12000", "output.series_interval=0.01",
            "output.field_interval=2"]  # fmt: skip
    direct = tmp_path / "direct"
    args = [str(EXE), str(INPUT / "case0.nml"), *[a for s in sets for a in ("--set", s)]]
    with (tmp_path / "direct.log").open("w") as log:
        twin = subprocess.Popen(
            [*args, "--set", f"output.dir={direct}"], stdout=log, stderr=subprocess.STDOUT,
            env={**os.environ, **mpi_env()},
        )  # fmt: skip
        out = tmp_path / "chain"
        env = job_env(
            SCENE=str(INPUT / "case0.nml"),
            OUTDIR=str(out),
            DKTLBM=str(gated_exe(tmp_path, out / "slurm-*.out", most=45)),
            DKT_SRUN_MPI="pmix",
            EXTRA=" ".join(f"--set {s}" for s in sets),
            MAX_RESUBMITS="6",
            SBATCH_SIGNAL="B:USR1@60",
        )
        first = sbatch(
            ["--ntasks=1", "--time=1", f"--job-name={name}",
             str(ROOT / "input" / "slurm" / "run_one.slurm")],
            tmp_path,
            env,
        )  # fmt: skip
        raised = {first}
        deadline = time.monotonic() + 600
        while jobs := squeue(name):
            for job, _ in jobs:
                if job not in raised:
                    subprocess.run(["scontrol", "update", f"JobId={job}", "TimeLimit=10"],
                                   check=True, timeout=60)  # fmt: skip
                    raised.add(job)
            assert time.monotonic() < deadline, f"chain {name} still queued: {jobs}"
            time.sleep(0.2)
        assert twin.wait(timeout=600) == 0, (tmp_path / "direct.log").read_text()
    logs = "".join(p.read_text() for p in sorted(out.glob("slurm-*.out")))
    jobs = (out / "jobs").read_text().split()
    assert jobs[0] == first and len(jobs) >= 2, f"the time limit did not cut the run:\n{logs}"
    assert "SIGUSR1" in logs and "--restart" in logs, logs
    assert job_field(first, "TimeLimit") == "00:01:00"
    assert job_field(first, "ExitCode") == "0:0", logs
    assert (out / "case0.finished").exists(), logs
    assert_same_output(direct, out)


def plan(out: Path, dhs: str) -> list[dict[str, str]]:
    proc = subprocess.run(
        [
            *SWEEP_PY,
            "plan",
            str(INPUT / "case0.nml"),
            "--dh",
            dhs,
            *[a for s in LONG_SETS for a in ("--set", s)],
            "--exe",
            str(EXE),
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    with (out / "runs.csv").open(newline="") as f:
        return list(csv.DictReader(f))


def collect(out: Path) -> dict[str, str]:
    proc = subprocess.run(
        [*SWEEP_PY, "collect", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, "MPLBACKEND": "Agg"},
    )
    assert proc.returncode == 0, proc.stderr
    with (out / "regime.csv").open(newline="") as f:
        return {Path(r["dir"]).name: r["pattern"] for r in csv.DictReader(f)}


def test_sweep_array_task_interrupted_and_resumed(tmp_path: Path) -> None:
    """sweep_array.slurm over a 2-run plan with --ntasks=1 on the sbatch line: task 1 is sent
    SIGUSR1 as soon as its shell runs, before its dktlbm starts (gated_exe holds that run
    only), and is resubmitted as that index only, with 1 task; both runs end finished,
    `collect` shows both with a pattern, and the interrupted run's file is bitwise that of
    its run finished in one go with the planned run's own settings (same ranks)."""
    name = "dkt-real-array"
    out = tmp_path / "sweep"
    rows = plan(out, "2,2.0001")
    held = out / rows[1]["id"]
    gated = gated_exe(tmp_path, held / "run.log", f"output.dir={held} ")
    env = job_env(
        RUNS=str(out / "runs.csv"),
        DKTLBM=str(gated),
        DKT_SRUN_MPI="pmix",
        MAX_RESUBMITS="3",
        SBATCH_SIGNAL="B:USR1@10",
    )
    array = sbatch(
        [
            "--array=0-1",
            "--ntasks=1",
            "--time=5",
            f"--job-name={name}",
            str(ROOT / "input" / "slurm" / "sweep_array.slurm"),
        ],
        ROOT,
        env,
    )
    wait_running(f"{array}_1", name)
    wait_for(out / rows[1]["id"] / "run.log")
    subprocess.run(["scancel", "--batch", "--signal=USR1", f"{array}_1"], check=True, timeout=60)
    wait_gone(name)
    interrupted = out / rows[1]["id"]
    log = (interrupted / "run.log").read_text()
    assert len((interrupted / "jobs").read_text().split()) >= 2, log
    assert "--restart" in log and "SIGUSR1" in log, log
    patterns = collect(out)
    assert all(p not in ("missing", "failed", "stopped") for p in patterns.values()), patterns

    # the twin: the planned run's own --set options (the sweep adds its precision), in one go
    words = shlex.split(rows[1]["command"])
    sets = [v for flag, v in zip(words, words[1:], strict=False)
            if flag == "--set" and not v.startswith("output.dir=")]
    assert "lbm.precision=single_arith" in sets, sets
    direct = tmp_path / "direct"
    run("case0.nml", 1, sets, direct, timeout=600)
    assert_same_output(direct, interrupted)


def test_sweep_py_slurm_plan_collected_into_a_regime_map(tmp_path: Path) -> None:
    """`dkt-sweep slurm` with its default 4 tasks, submitted with --ntasks=1 from another
    directory than the sweep's (which it finds by itself), runs both rows; a second
    submission skips the finished runs and leaves their logs; collect draws the map."""
    name = "dkt-real-sweep"
    out = tmp_path / "sweep"
    plan(out, "2,2.0001")
    proc = subprocess.run(
        [
            *SWEEP_PY,
            "slurm",
            "--out",
            str(out),
            "--time",
            "00:05:00",
            "--job-name",
            name,
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 0, proc.stderr
    for _ in range(2):
        sbatch(["--ntasks=1", str(out / "sweep.slurm")], tmp_path, job_env())
        wait_gone(name)
    logs = {p.parent.name: p.read_text() for p in out.glob("*/run.log")}
    assert len(logs) == 2
    for text in logs.values():
        assert text.count("# job ") == 1, text  # run once; the second task skipped it
        assert "is finished" in text, text
    assert not list(tmp_path.glob("slurm-*.out"))
    patterns = collect(out)
    assert all(p not in ("missing", "failed", "stopped") for p in patterns.values()), patterns
    assert (out / "regime.png").stat().st_size > 0


def test_installed_sweep_submitted_from_an_empty_directory(tmp_path: Path) -> None:
    """The installed copy (cmake --install prefix, package in a venv; no source tree on any
    path): `dkt-sweep plan` of an installed example and `dkt-sweep slurm`, run from an empty
    directory, write an array whose commands start the installed dktlbm and whose script holds
    the installed dkt_job.sh; sbatch-ed, it finishes both runs."""
    installed = install(tmp_path / "install")
    env = user_env(installed)
    env["PATH"] += os.pathsep + str(Path(shutil.which("sbatch") or "/usr/bin/sbatch").parent)
    here = tmp_path / "empty"
    here.mkdir()
    scene = installed["prefix"] / "share" / "dktlbm" / "examples" / "case0.nml"
    name = "dkt-installed-sweep"
    sets = [a for s in LONG_SETS for a in ("--set", s)]
    for args in (["plan", scene, "--dh", "2,2.0001", *sets, "--out", "sweep"],
                 ["slurm", "--out", "sweep", "--time", "00:05:00", "--job-name", name]):
        proc = subprocess.run(["dkt-sweep", *map(str, args)], capture_output=True, text=True,
                              timeout=120, env=env, cwd=here)
        assert proc.returncode == 0, proc.stdout + proc.stderr
    with (here / "sweep" / "runs.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    exe = installed["prefix"] / "bin" / "dktlbm"
    assert len(rows) == 2 and all(r["command"].startswith(f"{exe} ") for r in rows), rows
    script = (here / "sweep" / "sweep.slurm").read_text()
    installed_lib = installed["prefix"] / "share" / "dktlbm" / "slurm" / "dkt_job.sh"
    assert installed_lib.read_text() in script
    sbatch(["--ntasks=1", "sweep/sweep.slurm"], here, {**env, **mpi_env()})
    wait_gone(name)
    for r in rows:
        log = (here / "sweep" / r["id"] / "run.log").read_text()
        assert str(exe) in log, log
        assert run_status(here / "sweep" / r["id"] / "case0.h5") == "finished", log
