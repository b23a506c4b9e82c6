"""The universal prior model (Cao et al. 2022, Section 3.1, Eq. 1-3) on the volumetric primitives of
models/avatars/primitives: the same layout, march and effects; the decoder takes a spatial 4x4x16 expression code
from the expression encoder and adds the bias maps the identity encoder makes from a person's neutral texture and
geometry. One class is both the prior (trained on many identities, each frame's geometry carrying its identity's
maps) and a person's avatar (the maps of one person in its buffers, `personalize`).

The expression encoder reads the frame's geometry as the guide mesh gives it, less the neutral's (Delta G, in the
chart), so sliders drive it as they drive every avatar; Delta T, the texture's change, is zero in this version
(no frame's unprojected texture reaches the encoder yet): what a mesh cannot show (wrinkles, the mouth's inside)
comes from the identity's bias maps and the decoder alone. Gaze joins the decoder's 8x8 features only over the
chart's eye cells (the seed's masked gaze)."""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, replace
from typing import Annotated, ClassVar

import numpy as np
import torch

from models.avatars.base import TrainingBatch
from models.avatars.components import losses
from models.avatars.names import PersonalTune
from models.avatars.primitives.avatar import PrimitivesAvatar, PrimitivesConfig, PrimitivesGeometry
from models.avatars.primitives.chart import chart_sampler, geometry_map
from models.avatars.primitives.decoder import SlabDecoder
from models.avatars.prior.encoders import ExpressionEncoder, IdentityEncoder, kl_divergence
from models.head.controls import Controls
from models.head.model import HeadModel
from models.ranges import Range


@dataclass(frozen=True)
class PriorConfig(PrimitivesConfig):
    """The primitives' sizes, and the prior's."""

    latent: Annotated[int, Range(1, 256)] = 16
    """Channels of the 4x4 expression code."""
    kl: Annotated[float, Range(0)] = 1e-5
    """The expression code's KL weight (the variational encoder's; summed over the code's 256 numbers). At 1e-3
    the code collapsed (25 minutes on 12 people: an open jaw moved it by about its own size, the decoder read the
    expression from the primitives' places alone)."""
    code_dim: Annotated[int, Range(0, 1024)] = 0
    """No per-frame code: a frame is its identity's maps and its guide mesh."""
    expression_maps: bool = False
    """Unused: the prior reads Delta G through its expression encoder (Eq. 1), not beside its condition."""
    gaze_at_eyes: bool = True
    """Gaze joins the decoder only over the chart's eye cells (the seed's masked gaze)."""
    tune: PersonalTune = "all"
    """Which weights train (PriorAvatar.tune_only): all (the prior's own training, and personalising a person's
    avatar), decoder, or texel (the decoder's per-texel bias maps alone: a whole head's outside)."""


@dataclass
class PriorGeometry(PrimitivesGeometry):
    """A primitives frame (its `expression`: Delta G, 1,3,S,S, what the expression encoder reads) and, for a corpus
    frame, its identity's neutral texture and geometry maps (else the avatar's own)."""

    identity: tuple[torch.Tensor, torch.Tensor] | None = None

    def to(self, device: torch.device | str) -> PriorGeometry:
        base = super().to(device)
        ident = None if self.identity is None else tuple(m.to(device) for m in self.identity)
        return PriorGeometry(**{k: getattr(base, k) for k in PrimitivesGeometry.__dataclass_fields__}, identity=ident)


class PriorAvatar(PrimitivesAvatar):
    name: ClassVar[str] = "prior"
    config_class: ClassVar[type] = PriorConfig
    config_key: ClassVar[str] = "prior"
    personalizes: ClassVar[bool] = True
    all_round: ClassVar[bool] = True
    frames_per_step: ClassVar[int] = 4
    """Personalising keeps 4 frames a step (the primitives' 2 was measured on training from scratch alone)."""

    def __init__(self, head_model: HeadModel, cfg: PriorConfig, n_frames: int, background: np.ndarray,
                 effects: tuple[str, ...] = (), light_dir: tuple[float, float, float] | None = None):
        del n_frames  # no per-frame codes: a frame is its identity's maps and its guide mesh
        super().__init__(head_model, cfg, 1, background, effects, light_dir)
        S = cfg.grid * cfg.voxels
        self.identity_encoder = IdentityEncoder(S, self.decoder.bias_shapes())
        self.expression_encoder = ExpressionEncoder(S, cfg.latent)
        self.register_buffer("neutral_texture", torch.zeros(1, 3, S, S))
        self.register_buffer("neutral_geometry", torch.zeros(1, 3, S, S))
        self.sampler = chart_sampler(head_model, S, cfg.front)  # the chart the layout has (PrimitivesAvatar)
        self._kl: torch.Tensor | None = None
        self._noise: torch.Generator | None = None
        self._own_biases: list[torch.Tensor] | None = None
        self._step_biases: list[torch.Tensor] | None = None
        """Within a training step (`training_step`): this avatar's bias maps, made once for all the step's frames."""
        self._in_step = False
        self.tune_only(cfg.tune)

    @classmethod
    def default_config(cls, tracked: bool) -> None:
        """The prior's own sizes, a video's scan or not (its decoder is the prior's)."""
        del tracked
        return None

    def fit_to_tracked_video(self, corrections: bool | None = None) -> None:
        """No per-frame corrections: the prior keeps no per-frame anything (a frame is its maps and its mesh)."""

    def note_views(self, frames) -> None:
        """What the frames saw: where their fade ends (the neck and shoulders a video's frame cut fade out there,
        note_reach); no cone of views: the prior saw heads from every side, its decoder reads any view."""
        self.note_reach(frames)

    def make_decoder(self) -> SlabDecoder:
        """The primitives' decoder with the spatial expression code in place of the controls' expression (which
        reaches it as Delta G): its condition is the view (and the light where the capture records one)."""
        extra = 3 if self.light_dir is not None else 0
        return SlabDecoder(self.cfg.code_dim + 3 + extra, 6, self.cfg.grid, self.cfg.voxels, 3, self.cfg.width,
                           map_channels=1 if self.casts_shadows else 0, latent_channels=self.cfg.latent)

    # ---- the person --------------------------------------------------------------------------------------
    def personalize(self, texture: torch.Tensor, geometry: torch.Tensor) -> None:
        """Make this avatar the person whose neutral texture and geometry maps (1,3,S,S) these are (Eq. 2)."""
        self.neutral_texture.copy_(texture.reshape(self.neutral_texture.shape))
        self.neutral_geometry.copy_(geometry.reshape(self.neutral_geometry.shape))
        self._own_biases = None

    def tune_only(self, which: PersonalTune) -> None:
        """Which weights training changes from now on (the rest kept as they are; the choice is the config's, so a
        resumed run keeps it): every one ("all"), the decoder's ("decoder": the identity and expression encoders
        kept), or the decoder's per-texel bias maps alone ("texel": each upsampling's and the slab's; a texel no
        frame of the video saw gets no gradient and stays the prior's, where fine-tuning the shared weights changes
        what every texel decodes)."""
        self.cfg = replace(self.cfg, tune=which)
        self.requires_grad_(which == "all")
        if which == "decoder":
            self.decoder.requires_grad_(True)
        elif which == "texel":
            for bias in self.texel_parameters():
                bias.requires_grad_(True)

    def texel_parameters(self) -> list[torch.nn.Parameter]:
        """The decoder's per-texel bias maps: its own (untied) bias of every upsampling level and of the slab."""
        return [*self.decoder.biases, self.decoder.slab_bias]

    def neutral_geometry_of(self, shape: np.ndarray) -> torch.Tensor:
        """(1,3,S,S) the geometry map of the head model's neutral face with these identity coefficients."""
        v, _, _ = self.head.pose([Controls(shape=shape)])
        return geometry_map(self.sampler, self.triangles, v[0])[None]

    def codes(self, frame: int | None, weights: torch.Tensor | None = None) -> torch.Tensor:
        return self.background.new_zeros(1, self.cfg.code_dim)

    # ---- per frame -------------------------------------------------------------------------------------
    @torch.no_grad()
    def controls_expression_map(self, controls: Controls, posed: torch.Tensor, root: torch.Tensor) -> torch.Tensor:
        """Delta G, what the expression encoder reads: the geometry map of the posed mesh (V,3) in the head's frame
        (head_local: root, the posed root joint), less the person's neutral face's."""
        key = np.asarray(controls.shape, np.float32).tobytes()
        if self._neutral is None or self._neutral[0] != key:  # one person's frames follow each other: kept
            self._neutral = key, self.neutral_geometry_of(controls.shape)
        local = self.head_local(controls, posed, root)
        return geometry_map(self.sampler, self.triangles, local)[None] - self._neutral[1]

    def geometry(self, controls: Controls, time_s: float | None = None) -> PriorGeometry:
        base = super().geometry(controls, time_s)
        return PriorGeometry(**{k: getattr(base, k) for k in PrimitivesGeometry.__dataclass_fields__})

    def identity_biases(self, geo: PriorGeometry) -> list[torch.Tensor]:
        """E_id's bias maps (Eq. 2) for the frame's identity: a corpus frame's own maps, else this avatar's (made
        once and kept while the weights do not train: compute once, use often)."""
        if geo.identity is not None:
            return self.identity_encoder(*geo.identity)
        if self.training or torch.is_grad_enabled():
            if not self._in_step:
                return self.identity_encoder(self.neutral_texture, self.neutral_geometry)
            if self._step_biases is None:  # the step's frames are all this person: one pass of E_id, one backward
                self._step_biases = self.identity_encoder(self.neutral_texture, self.neutral_geometry)
            return self._step_biases
        if self._own_biases is None:
            self._own_biases = self.identity_encoder(self.neutral_texture, self.neutral_geometry)
        return self._own_biases

    @contextlib.contextmanager
    def training_step(self):
        """A personalisation step's frames share their identity's bias maps: made once a step (E_id ran for each of
        the step's 4 frames, a quarter of a step's time on one thread)."""
        self._in_step, self._step_biases = True, None
        try:
            yield
        finally:
            self._in_step, self._step_biases = False, None

    def train(self, mode: bool = True):
        self._own_biases = None
        return super().train(mode)

    def decode_slabs(self, geo: PriorGeometry, condition: torch.Tensor, light: torch.Tensor | None,
                     training: bool, posed: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Eq. 1 and 3: the expression code from Delta G (sampled while training: the variational encoder's
        reparameterisation, with its KL kept for the loss), the decoder with the identity's bias maps."""
        condition = condition[:, self.condition_dim:]  # the controls' expression reaches the prior as Delta G only
        delta_t = torch.zeros_like(geo.expression)
        mean, log_var = self.expression_encoder(delta_t, geo.expression)
        if training:
            noise = torch.randn(mean.shape, generator=self._noise).to(mean) if self._noise is not None else \
                torch.randn_like(mean)
            code = mean + noise * (0.5 * log_var).exp()
            self._kl = kl_divergence(mean, log_var)
        else:
            code = mean
        return self.decoder(condition, geo.gaze, light, latent=code, bias_maps=self.identity_biases(geo),
                            gaze_mask=self.gaze_mask)

    def loss_terms(self, batch: TrainingBatch) -> dict[str, torch.Tensor]:
        """The primitives' photometric (l2) and regularisers, l1 beside them (the seed's Section 4.1.1; its VGG
        and GAN terms need downloaded weights or a discriminator's hours), and the expression code's KL."""
        self._kl, self._noise = None, batch.generator  # the sample's own draws, wherever it runs
        out = self.render_rays(batch.rays, batch.geometry, batch.frame, batch.generator, training=True)
        rgb = out.buffers["rgb"]
        return {"photometric": losses.photometric(rgb, batch.target), "l1": (rgb - batch.target).abs().mean(),
                **self.regularisers(out), "kl": self.cfg.kl * self._kl}

    def describe_rendering(self) -> str:
        return "prior: " + super().describe_rendering()
