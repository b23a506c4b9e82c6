"""Give an avatar trained on a tracked video before held-out frames took the nearest training frames' codes
(models/avatars/components/codes.py) the keys that rule needs, and one trained before new views were held to its
capture's (models/avatars/components/views.py) that cone, from its capture's training frames, into a new folder
(the avatar's own folder is left as it is). Where the capture's frames have their times in the video (`track`
writes `time_s`), the training frames' times too, and the choice `train` makes at its end of whether held-out
frames take codes by controls and time (models/training/trainer.py choose_code_time), said in a line.

    .venv/bin/python scripts/key_codes.py AVATAR DATASET OUT
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from models.avatars.checkpoint import save_checkpoint
from models.avatars.registry import load_avatar
from models.capture.dataset import load_split
from models.training.data import build_frames
from models.training.trainer import choose_code_time
from render.gl.context import GLContext


def main() -> int:
    if len(sys.argv) != 4:
        print(__doc__, file=sys.stderr)
        return 2
    avatar_dir, dataset, out = map(Path, sys.argv[1:])
    if out.exists():
        print(f"{out}: exists; choose a new folder", file=sys.stderr)
        return 2
    avatar, meta = load_avatar(avatar_dir)
    split = load_split(dataset, "train")
    frames = split.frames
    if len(frames) != int(meta["frames"]):
        print(f"{dataset}: {len(frames)} training frames, not the avatar's {meta['frames']}", file=sys.stderr)
        return 2
    avatar.code_keys.note([f.controls for f in frames], [f.time_s for f in frames])
    gl = GLContext.headless()
    if avatar.views.eye is None:  # trained before the views were kept (a whole head always keeps its inside's)
        avatar.note_views(build_frames(split, avatar, gl))
    choice = choose_code_time(avatar, load_split(dataset, "val"), gl)
    if choice is not None:
        print(f"held-out frames take codes by controls{' and time' if choice['by_time'] else ''}: {choice}")
    save_checkpoint(out, meta, avatar.state_dict(), int(meta.get("step", 1)))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
