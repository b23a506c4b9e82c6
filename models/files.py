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


def _about(e: OSError, users: Path) -> OSError:
    """An error about one of the program's own temporary files retold about the user's path: the temporary's name
    means nothing to them."""
    return e if e.errno is None else type(e)(e.errno, e.strerror, str(users))


def atomic_write(path: str | Path, write: Callable[[str], None]) -> None:
    """Call write(tmp) on a temporary file beside `path`, fsync it, then rename it over `path`.
    On any failure the temporary file is removed and `path` is untouched; an error about the temporary names
    `path`. The file gets the permissions any new file would (the user's umask: mkstemp's are owner-only, and a
    writer that replaces the temporary, as safetensors does, makes its own), set after the rename."""
    path = Path(path)
    try:
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    except OSError as e:
        raise _about(e, path) from None
    os.close(fd)
    try:
        write(tmp)
        with open(tmp, "rb") as f:
            os.fsync(f.fileno())
        os.replace(tmp, path)
        os.chmod(path, 0o666 & ~_UMASK)
    except OSError as e:
        Path(tmp).unlink(missing_ok=True)
        if e.filename is None or Path(e.filename) == Path(tmp):
            raise _about(e, path) from None
        raise
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    atomic_write(path, lambda tmp: Path(tmp).write_bytes(data))


class FolderBusy(RuntimeError):
    """Another process holds a folder's writer lock; the message names the folder and that process."""


class WriterLock:
    """One writer per folder: filelock's lock on FOLDER/.writer.lock (flock on Unix, LockFileEx on Windows), held
    while the owner runs and freed by the OS when it ends however it ends (a kill leaves no stale lock). The file
    says who holds it. On leaving, the lock file is removed, and so are the folders entering made (FOLDER, and
    parents it had to make) where they hold nothing: a run that failed leaves no trace."""

    NAME = ".writer.lock"
    WAIT_S = 0.2
    """How long a second writer waits before it is refused: long enough to outlast a holder that is just letting go
    (filelock then tries the file the next holder made), too short for anyone to notice."""

    def __init__(self, folder: str | Path, what: str):
        self.folder, self.what = Path(folder), what
        self._lock = None
        self._made: list[Path] = []

    def _sign(self, fd: int) -> None:
        """Write who holds the lock into its file (filelock calls this with the locked descriptor)."""
        os.ftruncate(fd, 0)
        os.lseek(fd, 0, os.SEEK_SET)
        os.write(fd, f"{self.what} (pid {os.getpid()})\n".encode())

    def __enter__(self) -> WriterLock:
        from filelock import FileLock, Timeout

        self._made = [p for p in (self.folder, *self.folder.parents) if not p.exists()]
        self.folder.mkdir(parents=True, exist_ok=True)
        path = self.folder / self.NAME
        # no mode: filelock creates the file as any new file is made (the user's umask)
        lock = FileLock(path, timeout=self.WAIT_S, on_acquired=self._sign)
        try:
            lock.acquire()
        except Timeout:
            try:
                holder = path.read_text(errors="replace")[:200].strip()
            except OSError:  # gone meanwhile, or locked against reading (Windows)
                holder = ""
            raise FolderBusy(f"{self.folder}: in use by {holder or 'another process'}; wait for it to finish (or stop "
                             "it) or choose another folder") from None
        self._lock = lock
        return self

    def __exit__(self, *exc) -> None:
        if self._lock is None:
            return
        # While still held, no one else has it yet; one who opened this file before and locks it after finds it
        # unlinked, and filelock has it try the path again. Windows cannot remove an open file: filelock removes it
        # there on release.
        with contextlib.suppress(OSError):
            (self.folder / self.NAME).unlink(missing_ok=True)
        self._lock.release()
        self._lock = None
        for made in self._made:  # deepest first
            try:
                made.rmdir()
            except OSError:  # it holds something (or was never made): kept
                break


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
    try:
        tmp = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.partial-{os.getpid()}-"))
    except OSError as e:
        raise _about(e, out) from None
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


def unwritable(out: str | Path) -> str | None:
    """Why a file or folder to be written at `out` could not be, or None; checked before any work, so that a long
    run does not end on it. A path not made yet is judged by its nearest existing parent, an existing file by its
    folder (it is replaced there), an existing folder by itself (written into)."""
    out = Path(out)
    place = out if out.is_dir() else out.parent
    while not place.exists():
        place = place.parent
    if not place.is_dir():
        return f"{place} is a file, not a folder"
    if not os.access(place, os.W_OK | os.X_OK):
        return f"no permission to write in {place}"
    return None
