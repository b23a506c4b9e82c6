"""The tracking pipeline: a monocular video of one face -> the frames, the head model fitted to them, and a capture
dataset (`avatar-studio track`, app/track.py, parses its options, calls these and reports; `reenact` tracks its
driving video with track_video).

Frames are decoded at a chosen rate; MediaPipe's face landmarker finds 478 landmarks, blendshape scores and a head
pose in each; one face-centred square crop serves every frame (fixed intrinsics), or where the head travels so far
that one crop would leave the face small, a crop that follows it (each frame its own window of one canvas, and its
own principal point: video.py); the head model is fitted (identity once, then per frame head pose, jaw and
expression, from landmark reprojection with temporal smoothness; gaze from the blendshape scores), and each
frame's turn split into the torso's slow one and the head's own on the neck (torso.py); MediaPipe's
selfie segmenter (segmenter.py; or GrabCut) cuts a foreground mask per frame, and the room behind the person becomes
a background plate (masks.py) that avatars composite over, or where the room moved, each frame's own room; the
frames are written as the camera saw them; the last part of the video (or with split "view",
the frames where the head is turned furthest: splits.py) is held out as the test split.

`cfg` is the track command's settings (app/configs.py TrackConfig: video, fps, seconds, size, crop, fov_deg, head,
test_fraction, split, iterations, shape_components, smooth, blur), read for those fields alone.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np
import torch

from models.capture.dataset import write_split
from models.capture.synthetic import absolute_head_spec, write_png8
from models.head.controls import controls_to_dict
from models.head.head import Head
from models.tracking.blendshapes import expression_from_scores, gaze_from_scores, jaw_from_scores
from models.tracking.canonical import canonical_face_mesh
from models.tracking.correspond import correspond, skin_vertices
from models.tracking.finder import FaceFinder
from models.tracking.fit import FitConfig, Intrinsics, fit, project
from models.tracking.landmarker import Face
from models.tracking.masks import (
    STILL_ROOM_LEVELS,
    background_plate,
    foreground_masks,
    mask_way,
    own_room,
    room_residual,
)
from models.tracking.splits import frame_splits
from models.tracking.torso import TORSO_SIGMA_S, torso_still
from models.tracking.video import Framing, VideoInfo, cropped_frames, face_framing, sampled_frames
from render.video import write_video


class TrackingError(ValueError):
    """The video cannot be tracked (no frames, too few faces, several people); the message names it."""


def _quiet(*_) -> None:
    return None


@dataclass(frozen=True)
class Feedback:
    """How the pipeline tells what it is doing (the command draws the bars and prints the lines)."""

    say: Callable[[str], None] = _quiet
    """One line of news."""
    landmarks: Callable[[int, int | None], None] = _quiet
    """(frames read, about how many in all or None) as the landmarker reads them."""
    fitting: Callable[[int, int], None] = _quiet
    """(iterations done, in all) as the fit runs."""
    landmarks_found: Callable[[], None] = _quiet
    """Once the landmarker has found enough sharp faces (the command remembers a --landmarker that worked)."""
    masks: Callable[[int, int], None] = _quiet
    """(masks cut, in all) as they are cut."""
    writing: Callable[[int, int], None] = _quiet
    """(frames written, in all) as the capture's frames and masks are written, then the overlay's frames."""


OTHER_PERSON = 0.5
"""A second face at least this share of the main face's width is another person in the shot; a smaller one (a
photograph on the wall, someone far behind) is part of the room, and the largest face is tracked."""


def detect_faces(cfg, bundle: Path, info: VideoInfo, progress: Callable[[int, int | None], None]
                 ) -> tuple[list[dict], list[dict], int]:
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
        raise TrackingError(f"{cfg.video}: no frames could be decoded")
    if several > 0.1 * read:
        raise TrackingError(f"{cfg.video}: several people (a second face at least {OTHER_PERSON:.0%} as wide as the "
                             f"first in {several} of {read} frames); track needs a video of one face")
    if read < 10:
        raise TrackingError(f"{cfg.video}: only {read} frames taken (at least 10 are needed: a longer part of the "
                             "video, or a higher --fps)")
    if len(kept) < 10:
        raise TrackingError(f"{cfg.video}: a face was found in only {len(kept)} of {read} frames "
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


def track_video(cfg, model, bundle: Path, info: VideoInfo, feedback: Feedback = Feedback()) -> Tracked:
    """Landmarks in every sampled frame (with the landmarker `bundle`), the crop, and the head model fitted to them
    (track's and reenact's first half)."""
    t_start = time.perf_counter()
    canonical, _ = canonical_face_mesh(bundle)
    corr = correspond(model, canonical)
    kept, dropped, read = sharp_faces(cfg, bundle, info, feedback.landmarks)
    feedback.landmarks_found()
    t_landmarks = time.perf_counter() - t_start
    feedback.say(f"{cfg.video}: {len(kept)} of {read} frames kept ({len(dropped)} dropped) in {t_landmarks:.1f} s")
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
    result = fit_frames(cfg, model, corr.vertex_ids, faces, targets, k, feedback)
    times = np.array([f["time_s"] for f in kept], np.float64)
    rate = (len(times) - 1) / max(float(times[-1] - times[0]), 1e-6) if len(times) > 1 else 1.0
    result = replace(result, controls=torso_still(result.controls, model, rate))  # the body stays, the neck turns
    # The error that counts: the full head model's forward pass with the fitted controls, projected.
    with torch.inference_mode():
        verts = Head(model).pose(result.controls)[0]
    pixels = project(verts, k).numpy()
    errors = np.linalg.norm(pixels[:, corr.vertex_ids] - targets, axis=-1)
    return Tracked(kept, dropped, read, framing, k, result, targets, pixels, errors, corr.mp_ids, corr.vertex_ids,
                   info, t_landmarks)


def sharp_faces(cfg, bundle: Path, info: VideoInfo, progress: Callable[[int, int | None], None]
                ) -> tuple[list[dict], list[dict], int]:
    """The frames with one face, sharp enough (the face's sharpness against the video's median); progress(done,
    total) as the frames are read (total: about how many, None where the video does not say)."""
    kept, dropped, read = detect_faces(cfg, bundle, info, progress)
    sharp = np.array([f["sharpness"] for f in kept])
    limit = cfg.blur * float(np.median(sharp))
    for f, s in zip(list(kept), sharp, strict=True):
        if s < limit:
            kept.remove(f)
            dropped.append({"source_frame": f["source_frame"], "time_s": round(f["time_s"], 3),
                            "reason": f"blurred (sharpness {s:.0f} < {limit:.0f})"})
    if len(kept) < 10:
        raise TrackingError(f"{cfg.video}: only {len(kept)} sharp frames with a face (at least 10 are needed)")
    return kept, dropped, read


def fit_frames(cfg, model, vertex_ids: np.ndarray, faces: list[Face], targets: np.ndarray, k: Intrinsics,
               feedback: Feedback):
    """The head model fitted to every frame's landmarks (targets (N,L,2), crop pixels), started from the
    blendshape scores."""
    init_expr = np.stack([expression_from_scores(model, f.blendshapes) for f in faces])
    init_jaw = np.stack([jaw_from_scores(f.blendshapes) for f in faces])
    gaze = np.stack([gaze_from_scores(f.blendshapes) for f in faces])
    feedback.say(f"fitting {model.name} to {len(faces)} frames...")
    base = FitConfig()
    fit_cfg = replace(base, iterations=cfg.iterations, shape_components=cfg.shape_components,
                      smooth_rotation=base.smooth_rotation * cfg.smooth,
                      smooth_translation=base.smooth_translation * cfg.smooth,
                      smooth_expression=base.smooth_expression * cfg.smooth)
    result = fit(model, vertex_ids, targets, k, init_expr, init_jaw, gaze, fit_cfg,
                 on_iteration=lambda done: feedback.fitting(done, fit_cfg.iterations))
    feedback.say(f"fitted {model.name} to {len(faces)} frames ({targets.shape[1]} landmarks) in {result.seconds:.1f} s")
    return result


def write_capture(cfg, tr: Tracked, model, folder: Path, feedback: Feedback = Feedback()) -> dict:
    """The tracked video as a capture dataset in `folder` (the frames, their masks, the background plate, the
    splits; with cfg.overlay, tracking/overlay.mp4: the fitted mesh over the frames); returns the tracking report
    (tracking/report.json) but for its total time ("seconds" "total" and "seconds_per_frame": None, the caller's)."""
    (folder / "tracking").mkdir(parents=True)
    t_masks = time.perf_counter()
    crops = [f["image"] for f in tr.kept]
    framing, faces = tr.framing, tr.faces
    way = mask_way(cfg.masks)
    masks = foreground_masks(crops, [framing.points(face.landmarks_px[:468]) - framing.offsets[j]
                                     for j, face in enumerate(faces)], progress=feedback.masks, way=way)
    t_masks = time.perf_counter() - t_masks
    n = len(crops)
    total = n * (2 if cfg.overlay else 1)
    splits, per_frame, plate_report = write_frames(cfg, folder, tr.kept, crops, masks, framing, tr.intrinsics,
                                                   tr.result, tr.errors, tr.info.fps,
                                                   lambda done: feedback.writing(done, total))
    if cfg.overlay:
        o, pixels, targets = framing.offsets, tr.pixels, tr.targets

        def drawn(j: int, img: np.ndarray) -> np.ndarray:
            feedback.writing(n + j + 1, total)
            return overlay(img, pixels[j] - o[j], model, targets[j] - o[j], pixels[j][tr.vertex_ids] - o[j])

        write_video((drawn(j, img) for j, img in enumerate(crops)), folder / "tracking" / "overlay.mp4",
                    fps=cfg.fps or tr.info.fps)
    return {**track_report(cfg, tr, splits, per_frame, plate_report, t_masks), "masks_by": way}


def neck_turns(controls) -> dict | None:
    """How far the head turned on the body (the neck's turn, degrees: torso.py), median and most over the frames;
    None for a head model without a neck, whose root carries the whole turn."""
    turns = np.degrees([float(np.linalg.norm(c.neck)) for c in controls])
    if not np.any(turns):
        return None
    return {"median": round(float(np.median(turns)), 2), "max": round(float(np.max(turns)), 2),
            "torso_sigma_s": TORSO_SIGMA_S}


def track_report(cfg, tr: Tracked, splits: dict[str, list[dict]], per_frame: list[dict], plate_report: dict,
                 t_masks: float) -> dict:
    """What tracking/report.json says of a run: frames kept and dropped, the crop, the plate, the landmark error
    over the frames and each frame's, the time each stage took."""
    k, framing, faces, errors = tr.intrinsics, tr.framing, tr.faces, tr.errors
    return {
        "video": str(cfg.video), "head_model": absolute_head_spec(cfg.head), "frames_read": tr.read,
        "frames_kept": len(tr.kept),
        "frames_dropped": len(tr.dropped), "dropped": tr.dropped, "splits": {s: len(v) for s, v in splits.items()},
        "split_by": cfg.split,
        "landmarks_used": len(tr.mp_ids), "image_px": cfg.size, "intrinsics": [k.fx, k.fy, k.cx, k.cy],
        "face_width_px": face_width_px(faces, framing),
        "source_face_px": round(float(np.median([np.ptp(f.landmarks_px[:468, 0]) for f in faces])), 1),
        "faces_found_by": {by: sum(f["found_by"] == by for f in tr.kept) for by in ("frame", "following", "search")},
        "upsampled": round(max(cfg.size / framing.side, 1.0), 3),
        "crop": {"x0": round(framing.x0, 1), "y0": round(framing.y0, 1), "side": round(framing.side, 1),
                 "whole_frame": framing.side >= min(tr.info.width, tr.info.height) - 0.5,
                 "following": framing.following, "canvas_px": [framing.width, framing.height]},
        "fov_deg": cfg.fov_deg, "background_plate": plate_report,
        "landmark_error_px": {"median": round(float(np.median(errors)), 3),
                              "p95": round(float(np.percentile(errors, 95)), 3),
                              "worst_frame_median": round(float(max(p["median_px"] for p in per_frame)), 3)},
        "neck_turn_deg": neck_turns(tr.result.controls),
        "seconds": {"landmarks": round(tr.seconds_landmarks, 2), "fit": round(tr.result.seconds, 2),
                    "masks": round(t_masks, 2)},
        "seconds_per_frame": None, "per_frame": per_frame,
    }


def write_frames(cfg, partial: Path, kept: list[dict], crops: list[np.ndarray], masks: list[np.ndarray],
                 framing: Framing, k: Intrinsics, result, errors: np.ndarray, video_fps: float,
                 progress: Callable[[int], None] = _quiet) -> tuple[dict[str, list[dict]], list[dict], dict]:
    """The frames as the camera saw them, their masks, the background plate (from the training frames: nothing
    of the held-out ones; the canvas's size, with its own intrinsics, where the crop follows the head: each frame
    then has its own intrinsics, the canvas's less its window's offset) and the three splits' transforms; returns
    the splits, each frame's landmark error and the plate's report; progress(frames written) after each frame."""
    (partial / "images").mkdir()
    (partial / "masks").mkdir()
    n_test = max(1, math.ceil(cfg.test_fraction * len(kept)))
    split_list = frame_splits(cfg.split, np.stack([c.head_rotation().astype(np.float64) for c in result.controls]),
                              n_test)
    train = [j for j in range(len(kept)) if split_list[j] == "train"]
    plate, inpainted = background_plate([crops[j] for j in train], [masks[j] for j in train],
                                        grow_px=max(1, round(0.01 * cfg.size)), offsets=framing.offsets[train],
                                        canvas_wh=(framing.width, framing.height))
    write_png8(partial / "background.png", plate / 255.0)
    residual = room_residual([crops[j] for j in train], [masks[j] for j in train], plate,
                             grow_px=max(1, round(0.03 * cfg.size)), offsets=framing.offsets[train])
    moving = residual > STILL_ROOM_LEVELS
    own_rooms = cfg.room == "frames" or (cfg.room == "auto" and moving)
    plate_report = {"file": "background.png", "inpainted_share": round(inpainted, 4),
                    "frames": len(train), "room_residual_levels": round(residual, 2),
                    "room": "moving" if moving else "still",
                    "behind_frames": "their own rooms (rooms/)" if own_rooms else "the plate",
                    "why": f"--room {cfg.room}" if cfg.room != "auto" else
                    f"the room {'moved' if moving else 'stood still'}: {residual:.1f} levels from the plate "
                    f"({'over' if moving else 'within'} {STILL_ROOM_LEVELS:g})"}
    if own_rooms:
        (partial / "rooms").mkdir()
    own = [[k.fx, k.fy, k.cx - float(ox), k.cy - float(oy)] for ox, oy in framing.offsets]  # each window's camera
    header = split_header(cfg, framing, k, own[0], result.shape, video_fps)
    splits: dict[str, list[dict]] = {"train": [], "val": [], "test": []}
    per_frame = []
    for j, (f, img, mask, c) in enumerate(zip(kept, crops, masks, result.controls, strict=True)):
        name = f"{j:04d}.png"
        write_png8(partial / "images" / name, img / 255.0)
        write_png8(partial / "masks" / name, mask)
        if own_rooms:
            write_png8(partial / "rooms" / name, own_room(img, mask, max(1, round(0.01 * cfg.size))) / 255.0)
        lm = framing.points(f["face"].landmarks_px[:468]) - framing.offsets[j]
        lo, hi = lm.min(0), lm.max(0)
        pad = 0.1 * (hi - lo)
        lo, hi = np.clip((lo - pad) / cfg.size, 0, 1), np.clip((hi + pad) / cfg.size, 0, 1)
        split = split_list[j]
        splits[split].append({
            "file_path": f"images/{name}", "mask_path": f"masks/{name}", "transform_matrix": np.eye(4).tolist(),
            **({"room_path": f"rooms/{name}"} if own_rooms else {}),
            "expression": c.expression.tolist(),
            "controls": {key: v for key, v in controls_to_dict(c).items() if key != "shape"},
            "bbox": [float(lo[1]), float(hi[1]), float(lo[0]), float(hi[0])],
            "source_frame": f["source_frame"], "time_s": round(f["time_s"], 4),
            **({"intrinsics": own[j]} if framing.following else {})})
        e = errors[j]
        per_frame.append({"frame": j, "split": split, "source_frame": f["source_frame"],
                          "time_s": round(f["time_s"], 3), "median_px": round(float(np.median(e)), 3),
                          "p95_px": round(float(np.percentile(e, 95)), 3)})
        progress(j + 1)
    for split, frames in splits.items():
        write_split(partial, split, header, frames)
    return splits, per_frame, plate_report


def split_header(cfg, framing: Framing, k: Intrinsics, first: list[float], shape: np.ndarray, video_fps: float
                 ) -> dict:
    """What every split's transforms file says of the capture: the camera (the first window's intrinsics), the head
    model and its fitted shape, the plate, where the frames came from; the canvas's intrinsics where the crop
    follows the head (the plate's own camera)."""
    header = {"camera_angle_x": 2 * math.atan(0.5 * cfg.size / k.fx), "intrinsics": first,
              "width": cfg.size, "height": cfg.size, "head_model": absolute_head_spec(cfg.head),
              "shape": shape.tolist(), "background": "background.png",
              "source": {"video": str(cfg.video.resolve()), "fps": cfg.fps or video_fps, "fov_deg": cfg.fov_deg,
                         "crop": {"x0": framing.x0, "y0": framing.y0, "side": framing.side,
                                  "following": framing.following}}}
    if framing.following:
        header["background_intrinsics"] = [k.fx, k.fy, k.cx, k.cy]
    return header


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
