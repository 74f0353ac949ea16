"""The README's main job, exactly as a user runs it: `clsky animate` with no arguments (slow: ~80 s).

Checks what the animation issue asks of it: an MP4 that decodes with the right frame count and size,
PNG frames, and one metrics row per frame.
"""

import csv
import subprocess
import sys

import pytest

imageio = pytest.importorskip("imageio.v3")


@pytest.mark.slow
def test_default_animate_writes_a_decodable_mp4_and_png_frames(tmp_path):
    result = subprocess.run([sys.executable, "-m", "clsky.anim", "animate", "--progress", "none"], cwd=tmp_path,
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.strip().splitlines()
    assert lines[0].startswith("scene plan (default quality, error budget 1 %)")     # printed first
    assert lines[-1].startswith("120 frames 512x512 (compare)")                     # the summary
    video = imageio.imread(tmp_path / "sky.mp4")
    pngs = sorted((tmp_path / "sky_frames").glob("frame_*.png"))
    first = imageio.imread(pngs[0])
    assert len(pngs) == 120
    assert video.shape == (120,) + first.shape              # the composite table | ray march | error
    assert first.shape[0] == 512 and first.shape[1] >= 3 * 512
    with open(tmp_path / "sky_metrics.csv") as stream:
        assert len(list(csv.DictReader(stream))) == 120
