"""Files the program writes: atomically, with ordinary permissions, partial folders of its own that never touch
a user's, and one writer per folder."""

from __future__ import annotations

import os
import stat
import subprocess
import sys
import textwrap

import pytest

from models.files import (
    FolderBusy,
    WriterLock,
    atomic_write,
    atomic_write_bytes,
    clean_partials,
    partial_folder,
    unwritable,
)


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


def _unwritable_place(tmp_path):
    """A folder path nothing can be written under: read-only (0o555) for a user; as root, whom modes do not stop,
    a path under a regular file."""
    if os.geteuid() != 0:
        ro = tmp_path / "ro"
        ro.mkdir(mode=0o555)
        return ro
    (tmp_path / "plain_file").write_text("not a folder")
    return tmp_path / "plain_file"


def test_weights_get_the_users_permissions(tmp_path):
    """safetensors replaces the temporary it is given with a file of its own, mode 0600 (what `train` wrote its
    weights with): the mode is set after the rename."""
    import numpy as np
    from safetensors.numpy import save_file

    umask = os.umask(0o022)
    os.umask(umask)
    target = tmp_path / "weights-000001.safetensors"
    atomic_write(target, lambda tmp: save_file({"w": np.zeros(3, np.float32)}, tmp))
    assert stat.S_IMODE(target.stat().st_mode) == 0o666 & ~umask  # 0644 under the usual 022, not 0600


def test_an_unwritable_place_is_named_as_the_user_gave_it(tmp_path):
    """The error names the user's path, never the program's temporary (.NAME.XXXX.tmp, .NAME.partial-PID-XXXX)."""
    place = _unwritable_place(tmp_path)
    with pytest.raises(OSError, match=r"a\.json") as e:
        atomic_write_bytes(place / "a.json", b"{}")
    assert e.value.filename == str(place / "a.json"), e.value
    with pytest.raises(OSError, match=place.name) as e, partial_folder(place / "dataset"):
        pass
    assert ".partial" not in e.value.filename and ".tmp" not in e.value.filename, e.value
    assert unwritable(place / "deeper" / "out.png") is not None and place.name in unwritable(place / "x")
    assert unwritable(tmp_path / "new" / "deeper" / "out.png") is None  # made on the way: its parent is writable


def test_a_writer_leaves_no_lock_and_no_empty_folder(tmp_path):
    """The lock file goes when the writer does; the folders it made go too where nothing was written (a failed
    run), and stay where something was."""
    failed = tmp_path / "made" / "avatar"

    def fail() -> None:
        with WriterLock(failed, "a trainer"):
            assert (failed / WriterLock.NAME).is_file()
            raise RuntimeError("the capture was not a capture")

    with pytest.raises(RuntimeError):
        fail()
    assert list(tmp_path.iterdir()) == []
    done = tmp_path / "avatar"
    with WriterLock(done, "a trainer"):
        (done / "avatar.json").write_text("{}")
    assert [p.name for p in done.iterdir()] == ["avatar.json"]
    with WriterLock(done, "a trainer"):  # taken again: its own lock file, removed again
        pass
    assert [p.name for p in done.iterdir()] == ["avatar.json"]
