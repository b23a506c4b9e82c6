"""Whether the studio's window can open here: checked before the window opens, so that a machine with no
display gets one line, not GLFW's assertion."""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import sys


def display_problem(env: dict[str, str] | None = None) -> str | None:
    """Why the window cannot open here, or None: on Linux it needs a display, named by WAYLAND_DISPLAY or DISPLAY
    (an X display is opened and closed again to see that it answers). Where the check cannot tell, GLFW will."""
    env = os.environ if env is None else env
    if not sys.platform.startswith("linux") or env.get("WAYLAND_DISPLAY"):
        return None
    name = env.get("DISPLAY", "")
    if not name:
        return ("no display to open the studio's window on (DISPLAY is not set): run it on a desktop, or on a "
                "virtual display (xvfb-run -a avatar-studio studio ...)")
    try:
        x11 = ctypes.CDLL(ctypes.util.find_library("X11") or "libX11.so.6")
    except OSError:
        return None
    x11.XOpenDisplay.restype, x11.XOpenDisplay.argtypes = ctypes.c_void_p, [ctypes.c_char_p]
    x11.XCloseDisplay.argtypes = [ctypes.c_void_p]
    handle = x11.XOpenDisplay(name.encode())
    if not handle:
        return f"the display {name} (DISPLAY) does not answer: no window can open there"
    x11.XCloseDisplay(handle)
    return None
