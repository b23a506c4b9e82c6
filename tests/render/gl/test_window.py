"""The same GLContext attached to a real window (glfw under Xvfb): the preview drawn there and shown on
the window's screen reads back the same pixels as the headless context.

The window runs in its own process, as the studio does: a thread cannot have an EGL context (the
headless one the other tests use) and a GLX context current at once.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from render.camera import framing_camera
from render.gl.preview import MeshFrame, PreviewRenderer, PreviewSettings
from tests.conftest import xvfb

SIZE = 96
REPO = Path(__file__).resolve().parents[3]

WINDOW_SCRIPT = r"""
import sys, time
import glfw, numpy as np
from models.head.sources import load_builtin
from render.camera import framing_camera
from render.gl.context import GLContext
from render.gl.preview import MeshFrame, PreviewRenderer, PreviewSettings
size, out = int(sys.argv[1]), sys.argv[2]
for _ in range(50):
    if glfw.init():
        break
    time.sleep(0.1)
glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, 3)
glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, 3)
glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
glfw.window_hint(glfw.OPENGL_FORWARD_COMPAT, True)
window = glfw.create_window(size, size, "avatar-studio test", None, None)
assert window, "no GL 3.3 window"
glfw.make_context_current(window)
gl = GLContext.from_current_window()
m = load_builtin()
cam = framing_camera(m.template, 20, 0, width_px=size, height_px=size)
renderer = PreviewRenderer(gl)
renderer.draw(MeshFrame(m.template, m.triangles), cam, PreviewSettings(samples=1, pass_name="normals"))
renderer.present(gl.ctx.screen)
shown = np.frombuffer(gl.ctx.screen.read(components=3, alignment=1), np.uint8).reshape(size, size, 3)[::-1]
glfw.swap_buffers(window)
np.save(out, shown)
print(gl.renderer)
glfw.terminate()
"""


@pytest.fixture(scope="module")
def xvfb_display():
    with xvfb(":87", "320x240x24") as display:
        yield display


@pytest.mark.gl
def test_window_matches_headless(xvfb_display, gl, builtin_model, tmp_path):
    out = tmp_path / "shown.npy"
    r = subprocess.run([sys.executable, "-c", WINDOW_SCRIPT, str(SIZE), str(out)], cwd=REPO, capture_output=True,
                       text=True, timeout=120, env={**os.environ, "DISPLAY": xvfb_display})
    assert r.returncode == 0, r.stderr
    shown = np.load(out)
    cam = framing_camera(builtin_model.template, 20, 0, width_px=SIZE, height_px=SIZE)
    headless = PreviewRenderer(gl)
    expected = headless.render(MeshFrame(builtin_model.template, builtin_model.triangles), cam,
                               PreviewSettings(samples=1, pass_name="normals"))
    headless.release()
    assert (np.abs(expected.astype(int) - [41, 43, 48]).sum(2) > 30).mean() > 0.1  # the head is there
    assert np.abs(shown.astype(int) - expected.astype(int)).max() <= 1
