"""The paper's validation scene case0_box (docs/model.md §7-8) at the paper's resolution (25
spacings per diameter, 250 x 1000 cells): the drafting gap, the start of kissing and the tumbling.

Published: a nearly constant surface gap of about 0.2 cm until t = 0.7 s, kissing at about
1.4 s, tumbling completed at about 2.1 s (the paper); an independent HLBM code: gap below one
cell from 1.21 to 1.79 s, passing at 1.87 s. docs/model.md §8 warns that the times depend on
resolution and on how the symmetry is broken; the README's validation table lists the measured times
next to these. This test holds what the scene must reproduce: the drafting gap, the start of
kissing within 0.1 s of the HLBM time, and one kissing episode that ends in tumbling (the
trailing disk passes the leading one) within the run.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from dkt_run import run


def test_case0_box_drafts_kisses_and_tumbles_like_the_published_runs(tmp_path: Path) -> None:
    out = tmp_path / "case0_box"
    run("case0_box.nml", 2, ["output.field_interval=0"], out, timeout=900)
    with h5py.File(out / "case0_box.h5", "r") as h5:
        t = h5["particles/t"][()]
        y = h5["particles/y"][()]
        diag = h5["diagnostics"]
        dr = diag["dr"][()]
        pattern = diag.attrs["pattern"]  # str; bytes in files before version 0.2.0
        pattern = pattern.decode() if isinstance(pattern, bytes) else str(pattern)
        starts = diag["episodes/start"][()]
        ends = diag["episodes/end"][()]
        enter = float(diag.attrs["kiss_enter"])
    # drafting: the surface gap stays near its initial 0.2 cm (within 5 %) up to t = 0.5 s
    early = t <= 0.5
    print(f"gap at 0.5 s: {np.interp(0.5, t, dr):.4f} cm; kissing from {starts} to {ends} s")
    assert np.all(np.abs(dr[early] - 0.2) < 0.01)
    # kissing: the gap closes to the entry threshold (3 spacings, 0.024 cm) near 1.2 s
    assert enter < 0.03
    assert abs(starts[0] - 1.21) < 0.1
    # tumbling: one episode, released before the end, and the trailing disk (1, above at t = 0)
    # overtakes the leading one
    assert pattern == "once"
    assert ends[0] < t[-1] - 0.1
    passing = t[np.nonzero(y[:, 0] < y[:, 1])[0]]
    assert passing.size > 0, "the pair did not tumble within the run"
    print(f"passing at {passing[0]:.3f} s (paper: tumbling done at about 2.1 s; HLBM: 1.87 s)")
    assert ends[0] < passing[0] + 0.5
