# SPDX-License-Identifier: Apache-2.0
"""An output directory held by one run at a time: two runs writing into one directory would
interleave their files (one run's inputs lost to the other's cleanup).

The run holds an advisory `flock(LOCK_EX)` on a lock file in the directory, from start to end,
and writes its pid and start time into it so that a second run can say which run holds it. The
lock goes with the file descriptor: a run that died (killed, crashed) holds nothing, and the
next run takes its lock over and says so (its pid and start time still in the file). A clean
end removes the file. A file system without flock (some network mounts) is refused: without it
the lock cannot be told from a stale one.
"""

from __future__ import annotations

import datetime
import fcntl
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


class DirectoryBusy(Exception):
    """The directory is held by another run, or cannot be locked (the message says which)."""


def _holder(text: str) -> str:
    """'pid N, started T' of a lock file's text (or what it says, when not that)."""
    fields = dict(line.split("=", 1) for line in text.splitlines() if "=" in line)
    if "pid" in fields:
        return f"pid {fields['pid']}, started {fields.get('started', 'at an unknown time')}"
    return "a run that wrote no pid"


def _acquire(path: Path) -> tuple[int, str]:
    """Open and lock `path` (the file that is there when locked, not one unlinked meanwhile);
    (fd, the earlier content: a dead run's when not empty)."""
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            text = os.read(fd, 4096).decode("utf-8", "replace")
            os.close(fd)
            raise DirectoryBusy(f"is in use by another run ({_holder(text)})") from None
        except OSError as exc:
            os.close(fd)
            raise DirectoryBusy(f"cannot be locked ({exc.strerror or exc})") from None
        try:
            same = os.fstat(fd).st_ino == os.stat(path).st_ino
        except FileNotFoundError:  # its holder ended and removed it between open and flock
            same = False
        if same:
            return fd, os.read(fd, 4096).decode("utf-8", "replace")
        os.close(fd)


@contextmanager
def locked(directory: Path, name: str) -> Iterator[str]:
    """Hold `directory` (which must exist) for this run through its lock file `name`.

    Parameters
    ----------
    directory : Path
        The output directory.
    name : str
        The lock file's name in it.

    Yields
    ------
    str
        '' or a note: the stale lock of a run that died, taken over.

    Raises
    ------
    DirectoryBusy
        Another run holds it (its pid and start time in the message), or it cannot be locked.
    OSError
        The lock file cannot be created (the directory is not writable).
    """
    path = directory / name
    fd, earlier = _acquire(path)
    try:
        note = (
            f"took over the lock of a run that ended without releasing it ({_holder(earlier)})"
            if earlier.strip()
            else ""
        )
        started = datetime.datetime.now(datetime.timezone.utc).replace(microsecond=0)
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"pid={os.getpid()}\nstarted={started.isoformat()}\n".encode(), 0)
        yield note
    finally:
        try:
            path.unlink(missing_ok=True)  # before the unlock: a waiting run re-checks the inode
        finally:
            os.close(fd)
