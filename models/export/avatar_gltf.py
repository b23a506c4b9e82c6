"""An avatar as a glTF 2.0 binary for other tools: its head model's guide mesh at rest with the expressions as
morph targets and the joints as a skin, a colour texture baked from the avatar's renders, and an animation.

The mesh is the head model's template (metres, +y up, +z out of the face), at the origin: the place the capture held
the head (the avatar's rest translation) is left out, as a tool wants a head to stand where it is put. The first V
vertices are the template's, in the head model's order; the copies that the texture's seams need follow
(`mesh.extras.seam_vertex_of` names the vertex each copies).
"""

from __future__ import annotations

import io
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from PIL import Image

from models.avatars.base import Avatar
from models.export import skeleton
from models.export.bake import BakedTexture, bake_texture
from models.export.chart import Chart, head_chart
from models.export.gltf import MeshAsset, Skin, glb_bytes
from models.export.keys import Clip
from models.head.model import HeadModel
from render.gl.raster import Rasterizer
from render.mesh import vertex_normals


@dataclass(frozen=True)
class BakeSettings:
    """How the texture is baked."""

    texture_px: int = 1024
    """Width and height of the texture."""
    render_px: int = 256
    """Width and height of the renders it is baked from."""
    yaws: int = 6
    """Cameras across the yaws the avatar can show, at the head's height (half as many again above and below)."""
    preset: str = "preview"
    """The avatar's quality preset the renders use."""


@dataclass(frozen=True, eq=False)
class Export:
    """A written .glb and what went into it."""

    data: bytes
    chart: Chart
    texture: BakedTexture
    mesh: MeshAsset
    seconds: dict[str, float]  # chart, bake, write


def expression_names(head: HeadModel) -> tuple[str, ...]:
    """The sliders' names of the expressions (expression_K where the head model names none)."""
    return tuple(head.expr_names) or tuple(f"expression_{k}" for k in range(head.num_expression))


def head_skin(head: HeadModel, vertex_of: np.ndarray) -> Skin | None:
    """The head model's joints as a glTF skin for the glTF vertices (each the head-model vertex vertex_of names);
    None for a model with a root alone (nothing to pose that the node's own transform could not)."""
    if head.num_joints < 2:
        return None
    rest = skeleton.rest_joints(head.J_regressor, head.template)
    joints, weights = skeleton.strongest_influences(head.weights)
    return Skin(tuple(head.joint_names), np.asarray(head.parents), skeleton.local_translations(rest, head.parents),
                skeleton.inverse_bind_matrices(rest), joints[vertex_of], weights[vertex_of])


def head_mesh(head: HeadModel, chart: Chart, texture_png: bytes | None) -> MeshAsset:
    """The head model's template on the chart's vertices: normals, the expression basis as morph targets (target k's
    deltas are column k of the basis), the skin."""
    v = chart.vertex_of
    return MeshAsset(name="head", positions=head.template[v], normals=vertex_normals(head.template, head.triangles)[v],
                     uv=chart.uv, triangles=chart.triangles, morph_names=expression_names(head),
                     morph_deltas=np.transpose(head.expr_basis, (2, 0, 1))[:, v], texture_png=texture_png,
                     skin=head_skin(head, v),
                     extras={"head_model": head.name, "seam_vertex_of": v[head.num_vertices:].tolist()})


def png_bytes(image: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    Image.fromarray(image).save(buffer, format="PNG")
    return buffer.getvalue()


def export_glb(avatar: Avatar, rasterizer: Rasterizer, settings: BakeSettings, clip: Clip | None = None,
               on_view: Callable[[int, int], None] | None = None) -> Export:
    """The avatar as a .glb's bytes: chart, bake (on_view(done, total) after each render), mesh, animation."""
    head = avatar.head_model
    t0 = time.perf_counter()
    chart = head_chart(head, settings.texture_px)
    t1 = time.perf_counter()
    texture = bake_texture(avatar, chart, settings.texture_px, settings.render_px, settings.yaws, rasterizer,
                           settings.preset, on_view)
    t2 = time.perf_counter()
    mesh = head_mesh(head, chart, png_bytes(texture.image))
    data = glb_bytes(mesh, (clip,) if clip is not None else (), generator="avatar-studio export")
    t3 = time.perf_counter()
    return Export(data, chart, texture, mesh, {"chart": t1 - t0, "bake": t2 - t1, "write": t3 - t2})
