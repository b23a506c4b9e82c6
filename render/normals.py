"""A rendered surface's normals from its depth and its guide mesh, as pure numpy functions over images.

A volumetric avatar (the primitives, the prior) has no surface of its own: the gradient of its density, voxel by
voxel, is noise an artist cannot read a surface from. Its expected termination depth is a surface, though, and where
that surface lies on the guide mesh the mesh's smooth normals are the better estimate (the blend of CoDyNeRF's
normals network, "Controllable Dynamic Appearance for Neural 3D Portraits", Eq. 8, by the distance to the mesh,
written out by hand): `surface_normal_image` joins the two, the mesh's where the render's surface lies on it, the
depth's where it leaves it (hair, collar, anything the mesh does not model).
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter

from render.mesh import cross, vertex_normals
from render.rays import Raster

MESH_REACH_M = 0.01
"""The render's surface takes the mesh's normal with weight exp(-(gap / MESH_REACH_M)^2), gap how far along the ray
it lies in front of the mesh's surface: 0.78 at 5 mm, 0.37 at 1 cm, 0.02 at 2 cm (hair over the scalp). A surface at
or behind the mesh (a volume's expected depth lies a few millimetres inside the skin it draws: 7-9 mm median on the
demo avatar's test frames) is the mesh's surface seen through soft opacity, and takes its normal."""
DEPTH_JUMP = 0.05
"""Neighbouring pixels whose depths differ by more than this share of the nearer one are on two surfaces (an ear
before the cheek, the chin before the neck): no difference is taken across them."""


def mesh_normal_image(raster: Raster, vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(H,W,3) the mesh's unit normals (vertex normals interpolated by the raster's barycentric coordinates, the
    smooth shading normal) at every pixel the raster hits, 0 elsewhere.

    >>> from render.rays import Raster
    >>> v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]); t = np.array([[0, 1, 2]])
    >>> r = Raster(np.array([[0, -1]]), np.array([[1.0, np.inf]]), np.array([[[0.2, 0.3, 0.5], [0, 0, 0]]]),
    ...            np.array([[1.0, np.inf]]))
    >>> mesh_normal_image(r, v, t).tolist()  # the triangle in z = 0, counter-clockwise from +z
    [[[0.0, 0.0, 1.0], [0.0, 0.0, 0.0]]]
    """
    vn = vertex_normals(vertices, triangles)
    out = np.zeros((*raster.triangle.shape, 3), np.float32)
    hit = raster.hit
    corners = np.asarray(triangles)[raster.triangle[hit]]  # (N,3) vertex ids
    out[hit] = unit(np.einsum("nk,nkc->nc", np.asarray(raster.bary[hit], np.float32), vn[corners]))
    return out


def _smoothed(values: np.ndarray, valid: np.ndarray, sigma_px: float) -> np.ndarray:
    """(H,W,C) a Gaussian blur of `values` over the valid pixels alone (normalised convolution): an edge pixel is an
    average of its surface, not of the background."""
    if sigma_px <= 0:
        return values
    w = gaussian_filter(valid.astype(np.float32), sigma_px, truncate=3.0)
    blurred = gaussian_filter(values * valid[..., None], (sigma_px, sigma_px, 0.0), truncate=3.0)
    blurred /= np.maximum(w, 1e-12)[..., None]
    return np.where(valid[..., None], blurred, values)


def _difference(points: np.ndarray, t: np.ndarray, valid: np.ndarray, axis: int) -> np.ndarray:
    """(H,W,3) the points' derivative along an image axis: central where both neighbours lie on the pixel's surface,
    one-sided where one does, 0 where neither."""
    lo, hi = [slice(None)] * 2, [slice(None)] * 2
    lo[axis], hi[axis] = slice(0, -1), slice(1, None)
    lo, hi = tuple(lo), tuple(hi)
    a, b = t[lo], t[hi]  # each pair of neighbours: the pixel and the next along the axis
    with np.errstate(invalid="ignore"):
        pair = valid[lo] & valid[hi] & (np.abs(b - a) <= DEPTH_JUMP * np.minimum(a, b))
    step = points[hi] - points[lo]
    step *= pair[..., None]
    out = np.zeros_like(points)
    out[lo] += step  # the pixel's step ahead
    out[hi] += step  # and behind
    sides = np.zeros(t.shape, np.float32)
    sides[lo] += pair
    sides[hi] += pair
    out /= np.maximum(sides, 1.0)[..., None]  # both: their mean, the central difference
    return out


def depth_normal_image(origin: np.ndarray, directions: np.ndarray, distance: np.ndarray,
                       sigma_px: float = 1.0) -> np.ndarray:
    """(H,W,3) unit normals, world, of the surface a depth image draws: each pixel's point o + t d (t its distance
    along its unit ray, inf where nothing is drawn), the cross product of its derivatives along the rows and columns
    (none across a depth jump), turned to face the camera, then smoothed over the drawn pixels by sigma_px; 0 where
    nothing is drawn or the pixel has no neighbour on its surface. In float32 (a millimetre's step at half a metre
    keeps 5 digits).

    >>> d = np.stack(np.meshgrid(np.linspace(-0.1, 0.1, 5), np.linspace(0.1, -0.1, 5)), -1)
    >>> d = np.concatenate([d, -np.ones((5, 5, 1))], -1); d /= np.linalg.norm(d, axis=-1, keepdims=True)
    >>> t = 2.0 / -d[..., 2]  # the plane z = -2 seen head on
    >>> (depth_normal_image(np.zeros(3), d, t)[2, 2].round(6) + 0.0).tolist()
    [0.0, 0.0, 1.0]
    """
    t = np.asarray(distance, np.float32)
    valid = np.isfinite(t)
    d = np.asarray(directions, np.float32)
    points = np.where(valid, t, np.float32(0.0))[..., None] * d
    points += np.asarray(origin, np.float32)
    points *= valid[..., None]
    n = cross(_difference(points, t, valid, 0), _difference(points, t, valid, 1))  # dy x dx faces the camera
    n[np.einsum("hwc,hwc->hw", n, d) > 0] *= -1.0
    n = unit(n)
    # smoothed after the differences, not before: a blur of the points would mix two surfaces across a depth jump
    # before the differences could tell them apart (46 degrees of tilt beside a 10 cm step at 2 px)
    return unit(_smoothed(n, np.einsum("hwc,hwc->hw", n, n) > 0, sigma_px))  # unit or 0: where it has one


def unit(v: np.ndarray) -> np.ndarray:
    """(...,3) vectors scaled to length 1; 0 where they are 0 (in v's floating type)."""
    length = np.sqrt(np.einsum("...c,...c->...", v, v))[..., None]
    return np.where(length > 1e-12, v / np.maximum(length, 1e-12), 0.0).astype(v.dtype, copy=False)


def surface_normal_image(depth_normals: np.ndarray, distance: np.ndarray, mesh_normals: np.ndarray,
                         mesh_distance: np.ndarray, reach_m: float = MESH_REACH_M) -> np.ndarray:
    """(H,W,3) unit normals: the mesh's where the render's surface (distance along the ray, inf where none) lies on
    or behind the mesh (mesh_distance), the depth's where it stands in front of it, weighted by exp(-(gap /
    reach_m)^2); 0 where nothing is drawn.

    >>> up, out = np.array([[[0.0, 1, 0]]]), np.array([[[0.0, 0, 1]]])
    >>> surface_normal_image(out, np.array([[2.0]]), up, np.array([[2.0]])).tolist()  # on the mesh: its normal
    [[[0.0, 1.0, 0.0]]]
    >>> surface_normal_image(out, np.array([[2.0]]), up, np.array([[np.inf]])).tolist()  # no mesh there: the depth's
    [[[0.0, 0.0, 1.0]]]
    """
    t = np.asarray(distance, np.float64)  # the gap of a centimetre between two distances of a metre: in float64
    mesh_normals = np.asarray(mesh_normals, np.float32)
    both = np.isfinite(t) & np.isfinite(mesh_distance) & mesh_normals.any(-1)
    gap = np.maximum(np.where(both, mesh_distance, 0.0) - np.where(both, t, 0.0), 0.0)  # in front of the mesh
    w = np.where(both, np.exp(-np.square(gap / reach_m)), 0.0).astype(np.float32)[..., None]
    n = w * mesh_normals + (1.0 - w) * np.asarray(depth_normals, np.float32)
    n[~np.isfinite(t)] = 0.0
    return unit(n)
