#!/usr/bin/env bash
# Rebuild the demo avatar shipped in resources/demo_avatar/: a 256 px sun capture of the demo's person (`--head demo`,
# an ICT-FaceKit identity, with the look its identity seed draws: hair, brows, skin; the capture goes to
# out/demo_capture, where the studio's timeline finds it), then MINUTES (default 20) of training of the
# volumetric-primitives model with every effect (live in the studio on two cores) on DEVICE (default cpu; cuda on a
# GPU), then its test metrics (resources/demo_avatar/eval/metrics.json, shown in the Avatar panel).
set -euo pipefail
cd "$(dirname "$0")/.."
MINUTES=${MINUTES:-20}
MODEL=${MODEL:-primitives}
DEVICE=${DEVICE:-cpu}
PY=${PY:-.venv/bin/python}
[ -d out/demo_capture ] || "$PY" -m app.cli synth --head demo --identity 3 --scene sun --frames 200 --size 256 \
    --out out/demo_capture
rm -rf out/demo_avatar
"$PY" -m app.cli train out/demo_capture --model "$MODEL" --effects all --minutes "$MINUTES" --device "$DEVICE" \
    --out out/demo_avatar
"$PY" -m app.cli eval out/demo_avatar out/demo_capture --split test --out out/demo_avatar/eval
rm -rf resources/demo_avatar
mkdir -p resources/demo_avatar/eval
cp out/demo_avatar/avatar.json out/demo_avatar/weights-*.safetensors out/demo_avatar/progress.jsonl resources/demo_avatar/
cp out/demo_avatar/eval/metrics.json resources/demo_avatar/eval/
echo "resources/demo_avatar: $(du -sh resources/demo_avatar | cut -f1)"
