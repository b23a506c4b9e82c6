#!/usr/bin/env bash
# The avatar results table: train each effect set and the NerFACE baseline on a sun capture of the ICT head,
# then evaluate on the held-out test split. Two runs at a time, one core each (this machine has two), for
# MINUTES each (default 25). Writes out/results/<name>/ (avatar, progress.jsonl, eval/metrics.json).
set -euo pipefail
cd "$(dirname "$0")/.."
MINUTES=${MINUTES:-25}
DATA=${DATA:-out/ict_sun128}
[ -d "$DATA" ] || .venv/bin/avatar-studio synth --head ict:../shared/data/ict_facekit/ict_head.npz --scene sun \
    --frames 300 --size 128 --out "$DATA"

train() {  # name, then train options
    local name=$1; shift
    rm -rf "out/results/$name"
    OMP_NUM_THREADS=1 .venv/bin/avatar-studio train "$DATA" --minutes "$MINUTES" --out "out/results/$name" "$@" \
        > "out/results/$name.log" 2>&1
}
mkdir -p out/results
train all --effects all & train shading+specular --effects shading,specular & wait
train none --effects none & train nerface --model nerface & wait
for name in none shading+specular all; do
    .venv/bin/avatar-studio eval "out/results/$name" "$DATA" --split test --out "out/results/$name/eval"
done
# NerFACE renders each 128x128 frame in about half a minute here: every third test frame.
.venv/bin/avatar-studio eval out/results/nerface "$DATA" --split test --every 3 --out out/results/nerface/eval
