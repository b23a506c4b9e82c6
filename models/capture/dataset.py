"""Capture datasets (docs/formats.md): our transforms_{train,val,test}.json format, validated on load, and
importers for NerFACE's transforms files and IMavatar's flame_params.json.

Every error names the file, the frame and the field (DatasetError; the CLI exits with status 2).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from PIL import Image

from models.files import atomic_write
from models.head.controls import Controls, ControlsError, controls_from_dict
from models.head.sources import HEAD_KINDS, HEAD_SPECS

SPLITS = ("train", "val", "test")
#: Optional per-frame paths: synthetic captures' buffers; a tracked video's masks, and its frames' own rooms where its
#: camera moved (room_path: the frame with the person taken out and filled from around).
EXTRA_PATHS = ("mask_path", "normal_path", "shadow_path", "depth_path", "albedo_path", "unshadowed_path", "room_path")
NERFACE_EXPRESSION_DIM = 76


class DatasetError(ValueError):
    """A capture dataset that does not fit its format; the message names the file, frame and field."""


@dataclass(frozen=True)
class Frame:
    index: int
    image_path: Path
    camera_to_world: np.ndarray  # (4,4) OpenGL axes (camera looks down -z)
    expression: np.ndarray  # (E,) as stored (NerFACE's key)
    controls: Controls | None  # None for NerFACE captures (no head model)
    bbox: tuple[float, float, float, float] | None = None  # top, bottom, left, right, normalised
    extra: dict[str, Path] = field(default_factory=dict)  # mask_path, normal_path, ...
    intrinsics: tuple[float, float, float, float] | None = None
    """fx, fy, cx, cy of this frame where they are not the split's (a crop that follows a moving head: each frame's
    window of the video has its own principal point)."""
    time_s: float | None = None
    """Seconds into the video the frame was taken from (a tracked video's `time_s`); None where the capture does
    not say."""


@dataclass(frozen=True)
class CaptureSplit:
    """One split of a capture: cameras, per-frame controls and files."""

    folder: Path
    split: str
    source_format: str  # "avatar-studio", "nerface" or "imavatar"
    width: int
    height: int
    intrinsics: tuple[float, float, float, float]  # fx, fy, cx, cy in pixels
    head_model: str | None
    shape: np.ndarray
    background: np.ndarray | Path
    lighting: dict | None
    frames: list[Frame]
    depth_scale_m: float = 1e-4
    tracked: bool = False
    """Tracked from a video (`avatar-studio track`): the head poses carry the tracker's error."""
    background_intrinsics: tuple[float, float, float, float] | None = None
    """fx, fy, cx, cy of the background plate's own camera where its image is not the frames' (a following crop's
    plate covers every frame's window: each frame sees a part of it); None: the split's intrinsics and size."""

    def frame_intrinsics(self, frame: Frame) -> tuple[float, float, float, float]:
        return self.intrinsics if frame.intrinsics is None else frame.intrinsics

    @property
    def trains_codynerf(self) -> bool:
        """Whether the capture has a head model (NerFACE captures train only the NerFACE baseline)."""
        return self.head_model is not None


def _fail(path: Path, where: str, msg: str) -> DatasetError:
    return DatasetError(f"{path}: {where}{msg}")


def _read_json(path: Path) -> dict:
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise DatasetError(f"{path}: no such file") from None
    except OSError as e:
        raise DatasetError(f"{path}: cannot read ({e.strerror})") from None
    except json.JSONDecodeError as e:
        raise DatasetError(f"{path}: not valid JSON (line {e.lineno}, column {e.colno}: {e.msg})") from None
    if not isinstance(data, dict):
        raise DatasetError(f"{path}: expected a JSON object at the top")
    return data


def _numbers(path: Path, where: str, value: object, shape: tuple[int, ...] | None = None) -> np.ndarray:
    try:
        arr = np.asarray(value, np.float64)
    except (TypeError, ValueError):
        raise _fail(path, where, "must be numbers") from None
    if arr.dtype == object or (shape is not None and arr.shape != shape):
        raise _fail(path, where, f"must have shape {shape}, got {np.shape(value)}")
    if not np.all(np.isfinite(arr)):
        raise _fail(path, where, "has non-finite numbers")
    return arr


def _camera_to_world(path: Path, where: str, value: object) -> np.ndarray:
    m = _numbers(path, where, value)
    if m.shape == (3, 4):
        m = np.vstack([m, [0, 0, 0, 1]])
    if m.shape != (4, 4):
        raise _fail(path, where, f"must be a 4x4 matrix, got shape {m.shape}")
    r = m[:3, :3]
    if (abs(np.linalg.det(r) - 1) > 1e-3 or np.abs(r.T @ r - np.eye(3)).max() > 1e-3
            or np.abs(m[3] - [0, 0, 0, 1]).max() > 1e-6):  # det 1 alone lets a shear or a scaling 2, 1/2, 1 pass
        raise _fail(path, where, "must be a rigid camera-to-world transform (a rotation: R^T R = I, det 1)")
    return m


def _resolve(folder: Path, rel: str, json_path: Path, where: str, must_exist: bool = True) -> Path:
    if not isinstance(rel, str) or not rel:
        raise _fail(json_path, where, "must be a relative path")
    p = (folder / rel).resolve()
    if not p.is_relative_to(folder.resolve()):
        raise _fail(json_path, where, f"'{rel}' points outside the dataset folder")
    if not p.suffix:
        p = p.with_suffix(".png")  # NerFACE writes file paths without the extension
    if must_exist and not p.is_file():
        raise _fail(json_path, where, f"file '{rel}' does not exist")
    return p


def _image_size(path: Path) -> tuple[int, int]:
    try:
        with Image.open(path) as im:
            return im.size
    except OSError as e:
        raise DatasetError(f"{path}: not a readable image ({e})") from None


def check_images(split: CaptureSplit, progress=None) -> int:
    """Open every image the split lists (frames, masks and the other per-frame images, a background plate),
    decode it whole (a truncated file fails here) and check its size against the split's: DatasetError naming
    the file. Returns how many were checked."""
    paths = [p for f in split.frames for p in (f.image_path, *f.extra.values())]
    if isinstance(split.background, Path):
        paths.append(split.background)
    own_size = split.background if split.background_intrinsics is not None else None  # a plate of its own size
    for k, path in enumerate(paths):
        try:
            with Image.open(path) as im:
                im.load()
                size = im.size
        except (OSError, ValueError, SyntaxError) as e:
            raise DatasetError(f"{path}: not a readable image ({e})") from None
        if size != (split.width, split.height) and path != own_size:
            raise DatasetError(f"{path}: {size[0]}x{size[1]} pixels, but the capture's images are "
                               f"{split.width}x{split.height}")
        if progress is not None:
            progress(k + 1, len(paths))
    return len(paths)


def is_capture(folder: str | Path) -> bool:
    """Whether a folder holds a capture in a format load_split reads (a split's transforms, or IMavatar's)."""
    folder = Path(folder)
    return any((folder / f"transforms_{s}.json").is_file() for s in SPLITS) or (folder / "flame_params.json").is_file()


def trained_on(avatar_json: Path) -> str:
    """Where an avatar came from, for a message: the capture its avatar.json records, else how captures are made."""
    try:
        dataset = json.loads(avatar_json.read_text())["provenance"]["dataset"]
    except (OSError, ValueError, KeyError, TypeError):
        dataset = None
    return (f"it was trained on the capture {dataset}" if isinstance(dataset, str) and dataset
            else "a capture is what `avatar-studio track VIDEO` or `avatar-studio synth` writes")


def load_split(folder: str | Path, split: str = "train") -> CaptureSplit:
    """A split of a capture folder in any supported format (ours, NerFACE's or IMavatar's)."""
    folder = Path(folder)
    if split not in SPLITS:
        raise DatasetError(f"split '{split}': expected one of {', '.join(SPLITS)}")
    if not folder.is_dir():
        raise DatasetError(f"{folder}: no such dataset folder")
    if not (folder / f"transforms_{split}.json").is_file() and (folder / "flame_params.json").is_file():
        return load_imavatar(folder, split)
    if not is_capture(folder) and (folder / "avatar.json").is_file():
        raise DatasetError(f"{folder}: is an avatar (it holds avatar.json), not a capture dataset; "
                           + trained_on(folder / "avatar.json"))
    path = folder / f"transforms_{split}.json"
    data = _read_json(path)
    return _load_ours(folder, split, path, data) if "head_model" in data else _load_nerface(folder, split, path, data)


def _frames_list(path: Path, data: dict) -> list:
    frames = data.get("frames")
    if not isinstance(frames, list) or not frames:
        raise _fail(path, "", "field 'frames' must be a non-empty list")
    for i, f in enumerate(frames):
        if not isinstance(f, dict):
            raise _fail(path, f"frame {i}: ", "must be an object")
    return frames


def _load_ours(folder: Path, split: str, path: Path, data: dict) -> CaptureSplit:
    for key in ("width", "height", "intrinsics", "frames"):
        if key not in data:
            raise _fail(path, "", f"field '{key}' is missing")
    w, h = data["width"], data["height"]
    if not all(isinstance(v, int) and v > 0 for v in (w, h)):
        raise _fail(path, "", "fields 'width' and 'height' must be positive integers")
    intr = _intrinsics(path, "field 'intrinsics' ", data["intrinsics"])
    head_model = data["head_model"]
    if not isinstance(head_model, str) or head_model.split(":")[0] not in HEAD_KINDS:
        raise _fail(path, "", f"field 'head_model' must be {HEAD_SPECS}, got {head_model!r}")
    shape = _numbers(path, "field 'shape' ", data.get("shape", []))
    background = data.get("background", [0.0, 0.0, 0.0])
    if isinstance(background, str):
        bg: np.ndarray | Path = _resolve(folder, background, path, "field 'background' ")
    else:
        bg = _numbers(path, "field 'background' ", background, (3,))
    bg_intr = _optional_intrinsics(path, "field 'background_intrinsics' ", data.get("background_intrinsics"))
    if bg_intr is not None and not isinstance(bg, Path):
        raise _fail(path, "", "field 'background_intrinsics' needs a background image (field 'background')")
    frames = []
    for i, f in enumerate(_frames_list(path, data)):
        where = f"frame {i}: "
        for key in ("file_path", "transform_matrix", "controls"):
            if key not in f:
                raise _fail(path, where, f"field '{key}' is missing")
        try:
            controls = controls_from_dict(f["controls"])
        except ControlsError as e:
            raise _fail(path, where, f"field 'controls': {e}") from None
        controls = Controls(shape=shape.astype(np.float32), expression=controls.expression, root=controls.root,
                            neck=controls.neck, jaw=controls.jaw, gaze_left=controls.gaze_left,
                            gaze_right=controls.gaze_right, translation=controls.translation)
        extra = {k: _resolve(folder, f[k], path, f"{where}field '{k}' ") for k in EXTRA_PATHS if k in f}
        frames.append(Frame(
            index=i,
            image_path=_resolve(folder, f["file_path"], path, f"{where}field 'file_path' "),
            camera_to_world=_camera_to_world(path, f"{where}field 'transform_matrix' ", f["transform_matrix"]),
            expression=_numbers(path, f"{where}field 'expression' ", f.get("expression", controls.expression.tolist())),
            controls=controls,
            bbox=_bbox(path, where, f.get("bbox")),
            extra=extra,
            intrinsics=_optional_intrinsics(path, f"{where}field 'intrinsics' ", f.get("intrinsics")),
            time_s=_frame_time(path, where, f.get("time_s")),
        ))
    return CaptureSplit(folder, split, "avatar-studio", w, h, intr, head_model, shape, bg,
                        data.get("lighting"), frames, float(data.get("depth_scale_m", 1e-4)),
                        isinstance(data.get("source"), dict) and "video" in data["source"], bg_intr)


def _frame_time(path: Path, where: str, value: object) -> float | None:
    """A frame's `time_s` (seconds into its video, from 0), None where it is not given."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or value < 0:
        raise _fail(path, where, f"field 'time_s' must be a number of seconds from 0, got {value!r}")
    return float(value)


def _optional_intrinsics(path: Path, where: str, value: object) -> tuple[float, float, float, float] | None:
    """A frame's or a background plate's own fx, fy, cx, cy (pixels), None where it has none."""
    return None if value is None else _intrinsics(path, where, value)


def _intrinsics(path: Path, where: str, value: object) -> tuple[float, float, float, float]:
    """fx, fy, cx, cy (pixels), focal lengths positive (the rays divide by them)."""
    k = _numbers(path, where, value, (4,))
    if k[0] <= 0 or k[1] <= 0:
        raise _fail(path, where, f"must be [fx, fy, cx, cy] with positive focal lengths, got {k.tolist()}")
    return tuple(float(x) for x in k)


def _bbox(path: Path, where: str, value: object) -> tuple[float, float, float, float] | None:
    if value is None:
        return None
    b = _numbers(path, f"{where}field 'bbox' ", value, (4,))
    if b.min() < 0 or b.max() > 1 or b[0] > b[1] or b[2] > b[3]:
        raise _fail(path, where, "field 'bbox' must be [top, bottom, left, right] within [0, 1]")
    return tuple(float(x) for x in b)


def _load_nerface(folder: Path, split: str, path: Path, data: dict) -> CaptureSplit:
    """NerFACE's transforms_*.json: 76-d expressions, no head model, camera_angle_x and optional intrinsics."""
    raw = _frames_list(path, data)
    frames = []
    for i, f in enumerate(raw):
        where = f"frame {i}: "
        for key in ("file_path", "transform_matrix", "expression"):
            if key not in f:
                raise _fail(path, where, f"field '{key}' is missing")
        expr = _numbers(path, f"{where}field 'expression' ", f["expression"])
        if expr.shape != (NERFACE_EXPRESSION_DIM,):
            raise _fail(path, where, f"field 'expression' must have {NERFACE_EXPRESSION_DIM} values, got {expr.size}")
        frames.append(Frame(i, _resolve(folder, f["file_path"], path, f"{where}field 'file_path' "),
                            _camera_to_world(path, f"{where}field 'transform_matrix' ", f["transform_matrix"]),
                            expr, None, _bbox(path, where, f.get("bbox"))))
    w, h = _image_size(frames[0].image_path)
    if "intrinsics" in data:
        intr = _intrinsics(path, "field 'intrinsics' ", data["intrinsics"])
    elif "camera_angle_x" in data:
        fx = 0.5 * w / math.tan(0.5 * _angle_x(path, data["camera_angle_x"]))
        intr = (fx, fx, w / 2, h / 2)
    else:
        raise _fail(path, "", "needs 'intrinsics' or 'camera_angle_x'")
    return CaptureSplit(folder, split, "nerface", w, h, intr, None, np.zeros(0), np.ones(3), None, frames)


def _angle_x(path: Path, value: object) -> float:
    """NerFACE's camera_angle_x: the horizontal field of view (radians), 0 < angle < pi (at 0 the focal length is
    infinite, at pi and beyond zero or negative)."""
    where = "field 'camera_angle_x' "
    angle = _numbers(path, where, value)
    if angle.shape != () or not 0 < angle < math.pi:
        raise _fail(path, where, f"must be one angle in radians between 0 and pi, got {value!r}")
    return float(angle)


def load_imavatar(folder: Path, split: str = "train", test_fraction: float = 0.1) -> CaptureSplit:
    """IMavatar's flame_params.json: per frame a 3x4 world-to-camera `world_mat` (OpenGL axes), 50 FLAME
    expression and 15 pose values (global, neck, jaw, eyes); intrinsics normalised by the image size.
    IMavatar keeps a separate folder per sequence; here the last `test_fraction` of frames is the test split
    and every 20th of the rest the val split."""
    path = folder / "flame_params.json"
    data = _read_json(path)
    raw = _frames_list(path, data)
    for key in ("intrinsics", "shape_params"):
        if key not in data:
            raise _fail(path, "", f"field '{key}' is missing")
    shape = _numbers(path, "field 'shape_params' ", data["shape_params"])
    intr_norm = _numbers(path, "field 'intrinsics' ", data["intrinsics"], (4,))
    frames = []
    for i, f in enumerate(raw):
        where = f"frame {i}: "
        for key in ("file_path", "world_mat", "expression", "pose"):
            if key not in f:
                raise _fail(path, where, f"field '{key}' is missing")
        world_to_camera = _numbers(path, f"{where}field 'world_mat' ", f["world_mat"], (3, 4))
        c2w = _camera_to_world(path, f"{where}field 'world_mat' ", np.linalg.inv(np.vstack([world_to_camera,
                                                                                             [0, 0, 0, 1]])))
        expr = _numbers(path, f"{where}field 'expression' ", f["expression"])
        pose = _numbers(path, f"{where}field 'pose' ", f["pose"], (15,))
        controls = Controls(shape=shape.astype(np.float32), expression=expr.astype(np.float32),
                            root=pose[0:3].astype(np.float32), neck=pose[3:6].astype(np.float32),
                            jaw=pose[6:9].astype(np.float32), gaze_left=pose[9:12].astype(np.float32),
                            gaze_right=pose[12:15].astype(np.float32))
        frames.append(Frame(i, _resolve(folder, f["file_path"], path, f"{where}field 'file_path' "), c2w, expr,
                            controls))
    n_test = max(1, round(test_fraction * len(frames))) if len(frames) > 1 else 0
    rest, test = frames[: len(frames) - n_test], frames[len(frames) - n_test:]
    chosen = {"test": test, "val": rest[::20], "train": [f for k, f in enumerate(rest) if k % 20 != 0] or rest}[split]
    w, h = _image_size(frames[0].image_path)
    fx, fy, cx, cy = intr_norm
    intr = (abs(fx) * w, abs(fy) * h, cx * w, cy * h)
    return CaptureSplit(folder, split, "imavatar", w, h, intr, "flame", shape, np.ones(3), None, chosen)


def write_split(folder: Path, split: str, header: dict, frames: list[dict]) -> Path:
    """Write transforms_{split}.json atomically (temporary file, fsync, rename)."""
    path = folder / f"transforms_{split}.json"
    text = json.dumps({**header, "frames": frames}, indent=1)
    atomic_write(path, lambda tmp: Path(tmp).write_text(text))
    return path
