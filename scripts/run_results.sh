#!/usr/bin/env bash
# The avatar results table: train each effect set on a sun capture of the ICT head, then evaluate on the
# held-out test split. MINUTES per run (default 15). Writes out/results/<effects>/ and out/results/*.json.
set -euo pipefail
cd "$(dirname "$0")/.."
MINUTES=${MINUTES:-15}
DATA=${DATA:-out/ict_sun128}
[ -d "$DATA" ] || .venv/bin/avatar-studio synth --head ict:../shared/data/ict_facekit/ict_head.npz --scene sun \
    --frames 300 --size 128 --out "$DATA"
for effects in none shading,specular all; do
    name=${effects//,/+}
    rm -rf "out/results/$name"
    .venv/bin/avatar-studio train "$DATA" --effects "$effects" --minutes "$MINUTES" --out "out/results/$name"
    .venv/bin/avatar-studio eval "out/results/$name" "$DATA" --split test --out "out/results/$name/eval"
done
