"""input/slurm/: the batch scripts for one run (run_one.slurm) and for the job array of a sweep
(sweep_array.slurm), which stop the run with a checkpoint before the time limit and submit
themselves again until the run is finished.

The scripts run here under bash, not sbatch. Stand-ins on PATH log what they are given:
`srun` logs its arguments and executes them; `sbatch` logs its arguments and the environment it
was called with (what `--export=ALL,...` hands the next job) and reports a job id; `scontrol
show job` prints a job record whose Command= field the test chooses. The stand-in dktlbm
logs its arguments and acts as FAKE_MODE says, as the real program ends a job: `finish` writes
<name>.finished; `checkpoint` writes <name>_chk_<step>.h5 and <name>.checkpoint naming it and
exits 0 (stopped by the signal or run.wall_limit); `fail` writes a checkpoint and exits 3;
`noop` exits 0 writing nothing; `wait` waits for SIGUSR1, then checkpoints and exits 0;
`wait-die` waits for SIGUSR1, checkpoints and is then killed by SIGUSR1. A follow-up job is
run the way Slurm would start it: the script sbatch was given, with the environment sbatch
saw plus the --export assignments, a new job id and the --array index.

Most tests run on both scripts (the `case` fixture). Each test's docstring says what it
proves.
"""

from __future__ import annotations

import csv
import json
import os
import shlex
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import pytest

from dkt_run import dkt_command

ROOT = Path(os.environ.get("DKTLBM_ROOT", Path(__file__).resolve().parents[1]))
SLURM = ROOT / "input" / "slurm"
RUN_ONE = SLURM / "run_one.slurm"
SWEEP_ARRAY = SLURM / "sweep_array.slurm"
SWEEP_PY = dkt_command("sweep")
JOB_ID = "777"
TASK = 4  # the array index the sweep tests run

FAKE_DKTLBM = """#!{python}
import json, os, re, signal, sys, time
from pathlib import Path

args = sys.argv[1:]
logs = Path(os.environ["FAKE_LOG"])
mode = os.environ.get("FAKE_MODE", "finish")
sets = [args[i + 1] for i, a in enumerate(args[:-1]) if a == "--set"]
out = Path([s for s in sets if s.startswith("output.dir=")][-1].partition("=")[2])
restart = args[args.index("--restart") + 1] if "--restart" in args else None
name = Path(args[0]).stem
caught = []
record = {{"argv": args, "mode": mode, "caught": caught, "wrote": None}}
if (logs / "calls").exists():  # commands the script ran before this (signalling_stand_ins)
    record["calls_before"] = int((logs / "calls").read_text())


def checkpoint():
    step = 100
    if restart:
        step += int(re.search(r"_chk_([0-9]{{9}})[.]h5$", restart).group(1))
    path = out / f"{{name}}_chk_{{step:09d}}.h5"
    path.write_text("stand-in checkpoint")
    (out / f"{{name}}.checkpoint").write_text(f"{{path}}\\n")
    record["wrote"] = str(path)


def log():
    with (logs / "dktlbm.jsonl").open("a") as f:
        f.write(json.dumps(record) + "\\n")


out.mkdir(parents=True, exist_ok=True)
print("stand-in dktlbm:", mode, flush=True)
if mode in ("wait", "wait-die", "wait-late"):
    (logs / "started").touch()
    if mode == "wait-late":
        time.sleep(2)  # still setting up: a SIGUSR1 now would kill this process
    signal.signal(signal.SIGUSR1, lambda signum, frame: caught.append(int(signum)))
    if os.environ.get("DKTLBM_READY_FILE"):
        Path(os.environ["DKTLBM_READY_FILE"]).touch()
    deadline = time.monotonic() + 30
    while not caught and time.monotonic() < deadline:
        time.sleep(0.02)
    if not caught:
        log()
        sys.exit(4)
if mode == "finish":
    (out / f"{{name}}.finished").touch()
elif mode in ("checkpoint", "fail", "wait", "wait-die", "wait-late"):
    checkpoint()
log()
if mode == "fail":
    sys.exit(3)
if mode == "wait-die":
    signal.signal(signal.SIGUSR1, signal.SIG_DFL)
    os.kill(os.getpid(), signal.SIGUSR1)
    time.sleep(5)
    sys.exit(5)
"""

FAKE_SRUN = """#!{python}
import json, os, sys
from pathlib import Path

if sys.argv[1:] == ["--mpi=list"]:
    print("MPI plugin types are...")
    print(os.environ.get("FAKE_MPI_LIST", "none"))
    sys.exit(0)
n = 1
while sys.argv[n].startswith("-"):
    n += 1
options, args = sys.argv[1:n], sys.argv[n:]
with (Path(os.environ["FAKE_LOG"]) / "srun.jsonl").open("a") as f:
    f.write(json.dumps({{"argv": args, "options": options}}) + "\\n")
os.execvp(args[0], args)
"""

FAKE_SBATCH = """#!{python}
import json, os, sys
from pathlib import Path

with (Path(os.environ["FAKE_LOG"]) / "sbatch.jsonl").open("a") as f:
    f.write(json.dumps({{"argv": sys.argv[1:], "env": dict(os.environ)}}) + "\\n")
if os.environ.get("FAKE_SBATCH_FAIL"):
    print("sbatch: error: Batch job submission failed", file=sys.stderr)
    sys.exit(1)
print("Submitted batch job 1001")
"""

FAKE_SCONTROL = """#!{python}
import json, os, sys
from pathlib import Path

with (Path(os.environ["FAKE_LOG"]) / "scontrol.jsonl").open("a") as f:
    f.write(json.dumps({{"argv": sys.argv[1:]}}) + "\\n")
command = os.environ.get("FAKE_SCONTROL_COMMAND")
if sys.argv[1:3] != ["show", "job"] or len(sys.argv) < 4 or not command:
    print("slurm_load_jobs error: Invalid job id specified", file=sys.stderr)
    sys.exit(1)
print(f"JobId={{sys.argv[3]}} JobName=dktlbm")
print("   UserId=user(1000) GroupId=user(1000) MCS_label=N/A")
print("   JobState=RUNNING Reason=None Dependency=(null)")
print(f"   Command={{command}}")
print(f"   WorkDir={{os.getcwd()}}")
"""


@dataclass
class Case:
    """A script ready to run in a temporary directory: its environment, where the run writes,
    and the dktlbm arguments it must pass before any --restart."""

    script: Path
    env: dict[str, str]
    cwd: Path
    outdir: Path
    name: str
    exe: str
    args: list[str]
    logs: Path

    def run(self, mode: str, env: dict[str, str] | None = None, script: str | Path | None = None,
            ) -> subprocess.CompletedProcess:
        full = {**self.env, **(env or {}), "FAKE_MODE": mode}
        return subprocess.run(["bash", str(script or self.script)], cwd=self.cwd, env=full,
                              capture_output=True, text=True, timeout=60)

    def log(self, tool: str) -> list[dict]:
        path = self.logs / f"{tool}.jsonl"
        if not path.exists():
            return []
        return [json.loads(line) for line in path.read_text().splitlines()]

    def checkpoint_file(self, step: int) -> Path:
        return self.outdir / f"{self.name}_chk_{step:09d}.h5"


def write_fakes(tmp_path: Path) -> tuple[Path, Path]:
    """The stand-ins in tmp_path/bin and the directory they log to."""
    bin_dir = tmp_path / "bin"
    logs = tmp_path / "logs"
    bin_dir.mkdir()
    logs.mkdir()
    for name, text in (("dktlbm", FAKE_DKTLBM), ("srun", FAKE_SRUN), ("sbatch", FAKE_SBATCH),
                       ("scontrol", FAKE_SCONTROL)):
        path = bin_dir / name
        path.write_text(text.format(python=sys.executable))
        path.chmod(0o755)
    return bin_dir, logs


def base_env(tmp_path: Path, bin_dir: Path, logs: Path) -> dict[str, str]:
    """A clean environment (nothing from a real Slurm job): the stand-ins first on PATH."""
    return {"PATH": f"{bin_dir}:{os.environ.get('PATH', '/usr/bin:/bin')}",
            "HOME": os.environ.get("HOME", str(tmp_path)), "LANG": "C.UTF-8",
            "FAKE_LOG": str(logs), "SLURM_JOB_ID": JOB_ID, "SLURM_SUBMIT_DIR": str(tmp_path)}


def make_run_one(tmp_path: Path) -> Case:
    bin_dir, logs = write_fakes(tmp_path)
    (tmp_path / "scenes").mkdir()
    (tmp_path / "scenes" / "case1.nml").write_text("&run\n  steps = 10\n/\n")
    env = base_env(tmp_path, bin_dir, logs)
    # relative SCENE and OUTDIR, as submitted from the source tree; EXTRA in shell syntax
    env.update(SCENE="scenes/case1.nml", OUTDIR="out/case1", DKTLBM=str(bin_dir / "dktlbm"),
               EXTRA="--set run.checkpoint_wall=3600 --set 'particles.x=0.9,1.1'")
    outdir = tmp_path / "out" / "case1"
    args = ["scenes/case1.nml", "--set", "run.checkpoint_wall=3600", "--set",
            "particles.x=0.9,1.1", "--set", f"output.dir={outdir}"]
    return Case(RUN_ONE, env, tmp_path, outdir, "case1", str(bin_dir / "dktlbm"), args, logs)


def plan_sweep(tmp_path: Path) -> Path:
    """runs.csv of a 3 x 2 sweep written by `dkt-sweep plan`, with blanks in the scene's and the
    sweep's paths and a --set value holding a comma; the plan names an executable that does
    not exist here (DKTLBM replaces it)."""
    scene = tmp_path / "my scenes" / "pair scene.nml"
    scene.parent.mkdir()
    scene.write_text("&pair\n  gamma = 2.0, dh = 4.0\n/\n")
    out = tmp_path / "sweep dir"
    proc = subprocess.run(
        [*SWEEP_PY, "plan", str(scene), "--gamma", "1,2,3", "--dh", "2,4",
         "--set", "particles.x=0.9,1.1", "--out", str(out), "--exe", "/cluster/bin/dktlbm"],
        capture_output=True, text=True, timeout=120, env={**os.environ, "MPLBACKEND": "Agg"})
    assert proc.returncode == 0, proc.stderr
    return out / "runs.csv"


def make_sweep(tmp_path: Path) -> Case:
    bin_dir, logs = write_fakes(tmp_path)
    runs = plan_sweep(tmp_path)
    with runs.open(newline="") as f:
        row = list(csv.DictReader(f))[TASK]
    env = base_env(tmp_path, bin_dir, logs)
    env.update(RUNS="sweep dir/runs.csv", SLURM_ARRAY_TASK_ID=str(TASK),
               DKTLBM=str(bin_dir / "dktlbm"))
    outdir = tmp_path / "sweep dir" / row["id"]
    args = shlex.split(row["command"])[1:] + ["--set", f"output.dir={outdir}"]
    return Case(SWEEP_ARRAY, env, tmp_path, outdir, "pair scene", str(bin_dir / "dktlbm"),
                args, logs)


@pytest.fixture(params=["run_one", "sweep_array"])
def case(request: pytest.FixtureRequest, tmp_path: Path) -> Case:
    return make_run_one(tmp_path) if request.param == "run_one" else make_sweep(tmp_path)


def next_job(submission: dict, job_id: str) -> tuple[str, dict[str, str]]:
    """The job a recorded `sbatch` call asks for, as Slurm would start it: the script (the
    last argument), the caller's environment with the --export=ALL,... assignments, the array
    index given with --array, a new job id."""
    argv = submission["argv"]
    assert not argv[-1].startswith("-"), argv
    env = dict(submission["env"])
    exports = [a.removeprefix("--export=") for a in argv if a.startswith("--export=")]
    assert len(exports) == 1, argv
    kind, *assignments = exports[0].split(",")
    assert kind == "ALL", "the next job must get this job's environment (--export=ALL)"
    for assignment in assignments:
        key, _, value = assignment.partition("=")
        env[key] = value
    for a in argv:
        if a.startswith("--array="):
            index = a.removeprefix("--array=")
            assert index.isdigit(), f"resubmit one array index, not {index}"
            env["SLURM_ARRAY_TASK_ID"] = index
    env["SLURM_JOB_ID"] = job_id
    return argv[-1], env


def sbatch_header(path: Path) -> list[str]:
    """The #SBATCH lines sbatch reads: those before the first command."""
    options = []
    for line in path.read_text().splitlines()[1:]:
        stripped = line.strip()
        if stripped and not stripped.startswith("#"):
            break
        if stripped.startswith("#SBATCH"):
            options.append(stripped.removeprefix("#SBATCH").strip())
    return options


# ---------------------------------------------------------------- the files


@pytest.mark.parametrize("script", [RUN_ONE, SWEEP_ARRAY], ids=lambda p: p.name)
def test_scripts_parse_and_ask_for_the_signal(script: Path) -> None:
    """Both scripts are bash that `bash -n` accepts, and their #SBATCH block, which sbatch
    reads only up to the first command, sets a job name, the task count, the time limit, the
    output file and SIGUSR1 to the batch shell (B:) at least a minute before the limit, as the
    forwarding trap expects; the sweep script is a job array. No #SBATCH line comes after the
    first command, where sbatch would silently ignore it."""
    assert script.read_text().startswith("#!/bin/bash\n")
    proc = subprocess.run(["bash", "-n", str(script)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    options = sbatch_header(script)
    for key in ("--job-name=", "--ntasks=", "--time=", "--output="):
        assert any(o.startswith(key) for o in options), (key, options)
    signals = [o for o in options if o.startswith("--signal=")]
    assert len(signals) == 1 and signals[0].startswith("--signal=B:USR1@"), options
    assert int(signals[0].rpartition("@")[2]) >= 60
    assert any(o.startswith("--array=") for o in options) == (script == SWEEP_ARRAY)
    all_lines = [ln.strip() for ln in script.read_text().splitlines()]
    assert sum(ln.startswith("#SBATCH") for ln in all_lines) == len(options)


# ---------------------------------------------------------------- one job


def test_finished_run_is_not_resubmitted_nor_run_again(case: Case) -> None:
    """A run that reaches its last step (writes <name>.finished) ends the job with status 0
    and no resubmission; srun ran exactly `DKTLBM SCENE [EXTRA] --set output.dir=<absolute
    OUTDIR>` without --restart. A job started once the run is finished says so, exits 0 and
    starts nothing."""
    proc = case.run("finish")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert [r["argv"] for r in case.log("srun")] == [[case.exe, *case.args]]
    assert [r["argv"] for r in case.log("dktlbm")] == [case.args]
    assert (case.outdir / f"{case.name}.finished").exists()
    assert case.log("sbatch") == []

    again = case.run("finish")
    assert again.returncode == 0, again.stdout + again.stderr
    assert "finished" in again.stdout
    assert len(case.log("srun")) == 1 and case.log("sbatch") == []


def test_checkpointed_run_is_resubmitted_once_and_resumed(case: Case) -> None:
    """A run that stops with a checkpoint and status 0 gets exactly one sbatch call:
    --export=ALL,RESUBMIT=1, a dependency on this job (afterany) so the two never overlap,
    for the array only this task's index. The job so submitted passes `--restart <the path
    in <name>.checkpoint>` after the same arguments; when that run finishes nothing more is
    submitted."""
    proc = case.run("checkpoint")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    first = case.log("dktlbm")
    assert [r["argv"] for r in first] == [case.args]
    checkpoint = case.checkpoint_file(100)
    assert first[0]["wrote"] == str(checkpoint) and checkpoint.exists()
    submissions = case.log("sbatch")
    assert len(submissions) == 1
    argv = submissions[0]["argv"]
    assert "--export=ALL,RESUBMIT=1" in argv
    assert f"--dependency=afterany:{JOB_ID}" in argv
    assert (f"--array={TASK}" in argv) == (case.script == SWEEP_ARRAY)

    script, env = next_job(submissions[0], "778")
    proc = case.run("finish", env=env, script=script)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    second = case.log("dktlbm")[1]["argv"]
    assert second == [*case.args, "--restart", str(checkpoint)]
    assert len(case.log("sbatch")) == 1


def test_resubmissions_stop_after_max_resubmits(case: Case) -> None:
    """With MAX_RESUBMITS=2 and a run that never finishes, the chain is the first job and two
    resubmissions (RESUBMIT=1, then 2), each resuming from the checkpoint the job before
    wrote; the third job does not submit a fourth and exits non-zero, naming MAX_RESUBMITS."""
    script: str | Path = case.script
    env = {**case.env, "MAX_RESUBMITS": "2"}
    results = []
    for job in range(3):
        results.append(case.run("checkpoint", env=env, script=script))
        submissions = case.log("sbatch")
        if len(submissions) == job + 1:
            script, env = next_job(submissions[-1], str(int(JOB_ID) + job + 1))
    assert [p.returncode for p in results] == [0, 0, 1], [p.stdout for p in results]
    assert "MAX_RESUBMITS" in results[-1].stdout
    submissions = case.log("sbatch")
    assert [[a for a in s["argv"] if a.startswith("--export=")] for s in submissions] == [
        ["--export=ALL,RESUBMIT=1"], ["--export=ALL,RESUBMIT=2"]]
    runs = case.log("dktlbm")
    assert [r["argv"] for r in runs] == [
        case.args,
        [*case.args, "--restart", str(case.checkpoint_file(100))],
        [*case.args, "--restart", str(case.checkpoint_file(200))],
    ]


def test_failed_run_exits_nonzero_and_is_not_resubmitted(case: Case) -> None:
    """dktlbm exiting 3 without a signal is a failure: the job exits with that status and
    submits nothing, although the run left a checkpoint that could be resumed."""
    proc = case.run("fail")
    assert proc.returncode == 3, proc.stdout + proc.stderr
    assert case.checkpoint_file(100).exists()
    assert case.log("sbatch") == []


@pytest.mark.parametrize("mode", ["wait", "wait-die", "wait-late"])
def test_sigusr1_is_forwarded_and_the_run_resubmitted(case: Case, mode: str) -> None:
    """SIGUSR1 to the batch shell (what --signal=B:USR1 does) does not end the script: it is
    passed on to the run through srun, the run checkpoints, and the job resubmits itself and
    exits 0. This holds too when the run then ends with a non-zero status (killed by the
    signal): after the signal that is not a failure, as the checkpoint is new. `wait-late`:
    the signal comes while the run is still setting up, 2 s before it has its handler (which
    the signal would kill it): the script holds it until the run says it is ready
    (DKTLBM_READY_FILE) and the run still catches it once."""
    proc = subprocess.Popen(["bash", str(case.script)], cwd=case.cwd,
                            env={**case.env, "FAKE_MODE": mode}, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 30
        while not (case.logs / "started").exists():
            assert proc.poll() is None and time.monotonic() < deadline, "the run did not start"
            time.sleep(0.02)
        os.kill(proc.pid, signal.SIGUSR1)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, out + err
    runs = case.log("dktlbm")
    assert len(runs) == 1 and runs[0]["caught"] == [int(signal.SIGUSR1)]
    assert "SIGUSR1" in out
    assert len(case.log("sbatch")) == 1


SIGNALLING_COMMANDS = ("rm", "mkdir", "date", "sed", "tr", "cat", "ls", "basename", "dirname",
                       "readlink", "realpath", "mv", "cp", "grep", "head", "tail", "touch",
                       "python3")


def signalling_stand_ins(bin_dir: Path, logs: Path) -> None:
    """Stand-ins for the ordinary commands the scripts run: each counts its call in
    logs/calls and, on the call numbered SIGNAL_AT, sends SIGUSR1 to the batch shell
    (BATCH_PID) while it is still running (as Slurm's signal may come at any moment), then
    runs the real command. The count is taken under a lock: the commands of a pipeline run
    at once, and without it two of them could read the file while a third had emptied it to
    write, restarting the count (the signal then came after the run, a spurious failure)."""
    flock = shutil.which("flock")
    assert flock, "flock (util-linux)"
    for name in SIGNALLING_COMMANDS:
        real = shutil.which(name)
        assert real, name
        path = bin_dir / name
        path.write_text(
            "#!/bin/sh\n"
            f"exec 9>> {logs}/calls.lock; {flock} 9\n"
            f"c=0; [ -e {logs}/calls ] && read -r c < {logs}/calls\n"
            f"c=$((c + 1)); echo $c > {logs}/calls\n"
            "exec 9>&-\n"
            'if [ "$c" = "${SIGNAL_AT:-0}" ] && [ -n "${BATCH_PID:-}" ]; then\n'
            '  kill -USR1 "$BATCH_PID"\n'
            "fi\n"
            f'exec "{real}" "$@"\n'
        )
        path.chmod(0o755)


@pytest.mark.parametrize("script", ["run_one", "sweep_array"])
def test_sigusr1_at_any_moment_before_the_run_is_kept(tmp_path: Path, script: str) -> None:
    """A SIGUSR1 that reaches the batch shell while it runs any one of its commands before
    the run starts (each call in turn: a first job counts them, then one job per call) is
    neither lost nor fatal: the run catches it once, checkpoints, and the job resubmits itself
    and exits 0. (A signal that came after the script read its first trap's note but before it
    set the forwarding trap was lost, and the run went on to its end: seen on real Slurm.)"""
    def make(n: int) -> Case:
        place = tmp_path / f"n{n}"
        place.mkdir()
        case = make_run_one(place) if script == "run_one" else make_sweep(place)
        signalling_stand_ins(place / "bin", case.logs)
        return case

    counted = make(0)
    proc = counted.run("finish")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    before = counted.log("dktlbm")[0]["calls_before"]
    assert before >= 3, before  # the stand-ins do see the script's commands
    for n in range(1, before + 1):
        case = make(n)
        # exec keeps the shell's pid, which the stand-ins signal
        proc = subprocess.run(["bash", "-c", 'BATCH_PID=$$ exec bash "$0"', str(case.script)],
                              cwd=case.cwd, capture_output=True, text=True, timeout=90,
                              env={**case.env, "FAKE_MODE": "wait", "SIGNAL_AT": str(n)})
        out = proc.stdout + proc.stderr
        assert proc.returncode == 0, f"signal during command {n} of {before}:\n{out}"
        runs = case.log("dktlbm")
        assert len(runs) == 1 and runs[0]["caught"] == [int(signal.SIGUSR1)], (n, out)
        assert runs[0]["calls_before"] >= n, (n, out)  # the signal came before the run
        assert "SIGUSR1" in out and len(case.log("sbatch")) == 1, (n, out)


def test_no_new_checkpoint_is_not_resubmitted(case: Case) -> None:
    """A job that resumes from the recorded checkpoint and stops (status 0) without writing
    a newer one is not resubmitted, so a run that makes no progress cannot loop through the
    queue; the job exits non-zero."""
    case.outdir.mkdir(parents=True)
    checkpoint = case.checkpoint_file(500)
    checkpoint.write_text("stand-in checkpoint")
    (case.outdir / f"{case.name}.checkpoint").write_text(f"{checkpoint}\n")
    proc = case.run("noop")
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert [r["argv"] for r in case.log("dktlbm")] == [
        [*case.args, "--restart", str(checkpoint)]]
    assert case.log("sbatch") == []


def test_recorded_checkpoint_moved_or_missing(case: Case) -> None:
    """<name>.checkpoint naming a file that is gone (the directory was moved): the checkpoint
    of the same name in the output directory is used. When there is none either, the job
    exits 2 without starting the run (which would otherwise start over)."""
    case.outdir.mkdir(parents=True)
    here = case.checkpoint_file(500)
    here.write_text("stand-in checkpoint")
    (case.outdir / f"{case.name}.checkpoint").write_text(f"/moved/away/{here.name}\n")
    proc = case.run("finish")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert case.log("dktlbm")[0]["argv"] == [*case.args, "--restart", str(here)]

    (case.outdir / f"{case.name}.finished").unlink()
    here.unlink()
    proc = case.run("finish")
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert len(case.log("srun")) == 1


@pytest.mark.parametrize("source", ["SUBMIT_SCRIPT", "scontrol", "scontrol-missing", "none"])
def test_the_script_resubmitted(case: Case, tmp_path: Path, source: str) -> None:
    """The file given to sbatch: SUBMIT_SCRIPT when set (even when scontrol knows another);
    else the Command= path of `scontrol show job <this job>` when that file exists; else $0
    (under Slurm the spool copy, which exists while the job runs)."""
    explicit = tmp_path / "explicit.slurm"
    recorded = tmp_path / "recorded.slurm"
    shutil.copy(case.script, explicit)
    shutil.copy(case.script, recorded)
    env = {"SUBMIT_SCRIPT": str(explicit), "FAKE_SCONTROL_COMMAND": str(recorded)}
    expected = {"SUBMIT_SCRIPT": explicit, "scontrol": recorded,
                "scontrol-missing": case.script, "none": case.script}[source]
    if source != "SUBMIT_SCRIPT":
        del env["SUBMIT_SCRIPT"]
    if source == "scontrol-missing":
        env["FAKE_SCONTROL_COMMAND"] = str(tmp_path / "gone.slurm")
    if source == "none":
        del env["FAKE_SCONTROL_COMMAND"]
    proc = case.run("checkpoint", env=env)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert [s["argv"][-1] for s in case.log("sbatch")] == [str(expected)]
    if source.startswith("scontrol"):
        assert case.log("scontrol")[0]["argv"] == ["show", "job", JOB_ID]


def test_failed_sbatch_is_reported(case: Case) -> None:
    """When sbatch refuses the resubmission, the job exits non-zero (the run is neither
    finished nor continued) and prints the command that goes on by hand: the same arguments
    with --restart and the new checkpoint."""
    proc = case.run("checkpoint", env={"FAKE_SBATCH_FAIL": "1"})
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert len(case.log("sbatch")) == 1
    hints = [ln.partition("by hand: ")[2] for ln in proc.stdout.splitlines() if "by hand: " in ln]
    assert len(hints) == 1, proc.stdout
    assert shlex.split(hints[0]) == ["srun", case.exe, *case.args, "--restart",
                                     str(case.checkpoint_file(100))]


# ---------------------------------------------------------------- the array's plan row


def test_array_task_runs_its_plan_row(tmp_path: Path) -> None:
    """Array task 4 runs line 4+1 of runs.csv (after the header): the run g3_h2 of the 3 x 2
    plan, with the row's arguments as `dkt-sweep plan` wrote them (the scene path with a blank,
    particles.x=0.9,1.1 as one argument though the CSV field is quoted for its commas), the
    plan's executable replaced by DKTLBM, and output.dir=<sweep dir>/<id>; the run's output
    goes to <sweep dir>/<id>/run.log. An index beyond the plan exits 2 and starts nothing."""
    case = make_sweep(tmp_path)
    runs = tmp_path / "sweep dir" / "runs.csv"
    line = runs.read_text().splitlines()[TASK + 1]
    assert line.startswith("g3_h2,") and '"' in line
    proc = case.run("finish")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert case.outdir == tmp_path / "sweep dir" / "g3_h2"
    argv = case.log("dktlbm")[0]["argv"]
    assert argv == case.args
    assert argv[0] == str(tmp_path / "my scenes" / "pair scene.nml")
    for pair in ("pair.gamma=3", "pair.dh=2", "particles.x=0.9,1.1"):
        assert argv[argv.index(pair) - 1] == "--set", pair
    assert argv[-2:] == ["--set", f"output.dir={case.outdir}"]
    assert case.log("srun")[0]["argv"][0] == case.exe
    assert "stand-in dktlbm: finish" in (case.outdir / "run.log").read_text()

    proc = case.run("finish", env={"SLURM_ARRAY_TASK_ID": "6"})
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "no row 6" in proc.stdout + proc.stderr
    assert len(case.log("srun")) == 1
