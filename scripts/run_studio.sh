#!/usr/bin/env bash
# `make run`: the studio on the shipped demo avatar. With a display, the window opens. Without one (a server,
# CI), the studio runs under Xvfb for 300 frames and saves a screenshot of its window to out/studio.png.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ -n "${DISPLAY:-}" ]; then
    exec .venv/bin/avatar-studio studio "$@"
fi
command -v Xvfb >/dev/null || { echo "no display and no Xvfb: install xvfb (make does, as root)"; exit 2; }
display=":$((90 + RANDOM % 9))"
Xvfb "$display" -screen 0 1600x1000x24 -nolisten tcp >/dev/null 2>&1 &
xvfb=$!
trap 'kill $xvfb' EXIT
sleep 1
echo "no display: running the studio under Xvfb ($display) and saving its window to out/studio.png"
DISPLAY=$display .venv/bin/avatar-studio studio "$@" --screenshot out/studio.png --frames 300
