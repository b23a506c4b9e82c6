#!/usr/bin/env bash
# Rebuild the universal prior shipped in resources/prior/: a corpus of PEOPLE (default 24) synthetic people of the
# built-in head (40 frames of the range-of-motion script, each from 4 cameras at once round the head, 128 px;
# seeds 1-PEOPLE; about 8 s a person), then MINUTES (default 60) of prior-train in one process on one thread (the
# corpus takes about 2 minutes to read first). WORKERS=2 trains under torchrun on two processes instead.
set -euo pipefail
cd "$(dirname "$0")/.."
MINUTES=${MINUTES:-60}
PEOPLE=${PEOPLE:-24}
WORKERS=${WORKERS:-1}
CORPUS=out/corpus$PEOPLE
[ -d "$CORPUS" ] || .venv/bin/avatar-studio corpus --identities "$PEOPLE" --frames 40 --views 4 --size 128 --out "$CORPUS"
rm -rf out/prior
if [ "$WORKERS" -gt 1 ]; then
  .venv/bin/torchrun --nproc-per-node "$WORKERS" .venv/bin/avatar-studio prior-train "$CORPUS" --out out/prior \
    --minutes "$MINUTES"
else
  OMP_NUM_THREADS=1 .venv/bin/avatar-studio prior-train "$CORPUS" --out out/prior --minutes "$MINUTES"
fi
rm -rf resources/prior
mkdir -p resources/prior
cp out/prior/avatar.json out/prior/weights-*.safetensors out/prior/progress.jsonl resources/prior/
echo "resources/prior: $(du -sh resources/prior | cut -f1)"
