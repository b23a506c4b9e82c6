#!/usr/bin/env bash
# The real-video results of the README: track each shared clip (every frame, SIZE px), train `none` and `all`
# on it for MINUTES each (the two at once, one core each: this machine has two), evaluate both on the held-out
# last 10% and draw truth / none / all on three of those frames. Writes out/real/<SIZE>/<video>/ (dataset, none,
# all, *.log) and out/real/<SIZE>/<video>.png (not docs/: the clips and frames of them stay out of the repository).
# Usage: scripts/run_real.sh [VIDEO...]   (default: the three clips of ../shared/data/video/)
set -euo pipefail
cd "$(dirname "$0")/.."
SIZE=${SIZE:-256}
MINUTES=${MINUTES:-30}
VIDEOS=${*:-expressions_d3 talking_hdtf expressions_d19}
export AVATAR_STUDIO_LANDMARKER=${AVATAR_STUDIO_LANDMARKER:-../shared/data/mediapipe/face_landmarker_v2_with_blendshapes.task}
for v in $VIDEOS; do
    root=out/real/$SIZE/$v
    mkdir -p "$root"
    [ -d "$root/dataset" ] || .venv/bin/avatar-studio track "../shared/data/video/$v.mp4" --size "$SIZE" \
        --head ict:../shared/data/ict_facekit/ict_head.npz --out "$root/dataset" > "$root/track.log" 2>&1
    for e in none all; do
        rm -rf "${root:?}/$e"
        OMP_NUM_THREADS=1 .venv/bin/avatar-studio train "$root/dataset" --effects $e --minutes "$MINUTES" \
            --out "$root/$e" > "$root/train_$e.log" 2>&1 &
    done
    wait
    for e in none all; do
        .venv/bin/avatar-studio eval "$root/$e" "$root/dataset" --split test --out "$root/$e/eval"
    done
    .venv/bin/python scripts/results_picture.py "$root" "out/real/$SIZE/$v.png" --runs none,all --frames spread
done
