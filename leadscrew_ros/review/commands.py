# SPDX-License-Identifier: Apache-2.0
"""The squeak guard's command in a log, for `replay`: the raw speed command (`speed_command`)
and the guarded one (`speed_command_guarded`, std_msgs/Float64, rad/s) and the time the guard
changed the command (`guard/active`, std_msgs/Bool, held until the next), topics of the log's
input namespace as `ros.guard_node` publishes them. Binned over time (`decimation.Envelope`):
constant memory whatever the log's length.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

from ..bag import cdr, messages
from ..bag.logfile import LogMessage
from .decimation import Envelope
from .timeline import resolve

COMMANDS = (messages.SPEED_COMMAND, messages.SPEED_COMMAND_GUARDED)
LABELS = {messages.SPEED_COMMAND: "raw command", messages.SPEED_COMMAND_GUARDED: "guarded command"}


@dataclass
class CommandTrace:
    """The raw and the guarded speed command of a log and the guard's active time.

    Parameters
    ----------
    namespace : str
        The log's input namespace: the topics are resolved in it.

    Attributes
    ----------
    envelopes : dict of str to Envelope
        Relative topic (`COMMANDS`) -> its values over time [s, rad/s], for the topics found.
    counts : Counter
        Messages taken per relative topic (guard/active too).
    undecodable : Counter
        Messages whose payload did not decode, per relative topic (not taken).
    lo, hi : dict of str to float
        Least and greatest finite value per relative command topic [rad/s].
    active_s : float
        Time with guard/active true [s] (to the last message of the log).
    """

    namespace: str = "/"
    envelopes: dict[str, Envelope] = field(default_factory=dict)
    counts: Counter = field(default_factory=Counter)
    undecodable: Counter = field(default_factory=Counter)
    lo: dict[str, float] = field(default_factory=dict)
    hi: dict[str, float] = field(default_factory=dict)
    active_s: float = 0.0
    _active_since: float | None = None

    def __post_init__(self) -> None:
        self._topics = {
            resolve(t, self.namespace): (t, messages.GUARD_TYPES[t])
            for t in (*COMMANDS, messages.GUARD_ACTIVE)
        }

    def takes(self, topic: str) -> bool:
        """Whether messages on `topic` (a full name) may be the guard's (`add` checks the
        type)."""
        return topic in self._topics

    def add(self, m: LogMessage, t_s: float) -> None:
        """Take `m` if it is one of the guard's topics (its type), at `t_s` [s]."""
        found = self._topics.get(m.topic.name)
        if found is None or m.topic.type_name != found[1]:
            return
        topic = found[0]
        decode = cdr.decode_bool if topic == messages.GUARD_ACTIVE else cdr.decode_float64
        try:
            number = decode(m.data)
        except ValueError:
            self.undecodable[topic] += 1
            return
        self.counts[topic] += 1
        if topic == messages.GUARD_ACTIVE:
            self._set_active(bool(number), t_s)
            return
        self.envelopes.setdefault(topic, Envelope(1)).add(t_s, number)
        if math.isfinite(number):
            self.lo[topic] = min(self.lo.get(topic, number), number)
            self.hi[topic] = max(self.hi.get(topic, number), number)

    def _set_active(self, active: bool, t_s: float) -> None:
        if active and self._active_since is None:
            self._active_since = t_s
        elif not active and self._active_since is not None:
            self.active_s += t_s - self._active_since
            self._active_since = None

    def close(self, end_s: float) -> None:
        """The log ends at `end_s` [s]: an active guard counts until then."""
        self._set_active(False, end_s)

    @property
    def found(self) -> bool:
        """The log has the raw or the guarded command."""
        return bool(self.envelopes)

    def as_dict(self) -> dict[str, Any]:
        """summary.json's `speed_commands`: per topic messages and range [rad/s], the guard's
        active time [s]."""
        return {
            "topics": {
                resolve(t, self.namespace): {
                    "messages": self.counts[t],
                    "min_rad_s": self.lo.get(t),
                    "max_rad_s": self.hi.get(t),
                }
                for t in COMMANDS
                if t in self.envelopes
            },
            "guard_active_s": self.active_s if self.counts[messages.GUARD_ACTIVE] else None,
            "undecodable": dict(self.undecodable),
        }

    def text(self) -> list[str]:
        """summary.txt's lines on the commands."""
        lines = []
        for t in COMMANDS:
            if t in self.envelopes:
                lines.append(
                    f"{LABELS[t]} ({resolve(t, self.namespace)}): {self.counts[t]} messages, "
                    f"{self.lo.get(t, math.nan):.4g} .. {self.hi.get(t, math.nan):.4g} rad/s"
                )
        if self.counts[messages.GUARD_ACTIVE]:
            lines.append(f"guard active (changing the command): {self.active_s:.2f} s")
        lines += [
            f"{LABELS.get(t, t)}: {n} message(s) not decodable, not taken"
            for t, n in sorted(self.undecodable.items())
        ]
        return lines
