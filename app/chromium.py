"""Headless Chromium driven over the DevTools protocol on a pipe (`--remote-debugging-pipe`: commands in on file
descriptor 3, replies and events out on 4, each a JSON message ended by a NUL byte), with WebGL on SwiftShader;
and a folder served over HTTP on the loopback, as a page's ES modules and fetches need an origin. No driver
program and no WebSocket: the protocol's messages are written and read here."""

from __future__ import annotations

import base64
import fcntl
import functools
import http.server
import io
import json
import os
import select
import shutil
import subprocess
import tempfile
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from PIL import Image

NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
FLAGS = ("--headless", "--no-sandbox", "--no-first-run", "--no-default-browser-check", "--disable-extensions",
         "--disable-dev-shm-usage", "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--mute-audio",
         "--hide-scrollbars", "--remote-debugging-pipe")
"""WebGL without a GPU: ANGLE on SwiftShader (Chromium's CPU Vulkan). --no-sandbox: the sandbox refuses to run as
root, as on CI."""


class BrowserError(RuntimeError):
    """Chromium failed, or a page's script threw."""


def find_chromium() -> str | None:
    """The Chromium (or Chrome) binary on the PATH, or in CHROMIUM; None where there is none."""
    given = os.environ.get("CHROMIUM")
    if given:
        return shutil.which(given)
    return next((p for p in map(shutil.which, NAMES) if p), None)


class Chromium:
    """One headless browser with one page of width x height CSS pixels at a device pixel ratio of 1."""

    def __init__(self, binary: str, width_px: int = 512, height_px: int = 512, timeout_s: float = 60.0):
        self.timeout_s = timeout_s
        self._profile = tempfile.TemporaryDirectory(prefix="chromium-")
        self._log = open(Path(self._profile.name) / "stderr.log", "w+b")
        to_browser, self._write = os.pipe()
        self._read, from_browser = os.pipe()
        # Chromium's ends moved above 3 and 4 first, so that putting one on 3 cannot overwrite the other.
        high = [fcntl.fcntl(fd, fcntl.F_DUPFD, 10) for fd in (to_browser, from_browser)]
        for fd in (to_browser, from_browser):
            os.close(fd)

        def pipes_on_3_and_4() -> None:
            os.dup2(high[0], 3)
            os.dup2(high[1], 4)

        self.process = subprocess.Popen(
            [binary, *FLAGS, f"--user-data-dir={self._profile.name}", f"--window-size={width_px},{height_px}",
             "about:blank"], stdin=subprocess.DEVNULL, stdout=self._log, stderr=self._log,
            preexec_fn=pipes_on_3_and_4, pass_fds=(3, 4))
        for fd in high:
            os.close(fd)
        self._buffer = b""
        self._next_id = 0
        self._events: list[dict] = []
        try:
            target = self.call("Target.createTarget", url="about:blank")["targetId"]
            self.session = self.call("Target.attachToTarget", targetId=target, flatten=True)["sessionId"]
            self.call("Page.enable", session=self.session)
            self.call("Runtime.enable", session=self.session)
            self.call("Emulation.setDeviceMetricsOverride", session=self.session, width=width_px, height=height_px,
                      deviceScaleFactor=1, mobile=False)
        except BaseException:
            self.close()
            raise

    def call(self, method: str, session: str | None = None, **params) -> dict:
        """Send one command and wait for its reply (events that come first are kept for wait_for)."""
        self._next_id += 1
        message = {"id": self._next_id, "method": method, "params": params}
        if session is not None:
            message["sessionId"] = session
        os.write(self._write, json.dumps(message).encode() + b"\0")
        while True:
            reply = self._receive()
            if reply.get("id") == self._next_id:
                if "error" in reply:
                    raise BrowserError(f"{method}: {reply['error'].get('message')}")
                return reply["result"]
            if "method" in reply:
                self._events.append(reply)

    def wait_for(self, event: str) -> dict:
        """The next event of that name (one already received counts)."""
        while True:
            for k, e in enumerate(self._events):
                if e["method"] == event:
                    return self._events.pop(k)["params"]
            self._events.append(self._receive())

    def open(self, url: str) -> None:
        """Load a page and wait for its load event (its module scripts have run by then)."""
        self._events.clear()
        self.call("Page.navigate", session=self.session, url=url)
        self.wait_for("Page.loadEventFired")

    def evaluate(self, expression: str):
        """The value of a JavaScript expression in the page (a promise is awaited); BrowserError where it throws."""
        done = self.call("Runtime.evaluate", session=self.session, expression=expression, awaitPromise=True,
                         returnByValue=True)
        if "exceptionDetails" in done:
            details = done["exceptionDetails"]
            raise BrowserError(f"in the page: {details.get('exception', {}).get('description') or details['text']}")
        return done["result"].get("value")

    def screenshot(self) -> np.ndarray:
        """(H,W,3) uint8: the page as shown."""
        data = self.call("Page.captureScreenshot", session=self.session, format="png")["data"]
        return np.asarray(Image.open(io.BytesIO(base64.b64decode(data))).convert("RGB"))

    def console_errors(self) -> list[str]:
        """The page's uncaught exceptions and console errors so far."""
        out = []
        for e in self._events:
            if e["method"] == "Runtime.exceptionThrown":
                out.append(e["params"]["exceptionDetails"].get("exception", {}).get("description", "exception"))
            elif e["method"] == "Runtime.consoleAPICalled" and e["params"]["type"] == "error":
                out.append(" ".join(str(a.get("value", a.get("description"))) for a in e["params"]["args"]))
        return out

    def _receive(self) -> dict:
        deadline = time.monotonic() + self.timeout_s
        while b"\0" not in self._buffer:
            ready, _, _ = select.select([self._read], [], [], max(0.0, deadline - time.monotonic()))
            chunk = os.read(self._read, 1 << 20) if ready else b""
            if not chunk:
                why = "stopped answering" if not ready else "exited"
                raise BrowserError(f"Chromium {why}: {self._stderr_tail()}")
            self._buffer += chunk
        message, self._buffer = self._buffer.split(b"\0", 1)
        return json.loads(message)

    def _stderr_tail(self) -> str:
        self._log.flush()
        self._log.seek(0)
        return self._log.read().decode(errors="replace")[-2000:].strip() or "(nothing on its stderr)"

    def close(self) -> None:
        if self.process.poll() is None:
            try:
                os.write(self._write, json.dumps({"id": 0, "method": "Browser.close"}).encode() + b"\0")
                self.process.wait(timeout=10)
            except (OSError, subprocess.TimeoutExpired):
                self.process.kill()
                self.process.wait()
        for fd in (self._read, self._write):
            os.close(fd)
        self._log.close()
        self._profile.cleanup()

    def __enter__(self) -> Chromium:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class _Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args) -> None:
        pass


@contextmanager
def served(folder: Path) -> Iterator[str]:
    """A folder served over HTTP on 127.0.0.1 (a free port) while the block runs: its base URL, ending in /."""
    handler = functools.partial(_Quiet, directory=str(folder))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/"
    finally:
        server.shutdown()
        server.server_close()
