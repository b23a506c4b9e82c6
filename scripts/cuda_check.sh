#!/usr/bin/env bash
# The GPU path, checked on a machine with a CUDA GPU: the tests that need one (train --device cuda against the CPU,
# step for step, for CoDyNeRF and the primitives), then prior-train under torchrun on NCCL (one process a GPU) for a
# few steps on a small corpus (CORPUS; make one with `avatar-studio corpus --identities 2 --frames 10 --views 2
# --size 64`). PYTHON is the interpreter with torch (default: the project's venv, else python3).
set -euo pipefail
cd "$(dirname "$0")/.."
CORPUS=${1:?usage: scripts/cuda_check.sh CORPUS [OUT]}
OUT=${2:-out/cuda_check}
PY=${PYTHON:-$( [ -x .venv/bin/python ] && echo .venv/bin/python || echo python3 )}
export PYTHONPATH=.${PYTHONPATH:+:$PYTHONPATH}
"$PY" -c "import torch; print('torch', torch.__version__, 'on', torch.cuda.get_device_name(0))"
"$PY" -m pytest -q -p no:cacheprovider -rs \
    tests/models/avatars/codynerf/test_avatar.py::test_cuda_matches_cpu \
    "tests/models/avatars/primitives/test_primitives.py::test_cuda_trains_and_renders_as_the_cpu_does" \
    tests/models/avatars/prior/test_prior.py::test_each_gpu_process_takes_its_own_gpu
GPUS=$("$PY" -c "import torch; print(torch.cuda.device_count())")
rm -rf "$OUT/prior"
"$PY" -m torch.distributed.run --nproc-per-node "$GPUS" -m app.cli prior-train "$CORPUS" --out "$OUT/prior" \
    --steps 20 --device cuda
"$PY" -m app.cli render "$OUT/prior" --out "$OUT/prior.png" --size 128 --device cuda 2>/dev/null \
    || "$PY" -m app.cli render "$OUT/prior" --out "$OUT/prior.png" --size 128
