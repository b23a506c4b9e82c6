"""The Avatar panel's own folder browser, for desktops without a file dialog program."""

from __future__ import annotations

import sys

from app.studio.avatar_panel import subfolders, system_dialog_available


def test_subfolders_sorted_without_hidden_ones(tmp_path):
    for name in ("b", "A", ".hidden", "c"):
        (tmp_path / name).mkdir()
    (tmp_path / "file.txt").write_text("x")
    assert [p.name for p in subfolders(tmp_path)] == ["A", "b", "c"]
    assert subfolders(tmp_path / "missing") == []


def test_no_dialog_program_means_the_built_in_browser(monkeypatch, tmp_path):
    monkeypatch.setenv("PATH", str(tmp_path))  # nothing to run
    assert system_dialog_available() is (sys.platform != "linux")
    (tmp_path / "zenity").write_text("#!/bin/sh\n")
    (tmp_path / "zenity").chmod(0o755)
    assert system_dialog_available()
