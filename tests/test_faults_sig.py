"""Every way a user stops a run keeps its data: signals and a closed standard output.

Each stopping signal (SIGINT, SIGHUP, SIGTERM, SIGUSR2, SIGXCPU, SIGALRM; SIGTERM and SIGUSR1
to the ranks are in test_restart.py and test_stops.py) is sent at a seeded random moment, to a
plain run (no mpirun: the process group, as Ctrl-C in a terminal does) and to a run under
`mpirun -n 2` (to mpirun, which forwards some signals and turns the others into SIGTERM to the
ranks). Each case asserts: no hang (every wait has a timeout), the
documented exit status, `stop_reason = signal`, the log naming the signal, a checkpoint named
in <name>.checkpoint, the series up to the stop, and that the run resumed from that checkpoint
ends bitwise equal to a run that never stopped (every dataset, the /diagnostics attributes,
the CSV and the XDMF). A signal sent as soon as the processes catch it, before MPI_Init, is
held and acted on at the first steps. A run whose standard output is piped into `head` (the
reader goes away) runs to its end: exit 0, `finished`, the log file complete.

Before these were handled, measured: SIGINT/SIGHUP/SIGXCPU/SIGALRM/SIGUSR2 killed a plain run
with no checkpoint and `stop_reason = running`, and `| head -12` ended it with status 141.
"""

from __future__ import annotations

import os
import random
import re
import signal
import subprocess
import time
from pathlib import Path

import h5py
import pytest

from dkt_run import EXE, INPUT, mpi_command, mpi_env, run, session_pids
from dktlbm.read import text_attr
from test_restart import assert_same_output  # every dataset, attributes, CSV and XDMF

STEPS = 6000  # about 2 s on one rank: every signal lands mid-run
SETS = [
    "lbm.cells_per_diameter=10",
    "output.series_interval=0.01",
    "output.field_interval=0.1",
    "run.mach_limit=0.6",
    f"run.steps={STEPS}",
    "run.progress_every=100",
]
TIMEOUT = 120.0  # any single run; far more than one needs on two busy cores
# mpirun's documented status when it ended the job itself (SIGINT, SIGHUP, SIGTERM to mpirun):
# the ranks checkpoint and exit 0, mpirun still reports the job as ended by a signal
MPIRUN_ENDED = 1


def command(ranks: int | None, out: Path, extra: list[str] | None = None) -> list[str]:
    """dktlbm on case0 with SETS and output.dir = out: plain (ranks None) or under mpirun."""
    prefix = [] if ranks is None else mpi_command(ranks)
    cmd = [*prefix, str(EXE), str(INPUT / "case0.nml")]
    for s in [*SETS, f"output.dir={out}"]:
        cmd += ["--set", s]
    return cmd + (extra or [])


def kill_session(proc: subprocess.Popen) -> None:
    for pid in [proc.pid, *session_pids(proc.pid)]:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


def wait_for(test, proc: subprocess.Popen, what: str) -> None:
    """Poll `test()` until true; a run that ends first or a wait past TIMEOUT fails."""
    deadline = time.time() + TIMEOUT
    while not test():
        if proc.poll() is not None:
            out, err = proc.communicate()
            pytest.fail(f"the run ended ({proc.returncode}) before {what}:\n{out}\n{err}")
        if time.time() > deadline:
            kill_session(proc)
            pytest.fail(f"hang: no {what} within {TIMEOUT} s")
        time.sleep(0.02)


def finish(proc: subprocess.Popen) -> tuple[str, str]:
    try:
        return proc.communicate(timeout=TIMEOUT)
    except subprocess.TimeoutExpired:
        kill_session(proc)
        out, err = proc.communicate()
        pytest.fail(f"hang: the run did not end within {TIMEOUT} s of the signal\n{out}\n{err}")


def handlers_in(proc: subprocess.Popen, count: int, signum: int) -> bool:
    """Whether all `count` dktlbm processes of the session catch `signum` (/proc SigCgt): the
    moment right after the program's first statement, before MPI_Init and the input."""
    pids = session_pids(proc.pid, "dktlbm")
    if len(pids) < count:
        return False
    for pid in pids:
        try:
            status = Path(f"/proc/{pid}/status").read_text()
        except OSError:
            return False
        caught = int(re.search(r"^SigCgt:\s*([0-9a-f]+)", status, re.MULTILINE).group(1), 16)
        if not caught >> (signum - 1) & 1:
            return False
    return True


def signalled_run(
    out: Path, ranks: int | None, signum: int, seed: int, *, target: str, when: str = "stepping"
) -> tuple[int, str, str]:
    """Start a run, send `signum` at a seeded random moment and return (status, stdout, stderr).
    when = 'stepping': up to 0.1 s after a progress line drawn from steps 100-1500; 'ready': as
    soon as every process catches the signal, before MPI_Init and long before the first step.
    target = 'group': the launched process's group (Ctrl-C in a terminal); 'launcher': the
    launched process only (mpirun); 'ranks': every dktlbm process (a batch system signalling
    the tasks)."""
    proc = subprocess.Popen(
        command(ranks, out),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=mpi_env(),
        start_new_session=True,
    )
    log = out / "case0.log"
    if when == "ready":
        wait_for(lambda: handlers_in(proc, ranks or 1, signum), proc, "signal handlers")
    else:
        rng = random.Random(seed)
        line = f"step {100 * rng.randint(1, 15)}/"
        wait_for(lambda: log.exists() and line in log.read_text(), proc, line)
        time.sleep(rng.uniform(0.0, 0.1))
    if target == "group":
        os.killpg(proc.pid, signum)
    elif target == "launcher":
        os.kill(proc.pid, signum)
    else:
        # a run without mpirun is one process, the one started: not a copy it forks on its way
        # to exec Open MPI's daemon in MPI_Init (named dktlbm until the exec), which a signal
        # would kill ("Unable to start a daemon on the local node")
        pids = [proc.pid] if ranks is None else session_pids(proc.pid, "dktlbm")
        for pid in pids:
            os.kill(pid, signum)
    stdout, stderr = finish(proc)
    return proc.returncode, stdout, stderr


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The run that never stops (on 2 ranks: results do not depend on the rank count)."""
    out = tmp_path_factory.mktemp("reference") / "run"
    proc = subprocess.run(command(2, out), capture_output=True, text=True, env=mpi_env(),
                          timeout=TIMEOUT)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return out


def assert_stopped_and_resumes(
    reference: Path, out: Path, name: str, status: int, stdout: str, stderr: str, expected: int
) -> None:
    """The stop kept everything (exit status, stop_reason, log, checkpoint, series up to the
    stop) and the run resumed from its checkpoint equals the reference bit for bit."""
    assert status == expected, f"exit status {status}, expected {expected}\n{stdout}\n{stderr}"
    log = (out / "case0.log").read_text()
    m = re.search(rf"stopped on signal {name} after step (\d+) of {STEPS}", log)
    assert m, f"the log does not say the run stopped on {name}:\n{log}\n{stderr}"
    step = int(m.group(1))
    assert step < STEPS, "the signal came too late to test a stop"
    assert not (out / "case0.finished").exists()
    checkpoint = Path((out / "case0.checkpoint").read_text().strip())
    assert checkpoint.name == f"case0_chk_{step:09d}.h5" and checkpoint.exists()
    with h5py.File(out / "case0.h5", "r") as h5:
        assert text_attr(h5["run"].attrs["stop_reason"]) == "signal"
        t = h5["particles/t"][()]
        dt = float(h5["run"].attrs["dt"])
    assert t[-1] == pytest.approx(step * dt, rel=1e-12), "the series does not reach the stop"
    run("case0.nml", 2, SETS, out, extra=["--restart", str(checkpoint)], timeout=TIMEOUT)
    assert (out / "case0.finished").exists()
    assert_same_output(reference, out)


# SIGTERM and SIGUSR1 to the ranks: tests/test_restart.py, tests/test_stops.py
PLAIN = [("SIGINT", 1), ("SIGINT", 2), ("SIGHUP", 3), ("SIGXCPU", 5), ("SIGALRM", 6),
         ("SIGUSR2", 7)]


@pytest.mark.parametrize(("name", "seed"), PLAIN, ids=[f"{n}-{s}" for n, s in PLAIN])
def test_a_signal_to_a_plain_run_checkpoints_and_resumes_bitwise(
    reference: Path, tmp_path: Path, name: str, seed: int
) -> None:
    """No mpirun (a singleton run), the signal to the whole process group as a terminal sends
    Ctrl-C (SIGINT) or a hang-up (SIGHUP): checkpoint, stop_reason, exit 0, bitwise resume."""
    out = tmp_path / "run"
    status, stdout, stderr = signalled_run(out, None, getattr(signal, name), seed, target="group")
    assert_stopped_and_resumes(reference, out, name, status, stdout, stderr, 0)


MPIRUN = [
    # signals mpirun forwards to the ranks: each rank stops itself, mpirun exits 0
    ("SIGUSR2", "SIGUSR2", 12, 0),
    ("SIGXCPU", "SIGXCPU", 13, 0),
    ("SIGALRM", "SIGALRM", 14, 0),
    # signals mpirun acts on itself: it sends SIGTERM to the ranks, which stop cleanly
    ("SIGINT", "SIGTERM", 15, MPIRUN_ENDED),
    ("SIGINT", "SIGTERM", 16, MPIRUN_ENDED),
    ("SIGHUP", "SIGTERM", 17, MPIRUN_ENDED),
    ("SIGTERM", "SIGTERM", 18, MPIRUN_ENDED),
]


@pytest.mark.parametrize(("sent", "logged", "seed", "status"), MPIRUN,
                         ids=[f"{s}-{n}" for s, _, n, _ in MPIRUN])
def test_a_signal_to_mpirun_checkpoints_and_resumes_bitwise(
    reference: Path, tmp_path: Path, sent: str, logged: str, seed: int, status: int
) -> None:
    """`mpirun -n 2`, the signal to mpirun (what Ctrl-C or `kill <mpirun pid>` reaches): the
    ranks checkpoint and close the run file; mpirun's exit status is the documented one."""
    out = tmp_path / "run"
    got, stdout, stderr = signalled_run(out, 2, getattr(signal, sent), seed, target="launcher")
    assert_stopped_and_resumes(reference, out, logged, got, stdout, stderr, status)


@pytest.mark.parametrize("name", ["SIGINT", "SIGHUP"])
def test_a_signal_to_the_ranks_checkpoints_and_resumes_bitwise(
    reference: Path, tmp_path: Path, name: str
) -> None:
    """The signal to every rank of `mpirun -n 2` (a batch system signalling its tasks): the
    ranks stop cleanly and mpirun exits 0."""
    out = tmp_path / "run"
    got, stdout, stderr = signalled_run(out, 2, getattr(signal, name), 21, target="ranks")
    assert_stopped_and_resumes(reference, out, name, got, stdout, stderr, 0)


@pytest.mark.parametrize("ranks", [None, 2], ids=["plain", "mpirun-2"])
def test_a_signal_before_the_first_step_is_held_and_acted_on(
    reference: Path, tmp_path: Path, ranks: int | None
) -> None:
    """SIGINT to the ranks as soon as they catch it (the first statement of the program, before
    MPI_Init): the signal is held through the set-up and acted on at the first steps (the
    ranks agree on it one step later), instead of killing the run or being ignored."""
    out = tmp_path / "run"
    got, stdout, stderr = signalled_run(out, ranks, signal.SIGINT, 0, target="ranks",
                                        when="ready")
    assert_stopped_and_resumes(reference, out, "SIGINT", got, stdout, stderr, 0)
    step = int(Path((out / "case0.checkpoint").read_text().strip()).stem.split("_")[-1])
    assert step <= 2, f"the held signal was acted on only at step {step}"


def test_a_closed_standard_output_does_not_stop_the_run(reference: Path, tmp_path: Path) -> None:
    """`dktlbm ... | head -12`: the reader goes away after 12 lines; the run must not die of
    SIGPIPE or a write error. It runs to its end (exit 0, `finished`), the log file holds every
    line, and the output equals the reference."""
    out = tmp_path / "run"
    with subprocess.Popen(command(None, out), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                          env=mpi_env(), start_new_session=True) as proc:
        head = subprocess.run(["head", "-12"], stdin=proc.stdout, capture_output=True,
                              timeout=TIMEOUT)
        proc.stdout.close()  # the only reader is gone: writes now fail with EPIPE
        try:
            _, stderr = proc.communicate(timeout=TIMEOUT)
        except subprocess.TimeoutExpired:
            kill_session(proc)
            pytest.fail("hang after the pipe closed")
    assert len(head.stdout.splitlines()) == 12
    assert proc.returncode == 0, f"exit status {proc.returncode}\n{stderr.decode()}"
    with h5py.File(out / "case0.h5", "r") as h5:
        assert text_attr(h5["run"].attrs["stop_reason"]) == "finished"
    log = (out / "case0.log").read_text()
    assert f"step {STEPS - 100}/{STEPS}" in log, "the log lost the lines after the pipe closed"
    assert (out / "case0.finished").exists()
    assert_same_output(reference, out)
