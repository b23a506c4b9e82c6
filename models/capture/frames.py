"""A capture's frames as the avatars see them: the camera of a frame, its pixels' ray directions, its image."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from PIL import Image
from scipy.ndimage import distance_transform_edt

from models.capture.dataset import CaptureSplit, DatasetError, Frame
from render.camera import Camera


def frame_camera(split: CaptureSplit, frame: Frame) -> Camera:
    """The camera of one of the split's frames (its own intrinsics where it has them: a following crop's)."""
    return pinhole_camera(split.frame_intrinsics(frame), split.width, split.height, frame.camera_to_world)


def camera_of(split: CaptureSplit, c2w: np.ndarray) -> Camera:
    """The split's camera (its intrinsics and image size) placed at c2w."""
    return pinhole_camera(split.intrinsics, split.width, split.height, c2w)


def pinhole_camera(intrinsics, width: int, height: int, c2w: np.ndarray) -> Camera:
    """Any pinhole (principal point anywhere, fx and fy apart); centred cameras with square pixels (within 1e-6 px)
    keep the centred form."""
    fx, fy, cx, cy = intrinsics
    view = np.linalg.inv(c2w)
    if max(abs(cx - width / 2), abs(cy - height / 2), abs(fx - fy)) < 1e-6:
        fov = math.degrees(2 * math.atan(0.5 * height / fy))
        return Camera(view, fov, width, height, near_m=0.05, far_m=10.0)
    return Camera.from_intrinsics(view, fx, fy, cx, cy, width, height, near_m=0.05, far_m=10.0)


#: PIL's modes of a 16-bit grey PNG: its values are 0..65535 (converting to "L" or "RGB" clips them at 255).
_GREY16_MODES = ("I;16", "I;16B", "I;16L", "I;16N")


def _image_has_alpha(im: Image.Image) -> bool:
    """An alpha channel (RGBA, LA, PA), or a tRNS chunk: a palette's transparent entries, or one colour (or grey
    level) transparent."""
    return im.mode in ("RGBA", "LA", "PA") or "transparency" in im.info


def _grey16(im: Image.Image) -> tuple[np.ndarray, np.ndarray | None]:
    """A 16-bit grey image's levels (H,W) in [0,1] (value / 65535), and its alpha (H,W) where a tRNS chunk makes one
    grey level transparent (PIL's convert to RGBA ignores it), else None."""
    raw = np.asarray(im).astype(np.int64)
    t = im.info.get("transparency")
    alpha = None if t is None else (raw != int(t)).astype(np.float32)
    return (raw / 65535.0).astype(np.float32), alpha


def _rgb_or_rgba(im: Image.Image) -> Image.Image:
    """An 8-bit image as RGB, or RGBA where it has alpha (a tRNS chunk's transparent pixels at alpha 0)."""
    return im.convert("RGBA" if _image_has_alpha(im) else "RGB")


def _pixels(im: Image.Image) -> np.ndarray:
    """(H,W,3) or, with alpha (see _image_has_alpha), (H,W,4) float32 in [0,1], as the file holds them."""
    if im.mode in _GREY16_MODES:
        grey, alpha = _grey16(im)
        return np.stack([grey] * 3 + ([] if alpha is None else [alpha]), -1)
    return np.asarray(_rgb_or_rgba(im), np.float32) / 255.0


def has_alpha(path) -> bool:
    """Whether an image file has alpha, as load_rgb and load_rgb8 read it (its header alone is read)."""
    with Image.open(path) as im:
        return _image_has_alpha(im)


def load_rgb8(path) -> np.ndarray:
    """(H,W,3) uint8 as the file holds it, or (H,W,4) where it has alpha (a tRNS chunk's transparency among it); a
    16-bit grey image rounded to 8 bits (value / 257)."""
    with Image.open(path) as im:
        if im.mode in _GREY16_MODES:
            return np.round(_pixels(im) * 255.0).astype(np.uint8)
        return np.asarray(_rgb_or_rgba(im))


def load_rgb(path, background: np.ndarray | None = None) -> np.ndarray:
    """(H,W,3) float32 in [0,1]: the file's colours (a 16-bit grey image's value / 65535), composited over
    `background` where it has alpha or a tRNS chunk's transparency (white where none is given)."""
    with Image.open(path) as im:
        a = _pixels(im)
    if a.shape[-1] == 4:
        bg = np.ones(3, np.float32) if background is None else background
        a = a[..., :3] * a[..., 3:] + bg * (1 - a[..., 3:])
    return a


def background_plate(split: CaptureSplit) -> tuple[np.ndarray, Camera] | None:
    """The capture's background plate (H,W,3) and the one camera it belongs to, where its "background" names an
    image (a tracked video's room); None where the background is a colour. The plate is the frames' size, or of
    its own size with its own intrinsics (a following crop's: every frame's window lies in it)."""
    if not isinstance(split.background, Path):
        return None
    try:
        plate = load_rgb(split.background)
    except (OSError, ValueError) as e:
        raise DatasetError(f"{split.background}: the background plate cannot be read ({e})") from None
    if split.background_intrinsics is None and plate.shape[:2] != (split.height, split.width):
        raise DatasetError(f"{split.background}: the background plate is {plate.shape[1]}x{plate.shape[0]} pixels; "
                           f"the capture's images are {split.width}x{split.height}")
    c2w = [f.camera_to_world for f in split.frames]
    if c2w and not all(np.allclose(m, c2w[0], atol=1e-6) for m in c2w):
        raise DatasetError(f"{split.background}: a background plate needs one fixed camera, and the frames of "
                           f"{split.folder / f'transforms_{split.split}.json'} have several")
    if split.background_intrinsics is not None:
        return plate, pinhole_camera(split.background_intrinsics, plate.shape[1], plate.shape[0],
                                     c2w[0] if c2w else np.eye(4))
    return plate, camera_of(split, c2w[0] if c2w else np.eye(4))


def frame_room(frame: Frame) -> np.ndarray | None:
    """(H,W,3) float the room behind this frame's person as its own camera saw it, where the capture keeps one a
    frame (a tracked video whose camera moved: the frame with the person filled from around); None where the
    capture's plate stands behind every frame."""
    path = frame.extra.get("room_path")
    return None if path is None else read_room(path)


def read_room(path) -> np.ndarray:
    """(H,W,3) float a frame's room from its file (frame_room); DatasetError naming the file where it cannot be read."""
    try:
        return load_rgb(path)
    except (OSError, ValueError) as e:
        raise DatasetError(f"{path}: the frame's room cannot be read ({e})") from None


def load_mask(path) -> np.ndarray:
    """(H,W) coverage in [0,1]: 8-bit levels / 255, 16-bit grey ones / 65535."""
    with Image.open(path) as im:
        if im.mode in _GREY16_MODES:
            return _grey16(im)[0]
        return np.asarray(im.convert("L"), np.float32) / 255.0


def foreground_reach_m(hit: np.ndarray, depth: np.ndarray, mask: np.ndarray, focal_px: float) -> np.ndarray:
    """For each foreground pixel of a capture's mask (H,W) outside the mesh's silhouette (hit, (H,W)), how far
    (metres, at the nearest mesh pixel's depth) it lies from the silhouette: what an avatar must render beyond
    the mesh."""
    outside = (mask > 0.5) & ~hit
    if not outside.any() or not hit.any():
        return np.zeros(0, np.float32)
    dist_px, (ii, jj) = distance_transform_edt(~hit, return_indices=True)
    return (dist_px * depth[ii, jj] / focal_px)[outside].astype(np.float32)


def view_range(split: CaptureSplit, head_centre: np.ndarray) -> dict[str, list[float]]:
    """The directions the capture saw the head from, in the head's own frame (its turn undone: head_rotation): the
    cameras' yaw (0: in front, positive: the subject's left) and pitch, least and most over the frames, degrees.
    head_centre (3,): the head model's template centre (taken as where the head turns about)."""
    from scipy.spatial.transform import Rotation

    yaws, pitches = [], []
    for f in split.frames:
        c = f.camera_to_world[:3, 3]
        centre = np.asarray(head_centre, np.float64) + np.asarray(f.controls.translation, np.float64)
        p = Rotation.from_rotvec(f.controls.head_rotation().astype(np.float64)).inv().apply(c - centre)
        yaws.append(math.degrees(math.atan2(p[0], p[2])))
        pitches.append(math.degrees(math.atan2(p[1], math.hypot(p[0], p[2]))))
    if not yaws:
        return {"yaw_deg": [-180.0, 180.0], "pitch_deg": [-90.0, 90.0]}
    return {"yaw_deg": [round(min(yaws), 1), round(max(yaws), 1)],
            "pitch_deg": [round(min(pitches), 1), round(max(pitches), 1)]}
