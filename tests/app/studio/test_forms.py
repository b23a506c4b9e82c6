"""The Export and Jobs panels' forms: every field reaches the option it names, and the default output paths are
absolute (under the studio's home), wherever the studio was started."""

from __future__ import annotations

from pathlib import Path

from app.studio.config import STUDIO_HOME
from app.studio.export_panel import ExportForm
from app.studio.jobs_panel import JobForm


def test_export_form_fields_reach_their_options():
    cfg = ExportForm(frames=24, views_only=False, elevation=10.0, zoom=1.5, size=129, preset=2, animate=True).config(
        Path("av"))
    assert (cfg.frames, cfg.sweep_deg, cfg.elevation_deg, cfg.zoom, cfg.size, cfg.preset, cfg.animate) == \
        (24, 0.0, 10.0, 1.5, 128, "final", True)
    assert ExportForm().config(Path("av")).sweep_deg is None  # the avatar's captured views


def test_default_outputs_are_under_the_studio_home():
    for path in (Path(ExportForm().out), Path(JobForm().out)):
        assert path.is_absolute() and STUDIO_HOME in path.parents
