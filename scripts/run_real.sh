#!/usr/bin/env bash
# The real-video results of the README: track each shared clip (every frame, SIZE px), train `none` and `all`
# on it for MINUTES each (the two at once, one core each: this machine has two), evaluate both on the held-out
# last 10% and draw truth / none / all on three of those frames. Writes out/real/<SIZE>/<video>/ (dataset, none,
# all, *.log) and out/real/<SIZE>/<video>.png (not docs/: the clips and frames of them stay out of the repository).
# Usage: [MODEL=primitives] scripts/run_real.sh [VIDEO...]   (default: codynerf on the three clips of
# ../shared/data/video/; with MODEL, the avatars go to out/real/<SIZE>/<video>/<MODEL>_{none,all})
set -euo pipefail
cd "$(dirname "$0")/.."
SIZE=${SIZE:-256}
MINUTES=${MINUTES:-30}
MODEL=${MODEL:-}
VIDEOS=${*:-expressions_d3 talking_hdtf expressions_d19}
export AVATAR_STUDIO_LANDMARKER=${AVATAR_STUDIO_LANDMARKER:-../shared/data/mediapipe/face_landmarker_v2_with_blendshapes.task}
for v in $VIDEOS; do
    root=out/real/$SIZE/$v
    mkdir -p "$root"
    [ -d "$root/dataset" ] || .venv/bin/avatar-studio track "../shared/data/video/$v.mp4" --size "$SIZE" \
        --head ict:../shared/data/ict_facekit/ict_head.npz --out "$root/dataset" > "$root/track.log" 2>&1
    runs=${MODEL:+${MODEL}_}
    for e in none all; do
        rm -rf "${root:?}/$runs$e"
        OMP_NUM_THREADS=1 .venv/bin/avatar-studio train "$root/dataset" --model "${MODEL:-codynerf}" --effects $e \
            --minutes "$MINUTES" --out "$root/$runs$e" > "$root/train_$runs$e.log" 2>&1 &
    done
    wait
    for e in none all; do
        .venv/bin/avatar-studio eval "$root/$runs$e" "$root/dataset" --split test --out "$root/$runs$e/eval"
    done
    .venv/bin/python scripts/results_picture.py "$root" "out/real/$SIZE/$v${MODEL:+_$MODEL}.png" --runs "${runs}none,${runs}all" \
        --frames spread
done
