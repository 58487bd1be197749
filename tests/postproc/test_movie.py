"""dkt-field --movie: one frame per stored field snapshot, as an MP4 when ffmpeg is found, as
a GIF when it is not (PATH without ffmpeg) or when OUT ends in .gif, each frame counted back
from the file written (ffprobe for the MP4, Pillow for the GIF).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import pytest
import synthetic as syn

FFMPEG = shutil.which("ffmpeg")
FFPROBE = shutil.which("ffprobe")


def snapshots(h5: Path) -> int:
    with h5py.File(h5, "r") as f:
        return len(f["fields"])


def field_movie(h5: Path, *args: str, env: dict[str, str] | None = None):
    return subprocess.run([sys.executable, "-m", "dktlbm.field", str(h5), "--movie", *args],
                          capture_output=True, text=True, timeout=300,
                          env={**os.environ, "MPLBACKEND": "Agg", **(env or {})})


@pytest.fixture
def run_file(tmp_path: Path) -> Path:
    f = tmp_path / "w.h5"
    syn.write_run(f, syn.SHAPES["once"], (0.2, 0.1))
    assert snapshots(f) == len(syn.FIELD_TIMES) > 1
    return f


@pytest.mark.skipif(FFMPEG is None or FFPROBE is None, reason="ffmpeg/ffprobe not installed")
def test_mp4_has_a_frame_per_snapshot(run_file: Path) -> None:
    proc = field_movie(run_file)
    assert proc.returncode == 0, proc.stderr
    mp4 = run_file.with_name("w_vorticity.mp4")
    assert f"wrote {mp4}" in proc.stdout
    probe = subprocess.run([FFPROBE, "-v", "error", "-count_frames", "-select_streams", "v:0",
                            "-show_entries", "stream=nb_read_frames", "-of", "csv=p=0",
                            str(mp4)], capture_output=True, text=True, check=True)
    assert int(probe.stdout.strip()) == snapshots(run_file)


def test_gif_when_asked_for(run_file: Path, tmp_path: Path) -> None:
    """OUT.gif is written as a GIF whether or not ffmpeg is there, a frame per snapshot."""
    gif = tmp_path / "asked.gif"
    proc = field_movie(run_file, str(gif), "--fps", "2")
    assert proc.returncode == 0, proc.stderr
    from PIL import Image

    with Image.open(gif) as image:
        assert image.format == "GIF" and image.n_frames == snapshots(run_file)


def test_gif_without_ffmpeg_has_a_frame_per_snapshot(run_file: Path, tmp_path: Path) -> None:
    """PATH holds every program of this PATH but ffmpeg: the GIF fallback is taken, named
    after the given OUT with .gif, and each snapshot is one frame."""
    bare = tmp_path / "bin"
    bare.mkdir()
    for directory in os.environ["PATH"].split(os.pathsep):
        for program in Path(directory).glob("*") if Path(directory).is_dir() else []:
            link = bare / program.name
            if not program.name.startswith("ffmpeg") and not link.exists():
                link.symlink_to(program)
    assert shutil.which("ffmpeg", path=str(bare)) is None
    out = tmp_path / "movies" / "w.mp4"
    proc = field_movie(run_file, str(out), "--field", "speed", env={"PATH": str(bare)})
    assert proc.returncode == 0, proc.stderr
    gif = out.with_suffix(".gif")
    assert "ffmpeg not found" in proc.stdout and f"wrote {gif}" in proc.stdout
    assert not out.exists()
    from PIL import Image

    with Image.open(gif) as image:
        assert image.format == "GIF"
        assert image.n_frames == snapshots(run_file)
