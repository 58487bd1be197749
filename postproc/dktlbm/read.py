"""Reader of dktlbm run files (`<dir>/<name>.h5`) shared by the post-processing scripts.

    run = open_run("runs/case1/case1.h5")     # /run, /particles and /diagnostics, checked
    pair = pair_of(run)                       # D_x, D_y, D_r, Re, C_d, DKT pattern, episodes
    snap = read_field("runs/case1/case1.h5", "vorticity", time=1.5)   # nearest stored field

Units are the file's: cm, g, s. The pair is particles 1 and 2; D_1 is the larger diameter.
The scales (t_ref, h_ref, gravity, fluid density and viscosity, D_1, the diameters of the pair)
and the kissing thresholds are read from the attributes the program stores in /run. For
files written before it stored them, the values come from the namelist stored in /run, and
what that does not give from the dktlbm executable itself (`dktlbm FILE --print-defaults`
and `--check`, in dktlbm.settings, the one place that runs it): no default is repeated here.
When
the file has a /diagnostics group its series, thresholds, pattern and episodes are used
as written; otherwise (older files, scenes without a pair group) they are computed here from
/particles with the same rules (docs/model.md §6):

    enter   = max(enter_cells * dx, enter_d1 * D_1)      (&diagnostics enter_cells = 0:
    release = max(release_cells * dx, release_d1 * D_1)   as dktlbm --check reports it)

An episode starts at the first sample with D_r <= enter while not in an episode and ends at
the first later sample with D_r > release (or at the last sample: an open episode). Pattern:
two or more episodes 'repeated', one 'once', none 'never'.

Every problem with an input file raises RunFileError, whose text is `<file>: <what>`; the
scripts print it as `error: <file>: <what>` and exit with status 2.

A run that stopped before its last step (/run attribute stop_reason: 'guard: ...', 'signal',
'wall_limit', 'error: ...', or 'running' for a run killed or still going) is read all the
same: open_run prints a warning that says why it stopped and that its series end early.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from .launch import LaunchError

# The namelist parser and the program's settings live in .settings (the fallback for files
# without stored values); they stay importable from here, as the sweeps and scripts use them.
from .settings import RunSettings as RunSettings
from .settings import fortran_float as fortran_float
from .settings import kiss_cells as kiss_cells
from .settings import nml_float as nml_float
from .settings import nml_floats as nml_floats
from .settings import parse_namelist as parse_namelist
from .settings import program_settings as program_settings

PATTERNS = ("repeated", "once", "never")
SERIES = ("x", "y", "u", "v", "omega", "fx", "fy", "torque")
FIELD_NAMES = ("vorticity", "pressure", "speed", "ux", "uy", "rho")


class RunFileError(Exception):
    """A file that cannot be used: missing, not HDF5, not a dktlbm run, or lacking what is
    needed. str() gives `<file>: <what is wrong>`."""

    def __init__(self, path: str | Path, what: str) -> None:
        super().__init__(f"{path}: {what}")
        self.path = str(path)
        self.what = what


LIMIT_KEYS = ("enter_cells", "enter_d1", "release_cells", "release_d1")


# ---------------------------------------------------------------- the run file


def text_attr(value: Any) -> str:
    """An HDF5 string attribute as str: variable-length UTF-8 (newer files), fixed-length bytes
    (older ones) or a one-element array of either."""
    if isinstance(value, bytes | np.bytes_):
        value = value.decode("utf-8", "replace")
    elif isinstance(value, np.ndarray):
        value = value.ravel()[0] if value.size else ""
        return text_attr(value)
    return str(value).rstrip("\0").strip()


def run_namelist(h5: Any) -> str:
    """The namelist text a run stored in /run of the open file `h5`: the attribute `namelist`,
    or for a long one (some 500 particles and more) the dataset /run/namelist; '' if neither."""
    run = h5.get("run")
    if run is None:
        return ""
    if "namelist" in run.attrs:
        return text_attr(run.attrs["namelist"])
    if "namelist" in run:
        return text_attr(run["namelist"][()])
    return ""


class NotANumber(ValueError):
    """A stored value that must be a number and is not: open_h5 turns it into a RunFileError
    naming the file."""


def _num(value: Any, name: str | None = None) -> float:
    """The number a stored attribute holds (an array of one, an integer or a float); NotANumber
    (naming the attribute `name`, when given) for anything else."""
    try:
        return float(np.asarray(value, dtype=float).ravel()[0])
    except (TypeError, ValueError, IndexError, OverflowError):
        shown = repr(value)
        if len(shown) > 60:
            shown = shown[:57] + "..."
        what = f"attribute {name}" if name else "a stored value"
        raise NotANumber(f"{what} = {shown} is not a number (a damaged or foreign run "
                         "file?)") from None


def _num_or(attrs: Any, key: str, default: float) -> float:
    """_num of attribute `key` of `attrs`, or `default` when there is none."""
    return _num(attrs[key], key) if key in attrs else default


def numeric_attrs(attrs: Any) -> dict[str, float]:
    """The numeric attributes of one HDF5 object as floats, integers (newer files) and floats
    (older ones) alike; the `*_units` companions and the strings are left out."""
    out = {}
    for key, value in attrs.items():
        a = np.asarray(value)
        if not key.endswith("_units") and a.dtype.kind in "fiu" and a.size == 1:
            out[key] = _num(a)
    return out


@contextmanager
def open_h5(path: str | Path) -> Iterator[Any]:
    """h5py.File of `path` for reading; RunFileError when it is missing or not HDF5."""
    import h5py

    p = Path(path)
    if not p.exists():
        raise RunFileError(path, "no such file")
    if p.is_dir():
        raise RunFileError(path, "is a directory, not a run file")
    try:
        is_h5 = h5py.is_hdf5(p)
    except OSError as exc:
        raise RunFileError(path, f"cannot read: {exc}") from None
    if not is_h5:
        raise RunFileError(path, "not an HDF5 file")
    if held_open(p):
        # HDF5 gives a reader no consistent view of a file another process is writing
        raise RunFileError(path, "is being written by a live run (a process on this machine "
                           "has it open); read it once the run has stopped (SIGTERM stops it "
                           "with a checkpoint)")
    try:
        h5 = h5py.File(p, "r")
    except OSError as exc:
        raise RunFileError(path, f"cannot open as HDF5: {exc}") from None
    try:
        yield h5
    except NotANumber as exc:
        raise RunFileError(path, str(exc)) from None
    finally:
        h5.close()


@dataclass
class Run:
    """One run file: /particles series (n samples, count particles), scales and metadata.
    Scales come from /run attributes, else /diagnostics, else the run's settings (the namelist
    in /run, and what dktlbm makes of it)."""

    path: Path
    name: str
    namelist: dict[str, dict[str, list[str]]]
    dx: float  # cm, lattice spacing (NaN if unknown)
    dt: float  # s, time step (NaN if unknown)
    steps: int  # time steps of the whole run (0 if unknown)
    count: int  # particles
    t: np.ndarray  # (n,) s
    series: dict[str, np.ndarray]  # SERIES name -> (n, count)
    diameters: np.ndarray  # (count,) cm (NaN if unknown)
    window_offset: np.ndarray | None  # (n,) cm, y of the window bottom
    width: float  # cm, channel width W
    t_ref: float  # s, t* = t/t_ref
    h_ref: float  # cm, H of y/H and u/sqrt(H g)
    gravity: float  # cm/s^2
    rho_f: float  # g/cm^3
    mu: float  # g/(cm s)
    diagnostics: dict[str, Any] | None = None  # /diagnostics: attrs and datasets
    has_fields: bool = False
    stop_reason: str = ""  # /run stop_reason; '' in files written before it was stored
    run_attrs: dict[str, float] = field(default_factory=dict)  # numeric /run attributes
    settings: RunSettings = field(default_factory=lambda: RunSettings(""))  # the input

    @property
    def complete(self) -> bool:
        """False when the run stopped before its end (a guard, a signal, the wall limit, an
        error) or never closed its file; True for a finished run, an escape from the window
        (the pair separated: the run's natural end), and older files that do not say."""
        return self.stop_reason in ("", "finished", "window_escape")

    def stop_note(self) -> str | None:
        """Why the run stopped early and where its series end; None for a complete run."""
        if self.complete:
            return None
        why = "it was killed or is still running (its file was not closed)" \
            if self.stop_reason == "running" else f"stopped: {self.stop_reason}"
        end = self.steps * self.dt if self.steps > 0 and math.isfinite(self.dt) else math.nan
        upto = f"the series end at t = {fmt(float(self.t[-1]))} s" if self.t.size else \
            "no series were written"
        if math.isfinite(end):
            upto += f" of {fmt(end)} s"
        return f"{self.path}: the run ended early ({why}); {upto}, so they are incomplete"

    @property
    def tstar(self) -> np.ndarray:
        return self.t / self.t_ref

    @property
    def velocity_scale(self) -> float:
        """sqrt(H g), cm/s."""
        return math.sqrt(self.h_ref * self.gravity)

    @property
    def omega_scale(self) -> float:
        """2 pi / t_ref, 1/s."""
        return 2.0 * math.pi / self.t_ref

    def label(self) -> str:
        return self.name

    def to_dataframe(self) -> Any:
        """The particle series as a pandas DataFrame indexed by (particle, t), units in
        `df.attrs["units"]` (dktlbm.frames). ImportError naming the package without pandas."""
        from .frames import to_dataframe

        return to_dataframe(self)

    def to_xarray(self) -> Any:
        """The particle series and diameters as an xarray Dataset over (particle, t), each
        variable's unit in its attrs (dktlbm.frames). ImportError naming the package without
        xarray."""
        from .frames import to_xarray

        return to_xarray(self)


def _read_diagnostics(h5: Any) -> dict[str, Any] | None:
    if "diagnostics" not in h5:
        return None
    g = h5["diagnostics"]
    d: dict[str, Any] = {"attrs": {}}
    for k, v in g.attrs.items():
        d["attrs"][k] = text_attr(v) if k == "pattern" else v
    for k, v in g.items():
        if hasattr(v, "shape"):
            d[k] = np.asarray(v[()], dtype=float)
    if "episodes" in g and hasattr(g["episodes"], "keys"):
        ep = g["episodes"]
        d["episodes_start"] = np.atleast_1d(np.asarray(ep["start"][()], dtype=float))
        d["episodes_end"] = np.atleast_1d(np.asarray(ep["end"][()], dtype=float))
        if "gap_min" in ep:
            # the smallest gap of each episode over every step, not only the sampled ones
            d["episodes_gap_min"] = np.atleast_1d(np.asarray(ep["gap_min"][()], dtype=float))
    return d


def _diameters(settings: RunSettings, count: int, diag: dict[str, Any] | None,
               stored: dict[str, float]) -> np.ndarray:
    """The particle diameters, cm: the pair's as stored in /run (diameter_1, diameter_2) or
    /diagnostics (d1, gamma); the others, and all of them in older files, from the run's
    settings, asked only when needed."""
    d = np.full(count, math.nan)
    for k in range(min(count, 2)):
        if f"diameter_{k + 1}" in stored:
            d[k] = stored[f"diameter_{k + 1}"]
    if count == 1 and "d1" in stored:
        d[0] = stored["d1"]
    if diag is not None and count >= 2 and np.isnan(d[:2]).any():
        a = diag["attrs"]
        if "d1" in a and "gamma" in a and _num(a["gamma"], "gamma") > 0:
            d1 = _num(a["d1"], "d1")
            d[0], d[1] = d1, d1 / _num(a["gamma"], "gamma")
    if np.isnan(d).any():
        # &pair gamma > 0 writes particles 1 (D_1) and 2 (D_1/gamma): the namelist in /run may
        # be the input as given, before that expansion.
        for k in np.flatnonzero(np.isnan(d)):
            d[k] = settings.number("particles", "diameter", int(k))
        if count >= 2 and settings.number("pair", "gamma") > 0:
            d1 = settings.number("pair", "d1")
            d[0], d[1] = d1, d1 / settings.number("pair", "gamma")
    return d


def open_run(path: str | Path, need_particles: int = 1, warn: bool = True) -> Run:
    """Read a dktlbm run file. RunFileError when the file is missing, not HDF5, not a dktlbm
    run (no /particles group), or holds fewer than `need_particles` particles. A run that
    stopped early is read as far as it got, with a warning on stderr unless not `warn`."""
    import h5py

    with open_h5(path) as h5:
        group = h5.get("particles")
        if not isinstance(group, h5py.Group) or not isinstance(group.get("t"), h5py.Dataset):
            what = "not a dktlbm run file (no /particles group)"
            if "run" in h5 and group is None:
                reason = stop_reason(h5)
                if reason not in ("", "finished", "window_escape"):
                    what = (f"the run stopped before it wrote any particle sample "
                            f"(stop_reason: {reason})")
                else:
                    what = "the run has no particles (no /particles group)"
            raise RunFileError(path, what)
        try:
            run = _read_run(Path(path), h5, need_particles)
        except RunFileError:
            raise
        except LaunchError as exc:
            raise RunFileError(path, f"the file lacks scales that files since dktlbm 0.1 store "
                               f"in /run, and dktlbm cannot supply them: {exc}") from None
        except (KeyError, ValueError, TypeError, IndexError, OSError) as exc:
            raise RunFileError(path, f"not a readable dktlbm run file ({exc})") from None
    note = run.stop_note()
    if note and warn:
        print(f"warning: {note}", file=sys.stderr)
    return run


def run_t_ref(path: str | Path) -> float:
    """t_ref of a run file, s (t* = t/t_ref): the /run attribute, else the run's settings; also
    for a run without particles."""
    with open_h5(path) as h5:
        attrs = h5["run"].attrs if "run" in h5 else {}
        if "t_ref" in attrs:
            return _num(attrs["t_ref"], "t_ref")
        text = run_namelist(h5)
    try:
        return RunSettings(text).number("run", "t_ref")
    except LaunchError as exc:
        raise RunFileError(path, f"no /run t_ref, and dktlbm cannot supply it: {exc}") from None


def stop_reason(h5: Any) -> str:
    """/run stop_reason of an open run file: 'finished', 'window_escape', 'signal',
    'wall_limit', 'guard: ...', 'error: ...', 'running' (killed or still going); '' when the
    file predates the attribute."""
    if "run" not in h5 or "stop_reason" not in h5["run"].attrs:
        return ""
    return text_attr(h5["run"].attrs["stop_reason"])


def _read_run(path: Path, h5: Any, need: int) -> Run:
    p = h5["particles"]
    t = np.asarray(p["t"][()], dtype=float).ravel()
    series: dict[str, np.ndarray] = {}
    for name in SERIES:
        if name not in p:
            raise RunFileError(path, f"not a dktlbm run file (no /particles/{name})")
        a = np.asarray(p[name][()], dtype=float)
        if a.ndim == 1:
            a = a[:, None]
        if a.shape[0] != t.size:
            raise RunFileError(path, f"/particles/{name} has {a.shape[0]} samples, t {t.size}")
        series[name] = a
    count = int(_num(p.attrs["count"], "count")) if "count" in p.attrs else series["x"].shape[1]
    count = min(count, series["x"].shape[1])
    if count < need:
        noun = "particle" if count == 1 else "particles"
        raise RunFileError(path, f"the run has {count} {noun}; a pair needs {need}")
    if t.size == 0:
        raise RunFileError(path, "/particles holds no samples")
    offset = np.asarray(p["window_offset"][()], dtype=float) if "window_offset" in p else None

    run_attrs = h5["run"].attrs if "run" in h5 else {}
    settings = RunSettings(run_namelist(h5))
    numbers = numeric_attrs(run_attrs)
    dx = _num_or(run_attrs, "dx", math.nan)
    dt = _num_or(run_attrs, "dt", math.nan)
    steps = int(_num_or(run_attrs, "steps", 0))

    diag = _read_diagnostics(h5)
    a = diag["attrs"] if diag is not None else {}

    def scale(attr: str, group: str, key: str) -> float:
        # as stored by the program; the run's settings only for older files
        if attr in numbers:
            return numbers[attr]
        if attr in a:
            return _num(a[attr], attr)
        return settings.number(group, key)

    t_ref = scale("t_ref", "run", "t_ref")
    gravity = scale("gravity", "particles", "gravity")
    # h_ref = g t_ref^2, as the program defines and stores it
    h_ref = numbers.get("h_ref", _num_or(a, "h_ref", gravity * t_ref**2))
    return Run(
        path=path,
        name=path.stem,
        namelist=settings.given,
        dx=dx,
        dt=dt,
        steps=steps,
        count=count,
        t=t,
        series={k: v[:, :count] for k, v in series.items()},
        diameters=_diameters(settings, count, diag, numbers),
        window_offset=offset,
        width=scale("width", "domain", "width"),
        t_ref=t_ref,
        h_ref=h_ref,
        gravity=gravity,
        rho_f=scale("rho_f", "fluid", "density"),
        mu=scale("mu", "fluid", "viscosity"),
        diagnostics=diag,
        has_fields="fields" in h5,
        stop_reason=stop_reason(h5),
        run_attrs=numbers,
        settings=settings,
    )


# ---------------------------------------------------------------- the pair and its pattern


@dataclass
class Thresholds:
    """Kissing thresholds on D_r, cm; `rule` says how they were chosen."""

    enter: float
    release: float
    dx: float
    d1: float
    rule: str = "the run's settings"

    @property
    def enter_cells(self) -> float:
        return self.enter / self.dx if self.dx > 0 else math.nan

    @property
    def release_cells(self) -> float:
        return self.release / self.dx if self.dx > 0 else math.nan

    @property
    def enter_d1(self) -> float:
        return self.enter / self.d1

    @property
    def release_d1(self) -> float:
        return self.release / self.d1


def thresholds(dx: float, d1: float, *, enter_cells: float, enter_d1: float,
               release_cells: float, release_d1: float,
               rule: str = "the run's settings") -> Thresholds:
    """enter = max(enter_cells dx, enter_d1 D_1), release = max(release_cells dx,
    release_d1 D_1); a spacing that is unknown (NaN) counts as 0."""
    cells = dx if math.isfinite(dx) else 0.0
    return Thresholds(
        enter=max(enter_cells * cells, enter_d1 * d1),
        release=max(release_cells * cells, release_d1 * d1),
        dx=dx,
        d1=d1,
        rule=rule,
    )


def classify(dr: np.ndarray, enter: float, release: float) -> tuple[list[tuple[int, int]], bool]:
    """Kissing episodes of the gap series `dr` as (first sample, end sample) index pairs, and
    whether the last one is still open at the end of the series. An episode starts at the
    first sample with dr <= enter while not in an episode and ends at the first later sample
    with dr > release; an open episode ends at the last sample."""
    episodes: list[tuple[int, int]] = []
    start = -1
    for i, gap in enumerate(np.asarray(dr, dtype=float)):
        if start < 0:
            if gap <= enter:
                start = i
        elif gap > release:
            episodes.append((start, i))
            start = -1
    is_open = start >= 0
    if is_open:
        episodes.append((start, len(dr) - 1))
    return episodes, is_open


def _classify(run: Run, t: np.ndarray, dr: np.ndarray, enter: float,
              release: float) -> tuple[list[tuple[int, int]], bool]:
    """classify(dr) up to the first gap that is not a number (the run's positions went NaN:
    what follows says nothing of the pair), with a warning on stderr naming the file and the
    time; an open episode then ends at the last finite sample."""
    bad = np.flatnonzero(~np.isfinite(np.asarray(dr, dtype=float)))
    if bad.size == 0:
        return classify(dr, enter, release)
    k = int(bad[0])
    print(f"warning: {run.path}: the gap D_r is not a number from t = {float(t[k]):.6g} s on "
          f"(sample {k}: NaN positions); the pattern is classified from the {k} samples "
          "before it", file=sys.stderr)
    return classify(dr[:k], enter, release)


def pattern_name(n_episodes: int) -> str:
    return "repeated" if n_episodes >= 2 else "once" if n_episodes == 1 else "never"


@dataclass
class Episode:
    start: float  # s
    end: float  # s
    min_gap: float  # cm, smallest D_r from start to end
    open: bool  # the run ended inside it


@dataclass
class Pair:
    """Particles 1 and 2 of a run: separation series (n,), per-particle Re and C_d (n, 2),
    the DKT pattern with its episodes, and how it was obtained (`source`)."""

    run: Run
    t: np.ndarray
    dx: np.ndarray
    dy: np.ndarray
    dr: np.ndarray
    re: np.ndarray
    cd: np.ndarray
    d1: float
    gamma: float
    dh: float
    limits: Thresholds
    pattern: str
    episodes: list[Episode] = field(default_factory=list)
    source: str = "computed from /particles"

    @property
    def tstar(self) -> np.ndarray:
        return self.t / self.run.t_ref

    @property
    def dr_star(self) -> np.ndarray:
        return self.dr / self.d1

    @property
    def open_episode(self) -> bool:
        return bool(self.episodes) and self.episodes[-1].open


def reynolds_and_drag(run: Run) -> tuple[np.ndarray, np.ndarray]:
    """Re_a = rho_f |U| D_p / mu and C_d = F_y / (rho_f U_p^2 D_p / 2) (docs/model.md E12, U_p =
    |U|, NaN while U_p = 0), each (n, count), from /particles."""
    speed = np.hypot(run.series["u"], run.series["v"])
    dp = run.diameters[None, :]
    re = run.rho_f * speed * dp / run.mu
    dyn = 0.5 * run.rho_f * speed**2 * dp
    with np.errstate(divide="ignore", invalid="ignore"):
        cd = np.where(dyn > 0, run.series["fy"] / np.where(dyn > 0, dyn, 1.0), np.nan)
    return re, cd


def _episodes(t: np.ndarray, dr: np.ndarray, index_pairs: list[tuple[int, int]],
              is_open: bool) -> list[Episode]:
    out = []
    for k, (i0, i1) in enumerate(index_pairs):
        last = is_open and k == len(index_pairs) - 1
        out.append(Episode(float(t[i0]), float(t[i1]), float(np.min(dr[i0:i1 + 1])), last))
    return out


def run_until(run: Run, t_end: float) -> Run:
    """`run` as if it had finished at `t_end` (s): its samples up to that run's last step
    (t_end over the time step, rounded as the program rounds it), /diagnostics with them, and
    the kissing episodes that start by the last of them, one still going there left open. A
    run to `t_end` writes these samples, and one more: the closing sample at its last step,
    when that is off the sampling interval."""
    steps = math.floor(t_end / run.dt + 0.5)  # as the program counts them (nint)
    edge = (steps + 0.5) * run.dt
    n = int(run.t.searchsorted(edge, side="right"))
    diag = run.diagnostics
    if diag is not None and "t" in diag:
        t = diag["t"].ravel()
        m = int(t.searchsorted(edge, side="right"))
        cut = {k: v[:m] if isinstance(v, np.ndarray) and v.shape[:1] == t.shape else v
               for k, v in diag.items()}
        last = float(t[m - 1]) if m else -math.inf
        starts = np.asarray(diag.get("episodes_start", np.zeros(0)), dtype=float)
        ends = np.asarray(diag.get("episodes_end", np.zeros(0)), dtype=float)
        keep = starts <= last
        a = diag["attrs"]
        was_open = bool(_num_or(a, "open_episode", 0.0))
        # open at the cut: ending after it, or the run's open episode with none cut away
        still = bool(keep.any() and (ends[keep][-1] > last or (keep.all() and was_open)))
        cut["episodes_start"] = starts[keep]
        cut["episodes_end"] = np.minimum(ends[keep], last)
        cut["attrs"] = {**a, "pattern": pattern_name(int(keep.sum())),
                        "episodes": int(keep.sum()), "open_episode": int(still)}
        diag = cut
    return replace(run, t=run.t[:n], series={k: v[:n] for k, v in run.series.items()},
                   window_offset=None if run.window_offset is None else run.window_offset[:n],
                   steps=steps, stop_reason="finished", diagnostics=diag)


def pair_of(run: Run, limits: dict[str, float] | None = None,
            from_particles: bool = False) -> Pair:
    """The pair (particles 1 and 2) of `run`. With /diagnostics its series, thresholds,
    pattern and episodes are taken as written, unless `limits` (any of enter_cells, enter_d1,
    release_cells, release_d1) is given: then the gap is classified here with those values
    (the run's own settings for the others). `from_particles` ignores /diagnostics: everything
    is computed from /particles (to check one against the other)."""
    if run.count < 2:
        raise RunFileError(run.path, f"the run has {run.count} particle; a pair needs 2")
    diag = run.diagnostics
    try:
        if not from_particles and diag is not None and all(k in diag for k in ("t", "dr")):
            return _pair_from_diagnostics(run, diag, limits)
        return _pair_from_particles(run, limits)
    except NotANumber as exc:
        # the attributes were read with the file open; the file is named here
        raise RunFileError(run.path, str(exc)) from None


def _limits(run: Run, d1: float, limits: dict[str, float] | None,
            attrs: dict[str, Any] | None = None) -> Thresholds:
    """The thresholds the run used, with `limits` (given by the user) taking precedence: the
    /run attributes kiss_enter_cells, kiss_release_cells, kiss_enter_d1, kiss_release_d1 that
    a pair's run file stores (enter_cells as it acted), else the /diagnostics attributes
    `attrs` for the two in spacings; what the file does not give, _from_settings."""
    values = {k: run.run_attrs[f"kiss_{k}"] for k in LIMIT_KEYS if f"kiss_{k}" in run.run_attrs}
    for key in ("enter_cells", "release_cells"):
        if key not in values and attrs and f"kiss_{key}" in attrs:
            values[key] = _num(attrs[f"kiss_{key}"], f"kiss_{key}")
    given = {k: v for k, v in (limits or {}).items() if v is not None}
    values.update(given)
    if len(values) < len(LIMIT_KEYS) or values["enter_cells"] <= 0:
        values = _from_settings(run, values)
    rule = "given on the command line" if given else "the run's settings"
    return thresholds(run.dx, d1, rule=rule, **values)


def _from_settings(run: Run, values: dict[str, float]) -> dict[str, float]:
    """The one fallback for thresholds a run file does not store (files written before
    dktlbm 0.1.0, scenes without a pair) and for an enter_cells of 0 given by the user:
    `values` completed from &diagnostics of the run's settings (its stored namelist, else
    dktlbm's defaults), and enter_cells = 0, the program's rule on collision.range, resolved
    as `dktlbm --check` reports it (kiss_cells). Either may run the executable."""
    out = {k: values[k] if k in values else run.settings.number("diagnostics", k)
           for k in LIMIT_KEYS}
    if out["enter_cells"] <= 0:
        out["enter_cells"], out["release_cells"] = kiss_cells(
            out["enter_cells"], out["release_cells"], run.settings.number("collision", "range"))
    return out


def _pair_from_particles(run: Run, limits: dict[str, float] | None) -> Pair:
    s = run.series
    d = run.diameters[:2]
    if not np.all(np.isfinite(d)):
        raise RunFileError(run.path, "the particle diameters are unknown")
    dx = s["x"][:, 0] - s["x"][:, 1]
    dy = s["y"][:, 0] - s["y"][:, 1]
    dr = np.hypot(dx, dy) - 0.5 * (d[0] + d[1])
    d1 = float(max(d[0], d[1]))
    gamma = float(max(d[0], d[1]) / min(d[0], d[1]))
    dh = float(abs(dy[0]) / d1)
    lim = _limits(run, d1, limits)
    pairs, is_open = _classify(run, run.t, dr, lim.enter, lim.release)
    re, cd = reynolds_and_drag(run)
    return Pair(run, run.t, dx, dy, dr, re[:, :2], cd[:, :2], d1, gamma, dh, lim,
                pattern_name(len(pairs)), _episodes(run.t, dr, pairs, is_open))


def _pair_from_diagnostics(run: Run, diag: dict[str, Any],
                           limits: dict[str, float] | None) -> Pair:
    a = diag["attrs"]
    t = diag["t"].ravel()
    dr = diag["dr"].ravel()
    d1 = _num(a["d1"], "d1") if "d1" in a else float(np.nanmax(run.diameters[:2]))
    gamma = _num(a["gamma"], "gamma") if "gamma" in a else float(
        np.nanmax(run.diameters[:2]) / np.nanmin(run.diameters[:2]))
    dx = diag["dx"].ravel() if "dx" in diag else np.full_like(t, math.nan)
    dy = diag["dy"].ravel() if "dy" in diag else np.full_like(t, math.nan)
    dh = _num(a["dh"], "dh") if "dh" in a else float(abs(dy[0]) / d1)
    re_p, cd_p = reynolds_and_drag(run)
    same_t = run.t.size == t.size
    re = diag["re"] if "re" in diag else (re_p[:, :2] if same_t else np.full((t.size, 2), np.nan))
    cd = diag["cd"] if "cd" in diag else (cd_p[:, :2] if same_t else np.full((t.size, 2), np.nan))
    if limits and any(v is not None for v in limits.values()):
        lim = _limits(run, d1, limits, a)
        pairs, is_open = _classify(run, t, dr, lim.enter, lim.release)
        episodes = _episodes(t, dr, pairs, is_open)
        pattern = pattern_name(len(pairs))
        source = "computed from /diagnostics/dr with the given thresholds"
    else:
        stored = run.run_attrs
        enter = _num_or(a, "kiss_enter", stored.get("kiss_enter", math.nan))
        release = _num_or(a, "kiss_release", stored.get("kiss_release", math.nan))
        if not (math.isfinite(enter) and math.isfinite(release)):
            lim = _limits(run, d1, None, a)
        else:
            lim = Thresholds(enter, release, run.dx, d1, rule="as written in /diagnostics")
        pattern = text_attr(a.get("pattern", ""))
        if (pattern not in PATTERNS or run.stop_reason == "running"
                or not np.all(np.isfinite(dr))):
            # an unfinished file: classify what there is, up to the first gap that is not a
            # number. The program writes the pattern when it closes the file, whatever stopped
            # it; in a file still 'running' it can only be the one of the finished run that a
            # killed restart extended (files of earlier versions), which is not this run's
            pairs, is_open = _classify(run, t, dr, lim.enter, lim.release)
            pattern = pattern_name(len(pairs))
            episodes = _episodes(t, dr, pairs, is_open)
            source = ("computed from /diagnostics/dr (no pattern attribute, or the run is "
                      "not finished)")
        else:
            starts = diag.get("episodes_start", np.zeros(0))
            ends = diag.get("episodes_end", np.zeros(0))
            is_open = bool(_num_or(a, "open_episode", 0.0))
            stored_gaps = diag.get("episodes_gap_min")
            episodes = []
            for k, (t0, t1) in enumerate(zip(starts, ends, strict=False)):
                if stored_gaps is not None and k < len(stored_gaps):
                    # as the program found it, step by step (the samples may miss the least)
                    gap = float(stored_gaps[k])
                else:
                    inside = (t >= t0) & (t <= t1)
                    gap = float(np.min(dr[inside])) if np.any(inside) else math.nan
                episodes.append(Episode(float(t0), float(t1), gap,
                                        is_open and k == len(starts) - 1))
            source = "as written in /diagnostics"
    return Pair(run, t, dx, dy, dr, np.asarray(re), np.asarray(cd), d1, gamma, dh, lim,
                pattern, episodes, source)


# ---------------------------------------------------------------- run status (sweeps)


#: a run file, log or CSV written to within this many seconds counts as a live run's
#: (a run on another machine, which /proc does not show); the series are flushed at least
#: this often while a run writes (a checkpoint, a field or a full sample buffer)
RUNNING_QUIET = 120.0
PAUSED = ("signal", "wall_limit")  # stop reasons after which a checkpoint resumes the run


def held_open(path: str | Path) -> bool:
    """Whether a process on this machine has `path` open (Linux /proc; False elsewhere)."""
    target = str(Path(path).resolve())
    for fd_dir in Path("/proc").glob("[0-9]*/fd"):
        if fd_dir.parent.name == str(os.getpid()):  # this process's own handles are its own
            continue
        try:
            for fd in fd_dir.iterdir():
                if str(fd.readlink()) == target:
                    return True
        except OSError:  # another user's process, or one that just ended
            continue
    return False


def _recently_written(p: Path) -> bool:
    """Whether the run file `p`, its log or its CSV changed in the last RUNNING_QUIET s."""
    now = time.time()
    for f in (p, p.with_suffix(".log"), p.with_name(p.stem + "_diagnostics.csv")):
        try:
            if now - f.stat().st_mtime < RUNNING_QUIET:
                return True
        except OSError:
            continue
    return False


def run_status(path: str | Path) -> str:
    """The state of the run file `path`:

    - 'missing': no file;
    - 'finished': /run stop_reason 'finished' or 'window_escape' (older files without it:
      /diagnostics has its `pattern` attribute, or /particles reaches the run's last step);
    - 'running': a live run is writing it: a process on this machine has it open, or its
      stop_reason is 'running' and the file, its log or its CSV changed within the last
      RUNNING_QUIET s (a run on another machine). Never start or overwrite it;
    - 'paused': stop_reason 'signal' or 'wall_limit': stopped cleanly with a checkpoint
      (<name>.checkpoint names it), to be resumed with --restart;
    - 'failed': anything else: stopped by a guard, an error or a particle stop, killed
      (stop_reason 'running' and quiet), or unreadable."""
    p = Path(path)
    if not p.is_file():
        return "missing"
    if held_open(p):  # read nothing a live run is writing
        return "running"
    try:
        with open_h5(p) as h5:
            reason = stop_reason(h5)
            if reason:
                if reason in ("finished", "window_escape"):
                    return "finished"
                if reason in PAUSED:
                    return "paused"
                return "running" if reason == "running" and _recently_written(p) else "failed"
            if "diagnostics" in h5:
                return "finished" if "pattern" in h5["diagnostics"].attrs else "failed"
            if "particles" not in h5 or "run" not in h5:
                return "failed"
            a = h5["run"].attrs
            if "steps" not in a or "dt" not in a:
                return "failed"
            t = np.asarray(h5["particles"]["t"][()], dtype=float)
            end = _num(a["steps"], "steps") * _num(a["dt"], "dt")
            done = t.size > 0 and t[-1] >= end - 0.5 * _num(a["dt"], "dt")
            return "finished" if done else "failed"
    except (RunFileError, OSError, KeyError, ValueError):
        return "failed"


# ---------------------------------------------------------------- fields


@dataclass
class Snapshot:
    """One stored field: data (ny, nx); node (i, j) at x = (i + 1/2) dx, y = (j + 1/2) dx +
    offset. `solid` marks nodes inside a particle (None when the file has no such mask)."""

    name: str
    group: str
    time: float
    step: int
    offset: float
    dx: float
    data: np.ndarray
    solid: np.ndarray | None

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(x0, x1, y0, y1), cm: the cells' outer edges."""
        ny, nx = self.data.shape
        return (0.0, nx * self.dx, self.offset, self.offset + ny * self.dx)


def field_times(path: str | Path) -> list[tuple[str, float]]:
    """(group name, time in s) of each stored field snapshot, in time order."""
    with open_h5(path) as h5:
        return _field_times(Path(path), h5)


def _field_times(path: Path, h5: Any) -> list[tuple[str, float]]:
    if "fields" not in h5:
        what = "no /fields group" if "run" in h5 else "not a dktlbm run file (no /run group)"
        raise RunFileError(path, what)
    out = []
    for name, g in h5["fields"].items():
        if "time" in g.attrs:
            out.append((name, _num(g.attrs["time"], "time")))
    if not out:
        raise RunFileError(path, "/fields holds no snapshots")
    return sorted(out, key=lambda item: item[1])


def read_field(path: str | Path, name: str = "vorticity", time: float | None = None) -> Snapshot:
    """Field `name` (one of FIELD_NAMES; 'speed' = |u|) of the snapshot nearest to `time`
    (s; None = the last one)."""
    if name not in FIELD_NAMES:
        raise ValueError(f"unknown field {name!r}; choose from {', '.join(FIELD_NAMES)}")
    with open_h5(path) as h5:
        if "run" not in h5 and "particles" not in h5:
            raise RunFileError(path, "not a dktlbm run file (no /run or /particles group)")
        times = _field_times(Path(path), h5)
        if time is None:
            group, t = times[-1]
        else:
            group, t = min(times, key=lambda item: abs(item[1] - time))
        g = h5["fields"][group]
        try:
            if name == "speed":
                data = np.hypot(g["ux"][()], g["uy"][()])
            else:
                data = np.asarray(g[name][()], dtype=float)
            solid = np.asarray(g["particle"][()]) > 0 if "particle" in g else None
            dx = _num(h5["run"].attrs["dx"], "dx")
        except KeyError as exc:
            raise RunFileError(path, f"/fields/{group} lacks {exc}") from None
        if not (math.isfinite(dx) and dx > 0):
            raise RunFileError(path, f"attribute dx = {dx!r} is not a lattice spacing (a "
                               "damaged or foreign run file?)")
        step = int(_num(g.attrs["step"], "step")) if "step" in g.attrs else -1
        offset = _num_or(g.attrs, "window_offset", 0.0)
    return Snapshot(name, group, t, step, offset, dx, np.asarray(data, dtype=float), solid)


# ---------------------------------------------------------------- command-line helpers


def add_version(parser: argparse.ArgumentParser) -> None:
    """--version on a dkt-* command: its name and the package's version."""
    from . import __version__

    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")


def add_output_options(parser: argparse.ArgumentParser, suffix: str) -> None:
    parser.add_argument(
        "-o", "--output", type=Path, metavar="OUT.png",
        help=f"the PNG to write (default: beside the (first) run file, <name>_{suffix}.png)")
    parser.add_argument("--pdf", action="store_true",
                        help="also write a PDF beside the PNG (same name, .pdf)")


def output_path(run_file: str | Path, suffix: str, given: Path | None) -> Path:
    """The PNG path: `given` (with .png added when it has another ending), else
    <run file dir>/<run file stem>_<suffix>.png."""
    if given is not None:
        return given if given.suffix.lower() == ".png" else given.with_name(given.name + ".png")
    p = Path(run_file)
    return p.with_name(f"{p.stem}_{suffix}.png")


def save_figure(fig: Any, png: Path, pdf: bool) -> list[Path]:
    """Write `fig` to `png` (and the PDF beside it); print and return the paths."""
    png.parent.mkdir(parents=True, exist_ok=True)
    written = [png]
    fig.savefig(png, dpi=150)
    if pdf:
        written.append(png.with_suffix(".pdf"))
        fig.savefig(written[-1])
    for p in written:
        print(f"wrote {p}")
    return written


def guarded(body: Callable[[], int]) -> int:
    """Run `body`; a RunFileError, a missing executable (LaunchError), a stored value that is not
    a number (NotANumber) or an unwritable output becomes `error: ...` on stderr and exit
    status 2, without a traceback. A reader that stopped reading (`dkt-pattern run.h5 | head
    -1`) ends the command quietly, status 0."""
    try:
        try:
            return body()
        finally:
            sys.stdout.flush()
    except BrokenPipeError:
        # the rest of the output goes nowhere, as the shell's own commands do; the interpreter's
        # final flush must not fail on the closed pipe either
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except (RunFileError, LaunchError, NotANumber) as exc:
        print(f"error: {exc}", file=sys.stderr)
    except OSError as exc:
        where = exc.filename if exc.filename else "output"
        print(f"error: {where}: {exc.strerror or exc}", file=sys.stderr)
    return 2


def fmt(value: float, digits: int = 4) -> str:
    return "nan" if not math.isfinite(value) else f"{value:.{digits}g}"


def unique_names(paths: Sequence[str | Path]) -> list[str]:
    """Short names of run files: the stem, or parent/stem when stems repeat (sweep runs)."""
    stems = [Path(p).stem for p in paths]
    if len(set(stems)) == len(stems):
        return stems
    return [f"{Path(p).parent.name}/{Path(p).stem}" for p in paths]
