"""The post-processing package (postproc/dktlbm): the run-file reader, the DKT classifier,
dkt-pattern, the plotting commands' command lines and their handling of bad input, on
synthetic run files whose gap curves cross the thresholds at known times
(tests/postproc/synthetic.py) and on two small real runs; and the old script paths beside the
package. Each test's docstring says what it proves."""

from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
import synthetic as syn

from dkt_run import ROOT, run
from dktlbm import gap, pattern, read

POSTPROC = ROOT / "postproc"
PLOTS = {"gap": "gap", "trajectories": "trajectories", "drag": "drag", "field": "vorticity"}
SCRIPTS = [*PLOTS, "pattern"]


def script(name: str, *args: str | Path, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """Run the command dkt-<name> as `python3 -m dktlbm.<name>`: a separate process."""
    env = {**os.environ, "MPLBACKEND": "Agg"}
    return subprocess.run([sys.executable, "-m", f"dktlbm.{name}", *map(str, args)],
                          capture_output=True, text=True, timeout=120, env=env, cwd=cwd)


def assert_png(path: Path) -> None:
    assert path.is_file(), f"{path} missing"
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 2000, f"{path} is not a PNG image"


def assert_pdf(path: Path) -> None:
    assert path.is_file(), f"{path} missing"
    data = path.read_bytes()
    assert data[:5] == b"%PDF-" and len(data) > 1000, f"{path} is not a PDF"


def expected_episodes(name: str) -> list[tuple[float, float, bool]]:
    """(start, end, open) of each episode of synthetic shape `name`: the start is the first
    sample at or after the analytic crossing of ENTER downwards, the end the first sample
    after the crossing of RELEASE upwards (the last sample for an open episode)."""
    k = syn.SHAPES[name]
    first = after = syn.first_sample_at_or_after  # no crossing falls on a sample
    if name == "repeated":
        return [(first(syn.crossing(k, 0, syn.ENTER)), after(syn.crossing(k, 2, syn.RELEASE)),
                 False),
                (first(syn.crossing(k, 3, syn.ENTER)), after(syn.crossing(k, 4, syn.RELEASE)),
                 False)]
    if name == "once":
        return [(first(syn.crossing(k, 0, syn.ENTER)), after(syn.crossing(k, 3, syn.RELEASE)),
                 False)]
    if name == "open":
        return [(first(syn.crossing(k, 0, syn.ENTER)), syn.T_END, True)]
    return []


# ---------------------------------------------------------------- reader and classifier


def test_namelist_parser_reads_the_input_grammar() -> None:
    """parse_namelist follows input/README.md: groups, several items on a line, arrays, one
    element by index, quoted strings with '!' and doubled quotes, comments, &end."""
    text = """! comment
&Domain
  width = 2.5, height = 8.0   ! cm
  sides = 'wall'
/
&particles
  diameter = 0.2, 0.1
  diameter(2) = 0.05
  motion = 'free', 'it''s!'
/
&run t_end = 1d-1 &end
"""
    nml = read.parse_namelist(text)
    assert read.nml_float(nml, "domain", "width", 0.0) == 2.5
    assert read.nml_float(nml, "domain", "height", 0.0) == 8.0
    assert nml["domain"]["sides"] == ["wall"]
    assert read.nml_floats(nml, "particles", "diameter") == [0.2, 0.05]
    assert nml["particles"]["motion"] == ["free", "it's!"]
    assert read.nml_float(nml, "run", "t_end", 0.0) == pytest.approx(0.1)
    assert read.nml_float(nml, "fluid", "density", 1.0) == 1.0  # absent: the default


def test_classifier_follows_the_episode_definition() -> None:
    """An episode starts at the first sample with D_r <= enter (equality included) and ends at
    the first later sample with D_r > release (equality does not end it); a rise above enter
    but not above release keeps the episode; an episode still open ends at the last sample."""
    enter, release = 0.02, 0.05
    dr = np.array([0.3, 0.02, 0.05, 0.04, 0.0500001, 0.2, 0.01, 0.3, 0.019, 0.03])
    episodes, is_open = read.classify(dr, enter, release)
    assert episodes == [(1, 4), (6, 7), (8, 9)]
    assert is_open
    assert read.classify(np.array([0.3, 0.021, 0.3]), enter, release) == ([], False)
    assert [read.pattern_name(n) for n in (0, 1, 2, 5)] == ["never", "once", "repeated",
                                                               "repeated"]


def test_thresholds_take_the_larger_of_spacings_and_d1_fraction() -> None:
    """enter = max(2 dx, 0.05 D_1), release = max(4 dx, 0.25 D_1) for those settings: on a
    coarse lattice the spacings decide, on a fine one the fractions of D_1."""
    limits = {"enter_cells": 2.0, "enter_d1": 0.05, "release_cells": 4.0, "release_d1": 0.25}
    coarse = read.thresholds(0.025, 0.2, **limits)
    assert (coarse.enter, coarse.release) == pytest.approx((0.05, 0.1))
    fine = read.thresholds(0.001, 0.2, **limits)
    assert (fine.enter, fine.release) == pytest.approx((0.01, 0.05))
    assert coarse.enter_cells == pytest.approx(2.0) and fine.release_d1 == pytest.approx(0.25)


@pytest.mark.parametrize("shape", list(syn.SHAPES))
def test_pattern_computed_from_particles_matches_the_gap_curve(tmp_path: Path,
                                                               shape: str) -> None:
    """Without /diagnostics the reader computes D_x, D_y, D_r from /particles and classifies:
    the pattern, each episode's start and end (to the sample after the analytic crossing),
    the open flag and the smallest gap are those of the constructed gap curve; gamma and
    D_h/D_1 are those of the construction."""
    f = tmp_path / f"{shape}.h5"
    s = syn.write_run(f, syn.SHAPES[shape], (0.2, 0.1))
    pair = read.pair_of(read.open_run(f, need_particles=2))
    assert pair.source.startswith("computed")
    np.testing.assert_allclose(pair.dr, s["dr"], atol=1e-12)
    np.testing.assert_allclose(pair.dx, s["dx"], atol=1e-12)
    assert pair.gamma == pytest.approx(2.0)
    assert pair.dh == pytest.approx((0.4 + 0.15) / 0.2)  # first knot gap + R_1 + R_2, over D_1
    assert (pair.limits.enter, pair.limits.release) == pytest.approx((syn.ENTER, syn.RELEASE))
    expected = expected_episodes(shape)
    assert pair.pattern == {0: "never", 1: "once"}.get(len(expected), "repeated")
    assert len(pair.episodes) == len(expected)
    for got, (start, end, is_open) in zip(pair.episodes, expected, strict=True):
        assert got.start == pytest.approx(start, abs=1e-9)
        assert got.end == pytest.approx(end, abs=1e-9)
        assert got.open == is_open
        knots_inside = [d for t, d in syn.SHAPES[shape] if start <= t <= end]
        assert got.min_gap == pytest.approx(min(knots_inside), abs=1e-9)
    assert pair.open_episode == (shape == "open")


def test_scales_come_from_diagnostics_else_the_namelist(tmp_path: Path) -> None:
    """W, t_ref and g for the normalisation: from the namelist in /run when the file has no
    /diagnostics (here W = 2.5 cm, t_ref = 0.2 s, g = 981, so H = g t_ref^2 as the program
    defines it), from the /diagnostics attributes when it has them (which take precedence)."""
    plain = tmp_path / "plain.h5"
    syn.write_run(plain, syn.SHAPES["never"], width=2.5, t_ref=0.2, gravity=981.0,
                  fields=False)
    r = read.open_run(plain)
    h_ref = 981.0 * 0.2**2
    assert (r.width, r.t_ref, r.gravity, r.h_ref) == pytest.approx((2.5, 0.2, 981.0, h_ref))
    assert r.velocity_scale == pytest.approx(math.sqrt(h_ref * 981.0))
    diag = tmp_path / "diag.h5"
    syn.write_run(diag, syn.SHAPES["never"], width=2.5, t_ref=0.2, gravity=981.0,
                  fields=False, diagnostics={"attrs": {
                      "pattern": "never", "episodes": 0, "open_episode": 0, "width": 3.0,
                      "t_ref": 0.15, "gravity": 970.0, "h_ref": 17.5}})
    r = read.open_run(diag)
    assert (r.width, r.t_ref, r.gravity, r.h_ref) == pytest.approx((3.0, 0.15, 970.0, 17.5))


def test_run_attributes_are_read_and_an_early_stop_is_reported(tmp_path: Path) -> None:
    """Files since the program stores its scales and thresholds in /run: the reader takes them
    from there (values here differ from the namelist and the defaults, so a reader that
    recomputes them fails), and reports a run that stopped early: run_status 'paused' (a
    signal) or 'failed' (killed: 'running' but quiet) even though its series look complete, a
    warning with the reason, and pattern.py's 'incomplete:' line (JSON stop_reason,
    complete); 'finished' is reported as finished."""
    f = tmp_path / "stored.h5"
    syn.write_run(f, syn.SHAPES["repeated"], (0.2, 0.1), t_ref=0.2, fields=False)

    def store(reason: str) -> None:
        with h5py.File(f, "r+") as h5:
            a = h5["run"].attrs
            for key, value in (("t_ref", 0.3), ("rho_f", 1.2), ("mu", 0.02),
                               ("diameter_1", 0.2), ("diameter_2", 0.1),
                               ("kiss_enter_cells", 3.0), ("kiss_enter_d1", 0.05),
                               ("kiss_release_cells", 6.0), ("kiss_release_d1", 0.25)):
                a[key] = float(value)
            a["stop_reason"] = np.bytes_(reason.encode())

    store("finished")
    r = read.open_run(f)
    assert (r.t_ref, r.rho_f, r.mu) == pytest.approx((0.3, 1.2, 0.02))
    lim = read.pair_of(r).limits
    assert (lim.enter, lim.release) == pytest.approx((3.0 * syn.DX, 6.0 * syn.DX))
    assert r.complete and r.stop_note() is None
    assert read.run_status(f) == "finished"

    for reason, says, status in (("signal", "stopped: signal", "paused"),
                                 ("running", "killed or is still running", "failed")):
        store(reason)
        # written long ago: a 'running' file nobody writes any more is a killed run
        old = f.stat().st_mtime - 2 * read.RUNNING_QUIET
        os.utime(f, (old, old))
        assert read.run_status(f) == status
        proc = script("pattern", f)
        assert proc.returncode == 0, proc.stderr
        assert f"incomplete: the run stopped early ({reason})" in proc.stdout
        assert "warning:" in proc.stderr and "ended early" in proc.stderr, proc.stderr
        assert says in proc.stderr, proc.stderr
        r = json.loads(script("pattern", f, "--json").stdout)
        assert r["stop_reason"] == reason and r["complete"] is False


# ---------------------------------------------------------------- pattern.py


def test_pattern_cli_text_and_json(tmp_path: Path) -> None:
    """pattern.py prints the pattern, the episodes (s and t*) with their smallest gaps, the
    thresholds, gamma and D_h/D_1; --json gives the same as data. Exit status 0."""
    f = tmp_path / "rep.h5"
    syn.write_run(f, syn.SHAPES["repeated"], (0.2, 0.1))
    proc = script("pattern", f)
    assert proc.returncode == 0, proc.stderr
    assert "pattern repeated (2 kissing episodes" in proc.stdout
    assert "episode 1:" in proc.stdout and "episode 2:" in proc.stdout
    assert "D_r <= 0.02 cm" in proc.stdout and "D_r > 0.05 cm" in proc.stdout
    assert "gamma = D_1/D_2 = 2" in proc.stdout

    proc = script("pattern", f, "--json")
    assert proc.returncode == 0, proc.stderr
    r = json.loads(proc.stdout)
    assert r["pattern"] == "repeated" and r["episodes"] == 2 and not r["open_episode"]
    assert r["gamma"] == pytest.approx(2.0) and r["dh"] == pytest.approx(2.75)
    th = r["thresholds"]
    assert th["enter_cm"] == pytest.approx(syn.ENTER)
    assert th["release_cm"] == pytest.approx(syn.RELEASE)
    assert th["enter_cells"] == pytest.approx(2.0) and th["release_d1"] == pytest.approx(0.25)
    for got, (start, end, _) in zip(r["kissing"], expected_episodes("repeated"), strict=True):
        assert got["start"] == pytest.approx(start, abs=1e-9)
        assert got["end"] == pytest.approx(end, abs=1e-9)
        assert got["start_tstar"] == pytest.approx(start / 0.135526)
        assert got["min_gap"] == pytest.approx(0.005, abs=1e-9)
        assert got["min_gap_d1"] == pytest.approx(0.005 / 0.2, abs=1e-8)


def test_pattern_terminal_reynolds_numbers(tmp_path: Path) -> None:
    """--terminal T*: each particle's Re = rho_f |U| D_p / mu averaged over t* >= T*, with its
    range there, equal to the same average computed here from the file's velocities (the two
    disks' values differ: D = 0.2 and 0.1 cm); a T* after the run's end is refused (exit 2,
    naming the option)."""
    f = tmp_path / "rep.h5"
    series = syn.write_run(f, syn.SHAPES["repeated"], (0.2, 0.1), rho=1.0, mu=0.01)
    t_ref = 0.135526
    start = 0.5 * syn.T_END / t_ref
    proc = script("pattern", f, "--json", "--terminal", f"{start}")
    assert proc.returncode == 0, proc.stderr
    got = json.loads(proc.stdout)["terminal"]
    keep = syn.T / t_ref >= start
    speed = np.hypot(series["u"], series["v"])[keep]
    for k, d in enumerate((0.2, 0.1)):
        re = 1.0 * speed[:, k] * d / 0.01
        assert got["re_mean"][k] == pytest.approx(re.mean(), rel=1e-12)
        assert (got["re_min"][k], got["re_max"][k]) == pytest.approx((re.min(), re.max()))
    assert got["samples"] == int(keep.sum()) and got["re_mean"][0] != got["re_mean"][1]
    text = script("pattern", f, "--terminal", f"{start}").stdout
    assert "terminal Reynolds numbers" in text and "particle 2 (D = 0.1 cm): Re = " in text
    late = script("pattern", f, "--terminal", f"{2 * syn.T_END / t_ref}")
    assert late.returncode == 2 and "--terminal" in late.stderr


def test_pattern_uses_diagnostics_as_written_unless_thresholds_are_given(tmp_path: Path) -> None:
    """A file with /diagnostics is reported as written: here the program's thresholds were
    0.03/0.3 cm, under which the two-dip gap is one episode ('once'), and that is what
    pattern.py reports, not a reclassification with the defaults. Thresholds on the command
    line classify again: the defaults give 'repeated'; --release-d1 1.5 alone (release 0.3 cm,
    enter keeping its default) gives 'once' again. An episode's smallest gap is the program's
    (/diagnostics/episodes gap_min, over every step) where the file has it, else the least
    sample."""
    k = syn.SHAPES["repeated"]
    start = syn.first_sample_at_or_after(syn.crossing(k, 0, 0.03))
    end = syn.first_sample_at_or_after(syn.crossing(k, 5, 0.3))
    f = tmp_path / "diag.h5"
    syn.write_run(f, k, diagnostics={
        "attrs": {"pattern": "once", "episodes": 1, "open_episode": 0, "kiss_enter": 0.03,
                  "kiss_release": 0.3},
        "episodes": [(start, end)]})
    r = json.loads(script("pattern", f, "--json").stdout)
    assert r["pattern"] == "once" and r["episodes"] == 1
    assert r["thresholds"]["enter_cm"] == pytest.approx(0.03)
    assert r["thresholds"]["release_cm"] == pytest.approx(0.3)
    assert r["kissing"][0]["start"] == pytest.approx(start)
    assert r["kissing"][0]["end"] == pytest.approx(end)
    assert r["source"] == "as written in /diagnostics"
    # without the program's smallest gap of the episode, the least sample
    sampled = r["kissing"][0]["min_gap"]
    with h5py.File(f, "r") as h5:
        t, dr = h5["diagnostics/t"][()], h5["diagnostics/dr"][()]
    assert sampled == pytest.approx(float(np.min(dr[(t >= start) & (t <= end)])))
    # with it (the program's, over every step: below every sample), that one
    with h5py.File(f, "a") as h5:
        h5["diagnostics/episodes"]["gap_min"] = np.array([0.75 * sampled])
    r = json.loads(script("pattern", f, "--json").stdout)
    assert r["kissing"][0]["min_gap"] == 0.75 * sampled

    r = json.loads(script("pattern", f, "--json", "--enter-cells", "2",
                          "--release-cells", "4").stdout)
    assert r["pattern"] == "repeated" and r["episodes"] == 2
    assert r["thresholds"]["enter_cm"] == pytest.approx(syn.ENTER)
    assert r["thresholds"]["rule"] == "given on the command line"

    r = json.loads(script("pattern", f, "--json", "--release-d1", "1.5").stdout)
    assert r["pattern"] == "once"
    assert r["thresholds"]["enter_cm"] == pytest.approx(syn.ENTER)
    assert r["thresholds"]["release_cm"] == pytest.approx(0.3)


def test_main_is_importable(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Each script can be used from Python: main(argv) returns the exit status."""
    f = tmp_path / "open.h5"
    syn.write_run(f, syn.SHAPES["open"])
    assert pattern.main([str(f), "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["pattern"] == "once" and r["open_episode"] and r["kissing"][0]["open"]
    assert r["kissing"][0]["end"] == pytest.approx(syn.T_END)
    assert gap.main([str(tmp_path / "missing.h5")]) == 2
    assert capsys.readouterr().err.startswith("error: ")


# ---------------------------------------------------------------- plotting scripts


@pytest.mark.parametrize("name", list(PLOTS))
def test_plot_script_writes_png_and_pdf(tmp_path: Path, name: str) -> None:
    """Each plotting script, run from the command line on a synthetic windowed run, writes the
    PNG given by -o and, with --pdf, a PDF beside it."""
    f = tmp_path / "run.h5"
    syn.write_run(f, syn.SHAPES["repeated"], (0.2, 0.1))
    out = tmp_path / "plots" / f"{name}.png"
    proc = script(name, f, "-o", out, "--pdf")
    assert proc.returncode == 0, proc.stderr
    assert_png(out)
    assert_pdf(out.with_suffix(".pdf"))


@pytest.mark.parametrize("name", list(PLOTS))
def test_plot_script_default_output_is_beside_the_run_file(tmp_path: Path, name: str) -> None:
    """Without -o the PNG goes beside the run file as <name>_<plot>.png, and no PDF."""
    f = tmp_path / "case9" / "case9.h5"
    syn.write_run(f, syn.SHAPES["once"])
    proc = script(name, f, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert_png(tmp_path / "case9" / f"case9_{PLOTS[name]}.png")
    assert not list((tmp_path / "case9").glob("*.pdf"))


def test_gap_overlays_runs_with_the_label_that_differs(tmp_path: Path) -> None:
    """gap.py with several runs: the automatic legend names gamma when only gamma differs,
    D_h/D_1 when only that differs, the run names when neither does; the overlay is drawn."""
    a, b, c = (tmp_path / n / "case1.h5" for n in ("a", "b", "c"))
    syn.write_run(a, syn.SHAPES["repeated"], (0.2, 0.2), fields=False)
    same_dh = [(0.0, 0.45), *syn.SHAPES["repeated"][1:]]  # D_h/D_1 = (0.45 + 0.15)/0.2 = 3
    syn.write_run(b, same_dh, (0.2, 0.1), fields=False)
    wide = [(0.0, 0.8), *syn.SHAPES["repeated"][1:]]  # D_h differs, gamma 1 as in a
    syn.write_run(c, wide, (0.2, 0.2), fields=False)
    pairs = {k: read.pair_of(read.open_run(p)) for k, p in zip("abc", (a, b, c),
                                                                      strict=True)}
    assert gap.legend_labels([pairs["a"], pairs["b"]], "auto") == ["γ = 1", "γ = 2"]
    assert gap.legend_labels([pairs["a"], pairs["c"]], "auto") == ["$D_h/D_1$ = 3",
                                                                    "$D_h/D_1$ = 5"]
    assert gap.legend_labels([pairs["a"], pairs["a"]], "auto") == ["a/case1", "a/case1"]
    assert gap.legend_labels([pairs["a"], pairs["b"]], "name") == ["a/case1", "b/case1"]
    out = tmp_path / "overlay.png"
    proc = script("gap", a, b, c, "-o", out, "--label", "gamma")
    assert proc.returncode == 0, proc.stderr
    assert_png(out)
    # the overlay has a title too: how many runs, and their patterns
    fig = gap.plot([pairs["a"], pairs["b"]], ["γ = 1", "γ = 2"])
    assert fig._suptitle is not None
    assert fig._suptitle.get_text() == "2 runs: the gap of particles 1 and 2 (patterns: repeated)"


def test_trajectories_title_says_what_h_is(tmp_path: Path) -> None:
    """The trajectories' title gives the width and the time scale t_r = sqrt(H/g) with its H
    (the reference length, 18 cm by default, not the box's height)."""
    from dktlbm import trajectories

    f = tmp_path / "t.h5"
    syn.write_run(f, syn.SHAPES["once"], (0.2, 0.1), fields=False)
    run = read.open_run(f)
    title = trajectories.plot(run)._suptitle.get_text()
    assert f"W = {run.width:g} cm" in title
    assert f"= {run.t_ref:.4g} s with H = {run.h_ref:g} cm" in title and "sqrt{H/g}" in title


@pytest.mark.parametrize("extent", [(2.0, 8.0), (2.0, 2.0), (8.0, 2.0)])
def test_field_axis_labels_lie_inside_the_figure(tmp_path: Path,
                                                 extent: tuple[float, float]) -> None:
    """dkt-field's figure of a tall box (case0_box: 2 x 8 cm), a square and a wide window,
    saved as a PNG: the x and y labels and the colour bar's label lie wholly inside the
    canvas (their window extents within the figure's bounding box, at the PNG's dpi)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from dktlbm import field

    width, height = extent
    dx = 0.05
    data = np.random.default_rng(1).normal(size=(round(height / dx), round(width / dx)))
    snap = read.Snapshot("vorticity", "000001", 0.25, 100, 0.0, dx, data, None)
    fig = field.plot(snap, [(width / 2, height / 2, 0.1)], "case0_box: vorticity at t = 0.25 s",
                     None, None, None)
    read.save_figure(fig, tmp_path / "field.png", pdf=False)  # as dkt-field saves it
    fig.set_dpi(150)  # save_figure's resolution, laid out again as in the PNG
    FigureCanvasAgg(fig).draw()
    renderer = fig.canvas.get_renderer()
    canvas = fig.bbox
    ax, bar = fig.axes[0], fig.axes[1]
    for label in (ax.yaxis.label, ax.xaxis.label, bar.yaxis.label):
        box = label.get_window_extent(renderer)
        assert label.get_text() and box.width > 0, label
        assert (box.x0 >= canvas.x0 and box.x1 <= canvas.x1 and box.y0 >= canvas.y0
                and box.y1 <= canvas.y1), (label.get_text(), box.bounds, canvas.bounds)


def test_field_snapshot_and_particles_at_the_chosen_time(tmp_path: Path) -> None:
    """field.py's data: the snapshot nearest --time (snapshots at 0, 1.5, 3 s; 1.1 s picks
    1.5 s), placed at its window offset (extent y from the offset up by ny dx), speed = |u|,
    nodes inside particles marked, and the particle circles at the /particles sample nearest
    that time with radius D/2; a --time without a snapshot of its own is said on stderr."""
    from dktlbm import field

    f = tmp_path / "w.h5"
    s = syn.write_run(f, syn.SHAPES["once"], (0.2, 0.1))
    snap = read.read_field(f, "speed", time=1.1)
    assert snap.time == pytest.approx(1.5)
    offset = 10.5 - 0.8 * 1.5
    assert snap.extent == pytest.approx((0.0, syn.WIDTH, offset, offset + syn.NY_WINDOW * syn.DX))
    with h5py.File(f) as h5:
        g = h5["fields"][snap.group]
        np.testing.assert_allclose(snap.data, np.hypot(g["ux"][()], g["uy"][()]))
        assert snap.solid is not None and np.array_equal(snap.solid, g["particle"][()] > 0)
    assert read.read_field(f, "rho").time == pytest.approx(syn.T_END)  # default: the last
    run, t_ref = field.open_particles(f)
    circles = field.circles_at(run, snap.time)
    i = int(np.argmin(np.abs(syn.T - 1.5)))
    assert np.ravel(circles) == pytest.approx([s["x"][i, 0], s["y"][i, 0], 0.1,
                                               s["x"][i, 1], s["y"][i, 1], 0.05])
    assert t_ref == pytest.approx(0.135526)
    out = tmp_path / "crop.png"
    proc = script("field", f, "--field", "pressure", "--time", "1.1", "--ylim", "9", "10",
                  "-o", out)
    assert proc.returncode == 0, proc.stderr
    assert_png(out)
    # a time with no snapshot (between two, or past the end) draws the nearest and says so
    assert "no field snapshot at t = 1.1 s" in proc.stderr and "t = 1.5 s" in proc.stderr
    proc = script("field", f, "--time", "99", "-o", tmp_path / "late.png")
    assert proc.returncode == 0, proc.stderr
    assert "no field snapshot at t = 99 s; drawing the nearest" in proc.stderr
    assert f"t = {syn.T_END:g} s" in proc.stderr
    proc = script("field", f, "--time", "1.5", "-o", tmp_path / "exact.png")
    assert proc.returncode == 0 and "note:" not in proc.stderr, proc.stderr


# ---------------------------------------------------------------- bad input


def _bad_file(kind: str, tmp_path: Path) -> Path:
    f = tmp_path / f"{kind}.h5"
    if kind == "not_hdf5":
        f.write_text("this is a text file, not HDF5\n")
    elif kind == "foreign_hdf5":
        with h5py.File(f, "w") as h5:
            h5["temperature"] = np.arange(10.0)
    return f


@pytest.mark.parametrize("kind", ["missing", "not_hdf5", "foreign_hdf5"])
@pytest.mark.parametrize("name", SCRIPTS)
def test_bad_file_gives_one_error_line_and_status_2(tmp_path: Path, name: str, kind: str) -> None:
    """A missing file, a file that is not HDF5 and an HDF5 file that is not a dktlbm run each
    give one line `error: <file>: <what>` on stderr, exit status 2 and no traceback."""
    f = _bad_file(kind, tmp_path)
    proc = script(name, f, "-o", tmp_path / "x.png") if name in PLOTS else script(name, f)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {f}: "), proc.stderr
    assert not (tmp_path / "x.png").exists()


def test_pair_scripts_refuse_a_single_particle_run(tmp_path: Path) -> None:
    """gap.py and pattern.py need a pair: a one-particle run is an error (status 2, says so);
    trajectories.py and drag.py draw it."""
    f = tmp_path / "single.h5"
    syn.write_run(f, syn.SHAPES["never"], (0.25,))
    for name in ("gap", "pattern"):
        proc = script(name, f)
        assert proc.returncode == 2 and "Traceback" not in proc.stderr
        assert proc.stderr.startswith(f"error: {f}: ") and "pair needs 2" in proc.stderr
    for name in ("trajectories", "drag"):
        proc = script(name, f)
        assert proc.returncode == 0, proc.stderr
        assert_png(tmp_path / f"single_{name}.png")


@pytest.mark.parametrize("name", [*SCRIPTS, "sweep", "suspension"])
def test_version(name: str) -> None:
    """Every dkt-* command says its version (--version), the package's, which is the one
    pyproject.toml gives (tests/test_readme.py ties that to CMakeLists.txt and CHANGELOG.md);
    dktlbm.__version__ is the same."""
    import dktlbm

    project = (ROOT / "pyproject.toml").read_text()
    version = re.search(r'^version = "([^"]+)"', project, re.M).group(1)
    assert dktlbm.__version__ == version
    proc = script(name, "--version")
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == f"dkt-{name} {version}"


@pytest.mark.parametrize("name", [*SCRIPTS, "sweep"])
def test_old_script_paths_still_run(name: str, tmp_path: Path) -> None:
    """The scripts beside the package, kept for scripts written before it: `python3
    postproc/<name>.py` runs dkt-<name> (its --version line) from another directory, and
    `import dktread` is dktlbm.read, with only postproc/ on the path."""
    env = {**os.environ, "PYTHONPATH": str(POSTPROC)}
    proc = subprocess.run([sys.executable, str(POSTPROC / f"{name}.py"), "--version"],
                          capture_output=True, text=True, timeout=60, env=env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith(f"dkt-{name} ")
    proc = subprocess.run([sys.executable, "-c", "import dktread, dktlbm.read; "
                           "assert dktread is dktlbm.read, dktread"],
                          capture_output=True, text=True, timeout=60, env=env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr


@pytest.mark.parametrize("name", [*SCRIPTS, "sweep"])
def test_help(name: str) -> None:
    """Every script explains its command line with --help."""
    proc = script(name, "--help")
    assert proc.returncode == 0 and proc.stdout.startswith("usage:")


# ---------------------------------------------------------------- real runs


def _all_scripts_on(f: Path, tmp_path: Path) -> dict:
    for name in PLOTS:
        out = tmp_path / f"real_{name}.png"
        proc = script(name, f, "-o", out, "--pdf")
        assert proc.returncode == 0, f"{name}: {proc.stderr}"
        assert_png(out)
        assert_pdf(out.with_suffix(".pdf"))
    proc = script("pattern", f, "--json")
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)


def _without_diagnostics(f: Path, copy: Path) -> Path:
    """A copy of run file `f` without its /diagnostics group, as files of scenes without a
    pair (and of earlier versions of the program) are."""
    copy.write_bytes(f.read_bytes())
    with h5py.File(copy, "a") as h5:
        if "diagnostics" in h5:
            del h5["diagnostics"]
    return copy


def test_real_run_without_diagnostics(tmp_path: Path) -> None:
    """A small real run of input/uhlmann.nml (two particles given one by one, no &pair group;
    1 rank), read from a copy of its file without /diagnostics: the reader computes the pair
    from /particles, starting from the scene's positions (x 0.999 and 1.0, y 6.5 and 7.0 cm,
    D = 0.25 cm: gamma 1, D_h/D_1 = 2), takes the thresholds from the namelist in /run, and
    classifies; every script runs on the copy; field.py's default is the last stored
    snapshot, at the end of the run (0.05 s); the copy counts as a finished run for sweeps.
    When the program wrote /diagnostics, its thresholds, gap series and pattern are the ones
    computed from the copy. (tau = 0.52, not 0.6: at 10 spacings per diameter tau = 0.6 stops
    on the Mach-number guard before 0.05 s.)"""
    out = tmp_path / "uhl"
    run("uhlmann.nml", 1, ["lbm.dx=0.025", "lbm.tau=0.52", "run.t_end=0.05",
                           "output.field_interval=0.025", "output.series_interval=0.005"],
        out, timeout=120)
    f = out / "uhlmann.h5"
    plain = _without_diagnostics(f, tmp_path / "uhlmann.h5")
    pair = read.pair_of(read.open_run(plain, need_particles=2))
    assert pair.source.startswith("computed")
    assert pair.dr[0] == pytest.approx(math.hypot(0.001, 0.5) - 0.25, abs=1e-9)
    assert (pair.gamma, pair.dh, pair.d1) == pytest.approx((1.0, 2.0, 0.25))
    r = _all_scripts_on(plain, tmp_path)
    assert r["pattern"] == pair.pattern
    assert read.read_field(plain, "vorticity").time == pytest.approx(0.05)
    assert read.run_status(plain) == "finished"
    with h5py.File(f) as h5:
        if "diagnostics" not in h5:
            return
    written = read.pair_of(read.open_run(f))
    assert written.source == "as written in /diagnostics"
    assert (written.limits.enter, written.limits.release) == pytest.approx(
        (pair.limits.enter, pair.limits.release))
    np.testing.assert_allclose(written.dr, pair.dr, atol=1e-9)
    assert written.pattern == pair.pattern


@pytest.mark.skipif(not (ROOT / "input/case0_box.nml").exists(),
                    reason="input/case0_box.nml is not there yet")
def test_real_pair_run_diagnostics_agree_with_particles(tmp_path: Path) -> None:
    """A small real run of input/case0_box.nml on 2 ranks (8 spacings per diameter, 0.3 s):
    every script runs on it, and the program's /diagnostics agree with what the reader
    computes from /particles by docs/model.md §6 and E12: D_x, D_y, D_r, Re_a and C_d of each
    sample, the thresholds, gamma, D_h/D_1, the pattern and its episodes."""
    out = tmp_path / "box"
    run("case0_box.nml", 2, ["lbm.cells_per_diameter=8", "run.t_end=0.3",
                             "output.field_interval=0.1"], out, timeout=300)
    f = out / "case0_box.h5"
    r = _all_scripts_on(f, tmp_path)
    with h5py.File(f) as h5:
        if "diagnostics" not in h5:
            pytest.skip("this build does not write /diagnostics yet")
    written = read.pair_of(read.open_run(f))
    computed = read.pair_of(read.open_run(f), from_particles=True)
    assert written.source == "as written in /diagnostics"
    np.testing.assert_allclose(written.t, computed.t, atol=1e-12)
    for name in ("dx", "dy", "dr"):
        np.testing.assert_allclose(getattr(written, name), getattr(computed, name), atol=1e-9)
    np.testing.assert_allclose(written.re, computed.re, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(written.cd, computed.cd, rtol=1e-9, atol=1e-9)  # NaN at rest
    assert (written.limits.enter, written.limits.release) == pytest.approx(
        (computed.limits.enter, computed.limits.release))
    assert (written.gamma, written.dh) == pytest.approx((computed.gamma, computed.dh))
    assert written.pattern == computed.pattern == r["pattern"]
    assert [t for e in written.episodes for t in (e.start, e.end)] == pytest.approx(
        [t for e in computed.episodes for t in (e.start, e.end)])


def test_pattern_piped_into_head_ends_quietly(tmp_path: Path) -> None:
    """`dkt-pattern run.h5 | head -1`: the reader may close the pipe before the command has
    written (head has its line, or `| true`). The command must end with status 0 and nothing
    on stderr, as the shell's own commands do; it used to print `error: output: Broken pipe`
    and exit 2. Here the pipe is closed before the command writes anything."""
    f = tmp_path / "rep.h5"
    syn.write_run(f, syn.SHAPES["repeated"], (0.2, 0.1))
    env = {**os.environ, "MPLBACKEND": "Agg"}
    proc = subprocess.Popen([sys.executable, "-m", "dktlbm.pattern", str(f)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    proc.stdout.close()  # the reader is gone before the first line
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=60) == 0, err
    assert err == "", err


def test_bed_measures_of_dkt_suspension_on_arrangements_known_exactly() -> None:
    """The bed measures that `dkt-suspension --summary` prints, on arrangements whose answers
    are known: touching disks on a square grid (n columns, rows stacked) fill pi/4 of any
    band of whole rows, and their contact numbers are 4 inside, 3 on an edge, 2 in a corner;
    in a hexagonal stack the inner disks have 6. A band cut through a row's middle counts half
    of that row's area. A gap just above the reach is not a contact."""
    from dktlbm.suspension import area_below, contacts, surface_gaps

    r, n, rows = 0.05, 6, 5
    gx, gy = np.meshgrid((2 * np.arange(n) + 1) * r, (2 * np.arange(rows) + 1) * r)
    x, y, rr = gx.ravel(), gy.ravel(), np.full(n * rows, r)
    width = 2 * r * n
    whole = area_below(y, rr, np.array([4 * r])).sum() / (width * 4 * r)
    assert whole == pytest.approx(math.pi / 4, rel=1e-12)
    half = area_below(y, rr, np.array([r])).sum()
    assert half == pytest.approx(0.5 * n * math.pi * r * r, rel=1e-12)
    z = contacts(surface_gaps(x, y, rr), 1e-9).reshape(rows, n)
    assert z[1:-1, 1:-1].min() == z[1:-1, 1:-1].max() == 4
    assert z[0, 0] == z[-1, -1] == 2 and z[0, 2] == z[2, 0] == 3
    apart = contacts(surface_gaps(x * 1.001, y * 1.001, rr), 1e-5)  # gaps 1e-4 r > the reach
    assert apart.max() == 0
    hx = np.array([(2 * i + (j % 2)) * r for j in range(5) for i in range(6)])
    hy = np.array([j * math.sqrt(3) * r for j in range(5) for i in range(6)])
    zh = contacts(surface_gaps(hx, hy, np.full(30, r)), 1e-9).reshape(5, 6)
    assert (zh[1:-1, 1:-1] == 6).all()
