"""The studio window, real, under Xvfb: scripted runs (app/studio/script.py) act through the widgets' own
code while the window draws; the tests read back pixels, files and the measured figures."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from PIL import Image

from tests.conftest import xvfb

REPO = Path(__file__).resolve().parents[3]
pytestmark = pytest.mark.gl


@pytest.fixture(scope="module")
def display():
    with xvfb(":88", "1920x1200x24") as disp:  # room for a 1920x1080 window
        yield disp


@pytest.fixture(scope="module")
def capture(synth_capture) -> Path:
    return synth_capture("sun", 16, 32)


@pytest.fixture(scope="module")
def avatar(capture, gl, tmp_path_factory) -> Path:
    from models.training.trainer import TrainConfig, prepare_training

    out = tmp_path_factory.mktemp("studio") / "avatar"
    t = prepare_training(TrainConfig(dataset=capture, out=out, effects="all", steps=40, rays_per_step=256,
                            checkpoint_seconds=1e9), gl)
    t.run(gl)
    return out


def studio(display: str, home: Path, *args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    env = {**os.environ, "DISPLAY": display, "HOME": str(home)}
    r = subprocess.run([sys.executable, "-m", "app.cli", "studio", *args], cwd=REPO, env=env, capture_output=True,
                       text=True, timeout=timeout)
    assert r.returncode == 0, r.stdout + r.stderr
    return r


def run_script(display: str, tmp_path: Path, avatar: Path, steps: list[dict], size: str = "1280x800") -> dict:
    script = tmp_path / "script.json"
    report = tmp_path / "report.json"
    script.write_text(json.dumps({"report": str(report), "steps": steps}))
    width, height = size.split("x")
    studio(display, tmp_path, str(avatar), "--script", str(script), "--width", width, "--height", height)
    return json.loads(report.read_text())


def failed_run(display: str, home: Path, avatar: Path, steps: list[dict]) -> tuple[int, list[str]]:
    """A scripted run that should fail: its exit status and its stderr's lines."""
    script = home / "script.json"
    script.write_text(json.dumps({"steps": steps}))
    env = {**os.environ, "DISPLAY": display, "HOME": str(home)}
    r = subprocess.run([sys.executable, "-m", "app.cli", "studio", str(avatar), "--script", str(script)], cwd=REPO,
                       env=env, capture_output=True, text=True, timeout=600)
    return r.returncode, r.stderr.splitlines()


def viewport_images(report: dict, shot: np.ndarray) -> dict[str, np.ndarray]:
    """The images of a "save_viewport" picture, cut where the report says the viewport drew them."""
    x0, y0 = report["viewport"]["rect"][:2]
    return {name: shot[y - y0:y - y0 + h, x - x0:x - x0 + w] for name, (x, y, w, h) in
            report["viewport"]["images"].items()}


def test_expression_slider_changes_the_face(display, avatar, tmp_path):
    a, b = tmp_path / "a.png", tmp_path / "b.png"
    wa, wb = tmp_path / "wa.png", tmp_path / "wb.png"
    shot = tmp_path / "viewport.png"
    steps = [
        {"refine_to": "preview"}, {"wait_render": "preview"}, {"save_neural": str(a)}, {"screenshot": str(wa)},
        {"expression": "mouthStretch", "value": 1.5}, {"jaw_open_deg": 25},
        {"wait_render": "preview"}, {"record_latency": True}, {"save_neural": str(b)}, {"screenshot": str(wb)},
        {"save_viewport": str(shot)}, {"wait_frames": 2}]
    report = run_script(display, tmp_path, avatar, steps)
    assert report["steps_run"] == len(steps)  # none skipped (a screenshot once ended two steps)
    na, nb = (np.asarray(Image.open(p), np.int16) for p in (a, b))
    # The render follows the space the 1280x800 window leaves it beside the guide (about 250 px across): rendered
    # at that size, in steps of 8 px, up to the live limit of 256 (160 px whatever the window, before).
    assert na.shape == nb.shape and na.shape[0] == na.shape[1] and na.shape[0] % 8 == 0 and 200 <= na.shape[0] <= 256
    changed = (np.abs(na - nb).max(-1) > 10).mean()
    print("neural pixels changed:", changed, "report:", report)
    assert changed > 0.005  # the mouth region moves
    sa, sb = (np.asarray(Image.open(p), np.int16) for p in (wa, wb))
    assert sa.shape == (800, 1280, 3)
    assert (np.abs(sa - sb).max(-1) > 10).mean() > 0.002  # the guide mesh and the render, in the window
    assert report["errors"] == [] and report["fps_idle"] + report["fps_rendering"] > 0
    assert report["latency_ms"] is not None
    # The window's frame on a software GL, its drawing threads' CPU included: 8.5 ms on the Intel Xeon with one
    # sample a pixel, 25 ms with hello_imgui's default of 8 (run_studio asks for one: docs/live.md); 16.0 ms with one
    # on the slower AMD EPYC (a clean clone's CI there, 27 November), where the bound of 16 failed it.
    assert report["frame_cpu_ms_median"] < 22, report["frame_cpu_ms_median"]
    moved = report["latencies"][0]  # the move's passes: the first pixels no later than the preview's
    assert 0 < moved["first"] <= moved["preview"] and moved.get("draft", moved["preview"]) <= moved["preview"], moved
    assert 0 < moved["preview render"] < moved["preview"], moved  # the render is part of the wait for its pixels
    # "Screenshot viewport": the guide and the render, as the window shows them (not the render alone): at 1280x800
    # the viewport is taller than wide, so one above the other (a column shows them larger than a row).
    view = np.asarray(Image.open(shot), np.int16)
    images = viewport_images(report, view)
    assert set(images) == {"guide", "neural"}
    assert view.shape[0] > 2 * images["guide"].shape[0] > 320, view.shape
    assert images["guide"].shape == images["neural"].shape and images["guide"].shape[0] == images["guide"].shape[1]
    assert images["guide"].std() > 5 and images["neural"].std() > 5
    small = [np.asarray(Image.fromarray(im.astype(np.uint8)).resize((32, 32)), np.float64)
             for im in (images["neural"], nb)]
    assert np.abs(small[0] - small[1]).mean() < 6  # the render saved is the one shown (scaled up, linear filter)


def test_shadow_buffers_in_the_viewport(display, avatar, capture, tmp_path):
    """With the head turned and the jaw open: the render without cast shadows is nowhere darker than the
    render, the light reaching the surface is white off the head and darker somewhere on it, as shown. Then a
    capture frame on the timeline: the captured image is shown beside the guide and the render."""
    shots = {b: tmp_path / f"{b}.png" for b in ("rgb", "rgb_no_shadows", "rgb_light")}
    steps = [{"head": [35, -10, 0]}, {"jaw_open_deg": 20}]
    for b, path in shots.items():
        steps += [{"buffer": b}, {"refine_to": "preview"}, {"wait_render": "preview"}, {"save_neural": str(path)}]
    timeline = tmp_path / "timeline.png"
    steps += [{"buffer": "rgb"}, {"timeline": 2}, {"wait_render": "preview"}, {"save_viewport": str(timeline)},
              {"wait_frames": 2}]
    report = run_script(display, tmp_path, avatar, steps)
    assert report["errors"] == []
    rgb, without, light = (np.asarray(Image.open(shots[b]), np.int16) for b in shots)
    assert rgb.shape == without.shape == light.shape and 200 <= rgb.shape[0] <= 256
    assert (without >= rgb - 1).all()  # uint8 rounding
    assert (light[0, 0] == 255).all() and light.min() < 255
    images = viewport_images(report, np.asarray(Image.open(timeline)))
    assert set(images) == {"guide", "neural", "capture"}  # guide, render, captured image
    from models.capture.dataset import load_split

    frame = load_split(capture, "train").frames[2]
    truth = np.asarray(Image.open(frame.image_path).convert("RGB").resize((24, 24)), np.float64)
    shown = np.asarray(Image.fromarray(images["capture"]).resize((24, 24)), np.float64)
    assert np.abs(shown - truth).mean() < 12  # the capture's own frame, as the window shows it


def test_script_mistakes_end_on_one_line_with_status_2(display, avatar, tmp_path, monkeypatch, capsys):
    """A wrong step is one line naming it (steps[INDEX] (ACTION)) and exit status 2, before the window opens:
    "wait_render": true once ended in a ValueError's traceback, a gaze of three numbers in a broadcast error. In
    this process, through the command line's main (no window opens; test_jobs_end_with_the_window sees a studio
    process end with status 2)."""
    from app.cli import main

    monkeypatch.setenv("DISPLAY", display)
    script = tmp_path / "script.json"
    for steps, line in [
        ([{"wait_frames": 1}, {"wait_render": True}],
         "steps[1] (wait_render): one of draft, preview or final, not true"),
        ([{"gaze": [10, 0, 0]}], "steps[0] (gaze): a list of 2 numbers (yaw, pitch in degrees), not [10, 0, 0]"),
    ]:
        script.write_text(json.dumps({"steps": steps}))
        assert main(["studio", str(avatar), "--script", str(script)]) == 2
        stderr = capsys.readouterr().err.splitlines()
        assert stderr == [f"avatar-studio studio: error: {script}: {line}"], stderr


def non_background(image: np.ndarray, colour, tolerance: int = 12) -> np.ndarray:
    """(H,W) bool: the pixels that differ from a flat colour by more than `tolerance` in some channel."""
    return (np.abs(image.astype(np.int16) - np.asarray(colour, np.int16)).max(-1) > tolerance)


@pytest.mark.parametrize("size", ["1280x800", "1920x1080"])
def test_the_viewport_images_fill_the_space_the_window_gives_them(display, avatar, tmp_path, size):
    """At two window sizes the guide and the render, square, take the viewport's space below its toolbar: what
    they draw (the pixels that are not the window's background, read back from a screenshot) spans at least 90% of
    its width or of its height, centred. And a save_neural right after the avatar opens waits for a render: the
    picture written holds the head, not only the background."""
    first, shot = tmp_path / "first.png", tmp_path / "window.png"
    report = run_script(display, tmp_path, avatar, [
        {"save_neural": str(first)}, {"refine_to": "preview"}, {"wait_render": "preview"}, {"wait_frames": 2},
        {"screenshot": str(shot)}], size=size)
    assert report["errors"] == [], report["errors"]
    background = np.asarray(json.loads((avatar / "avatar.json").read_text())["background"], np.float64)
    neural = np.asarray(Image.open(first))
    assert neural.shape[0] == neural.shape[1] >= 64
    assert 0.05 < non_background(neural, np.round(255 * background)).mean() < 0.95  # the head on its background
    window = np.asarray(Image.open(shot))
    assert window.shape == (int(size.split("x")[1]), int(size.split("x")[0]), 3)
    x, y, w, h = report["viewport"]["space"]
    assert 500 < w and 600 < h  # below the toolbar, between the side panels
    clear = window[y + h - 2, x + 2]  # a corner the images leave: the window's own background
    drawn = non_background(window[y:y + h, x:x + w], clear, tolerance=3)
    rows, cols = np.nonzero(drawn.any(1))[0], np.nonzero(drawn.any(0))[0]
    spans = ((rows[-1] - rows[0] + 1) / h, (cols[-1] - cols[0] + 1) / w)
    print(size, "viewport space", (w, h), "drawn spans (height, width)", spans, report["viewport"]["images"])
    assert max(spans) >= 0.9, spans
    centre = ((rows[0] + rows[-1]) / 2 - h / 2, (cols[0] + cols[-1]) / 2 - w / 2)
    assert abs(centre[0]) <= 0.03 * h and abs(centre[1]) <= 0.03 * w, centre  # centred
    for _, _, iw, ih in report["viewport"]["images"].values():
        assert iw == ih  # the square renders keep their aspect


def test_timeline_frames_never_warn_about_views(display, avatar, tmp_path):
    """An avatar whose capture saw the head only from the front (yaw -1 to 1 degrees here): the orbit camera at 40
    degrees warns, but each capture frame on the timeline, shown from its own camera, never does (the frames'
    heads turn, and the warning once weighed the orbit camera against them)."""
    import shutil

    front = tmp_path / "front_avatar"
    shutil.copytree(avatar, front)
    meta = json.loads((front / "avatar.json").read_text())
    meta["view_range"] = {"yaw_deg": [-1.0, 1.0], "pitch_deg": [-1.0, 1.0]}
    (front / "avatar.json").write_text(json.dumps(meta))
    steps = [{"view": {"yaw_deg": 40.0}}, {"expect_warning": "beyond the captured views (yaw -1 to 1 degrees)"}]
    for k in (0, 5, 11):
        steps += [{"timeline": k}, {"expect_warning": None}]
    steps += [{"wait_render": "draft"}, {"expect_warning": None}, {"timeline": -1}, {"reset": "head"},
              {"expect_warning": "beyond the captured views"}]
    report = run_script(display, tmp_path, front, steps)
    assert report["steps_run"] == len(steps) and report["errors"] == []


def test_errors_training_job_and_turntable(display, avatar, capture, tmp_path):
    mp4 = tmp_path / "turn.mp4"
    job_out = tmp_path / "job"
    report = run_script(display, tmp_path, avatar, [
        {"open": str(tmp_path / "not_an_avatar")},
        {"expect_error": "no such avatar folder"},
        {"train": {"dataset": str(tmp_path / "missing"), "out": str(job_out)}},
        {"expect_error": "missing"},
        {"train": {"dataset": str(capture), "out": str(job_out), "steps": 20, "effects": "none"}},
        {"wait_frames": 30},
        {"wait_job": True},
        {"open_job": True},
        {"export": {"out": str(mp4), "frames": 8, "size": 64, "preset": "draft"}},
        {"wait_export": True},
        {"wait_frames": 5}])
    # The studio is still up after the errors, the job ran in its own process and its avatar opened.
    progress = [json.loads(x) for x in (job_out / "progress.jsonl").read_text().splitlines()]
    assert progress[-1]["step"] == 20 and report["frames"]["training"] > 0
    assert report["fps_training"] > 0
    cap = cv2.VideoCapture(str(mp4))
    fourcc = int(cap.get(cv2.CAP_PROP_FOURCC)).to_bytes(4, "little").decode().lower()
    frames = []
    while True:
        ok, f = cap.read()
        if not ok:
            break
        frames.append(f)
    assert len(frames) == 8 and frames[0].shape == (64, 64, 3)  # the size asked for, whatever the preset renders
    assert fourcc in ("h264", "avc1")
    assert len(list((tmp_path / "turn").glob("frame_*.png"))) == 8


def test_jobs_end_with_the_window(display, avatar, capture, tmp_path):
    """A job the window started does not outlive it unless the user chose so: here the script fails (an error
    that never comes) while a 10-minute job runs, the studio exits 2 with one line naming the step, and no trainer
    of that job is left."""
    job_out = tmp_path / "long_job"
    status, stderr = failed_run(display, tmp_path, avatar, [
        {"train": {"dataset": str(capture), "out": str(job_out), "minutes": 10, "effects": "none"}},
        {"wait_frames": 30},
        {"expect_error": "an error nobody reports"}])
    assert status == 2 and stderr[-1].startswith(
        f"avatar-studio studio: error: {tmp_path / 'script.json'}: steps[2] (expect_error): no message containing "
        "'an error nobody reports'"), stderr
    assert not any("Traceback" in line for line in stderr), stderr
    left = subprocess.run(["pgrep", "-f", f"train .*{job_out}"], capture_output=True, text=True)
    assert left.stdout.strip() == "", f"trainer still running: {left.stdout}"


def test_new_avatar_from_video(display, avatar, tmp_path, face_video, landmarker, ict_npz):
    """"New avatar from video": one job tracks the real video, then trains the model chosen on it; the tracker's
    report and the avatar are written and the studio opens the avatar when the job is done."""
    out = tmp_path / "me"
    report = run_script(display, tmp_path, avatar, [
        {"from_video": {"video": str(face_video), "head": f"ict:{ict_npz}", "landmarker": str(landmarker),
                        "out": str(out), "steps": 10, "size": 96, "fps": 2, "model": "primitives"}},
        {"wait_frames": 10},
        {"wait_job": True},
        {"wait_frames": 3},
        {"expect_open": str(out)}])  # a failed step makes the studio exit non-zero: run_script asserts it
    assert report["frames"]["training"] > 0
    tracked = json.loads((tmp_path / "me_dataset" / "tracking" / "report.json").read_text())
    assert tracked["frames_kept"] > 20  # of the 24 that 2 a second of its 11.8 s make
    assert json.loads((out / "progress.jsonl").read_text().splitlines()[-1])["step"] == 10
    assert json.loads((out / "avatar.json").read_text())["model"] == "primitives"  # the model chosen above
    # While the script waits on the job the window idles (StudioConfig.idle_fps, 9 a second; 58.5 with
    # --idle-fps 0), so the job has the cores: the frames while it ran mix those idle ones with the first render's.
    assert 0 < report["fps_training"] < 15, report["fps_training"]


def test_no_display_is_one_line_and_status_2(tmp_path):
    """No DISPLAY: one line naming the problem, exit status 2, no window; a DISPLAY where no X server answers is
    named too."""
    from app.studio.display import display_problem

    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    r = subprocess.run([sys.executable, "-m", "app.cli", "studio", "--screenshot", str(tmp_path / "w.png")],
                       cwd=REPO, env=env, capture_output=True, text=True, timeout=120)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and "DISPLAY is not set" in lines[0], r.stderr
    assert not (tmp_path / "w.png").exists()
    assert display_problem({"DISPLAY": ":197"}) == ("the display :197 (DISPLAY) does not answer: no window can open "
                                                    "there")
    assert display_problem({"WAYLAND_DISPLAY": "wayland-0"}) is None  # GLFW tells there


def test_screenshot_option(display, avatar, tmp_path):
    shot = tmp_path / "window.png"
    studio(display, tmp_path, str(avatar), "--screenshot", str(shot), "--frames", "20", "--width", "1024",
           "--height", "700")
    img = np.asarray(Image.open(shot))
    assert img.shape == (700, 1024, 3) and img.std() > 10


def test_keyframes_play_and_export(display, avatar, tmp_path):
    """The Animation tab through the window: a smile keyed at 0 s (rest) and 1 s (0.8) with the jaw open, the
    sliders in between at the smooth curve's value, the file saved and loaded back, playback moving the time on,
    and the export an mp4 of the animation's frames."""
    anim_file, mp4 = tmp_path / "anim.json", tmp_path / "anim.mp4"
    report = run_script(display, tmp_path, avatar, [
        {"wait_render": "draft"}, {"seek": 1.0}, {"expression": 0, "value": 0.8}, {"jaw_open_deg": 20},
        {"key": True}, {"seek": 0.25}, {"save_animation": str(anim_file)}, {"load_animation": str(anim_file)},
        {"play": True}, {"wait_frames": 30}, {"play": False},
        {"export_animation": {"out": str(mp4), "size": 32, "preset": "draft"}}, {"wait_export": True}])
    assert report["errors"] == [], report["errors"]
    saved = json.loads(anim_file.read_text())
    tracks = saved["tracks"]
    smile = [c for c in tracks if c.startswith("expression.")]
    assert len(smile) == 1 and tracks[smile[0]] == [[0.0, 0.0], [1.0, 0.8]]  # keyed from rest at 0 s
    assert tracks["jaw.open"] == [[0.0, 0.0], [1.0, 20.0]] and set(tracks) == {smile[0], "jaw.open"}
    assert report["animation"] == saved  # loaded back as saved
    assert report["anim_time"] != 0.25 and report["fps_playing"] > 0  # playback moved on, the window drew
    cap = cv2.VideoCapture(str(mp4))
    n = 0
    while cap.read()[0]:
        n += 1
    assert n == round(saved["duration_s"] * saved["fps"])  # the animation's frames, at its rate


def test_undo_reset_poses_and_a_performance_on_the_timeline(display, tmp_path, face_video, landmarker):
    """Through the window, on the demo: a pose saved and recalled, group resets, undo and redo; then 0.8 s of
    a real video reenacted as a job, whose animation lands on the timeline when it is done."""
    from app.animation import load_animation
    from tests.conftest import BUILTIN_AVATAR as DEMO  # the built-in head's names and jaw joint

    mp4 = tmp_path / "perf.mp4"
    report = run_script(display, tmp_path, DEMO, [
        {"wait_render": "draft"}, {"expression": "smile_L", "value": 0.8}, {"jaw_open_deg": 14},
        {"save_pose": "grin"}, {"reset": "expression:mouth"}, {"reset": "jaw"},
        {"record_sliders": True}, {"undo": True}, {"record_sliders": True}, {"undo": True}, {"record_sliders": True},
        {"redo": True}, {"record_sliders": True}, {"reset": "expression"}, {"reset": "jaw"}, {"recall_pose": "grin"},
        {"record_sliders": True},
        {"reenact": {"video": str(face_video), "landmarker": str(landmarker), "out": str(mp4), "size": 64,
                     "seconds": 0.8}},
        {"wait_frames": 5}, {"wait_job": True}, {"wait_frames": 5}, {"seek": 0.5}, {"record_sliders": True}])
    assert report["errors"] == [], report["errors"]
    assert report["poses"] == ["grin"]
    log = report["sliders_log"]
    smile = [s["expression"][0] for s in log[:5]]  # smile_L is the built-in head's first expression
    jaw = [s["jaw_open_deg"] for s in log[:5]]
    # reset mouth and jaw | undo: the jaw back | undo: the smile back | redo: the smile reset again | the pose
    assert smile == [0.0, 0.0, 0.8, 0.0, 0.8] and jaw == [0.0, 14.0, 14.0, 14.0, 14.0]
    poses = json.loads((tmp_path / ".config" / "avatar-studio" / "poses.json").read_text())
    assert poses["avatars"][str(DEMO.resolve())]["grin"]["jaw.open"] == 14.0
    saved = json.loads(mp4.with_suffix(".json").read_text())
    assert report["animation"] == saved and any(c.startswith("expression.") for c in saved["tracks"])
    anim = load_animation(mp4.with_suffix(".json"))  # the timeline at 0.5 s: the performance's values there
    assert log[5]["jaw_open_deg"] == pytest.approx(anim.value("jaw.open", 0.5), abs=1e-4)
    assert log[5]["expression"][0] == pytest.approx(anim.value("expression.smile_L", 0.5), abs=1e-4)
