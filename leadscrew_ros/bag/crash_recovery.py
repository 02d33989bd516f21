# SPDX-License-Identifier: Apache-2.0
"""Bags of a node cut off by an earlier crash (no metadata.yaml, or a file without footer):
found on start, reported, and recovered in place on request. rclpy-free."""

from __future__ import annotations

import re
import threading
from pathlib import Path

from ..live.status import Level
from .logfile import RECOVER_HINT, LogError, cut_off_bags, recover_bag


class CrashRecovery:
    """The bags of this node in the record directory that an earlier crash cut off (no
    metadata.yaml, or a file without footer): reported, and recovered in place by `start`
    (`logfile.recover_bag`, on a thread of its own: a large bag takes a while)."""

    def __init__(self, directory: str, prefix: str):
        own = re.compile(re.escape(prefix) + r"_\d{4}_\d\d_\d\d-\d\d_\d\d_\d\d_\d{3}(_\d+)?$")
        self.bags = [
            b
            for b in cut_off_bags(Path(directory).expanduser())
            if b.is_dir() and own.match(b.name)
        ]
        self.recovered: list[Path] = []
        self.failed: dict[Path, str] = {}
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        """Recover the cut-off bags on a background thread."""
        self._thread = threading.Thread(
            target=self._recover, daemon=True, name="cut-off bag recovery"
        )
        self._thread.start()

    def join(self) -> None:
        """Wait for the recovery thread, if `start` started one."""
        if self._thread is not None:
            self._thread.join()

    def _recover(self) -> None:
        for bag in self.bags:
            try:
                recover_bag(bag)
                self.recovered.append(bag)
            except (LogError, OSError) as exc:
                self.failed[bag] = str(exc)

    @property
    def pending(self) -> list[Path]:
        """Cut-off bags not recovered (yet)."""
        return [b for b in self.bags if b not in self.recovered]

    @property
    def state(self) -> tuple:
        """Counts of (cut-off, recovered, failed) bags."""
        return len(self.bags), len(self.recovered), len(self.failed)

    @property
    def level(self) -> Level:
        """WARN while a bag is still cut off or being recovered, else OK."""
        return Level.WARN if self.pending else Level.OK

    @property
    def message(self) -> str:
        """'' when there is nothing to say."""
        parts = []
        if self.recovered:
            parts.append(
                f"recovered {len(self.recovered)} cut-off bag(s) of an earlier run: "
                + ", ".join(str(b) for b in self.recovered)
            )
        running = self._thread is not None and self._thread.is_alive()
        waiting = [b for b in self.pending if b not in self.failed]
        if waiting and running:
            parts.append(f"recovering {len(waiting)} cut-off bag(s) of an earlier run")
        elif self.pending:
            parts.append(
                f"{len(self.pending)} bag(s) of an earlier run cut off (crash?): "
                + ", ".join(str(b) for b in self.pending)
                + "; run `"
                + f"{RECOVER_HINT} BAGDIR` on each"
                + "".join(f" ({self.failed[b]})" for b in self.pending if b in self.failed)
            )
        return "; ".join(parts)
