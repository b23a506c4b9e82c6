"""The Jobs panel: start training on a dataset (model, effect set, time budget), watch progress, loss and
validation PSNR (implot), ETA; cancel (the checkpoint is kept), resume, open the result when done. Several
jobs queue; each is its own process."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from imgui_bundle import imgui, implot

from app.jobs import JobQueue
from app.studio.actions import (
    CancelJob,
    OpenAvatar,
    OpenReenactment,
    ResumeJob,
    StartFromVideo,
    StartReenact,
    StartTraining,
)
from app.studio.config import STUDIO_HOME
from app.studio.context import PanelContext
from models.avatars.registry import AVATARS
from models.capture.dataset import DatasetError, load_split

MODELS = ("default", *AVATARS)
"""The model a job trains: `train`'s own choice first (for a tracked video a whole head where the universal prior
ships, else VIDEO_MODEL from scratch: registry.training_start; for a synthetic capture default_model), or a model
named. The same choice for a capture and for a new avatar from a video, as `train` makes it on the command line."""
EFFECTS = ("all", "none", "shading", "shading,specular", "shadows")


def model_chosen(index: int) -> str | None:
    """The model a form's combo names (MODELS[index]); None for "default", `train`'s own choice.

    >>> model_chosen(0), model_chosen(MODELS.index("primitives"))
    (None, 'primitives')
    """
    return None if index == 0 else MODELS[index]


@dataclass
class JobForm:
    dataset: str = ""
    out: str = field(default_factory=lambda: str(STUDIO_HOME / "avatars" / "new"))
    model: int = 0
    video_model: int = 0
    effects: int = 0
    minutes: float = 30.0
    video: str = ""
    head: str = "builtin"
    landmarker: str = field(default_factory=lambda: os.environ.get("AVATAR_STUDIO_LANDMARKER", ""))
    performance: str = ""
    reenact_out: str = field(default_factory=lambda: str(STUDIO_HOME / "reenact.mp4"))


def start_from_video(jobs: JobQueue, c: StartFromVideo) -> str | None:
    """Queue a job that tracks the video into a dataset beside the avatar folder, then trains on it; or why
    not."""
    video_path, out_path = Path(c.video), Path(c.out)
    if not video_path.is_file():
        return f"{video_path}: no such video file"
    if not c.landmarker or not Path(c.landmarker).is_file():
        return (f"{c.landmarker or '(none given)'}: MediaPipe's face landmarker bundle is needed "
                "(face_landmarker_v2_with_blendshapes.task)")
    if out_path.exists():
        return f"{out_path}: already exists; choose a new avatar folder"
    dataset = out_path.with_name(out_path.name + "_dataset")
    jobs.submit(dataset, out_path, model=c.model, effects=c.effects, minutes=c.minutes, steps=c.steps, video=video_path,
                head=c.head.strip() or "builtin", landmarker=Path(c.landmarker), track_size=c.size, track_fps=c.fps)
    return None


def start_reenact(jobs: JobQueue, avatar: Path | None, c: StartReenact) -> str | None:
    """Queue a reenactment of the open avatar by a performance (a video, a capture, another avatar's frames); or why
    not."""
    if avatar is None:
        return "open an avatar to drive first"
    video_path, out_path = Path(c.video), Path(c.out)
    if not video_path.exists():
        return f"{video_path}: no such video, capture or avatar folder"
    if video_path.is_file() and (not c.landmarker or not Path(c.landmarker).is_file()):
        return (f"{c.landmarker or '(none given)'}: MediaPipe's face landmarker bundle is needed "
                "(face_landmarker_v2_with_blendshapes.task)")
    if out_path.suffix.lower() != ".mp4":
        return f"{out_path}: the performance is written as an .mp4"
    jobs.submit(avatar, out_path, stage="reenact", video=video_path,
                landmarker=Path(c.landmarker) if c.landmarker else None, track_size=c.size, seconds=c.seconds)
    return None


def start(jobs: JobQueue, c: StartTraining) -> str | None:
    """Check the dataset here (a clear message in the window), then queue the job; or why not."""
    try:
        load_split(c.dataset, "train")
    except DatasetError as e:
        return str(e)
    out_path = Path(c.out)
    if (out_path / "avatar.json").exists():
        return f"{out_path}: already holds an avatar; choose a new folder (or resume its job)"
    jobs.submit(Path(c.dataset), out_path, model=c.model, effects=c.effects, minutes=c.minutes, steps=c.steps)
    return None


def progress_text(job) -> str:
    """The progress bar's words: the step, and while the job runs the time it has left."""
    last = job.progress[-1] if job.progress else {}
    text = f"step {last.get('step', 0)}"
    eta = last.get("eta_s")
    if job.state == "running" and eta is not None and eta >= 0:
        return text + f", ETA {eta:.0f} s"
    return text if job.state == "running" else f"{text}, {job.state}"


FORM = JobForm()
"""The panel's form (widget state)."""


def draw(ctx: PanelContext) -> None:
    f, act, jobs = FORM, ctx.act, ctx.jobs
    _, f.dataset = imgui.input_text("dataset", f.dataset)
    _, f.out = imgui.input_text("avatar folder", f.out)
    imgui.set_next_item_width(110)
    _, f.model = imgui.combo("model", f.model, list(MODELS))
    imgui.same_line()
    imgui.set_next_item_width(110)
    _, f.effects = imgui.combo("effects", f.effects, list(EFFECTS))
    imgui.set_next_item_width(110)
    _, f.minutes = imgui.input_float("minutes", f.minutes, 5.0, 10.0, "%.0f")
    imgui.same_line()
    if imgui.button("Start training"):
        act(StartTraining(f.dataset.strip(), f.out.strip(), model_chosen(f.model), EFFECTS[f.effects],
                          max(f.minutes, 0.1)))
    if imgui.collapsing_header("New avatar from video"):
        _, f.video = imgui.input_text("video", f.video)
        _, f.head = imgui.input_text("head model", f.head)
        _, f.landmarker = imgui.input_text("landmarker (.task)", f.landmarker)
        imgui.set_next_item_width(110)
        _, f.video_model = imgui.combo("model##video", f.video_model, list(MODELS))
        if imgui.button("Track and train"):
            act(StartFromVideo(f.video.strip(), f.head, f.landmarker.strip(), f.out.strip(), EFFECTS[f.effects],
                               max(f.minutes, 0.1),
                               model=model_chosen(f.video_model)))
        imgui.same_line()
        imgui.text_disabled("(avatar folder, effects and minutes from above)")
    if imgui.collapsing_header("Drive the open avatar from a performance"):
        _, f.performance = imgui.input_text("performance", f.performance)
        if imgui.is_item_hovered():
            imgui.set_tooltip("a video of a face, a capture folder, or another avatar's folder (its capture's frames)")
        _, f.reenact_out = imgui.input_text("mp4##reenact", f.reenact_out)
        _, f.landmarker = imgui.input_text("landmarker (.task)##reenact", f.landmarker)
        if imgui.button("Reenact"):
            act(StartReenact(f.performance.strip(), f.landmarker.strip(), f.reenact_out.strip()))
        imgui.same_line()
        imgui.text_disabled("(then on the Animation timeline, Export panel)")
    if ctx.session.job_message:
        imgui.push_text_wrap_pos(0)
        imgui.text_colored(imgui.ImVec4(1.0, 0.45, 0.35, 1.0), ctx.session.job_message)
        imgui.pop_text_wrap_pos()
    imgui.separator()
    for job in reversed(jobs.jobs):
        imgui.push_id(job.id)
        model = job.model or "default"  # train's own choice, which it prints in the job's log
        what = f"driven by {job.video.name}" if job.stage == "reenact" and job.video else f"{model} {job.effects}"
        imgui.text(f"#{job.id} {job.out.name}: {what} - {jobs.status(job)}"
                   + (" (resumed)" if job.resume else ""))
        imgui.progress_bar(job.fraction, imgui.ImVec2(-1, 0), progress_text(job))
        if job.error:
            imgui.push_text_wrap_pos(0)
            imgui.text_colored(imgui.ImVec4(1.0, 0.45, 0.35, 1.0), job.error)
            imgui.pop_text_wrap_pos()
        if len(job.progress) > 1 and implot.begin_plot("##curves", imgui.ImVec2(-1, 110)):
            steps = np.array([p["step"] for p in job.progress], np.float64)
            loss = np.array([p.get("loss", np.nan) for p in job.progress], np.float64)
            val = np.array([(p["step"], p["val_psnr"]) for p in job.progress if "val_psnr" in p], np.float64)
            # All setup first (implot's rule), then the lines.
            implot.setup_axes("step", "loss", implot.AxisFlags_.auto_fit, implot.AxisFlags_.auto_fit)
            # The legend above the plot, not over the curves' first points.
            implot.setup_legend(implot.Location_.north, implot.LegendFlags_.outside | implot.LegendFlags_.horizontal)
            implot.setup_axis_scale(implot.ImAxis_.y1, implot.Scale_.log10)
            if len(val):
                right = implot.AxisFlags_.auto_fit | implot.AxisFlags_.opposite
                implot.setup_axis(implot.ImAxis_.y2, "val PSNR", right)
            implot.plot_line("loss", steps, loss)
            if len(val):
                implot.set_axes(implot.ImAxis_.x1, implot.ImAxis_.y2)
                implot.plot_line("val PSNR", np.ascontiguousarray(val[:, 0]), np.ascontiguousarray(val[:, 1]))
            implot.end_plot()
        if job.state in ("queued", "running") and imgui.small_button("Cancel"):
            act(CancelJob(job.id))
        if job.stage == "reenact" and job.state == "done" and imgui.small_button("Show on timeline"):
            act(OpenReenactment(job.id))
        if job.state in ("cancelled", "done") and (job.out / "avatar.json").exists():
            if imgui.small_button("Open"):
                act(OpenAvatar(job.out))
            if job.state == "cancelled":
                imgui.same_line()
                if imgui.small_button("Resume"):
                    act(ResumeJob(job.id))
        imgui.separator()
        imgui.pop_id()
