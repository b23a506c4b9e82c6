"""What the program shows of a render and of the guide mesh, shared by the commands and the studio: which
buffers a render must make to show one, a buffer as an 8-bit image, an image at the size asked for, and the posed
guide mesh as the GL preview draws it."""

from __future__ import annotations

import numpy as np
from PIL import Image

from models.capture.scenes import eye_attribute
from models.head.model import HeadModel
from render.gl.preview import MeshFrame

INSPECT = {"rgb_no_shadows": "rgb_no_shadows", "rgb_light": "rgb_light", "shadow_change": "rgb_no_shadows",
           "shading": "rgb_flat"}
"""Buffers shown from an avatar's inspection buffers (render_image(inspect=True)): which one each needs."""

PLAIN = ("rgb", "depth", "opacity")
"""Buffers every render makes."""


def render_needs(buffer: str) -> tuple[tuple[str, ...], bool]:
    """What a render must make to show `buffer`: the optional buffers (render_image's `buffers`) and whether the
    inspection buffers (`inspect`). Nothing else is made: a primitives avatar's colour render composites 3 channels
    where its normals and light make 7.

    >>> render_needs("rgb"), render_needs("normals"), render_needs("shadow_change")
    (((), False), (('normals',), False), ((), True))
    """
    if buffer in INSPECT:
        return (), True
    return ((), False) if buffer in PLAIN else ((buffer,), False)


def needs_covered(shown: str, wanted: str) -> bool:
    """Whether a render made to show `shown` has what `wanted` needs (no new render when switching to it).

    >>> needs_covered("normals", "rgb"), needs_covered("rgb", "normals"), needs_covered("rgb_light", "shading")
    (True, False, True)
    """
    (have, inspect), (need, inspecting) = render_needs(shown), render_needs(wanted)
    return set(need) <= set(have) and (inspect or not inspecting)


def buffer_image(buffers: dict[str, np.ndarray], name: str) -> np.ndarray:
    """A buffer of the neural render as (H,W,3) uint8 for display."""
    if name == "shadow_change":  # what the pose's and expression's shadow inputs change: darker = shadowed
        img = (0.5 + 2.0 * (buffers["rgb"] - buffers["rgb_no_shadows"]).mean(-1))[..., None].repeat(3, 2)
        return (np.clip(img, 0, 1) * 255).round().astype(np.uint8)
    if name == "shading":  # the render minus the render with every normal facing the viewer, signed about grey
        return (np.clip(0.5 + 2.0 * (buffers["rgb"] - buffers["rgb_flat"]), 0, 1) * 255).round().astype(np.uint8)
    b = buffers[name]
    if name in ("normals", "grad_normals"):
        img = b * 0.5 + 0.5
    elif name == "depth":
        finite = np.isfinite(b)
        lo, hi = (b[finite].min(), b[finite].max()) if finite.any() else (0.0, 1.0)
        img = np.where(finite, 1 - (b - lo) / max(hi - lo, 1e-6), 0)[..., None].repeat(3, 2)
    elif name == "opacity":
        img = b[..., None].repeat(3, 2)
    else:
        img = b
    return (np.clip(img, 0, 1) * 255).round().astype(np.uint8)


def resized(image: np.ndarray, size: int) -> np.ndarray:
    """An (H,W,3) uint8 image at size x size, Lanczos-filtered: a preset's smaller render scaled up to the size asked
    for, a larger picture (a driver's frame) down."""
    if image.shape[:2] == (size, size):
        return image
    return np.asarray(Image.fromarray(image).resize((size, size), Image.Resampling.LANCZOS))


def guide_frame(head: HeadModel, verts: np.ndarray, landmarks: np.ndarray | None = None) -> MeshFrame:
    """The posed guide mesh (V,3) as the GL preview draws it: with its rest positions and eyeballs, so the guide's
    irises follow the gaze."""
    return MeshFrame(verts, head.triangles, landmarks, head.template, eye_attribute(head, head.template))
