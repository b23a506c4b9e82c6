#!/usr/bin/env bash
# Rebuild the universal prior shipped in resources/prior/: a corpus of 12 synthetic people of the built-in head
# (40 frames of the range-of-motion script, each from 4 cameras at once round the head, 128 px, ambient light;
# seeds 1-12), then MINUTES (default 15) of prior-train in one process. WORKERS=2 trains under torchrun on two
# processes instead.
set -euo pipefail
cd "$(dirname "$0")/.."
MINUTES=${MINUTES:-15}
WORKERS=${WORKERS:-1}
[ -d out/corpus ] || .venv/bin/avatar-studio corpus --identities 12 --frames 40 --views 4 --size 128 --out out/corpus
rm -rf out/prior
if [ "$WORKERS" -gt 1 ]; then
  .venv/bin/torchrun --nproc-per-node "$WORKERS" .venv/bin/avatar-studio prior-train out/corpus --out out/prior \
    --minutes "$MINUTES"
else
  .venv/bin/avatar-studio prior-train out/corpus --out out/prior --minutes "$MINUTES"
fi
rm -rf resources/prior
mkdir -p resources/prior
cp out/prior/avatar.json out/prior/weights-*.safetensors out/prior/progress.jsonl resources/prior/
echo "resources/prior: $(du -sh resources/prior | cut -f1)"
