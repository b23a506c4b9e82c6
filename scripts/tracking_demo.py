"""Track a synthetic capture played as a video, measure against its known controls, and draw the README's
tracking picture (overlay frames: the fitted mesh's wireframe, MediaPipe's landmarks in green, where the fitted
head puts them in red).

    .venv/bin/python scripts/tracking_demo.py --ict ../shared/data/ict_facekit/ict_head.npz \
        --landmarker ../shared/data/mediapipe/face_landmarker_v2_with_blendshapes.task --out out/tracking_demo

Writes OUT/capture (the synthetic capture), OUT/synthetic.mp4, OUT/tracked (the tracked dataset with its
report), OUT/errors.json (head rotation and expression errors against the truth) and docs/img/tracking.png.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from app.cli import main as cli
from models.capture.dataset import load_split
from models.capture.synthetic import SynthConfig, synthesize
from models.head.sources import load_head
from render.gl.context import GLContext
from render.video import write_video


def frames_in_order(dataset: Path) -> list:
    frames = [f for s in ("train", "val", "test") for f in load_split(dataset, s).frames]
    return sorted(frames, key=lambda f: int(Path(f.image_path).stem))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--ict", type=Path, required=True)
    p.add_argument("--landmarker", type=Path, required=True)
    p.add_argument("--out", type=Path, default=Path("out/tracking_demo"))
    p.add_argument("--picture", type=Path, default=Path("docs/img/tracking.png"))
    a = p.parse_args()
    capture, video, tracked = a.out / "capture", a.out / "synthetic.mp4", a.out / "tracked"
    if not (capture / "transforms_test.json").exists():
        synthesize(SynthConfig(head=f"ict:{a.ict}", scene="studio", frames=30, size=256, out=capture),
                   load_head(f"ict:{a.ict}"), GLContext.headless())
    truth = frames_in_order(capture)
    if not video.exists():
        write_video((cv2.cvtColor(cv2.imread(str(f.image_path)), cv2.COLOR_BGR2RGB) for f in truth), video, fps=30)
    if not tracked.exists():
        rc = cli(["track", str(video), "--head", f"ict:{a.ict}", "--out", str(tracked), "--landmarker",
                  str(a.landmarker), "--size", "256", "--fps", "30", "--fov-deg", "18", "--blur", "0",
                  "--smooth", "0"])
        if rc:
            raise SystemExit(rc)
    got = frames_in_order(tracked)
    angles, weights = [], []
    for t, f in zip(truth, got, strict=True):
        view = Rotation.from_matrix(np.linalg.inv(t.camera_to_world)[:3, :3])
        true_rel = view * Rotation.from_rotvec(t.controls.root)  # the head as the camera sees it
        angles.append(float(np.degrees((true_rel.inv() * Rotation.from_rotvec(f.controls.root)).magnitude())))
        weights.append(float(np.abs(f.controls.expression - t.controls.expression).mean()))
    report = json.loads((tracked / "tracking" / "report.json").read_text())
    errors = {"frames": len(angles), "rotation_deg": {"median": float(np.median(angles)), "max": max(angles)},
              "expression_weight_mae": {"median": float(np.median(weights)), "max": max(weights)},
              "landmark_error_px": report["landmark_error_px"], "seconds_per_frame": report["seconds_per_frame"]}
    (a.out / "errors.json").write_text(json.dumps(errors, indent=1) + "\n")
    print(json.dumps(errors, indent=1))
    cap = cv2.VideoCapture(str(tracked / "tracking" / "overlay.mp4"))
    overlay = []
    while True:
        ok, bgr = cap.read()
        if not ok:
            break
        overlay.append(bgr)
    cap.release()
    pick = [0, 3, 9, 14, 20]
    row_in = np.concatenate([cv2.imread(str(truth[i].image_path)) for i in pick], 1)
    row_out = np.concatenate([overlay[i] for i in pick], 1)
    a.picture.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(a.picture), np.concatenate([row_in, row_out], 0))
    print(f"wrote {a.picture}")


if __name__ == "__main__":
    main()
