#!/usr/bin/env bash
# The README's first picture: the studio at 1440x900 under Xvfb on the shipped demo avatar, smiling a little with
# the eyes turned, at its final pass. Writes docs/img/studio.png (or the path given).
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-docs/img/studio.png}
display=:93
Xvfb "$display" -screen 0 1600x1000x24 -nolisten tcp >/dev/null 2>&1 &
xvfb=$!
trap 'kill $xvfb' EXIT
sleep 1
work=$(mktemp -d)
cat > "$work/script.json" <<JSON
{"report": "$work/report.json", "steps": [
  {"refine_to": "final"}, {"wait_render": "final"}, {"expression": "mouthSmile_L", "value": 0.6}, {"expression": "mouthSmile_R", "value": 0.6},
  {"head": [12, -4, 0]}, {"gaze": [14, 0]}, {"wait_render": "final"}, {"wait_frames": 30}, {"screenshot": "$OUT"}]}
JSON
DISPLAY=$display .venv/bin/avatar-studio studio --script "$work/script.json" --width 1440 --height 900
echo "wrote $OUT"
