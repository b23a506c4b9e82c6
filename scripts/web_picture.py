"""The docs' picture of the demo avatar in the browser (docs/img/export_web.png): the demo exported with
`--format web` (default bake settings) and a short animation in its head model's terms (ICT's jawOpen and
mouthSmile_L, the head turning), its player opened in headless Chromium, the animation at 1.5 s and the outer brows
raised a little on their sliders, a camera
a little to the side, the page captured.

    .venv/bin/python scripts/web_picture.py [OUT.png] [WEB_FOLDER]
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

from PIL import Image

from app.chromium import Chromium, find_chromium, served
from app.cli import main as cli
from render.camera import turntable_camera

REPO = Path(__file__).resolve().parents[1]
WIDTH, HEIGHT, PANEL = 900, 640, 230
ANIMATION = {"format": "avatar-studio/animation/1", "fps": 30, "duration_s": 4.0, "interpolation": "smooth",
             "tracks": {"expression.jawOpen": [[0, 0], [1.5, 0.5]], "expression.mouthSmile_L": [[0, 0], [2, 0.8]],
                        "head.yaw": [[0, -20], [4, 20]]}}
AT_S = 1.5
BROWS = {"browOuterUp_L": 0.4, "browOuterUp_R": 0.4}


def main() -> None:
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else REPO / "docs" / "img" / "export_web.png"
    folder = Path(sys.argv[2]) if len(sys.argv) > 2 else REPO / "out" / "demo_web"
    with tempfile.TemporaryDirectory() as tmp:
        animation = Path(tmp) / "talk.json"
        animation.write_text(json.dumps(ANIMATION))
        if cli(["export", str(REPO / "resources" / "demo_avatar"), "--format", "web", "--out", str(folder),
                "--animation", str(animation)]) != 0:
            sys.exit("export failed")
    binary = find_chromium()
    if binary is None:
        sys.exit("no Chromium on the PATH (scripts/setup_system.sh installs it)")
    with served(folder) as url, Chromium(binary, WIDTH, HEIGHT) as browser:
        browser.open(url + "index.html")
        browser.evaluate("window.player.ready")
        from models.avatars.registry import load_avatar

        head = load_avatar(REPO / "resources" / "demo_avatar")[0].head_model
        camera = turntable_camera(head.template, 20.0, 5.0, width_px=WIDTH - PANEL, height_px=HEIGHT, zoom=0.8)
        browser.evaluate(f"window.player.setView({camera.view.ravel().tolist()}, "
                         f"{camera.projection.ravel().tolist()}, {camera.width_px}, {camera.height_px})")
        browser.evaluate(f"window.player.seek({AT_S})")
        for name, w in BROWS.items():
            browser.evaluate(f"window.player.setWeight('{name}', {w})")
        browser.evaluate("window.player.snapshot()")  # drawn now
        image = browser.screenshot()
        if browser.console_errors():
            sys.exit(f"the page said: {browser.console_errors()}")
    out.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(image).save(out, optimize=True)
    print(f"wrote {out} ({image.shape[1]}x{image.shape[0]})")


if __name__ == "__main__":
    main()
