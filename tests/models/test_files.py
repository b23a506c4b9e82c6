"""Files the program writes: atomically, with ordinary permissions, partial folders of its own that never touch
a user's, and one writer per folder."""

from __future__ import annotations

import os
import stat
import subprocess
import sys
import textwrap

import pytest

from models.files import FolderBusy, WriterLock, atomic_write_bytes, clean_partials, partial_folder


def test_atomic_write_gives_ordinary_permissions(tmp_path):
    old = os.umask(0o022)
    try:
        atomic_write_bytes(tmp_path / "a.json", b"{}")
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "a.json").stat().st_mode) == 0o644  # not mkstemp's 0600
    assert [p.name for p in tmp_path.iterdir()] == ["a.json"]  # no temporary left


def test_partial_folder_never_touches_the_users_files(tmp_path):
    out = tmp_path / "capture"
    mine = tmp_path / "capture.partial"  # a user's folder with the old partial name
    mine.mkdir()
    (mine / "notes.txt").write_text("keep me")
    dead = tmp_path / ".capture.partial-999999999-abc"  # a killed run's leftover (no such process)
    dead.mkdir()
    with partial_folder(out) as tmp:
        assert tmp.parent == tmp_path and tmp.name.startswith(f".capture.partial-{os.getpid()}-")
        (tmp / "x").write_text("1")
    assert (out / "x").read_text() == "1" and not dead.exists()
    assert (mine / "notes.txt").read_text() == "keep me"
    def fail() -> None:
        with partial_folder(tmp_path / "other") as tmp:
            (tmp / "y").write_text("2")
            raise RuntimeError("boom")

    with pytest.raises(RuntimeError):  # a failure leaves nothing
        fail()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["capture", "capture.partial"]
    assert clean_partials(out) == []


def test_one_writer_per_folder(tmp_path):
    folder = tmp_path / "avatar"
    holder = subprocess.Popen([sys.executable, "-c", textwrap.dedent(f"""
        import sys, time
        sys.path.insert(0, {str(os.getcwd())!r})
        from models.files import WriterLock
        with WriterLock({str(folder)!r}, "a trainer"):
            print("held", flush=True)
            time.sleep(60)
        """)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(FolderBusy, match=rf"in use by a trainer \(pid {holder.pid}\)"), WriterLock(folder, "me"):
            pass
    finally:
        holder.kill()
        holder.wait()
    with WriterLock(folder, "me"):  # the OS freed the killed holder's lock
        pass
