"""The studio's Session and its actions, without a window: what each action does to the one value the panels
draw from, with hand-worked numbers; and the application's commands (opening, training, exporting) carried out
by a Studio that never opens a window."""

from __future__ import annotations

import dataclasses
import math
import re
import time
from pathlib import Path

import numpy as np
import pytest

from app.studio import actions as a
from app.studio.session import AvatarFiles, Session, read_avatar_folder, views_warning
from models.capture.dataset import load_split

REPO = Path(__file__).resolve().parents[3]
DEMO = REPO / "resources" / "demo_avatar"
pytestmark = pytest.mark.gl


@pytest.fixture(scope="module")
def files(synth_capture) -> AvatarFiles:
    """The shipped demo avatar (built-in head), with a small synthetic capture of the same head as its timeline."""
    demo = read_avatar_folder(DEMO)
    return dataclasses.replace(demo, capture=load_split(synth_capture("studio", 8, 16), "train"))


@pytest.fixture
def session(files) -> Session:
    s = Session()
    a.AvatarOpened(files).apply(s)
    s.dirty = False
    return s


def test_opening_an_avatar_resets_the_sliders_at_the_capture_identity(files):
    s = Session(timeline_frame=3, opening=DEMO, dirty=False)
    a.AvatarOpened(files).apply(s)
    assert s.avatar is files.avatar and s.opening is None and s.dirty and s.timeline_frame == -1
    assert s.sliders.expression.shape == (files.avatar.head_model.num_expression,)
    assert not s.sliders.expression.any()
    np.testing.assert_array_equal(s.sliders.shape, files.capture.frames[0].controls.shape)
    failed = Session(opening=Path("x"))
    a.OpenFailed("x: not an avatar folder").apply(failed)
    assert failed.opening is None and failed.errors == ["x: not an avatar folder"]


def test_slider_actions_move_the_controls(session):
    session.timeline_frame = 2
    a.SetExpression(2, 0.7).apply(session)
    assert session.timeline_frame == -1 and session.dirty  # a slider takes over from the timeline
    c = session.controls()
    assert c.expression[2] == pytest.approx(0.7) and np.count_nonzero(c.expression) == 1
    a.SetAngles("head", (30.0, 0.0, 0.0)).apply(session)
    np.testing.assert_allclose(session.controls().root, [0.0, math.radians(30), 0.0], atol=1e-6)  # yaw about +y
    a.SetJaw(10.0).apply(session)
    np.testing.assert_allclose(session.controls().jaw, [math.radians(10), 0.0, 0.0], atol=1e-7)
    a.SetAngles("gaze_left", (20.0, 0.0)).apply(session)
    np.testing.assert_allclose(session.controls().gaze_right, session.controls().gaze_left)  # linked: both eyes
    a.LinkGaze(False).apply(session)
    np.testing.assert_allclose(session.controls().gaze_right, 0.0)
    a.ResetPose().apply(session)
    a.ResetGaze().apply(session)
    a.ResetExpression().apply(session)
    c = session.controls()
    assert not c.root.any() and not c.neck.any() and not c.gaze_left.any() and not c.expression.any()
    with pytest.raises(ValueError, match="no angles"):
        a.SetAngles("elbow", (1.0,)).apply(session)


def test_undo_and_redo_step_through_whole_changes(session):
    """A slider dragged through many values is one change; undo walks back change by change, redo forward, and a
    new change after an undo drops what could be redone."""
    for v in (0.1, 0.3, 0.6):  # one drag
        a.SetExpression(2, v).apply(session)
    a.SetJaw(12.0).apply(session)
    a.Orbit(10.0).apply(session)
    a.Orbit(15.0).apply(session)  # one drag of the camera
    yaw = session.view.yaw_deg
    assert len(session.history.undo) == 3
    a.Undo().apply(session)
    assert session.view.yaw_deg == 20.0 and session.sliders.jaw_open_deg == 12.0
    a.Undo().apply(session)
    assert session.sliders.jaw_open_deg == 0.0 and session.sliders.expression[2] == pytest.approx(0.6)
    a.Undo().apply(session)
    assert not session.sliders.expression.any() and session.dirty
    a.Undo().apply(session)  # nothing further back: nothing changes
    assert not session.sliders.expression.any()
    a.Undo(forward=True).apply(session)
    a.Undo(forward=True).apply(session)
    assert session.sliders.expression[2] == pytest.approx(0.6) and session.sliders.jaw_open_deg == 12.0
    assert len(session.history.redo) == 1
    a.ResetExpression().apply(session)  # a new change: the camera drag can no longer be redone
    assert session.history.redo == [] and session.view.yaw_deg != yaw
    a.Undo().apply(session)
    assert session.sliders.expression[2] == pytest.approx(0.6)


def test_resets_per_group(session):
    head = session.avatar.head_model
    for name in ("browOuterUp_L", "mouthSmile_L", "eyeBlink_R", "noseSneer_L"):
        a.SetExpression(head.expression_index(name), 0.5).apply(session)
    a.SetAngles("head", (10.0, 5.0, 0.0)).apply(session)
    a.SetAngles("neck", (4.0, 0.0, 0.0)).apply(session)
    a.SetJaw(8.0).apply(session)
    a.ResetGroup("expression:brows").apply(session)
    e = lambda name: session.sliders.expression[head.expression_index(name)]
    assert e("browOuterUp_L") == 0 and e("mouthSmile_L") == 0.5 and e("eyeBlink_R") == 0.5
    a.ResetGroup("expression:mouth").apply(session)
    assert e("mouthSmile_L") == 0 and e("eyeBlink_R") == 0.5 and e("noseSneer_L") == 0.5
    a.ResetGroup("head").apply(session)
    assert not session.sliders.head.any() and session.sliders.neck[0] == 4.0
    a.ResetGroup("jaw").apply(session)
    assert session.sliders.jaw_open_deg == 0 and session.sliders.neck[0] == 4.0
    with pytest.raises(ValueError, match="no expression group"):
        a.ResetGroup("expression:elbows").apply(session)
    with pytest.raises(ValueError, match="no slider group"):
        a.ResetGroup("tail").apply(session)
    a.Undo().apply(session)  # a reset is undone like any change
    assert session.sliders.jaw_open_deg == 8.0


def test_named_poses_are_kept_per_avatar(session, tmp_path, monkeypatch):
    from app.studio import poses

    monkeypatch.setattr(poses, "POSES_FILE", tmp_path / "poses.json")
    head = session.avatar.head_model
    a.SetExpression(head.expression_index("mouthSmile_L"), 0.8).apply(session)
    a.SetJaw(14.0).apply(session)
    a.SavePose("grin").apply(session)
    saved = __import__("json").loads((tmp_path / "poses.json").read_text())
    pose = saved["avatars"][str(DEMO.resolve())]["grin"]
    assert pose["expression.mouthSmile_L"] == pytest.approx(0.8) and pose["jaw.open"] == 14.0
    assert not any(c.startswith("camera.") for c in pose)  # a pose is the face, not the view
    a.ResetExpression().apply(session)
    a.ResetGroup("jaw").apply(session)
    a.SetView(yaw_deg=-40.0).apply(session)
    a.RecallPose("grin").apply(session)
    assert session.sliders.expression[head.expression_index("mouthSmile_L")] == pytest.approx(0.8)
    assert session.sliders.jaw_open_deg == 14.0 and session.view.yaw_deg == -40.0
    other = Session()  # the same avatar opened again finds its pose
    a.AvatarOpened(session.files).apply(other)
    assert set(other.poses) == {"grin"}
    a.DeletePose("grin").apply(session)
    assert session.poses == {} and "grin" not in (tmp_path / "poses.json").read_text()
    (tmp_path / "poses.json").write_text("{not json")  # the user's broken file is never overwritten
    a.SavePose("again").apply(session)
    assert "poses.json" in session.errors[-1] and (tmp_path / "poses.json").read_text() == "{not json"


def test_timeline_shows_a_capture_frame_and_moves_the_sliders_to_it(session, files):
    frame = files.capture.frames[2].controls
    a.ShowFrame(2).apply(session)
    assert session.timeline_frame == 2 and session.dirty and session.controls() is frame
    c = session.sliders.controls()  # the sliders show the frame's values
    np.testing.assert_allclose(c.expression[:len(frame.expression)], frame.expression, atol=1e-6)
    a.CopyFrameToSliders().apply(session)
    assert session.timeline_frame == -1
    c = session.controls()
    n = len(frame.expression)
    np.testing.assert_allclose(c.expression[:n], frame.expression, atol=1e-6)
    for joint in ("root", "neck", "gaze_left"):
        np.testing.assert_allclose(getattr(c, joint), getattr(frame, joint), atol=1e-5)  # Euler round trip
    a.ShowFrame(2).apply(session)  # on the timeline the render takes the capture's own camera, scaled
    cam = session.render_camera(64)
    fx, fy, cx, cy = files.capture.intrinsics
    s = 64 / files.capture.width
    np.testing.assert_allclose(cam.intrinsics, (fx * s, fy * s, cx * s, cy * s), rtol=1e-6)
    np.testing.assert_allclose(cam.view, np.linalg.inv(files.capture.frames[2].camera_to_world), atol=1e-9)
    a.ShowFrame(99).apply(session)  # past the capture: the sliders
    assert session.timeline_frame == -1
    orbit = session.view.camera(session.avatar.head_model.template, 64, 64)
    np.testing.assert_allclose(session.render_camera(64).view, orbit.view)


def test_a_capture_frame_never_warns_that_it_is_beyond_the_captured_views(session, files, monkeypatch):
    """The warning weighs the orbit camera's yaw about the head (the camera's less the head's) against the captured
    yaws and a 10 degree margin; a capture frame is shown from its own camera, whatever the orbit camera holds."""
    narrow = {"yaw_deg": [-5.0, 5.0], "pitch_deg": [-5.0, 5.0]}
    monkeypatch.setattr(files, "avatar", dataclasses.replace(files.avatar, view_range=narrow))
    a.SetView(yaw_deg=14.0).apply(session)  # 14 - 0 = 14 <= 5 + 10
    assert views_warning(session) == ""
    a.SetView(yaw_deg=40.0).apply(session)  # 40 > 15
    assert views_warning(session).startswith("beyond the captured views (yaw -5 to 5 degrees)")
    a.SetAngles("head", (30.0, 0.0, 0.0)).apply(session)  # 40 - 30 = 10: the head turned with the camera
    assert views_warning(session) == ""
    a.SetAngles("head", (-30.0, 0.0, 0.0)).apply(session)  # 40 + 30 = 70
    assert views_warning(session) != ""
    weighed_as_before = 0  # frames the orbit camera and the frame's sliders put beyond the views (what warned)
    for k in range(len(files.capture.frames)):  # the sliders move to each frame's head, the camera stays at 40
        a.ShowFrame(k).apply(session)
        assert views_warning(session) == "", k
        weighed_as_before += files.avatar.views_beyond(session.view.yaw_deg - float(session.sliders.head[0]))
    assert weighed_as_before >= len(files.capture.frames) // 2  # 6 of these 7 frames warned before
    a.ShowFrame(-1).apply(session)
    a.SetAngles("head", (0.0, 0.0, 0.0)).apply(session)  # the sliders again: the orbit camera is weighed again
    assert views_warning(session) != ""
    monkeypatch.setattr(files, "avatar", dataclasses.replace(files.avatar, view_range=None))  # views unknown
    assert views_warning(session) == ""


def test_camera_actions(session):
    v = session.view
    assert (v.yaw_deg, v.pitch_deg) == (20.0, 5.0)
    a.Orbit(100.0, 0.0).apply(session)  # 0.4 degrees a pixel, dragging right turns the camera left
    assert v.yaw_deg == pytest.approx(-20.0) and session.dirty
    a.Orbit(-500.0).apply(session)  # -20 + 200 = 180, wrapped to [-180, 180)
    assert v.yaw_deg == pytest.approx(-180.0)
    a.Orbit(0.0, 1000.0).apply(session)
    assert v.pitch_deg == 85.0  # clamped short of the pole
    for _ in range(40):
        a.Zoom(3.0).apply(session)
    assert session.view.zoom == 8.0
    a.ResetView().apply(session)
    before = session.view.camera(session.avatar.head_model.template, 64, 64)
    a.Pan(10.0, 0.0, 64).apply(session)
    pan = session.view.pan
    forward = -np.linalg.inv(before.view)[:3, 2]
    assert np.linalg.norm(pan) > 0 and abs(float(pan @ forward)) < 1e-6  # in the image plane
    a.SetView(fov_deg=30.0).apply(session)
    assert session.view.fov_deg == 30.0 and session.view.yaw_deg == 20.0


def test_buffers_render_again_only_when_first_asked_for(session):
    a.ShowBuffer("normals").apply(session)  # a render makes what it shows: the colour's has no normals
    assert session.dirty and session.display.buffer == "normals"
    session.dirty = False
    a.ShowBuffer("depth").apply(session)  # every render has depth
    assert not session.dirty
    a.ShowBuffer("shading").apply(session)  # made of the render with normals to the viewer: a new render
    assert session.dirty
    session.dirty = False
    a.ShowBuffer("rgb_light").apply(session)  # the request already asked for every inspection buffer
    assert not session.dirty
    a.ShowBuffer("rgb").apply(session)
    assert not session.dirty
    a.SetDisplay({"layout": "over", "overlay_alpha": 0.25}).apply(session)
    assert (session.display.layout, session.display.overlay_alpha, session.dirty) == ("over", 0.25, False)
    with pytest.raises(ValueError, match="no display setting"):
        a.SetDisplay({"neural_size": 4}).apply(session)
    a.RefineTo("preview").apply(session)
    assert session.display.refine_to == "preview" and session.dirty
    session.dirty = False
    a.ShowAtSize(203).apply(session)  # shown larger: rendered at the size shown, in steps of 8 px
    assert session.display.neural_size == 200 and session.dirty
    session.dirty = False
    a.ShowAtSize(205).apply(session)  # the same render size: nothing to render again
    assert not session.dirty
    a.ShowAtSize(900).apply(session)
    assert session.display.neural_size == 256 and session.dirty  # the live limit; shown scaled up


def test_messages_keep_the_last_eight(session):
    for k in range(11):
        a.Report(f"message {k}").apply(session)
    assert session.errors == [f"message {k}" for k in range(3, 11)]
    a.ClearMessages().apply(session)
    assert session.errors == []


def test_every_documented_script_step_is_in_the_table():
    from app.studio import script

    documented = set(re.findall(r'^  \{"(\w+)"', script.__doc__, re.M))
    assert documented == set(script.STEPS), documented ^ set(script.STEPS)


def test_commands_carried_out_by_the_application(tmp_path, files):
    """Opening (a folder that is not an avatar, then the demo), training on a folder that is not a capture, a
    turntable to a file that is not an mp4: each ends as the window would show it, with no window."""
    from app.studio.app import Studio
    from app.studio.config import StudioConfig
    from app.turntable import TurntableConfig

    studio = Studio(StudioConfig())
    try:
        def settle() -> None:
            for _ in range(600):
                studio.poll_opening()
                if studio.opening is None:
                    return
                time.sleep(0.05)
            raise AssertionError("the avatar never finished opening")

        studio.act(a.OpenAvatar(tmp_path / "nothing"))
        assert studio.session.opening == tmp_path / "nothing"
        settle()
        assert studio.session.avatar is None and str(tmp_path / "nothing") in studio.session.errors[-1]
        studio.act(a.OpenAvatar(DEMO))
        settle()
        assert studio.session.folder == DEMO and studio.session.avatar.name == "primitives"
        before = list(studio.session.errors)
        studio.act(a.StartTraining(str(tmp_path), str(tmp_path / "out")))
        assert str(tmp_path) in studio.session.job_message and not studio.jobs.jobs  # in the Jobs panel
        assert studio.session.errors == before  # not among the Avatar panel's messages
        studio.act(a.ExportTurntable(TurntableConfig(DEMO, tmp_path / "turn.avi")))
        assert studio.session.errors[-1].endswith("the turntable is written as an .mp4")
        assert not studio.exporter.running
        studio.act(a.SaveViewport(tmp_path / "v.png"))
        assert studio.session.errors[-1] == "nothing shown yet to save"
    finally:
        studio.close()
