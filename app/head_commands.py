"""`preview`, `mesh` and (until the window exists) `studio`: a head model posed by controls."""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from PIL import Image

from app.configs import HeadPoseConfig, MeshConfig, PreviewConfig
from app.display import guide_frame
from app.errors import UserInputError
from models.files import atomic_write, atomic_write_bytes
from models.head.controls import Controls, ControlsError, load_controls
from models.head.head import Head, posed_mesh
from models.head.model import HeadModel, portrait_vertices
from models.head.sources import load_head
from render.camera import framing_camera
from render.gl.context import GLContext
from render.gl.preview import PreviewRenderer, PreviewSettings


def parse_expression_args(head: HeadModel, items: tuple[str, ...], controls: Controls) -> Controls:
    """Apply NAME=W / INDEX=W pairs to the controls."""
    named: dict[str, float] = {}
    expr = np.zeros(head.num_expression, np.float32)
    expr[: len(controls.expression)] = controls.expression
    for item in items:
        key, sep, value = item.partition("=")
        try:
            w = float(value)
        except ValueError:
            w = None
        if not sep or w is None or not np.isfinite(w):
            raise UserInputError(f"--expression {item!r}: expected NAME=WEIGHT, as in smile_L=0.8")
        if key.isdigit():
            if int(key) >= head.num_expression:
                raise UserInputError(f"--expression {item!r}: head '{head.name}' has {head.num_expression} "
                                     "expression components")
            expr[int(key)] = w
        else:
            named[key] = w
    try:
        return replace(controls, expression=expr).with_expression(head, named)
    except ControlsError as e:
        raise UserInputError(f"--expression: {e}") from None


def load_posed(cfg: HeadPoseConfig) -> tuple[HeadModel, np.ndarray, np.ndarray]:
    head = load_head(cfg.head)
    controls = load_controls(cfg.controls, head) if cfg.controls else Controls()
    controls = parse_expression_args(head, cfg.expression, controls)
    try:
        verts, lmks = posed_mesh(Head(head), controls)
    except ControlsError as e:
        raise UserInputError(f"{cfg.controls or 'controls'}: {e}") from None
    return head, verts, lmks


def _check_out(path: Path, suffixes: tuple[str, ...]) -> None:
    if path.suffix.lower() not in suffixes:
        raise UserInputError(f"{path}: output must end in {' or '.join(suffixes)}")
    if path.exists() and path.is_dir():
        raise UserInputError(f"{path}: is a folder, expected a file name")
    path.parent.mkdir(parents=True, exist_ok=True)


def save_png(path: Path, rgb: np.ndarray) -> None:
    """Write a PNG atomically (temporary file, then rename)."""
    atomic_write(path, lambda tmp: Image.fromarray(rgb).save(tmp, format="PNG"))


def render_head(gl: GLContext, head: HeadModel, verts: np.ndarray, lmks: np.ndarray, cfg: PreviewConfig
                ) -> np.ndarray:
    camera = framing_camera(portrait_vertices(head), cfg.yaw_deg, cfg.pitch_deg, width_px=cfg.size[0],
                            height_px=cfg.size[1])
    settings = PreviewSettings(pass_name=cfg.pass_, landmarks=cfg.landmarks, shadows=cfg.shadows)
    renderer = PreviewRenderer(gl)
    try:
        return renderer.render(guide_frame(head, verts, lmks), camera, settings)
    finally:
        renderer.release()


def run_preview(cfg: PreviewConfig) -> int:
    if min(cfg.size) < 1 or max(cfg.size) > 8192:
        raise UserInputError(f"--size {cfg.size[0]} {cfg.size[1]}: each side must be 1..8192 pixels")
    _check_out(cfg.out, (".png",))
    head, verts, lmks = load_posed(cfg)
    gl = GLContext.headless()
    t0 = time.perf_counter()
    rgb = render_head(gl, head, verts, lmks, cfg)
    ms = 1e3 * (time.perf_counter() - t0)
    save_png(cfg.out, rgb)
    print(f"wrote {cfg.out} ({cfg.size[0]}x{cfg.size[1]}, {head.name} head, {cfg.pass_} pass, {ms:.0f} ms)")
    return 0


def run_mesh(cfg: MeshConfig) -> int:
    from models.head.meshio import mesh_bytes

    _check_out(cfg.out, (".obj", ".ply"))
    head, verts, _ = load_posed(cfg)
    atomic_write_bytes(cfg.out, mesh_bytes(cfg.out.suffix, verts, head.triangles))
    print(f"wrote {cfg.out} ({len(verts)} vertices, {len(head.triangles)} triangles)")
    return 0


