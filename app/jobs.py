"""Background training jobs: each a separate `avatar-studio train` process, queued and run one at a time,
their progress read from the avatar folder's progress.jsonl. Cancelling sends SIGTERM: the trainer writes a
checkpoint and exits, so the job can be resumed later with --resume. A job made from a video runs
`avatar-studio track` first (its dataset written beside the avatar), then trains on what it tracked. A
reenactment job runs `avatar-studio reenact` (a performance video driving an avatar: `dataset` is the avatar's
folder, `out` the mp4, its animation OUT.json beside it); its progress is read from its log."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

State = Literal["queued", "running", "done", "failed", "cancelled"]


@dataclass
class Job:
    """One training run and what is known of it."""

    id: int
    dataset: Path
    out: Path
    model: str | None = None
    """None: train's default (primitives for a tracked video, codynerf for a synthetic capture)."""
    effects: str = "all"
    minutes: float | None = None
    steps: int | None = None
    resume: bool = False
    video: Path | None = None
    """Track this video into `dataset` first (a "new avatar from video" job)."""
    head: str = "builtin"
    landmarker: Path | None = None
    track_size: int = 256
    """Image size of the tracked dataset, pixels."""
    track_fps: float | None = None
    """Frames a second taken from the video (None: every frame)."""
    seconds: float | None = None
    """Only the video's first seconds (a reenactment)."""
    stage: Literal["track", "train", "reenact"] = "train"
    opened: bool = False
    """The studio opened the result (video jobs open theirs when done)."""
    state: State = "queued"
    error: str = ""
    progress: list[dict] = field(default_factory=list)
    proc: subprocess.Popen | None = None
    _read_bytes: int = 0
    _log_bytes: int = -1
    _frames_done: float = 0.0

    @property
    def log_path(self) -> Path:
        return self.out.with_name(self.out.name + ".log")

    def command(self) -> list[str]:
        if self.stage == "reenact":
            cmd = [sys.executable, "-m", "app.cli", "reenact", str(self.dataset), str(self.video), "--out",
                   str(self.out), "--size", str(self.track_size)]
            cmd += ["--seconds", str(self.seconds)] if self.seconds else []
            return cmd + (["--landmarker", str(self.landmarker)] if self.landmarker else [])
        if self.stage == "track":
            cmd = [sys.executable, "-m", "app.cli", "track", str(self.video), "--out", str(self.dataset),
                   "--head", self.head, "--size", str(self.track_size)]
            cmd += ["--fps", str(self.track_fps)] if self.track_fps else []
            return cmd + (["--landmarker", str(self.landmarker)] if self.landmarker else [])
        cmd = [sys.executable, "-m", "app.cli", "train", str(self.dataset), "--out", str(self.out),
               "--effects", self.effects] + (["--model", self.model] if self.model else [])
        if self.minutes:
            cmd += ["--minutes", str(self.minutes)]
        if self.steps:
            cmd += ["--steps", str(self.steps)]
        if self.resume:
            cmd.append("--resume")
        return cmd

    def read_progress(self) -> None:
        """Append the progress records written since the last call (a training's; a reenactment has none)."""
        if self.stage == "reenact":
            return
        path = self.out / "progress.jsonl"
        try:
            with open(path, "rb") as f:
                f.seek(self._read_bytes)
                data = f.read()
        except FileNotFoundError:
            return
        complete = data[: data.rfind(b"\n") + 1]  # a line being written is read next time
        self._read_bytes += len(complete)
        for line in complete.splitlines():
            try:
                self.progress.append(json.loads(line))
            except json.JSONDecodeError:
                continue

    @property
    def fraction(self) -> float:
        """Share of the budget spent, from the last progress record (a reenactment: of the frames rendered)."""
        if self.stage == "reenact":
            if self.state == "done":
                return 1.0
            try:  # the panel asks every frame: the log is read again only when it has grown
                size = self.log_path.stat().st_size
            except OSError:
                return 0.0
            if size != self._log_bytes:
                self._log_bytes = size
                done = re.findall(r"reenact: (\d+)/(\d+) frames", JobQueue.log_text(self))
                self._frames_done = int(done[-1][0]) / int(done[-1][1]) if done else 0.0
            return self._frames_done
        if not self.progress:
            return 0.0
        last = self.progress[-1]
        if self.steps:
            return min(1.0, last["step"] / self.steps)
        if self.minutes:
            return min(1.0, last["elapsed_s"] / (60 * self.minutes))
        return 0.0


class JobQueue:
    """Jobs in submission order; at most `max_running` run at once (the window keeps a core)."""

    def __init__(self, max_running: int = 1, threads_per_job: int = 1):
        self.jobs: list[Job] = []
        self.max_running = max_running
        self.threads_per_job = threads_per_job

    def submit(self, dataset: Path, out: Path, **options) -> Job:
        job = Job(len(self.jobs) + 1, Path(dataset), Path(out), **options)
        if job.stage == "train" and job.video is not None and not (job.dataset / "transforms_train.json").exists():
            job.stage = "track"
        self.jobs.append(job)
        self.poll()
        return job

    def _start(self, job: Job) -> None:
        job.out.parent.mkdir(parents=True, exist_ok=True)
        env = dict(os.environ, OMP_NUM_THREADS=str(self.threads_per_job), PYTHONUNBUFFERED="1")
        log = open(job.log_path, "ab")
        # Niced: the window (and its render) come first; training takes the idle time.
        job.proc = subprocess.Popen(job.command(), stdout=log, stderr=subprocess.STDOUT, env=env,
                                    cwd=Path(__file__).resolve().parents[1], preexec_fn=lambda: os.nice(10))
        log.close()
        job.state = "running"

    def poll(self) -> None:
        """Read progress, notice finished processes, start queued jobs."""
        for job in self.jobs:
            if job.state != "running" or job.proc is None:
                continue
            job.read_progress()
            rc = job.proc.poll()
            if rc is None:
                continue
            job.read_progress()
            if job.state == "running" and rc == 0 and job.stage == "track":
                job.stage = "train"  # tracked: train on it, as the same job
                self._start(job)
                continue
            if job.state == "running":
                job.state = "done" if rc == 0 else "failed"
            if rc != 0 and job.state == "failed":
                job.error = self.last_error(job)
        while len(self.running()) < self.max_running:
            queued = [j for j in self.jobs if j.state == "queued"]
            if not queued:
                break
            self._start(queued[0])

    @staticmethod
    def log_text(job: Job) -> str:
        try:
            return job.log_path.read_text(errors="replace").replace("\r", "\n")
        except OSError:
            return ""

    @staticmethod
    def last_line(job: Job) -> str:
        lines = [ln for ln in JobQueue.log_text(job).splitlines()
                 if ln.strip() and not ln.startswith(("W0000", "INFO:", "WARNING: All log"))]
        return lines[-1][:120] if lines else ""

    @staticmethod
    def last_error(job: Job) -> str:
        """The last line the job's process wrote (its one-line reason on exit status 2)."""
        try:
            lines = [ln for ln in job.log_path.read_text(errors="replace").replace("\r", "\n").splitlines()
                     if ln.strip()]
        except OSError:
            return f"exit status {job.proc.returncode if job.proc else '?'}"
        return lines[-1] if lines else f"exit status {job.proc.returncode if job.proc else '?'}"

    def running(self) -> list[Job]:
        return [j for j in self.jobs if j.state == "running"]

    def cancel(self, job: Job) -> None:
        """Stop a job; a running one checkpoints first (SIGTERM), so it can be resumed."""
        if job.state == "queued":
            job.state = "cancelled"
        elif job.state == "running" and job.proc is not None:
            job.state = "cancelled"
            job.proc.send_signal(signal.SIGTERM)

    def resume(self, job: Job) -> Job:
        """Queue a job that continues a cancelled or finished one from its checkpoint."""
        resume = (job.out / "avatar.json").exists()
        return self.submit(job.dataset, job.out, model=job.model, effects=job.effects, minutes=job.minutes,
                           steps=job.steps, resume=resume, video=job.video, head=job.head, landmarker=job.landmarker,
                           track_size=job.track_size, track_fps=job.track_fps)

    @staticmethod
    def status(job: Job) -> str:
        """What a job is doing, in a few words: its stage, and while tracking the tracker's last line, and while a
        training reads its frames (a long video's take minutes, before the first step) its last line."""
        if job.stage in ("track", "reenact") and job.state == "running":
            return ("tracking: " if job.stage == "track" else "") + JobQueue.last_line(job)
        if job.stage == "train" and job.state == "running" and not job.progress:
            return JobQueue.last_line(job) or job.state
        return job.state

    def stop_all(self, wait_s: float = 30.0) -> None:
        for job in self.running():
            self.cancel(job)
        for job in self.jobs:
            if job.proc is not None and job.proc.poll() is None:
                try:
                    job.proc.wait(wait_s)
                except subprocess.TimeoutExpired:
                    job.proc.kill()
