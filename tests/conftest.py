"""Shared fixtures: the real data in ../shared (skipped clearly when absent) and a headless GL context."""

from __future__ import annotations

import shutil
import subprocess
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"
ICT_NPZ = SHARED_DATA / "ict_facekit" / "ict_head.npz"
LANDMARKER = SHARED_DATA / "mediapipe" / "face_landmarker_v2_with_blendshapes.task"
FACE_VIDEO = SHARED_DATA / "video" / "expressions_d3.mp4"
DEMO = REPO / "resources" / "demo_avatar"  # what the studio opens: a primitives avatar
CODYNERF_DEMO = REPO / "resources" / "codynerf_avatar"  # the CoDyNeRF avatar shipped beside it
BUILTIN_AVATAR = REPO / "resources" / "builtin_avatar"  # a primitives avatar of the built-in head (jaw and neck joints)


@pytest.fixture(scope="session", autouse=True)
def _config_folder_of_the_run(tmp_path_factory) -> Iterator[Path]:
    """What the program remembers for its user (app/user_config.py: a --landmarker that worked) goes to a folder of
    the test run's, never the real home's; the commands that tests run in subprocesses inherit it."""
    with pytest.MonkeyPatch.context() as mp:
        folder = tmp_path_factory.mktemp("xdg_config")
        mp.setenv("XDG_CONFIG_HOME", str(folder))
        yield folder


@pytest.fixture(scope="session")
def ict_npz() -> Path:
    if not ICT_NPZ.is_file():
        pytest.skip(f"ICT-FaceKit data not found at {ICT_NPZ} (../shared is absent)")
    return ICT_NPZ


@pytest.fixture(scope="session")
def landmarker() -> Path:
    if not LANDMARKER.is_file():
        pytest.skip(f"MediaPipe's face landmarker bundle not found at {LANDMARKER} (../shared is absent)")
    return LANDMARKER


@pytest.fixture(scope="session")
def face_video() -> Path:
    if not FACE_VIDEO.is_file():
        pytest.skip(f"the face video not found at {FACE_VIDEO} (../shared is absent)")
    return FACE_VIDEO


@pytest.fixture(scope="session")
def ict_model(ict_npz):
    from models.head.ict import load_ict_npz

    return load_ict_npz(ict_npz)


@pytest.fixture(scope="session")
def builtin_model():
    from models.head.sources import load_builtin

    return load_builtin()


@pytest.fixture(scope="session")
def one_second_scan(tmp_path_factory, face_video, landmarker) -> Path:
    """The face video's first second tracked with the built-in head at 64 px (`track` as a user runs it, no overlay):
    a small real capture, made once for the tests that only read it."""
    from app.cli import main

    scan = tmp_path_factory.mktemp("one_second") / "real_person"
    assert main(["track", str(face_video), "--out", str(scan), "--size", "64", "--seconds", "1",
                 "--landmarker", str(landmarker), "--no-overlay"]) == 0
    return scan


@pytest.fixture(scope="session")
def gl():
    from render.gl.context import GLContext

    ctx = GLContext.headless()
    yield ctx
    ctx.release()


@pytest.fixture(scope="module")
def synth_capture(tmp_path_factory, gl):
    """make(scene, frames, size, hair="none"): a small synthetic capture of the built-in head, made once per module.
    Bald unless asked: the models' machinery (samplers, losses, views, the bench's settings) is tested on the head
    model's own surface, which their figures were worked out on; people with hair are tested in
    tests/models/capture/test_people.py and through the demo avatar."""
    from models.capture.synthetic import SynthConfig, synthesize
    from models.head.sources import load_builtin

    def make(scene: str, frames: int, size: int, hair: str = "none") -> Path:
        out = tmp_path_factory.mktemp("capture") / f"{scene}_{frames}_{size}_{hair}"
        synthesize(SynthConfig(scene=scene, frames=frames, size=size, out=out, hair=hair), load_builtin(), gl)
        return out

    return make


@contextmanager
def xvfb(display: str, screen: str) -> Iterator[str]:
    """An X server for window tests (skipped where Xvfb is not installed); yields its DISPLAY."""
    if shutil.which("Xvfb") is None:
        pytest.skip("Xvfb is not installed (make test installs it when run as root)")
    proc = subprocess.Popen(["Xvfb", display, "-screen", "0", screen, "-nolisten", "tcp"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        yield display
    finally:
        proc.terminate()
        proc.wait()
