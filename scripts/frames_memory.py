"""What reading a capture's training frames costs before the first step: seconds, the resident memory it adds, the
process's peak, and the tensors that hold the frames (one thread, as a training beside another runs).

    .venv/bin/python scripts/frames_memory.py out/real/256/expressions_d3/dataset [--effects all]
"""

from __future__ import annotations

import argparse
import resource
import time
from pathlib import Path

import torch

from models.training.trainer import TrainConfig, prepare_training
from render.gl.context import GLContext


def resident_mib() -> float:
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("VmRSS")) / 1024


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dataset", type=Path)
    parser.add_argument("--effects", default="all")
    args = parser.parse_args()
    torch.set_num_threads(1)
    gl = GLContext.headless()
    before, t0 = resident_mib(), time.perf_counter()
    trainer = prepare_training(TrainConfig(dataset=args.dataset, out=Path("/nonexistent"), effects=args.effects,
                                           steps=1), gl)
    seconds, added = time.perf_counter() - t0, resident_mib() - before
    fs = trainer.frames
    mib = lambda t: 0.0 if t is None else t.element_size() * t.numel() / 2**20
    held = {"images": mib(fs.images), "surface_t": mib(fs.surface_t),
            "active_index": sum(mib(a) for a in fs.active_index),
            "geometry": sum(mib(v) for g in fs.geometry for v in vars(g).values() if torch.is_tensor(v))}
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"{len(fs)} frames of {tuple(fs.images.shape[1:3])}: read in {seconds:.1f} s, {added:.0f} MiB more "
          f"resident ({added / len(fs):.2f} MiB a frame), the process's peak {peak:.0f} MiB")
    print("held: " + ", ".join(f"{k} {v:.0f} MiB" for k, v in held.items()))


if __name__ == "__main__":
    main()
