"""The avatar interface (docs/architecture.md): what every model implements, and all that the rest of the program (the
trainer, eval, bench, the quality presets, turntables, the studio) asks of an avatar.

An avatar is built for a capture (`for_capture`) or from its avatar.json (`from_meta`), and describes itself
for avatar.json (`meta`). Per frame it makes a geometry from the head model's controls (`frame_geometry`:
whatever it needs, meshes, a shadow map, a rigid pose) and says which pixels' rays it renders. For a batch of
rays it gives named buffers (`render_rays`: rgb, opacity, depth, and what its effects provide), its loss terms
for a training batch (`loss_terms`: named, weighted), and after the hot path the inspection buffers it
declares (`inspect`). Images are the same for every model: rendering.py's `render_image` sends a camera's rays
through `render_rays` in batches, with a frozen RenderOptions.

The core a model implements is the abstract methods (for_capture, from_meta, meta, frame_geometry, image_pixels,
note_views, render_rays, loss_terms) and, where it has them, its buffers (buffer_names, layout, inspect); the rest
are hooks with defaults. What it keeps of its capture beside its weights is components it holds (the plate, the
views, the code keys: components/); what its folder says beside the weights is its card (card.py).
"""

from __future__ import annotations

import contextlib
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import torch
from torch import nn

from models.avatars.card import AvatarCard
from models.avatars.components.codes import CodeKeys
from models.avatars.components.kept import keep_weight_names
from models.avatars.mesh import MeshField
from models.head.controls import Controls
from models.head.head import Head
from models.head.model import HeadModel
from render.camera import Camera
from render.gl.raster import Rasterizer
from render.rays import Coverage, Rays

BACKGROUND = "background"
"""The fill of colour buffers outside the rendered pixels: the avatar's background colour."""
BASE_LAYOUT: dict[str, tuple[int, float | str]] = {"rgb": (3, BACKGROUND), "opacity": (0, 0.0),
                                                   "depth": (0, float("inf"))}
"""The buffers every avatar renders: channels (0: scalar) and the value of pixels not rendered."""


class RenderCancelled(Exception):
    """A render stopped part-way because a newer request replaced it."""


@dataclass
class RayOutput:
    """What a model renders for R rays."""

    buffers: dict[str, torch.Tensor]
    """Named per-ray buffers: rgb (R,3), opacity (R,), depth (R,) (expected distance along the ray), and the
    model's own (e.g. normals (R,3))."""
    internals: Any = None
    """The model's intermediate values (samples, weights, per-sample features): its losses and inspection
    buffers read them; nothing outside the model does."""


@dataclass
class TrainingBatch:
    """One frame's rays of a training step."""

    frame: int  # index of the training frame (its per-frame codes)
    rays: Rays
    target: torch.Tensor  # (R,3) the capture's colours
    geometry: Any  # the frame's geometry (frame_geometry)
    progress: float  # share of the run done, in [0,1]: schedules read it
    generator: torch.Generator  # every random draw of the step (its state is checkpointed)


class Avatar(nn.Module, ABC):
    """A head avatar that follows a morphable head model's controls."""

    name: ClassVar[str]
    """The registry's name (models/avatars/registry.py); avatar.json's "model"."""
    rays_per_step: ClassVar[int] = 1024
    """Training rays a step unless told otherwise."""
    frames_per_step: ClassVar[int] = 4
    """Training frames a step draws its rays from unless told otherwise."""
    quality_knobs: ClassVar[tuple[str, ...]] = ()
    """Which fields of a Quality setting change this model's rendering besides the image size (none: the
    model always renders the same way, as the dense NerFACE baseline does)."""
    config_class: ClassVar[type | None] = None
    """The frozen dataclass for_capture's `config` is (`train --model-options` sets its fields); None: none."""
    personalizes: ClassVar[bool] = False
    """Whether `personalize` makes one person's avatar of this one from a scan of them (a universal prior does)."""
    all_round: ClassVar[bool] = False
    """Whether it has a head to show from every side whatever its capture saw (a universal prior's, a whole head's):
    its views are recorded as the full turn, so turntables and the studio's orbit go all the way round."""
    normals_from_surface: ClassVar[bool] = False
    """The normals buffer is the rendered surface's (render/normals.py: the guide mesh's normals where the render's
    depth lies on the mesh, the depth's own elsewhere), made by render_image, not by render_rays: for a model with
    no normals of its own worth showing (a density's gradient, voxel by voxel, is noise)."""
    reads_raster: ClassVar[bool] = True
    """Whether the pixels it renders (image_pixels) and their rays read the posed guide mesh's raster; False: every
    pixel's ray, no mesh rasterized (the primitives' march finds the rays that meet a primitive itself)."""

    @property
    def trains_on_surface(self) -> bool:
        """Whether training's rays carry their distance to the guide mesh (training_surface): a frame's raster is
        then kept (N,H,W); by default where the avatar reads its raster."""
        return self.reads_raster

    def training_surface(self, raster: Any) -> np.ndarray:
        """(H,W) the distance along each pixel's ray to the guide mesh that training's rays carry (Rays.surface_t),
        from a frame's raster (render/gl/raster.py Raster): inf where none. By default the raster's own."""
        return raster.distance

    @classmethod
    def default_config(cls, tracked: bool) -> Any:
        """The config a new avatar of a capture gets (None: for_capture's own defaults); tracked: a tracked video,
        one camera that stays in front of the face."""
        del tracked
        return None

    def __init__(self, head_model: HeadModel, n_frames: int, background: np.ndarray):
        super().__init__()
        self.n_frames = n_frames
        """The capture's training frames (each has its per-frame codes)."""
        self.head_model = head_model
        self.head = Head(head_model)
        self.register_buffer("background", torch.as_tensor(np.asarray(background, np.float32)))
        keep_weight_names(self)  # what a model keeps of its capture (components/kept.py) saved under its old names
        self.card = AvatarCard(self.name, head_model)
        """What its folder says of it beside the weights (card.py: rest pose, views, presets; registry.load_avatar
        reads it)."""

    def background_colour(self) -> np.ndarray:
        """(3,) float32, a copy of the background colour, wherever the avatar's tensors are (a GPU's too: the frames it
        is measured against are composited over it on the CPU)."""
        return self.background.detach().cpu().numpy().astype(np.float32)

    def ray_background(self, rays: Rays) -> torch.Tensor:
        """What each ray sees behind the avatar: the plate's pixel where the rays carry one, else the colour."""
        return self.background if rays.background is None else rays.background

    code_keys: CodeKeys
    """The training frames' control keys (and times) by which frames no one trained on take their codes."""

    optional_buffers: ClassVar[tuple[str, ...]] = ()
    """Buffers of a model's own that it has only where its capture gave them (registered when noted, saved with the
    weights); the plate, the views and the code keys are components (components/kept.py)."""

    def _load_from_state_dict(self, state_dict, prefix, *args, **kwargs):
        """Weights with optional buffers give the avatar them (of their size) before they are read."""
        for name in self.optional_buffers:
            if prefix + name in state_dict:
                self.register_buffer(name, torch.empty_like(state_dict[prefix + name]))
        super()._load_from_state_dict(state_dict, prefix, *args, **kwargs)

    # ---- making and describing -------------------------------------------------------------------------
    @classmethod
    @abstractmethod
    def for_capture(cls, head_model: HeadModel, n_frames: int, background: np.ndarray, effects: tuple[str, ...],
                    lighting: dict | None, config: Any = None) -> Avatar:
        """A new avatar for a capture of n_frames with this lighting record; `config`: the model's own sizes
        (None: its defaults)."""

    @classmethod
    @abstractmethod
    def from_meta(cls, head_model: HeadModel, meta: dict) -> Avatar:
        """The avatar avatar.json describes (before its weights are loaded); KeyError/TypeError/ValueError on
        a description that does not fit."""

    @abstractmethod
    def meta(self) -> dict:
        """What from_meta reads back: the model's name, effects and sizes (JSON data)."""

    @property
    def effects(self) -> tuple[str, ...]:
        """The lighting effects the avatar models (empty: none)."""
        return ()

    def describe_effects(self) -> str:
        """The effects in a few words (reports): "none" without any."""
        return ", ".join(self.effects) or "none"

    def describe_rendering(self) -> str:
        """How the avatar renders, in a few words (reports)."""
        return self.name

    def describe_display(self) -> str:
        """Which code rendered the last display batch, for a model with more than one (the primitives' march: "C",
        or torch and why); "" for the others."""
        return ""

    # ---- per frame -------------------------------------------------------------------------------------
    @abstractmethod
    def frame_geometry(self, controls: Controls, rasterizer: Rasterizer | None, time_s: float | None = None) -> Any:
        """Everything about one frame's head that its rays need (with `.to(device)` and `.posed`, the posed
        vertices (V,3)). time_s: where the frame is one of the avatar's own capture's video, its time there (the
        codes may follow it: components/codes.py)."""

    @abstractmethod
    def image_pixels(self, camera: Camera, raster: Coverage) -> np.ndarray:
        """(H,W) bool: the pixels whose rays are rendered in an image (the rest take each buffer's fill)."""

    def training_pixels(self, camera: Camera, raster: Coverage) -> np.ndarray:
        """(H,W) bool: where training draws its rays."""
        return self.image_pixels(camera, raster)

    def draw_training_pixels(self, active: torch.Tensor, n_pixels: int, n: int, generator: torch.Generator
                             ) -> torch.Tensor:
        """n flat pixel indices of one frame for a training step, from its active ones (K,)."""
        del n_pixels
        return active[torch.randint(len(active), (n,), generator=generator)]

    @abstractmethod
    def note_views(self, frames: Any) -> None:
        """Keep what the training frames (models/training/data.py: their rays' origins, geometry, split) say of
        the views the model was trained on (its `views`, components/views.py), with the weights."""

    def fit_to_capture(self, foreground_reach_m: np.ndarray | None) -> None:
        """Adapt the render settings to the capture: how far (metres, per foreground pixel of the masks) the
        capture's foreground reaches beyond the mesh's silhouette; None where it has no masks."""

    def fit_to_tracked_video(self, corrections: bool | None = None) -> None:
        """The capture was tracked from a video: its head poses carry the tracker's error, and its background is
        a real room. Models adapt what they learn (the default: nothing). corrections: learn per-frame pose (and
        where the model can, expression) corrections (None: the model's default)."""

    def parameter_groups(self) -> list[dict]:
        """The trained parameters in groups, each with its learning rate's scale (`lr_scale`)."""
        return [{"params": list(self.parameters()), "lr_scale": 1.0}]

    # ---- rays ------------------------------------------------------------------------------------------
    @abstractmethod
    def render_rays(self, rays: Rays, geometry: Any, frame: int | None, generator: torch.Generator | None = None,
                    training: bool = False, options: Any = None) -> RayOutput:
        """Named buffers of R rays. frame: a training frame's codes (None: the mean code, for novel controls).
        training: the exact path with every random draw from `generator` (display may take the shortcuts its
        render settings allow). options: render_image's RenderOptions (models/avatars/rendering.py) for a display
        batch: the optional buffers it makes, should_stop and cores for a model whose batches are long; None: all
        buffers, never stopped."""

    @abstractmethod
    def loss_terms(self, batch: TrainingBatch) -> dict[str, torch.Tensor]:
        """The training losses on one frame's rays: named scalars, each already weighted."""

    @classmethod
    def buffer_names(cls, meta: dict) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """The optional buffers render_image makes besides rgb, opacity and depth (render_rays gives them, but for
        the normals of a model whose normals_from_surface is set), and the inspection buffers its effects make
        meaningful, of the avatar this avatar.json describes: told without building it (the studio's window
        offers them; AvatarCard)."""
        del meta
        return (), ()

    def default_buffers(self) -> tuple[str, ...]:
        """The optional buffers render_image makes (buffer_names of this avatar's meta)."""
        return self.buffer_names(self.meta())[0]

    def inspection_buffers(self) -> tuple[str, ...]:
        """The inspection buffers it can make (buffer_names of this avatar's meta)."""
        return self.buffer_names(self.meta())[1]

    def inspect(self, out: RayOutput, geometry: Any, names: tuple[str, ...]) -> dict[str, torch.Tensor]:
        """The named inspection buffers (R,...) of rays already rendered, from their internals."""
        del out, geometry
        if names:
            raise ValueError(f"{self.name} avatars have no inspection buffers {names}")
        return {}

    def layout(self) -> dict[str, tuple[int, float | str]]:
        """Every buffer this avatar can render, with its channels and the fill of pixels not rendered."""
        return dict(BASE_LAYOUT)

    def display_mode(self, options: Any = None) -> contextlib.AbstractContextManager:
        """The autograd mode of display rendering (no gradients unless the model needs some), for render_image's
        RenderOptions (its quality may ask for bf16)."""
        return torch.inference_mode()

    # ---- settings and lifecycle ------------------------------------------------------------------------
    def mesh_field(self, controls: Controls, rasterizer: Rasterizer | None) -> MeshField:
        """The posed avatar's density and colour at any point, for mesh export (models/avatars/mesh.py)."""
        raise ValueError(f"a {self.name} avatar has no field to export as a mesh yet (primitives, prior and "
                         "CoDyNeRF avatars have)")

    @contextlib.contextmanager
    def training_step(self):
        """Around the trainer's loss terms of one step's frames (their backward comes after it): a model may work
        out once what those frames share."""
        yield

    def before_save(self, geometry: Any) -> None:
        """Called before each checkpoint with the first training frame's geometry (display caches follow the
        weights)."""

    @property
    def chunk_rays(self) -> int:
        """Rays per batch when rendering an image (memory)."""
        return 4096

    @property
    def interactive_chunk_rays(self) -> int:
        """Rays a batch in the studio's window: a new request waits at most for the batch in flight (a quarter of
        chunk_rays, whose batches are for throughput: about 40 ms of CoDyNeRF's `final` here)."""
        return 1024
