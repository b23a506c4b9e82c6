"""`avatar-studio track`: a monocular video of one face -> a capture dataset that `train` accepts.

Frames are decoded at a chosen rate; MediaPipe's face landmarker finds 478 landmarks, blendshape scores and
a head pose in each; one face-centred square crop serves every frame (fixed intrinsics), or where the head
travels so far that one crop would leave the face small, a crop that follows it (each frame its own window of
one canvas, and its own principal point: models/tracking/video.py); the head model is
fitted (identity once, then per frame head pose, jaw and expression, from landmark reprojection with temporal
smoothness; gaze from the blendshape scores); GrabCut cuts a foreground mask per frame, and the room behind the
person becomes a background plate (models/tracking/masks.py) that avatars composite over; the frames are
written as the camera saw them; the last part of the video (or with --split view, the frames where the head is turned
furthest: models/tracking/splits.py) is held out as the test split. A report says how
well it went before anyone spends time training:
landmark reprojection error per frame, frames dropped and why, and an overlay video of the fitted mesh.

Everything is written to a folder of the program's own beside OUT (models/files.py: partial_folder) and renamed
to OUT only when complete.
"""

from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np
import torch
from tqdm import tqdm

from app.capture_commands import next_train
from app.configs import TrackConfig
from app.errors import UserInputError
from app.progress import Progress
from app.user_config import config_folder, find_landmarker, remember, remembered
from models.capture.dataset import write_split
from models.capture.synthetic import absolute_head_spec, write_png8
from models.files import partial_folder
from models.head.controls import controls_to_dict
from models.head.head import Head
from models.head.sources import load_head
from models.tracking.blendshapes import expression_from_scores, gaze_from_scores, jaw_from_scores
from models.tracking.canonical import canonical_face_mesh
from models.tracking.correspond import correspond, skin_vertices
from models.tracking.finder import FaceFinder
from models.tracking.fit import FitConfig, Intrinsics, fit, project
from models.tracking.landmarker import Face, packaged_bundle
from models.tracking.masks import background_plate, foreground_masks
from models.tracking.splits import frame_splits
from models.tracking.video import Framing, VideoInfo, cropped_frames, face_framing, sampled_frames, video_info
from render.video import write_video


def landmarker_path(cfg: TrackConfig) -> Path:
    """The face landmarker bundle: --landmarker, else as app/user_config.py finds one (find_landmarker), the
    packaged one last."""
    return find_landmarker(cfg.landmarker, packaged_bundle)


def remember_landmarker(cfg: TrackConfig, bundle: Path) -> None:
    """A --landmarker that worked is remembered, so that later runs need none (said in one line)."""
    if cfg.landmarker is None:
        return
    path = str(bundle.resolve())
    if remembered("landmarker") != path:
        try:
            where = remember("landmarker", path)
        except OSError as e:  # the run goes on: only the next one needs the flag again
            print(f"could not remember --landmarker in {config_folder()} ({e.strerror})", flush=True)
            return
        print(f"remembered --landmarker {path} in {where}: later runs need no --landmarker", flush=True)


OTHER_PERSON = 0.5
"""A second face at least this share of the main face's width is another person in the shot; a smaller one (a
photograph on the wall, someone far behind) is part of the room, and the largest face is tracked."""


def detect_faces(cfg: TrackConfig, bundle: Path, info, progress) -> tuple[list[dict], list[dict], int]:
    """Landmarks of the one face in each sampled frame (the largest); frames without a face are dropped (with
    the reason). Another person (a second face at least OTHER_PERSON as wide) in more than a tenth of the frames
    is an error: track needs a video of one person."""
    share = min(cfg.fps / info.fps, 1.0) if cfg.fps else 1.0
    expected = max(1, round(info.frames * share)) if info.frames > 0 else None
    if expected and cfg.seconds:
        expected = min(expected, max(1, round(cfg.seconds * info.fps * share)))
    kept, dropped, several, read = [], [], 0, 0
    with FaceFinder(bundle, max_faces=2) as landmarker:
        for index, t, rgb in sampled_frames(cfg.video, cfg.fps):
            if cfg.seconds and t >= cfg.seconds:
                break
            read += 1
            faces = landmarker.detect(rgb, round(1000 * t))
            widths = [float(np.ptp(f.landmarks_px[:, 0])) for f in faces]
            if not faces:
                dropped.append({"source_frame": index, "time_s": round(t, 3), "reason": "no face found"})
            else:
                face = faces[int(np.argmax(widths))]
                if len(faces) > 1 and sorted(widths)[-2] >= OTHER_PERSON * max(widths):
                    several += 1
                # The full frame is not kept (a minute of 1080p is 11 GB): its crop is read again once the crop
                # that serves every frame is known.
                kept.append({"source_frame": index, "time_s": t, "face": face, "found_by": landmarker.found_by,
                             "sharpness": sharpness(rgb, face.landmarks_px)})
            progress(read, expected)
    if read == 0:
        raise UserInputError(f"{cfg.video}: no frames could be decoded")
    if several > 0.1 * read:
        raise UserInputError(f"{cfg.video}: several people (a second face at least {OTHER_PERSON:.0%} as wide as the "
                             f"first in {several} of {read} frames); track needs a video of one face")
    if read < 10:
        raise UserInputError(f"{cfg.video}: only {read} frames taken (at least 10 are needed: a longer part of the "
                             "video, or a higher --fps)")
    if len(kept) < 10:
        raise UserInputError(f"{cfg.video}: a face was found in only {len(kept)} of {read} frames "
                             "(at least 10 are needed)")
    return kept, dropped, read


def sharpness(rgb: np.ndarray, landmarks_px: np.ndarray) -> float:
    """Variance of the Laplacian over the face's box (grey levels): low for motion blur and defocus."""
    lo = np.clip(landmarks_px.min(0).astype(int), 0, None)
    hi = landmarks_px.max(0).astype(int)
    grey = cv2.cvtColor(rgb[lo[1]:hi[1], lo[0]:hi[0]], cv2.COLOR_RGB2GRAY)
    return float(cv2.Laplacian(grey, cv2.CV_64F).var()) if grey.size else 0.0


def face_width_px(faces: list[Face], framing: Framing) -> dict:
    """How wide the face is in the dataset's images (the extent of MediaPipe's 468 face landmarks across, image
    pixels): median, least and most over the frames."""
    widths = np.array([np.ptp(framing.points(f.landmarks_px[:468])[:, 0]) for f in faces])
    return {"median": round(float(np.median(widths)), 1), "min": round(float(widths.min()), 1),
            "max": round(float(widths.max()), 1)}


@dataclass
class Tracked:
    """A video tracked: the kept frames (source index, time, MediaPipe face, sharpness, and the frame's crop as
    "image", RGB uint8), where their crops lie (the framing's canvas), the canvas's intrinsics, the head model's
    fit, and where the fitted head puts every landmark (targets and pixels: canvas pixels; a frame's image pixels
    are these less its offset)."""

    kept: list[dict]
    dropped: list[dict]
    read: int
    framing: Framing
    intrinsics: Intrinsics
    result: object
    targets: np.ndarray
    pixels: np.ndarray
    errors: np.ndarray
    mp_ids: np.ndarray
    vertex_ids: np.ndarray
    info: VideoInfo
    seconds_landmarks: float

    @property
    def faces(self) -> list[Face]:
        return [f["face"] for f in self.kept]


def track_video(cfg: TrackConfig, model) -> Tracked:
    """Landmarks in every sampled frame, the crop, and the head model fitted to them (track's and reenact's first
    half)."""
    t_start = time.perf_counter()
    info = video_info(cfg.video)  # the video first: the input the user thinks of
    bundle = landmarker_path(cfg)
    canonical, _ = canonical_face_mesh(bundle)
    corr = correspond(model, canonical)
    kept, dropped, read = sharp_faces(cfg, bundle, info)
    remember_landmarker(cfg, bundle)
    t_landmarks = time.perf_counter() - t_start
    print(f"{cfg.video}: {len(kept)} of {read} frames kept ({len(dropped)} dropped) in {t_landmarks:.1f} s",
          flush=True)
    framing = face_framing([f["face"].landmarks_px for f in kept], cfg.size, (info.width, info.height), cfg.crop)
    windows = [framing.window(j) for j in range(len(kept))]
    for f, image in zip(kept, cropped_frames(cfg.video, cfg.fps, windows, [f["source_frame"] for f in kept]),
                        strict=True):
        f["image"] = image
    # The fit works on the canvas (one camera for every frame; a frame's window is the canvas cut at its offset).
    f_full = 0.5 * info.width / math.tan(math.radians(cfg.fov_deg) / 2)
    cx, cy = framing.points(np.array([info.width / 2, info.height / 2], np.float32))
    k = Intrinsics(f_full * framing.scale, f_full * framing.scale, float(cx), float(cy))
    faces: list[Face] = [f["face"] for f in kept]
    targets = np.stack([framing.points(f.landmarks_px[corr.mp_ids]) for f in faces])
    result = fit_frames(cfg, model, corr.vertex_ids, faces, targets, k)
    # The error that counts: the full head model's forward pass with the fitted controls, projected.
    with torch.inference_mode():
        verts = Head(model).pose(result.controls)[0]
    pixels = project(verts, k).numpy()
    errors = np.linalg.norm(pixels[:, corr.vertex_ids] - targets, axis=-1)
    return Tracked(kept, dropped, read, framing, k, result, targets, pixels, errors, corr.mp_ids, corr.vertex_ids,
                   info, t_landmarks)


def run_track(cfg: TrackConfig) -> int:
    t_start = time.perf_counter()
    check_config(cfg)
    model = load_head(cfg.head)
    tr = track_video(cfg, model)
    kept, dropped, read, framing, k, result = tr.kept, tr.dropped, tr.read, tr.framing, tr.intrinsics, tr.result
    faces, targets, pixels, errors, t_landmarks = tr.faces, tr.targets, tr.pixels, tr.errors, tr.seconds_landmarks

    with partial_folder(cfg.out) as partial:
        (partial / "tracking").mkdir(parents=True)
        t_masks = time.perf_counter()
        crops = [f["image"] for f in kept]
        bar = Progress("cutting masks", len(crops), unit="frames")
        masks = foreground_masks(crops, [framing.points(face.landmarks_px[:468]) - framing.offsets[j]
                                         for j, face in enumerate(faces)], progress=lambda done, _: bar.update(done))
        t_masks = time.perf_counter() - t_masks
        splits, per_frame, plate_report = write_frames(cfg, partial, kept, crops, masks, framing, k, result, errors,
                                                       tr.info.fps)
        if cfg.overlay:
            o = framing.offsets
            write_video((overlay(img, pixels[j] - o[j], model, targets[j] - o[j], pixels[j][tr.vertex_ids] - o[j])
                         for j, img in enumerate(crops)), partial / "tracking" / "overlay.mp4",
                        fps=cfg.fps or tr.info.fps)
        total = time.perf_counter() - t_start
        report = {
            "video": str(cfg.video), "head_model": absolute_head_spec(cfg.head), "frames_read": read,
            "frames_kept": len(kept),
            "frames_dropped": len(dropped), "dropped": dropped, "splits": {s: len(v) for s, v in splits.items()},
            "split_by": cfg.split,
            "landmarks_used": len(tr.mp_ids), "image_px": cfg.size, "intrinsics": [k.fx, k.fy, k.cx, k.cy],
            "face_width_px": face_width_px(faces, framing),
            "source_face_px": round(float(np.median([np.ptp(f.landmarks_px[:468, 0]) for f in faces])), 1),
            "faces_found_by": {by: sum(f["found_by"] == by for f in kept) for by in ("frame", "following", "search")},
            "upsampled": round(max(cfg.size / framing.side, 1.0), 3),
            "crop": {"x0": round(framing.x0, 1), "y0": round(framing.y0, 1), "side": round(framing.side, 1),
                     "whole_frame": framing.side >= min(tr.info.width, tr.info.height) - 0.5,
                     "following": framing.following, "canvas_px": [framing.width, framing.height]},
            "fov_deg": cfg.fov_deg, "background_plate": plate_report,
            "landmark_error_px": {"median": round(float(np.median(errors)), 3),
                                  "p95": round(float(np.percentile(errors, 95)), 3),
                                  "worst_frame_median": round(float(max(p["median_px"] for p in per_frame)), 3)},
            "seconds": {"landmarks": round(t_landmarks, 2), "fit": round(result.seconds, 2), "masks": round(t_masks, 2),
                        "total": round(total, 2)},
            "seconds_per_frame": round(total / read, 4), "per_frame": per_frame,
        }
        (partial / "tracking" / "report.json").write_text(json.dumps(report, indent=1) + "\n")
    le = report["landmark_error_px"]
    print(f"wrote {cfg.out}: {report['splits']['train']} train, {report['splits']['val']} val, "
          f"{report['splits']['test']} test frames; landmark error median {le['median']:.2f} px, "
          f"95th percentile {le['p95']:.2f} px ({cfg.size} px images, the face {report['face_width_px']['median']:.0f} "
          f"px wide); {total:.1f} s ({report['seconds_per_frame']:.3f} s a frame)"
          + (f"; overlay {cfg.out / 'tracking' / 'overlay.mp4'}" if cfg.overlay else ""))
    small = small_face_note(report, tr.info.width)
    if small:
        print(small)
    print(next_train(cfg.out))
    return 0


def small_face_note(report: dict, width: int) -> str:
    """One line where the face is small in the video: how small, how it was found, and what it costs (the crop's
    pixels upsampled to the dataset's size); empty where it is not.

    >>> small_face_note({"source_face_px": 112.0, "faces_found_by": {"frame": 0, "following": 58, "search": 2},
    ...                  "upsampled": 1.0}, 1920)
    'the face is small in the video (112 px across, 6% of its 1920 px width): found in windows of the frame (60 frames)'
    >>> small_face_note({"source_face_px": 60.0, "faces_found_by": {"frame": 5}, "upsampled": 1.42}, 640)
    'the face is small in the video (60 px across, 9% of its 640 px width): the crop is upsampled 1.42x (less detail)'
    >>> small_face_note({"source_face_px": 280.0, "faces_found_by": {"frame": 50}, "upsampled": 1.0}, 512)
    ''
    """
    found = report["faces_found_by"]
    windows = sum(n for by, n in found.items() if by != "frame")
    parts = []
    if windows:
        parts.append(f"found in windows of the frame ({windows} frames)")
    if report["upsampled"] > 1.0:
        parts.append(f"the crop is upsampled {report['upsampled']:.2f}x (less detail)")
    if not parts:
        return ""
    face = report["source_face_px"]
    return (f"the face is small in the video ({face:.0f} px across, {face / width:.0%} of its {width} px width): "
            + "; ".join(parts))


def check_config(cfg: TrackConfig) -> None:
    if cfg.out.exists():
        raise UserInputError(f"{cfg.out}: already exists; choose a new dataset folder")
    if not 32 <= cfg.size <= 2048:
        raise UserInputError(f"--size {cfg.size}: must be 32..2048 pixels")
    if not 0 < cfg.fov_deg < 170:
        raise UserInputError(f"--fov-deg {cfg.fov_deg}: must be between 0 and 170 degrees")


def sharp_faces(cfg: TrackConfig, bundle: Path, info) -> tuple[list[dict], list[dict], int]:
    """The frames with one face, sharp enough (the face's sharpness against the video's median), with progress:
    a bar on a terminal, a line every 25 frames in a log (the studio's job list shows its last line)."""
    tty = sys.stderr.isatty()
    bar = tqdm(desc="landmarks", unit="frame", disable=not tty)

    def progress(done: int, total: int | None) -> None:
        if tty:
            bar.total = total
            bar.n = done
            bar.refresh()
        elif done % 25 == 0:
            print(f"landmarks: {done}" + (f" of about {total}" if total else "") + " frames", flush=True)

    kept, dropped, read = detect_faces(cfg, bundle, info, progress)
    bar.close()
    sharp = np.array([f["sharpness"] for f in kept])
    limit = cfg.blur * float(np.median(sharp))
    for f, s in zip(list(kept), sharp, strict=True):
        if s < limit:
            kept.remove(f)
            dropped.append({"source_frame": f["source_frame"], "time_s": round(f["time_s"], 3),
                            "reason": f"blurred (sharpness {s:.0f} < {limit:.0f})"})
    if len(kept) < 10:
        raise UserInputError(f"{cfg.video}: only {len(kept)} sharp frames with a face (at least 10 are needed)")
    return kept, dropped, read


def fit_frames(cfg: TrackConfig, model, vertex_ids: np.ndarray, faces: list[Face], targets: np.ndarray,
               k: Intrinsics):
    """The head model fitted to every frame's landmarks (targets (N,L,2), crop pixels), started from the
    blendshape scores."""
    init_expr = np.stack([expression_from_scores(model, f.blendshapes) for f in faces])
    init_jaw = np.stack([jaw_from_scores(f.blendshapes) for f in faces])
    gaze = np.stack([gaze_from_scores(f.blendshapes) for f in faces])
    print(f"fitting {model.name} to {len(faces)} frames...", flush=True)
    base = FitConfig()
    fit_cfg = replace(base, iterations=cfg.iterations, shape_components=cfg.shape_components,
                      smooth_rotation=base.smooth_rotation * cfg.smooth,
                      smooth_translation=base.smooth_translation * cfg.smooth,
                      smooth_expression=base.smooth_expression * cfg.smooth)
    bar = Progress("fitting", fit_cfg.iterations, unit="iterations")
    result = fit(model, vertex_ids, targets, k, init_expr, init_jaw, gaze, fit_cfg, on_iteration=bar.update)
    print(f"fitted {model.name} to {len(faces)} frames ({targets.shape[1]} landmarks) in {result.seconds:.1f} s",
          flush=True)
    return result


def write_frames(cfg: TrackConfig, partial: Path, kept: list[dict], crops: list[np.ndarray], masks: list[np.ndarray],
                 framing: Framing, k: Intrinsics, result, errors: np.ndarray, video_fps: float
                 ) -> tuple[dict[str, list[dict]], list[dict], dict]:
    """The frames as the camera saw them, their masks, the background plate (from the training frames: nothing
    of the held-out ones; the canvas's size, with its own intrinsics, where the crop follows the head: each frame
    then has its own intrinsics, the canvas's less its window's offset) and the three splits' transforms; returns
    the splits, each frame's landmark error and the plate's report."""
    (partial / "images").mkdir()
    (partial / "masks").mkdir()
    n_test = max(1, math.ceil(cfg.test_fraction * len(kept)))
    split_list = frame_splits(cfg.split, np.stack([np.asarray(c.root, np.float64) for c in result.controls]), n_test)
    train = [j for j in range(len(kept)) if split_list[j] == "train"]
    plate, inpainted = background_plate([crops[j] for j in train], [masks[j] for j in train],
                                        grow_px=max(1, round(0.01 * cfg.size)), offsets=framing.offsets[train],
                                        canvas_wh=(framing.width, framing.height))
    write_png8(partial / "background.png", plate / 255.0)
    plate_report = {"file": "background.png", "inpainted_share": round(inpainted, 4),
                    "frames": len(train)}
    own = [[k.fx, k.fy, k.cx - float(ox), k.cy - float(oy)] for ox, oy in framing.offsets]  # each window's camera
    header = {"camera_angle_x": 2 * math.atan(0.5 * cfg.size / k.fx), "intrinsics": own[0],
              "width": cfg.size, "height": cfg.size, "head_model": absolute_head_spec(cfg.head),
              "shape": result.shape.tolist(), "background": "background.png",
              "source": {"video": str(cfg.video.resolve()), "fps": cfg.fps or video_fps, "fov_deg": cfg.fov_deg,
                         "crop": {"x0": framing.x0, "y0": framing.y0, "side": framing.side,
                                  "following": framing.following}}}
    if framing.following:
        header["background_intrinsics"] = [k.fx, k.fy, k.cx, k.cy]
    splits: dict[str, list[dict]] = {"train": [], "val": [], "test": []}
    per_frame = []
    for j, (f, img, mask, c) in enumerate(zip(kept, crops, masks, result.controls, strict=True)):
        name = f"{j:04d}.png"
        write_png8(partial / "images" / name, img / 255.0)
        write_png8(partial / "masks" / name, mask)
        lm = framing.points(f["face"].landmarks_px[:468]) - framing.offsets[j]
        lo, hi = lm.min(0), lm.max(0)
        pad = 0.1 * (hi - lo)
        lo, hi = np.clip((lo - pad) / cfg.size, 0, 1), np.clip((hi + pad) / cfg.size, 0, 1)
        split = split_list[j]
        splits[split].append({
            "file_path": f"images/{name}", "mask_path": f"masks/{name}", "transform_matrix": np.eye(4).tolist(),
            "expression": c.expression.tolist(),
            "controls": {key: v for key, v in controls_to_dict(c).items() if key != "shape"},
            "bbox": [float(lo[1]), float(hi[1]), float(lo[0]), float(hi[0])],
            "source_frame": f["source_frame"], **({"intrinsics": own[j]} if framing.following else {})})
        e = errors[j]
        per_frame.append({"frame": j, "split": split, "source_frame": f["source_frame"],
                          "time_s": round(f["time_s"], 3), "median_px": round(float(np.median(e)), 3),
                          "p95_px": round(float(np.percentile(e, 95)), 3)})
    for split, frames in splits.items():
        write_split(partial, split, header, frames)
    return splits, per_frame, plate_report


_EDGES: dict[int, np.ndarray] = {}


def overlay(img: np.ndarray, verts_px: np.ndarray, model, targets: np.ndarray, fitted: np.ndarray) -> np.ndarray:
    """The frame with the fitted skin's wireframe (every other triangle, those facing the camera), the landmarks
    (green) and where the fitted head puts them (red)."""
    key = id(model)
    if key not in _EDGES:
        skin = np.zeros(len(model.template), bool)
        skin[skin_vertices(model)] = True
        _EDGES[key] = model.triangles[skin[model.triangles].all(1)][::2]
    out = img.copy()
    wire = img.copy()
    tri = verts_px[_EDGES[key]]  # (T,3,2)
    # Triangles facing the camera wind clockwise in image coordinates (y down): draw only those.
    a, b = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    facing = (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]) < 0
    seg = tri[facing].round().astype(np.int32)
    cv2.polylines(wire, list(seg), True, (255, 255, 255), 1, cv2.LINE_AA)
    out = cv2.addWeighted(wire, 0.35, out, 0.65, 0)
    for p in targets.round().astype(int):
        cv2.circle(out, tuple(p), 1, (0, 255, 0), -1)
    for p in fitted.round().astype(int):
        cv2.circle(out, tuple(p), 1, (255, 0, 0), -1)
    return out
