# SPDX-License-Identifier: Apache-2.0
"""Which MCAP files are still being written: the one rule the recorder and the readers share.

The recorder holds an advisory `flock(LOCK_EX)` on every file it writes, from open to close (the
lock goes with the file descriptor, so a killed recorder leaves no stale lock). A reader asks
for a shared lock without waiting: refused means a live writer. flock locks belong to the open
file description, so this also tells a recording of this very process (the node) from a file
cut off by a crash.
"""

from __future__ import annotations

import fcntl
import os
from pathlib import Path

LIVE = "is being recorded (live writer)"  # what readers and `recover` say of such a file


def hold(fd: int) -> None:
    """Mark the file open on `fd` as being written until `fd` is closed (raises OSError if
    another writer holds it)."""
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)


def is_live(path: Path | str) -> bool:
    """True if a recorder (of any process) is writing the file `path` now."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    except OSError:  # a file system without flock: no writer can have locked it
        return False
    finally:
        os.close(fd)  # closing releases the probe's own lock
    return False


def live_files(path: Path | str) -> list[Path]:
    """The files of `path` (an MCAP file, or a bag directory's `*.mcap`) being written now."""
    path = Path(path)
    files = sorted(path.glob("*.mcap")) if path.is_dir() else [path]
    return [f for f in files if is_live(f)]
