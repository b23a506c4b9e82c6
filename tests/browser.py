"""The exported avatar's player page in headless Chromium, for the tests: the browser found or the test skipped (only
where no Chromium is installed; on CI, where the set-up installs it, its absence fails), the page served and opened,
the canvas read back."""

from __future__ import annotations

import base64
import io
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from app.chromium import Chromium, find_chromium, served
from app.web import missing_three
from render.camera import Camera


def _absent(why: str) -> None:
    """Skip, or on CI (where the set-up installs everything) fail."""
    (pytest.fail if os.environ.get("CI") else pytest.skip)(why)


def chromium_or_skip() -> str:
    binary = find_chromium()
    if binary is None:
        _absent("no Chromium on the PATH (the set-up installs Debian's `chromium`: scripts/setup_system.sh; "
                "CHROMIUM=PATH names another)")
    return binary


def three_or_skip() -> None:
    """three.js, which a web export copies, is installed (or the test skips)."""
    why = missing_three()
    if why is not None:
        _absent(why)


@contextmanager
def player_page(folder: Path, width_px: int = 640, height_px: int = 480) -> Iterator[Chromium]:
    """index.html of a web export's folder, opened and its .glb loaded (window.player.ready awaited)."""
    binary = chromium_or_skip()
    with served(folder) as url, Chromium(binary, width_px, height_px) as browser:
        browser.open(url + "index.html")
        browser.evaluate("window.player.ready")
        yield browser
        assert browser.console_errors() == []


def show_through(browser: Chromium, camera: Camera) -> None:
    """The player's camera set to this one: its view and projection matrices, its image size."""
    browser.evaluate(f"window.player.setView({camera.view.ravel().tolist()}, {camera.projection.ravel().tolist()}, "
                     f"{camera.width_px}, {camera.height_px})")


def snapshot(browser: Chromium) -> tuple[np.ndarray, np.ndarray]:
    """The canvas drawn now and read back: (H,W,3) float64 colour in 0..255 and (H,W) bool, where the mesh is (the
    canvas is cleared to transparent)."""
    url = browser.evaluate("window.player.snapshot()")
    rgba = np.asarray(Image.open(io.BytesIO(base64.b64decode(url.split(",", 1)[1]))).convert("RGBA"), np.float64)
    return rgba[..., :3], rgba[..., 3] > 127
