"""--size is the size of the file written: the demo avatar's presets render 0.375 (preview) and 0.25 (draft) of the
pixels asked for, and render, turntable, animate and reenact scale their images up to exactly --size. Each file is
read back (PNG with PIL, mp4 with OpenCV)."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from app.animation import Animation, save_animation
from app.cli import main
from models.avatars.rendering import RenderOptions, preset_options, render_image
from tests.app.videos import mp4_frames, psnr
from tests.conftest import DEMO

pytestmark = pytest.mark.gl

SIZE = 40
"""Asked for: the demo's preview renders 16 px of it (40 x 0.375 = 15, made even), its draft 10."""


@pytest.fixture(scope="module")
def demo():
    from models.avatars.registry import load_avatar

    avatar, _ = load_avatar(DEMO)
    # the test means something only where the presets render fewer pixels than asked for
    assert preset_options(avatar.card, "preview", SIZE)[1] == 16 and preset_options(avatar.card, "draft", SIZE)[1] == 10
    return avatar


def test_render_writes_the_size_asked_for(demo, tmp_path, gl):
    """The PNG is SIZE x SIZE, and it is the preset's 16 px render scaled up: box-filtered back down to 16 px it
    matches that render."""
    from models.head.controls import Controls
    from render.camera import framing_camera
    from render.gl.raster import Rasterizer

    out = tmp_path / "r.png"
    assert main(["render", str(DEMO), "--size", str(SIZE), "--out", str(out)]) == 0
    img = Image.open(out)
    assert img.size == (SIZE, SIZE)
    options, px = preset_options(demo.card, "preview", SIZE, RenderOptions(buffers=()))
    cam = framing_camera(demo.card.rest_vertices(), 0.0, 0.0, fov_y_deg=18.0, width_px=px, height_px=px)
    small = render_image(demo, cam, demo.card.at_rest(Controls()), options, Rasterizer(gl))["rgb"]
    small = (np.clip(small, 0, 1) * 255).round().astype(np.uint8)
    assert psnr(np.asarray(img.convert("RGB").resize((px, px), Image.Resampling.BOX)), small) > 27


def test_turntable_writes_the_size_asked_for(tmp_path):
    out = tmp_path / "t.mp4"
    assert main(["turntable", str(DEMO), "--size", str(SIZE), "--frames", "2", "--out", str(out)]) == 0
    frames = mp4_frames(out)
    assert len(frames) == 2 and all(f.shape == (SIZE, SIZE, 3) for f in frames)
    assert Image.open(tmp_path / "t" / "frame_0001.png").size == (SIZE, SIZE)


def test_animate_writes_the_size_asked_for(tmp_path):
    jaw = Animation(fps=4, duration_s=0.5, tracks={"expression.jawOpen": ((0.0, 0.0), (0.5, 0.8))})
    save_animation(jaw, tmp_path / "a.json")
    out = tmp_path / "a.mp4"
    assert main(["animate", str(DEMO), str(tmp_path / "a.json"), "--size", str(SIZE), "--preset", "draft",
                 "--out", str(out), "--no-pngs"]) == 0
    frames = mp4_frames(out)
    assert len(frames) == 2 and all(f.shape == (SIZE, SIZE, 3) for f in frames)


def test_reenact_writes_the_size_asked_for(tmp_path, synth_capture, capsys):
    """A capture drives the demo: the avatar's frames are SIZE x SIZE, the driver's beside them as large."""
    capture = synth_capture("ambient", 10, 32)
    out = tmp_path / "r.mp4"
    assert main(["reenact", str(DEMO), str(capture), "--size", str(SIZE), "--fps", "10", "--seconds", "0.2",
                 "--out", str(out)]) == 0
    assert all(f.shape == (SIZE, 2 * SIZE, 3) for f in mp4_frames(out))
    alone = tmp_path / "alone.mp4"
    assert main(["reenact", str(DEMO), str(capture), "--size", str(SIZE), "--fps", "10", "--seconds", "0.2",
                 "--no-side-by-side", "--out", str(alone)]) == 0
    assert [f.shape for f in mp4_frames(alone)] == [(SIZE, SIZE, 3)] * 2
    capsys.readouterr()


@pytest.mark.parametrize("command", ["turntable", "animate", "reenact"])
def test_an_odd_video_size_is_refused_before_any_work(command, tmp_path, capsys):
    """H.264 frames have even sides: an odd --size is exit status 2, one line, nothing written."""
    args = {"turntable": [], "animate": [str(tmp_path / "a.json")], "reenact": [str(tmp_path / "capture")]}[command]
    save_animation(Animation(fps=4, duration_s=0.5), tmp_path / "a.json")
    assert main([command, str(DEMO), *args, "--size", "41", "--out", str(tmp_path / "v.mp4")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "--size 41" in err and "even" in err
    assert not (tmp_path / "v.mp4").exists() and not (tmp_path / "v").exists()
