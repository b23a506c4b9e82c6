"""The every-clip benchmark's table: a row as its JSON holds it, read back as the README's columns."""

from __future__ import annotations

from benchmarks.bench_clips import CLIPS, table
from benchmarks.bench_held_out_views import VIDEOS


def test_a_row_reads_as_the_table_s_columns():
    row = {"clip": "more/singing_boy", "frames": {"train": 134, "val": 7, "test": 16}, "source_face_px": 193.4,
           "face_px": 104.2, "landmark_error_px": {"median": 1.55, "p95": 3.82}, "room": "moving", "steps": 4580,
           "val": {"psnr": 31.2}, "test": {"psnr": 25.621, "psnr_person": 23.637, "ssim": 0.8341, "face_mse": 0.00041,
                                         "render_ms": 140.7}}
    lines = table([row]).splitlines()
    assert len(lines) == 3 and lines[0].count("|") == lines[2].count("|") == 13
    assert lines[2] == ("| `more/singing_boy` | 134/7/16 | 193 / 104 | 1.55 / 3.82 | moving | 4580 | 31.20 | "
                        "**25.62** | 23.64 | 0.834 | 0.0004 | 141 |")


def test_the_clips_are_the_shared_ones():
    """Thirteen clips, each a video under ../shared/data/video where it is there."""
    assert len(set(CLIPS)) == 13
    if VIDEOS.is_dir():
        assert all((VIDEOS / f"{clip}.mp4").is_file() for clip in CLIPS)
