"""Fitting a head model to tracked 2D landmarks: identity once per video, then per frame head pose, jaw and
expression, by minimising landmark reprojection error with temporal smoothness (all frames at once, Adam).

The camera sits at the origin looking down -z (OpenGL axes); the head moves (root rotation, translation).
Only the vertices the landmarks sit on are skinned: their rest joints come from the whole mesh through the
joint regressor, precomputed as linear functions of identity and expression, so the fit runs on a few
hundred vertices whatever the head model's size.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np
import torch

from models.head.controls import Controls
from models.head.lbs import blend_shapes, lbs
from models.head.model import HeadModel

#: The fewest landmarks PnP (EPnP) starts a frame's pose from.
MIN_LANDMARKS = 4


class FitError(ValueError):
    """Landmarks that cannot be fitted (no frames, fewer landmarks than PnP needs, none finite); the message says
    what is missing."""


@dataclass(frozen=True)
class Intrinsics:
    fx: float
    fy: float
    cx: float
    cy: float

    def matrix(self) -> np.ndarray:
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1]], np.float64)


@dataclass(frozen=True)
class FitConfig:
    iterations: int = 200
    """All frames at once; the commands' default (app/configs.py)."""
    shape_components: int = 20
    """Identity components fitted (the first ones: the model's largest variations)."""
    lr: float = 0.01
    huber_px: float = 3.0
    smooth_rotation: float = 100.0
    """Weight of the squared change of the head's rotation (radians) from frame to frame."""
    smooth_translation: float = 1000.0
    """... of its translation (metres)."""
    smooth_expression: float = 0.2
    """... of the expression weights and jaw rotation."""
    pose_prior: float = 50.0
    """Weight of the squared rotation (radians) away from each frame's PnP estimate on the neutral head:
    without it, asymmetric expressions (mouthLeft, jawLeft...) trade against head yaw."""
    expression_prior: float = 0.5
    """Weight of the squared expression weights away from their starting values (the landmarker's blendshape
    scores where the model's expressions are named after them, else zero), summed over the weights: a face's
    static differences from the head model (eyes set higher, thinner lips) would otherwise be explained as
    expression in every frame."""
    shape_prior: float = 0.05


@dataclass
class FitResult:
    shape: np.ndarray  # (S,) identity coefficients (the model's full length)
    controls: list[Controls]  # per frame
    error_px: np.ndarray  # (N,K) reprojection error of each landmark, pixels; 0 where it was not fitted
    seconds: float
    fitted: np.ndarray  # (N,K) bool: the landmark's target was finite and in the fit


def expression_bounds(model: HeadModel) -> tuple[float, float]:
    """Named blendshapes (ICT, built-in) are weights in [0, 1]; PCA expressions (FLAME) span about +-3."""
    return (0.0, 1.0) if model.expr_names else (-3.0, 3.0)


def project(points: torch.Tensor, k: Intrinsics) -> torch.Tensor:
    """(...,3) camera-space points (OpenGL: looking down -z) -> (...,2) pixels (x right, y down)."""
    depth = (-points[..., 2]).clamp_min(1e-3)
    return torch.stack([k.cx + k.fx * points[..., 0] / depth, k.cy - k.fy * points[..., 1] / depth], -1)


class LandmarkHead:
    """The head model's forward pass for a subset of its vertices (those the landmarks sit on)."""

    def __init__(self, model: HeadModel, vertex_ids: np.ndarray, shape_components: int):
        t = lambda a: torch.as_tensor(np.asarray(a), dtype=torch.float32)
        S = min(shape_components, model.num_shape)
        self.model, self.S = model, S
        self.template = t(model.template[vertex_ids])
        self.shape_basis = t(model.shape_basis[vertex_ids][..., :S])
        self.expr_basis = t(model.expr_basis[vertex_ids])
        self.pose_basis = t(model.pose_basis[vertex_ids])
        self.weights = t(model.weights[vertex_ids])
        J = t(model.J_regressor)
        self.joint_template = J @ t(model.template)
        self.joint_shape = torch.einsum("jv,vck->jck", J, t(model.shape_basis[..., :S]))
        self.joint_expr = torch.einsum("jv,vck->jck", J, t(model.expr_basis))
        self.parents = [int(p) for p in model.parents]
        self.jaw = model.joint_names.index("jaw") if "jaw" in model.joint_names else None
        self.eyes = tuple(model.joint_names.index(n) if n in model.joint_names else None for n in ("eye_l", "eye_r"))

    def __call__(self, shape: torch.Tensor, expression: torch.Tensor, full_pose: torch.Tensor,
                 translation: torch.Tensor) -> torch.Tensor:
        """(B,K,3) posed landmark vertices for shape (S,), expression (B,E), full_pose (B,J,3), translation (B,3)."""
        B = expression.shape[0]
        rest_joints = (self.joint_template[None] + blend_shapes(shape[None], self.joint_shape)
                       + blend_shapes(expression, self.joint_expr))
        verts, _ = lbs(shape[None].expand(B, -1), expression, full_pose, self.template, self.shape_basis,
                       self.expr_basis, self.pose_basis, torch.zeros(0), self.parents, self.weights, rest_joints)
        return verts + translation[:, None]


def usable_landmarks(vertex_ids: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """(N,K) bool: which of targets (N,K,2) are finite (a landmarker writes NaN where it found no face). FitError
    where nothing can be fitted: no frames, fewer than MIN_LANDMARKS landmarks, or no frame with that many finite."""
    targets = np.asarray(targets)
    K = len(vertex_ids)
    if targets.ndim != 3 or targets.shape[1:] != (K, 2):
        raise FitError(f"landmark targets must be (frames, {K} landmarks, 2) pixels, got shape {targets.shape}")
    if len(targets) == 0:
        raise FitError("no frames to fit landmarks to")
    if K < MIN_LANDMARKS:
        raise FitError(f"fitting a head needs at least {MIN_LANDMARKS} landmarks (PnP), got {K}")
    finite = np.isfinite(targets).all(-1)
    if not (finite.sum(1) >= MIN_LANDMARKS).any():
        raise FitError(f"no frame of {len(targets)} has {MIN_LANDMARKS} finite landmarks (of {K}): no face to fit")
    return finite


def initial_pose(head: LandmarkHead, targets: np.ndarray, k: Intrinsics,
                 finite: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Root rotation (N,3) and translation (N,3) per frame from PnP on the neutral head's landmark vertices, on
    each frame's finite landmarks (finite (N,K), usable_landmarks). A frame with fewer than MIN_LANDMARKS of them
    starts from its neighbours' poses, interpolated linearly (the nearest one's beyond the first or last)."""
    obj = head.template.numpy().astype(np.float64)
    root_joint = head.joint_template[0].numpy().astype(np.float64)
    flip = np.diag([1.0, -1.0, -1.0])  # OpenCV camera axes -> OpenGL
    rots, trans, posed = [], [], []
    for pts, use in zip(targets, finite, strict=True):
        if use.sum() < MIN_LANDMARKS:
            rots.append(np.zeros(3))
            trans.append(np.zeros(3))
            continue
        posed.append(len(rots))
        o, pts = obj[use], pts[use].astype(np.float64)
        ok, rvec, tvec = cv2.solvePnP(o, pts, k.matrix(), None, flags=cv2.SOLVEPNP_EPNP)
        if ok:
            ok, rvec, tvec = cv2.solvePnP(o, pts, k.matrix(), None, rvec, tvec, True)
        R = flip @ cv2.Rodrigues(rvec)[0] if ok else np.eye(3)
        t = flip @ tvec.ravel() if ok else np.array([0.0, 0.0, -0.6])
        if t[2] > -0.05:  # behind or at the camera: PnP failed; start in front of it
            R, t = np.eye(3), np.array([0.0, 0.0, -0.6])
        rots.append(cv2.Rodrigues(R)[0].ravel())
        # LBS turns the head about its root joint: x = R (v - J0) + J0 + translation.
        trans.append(t + R @ root_joint - root_joint)
    rots, trans = np.asarray(rots, np.float32), np.asarray(trans, np.float32)
    if len(posed) < len(rots):
        frames = np.arange(len(rots))
        for a in (rots, trans):
            for c in range(3):
                a[:, c] = np.interp(frames, posed, a[posed, c])
    return rots, trans


def _zero_if_not_finite(a: np.ndarray) -> np.ndarray:
    """A frame without a face has no blendshape scores either: its start (expression, jaw, gaze) is neutral."""
    a = np.asarray(a)
    return np.where(np.isfinite(a), a, np.zeros((), a.dtype))


def fit(model: HeadModel, vertex_ids: np.ndarray, targets: np.ndarray, k: Intrinsics,
        init_expression: np.ndarray | None = None, init_jaw: np.ndarray | None = None,
        gaze: np.ndarray | None = None, cfg: FitConfig = FitConfig(),
        on_iteration: Callable[[int], None] | None = None) -> FitResult:
    """Fit identity, pose, jaw and expression to targets (N,K,2): the pixels of the landmarks that sit on
    vertex_ids (K,). init_expression (N,E) and init_jaw (N,3) start the expression (from the landmarker's
    blendshape scores); gaze (N,2,3), eye rotations, is kept as given. on_iteration(done): after each of
    cfg.iterations (a minute's video takes minutes).

    Targets that are not finite (NaN where a landmarker found no face) are left out of the reprojection term; a
    frame with none left is posed by the temporal smoothness alone, between its neighbours. FitError where
    nothing can be fitted (see usable_landmarks)."""
    import time

    t0 = time.perf_counter()
    finite = usable_landmarks(vertex_ids, targets)
    head = LandmarkHead(model, vertex_ids, cfg.shape_components)
    N, E = len(targets), model.num_expression
    lo, hi = expression_bounds(model)
    rot0, trans0 = initial_pose(head, targets, k, finite)
    # Zeros where a target is not finite: left out of the loss below, but a NaN there would still reach every
    # gradient through the norm's backward (0 * NaN).
    target = torch.as_tensor(np.where(finite[..., None], targets, 0.0), dtype=torch.float32)
    used = torch.as_tensor(finite)
    shape = torch.zeros(head.S, requires_grad=True)
    rot_pnp = torch.as_tensor(rot0)
    rot = rot_pnp.clone().requires_grad_(True)
    trans = torch.as_tensor(trans0).clone().requires_grad_(True)
    expr0 = (np.zeros((N, E), np.float32) if init_expression is None
             else np.clip(_zero_if_not_finite(init_expression), lo, hi))
    expr_start = torch.as_tensor(expr0, dtype=torch.float32)
    expr = expr_start.clone().requires_grad_(True)
    jaw0 = np.zeros((N, 3), np.float32) if init_jaw is None or head.jaw is None else _zero_if_not_finite(init_jaw)
    jaw = torch.as_tensor(jaw0, dtype=torch.float32).clone().requires_grad_(head.jaw is not None)
    eyes = torch.zeros(N, 2, 3) if gaze is None else torch.as_tensor(_zero_if_not_finite(gaze), dtype=torch.float32)
    params = [shape, rot, trans, expr] + ([jaw] if head.jaw is not None else [])
    opt = torch.optim.Adam(params, lr=cfg.lr)

    def full_pose() -> torch.Tensor:
        parts = [rot[:, None]]
        for j in range(1, model.num_joints):
            if j == head.jaw:
                parts.append(jaw[:, None])
            elif j in head.eyes:
                parts.append(eyes[:, head.eyes.index(j)][:, None])
            else:
                parts.append(torch.zeros(N, 1, 3))
        return torch.cat(parts, 1)

    def smooth(x: torch.Tensor) -> torch.Tensor:
        return ((x[1:] - x[:-1]) ** 2).sum(-1).mean() if len(x) > 1 else x.new_zeros(())

    for it in range(cfg.iterations):
        # Pose first: identity and expression join once the head is roughly in place.
        pose_only = it < cfg.iterations // 5
        opt.zero_grad()
        pixels = project(head(shape, expr, full_pose(), trans), k)
        err = (pixels - target).norm(dim=-1)[used]
        loss = torch.nn.functional.huber_loss(err, torch.zeros_like(err), delta=cfg.huber_px)
        loss = loss + cfg.smooth_rotation * smooth(rot) + cfg.smooth_translation * smooth(trans)
        loss = loss + cfg.pose_prior * ((rot - rot_pnp) ** 2).sum(-1).mean()
        loss = loss + cfg.smooth_expression * (smooth(expr) + smooth(jaw))
        loss = loss + cfg.expression_prior * ((expr - expr_start) ** 2).sum(-1).mean()
        loss = loss + cfg.shape_prior * (shape ** 2).mean()
        loss.backward()
        if pose_only:
            for p in (shape, expr, jaw):
                p.grad = None
        opt.step()
        with torch.no_grad():
            expr.clamp_(lo, hi)
            if head.jaw is not None:
                jaw[:, 0].clamp_(0.0, 0.6)
                jaw[:, 1:].zero_()
        if on_iteration is not None:
            on_iteration(it + 1)
    with torch.no_grad():
        pixels = project(head(shape, expr, full_pose(), trans), k)
        error = np.where(finite, (pixels - target).norm(dim=-1).numpy(), 0.0).astype(np.float32)
    full_shape = np.zeros(model.num_shape, np.float32)
    full_shape[: head.S] = shape.detach().numpy()
    e = expr.detach().numpy()
    r, t, jw, g = rot.detach().numpy(), trans.detach().numpy(), jaw.detach().numpy(), eyes.numpy()
    controls = [Controls(shape=full_shape, expression=e[i], root=r[i], translation=t[i],
                         jaw=jw[i] if head.jaw is not None else np.zeros(3, np.float32),
                         gaze_left=g[i, 0] if head.eyes[0] is not None else np.zeros(3, np.float32),
                         gaze_right=g[i, 1] if head.eyes[1] is not None else np.zeros(3, np.float32))
                for i in range(N)]
    return FitResult(full_shape, controls, error, time.perf_counter() - t0, finite)
