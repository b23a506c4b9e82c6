"""The Jobs panel's words for a job's progress: an ETA only while it runs, never a negative one."""

from __future__ import annotations

from pathlib import Path

from app.jobs import Job
from app.studio.jobs_panel import progress_text


def test_progress_text():
    job = Job(1, Path("d"), Path("o"), state="running", progress=[{"step": 50, "eta_s": 12.4}])
    assert progress_text(job) == "step 50, ETA 12 s"
    job.progress.append({"step": 60, "eta_s": -1.0})  # a log written before ETAs were clamped
    assert progress_text(job) == "step 60"
    job.state = "done"
    assert progress_text(job) == "step 60, done"
    assert progress_text(Job(2, Path("d"), Path("o"))) == "step 0, queued"


def test_a_reenactment_is_refused_with_its_reason_and_runs_the_reenact_command(tmp_path):
    from app.jobs import JobQueue
    from app.studio.actions import StartReenact
    from app.studio.jobs_panel import start_reenact

    video, bundle = tmp_path / "perf.mp4", tmp_path / "lm.task"
    video.write_bytes(b"x")
    bundle.write_bytes(b"x")
    jobs = JobQueue(max_running=0)  # queued, never started
    ask = lambda **kw: start_reenact(jobs, kw.pop("avatar", tmp_path), StartReenact(**{
        "video": str(video), "landmarker": str(bundle), "out": str(tmp_path / "o.mp4"), **kw}))
    assert ask(avatar=None) == "open an avatar to drive first"
    assert "no such video" in ask(video=str(tmp_path / "none.mp4"))
    assert ask(video=str(tmp_path), landmarker="", out=str(tmp_path / "f.mp4")) is None  # a folder: no landmarker
    jobs.jobs.clear()
    assert "landmarker" in ask(landmarker="")
    assert ask(out=str(tmp_path / "o.gif")).endswith("written as an .mp4")
    assert jobs.jobs == []
    assert ask(seconds=2.0) is None
    job = jobs.jobs[0]
    cmd = job.command()
    assert cmd[3:6] == ["reenact", str(tmp_path), str(video)] and cmd[cmd.index("--seconds") + 1] == "2.0"
    assert job.stage == "reenact" and job.fraction == 0.0
    job.log_path.write_text("reenact: 9/30 frames\nreenact: 12/30 frames\n")
    assert job.fraction == 0.4


def test_a_training_reading_its_frames_says_so(tmp_path):
    """Before its first step a training shows the last line of its log (train's "reading the frames: k/N"), then its
    state once steps are recorded."""
    from app.jobs import JobQueue

    job = Job(1, tmp_path / "d", tmp_path / "o", state="running")
    job.log_path.write_text("reading the frames: 30/302 frames\nreading the frames: 61/302 frames\n")
    assert JobQueue.status(job) == "reading the frames: 61/302 frames"
    job.progress.append({"step": 1, "eta_s": 1800.0})
    assert JobQueue.status(job) == "running"


def test_the_training_forms_default_model_is_trains_own_choice(synth_capture, tmp_path):
    """The form's first model is "default": the job runs `train` with no --model, so a tracked video gets the avatar
    `train` makes on the command line (a whole head where the prior ships), not the first model of the list; a model
    chosen is passed on."""
    from app.jobs import JobQueue
    from app.studio.actions import StartTraining
    from app.studio.jobs_panel import MODELS, start

    capture = synth_capture("sun", 4, 16)
    assert MODELS[0] == "default" and "whole" in MODELS and "codynerf" in MODELS
    jobs = JobQueue(max_running=0)  # queued, never started
    assert start(jobs, StartTraining(str(capture), str(tmp_path / "a"), None, "none", 1.0)) is None
    assert start(jobs, StartTraining(str(capture), str(tmp_path / "b"), "primitives", "none", 1.0)) is None
    default, chosen = (job.command() for job in jobs.jobs)
    assert default[3] == "train" and "--model" not in default
    assert chosen[chosen.index("--model") + 1] == "primitives"
