"""The prior's conditioning maps (Cao et al. 2022, Section 3.1, Eq. 1-2): a head's geometry (an xyz position image) and
texture (RGB) in the primitives' chart (models/avatars/primitives/layout.py), S x S texels, so that the identity
encoder's maps line up pixel for pixel with the decoder's slabs (S = K M). Every head model gets the same chart.

- geometry: each texel's surface point (where the chart's ray leaves the template, carried by the mesh as it moves),
  in the head's frame, centred and in decimetres (values of order 1);
- texture: the colours of a capture's frames where they see the texel, unprojected (a depth test against the
  posed mesh's raster, weighted by how squarely the camera sees the surface), averaged over frames."""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
from scipy import ndimage

from models.avatars.primitives.chart import GAZE_JOINTS, ChartSampler, carried_by, texel_points
from models.head.model import HeadModel
from render.camera import Camera
from render.fill import push_pull
from render.rays import Raster

VISIBLE_WITHIN_M = 0.004
"""A texel is seen by a pixel whose raster depth is at most this much in front of it."""


def texture_map(sampler: ChartSampler, triangles: torch.Tensor, vertices: torch.Tensor, camera: Camera,
                image: np.ndarray, raster: Raster) -> tuple[np.ndarray, np.ndarray]:
    """One frame's colours unprojected onto the chart: (S,S,3) colours and (S,S) weights (the cosine between the
    surface's normal and the ray to the camera where the texel is seen, else 0). vertices (V,3) world, posed as the
    frame shows them; image (H,W,3) in [0,1]; raster: the posed mesh from the camera."""
    S = sampler.size
    with torch.no_grad():
        p = texel_points(sampler, triangles, vertices.float()).cpu().numpy().astype(np.float64)
        tri = vertices.float()[triangles[torch.as_tensor(np.maximum(sampler.triangles, 0))]].cpu().numpy()
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    cam_pos = np.linalg.inv(camera.view)[:3, 3]
    to_cam = cam_pos - p
    to_cam /= np.maximum(np.linalg.norm(to_cam, axis=1, keepdims=True), 1e-12)
    facing = (n * to_cam).sum(1)
    clip = (camera.projection @ camera.view @ np.c_[p, np.ones(len(p))].T).T
    ndc = clip[:, :2] / np.where(np.abs(clip[:, 3:4]) > 1e-12, clip[:, 3:4], 1e-12)
    H, W = image.shape[:2]
    x, y = (ndc[:, 0] + 1) / 2 * W, (1 - ndc[:, 1]) / 2 * H
    depth = -(camera.view[:3, :3] @ p.T + camera.view[:3, 3:4])[2]
    inside = (x >= 0) & (x < W) & (y >= 0) & (y < H) & (depth > 0)
    xi, yi = np.clip(x.astype(int), 0, W - 1), np.clip(y.astype(int), 0, H - 1)
    seen = inside & sampler.valid & (facing > 0.1) & (depth <= raster.depth[yi, xi] + VISIBLE_WITHIN_M)
    grid = torch.as_tensor(np.stack([x / W * 2 - 1, y / H * 2 - 1], 1), dtype=torch.float32)[None, None]
    rgb = F.grid_sample(torch.as_tensor(image, dtype=torch.float32).permute(2, 0, 1)[None], grid,
                        align_corners=False)[0, :, 0].T.numpy()
    weight = np.where(seen, facing, 0.0)
    return rgb.reshape(S, S, 3), weight.reshape(S, S).astype(np.float32)


CROWN_ABOVE_EYES_M = 0.085
"""Texels this far above the eyes (on the template: the top of the skull, above a tall forehead; a child's rose to 7
cm) are the crown: what a frontal video sees of them is the hair's colour (a bald head's skin), taken for the back
of the head (average_texture)."""

NAPE_BELOW_EYES_M = 0.06
"""Texels no frame saw down to this far below the eyes are the back of the head and take the crown's colour; below
(the nape, the back of the neck) they are filled from around, hair and neck alike."""


HAIR_EDGE_PX = 2
"""beyond_head keeps this many pixels off the person's outline (the room blends in there) and off the head mesh's."""

HAIR_MIN_SHARE = 0.02
"""A capture's hair colour is read from the pixels beyond the mesh (hair_colour) where they are at least this share
of the mesh's own pixels above the eyes; fewer (a bald or close-cropped head the mesh fits) leave it to the crown."""


def eye_level(model: HeadModel) -> float:
    """The eyes' height on the template (y, metres): the mean of the vertices the eye joints carry; a head model
    without them has its eyes 0.35 of its half-height above its middle, where ICT's and the built-in head's lie."""
    verts = np.asarray(model.template, np.float64)
    carried = carried_by(model, GAZE_JOINTS)
    low, high = verts[:, 1].min(), verts[:, 1].max()
    return float(verts[carried, 1].mean() if carried.any() else 0.5 * (low + high) + 0.35 * 0.5 * (high - low))


def eye_vertices(model: HeadModel) -> np.ndarray:
    """(V,) the template's vertices within a centimetre of the eyes' height (eye_level): where they are posed in a
    frame, their mean image row is the eyes' row."""
    return np.abs(np.asarray(model.template, np.float64)[:, 1] - eye_level(model)) < 0.01


def beyond_head(person: np.ndarray, head: np.ndarray, edge_px: int = HAIR_EDGE_PX) -> np.ndarray:
    """(H,W) bool: the person's pixels (mask (H,W) bool) beyond the head mesh's (head (H,W) bool: its raster's
    coverage), edge_px off both outlines (the room blends in at the one, the mesh's edge wavers at the other)."""
    inner = ndimage.binary_erosion(person, iterations=edge_px) if edge_px else person
    return inner & ~(ndimage.binary_dilation(head, iterations=edge_px) if edge_px else head)


def hair_pixels(image: np.ndarray, beyond: np.ndarray, eye_row: float) -> np.ndarray:
    """(N,3) a frame's colours (image (H,W,3)) of the person beyond the head mesh (beyond_head) above the eyes'
    row: what the person has on the head beyond the skull (the hair; a hat; the skin of a bald head the mesh is
    smaller than).

    A person on rows 1-9 and columns 1-10 (columns 2-9 once eroded), the head on rows 6-9 and columns 4-7 (grown
    by a pixel: row 5 columns 4-7, rows 6-10 columns 3-8), the eyes' row 8 (pixel rows 0-7 above it), each pixel's
    red its row: rows 2-4 whole (8 each), row 5 but the grown head's top (4), rows 6 and 7 beside it (2 each).

    >>> person = np.zeros((12, 12), bool); person[1:10, 1:11] = True
    >>> head = np.zeros((12, 12), bool); head[6:10, 4:8] = True
    >>> image = np.zeros((12, 12, 3)); image[..., 0] = np.arange(12)[:, None]
    >>> found = hair_pixels(image, beyond_head(person, head, edge_px=1), eye_row=8.0)
    >>> np.unique(found[:, 0], return_counts=True)[1].tolist()
    [8, 8, 8, 4, 2, 2]
    """
    above = np.arange(image.shape[0])[:, None] + 0.5 < eye_row
    return np.asarray(image)[beyond & above]


HAIR_ROW_PIXELS = 3
"""hair_reach_m counts an image row as hair where this many of its pixels beyond the mesh have the hair's colour."""

HAIR_COLOUR_WITHIN = 0.1
"""A pixel has the hair's colour within this (RGB distance, colours in [0,1])."""

HAIR_GAP_M = 0.02
"""hair_reach_m follows the hair down from the eyes across gaps of at most this (a parting, an earring)."""


def hair_reach_m(image: np.ndarray, beyond: np.ndarray, hair: np.ndarray, eye_row: float, px_per_m: float
                 ) -> float:
    """How far below the eyes (metres, at the head's depth: px_per_m image pixels a metre) a frame shows the hair
    hanging beside the head: the lowest image row, followed down from the eyes' row across gaps of at most
    HAIR_GAP_M, with HAIR_ROW_PIXELS pixels of the person beyond the mesh (beyond, beyond_head) within
    HAIR_COLOUR_WITHIN of the hair's colour; 0 where none is below the eyes (short hair).

    Hair on rows 2-8 and 10 beside a head, a strand on row 14, the eyes on row 3, 100 px a metre (a pixel a
    centimetre: the gap allowed, 2 cm, is 2 rows): row 9's gap is crossed, rows 11-13 are too many, so the hair
    reaches row 10, 7 cm below the eyes.

    >>> beyond = np.zeros((16, 8), bool); beyond[:, :4] = True
    >>> image = np.ones((16, 8, 3)); image[2:9, :4] = 0.2; image[10, :4] = 0.2; image[14, :4] = 0.2
    >>> round(hair_reach_m(image, beyond, np.array([0.2, 0.2, 0.2]), eye_row=3.0, px_per_m=100.0), 6)
    0.07
    """
    near = beyond & (np.linalg.norm(np.asarray(image) - hair, axis=-1) < HAIR_COLOUR_WITHIN)
    rows = near.sum(1) >= HAIR_ROW_PIXELS
    gap, low = HAIR_GAP_M * px_per_m, eye_row
    for y in range(max(int(np.ceil(eye_row)), 0), len(rows)):
        if rows[y]:
            low = float(y)
        elif y - low > gap:
            break
    return (low - eye_row) / px_per_m


def hair_colour(pixels: list[np.ndarray], head_pixels: int) -> np.ndarray | None:
    """(3,) the median colour of frames' hair_pixels ((N,3) each), or None where they are fewer than HAIR_MIN_SHARE
    of head_pixels (the mesh's pixels above the eyes in the same frames)."""
    found = np.concatenate(pixels) if pixels else np.zeros((0, 3))
    if len(found) == 0 or len(found) < HAIR_MIN_SHARE * head_pixels:
        return None
    return np.median(found, axis=0)


def eye_heights(model: HeadModel, sampler: ChartSampler) -> np.ndarray:
    """(S,S) each texel's height above the eyes (eye_level) on the template, metres; nan off the head."""
    verts = np.asarray(model.template, np.float64)
    tri = np.asarray(model.triangles)[np.maximum(sampler.triangles, 0)]
    y = (verts[tri, 1] * sampler.bary).sum(1) - eye_level(model)
    S = sampler.size
    return np.where(sampler.valid, y, np.nan).reshape(S, S)


def weighted_median(values: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(C,) each channel's weighted median of values (N,C) with weights (N,) > 0.

    >>> weighted_median(np.array([[0.0], [1.0], [5.0]]), np.array([1.0, 3.0, 1.0])).tolist()
    [1.0]
    """
    out = []
    for c in values.T:
        order = np.argsort(c)
        cum = np.cumsum(weights[order])
        out.append(c[order][np.searchsorted(cum, 0.5 * cum[-1])])
    return np.array(out)


def weighted_mean(colours: list[np.ndarray], weights: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Frames' unprojected colours (S,S,3 each) averaged with their weights (S,S each): the mean (S,S,3), 0 where no
    frame saw the texel, and the weights' sum (S,S)."""
    w = np.stack(weights)[..., None]
    total = w.sum(0)
    return (np.stack(colours) * w).sum(0) / np.maximum(total, 1e-6), total[..., 0]


def average_texture(colours: list[np.ndarray], weights: list[np.ndarray], fill: np.ndarray | None = None,
                    heights: np.ndarray | None = None, hair: np.ndarray | None = None, hair_reach_m: float = 0.0
                    ) -> tuple[np.ndarray, np.ndarray]:
    """The weighted mean of frames' unprojected colours (S,S,3) and where any frame saw the texel (S,S) bool;
    texels none saw take `fill` where given, else are filled from the seen ones around them (render/fill.py's
    push-pull: a video that saw the front gives the back of the head the colours at the edge of what it saw, where
    the seed's mean of every seen texel gave it the face's skin); grey where none was seen. heights (S,S), each
    texel's height above the eyes (eye_heights): the unseen back of the head, down to NAPE_BELOW_EYES_M below the
    eyes, takes the hair's colour (3,) where given (hair_colour: what the frames show beyond the skull), else the
    colour seen on the crown (the weighted median of the texels CROWN_ABOVE_EYES_M above them), before the fill:
    the edge of a frontal video's view is the ears and cheeks as much as the hair, and from them the back came out
    skin-coloured under dark hair; and the crown's texels see the forehead where the hair starts high (two women
    with their hair drawn back: the backs of their heads came out skin-coloured). hair_reach_m: how far below the
    eyes the frames show the hair hanging (hair_reach_m): long hair takes the back down to there, over the nape
    that the fill gave the neck's skin."""
    mean, total = weighted_mean(colours, weights)
    seen = total > 1e-6
    if fill is not None:
        return np.where(seen[..., None], mean, fill).astype(np.float32), seen
    if not seen.any():
        return np.full_like(mean, 0.5, dtype=np.float32), seen
    known = seen
    if hair is None and heights is not None:
        hair = crown_colour(mean, total, heights)
    if hair is not None and heights is not None:
        back = ~seen & (np.nan_to_num(heights, nan=-1.0) > -max(NAPE_BELOW_EYES_M, hair_reach_m))
        mean = np.where(back[..., None], hair, mean)
        known = seen | back
    return push_pull(mean.astype(np.float64), known).astype(np.float32), seen


def crown_colour(mean: np.ndarray, weight: np.ndarray, heights: np.ndarray) -> np.ndarray | None:
    """(3,) the colour seen on the crown: the weighted median of the texels (S,S,3) seen (weight (S,S) > 0) that lie
    CROWN_ABOVE_EYES_M above the eyes (heights (S,S): eye_heights); None where none of them was seen."""
    crown = (weight > 1e-6) & (np.nan_to_num(heights, nan=-1.0) > CROWN_ABOVE_EYES_M)
    return weighted_median(mean[crown], weight[crown]) if crown.any() else None


def texture_tensor(texture: np.ndarray) -> torch.Tensor:
    """(3,S,S) from (S,S,3) colours in [0,1], centred on grey (the encoders' input range)."""
    return torch.as_tensor(texture, dtype=torch.float32).permute(2, 0, 1) * 2.0 - 1.0
