"""How far each frame of a capture's splits stands beyond the cone of views a whole head's inside was trained with
(models/avatars/components/views.py), in degrees: 0 within it. A whole head (models/avatars/whole/) renders a
frame within the cone exactly as its inside alone.

    .venv/bin/python scripts/views_beyond.py WHOLE_HEAD_AVATAR CAPTURE"""

from __future__ import annotations

import sys

import numpy as np
import torch

from models.avatars.registry import load_avatar
from models.avatars.whole.avatar import beyond_cone_deg
from models.capture.dataset import load_split
from models.capture.frames import frame_camera


def main() -> None:
    inside = load_avatar(sys.argv[1], model="whole")[0].inside
    if inside.views.axis is None:
        raise SystemExit(f"{sys.argv[1]}: its views have no cone (a capture from all round)")
    for split in ("train", "val", "test"):
        s = load_split(sys.argv[2], split)
        if not s.frames:
            continue
        beyond = []
        for f in s.frames:
            eye = torch.as_tensor(np.linalg.inv(frame_camera(s, f).view)[:3, 3], dtype=torch.float32)
            view = inside.view_of(inside.geometry(f.controls), eye)
            beyond.append(float(beyond_cone_deg(view[None], inside.views.axis, float(inside.views.cos))[0]))
        print(f"{split}: {len(beyond)} frames, degrees beyond the cone: median {np.median(beyond):.1f}, "
              f"90th percentile {np.percentile(beyond, 90):.1f}, most {max(beyond):.1f}")


if __name__ == "__main__":
    main()
