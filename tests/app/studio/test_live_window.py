"""Live driving in the real window under Xvfb: a shared video of a person (expressions_d3.mp4, whose mouth opens
from 10 s on) played in real time drives the demo avatar; the avatar's mouth opens on screen, the performance is
recorded into a file `animate` reads, and every shown render has its camera-to-pixels time."""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image
from scipy import ndimage

from app.animation import load_animation
from app.studio.session import read_avatar_folder
from tests.app.studio.test_window import run_script
from tests.conftest import DEMO, REPO, xvfb

SHARED_VIDEO = REPO.parent / "shared" / "data" / "video" / "expressions_d3.mp4"
pytestmark = [pytest.mark.gl, pytest.mark.skipif(not SHARED_VIDEO.is_file(),
                                                 reason=f"{SHARED_VIDEO} is not on this machine (../shared)")]


@pytest.fixture(scope="module")
def display():
    with xvfb(":87", "1600x1000x24") as disp:
        yield disp


def lips(image: np.ndarray) -> np.ndarray:
    """The avatar's lips: red pixels (green under half of red, not dark), those of the largest group of them lying
    within 3% of the image of each other (an open mouth parts the lips; a red spot elsewhere stays apart)."""
    r, g = image[..., 0].astype(np.int16), image[..., 1].astype(np.int16)
    red = (g < 0.5 * r) & (r > 80)
    groups, n = ndimage.label(ndimage.binary_dilation(red, iterations=max(1, round(0.03 * image.shape[0]))))
    assert n > 0, "no red lips in the render"
    largest = 1 + int(np.argmax(ndimage.sum(red, groups, range(1, n + 1))))
    return red & (groups == largest)


def opening(sliders: dict, names: list[str]) -> float:
    """How open the sliders hold the mouth: the jaw (degrees over 20) where the head model has a jaw joint, and the
    expressions named for the jaw's opening where it has those (ICT's jawOpen)."""
    weights = [w for n, w in zip(names, sliders["expression"], strict=True) if n.lower() in ("jawopen", "mouthopen")]
    return sliders["jaw_open_deg"] / 20.0 + sum(weights)


def mouth(image: np.ndarray) -> tuple[float, float]:
    """The mouth as the render shows it: the height of the box about the lips and the dark pixels inside it (the
    open mouth's inside), each against the face (its height; its area in pixels off the plain background)."""
    ys, xs = np.nonzero(lips(image))
    box = image[ys.min():ys.max() + 1, xs.min():xs.max() + 1]
    face = np.abs(image.astype(np.int16) - image[0, 0]).max(-1) > 20
    rows = np.nonzero(face.any(1))[0]
    return (ys.max() - ys.min() + 1) / (rows.max() - rows.min() + 1), float((box.mean(-1) < 60).sum() / face.sum())


def test_a_video_drives_the_avatar_and_its_mouth_opens_on_screen(display, tmp_path):
    closed, opened, perf = tmp_path / "closed.png", tmp_path / "open.png", tmp_path / "takes" / "perf.json"
    # The final pass whatever the machine's load (the live pass would fall to the draft's 64 px on a busy one).
    steps = [{"wait_render": "draft"}, {"live_pass": "final"}, {"live": str(SHARED_VIDEO)}, {"record": True},
             {"wait_live": 240}, {"save_live": str(closed)},  # 8 s in: the mouth shut
             {"wait_live": 320}, {"save_live": str(opened)},  # 10.7 s: the mouth open
             {"wait_live_end": True, "timeout_s": 60}, {"stop_recording": str(perf)}]
    report = run_script(display, tmp_path, DEMO, steps, size="1440x900")
    assert report["steps_run"] == len(steps)
    shut, wide = report["live_log"]
    assert 240 <= shut["frame"] < 290 and wide["frame"] >= 320, report["live_log"]
    # The sliders the poses set: the mouth shut, then open (the landmarker's jawOpen about 0.55 there: 11 degrees of
    # jaw, or the expression jawOpen at about 0.55 less the neutral face's).
    head = read_avatar_folder(DEMO).avatar.head_model
    names = [head.expr_names[i] if i < len(head.expr_names) else "" for i in range(head.num_expression)]
    assert opening(shut["sliders"], names) < 0.1 < 0.3 < opening(wide["sliders"], names), report["live_log"]
    a, b = (np.asarray(Image.open(p)) for p in (closed, opened))
    assert a.shape == b.shape == (256, 256, 3) and report["live"]["passes"].keys() == {"final"}
    # The person turns between the two frames, so the face's pixels move everywhere; the mouth's own change is the
    # opening: the lips' box taller, dark inside.
    (h_shut, dark_shut), (h_open, dark_open) = mouth(a), mouth(b)
    print("lips' height / face's", h_shut, h_open, "dark inside / face's area", dark_shut, dark_open)
    assert h_open > 1.5 * h_shut and dark_open > max(2 * dark_shut, 0.005)
    # The recording: the file animate reads, the mouth shut then open in it, over the video's length.
    anim = load_animation(perf)
    channel, scale = ("jaw.open", 20.0) if "jaw.open" in anim.tracks else ("expression.jawOpen", 1.0)
    jaw = {t: v / scale for t, v in anim.tracks[channel]}
    times = np.array(sorted(jaw))
    assert 9.0 < times[-1] - times[0] < 12.5 and len(times) > 30
    assert max(v for t, v in jaw.items() if t < 7.0) < 0.1 < 0.3 < max(jaw.values())
    assert json.loads(perf.read_text())["interpolation"] == "linear"
    live = report["live"]
    assert live["shown"] > 10 and len(live["latency_ms"]) == live["shown"]
    assert all(0 < ms < 5000 for ms in live["latency_ms"]) and live["track_ms_median"] > 0
    assert not any("render failed" in e for e in report["errors"]), report["errors"]
    assert report["errors"][-1] == f"live: {SHARED_VIDEO}: the video ended"


def test_stopping_live_driving_gives_the_sliders_back(display, tmp_path):
    """A missing video first: one message, and the studio goes on. Then stopped mid-video: no message, the poses
    stop coming, and a slider's move renders as before. The guide holds while live unless asked to follow
    (Display.live_guide), and follows the sliders again once live stops."""
    missing = tmp_path / "nothing.mp4"
    steps = [{"wait_render": "draft"}, {"live": str(missing)}, {"wait_live_end": True},
             {"expect_error": "no such video file"},
             {"record_sliders": True}, {"live": str(SHARED_VIDEO)}, {"wait_live": 30},
             {"record_sliders": True}, {"stop_live": True},
             {"record_sliders": True}, {"wait_frames": 30}, {"record_sliders": True},
             {"expression": 0, "value": 0.7}, {"wait_render": "draft"}, {"record_sliders": True},
             {"live_guide": True}, {"live": str(SHARED_VIDEO)}, {"wait_live": 30}, {"record_sliders": True},
             {"stop_live": True}]
    report = run_script(display, tmp_path, DEMO, steps)
    log = report["sliders_log"]
    before, live, stopped, later, moved, following = (entry.pop("guide_draws") for entry in log)
    assert live == before  # 30 live poses, the guide held
    assert moved > later >= stopped  # drawn again once live stopped
    assert following >= moved + 5  # asked to follow: drawn for the live poses
    stopped, later, moved = log[2:5]
    assert report["errors"] == [f"{missing}: no such video file (a camera is given by its index: --source 0)"]
    assert report["live"]["state"] is None
    assert 30 <= report["live"]["on_screen"] < 200
    assert stopped == later  # nothing drives the sliders once stopped
    assert moved["expression"][0] == 0.7 and moved["expression"][1:] == later["expression"][1:]
