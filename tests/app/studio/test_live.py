"""Live driving without a window: poses onto the sliders and into a recording (the Session's actions), the
recording read back as `animate` reads it, the camera-to-pixels figures, a video file played in real time with
stale frames dropped, the tracker process on a real video, and the sources that cannot be opened."""

from __future__ import annotations

import json
import math
import threading
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from app.animation import load_animation
from app.cli import main
from app.studio import actions as a
from app.studio.live import Feed, LiveFigures, LiveWorker, Pose, open_capture, source_problem
from app.studio.session import Session, read_avatar_folder
from tests.conftest import DEMO, REPO

SHARED_VIDEO = REPO.parent / "shared" / "data" / "video" / "expressions_d3.mp4"


@pytest.fixture(scope="module")
def files():
    return read_avatar_folder(DEMO)


@pytest.fixture
def session(files) -> Session:
    s = Session()
    a.AvatarOpened(files).apply(s)
    a.LiveStarted("clip.mp4").apply(s)
    s.dirty = False
    return s


@pytest.fixture(scope="module")
def counter_video(tmp_path_factory) -> Path:
    """60 frames at 30 fps, frame k's grey level 4 k: a frame read back names its index."""
    path = tmp_path_factory.mktemp("live") / "counter.avi"
    out = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 30.0, (64, 64))
    for k in range(60):
        out.write(np.full((64, 64, 3), 4 * k, np.uint8))
    out.release()
    return path


def first_expression(session: Session) -> str:
    """The open avatar's first expression's name (the demo's head model may change)."""
    return session.avatar.head_model.expr_names[0]


def test_a_pose_moves_the_sliders_without_an_undo_step(session):
    name = first_expression(session)
    a.LivePose({f"expression.{name}": 0.4, "jaw.open": 12.0, "head.yaw": -8.0, "gaze.pitch": 3.0}, 5.0, 17
               ).apply(session)
    sl, head = session.sliders, session.avatar.head_model
    assert sl.expression[head.expression_index(name)] == pytest.approx(0.4)
    assert sl.jaw_open_deg == pytest.approx(12.0) and sl.head[0] == pytest.approx(-8.0)
    assert sl.gaze_left[1] == pytest.approx(3.0) and sl.gaze_right[1] == pytest.approx(3.0)
    assert session.dirty and session.live.index == 17 and session.live.stamp == 5.0
    assert session.history.undo == []  # a performance is not a slider change to step back through
    session.live.running = False
    a.LivePose({"jaw.open": 20.0}, 6.0, 18).apply(session)  # a pose that comes after the stop changes nothing
    assert sl.jaw_open_deg == pytest.approx(12.0)


def test_recording_keeps_the_performance_as_an_animation(session, tmp_path):
    a.LivePose({"jaw.open": 1.0}, 99.0, 1).apply(session)  # before the recording: not kept
    a.StartRecording().apply(session)
    smile = f"expression.{first_expression(session)}"
    # Three poses 0.1 s apart: keys at 0, 0.1 and 0.2 s (from the first recorded pose's frame time, 100.0).
    for k, (jaw, weight) in enumerate([(0.0, 0.1), (10.0, 0.3), (20.0, 0.2)]):
        a.LivePose({"jaw.open": jaw, smile: weight}, 100.0 + 0.1 * k, 10 + k).apply(session)
    path = tmp_path / "takes" / "perf.json"
    a.StopRecording(path).apply(session)
    anim = load_animation(path)
    assert anim == session.animation and anim.interpolation == "linear"
    np.testing.assert_allclose(anim.tracks["jaw.open"], [(0.0, 0.0), (0.1, 10.0), (0.2, 20.0)], atol=1e-6)
    assert anim.value("jaw.open", 0.15) == pytest.approx(15.0)  # linear between the poses
    assert anim.value(smile, 0.05) == pytest.approx(0.2)
    assert anim.duration_s == pytest.approx(0.2 + 1 / 30, abs=1e-6)  # the last pose is shown for a frame
    assert not session.live.recording and session.anim_time == 0.0


def test_recording_needs_a_source_and_a_face(files, session):
    idle = Session()
    a.AvatarOpened(files).apply(idle)
    a.StartRecording().apply(idle)
    assert not idle.live.recording and idle.errors == ["nothing to record: start live driving first"]
    a.StartRecording().apply(session)
    a.StopRecording().apply(session)
    assert session.errors == ["nothing recorded: no face was tracked while recording"]
    before = session.animation
    a.StartRecording().apply(session)
    a.LivePose({"jaw.open": 5.0}, 1.0, 1).apply(session)
    a.LiveStopped("live: clip.mp4: the video ended").apply(session)  # the end finishes the recording
    assert not session.live.running and session.animation is not before
    assert session.animation.tracks["jaw.open"] == ((0.0, 5.0),)
    assert session.errors[-1] == "live: clip.mp4: the video ended"


def test_camera_to_pixels_is_counted_for_the_renders_shown():
    f = LiveFigures()
    f.submitted(7, 40, 10.000)  # frame 40 came at 10.000 s; its request 7 went out
    f.submitted(8, 0, None)  # a slider's request: not live
    f.drawing(8, 20.0)
    f.shown(10.050)
    assert f.latency_ms == [] and f.on_screen == -1
    f.drawing(7, 61.5)  # request 7's pixels drawn in this frame, presented at 10.120: 120 ms
    f.shown(10.120)
    f.submitted(9, 44, 10.100)
    f.drawing(9, 58.0)
    f.shown(10.230)  # 130 ms
    assert f.latency_ms == pytest.approx([120.0, 130.0]) and f.render_ms == [61.5, 58.0] and f.on_screen == 44
    report = f.report(None)
    assert report["fps_shown"] == pytest.approx(1 / 0.11, abs=0.01) and report["shown"] == 2


def test_a_video_plays_in_real_time_and_a_slow_reader_gets_the_newest_frame(counter_video):
    cap, problem = open_capture(str(counter_video))
    assert problem == ""
    feed = Feed(cap, camera=False)
    try:
        seen = []
        last = -1
        while len(seen) < 12:
            frame = feed.next_after(last, timeout_s=1.0)
            assert frame is not None
            # Frame k is due k / 30 s after the start, and comes then, not before, nor later than the feed allows:
            # a frame a whole frame late is skipped, so one that is read comes within a frame and its decode (the
            # first one took 32 ms on a busy 2-core machine, beside a 33 ms frame).
            assert -1e-3 <= frame.stamp - (feed.start + frame.index / 30.0) < 2 / 30.0, frame.index
            assert frame.media_ms == round(1000 * frame.index / 30)
            assert abs(int(frame.bgr[0, 0, 0]) - 4 * frame.index) <= 3  # the pixels are that frame's
            seen.append(frame.index)
            last = frame.index
            time.sleep(0.1)  # a tracker three frames slow
        steps = np.diff(seen)
        # It takes the newest frame each time: about 3 apart (0.1 s at 30 fps), never the next stale one.
        assert steps.min() >= 2 and np.median(steps) == 3, seen
    finally:
        feed.close()


def test_sources_that_cannot_be_opened_are_named(tmp_path):
    assert source_problem("7").startswith("camera 7: no camera there")
    assert source_problem(str(tmp_path / "no.mp4")) == f"{tmp_path / 'no.mp4'}: no such video file (a camera is " \
        "given by its index: --source 0)"
    (tmp_path / "notes.mp4").write_text("not a video")
    assert source_problem(str(tmp_path / "notes.mp4")) == f"{tmp_path / 'notes.mp4'}: not a video OpenCV can read"


def test_the_live_command_says_in_one_line_when_there_is_no_camera(capsys):
    assert main(["live", str(DEMO), "--source", "7"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("avatar-studio live: error: camera 7: no camera there"), err


@pytest.mark.skipif(not SHARED_VIDEO.is_file(), reason=f"{SHARED_VIDEO} is not on this machine (../shared)")
def test_the_tracker_process_follows_a_real_video(files):
    """expressions_d3.mp4 played in real time: a pose for nearly every frame, the jaw shut in the first seconds
    and open from 10 s (the person's mouth opens there), the head's turn within the sliders' range."""
    from app.user_config import find_landmarker

    poses: list[Pose] = []
    woken = threading.Event()
    worker = LiveWorker(str(SHARED_VIDEO), find_landmarker(), files.avatar.head_model, woken.set)
    try:
        deadline = time.monotonic() + 60
        seen = 0
        while worker.state in ("starting", "running") and time.monotonic() < deadline:
            woken.wait(0.5)
            woken.clear()
            if worker.received > seen and worker.pose is not None:
                seen = worker.received
                poses.append(worker.pose)
                worker.want(time.perf_counter())  # the next pose as soon as it can be had
    finally:
        worker.close()
    assert worker.state == "ended" and worker.message == "the video ended", worker.message
    by_frame = {p.index: p for p in poses}
    assert len(by_frame) > 0.5 * 354, len(by_frame)  # asked at once each time: most frames are tracked
    # How open the mouth is: the jaw (degrees over 20) where the head model has a jaw joint, else its jawOpen
    # expression (ICT's); the landmarker's jawOpen is about 0.55 from 10 s on, 0.35 rad (20 degrees) a unit.
    opening = lambda c: c.get("jaw.open", 0.0) / 20.0 + c.get("expression.jawOpen", 0.0)
    jaw = lambda lo, hi: [opening(p.channels) for p in poses if lo <= p.index < hi]
    assert max(jaw(30, 250)) < 0.1 and np.median(jaw(310, 354)) > 0.3, (max(jaw(30, 250)), jaw(310, 354))
    assert all(abs(p.channels["head.yaw"]) < 30 for p in poses)
    assert poses[-1].stamp > poses[0].stamp + 10.0  # played in real time: 354 frames at 30 fps, 11.8 s
    assert math.isfinite(np.median([p.track_ms for p in poses]))


@pytest.mark.gl
def test_a_recording_is_an_animation_file_for_animate(tmp_path, session):
    """The file a recording leaves is one `animate` renders (its own checks pass)."""
    a.StartRecording().apply(session)
    smile = f"expression.{first_expression(session)}"
    a.LivePose({smile: 0.0, "head.yaw": 0.0}, 3.0, 1).apply(session)
    a.LivePose({smile: 0.8, "head.yaw": 10.0}, 3.5, 16).apply(session)
    path = tmp_path / "perf.json"
    a.StopRecording(path).apply(session)
    out = tmp_path / "perf.mp4"
    assert main(["animate", str(DEMO), str(path), "--out", str(out), "--size", "32", "--preset", "draft"]) == 0
    assert cv2.VideoCapture(str(out)).get(cv2.CAP_PROP_FRAME_COUNT) == 16  # (0.5 + 1/30) s at 30 fps
    assert json.loads(path.read_text())["format"] == "avatar-studio/animation/1"


def test_a_tracker_that_dies_fails_live_driving_with_its_exit_code(files, counter_video):
    from app.user_config import find_landmarker

    worker = LiveWorker(str(counter_video), find_landmarker(), files.avatar.head_model, lambda: None)
    try:
        deadline = time.monotonic() + 60
        while worker.state == "starting" and time.monotonic() < deadline:
            time.sleep(0.05)
        assert worker.state == "running"
        worker._proc.kill()  # as a crash in the landmarker would end it: no word sent
        worker._proc.join(5)
        worker.check()
        assert worker.state == "failed" and worker.message == "live: the tracker stopped (exit code -9)"
    finally:
        worker.close()


@pytest.mark.skipif(not SHARED_VIDEO.is_file(), reason=f"{SHARED_VIDEO} is not on this machine (../shared)")
def test_unasked_the_tracker_makes_a_pose_every_quarter_second(files):
    """Where the window asks for no pose, the tracker makes one only every UNASKED_S (0.25 s): about 17 in the
    video's first 4 s after the first pose (against more than 15 a second where each is asked for at once, above);
    the other frames are dropped."""
    from app.studio.live import UNASKED_S
    from app.user_config import find_landmarker

    worker = LiveWorker(str(SHARED_VIDEO), find_landmarker(), files.avatar.head_model, lambda: None)
    stamps: list[float] = []
    try:
        deadline = time.monotonic() + 60
        while worker.state in ("starting", "running") and time.monotonic() < deadline:
            time.sleep(0.01)
            if worker.pose is not None and (not stamps or worker.pose.stamp != stamps[-1]):
                stamps.append(worker.pose.stamp)
            if stamps and stamps[-1] - stamps[0] >= 4.0:
                break
        state, received = worker.state, worker.received
    finally:
        worker.close()
    assert state == "running" and 12 <= received <= 20, (state, received)
    gaps = np.diff(stamps[1:])  # after the first pose, which comes at once
    assert np.median(gaps) == pytest.approx(UNASKED_S, abs=0.05), np.median(gaps)
