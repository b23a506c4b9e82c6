"""Synthetic captures (docs/captures.md): a head model performing the capture protocol under one lighting
scene, drawn through render/gl, written as a dataset with its ground truth (masks, normals, cast-shadow
masks, depth, albedo, and for scenes with cast shadows the image without them)."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import cv2
import numpy as np
import torch

from models.capture.configs import SynthConfig
from models.capture.dataset import write_split
from models.capture.looks import Look, look_for_identity
from models.capture.people import Person, dress
from models.capture.scenes import head_appearance, lighting_record, scene_lighting
from models.capture.script import FrameSpec, Rig, held_out_script, make_rig, training_script
from models.head.controls import Controls, controls_to_dict
from models.head.head import Head
from models.head.model import HeadModel, portrait_vertices
from render.camera import Camera, look_at
from render.gl.capture import Appearance, CaptureBuffers, CaptureMesh, CaptureRenderer
from render.gl.context import GLContext

DEPTH_SCALE_M = 1e-4  # one unit of the 16-bit depth PNGs
SHADOW_MIN_N_DOT_L = 0.05  # a surface facing away from the light is in attached, not cast, shadow


def view_offsets_deg(views: int) -> list[float]:
    """The rig's cameras' yaw about the script's camera, evenly round the head, in (-180, 180].

    >>> view_offsets_deg(3), view_offsets_deg(4)
    ([0.0, 120.0, -120.0], [0.0, 90.0, 180.0, -90.0])
    """
    return [float((360.0 * k / views + 180.0) % 360.0 - 180.0) or 0.0 if k * 2 != views else 180.0
            for k in range(views)]


def absolute_head_spec(spec: str) -> str:
    """ict:/flame: paths made absolute, so the dataset names its head model wherever it is opened from."""
    kind, sep, arg = spec.partition(":")
    return f"{kind}:{Path(arg).resolve()}" if sep and kind in ("ict", "flame") else spec


def identity_coefficients(head: HeadModel, identity: int) -> np.ndarray:
    if identity == 0:
        return np.zeros(head.num_shape, np.float32)
    rng = np.random.default_rng(identity)
    k = min(head.num_shape, 20)  # the leading components carry the identity
    coeffs = np.zeros(head.num_shape, np.float32)
    coeffs[:k] = np.clip(rng.normal(0, 1, k), -2, 2) * np.linspace(1.0, 0.4, k)
    return coeffs


def frame_camera(head_center: np.ndarray, distance_m: float, spec: FrameSpec, size: int, fov_y_deg: float
                 ) -> Camera:
    yaw, pitch = math.radians(spec.camera_yaw_deg), math.radians(spec.camera_pitch_deg)
    eye = head_center + distance_m * np.array([math.sin(yaw) * math.cos(pitch), math.sin(pitch),
                                               math.cos(yaw) * math.cos(pitch)])
    return Camera(look_at(eye, head_center), fov_y_deg, size, size, near_m=0.05, far_m=5.0)


def frame_controls(rig: Rig, spec: FrameSpec, shape: np.ndarray) -> Controls:
    # Head turn: yaw about +y, then pitch about +x (positive pitch tips the face up), as one axis-angle.
    yaw, pitch = math.radians(spec.head_yaw_deg), math.radians(-spec.head_pitch_deg)
    rot = _axis_angle_from_matrix(_rot_y(yaw) @ _rot_x(pitch))
    base = Controls(shape=shape, root=rot.astype(np.float32))
    return rig.controls(spec.weights, base)


def _rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _rot_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _axis_angle_from_matrix(R: np.ndarray) -> np.ndarray:
    angle = math.acos(np.clip((np.trace(R) - 1) / 2, -1, 1))
    if angle < 1e-9:
        return np.zeros(3)
    axis = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / (2 * math.sin(angle))
    return axis * angle


def write_png16(path: Path, rgb01: np.ndarray) -> None:
    """(H,W,3) values in [0,1] as a 16-bit RGB PNG."""
    data = np.round(np.clip(rgb01, 0, 1) * 65535).astype(np.uint16)
    if not cv2.imwrite(str(path), cv2.cvtColor(data, cv2.COLOR_RGB2BGR)):
        raise OSError(f"{path}: could not write PNG")


def read_png16(path: Path) -> np.ndarray:
    data = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if data is None:
        raise OSError(f"{path}: not a readable PNG")
    return cv2.cvtColor(data, cv2.COLOR_BGR2RGB).astype(np.float64) / 65535.0


def write_png8(path: Path, values01: np.ndarray) -> None:
    data = np.round(np.clip(values01, 0, 1) * 255).astype(np.uint8)
    if data.ndim == 3:
        data = cv2.cvtColor(data, cv2.COLOR_RGB2BGR)
    if not cv2.imwrite(str(path), data):
        raise OSError(f"{path}: could not write PNG")


def cast_shadow(buffers: CaptureBuffers) -> np.ndarray:
    """(H,W) in [0,1]: how much of the key light is blocked on surfaces that face it (cast shadows only)."""
    facing = buffers.n_dot_l > SHADOW_MIN_N_DOT_L
    return np.where(facing, (1.0 - buffers.visibility) * buffers.coverage, 0.0)


def _bbox(lmks_px: np.ndarray, size: int) -> list[float]:
    lo, hi = lmks_px.min(0), lmks_px.max(0)
    pad = 0.15 * (hi - lo)
    lo, hi = np.clip((lo - pad) / size, 0, 1), np.clip((hi + pad) / size, 0, 1)
    return [float(lo[1]), float(hi[1]), float(lo[0]), float(hi[0])]


def _project(camera: Camera, points: np.ndarray) -> np.ndarray:
    clip = (camera.projection @ camera.view @ np.c_[points, np.ones(len(points))].T).T
    ndc = clip[:, :2] / clip[:, 3:4]
    return np.stack([(ndc[:, 0] + 1) / 2 * camera.width_px, (1 - ndc[:, 1]) / 2 * camera.height_px], 1)


@dataclass(frozen=True, eq=False)
class Sitter:
    """Everything a capture keeps fixed about its person: the head model with an identity, dressed for a look, and
    where the cameras aim and stand."""

    model: Head
    rig: Rig
    shape: np.ndarray  # (S,) identity coefficients
    canonical: np.ndarray  # (V,3) the neutral head with its identity
    person: Person
    appearance: Appearance
    center: np.ndarray  # (3,) what the cameras look at
    distance_m: float

    def frame(self, spec: FrameSpec, size: int, fov_y_deg: float) -> tuple[CaptureMesh, Camera, Controls, np.ndarray]:
        """One frame of the script: the posed, dressed mesh, the camera, the controls and the (L,3) landmarks."""
        controls = frame_controls(self.rig, spec, self.shape)
        verts, _, lmks = self.model.pose(controls)
        verts, lmks = verts[0].numpy(), lmks[0].numpy()
        p = self.person
        posed, tangent = p.pose(self.canonical, verts)
        mesh = CaptureMesh(posed, p.triangles, p.canonical, p.material, tangent)
        return mesh, frame_camera(self.center, self.distance_m, spec, size, fov_y_deg), controls, lmks


def make_sitter(head: HeadModel, identity: int, look: Look, fov_y_deg: float) -> Sitter:
    shape = identity_coefficients(head, identity)
    model = Head(head)
    with torch.inference_mode():
        canonical = model.pose(Controls(shape=shape))[0][0].numpy()
    portrait = portrait_vertices(head, canonical)  # the face frames the shot, whatever the hair
    center = 0.5 * (portrait.min(0) + portrait.max(0))
    radius = float(np.linalg.norm(portrait - center, axis=1).max())
    return Sitter(model, make_rig(head), shape, canonical, dress(head, canonical, look),
                  head_appearance(head, canonical, look), center,
                  1.1 * radius / math.sin(math.radians(fov_y_deg) / 2))


def synthesize(cfg: SynthConfig, head: HeadModel, gl: GLContext,
               progress: Callable[[int, int], None] | None = None) -> dict:
    """Render and write the capture; returns a summary (frames per split, seconds)."""
    t0 = time.perf_counter()
    out = cfg.out
    lighting = scene_lighting(cfg.scene, cfg.light_deg)
    subs = ("images", "masks", "normals", "shadows", "depth", "albedo") + (("unshadowed",) if lighting.shadows else ())
    for sub in subs:
        (out / sub).mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(cfg.seed)
    n_test = max(1, round(0.1 * cfg.frames))
    script = training_script(cfg.frames - n_test, rng, cfg.turn_deg)
    val_ids = set(range(7, len(script), 20))
    test = held_out_script(n_test, [s for k, s in enumerate(script) if k not in val_ids], rng, turn_deg=cfg.turn_deg)
    look = look_for_identity(cfg.identity, cfg.hair, cfg.hair_color)
    sitter = make_sitter(head, cfg.identity, look, cfg.fov_y_deg)
    rig, shape = sitter.rig, sitter.shape
    renderer = CaptureRenderer(gl)
    bg = np.asarray(cfg.background, np.float64)
    f_px = 0.5 * cfg.size / math.tan(math.radians(cfg.fov_y_deg) / 2)
    header = {
        "camera_angle_x": math.radians(cfg.fov_y_deg),
        "intrinsics": [f_px, f_px, cfg.size / 2, cfg.size / 2],
        "width": cfg.size, "height": cfg.size,
        "head_model": absolute_head_spec(cfg.head), "shape": shape.tolist(), "background": bg.tolist(),
        "lighting": lighting_record(cfg.scene, lighting, cfg.light_deg),
        "depth_scale_m": DEPTH_SCALE_M,
        "protocol": {"frames": cfg.frames, "seed": cfg.seed, "identity": cfg.identity, "look": asdict(look),
                     "views": cfg.views,
                     "turn_deg": cfg.turn_deg,
                     "expression_channels": {c: d.tolist() for c, d in rig.directions.items()},
                     "jaw_joint": rig.jaw_joint},
    }
    splits: dict[str, list[dict]] = {"train": [], "val": [], "test": []}
    jobs = [("val" if k in val_ids else "train", s) for k, s in enumerate(script)] + [("test", s) for s in test]
    jobs = [(split, replace(s, camera_yaw_deg=s.camera_yaw_deg + off)) for split, s in jobs
            for off in view_offsets_deg(cfg.views)]
    with torch.inference_mode():
        for k, (split, spec) in enumerate(jobs):
            mesh, camera, controls, lmks = sitter.frame(spec, cfg.size, cfg.fov_y_deg)
            buf = renderer.render(mesh, camera, lighting, sitter.appearance)
            name = f"{k:04d}.png"
            image = buf.color + bg * (1 - buf.coverage[..., None])
            write_png8(out / "images" / name, image)
            extra = {}
            if lighting.shadows:  # the same frame with nothing in the key light's way: what "without" should show
                lit = renderer.render(mesh, camera, replace(lighting, shadows=False), sitter.appearance)
                write_png8(out / "unshadowed" / name, lit.color + bg * (1 - lit.coverage[..., None]))
                extra["unshadowed_path"] = f"unshadowed/{name}"
            write_png8(out / "masks" / name, buf.coverage)
            write_png16(out / "normals" / name, buf.normal * 0.5 + 0.5)
            write_png8(out / "shadows" / name, cast_shadow(buf))
            depth = np.where(np.isfinite(buf.depth), np.round(buf.depth / DEPTH_SCALE_M), 0)
            cv2.imwrite(str(out / "depth" / name), np.clip(depth, 0, 65535).astype(np.uint16))
            write_png8(out / "albedo" / name, buf.albedo)
            splits[split].append({
                "file_path": f"images/{name}", "mask_path": f"masks/{name}", "normal_path": f"normals/{name}",
                "shadow_path": f"shadows/{name}", "depth_path": f"depth/{name}", "albedo_path": f"albedo/{name}",
                **extra,
                "transform_matrix": np.linalg.inv(camera.view).tolist(),
                "expression": controls.expression.tolist(),
                "controls": {k: v for k, v in controls_to_dict(replace(controls, shape=np.zeros(0))).items()
                             if k != "shape"},
                "bbox": _bbox(_project(camera, lmks), cfg.size) if len(lmks) else None,
                "script": {"weights": spec.weights, "head_yaw_deg": spec.head_yaw_deg,
                           "head_pitch_deg": spec.head_pitch_deg, "camera_yaw_deg": spec.camera_yaw_deg,
                           "camera_pitch_deg": spec.camera_pitch_deg},
            })
            if progress:
                progress(k + 1, len(jobs))
    renderer.release()
    for split, frames in splits.items():
        write_split(out, split, header, frames)
    return {"frames": {s: len(f) for s, f in splits.items()}, "seconds": time.perf_counter() - t0}
