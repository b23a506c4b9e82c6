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
