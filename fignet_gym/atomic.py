"""Nothing half-written, nothing mixed: atomic file writes and one writer per output.

* :func:`write_text`: a reader (or a resumed run) sees the old file or the new one, never half.
* :func:`output_lock`: an exclusive lock on an output (a run folder or a file), so two processes
  never append to one run. The lock is a sibling file ``.<name>.lock`` holding the owner's pid,
  locked with ``fcntl.flock``: the kernel releases it when the owner dies, however it dies, so a
  lock file left by a killed run is stale by construction and is taken over, never obeyed. The
  lock file is a sibling, not inside the folder, so commands that check or clear a folder's
  content (``--force``) never see or delete it.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import time
from collections.abc import Iterator
from pathlib import Path

#: Suffix of a lock file (``.<name>.lock`` beside the locked output).
LOCK_SUFFIX = ".lock"


class OutputLockedError(ValueError):
    """Another live process holds the output (the message names it, its pid and the lock file)."""


def write_text(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` to ``path`` via a sibling temp file and ``os.replace``; returns ``path``."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)
    return path


def lock_path(out: str | os.PathLike) -> Path:
    """The lock file of an output folder or file: ``<parent>/.<name>.lock``."""
    out = Path(os.path.abspath(out))
    return out.with_name(f".{out.name}{LOCK_SUFFIX}")


@contextlib.contextmanager
def output_lock(out: str | os.PathLike, option: str = "--out") -> Iterator[Path]:
    """Hold an exclusive lock on ``out`` (a folder or a file) for the ``with`` block.

    Raises :class:`OutputLockedError` at once if a live process holds it (no waiting: a second
    writer is a user's mistake). Creates ``out``'s parent folder if needed. Yields the lock file.
    """
    path = lock_path(out)
    path.parent.mkdir(parents=True, exist_ok=True)
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            owner = _read_owner(fd)
            os.close(fd)
            raise OutputLockedError(
                f"{option} {out}: in use by another process ({owner}; lock file {path}); wait "
                "for it to finish or choose another " + option) from None
        # The previous owner may have unlinked the file between our open and our lock: then this
        # lock is on a dead inode that no one else will see. Retry on the current file.
        try:
            same = os.fstat(fd).st_ino == os.stat(path).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    try:
        os.ftruncate(fd, 0)
        os.write(fd, f"pid {os.getpid()} since {time.strftime('%Y-%m-%d %H:%M:%S')}\n".encode())
        yield path
    finally:
        # Unlink while still holding the lock (see the inode check above), then release.
        with contextlib.suppress(FileNotFoundError):
            os.unlink(path)
        os.close(fd)


def _read_owner(fd: int) -> str:
    try:
        text = os.pread(fd, 200, 0).decode(errors="replace").strip()
    except OSError:
        text = ""
    return text or "pid unknown"
