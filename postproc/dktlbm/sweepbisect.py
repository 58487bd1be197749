"""The threshold search `dkt-sweep bisect`: where along pair.gamma or pair.dh the settled DKT
pattern changes, and the settling of search points that `dkt-sweep map` (dktlbm.sweepmap)
shares.

A Bisector settles points by the rules of postproc/README.md ("Settled patterns"): a run's
Verdict (dktlbm.sweepcommon), t_end doubled while a 'once' or 'never' is not settled, up to
max_t_end, and window.above doubled after a window escape, up to max_above (or, with a window
that grows, each run's window growing up to it). bisect() narrows the bracket, writes
DIR/bisect.csv and DIR/runs.csv, and after each round prints an estimate of the time the whole
bisection has left (bisect_estimate).
"""

from __future__ import annotations

import csv
import hashlib
import json
import math
import os
import shlex
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from .sweepcommon import (
    RUNS_CSV,
    UNSETTLED,
    PlannedRun,
    SweepError,
    Verdict,
    base_value,
    clock_text,
    first_change,
    judge,
    point_value,
    read_plan,
    verdict,
    wall_seconds,
    write_plan,
)
from .sweepplan import Progress, run_plan, slurm_script

BISECT_CSV = "bisect.csv"
BISECT_STATE = "bisect.json"
BISECT_COLUMNS = ("row", "value", "pattern", "episodes", "first_kiss_t", "t_end", "end_t",
                  "status", "settled", "wall_s", "dir", "above")


# ---------------------------------------------------------------- settings


@dataclass
class Scene:
    """The base scene of a search: the first field of every search's settings."""

    base: Path


@dataclass
class SearchSettings(Scene):
    """What every search (bisect, map) runs besides its points: the runs' --set options,
    their directory and executable, and the limits that settle a point (Bisector.settle).

    A search's settings class names its points' class first and this one second
    (BisectSettings(SearchSettings, Line)): a dataclass lists the fields of its bases from the
    last base to the first, so its fields are the scene, then the points' (Line: key, lo, hi,
    tol), then these."""

    sets: list[str]
    out: Path
    exe: str
    t_end: float  # s, the runs' first end time
    max_t_end: float  # s, the longest run.t_end a point may use
    above: float  # D_1, the runs' first window.above
    # D_1, the longest the window may be above the lowest particle's centre, as the key
    # window.max_above: reached by doubling window.above after an escape, or by growing
    max_above: float
    kiss: bool = False  # tell 'kisses' (once or repeated) from 'never' only (judge)
    grow: float = 0.0  # D_1, the runs' window.max_above: their windows grow up to it; 0 = never

    def keys(self) -> dict[str, object]:
        """The keys the search's points lie along, as identity() records them."""
        raise NotImplementedError

    def identity(self) -> dict[str, object]:
        """What a rerun in the same directory must repeat to reuse its runs: the base scene,
        the keys (keys()) and the --set options. A run is otherwise named by its point, t_end
        and window (its id), so other ranges or tolerances (a tighter bracket of the same
        question) reuse every run they share and run only the new points."""
        return {"base": str(self.base),
                "base_sha256": hashlib.sha256(self.base.read_bytes()).hexdigest(),
                **self.keys(), "sets": self.sets}


@dataclass
class Line(Scene):
    """The points of a bisection: pair.<key> from lo to hi, narrowed to a bracket of tol."""

    key: str  # 'gamma' or 'dh'
    lo: float
    hi: float
    tol: float


@dataclass
class BisectSettings(SearchSettings, Line):
    """What a bisection runs: base, key, lo, hi, tol, then SearchSettings' fields."""

    def keys(self) -> dict[str, object]:
        return {"key": self.key}


# ---------------------------------------------------------------- bisect


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
        self.clock = time.monotonic  # times the rounds (bisect_estimate)
        self.round_seconds: list[float] = []  # of each round that ran a point
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
        g = at["gamma"] if "gamma" in at else base_value(c.base, c.sets, "gamma")
        h = at["dh"] if "dh" in at else base_value(c.base, c.sets, "dh")
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
                        f"is not final: raise the limit (--max-above with --grow, or the "
                        f"window.max_above the scene or a --set gives), or bracket "
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
        runs up to N points spaced evenly inside the bracket (round_points) and keeps the
        first sub-interval, from lo, whose ends differ. After each round that leaves the
        bracket wider than tol, a line estimates the time the whole bisection has left
        (bisect_estimate)."""
        c = self.cfg
        start, launched = self.clock(), self.launches
        first = self.settle([c.lo, c.hi])
        if self.launches > launched:  # the ends' round: per batch of N runs side by side
            self.round_seconds.append((self.clock() - start) / math.ceil(2 / self.jobs))
        lo, hi = (c.lo, first[c.lo][0].pattern), (c.hi, first[c.hi][0].pattern)
        if lo[1] == hi[1]:
            raise SweepError(
                f"{c.key} = {c.lo:.8g} and {c.key} = {c.hi:.8g} give the same pattern, "
                f"{lo[1]} and {hi[1]}: --lo and --hi must bracket a change of pattern")
        self._estimate(lo, hi)
        while hi[0] - lo[0] > c.tol * (1 + 1e-9):
            inside = sorted(v for v in self.earlier if lo[0] < v < hi[0])
            self.earlier -= set(inside)  # each earlier point is read once
            known = self.settle(inside, known_only=True) if inside else {}
            if known:  # settled before (another --tol): narrow with them, running nothing
                lo, hi = first_change(lo, hi, known)
                continue
            width = hi[0] - lo[0]
            n = round_points(width, c.tol, self.jobs)
            xs = sorted({point_value(lo[0] + k * width / (n + 1)) for k in range(1, n + 1)}
                        - {lo[0], hi[0]})
            if not xs:
                raise SweepError(f"--tol {c.tol:g} is finer than 8 significant digits of "
                                 f"{c.key} resolve")
            start, launched = self.clock(), self.launches
            lo, hi = first_change(lo, hi, self.settle(xs))
            if self.launches > launched:
                self.round_seconds.append(self.clock() - start)
            self._estimate(lo, hi)
        return lo, hi

    def _estimate(self, lo: tuple[float, str], hi: tuple[float, str]) -> None:
        line = bisect_estimate(lo[0], hi[0], self.cfg.tol, self.jobs, self.round_seconds)
        if line is not None:
            print(line, flush=True)


def round_points(width: float, tol: float, jobs: int) -> int:
    """The points a round places evenly inside a bracket `width` wide: up to `jobs`, and no
    more than it needs to reach `tol` (n points cut it into n + 1 equal parts)."""
    return min(jobs, max(1, math.ceil(width / tol - 1e-9) - 1))


def rounds_left(width: float, tol: float, jobs: int) -> int:
    """The rounds that narrow a bracket `width` wide to at most `tol`, up to `jobs` points a
    round (round_points): each keeps one of the parts its points cut the bracket into."""
    rounds = 0
    while width > tol * (1 + 1e-9):
        width /= round_points(width, tol, jobs) + 1
        rounds += 1
    return rounds


def bisect_estimate(lo: float, hi: float, tol: float, jobs: int,
                    seconds: list[float]) -> str | None:
    """The line that estimates how long the whole bisection still takes, after a round that
    left the bracket [lo, hi]: the rounds left (rounds_left) times the mean time of a round so
    far (`seconds`, one per round that ran a point; the ends' round counted per batch of
    `jobs` runs side by side). None once the bracket is at most `tol` wide. An estimate: a
    point that must run again with a later t_end or a taller window takes longer."""
    rounds = rounds_left(hi - lo, tol, jobs)
    if rounds == 0:
        return None
    points = round_points(hi - lo, tol, jobs)
    what = (f"{rounds} more round{'s' if rounds != 1 else ''} narrow [{lo:.8g}, {hi:.8g}] to "
            f"--tol {tol:g} ({points} point{'s' if points != 1 else ''} in the next)")
    if not seconds:
        return f"estimate: {what}; the time of a round is not known yet"
    mean = sum(seconds) / len(seconds)
    return (f"estimate: about {clock_text(mean * rounds)} left for the whole bisection: "
            f"{what}, at {clock_text(mean)} a round so far (more if a point must run again "
            f"with a later t_end or a taller window)")


def bisect_state(cfg: SearchSettings, state: str = BISECT_STATE,
                 what_it_is: str = "bisection") -> None:
    """Refuse a directory that holds a bisection (DIR/`state`: a map's is map.json) with other
    settings (cfg.identity()); record ours."""
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
