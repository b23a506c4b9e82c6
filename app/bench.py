"""`avatar-studio bench`: what accuracy costs in time, measured on this machine.

For trained avatars of a capture (one per effect set) and the capture's held-out test frames it measures,
for each render setting (samples per ray, image size, a second "fine" pass, bf16 or fp32): the time per frame
and the error against the ground truth (PSNR, FaceMSE) and against the most accurate setting measured; the
NerFACE-style dense renderer (64 + 64 samples, 8x256 MLPs) at the same image size beside them; and training
curves (test PSNR against training seconds) for each effect set. It writes `results.json`, the charts
`error_vs_time.png` and `training_curves.png`, and stores in each avatar the presets it chose from that
avatar's Pareto front (`presets.json`), which the studio's Quality panel shows.
"""

from __future__ import annotations

import json
import os
import platform
import sys
import time
from dataclasses import asdict, replace
from pathlib import Path

import cv2
import numpy as np
import torch
from tqdm import tqdm

from app.avatar_commands import face_mask_of
from app.configs import BenchConfig
from app.errors import UserInputError
from models.avatars.base import Avatar
from models.avatars.effects import effects_name
from models.avatars.quality import PRESET_NAMES, Preset, Quality, pareto, save_presets
from models.avatars.registry import BASELINE_MODEL, DEFAULT_MODEL, load_avatar, untrained_avatar
from models.avatars.rendering import RenderOptions, render_image
from models.capture.dataset import load_split
from models.capture.frames import frame_camera, frame_room, load_rgb
from models.files import atomic_write_bytes, foreign_files
from models.head.sources import load_head
from models.training.metrics import face_mse, psnr
from models.training.trainer import TrainConfig, prepare_training
from render.gl.context import GLContext
from render.gl.raster import Rasterizer

EFFECT_SETS = ("none", "shading,specular", "all")

SETTINGS = (
    # samples per ray at full size
    *(Quality(1.0, s) for s in (4, 6, 8, 12, 16, 24, 32)),
    # smaller images, shown scaled up (the smallest: first pixels in the studio while a slider moves)
    *(Quality(sc, s) for sc in (0.25, 0.375) for s in (4, 6)),
    *(Quality(sc, s) for sc in (0.5, 0.75) for s in (6, 8, 12)),
    # a second pass where the first pass's weights lie
    *(Quality(1.0, s, s) for s in (6, 8, 12, 16)),
    # bfloat16 networks
    *(Quality(1.0, s, 0, True) for s in (8, 12, 16)),
)
REFERENCE = Quality(1.0, 32, 32)
"""The most accurate setting measured: every other setting's error against it is its error against `final`."""


def settings_for(avatar: Avatar) -> tuple[list[Quality], Quality]:
    """The settings that differ for this avatar, and its reference: the knobs it does not read (its
    quality_knobs besides the image size) are left at their defaults, and settings that became one are measured
    once (a primitives avatar reads the samples alone: no second pass, no bf16)."""
    default = Quality()
    keep = lambda q: replace(q, **{k: getattr(default, k) for k in ("samples", "fine", "bf16")
                                   if k not in avatar.quality_knobs})
    return list(dict.fromkeys(keep(q) for q in SETTINGS)), keep(REFERENCE)


def series_name(model: str, effects: str) -> str:
    """What a bench's rows and charts call one avatar's settings: its effect set, and its model where it is not the
    registry's default (a primitives avatar of `all` beside CoDyNeRF's)."""
    return effects if model == DEFAULT_MODEL else f"{model} {effects}"

PRESET_RULES = {"final": 45.0, "preview": 35.0, "draft": 25.0}
"""Each preset is the fastest setting on the Pareto front whose PSNR against the reference is at least this
(dB): 45 dB is an error under 0.6% of the range (invisible), 35 dB under 2% (a flicker at edges), 25 dB a
blurred but faithful picture."""


def processor() -> str:
    """The processor's name and this machine's cores, e.g. "AMD EPYC, 2 cores"."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} cores"


def machine() -> str:
    return f"{processor()}, torch {torch.__version__} with {torch.get_num_threads()} threads"


def choose_presets(rows: list[dict]) -> dict[str, dict]:
    """The presets from one avatar's rows (each with ms, psnr_vs_reference, on_front): for each preset the
    fastest front setting that reaches its PSNR threshold against the reference (the reference itself if
    none does)."""
    front = [r for r in rows if r["on_front"]]
    chosen = {}
    for name in PRESET_NAMES:
        good = [r for r in front if r["psnr_vs_reference"] >= PRESET_RULES[name]]
        chosen[name] = min(good, key=lambda r: r["ms"]) if good else max(rows, key=lambda r: r["psnr_vs_reference"])
    return chosen


def upsample(img: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """A smaller render shown at the full size (bilinear, as the studio's texture filter does)."""
    if img.shape[:2] == size:
        return img
    return cv2.resize(img, (size[1], size[0]), interpolation=cv2.INTER_LINEAR)


class TestFrames:
    """The held-out frames a bench measures: cameras at the bench size, ground truth and face masks, and each frame's
    own room where the capture keeps one (frame_room; render_image resizes it to a setting's size)."""

    def __init__(self, dataset: Path, count: int, size: int, background: np.ndarray):
        split = load_split(dataset, "test")
        if not split.frames:
            raise UserInputError(f"{dataset}: the capture has no test frames to measure on")
        pick = np.unique(np.linspace(0, len(split.frames) - 1, min(count, len(split.frames))).round().astype(int))
        self.frames = [split.frames[i] for i in pick]
        self.rooms = [frame_room(f) for f in self.frames]
        self.cameras, self.truth, self.face = [], [], []
        for f in self.frames:
            cam = frame_camera(split, f)
            scale = size / cam.width_px
            self.cameras.append(cam.resized(size, round(cam.height_px * scale)))
            truth = load_rgb(f.image_path, background)
            hw = (self.cameras[-1].height_px, size)
            self.truth.append(upsample(truth, hw))
            self.face.append(cv2.resize(face_mask_of(f, truth.shape).astype(np.uint8), (hw[1], hw[0]),
                                        interpolation=cv2.INTER_NEAREST).astype(bool))


def measure(avatar: Avatar, quality: Quality, frames: TestFrames, raster: Rasterizer
            ) -> tuple[dict, list[np.ndarray]]:
    """Time per frame (median over the frames, after one warm-up render; the colour render alone, no optional
    buffers) and errors against the ground truth of one setting; the renders at full size."""
    images, times = [], []
    for i, (f, cam) in enumerate(zip(frames.frames, frames.cameras, strict=True)):
        size = quality.size(cam.width_px)
        c = cam.resized(size, max(8, round(cam.height_px * size / cam.width_px)))
        options = RenderOptions(buffers=(), quality=quality, room=frames.rooms[i])  # the colour, as the studio shows
        if i == 0:
            render_image(avatar, c, f.controls, options, raster)
        t0 = time.perf_counter()
        out = render_image(avatar, c, f.controls, options, raster)
        times.append(time.perf_counter() - t0)
        images.append(upsample(out["rgb"], frames.truth[i].shape[:2]))
    finite = all(bool(np.isfinite(im).all()) for im in images)
    row = {"ms": round(1e3 * float(np.median(times)), 1), "finite": finite,
           "psnr": round(float(np.mean([psnr(im, t) for im, t in zip(images, frames.truth, strict=True)])), 3),
           "face_mse": round(float(np.mean([face_mse(im, t, m) for im, t, m in
                                            zip(images, frames.truth, frames.face, strict=True)])), 6)}
    return row, images


def mean_psnr(images: list[np.ndarray], reference: list[np.ndarray]) -> float:
    return round(float(np.mean([min(psnr(a, b), 99.0) for a, b in zip(images, reference, strict=True)])), 3)


def training_curve(dataset: Path, effects: str, out: Path, seconds: float, frames: TestFrames, gl: GLContext,
                   points: int = 8) -> list[dict]:
    """Train an avatar for `seconds` of training time (evaluation not counted), measuring test PSNR at
    `points` even times; the avatar is saved in `out` (a real checkpoint, measured afterwards)."""
    trainer = prepare_training(TrainConfig(dataset=dataset, out=out, effects=effects, minutes=seconds / 60), gl)
    raster = Rasterizer(gl)
    curve, trained, next_eval = [], 0.0, 0.0
    bar = tqdm(total=round(seconds), desc=f"training {effects}", unit="s", leave=False, mininterval=1.0,
               disable=not sys.stderr.isatty(), bar_format="{l_bar}{bar}| {n:.0f}/{total_fmt} s")
    while True:
        if trained >= next_eval or trained >= seconds:
            trainer.avatar.eval()
            with torch.no_grad():
                row, _ = measure(trainer.avatar, Quality(), frames, raster)
            trainer.avatar.train()
            curve.append({"seconds": round(trained, 1), "step": trainer.step, "psnr": row["psnr"],
                          "face_mse": row["face_mse"]})
            next_eval += seconds / points
        if trained >= seconds:
            break
        t0 = time.perf_counter()
        trainer.train_step(trained / seconds)
        dt = time.perf_counter() - t0
        trained += dt
        bar.update(min(dt, seconds - bar.n))
    bar.close()
    trainer.elapsed = trained
    trainer.save()
    raster.release()
    return curve


def run_bench(cfg: BenchConfig) -> int:
    quick = cfg.quick
    size = cfg.size or (64 if quick else 128)
    seconds = cfg.train_seconds if cfg.train_seconds is not None else (25.0 if quick else 300.0)
    n_test = cfg.test_frames or (3 if quick else 6)
    out = cfg.out
    foreign = foreign_files(out, r"results\.json|error_vs_time\.png|training_curves\.png|capture|avatars|\..*\.tmp")
    if foreign:
        raise UserInputError(f"{out}: holds files bench did not write ({foreign[0].name}...); choose another --out")
    out.mkdir(parents=True, exist_ok=True)
    gl = GLContext.headless()
    t_start = time.perf_counter()
    dataset = cfg.dataset or synthesize_capture(out / "capture", quick, gl)
    bg_split = load_split(dataset, "train")
    background = bg_split.background if isinstance(bg_split.background, np.ndarray) else np.ones(3, np.float32)
    frames = TestFrames(dataset, n_test, size, background)
    print(f"bench on {dataset}: {len(frames.frames)} test frames at {size} px; {machine()}", flush=True)

    curves = {}
    trained_dirs = []
    if seconds <= 0 and not cfg.avatars:
        raise UserInputError("--train-seconds 0 measures given avatars only: pass --avatars")
    for effects in EFFECT_SETS if seconds > 0 else ():
        name = effects.replace(",", "+")
        folder = out / "avatars" / name
        if (folder / "avatar.json").exists():
            raise UserInputError(f"{folder}: already holds an avatar; choose a new --out folder")
        curves[name] = training_curve(dataset, effects, folder, seconds, frames, gl)
        trained_dirs.append(folder)
        print(f"trained {name}: test PSNR {curves[name][-1]['psnr']:.2f} dB after {seconds:.0f} s", flush=True)

    raster = Rasterizer(gl)
    rows: list[dict] = []
    chosen: dict[str, dict] = {}
    for path in cfg.avatars or trained_dirs:
        avatar, meta = load_avatar(path)
        if not avatar.quality_knobs:
            raise UserInputError(f"{path}: a {avatar.name} avatar renders the same at every setting (a dense "
                                 "baseline); pass it with --nerface")
        effects = series_name(avatar.name, effects_name(meta["effects"]))
        settings, reference = settings_for(avatar)
        ref_row, ref_images = measure(avatar, reference, frames, raster)
        avatar_rows = []
        for q in tqdm([*(q for q in settings if q != reference), reference], desc=f"settings {effects}",
                      leave=False, disable=not sys.stderr.isatty()):
            row, images = (ref_row, ref_images) if q == reference else measure(avatar, q, frames, raster)
            avatar_rows.append({"avatar": str(path), "effects": effects, "model": avatar.name, "setting": asdict(q),
                                "label": q.describe(), "image_px": size, **row,
                                "psnr_vs_reference": mean_psnr(images, ref_images), "_images": images})
        front = pareto([(r["ms"], -r["psnr_vs_reference"]) for r in avatar_rows])
        for r, f in zip(avatar_rows, front, strict=True):
            r["on_front"] = f
        picks = choose_presets(avatar_rows)
        final_images = picks["final"]["_images"]
        presets = {}
        for name, r in picks.items():
            r.setdefault("presets", []).append(name)
            presets[name] = Preset(Quality(**r["setting"]), r["ms"], mean_psnr(r["_images"], final_images),
                                   r["psnr"], r["face_mse"])
        for r in avatar_rows:
            r["psnr_vs_final"] = mean_psnr(r["_images"], final_images)
            del r["_images"]
        chosen[effects] = {k: asdict(p) for k, p in presets.items()}
        if cfg.store_presets:
            save_presets(path, presets, {"machine": machine(), "image_px": size, "dataset": str(dataset),
                                         "test_frames": len(frames.frames), "command": " ".join(sys.argv)})
        rows += avatar_rows
        print(f"{effects}: presets " + ", ".join(f"{k} = {r['label']} ({r['ms']:.0f} ms)" for k, r in picks.items()),
              flush=True)

    nerface_row = measure_nerface(cfg.nerface, dataset, frames, raster, quick)
    for r in rows:
        r["nerface_over"] = round(nerface_row["ms"] / max(r["ms"], 1e-9), 1)
    results = {"machine": machine(), "command": " ".join(["avatar-studio", *sys.argv[1:]]), "dataset": str(dataset),
               "image_px": size, "test_frames": [f.index for f in frames.frames], "reference": asdict(REFERENCE),
               "preset_rules_db": PRESET_RULES, "rows": rows, "nerface": nerface_row, "presets": chosen,
               "training_curves": curves, "train_seconds": seconds,
               "bench_seconds": round(time.perf_counter() - t_start, 1)}
    atomic_write_bytes(out / "results.json", (json.dumps(results, indent=1) + "\n").encode())
    from app.bench_charts import draw_charts  # matplotlib (0.3 s) loads when charts are drawn, not for --help

    for p in draw_charts(results, out):
        print(f"wrote {p}")
    print(f"wrote {out / 'results.json'} in {results['bench_seconds']:.0f} s")
    raster.release()
    return 0


def synthesize_capture(folder: Path, quick: bool, gl: GLContext) -> Path:
    """A sun capture of the built-in head (hard light: shading, highlights and cast shadows), made once."""
    from models.capture.synthetic import SynthConfig, synthesize
    from models.head.sources import load_builtin

    if (folder / "dataset.json").exists():
        return folder
    partial = folder.with_name(folder.name + ".partial")
    if partial.exists():
        import shutil

        shutil.rmtree(partial)
    print(f"synthesizing a capture into {folder}", flush=True)
    synthesize(SynthConfig(scene="sun", frames=60 if quick else 300, size=64 if quick else 128, out=partial),
               load_builtin(), gl)
    partial.rename(folder)
    return folder


def measure_nerface(path: Path | None, dataset: Path, frames: TestFrames, raster: Rasterizer, quick: bool) -> dict:
    """The dense renderer at the bench's size: its time per frame, and its errors if it was trained."""
    if path is not None:
        avatar, _ = load_avatar(path)
        if avatar.quality_knobs:
            raise UserInputError(f"{path}: --nerface needs a dense baseline avatar, not a {avatar.name} one "
                                 f"(avatar-studio train --model {BASELINE_MODEL})")
    else:
        avatar = untrained_avatar(BASELINE_MODEL, load_head(load_split(dataset, "train").head_model))
    n = 1 if quick or path is None else 2  # seconds a frame: the first test frames only
    images, times = [], []
    for f, cam in zip(frames.frames[:n], frames.cameras[:n], strict=True):
        t0 = time.perf_counter()
        with torch.inference_mode():
            images.append(render_image(avatar, cam, f.controls, RenderOptions(frame=None), raster)["rgb"])
        times.append(time.perf_counter() - t0)
    row = {"trained": path is not None, "ms": round(1e3 * float(np.median(times)), 1), "frames": n,
           "setting": avatar.describe_rendering()}
    if path is not None:
        row["psnr"] = round(float(np.mean([psnr(a, b) for a, b in zip(images, frames.truth[:n], strict=True)])), 3)
        row["face_mse"] = round(float(np.mean([face_mse(a, b, m) for a, b, m in
                                               zip(images, frames.truth[:n], frames.face[:n], strict=True)])), 6)
    print(f"NerFACE dense renderer: {row['ms'] / 1e3:.1f} s per {frames.cameras[0].width_px} px frame", flush=True)
    return row
