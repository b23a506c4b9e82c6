"""Hard cases for reading captures (models/capture/dataset.py, frames.py), swept by hypothesis: transforms files
with fields missing, of the wrong shape or type, non-finite numbers anywhere, transforms that are not rigid,
focal lengths from 1e-3 to 1e6 px and principal points far outside the image; images of the wrong size, cut short
or not images at all, in every PNG mode (grey, palette, 1-bit, alpha, 16-bit). Each is refused with a
DatasetError naming the file and the field, or read correctly: the numbers as written, the colours as the file
holds them, the cameras' rays finite and unit."""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from PIL import Image
from scipy.spatial.transform import Rotation

from models.capture.dataset import DatasetError, check_images, load_split
from models.capture.frames import frame_camera, load_mask, load_rgb, load_rgb8
from render.rays import pixel_rays

SWEEP = settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                        HealthCheck.function_scoped_fixture])
W, H = 6, 4


def header(**over) -> dict:
    return {"width": W, "height": H, "intrinsics": [10.0, 10.0, 3.0, 2.0], "head_model": "builtin",
            "shape": [0.0, 0.0], "background": [0.5, 0.5, 0.5], **over}


def frame(**over) -> dict:
    return {"file_path": "images/0000.png", "transform_matrix": np.eye(4).tolist(), "controls": {},
            "expression": [0.0, 0.0], "bbox": [0.1, 0.9, 0.2, 0.8], "intrinsics": [10.0, 10.0, 3.0, 2.0], **over}


@pytest.fixture
def capture(tmp_path_factory) -> Path:
    """A capture folder of one 6x4 frame (its transforms written by each test)."""
    folder = tmp_path_factory.mktemp("capture")
    (folder / "images").mkdir()
    Image.fromarray(np.full((H, W, 3), 100, np.uint8)).save(folder / "images" / "0000.png")
    return folder


def write(folder: Path, head: dict, frames: list[dict], text: str | None = None) -> Path:
    path = folder / "transforms_train.json"
    path.write_text(json.dumps({**head, "frames": frames}) if text is None else text)
    return path


def refused(folder: Path, *names: str) -> str:
    """load_split's DatasetError, checked to name the transforms file and each of `names`."""
    with pytest.raises(DatasetError) as e:
        load_split(folder)
    message = str(e.value)
    assert str(folder / "transforms_train.json") in message, message
    for name in names:
        assert name in message, (name, message)
    return message


# ---- fields missing, of the wrong shape or type ---------------------------------------------------------------

@pytest.mark.parametrize(("where", "field"), [("header", k) for k in ("width", "height", "intrinsics", "frames")]
                         + [("frame", k) for k in ("file_path", "transform_matrix", "controls")])
def test_a_missing_field_is_named(capture, where, field):
    doc = {**header(), "frames": [frame()]}
    del (doc if where == "header" else doc["frames"][0])[field]
    write(capture, {}, [], text=json.dumps(doc))
    refused(capture, f"'{field}'", *(["frame 0"] if where == "frame" else []))


WRONG = [  # (header or frame, field, value)
    ("header", "intrinsics", [10.0, 10.0, 3.0]), ("header", "intrinsics", [[10.0, 10.0], [3.0, 2.0]]),
    ("header", "intrinsics", "10 10 3 2"), ("header", "intrinsics", [10.0, None, 3.0, 2.0]),
    ("header", "width", 6.5), ("header", "width", "6"), ("header", "height", 0), ("header", "height", -4),
    ("header", "background", [0.5, 0.5]), ("header", "shape", [[0.0], [0.0, 1.0]]), ("header", "frames", []),
    ("header", "frames", {"0": {}}), ("header", "head_model", "smpl"), ("header", "head_model", 3),
    ("frame", "transform_matrix", np.eye(3).tolist()), ("frame", "transform_matrix", np.eye(4)[:2].tolist()),
    ("frame", "transform_matrix", [np.eye(4).tolist()]), ("frame", "transform_matrix", "identity"),
    ("frame", "transform_matrix", [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0]]),
    ("frame", "bbox", [0.1, 0.9, 0.2]), ("frame", "bbox", [0.9, 0.1, 0.2, 0.8]), ("frame", "bbox", [0, 1, 0, 2]),
    ("frame", "intrinsics", [10.0, 10.0, 3.0]), ("frame", "intrinsics", [0.0, 10.0, 3.0, 2.0]),
    ("frame", "intrinsics", [10.0, -1.0, 3.0, 2.0]), ("frame", "controls", [0.0]),
    ("frame", "controls", {"pose": {"root": [0.0, 1.0]}}), ("frame", "file_path", "../outside.png"),
    ("frame", "file_path", "images/missing.png"), ("frame", "file_path", ""), ("frame", "file_path", 7),
    ("frame", "mask_path", "masks/missing.png"),
]


@pytest.mark.parametrize(("where", "field", "value"), WRONG, ids=[f"{f}={v!r}"[:40] for _, f, v in WRONG])
def test_a_field_of_the_wrong_shape_or_type_is_named(capture, where, field, value):
    doc = {**header(), "frames": [frame()]}
    (doc if where == "header" else doc["frames"][0])[field] = value
    write(capture, {}, [], text=json.dumps(doc))
    names = [f"'{field}'"] if field not in ("width", "height") else ["'width' and 'height'"]
    refused(capture, *names, *(["frame 0"] if where == "frame" else []))


NUMERIC = {  # field: (header or frame, its valid value)
    "intrinsics": ("header", [10.0, 10.0, 3.0, 2.0]), "background": ("header", [0.5, 0.5, 0.5]),
    "shape": ("header", [0.0, 0.0]), "transform_matrix": ("frame", np.eye(4).tolist()),
    "bbox": ("frame", [0.1, 0.9, 0.2, 0.8]), "expression": ("frame", [0.0, 0.0]),
    "frame intrinsics": ("frame", [10.0, 10.0, 3.0, 2.0]),
}


@SWEEP
@given(field=st.sampled_from(sorted(NUMERIC)), position=st.integers(0, 15),
       bad=st.sampled_from(["NaN", "Infinity", "-Infinity"]))
def test_a_non_finite_number_anywhere_is_named(capture, field, position, bad):
    """Python's json writes (and reads) NaN and Infinity, not JSON: a capture written by numpy can hold them."""
    where, value = NUMERIC[field]
    flat = np.asarray(value, np.float64).ravel()
    marker = 123456.0  # put in the number's place, then replaced by its text
    flat[position % len(flat)] = marker
    value = flat.reshape(np.shape(value)).tolist()
    h, f = header(), frame()
    (h if where == "header" else f)[field.removeprefix("frame ")] = value
    write(capture, h, [f], json.dumps({**h, "frames": [f]}).replace(repr(marker), bad))
    refused(capture, f"'{field.removeprefix('frame ')}'", "non-finite", *(["frame 0"] if where == "frame" else []))


def test_text_that_is_not_json_is_named_with_its_line(capture):
    write(capture, {}, [], text='{"width": 6,\n "height": }')
    refused(capture, "not valid JSON", "line 2")


# ---- rigid and non-rigid transforms ---------------------------------------------------------------------------

quaternion = st.tuples(*[st.floats(-1, 1, allow_nan=False)] * 4).filter(lambda q: math.hypot(*q) > 1e-3)
translation = st.tuples(*[st.floats(-1e3, 1e3, allow_nan=False)] * 3)


@SWEEP
@given(q=quaternion, t=translation, three_rows=st.booleans())
def test_a_rigid_transform_is_read_as_written(capture, q, t, three_rows):
    """Any rotation (its rows written to 17 digits) and translation, 4x4 or its top 3x4: read as written."""
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = Rotation.from_quat(q).as_matrix(), t
    write(capture, header(), [frame(transform_matrix=(m[:3] if three_rows else m).tolist())])
    read = load_split(capture).frames[0].camera_to_world
    np.testing.assert_array_equal(read, m)


@SWEEP
@given(q=quaternion, scales=st.tuples(*[st.sampled_from([-1.0, 0.0, 1e-6, 0.5, 1.0, 1.01, 2.0, 1e6])] * 3))
def test_a_transform_that_scales_or_mirrors_is_refused(capture, q, scales):
    """A rotation times a scaling whose determinant is not 1 (mirrored, flattened, grown): not a camera's pose."""
    if abs(np.prod(scales) - 1) < 1e-3:  # a rotation after all (-1, -1, 1 among them): make it grow
        scales = (scales[0], scales[1], 2.0 * scales[2])
    m = np.eye(4)
    m[:3, :3] = Rotation.from_quat(q).as_matrix() @ np.diag(scales)
    write(capture, header(), [frame(transform_matrix=m.tolist())])
    refused(capture, "frame 0", "'transform_matrix'", "rigid")


@pytest.mark.parametrize("name", ["shear", "scale 2, 1/2, 1"])
def test_a_non_rigid_transform_of_determinant_one_is_refused(capture, name):
    m = np.eye(4)
    if name == "shear":
        m[0, 1] = 1.0  # [[1, 1, 0], [0, 1, 0], [0, 0, 1]]: det 1, columns not orthogonal
    else:
        m[:3, :3] = np.diag([2.0, 0.5, 1.0])
    write(capture, header(), [frame(transform_matrix=m.tolist())])
    refused(capture, "frame 0", "'transform_matrix'", "rigid")


# ---- intrinsics -----------------------------------------------------------------------------------------------

focal = st.floats(-3, 6).map(lambda e: 10.0 ** e)  # 1e-3 to 1e6 px
centre = st.floats(-1e6, 1e6, allow_nan=False) | st.sampled_from([0.0, W / 2, float(W)])


@SWEEP
@given(fx=focal, fy=focal, cx=centre, cy=centre, own=st.booleans())
def test_extreme_intrinsics_are_read_and_give_unit_rays(capture, fx, fy, cx, cy, own):
    """Focal lengths from 1e-3 to 1e6 px, the principal point up to 1e6 px outside the image, the split's or the
    frame's own: read as written, and the frame's camera has finite unit rays (float64 within 1e-12)."""
    k = [fx, fy, cx, cy]
    f = frame(intrinsics=k) if own else {k_: v for k_, v in frame().items() if k_ != "intrinsics"}
    write(capture, header(intrinsics=[10.0, 10.0, 3.0, 2.0] if own else k), [f])
    split = load_split(capture)
    assert split.frame_intrinsics(split.frames[0]) == tuple(k)
    _, d = pixel_rays(frame_camera(split, split.frames[0]))
    assert np.isfinite(d).all()
    np.testing.assert_allclose(np.linalg.norm(d, axis=-1), 1.0, atol=1e-12, rtol=0)


@pytest.mark.parametrize("k", [[0.0, 0.0, 3.0, 2.0], [-10.0, 10.0, 3.0, 2.0], [10.0, 0.0, 3.0, 2.0]])
def test_zero_or_negative_focal_lengths_of_the_split_are_refused(capture, k):
    write(capture, header(intrinsics=k), [frame()])
    refused(capture, "'intrinsics'", "focal")


def nerface(folder: Path, **head) -> None:
    write(folder, head, [{"file_path": "images/0000", "transform_matrix": np.eye(4).tolist(), "expression": [0] * 76}])


@pytest.mark.parametrize("angle", [0.3, 1.0, 2.5])
def test_a_nerface_field_of_view_is_read_as_a_focal_length(capture, angle):
    nerface(capture, camera_angle_x=angle)
    fx = 0.5 * W / math.tan(0.5 * angle)  # the field of view across the image's width
    assert load_split(capture).intrinsics == pytest.approx((fx, fx, W / 2, H / 2), rel=1e-12)


@pytest.mark.parametrize("head", [{"camera_angle_x": 0.0}, {"camera_angle_x": [0.5, 0.5]},
                                  {"camera_angle_x": -0.5}, {"camera_angle_x": 4.0},
                                  {"intrinsics": [0.0, 0.0, 3.0, 2.0]}], ids=lambda h: repr(h))
def test_an_unusable_nerface_camera_is_refused(capture, head):
    nerface(capture, **head)
    refused(capture, f"'{next(iter(head))}'")


# ---- images ---------------------------------------------------------------------------------------------------

@SWEEP
@given(size=st.tuples(st.integers(1, 9), st.integers(1, 9)).filter(lambda s: s != (W, H)),
       which=st.sampled_from(["file_path", "mask_path"]))
def test_an_image_of_the_wrong_size_is_named(capture, size, which):
    (capture / "masks").mkdir(exist_ok=True)
    for folder in ("images", "masks"):  # both of the capture's size, then one of them not
        Image.fromarray(np.zeros((H, W), np.uint8)).save(capture / folder / "0000.png")
    path = capture / ("images" if which == "file_path" else "masks") / "0000.png"
    Image.fromarray(np.zeros(size[::-1], np.uint8)).save(path)
    write(capture, header(), [frame(mask_path="masks/0000.png")])
    with pytest.raises(DatasetError) as e:
        check_images(load_split(capture))
    assert str(path) in str(e.value) and f"{size[0]}x{size[1]}" in str(e.value) and f"{W}x{H}" in str(e.value)


@pytest.mark.parametrize("damage", ["cut short", "not an image", "empty"])
def test_an_unreadable_image_is_named(capture, damage):
    path = capture / "images" / "0000.png"
    data = path.read_bytes()
    path.write_bytes({"cut short": data[: len(data) // 2], "not an image": b"<html>404</html>", "empty": b""}[damage])
    write(capture, header(), [frame()])
    with pytest.raises(DatasetError, match="not a readable image") as e:
        check_images(load_split(capture))
    assert str(path) in str(e.value)


pixels = st.binary(min_size=H * W * 4, max_size=H * W * 4).map(lambda b: np.frombuffer(b, np.uint8).reshape(H, W, 4))


@SWEEP
@given(px=pixels, mode=st.sampled_from(["L", "LA", "RGB", "RGBA", "P", "1"]),
       bg=st.sampled_from([None, (0.0, 0.0, 0.0), (0.2, 0.4, 0.9)]))
def test_8_bit_images_in_every_mode_read_as_they_hold(tmp_path, px, mode, bg):
    """Colours are the bytes / 255; with alpha (RGBA, LA) composited over the background (white where none is given):
    rgb a + bg (1 - a). load_rgb8 keeps the bytes, and its alpha."""
    path = tmp_path / f"{mode}.png"
    if mode in ("RGB", "RGBA", "L", "LA"):
        grey = mode.startswith("L")
        Image.fromarray(px[..., [0, 3] if mode == "LA" else slice(0, 1 if grey else len(mode))].copy().squeeze()
                        ).save(path)
        rgb = np.repeat(px[..., :1], 3, -1) if grey else px[..., :3]
        alpha = px[..., 3] if mode in ("RGBA", "LA") else None
    elif mode == "P":  # a palette of the pixels' own colours, indices into it
        colours, index = np.unique(px[..., :3].reshape(-1, 3), axis=0, return_inverse=True)
        im = Image.fromarray(index.reshape(H, W).astype(np.uint8), "L").convert("P")  # (keeps the indices)
        im.putpalette(colours.ravel().tolist())
        im.save(path)
        rgb, alpha = px[..., :3], None
    else:  # 1 bit a pixel: black or white
        Image.fromarray(px[..., 0] >= 128).save(path)
        rgb, alpha = np.repeat(np.where(px[..., :1] >= 128, 255, 0).astype(np.uint8), 3, -1), None
    expect = rgb / 255.0
    if alpha is not None:
        a = alpha[..., None] / 255.0
        expect = expect * a + np.asarray(bg if bg is not None else (1.0, 1.0, 1.0)) * (1 - a)
    got = load_rgb(path, None if bg is None else np.asarray(bg, np.float32))
    np.testing.assert_allclose(got, expect, atol=1e-6, rtol=0)
    raw = load_rgb8(path)
    np.testing.assert_array_equal(raw[..., :3], rgb)
    if alpha is not None:
        np.testing.assert_array_equal(raw[..., 3], alpha)


@SWEEP
@given(px=st.binary(min_size=H * W * 8, max_size=H * W * 8).map(
    lambda b: np.frombuffer(b, np.uint16).reshape(H, W, 4)), alpha=st.booleans())
def test_16_bit_colour_images_read_within_a_level(tmp_path, px, alpha):
    """A 16-bit RGB(A) PNG (written by OpenCV, channels BGR(A)): its colours within 1/255 of value / 65535 (PIL
    keeps the high byte), alpha composited over white."""
    path = tmp_path / "rgb16.png"
    chans = 4 if alpha else 3
    cv2.imwrite(str(path), np.ascontiguousarray(px[..., :chans][..., [2, 1, 0, 3][:chans]]))
    expect = px[..., :3] / 65535.0
    if alpha:
        a = px[..., 3:] / 65535.0
        expect = expect * a + (1 - a)
    np.testing.assert_allclose(load_rgb(path), expect, atol=2 / 255, rtol=0)


@pytest.mark.parametrize("reader", ["load_rgb", "load_mask"])
def test_16_bit_grey_images_read_within_a_level(tmp_path, reader):
    v = np.array([[0, 1000, 32768], [40000, 65000, 65535]], np.uint16)
    Image.fromarray(v).save(tmp_path / "grey16.png")
    got = load_rgb(tmp_path / "grey16.png")[..., 0] if reader == "load_rgb" else load_mask(tmp_path / "grey16.png")
    np.testing.assert_allclose(got, v / 65535.0, atol=1 / 255, rtol=0)


@pytest.mark.parametrize("mode", ["P", "RGB"])
def test_transparency_of_a_palette_or_colour_key_is_alpha(tmp_path, mode):
    a = np.zeros((2, 2, 3), np.uint8)
    a[0, 0] = (255, 0, 0)  # red; the black pixels are transparent
    if mode == "P":
        im = Image.fromarray(a).convert("P")
        im.save(tmp_path / "t.png", transparency=int(np.asarray(im)[1, 1]))
    else:
        Image.fromarray(a).save(tmp_path / "t.png", transparency=(0, 0, 0))
    got = load_rgb(tmp_path / "t.png", np.array([0.0, 1.0, 0.0], np.float32))  # over green
    np.testing.assert_array_equal(got[1, 1], [0.0, 1.0, 0.0])
    np.testing.assert_array_equal(got[0, 0], [1.0, 0.0, 0.0])
