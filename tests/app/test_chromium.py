"""Headless Chromium over the DevTools pipe (app/chromium.py): pages opened, scripts' values and errors, screenshots
read back pixel for pixel, WebGL on SwiftShader, a folder served on the loopback."""

from __future__ import annotations

import urllib.request

import numpy as np
import pytest

from app.chromium import BrowserError, Chromium, served
from tests.browser import chromium_or_skip

PAGE = ("data:text/html,<body style='margin:0;background:rgb(10,20,30)'>"
        "<div style='position:absolute;left:8px;top:4px;width:16px;height:12px;background:rgb(200,100,50)'></div>")


@pytest.fixture(scope="module")
def browser():
    with Chromium(chromium_or_skip(), 64, 48) as b:
        yield b


def test_a_screenshot_is_the_page_pixel_for_pixel(browser):
    browser.open(PAGE)
    image = browser.screenshot()
    assert image.shape == (48, 64, 3)
    inside = np.zeros((48, 64), bool)
    inside[4:16, 8:24] = True  # the div: rows 4..15, columns 8..23
    assert (image[inside] == [200, 100, 50]).all()
    assert (image[~inside] == [10, 20, 30]).all()


def test_values_come_back_and_a_throw_is_an_error_naming_it(browser):
    browser.open(PAGE)
    assert browser.evaluate("new Promise(r => setTimeout(() => r([1 + 2, 'a' + 'b']), 10))") == [3, "ab"]
    with pytest.raises(BrowserError, match="no such slider"):
        browser.evaluate("(() => { throw new Error('no such slider'); })()")


def test_webgl2_draws_on_swiftshader(browser):
    """A WebGL2 canvas cleared to (0.2, 0.4, 0.6) reads back 51, 102, 153 (0.2 * 255 = 51, ...)."""
    browser.open("data:text/html,<canvas id=c width=4 height=4></canvas>")
    got = browser.evaluate("(() => { const gl = document.getElementById('c').getContext('webgl2'); "
                           "gl.clearColor(0.2, 0.4, 0.6, 1); gl.clear(gl.COLOR_BUFFER_BIT); "
                           "const p = new Uint8Array(4); gl.readPixels(1, 1, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, p); "
                           "return [gl.getParameter(gl.VERSION), Array.from(p)]; })()")
    assert got[0].startswith("WebGL 2.0")
    assert got[1] == [51, 102, 153, 255]


def test_a_folder_is_served_on_the_loopback(tmp_path):
    (tmp_path / "a.bin").write_bytes(bytes(range(256)))
    with served(tmp_path) as url:
        assert url.startswith("http://127.0.0.1:")
        assert urllib.request.urlopen(url + "a.bin", timeout=10).read() == bytes(range(256))
