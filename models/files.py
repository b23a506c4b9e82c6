"""Writing files so that a crash never leaves a half-written one in place of what was there."""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

_UMASK = os.umask(0o022)
os.umask(_UMASK)  # read once, at import (setting it is the only way to read it)


def atomic_write(path: str | Path, write: Callable[[str], None]) -> None:
    """Call write(tmp) on a temporary file beside `path`, fsync it, then rename it over `path`.
    On any failure the temporary file is removed and `path` is untouched. The file gets the permissions any new
    file would (mkstemp's own are owner-only)."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.fchmod(fd, 0o666 & ~_UMASK)
    os.close(fd)
    try:
        write(tmp)
        with open(tmp, "rb") as f:
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    atomic_write(path, lambda tmp: Path(tmp).write_bytes(data))


class FolderBusy(RuntimeError):
    """Another process holds a folder's writer lock; the message names the folder and that process."""


class WriterLock:
    """One writer per folder: an OS file lock (flock) on FOLDER/.writer.lock, held while the owner runs and freed
    by the OS when it ends however it ends (a kill leaves no stale lock). The file says who holds it."""

    NAME = ".writer.lock"

    def __init__(self, folder: str | Path, what: str):
        self.folder, self.what = Path(folder), what
        self._fd: int | None = None

    def __enter__(self) -> WriterLock:
        import fcntl

        self.folder.mkdir(parents=True, exist_ok=True)
        path = self.folder / self.NAME
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 200, 0).decode(errors="replace").strip() or "another process"
            os.close(fd)
            raise FolderBusy(f"{self.folder}: in use by {holder}; wait for it to finish (or stop it) or choose "
                             "another folder") from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{self.what} (pid {os.getpid()})\n".encode(), 0)
        self._fd = fd
        return self

    def __exit__(self, *exc) -> None:
        if self._fd is not None:
            os.close(self._fd)  # closing the descriptor frees the lock
            self._fd = None


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process: alive
        return True
    return True


def clean_partials(out: Path) -> list[Path]:
    """Remove what killed runs left of `out` (partial_folder's folders whose process is gone); returns them."""
    removed = []
    for p in out.parent.glob(f".{out.name}.partial-*-*"):
        try:
            pid = int(p.name[len(f".{out.name}.partial-"):].split("-")[0])
        except ValueError:
            continue
        if p.is_dir() and not _alive(pid):
            shutil.rmtree(p, ignore_errors=True)
            removed.append(p)
    return removed


@contextlib.contextmanager
def partial_folder(out: str | Path) -> Iterator[Path]:
    """A folder to write `out` into, renamed to `out` when the block ends well. It is the program's own: named
    .OUT.partial-PID-XXXX beside `out`, created exclusively, removed when the block fails; leftovers of killed
    runs are removed first. Nothing of the user's (not `out`, not a folder named OUT.partial) is touched."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    clean_partials(out)
    tmp = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.partial-{os.getpid()}-"))
    os.chmod(tmp, 0o777 & ~_UMASK)
    try:
        yield tmp
        if out.exists():
            raise FileExistsError(f"{out}: appeared while it was being written; the new one is not put in its place")
        os.rename(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def foreign_files(folder: str | Path, ours: str) -> list[Path]:
    """The files in `folder` whose names do not match the regular expression `ours` (what a command writes
    there): a command that would write into a folder holding any must not, or it could overwrite them."""
    import re

    pattern = re.compile(ours)
    folder = Path(folder)
    if not folder.is_dir():
        return []
    return sorted(p for p in folder.iterdir() if not pattern.fullmatch(p.name))
