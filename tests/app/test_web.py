"""`avatar-studio export --format web`: a folder to host (the player page, three.js, the avatar's .glb with its
animation), and the page in headless Chromium driven as a user drives it (mouse events on its sliders and buttons),
its canvas read back: a mouth slider moves the mouth's pixels, a brow slider leaves them, play and pause, a drag
turns the camera."""

from __future__ import annotations

import json
import time

import numpy as np
import pygltflib
import pytest

from app.cli import main
from app.web import THREE_FILES
from models.export.bake import texture_image
from render.camera import project, turntable_camera
from render.gl.raster import Rasterizer
from tests.browser import player_page, show_through, snapshot, three_or_skip
from tests.conftest import BUILTIN_AVATAR as DEMO  # the built-in head: a skeleton with jaw and neck
from tests.models.export.reading import accessor, texture

PX = 256
TALK = {"format": "avatar-studio/animation/1", "fps": 10, "duration_s": 2.0, "interpolation": "linear",
        "tracks": {"expression.smile_L": [[0, 0], [1, 1], [2, 0]], "jaw.open": [[0, 0], [1, 20], [2, 0]]}}


@pytest.fixture(scope="module")
def web_export(tmp_path_factory):
    """The demo exported with --format web (a small bake: a 128 px texture from 2 renders of 64 px) and TALK."""
    three_or_skip()
    tmp = tmp_path_factory.mktemp("web")
    (tmp / "talk.json").write_text(json.dumps(TALK))
    out = tmp / "site"
    assert main(["export", str(DEMO), "--format", "web", "--out", str(out), "--texture-size", "128",
                 "--render-size", "64", "--views", "1", "--animation", str(tmp / "talk.json")]) == 0
    return out


@pytest.fixture(scope="module")
def page(web_export):
    with player_page(web_export, 640, 480) as browser:
        yield browser


def test_the_folder_holds_the_page_three_js_and_the_glb_with_its_animation(web_export):
    files = {p.relative_to(web_export).as_posix() for p in web_export.rglob("*") if p.is_file()}
    assert files == {"index.html", "player.js", "avatar.glb", *(f"three/{f}" for f in THREE_FILES)}
    gltf = pygltflib.GLTF2.load(str(web_export / "avatar.glb"))
    assert [a.name for a in gltf.animations] == ["talk"]
    html = (web_export / "index.html").read_text()
    assert '"three": "./three/build/three.module.js"' in html and 'src="./player.js"' in html


@pytest.mark.parametrize(("out", "says"), [("site.glb", "writes a folder"),
                                          ("stuff", "neither empty nor a web export")])
def test_a_bad_folder_is_refused_in_one_line(tmp_path, capsys, out, says):
    (tmp_path / "stuff").mkdir()
    (tmp_path / "stuff" / "notes.txt").write_text("mine")
    assert main(["export", str(DEMO), "--format", "web", "--out", str(tmp_path / out)]) == 2
    err = capsys.readouterr().err.strip()
    assert says in err and str(tmp_path / out) in err and "\n" not in err
    assert (tmp_path / "stuff" / "notes.txt").read_text() == "mine"


def click(page, x: float, y: float) -> None:
    """A left click at page pixel (x, y), as the mouse gives it."""
    for kind in ("mousePressed", "mouseReleased"):
        page.call("Input.dispatchMouseEvent", session=page.session, type=kind, x=x, y=y, button="left", clickCount=1)


def centre(page, element_id: str) -> tuple[float, float]:
    """Page pixel at the middle of an element, scrolled into view."""
    return tuple(page.evaluate(f"(() => {{ const e = document.getElementById('{element_id}'); e.scrollIntoView("
                               f"{{block: 'center'}}); const r = e.getBoundingClientRect(); "
                               f"return [r.left + r.width / 2, r.top + r.height / 2]; }})()"))


def click_slider(page, element_id: str, share: float) -> float:
    """Click a slider's track `share` of the way along it; the value the slider then holds (its output's text)."""
    x, y = centre(page, element_id)
    width = page.evaluate(f"document.getElementById('{element_id}').getBoundingClientRect().width")
    click(page, x + (share - 0.5) * width, y)
    return float(page.evaluate(f"document.getElementById('{element_id}').nextElementSibling.value"))


def region(head, camera, expression: str) -> tuple[slice, slice]:
    """The image box (rows, columns) of the vertices an expression moves (more than 1 mm at a weight of 1), 3 px
    beyond."""
    moved = np.linalg.norm(head.expr_basis[:, :, head.expression_index(expression)], axis=1) > 1e-3
    x, y, _ = project(camera, head.template[moved])
    return (slice(int(y.min()) - 3, int(y.max()) + 4), slice(int(x.min()) - 3, int(x.max()) + 4))


def test_a_mouth_slider_moves_the_mouths_pixels_and_a_brow_slider_leaves_them(page, builtin_model):
    """The mouth's box (mouthStretch's vertices) at the front, 256 px. Measured: mouthStretch clicked to about 1
    changes it by 2.2 (mean absolute, of 255: about 165 pixels by more than 10), the jaw clicked to about 20 degrees by
    7.4; browRaise_L at about 1 changes it by 0 and about 680 pixels of the brow's box."""
    camera = turntable_camera(builtin_model.template, 0.0, 0.0, width_px=PX, height_px=PX)
    mouth, brow = region(builtin_model, camera, "mouthStretch"), region(builtin_model, camera, "browRaise_L")
    show_through(page, camera)
    page.evaluate("window.player.neutral()")
    neutral = snapshot(page)[0]

    def change(image, box) -> tuple[float, int]:
        """Mean absolute change in the box, pixels that changed by more than 10."""
        d = np.abs(image[box] - neutral[box])
        return float(d.mean()), int((d.max(-1) > 10).sum())

    assert 0.9 < click_slider(page, "s-mouthStretch", 0.8) < 1.2  # range -1..1.5, the thumb's half-width inset
    stretched = snapshot(page)[0]
    assert change(stretched, mouth)[0] > 1.0 and change(stretched, mouth)[1] > 100
    assert change(stretched, brow)[0] < 0.05
    click(page, *centre(page, "reset"))
    assert page.evaluate("document.getElementById('s-mouthStretch').value") == "0"
    assert change(snapshot(page)[0], mouth)[0] < 0.05  # back where it was

    assert 15 < click_slider(page, "s-jaw", 0.7) < 25  # degrees, range -5..30
    assert change(snapshot(page)[0], mouth)[0] > 4.0
    click(page, *centre(page, "reset"))

    assert 0.9 < click_slider(page, "s-browRaise_L", 0.8) < 1.2
    raised = snapshot(page)[0]
    assert change(raised, brow)[1] > 300
    assert change(raised, mouth)[0] < 0.05


def test_play_runs_the_animation_and_pause_holds_it(page, builtin_model):
    """TALK smiles (smile_L) and opens the jaw to 20 degrees at 1 s: playing moves the mouth, the sliders follow the
    animation, pausing holds the frame."""
    camera = turntable_camera(builtin_model.template, 0.0, 0.0, width_px=PX, height_px=PX)
    mouth = region(builtin_model, camera, "mouthStretch")
    show_through(page, camera)
    page.evaluate("window.player.neutral()")
    neutral = snapshot(page)[0]
    box = centre(page, "play")
    click(page, *box)
    assert page.evaluate("document.getElementById('play').textContent") == "pause"
    deadline = time.monotonic() + 20
    while float(page.evaluate("document.getElementById('time-out').value")) < 0.5:
        assert time.monotonic() < deadline, "the animation did not advance"
        time.sleep(0.05)
    click(page, *box)
    t = float(page.evaluate("document.getElementById('time-out').value"))
    smile = float(page.evaluate("document.getElementById('s-smile_L').value"))
    jaw = float(page.evaluate("document.getElementById('s-jaw').value"))
    # TALK is linear: at t (0.5 .. 1.5 s), smile_L = 1 - |1 - t| and the jaw 20 times that, in degrees.
    assert smile == pytest.approx(1 - abs(1 - t), abs=0.02) and jaw == pytest.approx(20 * smile, abs=0.3)
    held = snapshot(page)[0]
    assert float(np.abs(held[mouth] - neutral[mouth]).mean()) > 5.0
    time.sleep(0.3)
    assert float(page.evaluate("document.getElementById('time-out').value")) == t
    np.testing.assert_array_equal(snapshot(page)[0], held)

    # The time slider shows the animation at the time clicked (a quarter of the way: about 0.5 s), paused.
    t = click_slider(page, "time", 0.25)
    assert 0.3 < t < 0.7
    smile = float(page.evaluate("document.getElementById('s-smile_L').value"))
    assert smile == pytest.approx(t, abs=0.02)
    assert page.evaluate("document.getElementById('play').textContent") == "play"


def test_dragging_across_the_view_turns_the_camera_round_the_head(page, web_export, gl):
    """OrbitControls turns the camera by 2 pi dx / (the canvas's height) to the left for a drag of dx pixels to the
    right: 20 px on a 256 px canvas from the front is the view from yaw -28.125 degrees. The page then matches the
    GL render of the file's own mesh, UVs and texture from there (measured: MAD 0.54 of 255, IoU 0.996), not from
    +28.125 (MAD 50, IoU 0.89)."""
    gltf = pygltflib.GLTF2.load(str(web_export / "avatar.glb"))
    prim = gltf.meshes[0].primitives[0]
    positions, uv = accessor(gltf, prim.attributes.POSITION), accessor(gltf, prim.attributes.TEXCOORD_0)
    triangles = accessor(gltf, prim.indices).reshape(-1, 3)
    show_through(page, turntable_camera(positions, 0.0, 0.0, width_px=PX, height_px=PX))
    page.evaluate("window.player.neutral()")
    left, top = page.evaluate("(() => { const r = document.querySelector('#view canvas').getBoundingClientRect(); "
                              "return [r.left, r.top]; })()")
    x, y = left + PX / 2, top + PX / 2
    page.call("Input.dispatchMouseEvent", session=page.session, type="mousePressed", x=x, y=y, button="left",
              buttons=1, clickCount=1)
    for dx in (5, 10, 15, 20):
        page.call("Input.dispatchMouseEvent", session=page.session, type="mouseMoved", x=x + dx, y=y, button="left",
                  buttons=1)
    page.call("Input.dispatchMouseEvent", session=page.session, type="mouseReleased", x=x + 20, y=y, button="left",
              buttons=0, clickCount=1)
    rgb, seen = snapshot(page)

    def against(yaw_deg: float) -> tuple[float, float]:
        camera = turntable_camera(positions, yaw_deg, 0.0, width_px=PX, height_px=PX)
        r = Rasterizer(gl).rasterize(positions, triangles, camera)
        ref = 255 * texture_image(r, uv, triangles, texture(gltf)).astype(np.float64)
        both = seen & r.hit
        return float(np.abs(rgb[both] - ref[both]).mean()), float(both.sum() / (seen | r.hit).sum())

    mad, iou = against(-360 * 20 / PX)
    assert mad < 2.0 and iou > 0.99, (mad, iou)
    mad, iou = against(360 * 20 / PX)
    assert mad > 10.0 and iou < 0.95, (mad, iou)
