# SPDX-License-Identifier: Apache-2.0
"""`leadscrew-squeak watch`: a live view of a running squeak_predictor in a terminal, without
the `ros2` command line.

A client node in a Context of its own (`remote.Remote`) subscribes, as any other client would,
to the node's outputs (with its latched QoS: the last message of each is there at once):
squeak/risk, squeak/active, squeak/modes, squeak/safe_speed, ... (decoded by `demo`'s
`SqueakMonitor`), squeak/heard and squeak/heard_frequency, and /diagnostics, of which it keeps
this node's statuses: the inputs in use (speed, load, nut position), the prediction's verdict,
the recording and, with listening on, the measurement. On a terminal the view is redrawn in
place twice a second; otherwise it is appended as plain text whenever it changes.
"""

from __future__ import annotations

import os
import shutil
import signal
import sys
import time
from typing import Any, TextIO

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.context import Context

from ..bag import cdr, messages
from ..live.status import (
    KEY_LOAD,
    KEY_MARGIN,
    KEY_NUT_POSITION,
    KEY_SAFE_SPEED,
    KEY_SAFE_SPEED_PENDING,
    KEY_SPEED,
    KEY_VALID,
    Level,
)
from .demo import SqueakMonitor
from .diagnostics import MEASUREMENT_TASK, PREDICTION_TASK, RECORDING_TASK
from .env import PROGRAM, StopSignals
from .node import LATCHED, LISTEN_CLASSES
from .remote import (
    DISCOVERY_S,
    NODE_WAIT_S,
    SPIN_STEP_S,
    NodeNotFound,
    RecordingState,
    Remote,
    node_name,
    not_found,
)

REFRESH_S = 0.5  # the view's period
OUTPUT_WAIT_S = 10.0  # longest wait for the node's latched outputs once it is found
SETTLE_S = 0.05  # `--once` prints after a spin this long takes no message (latched history)
CLEAR = "\x1b[H\x1b[J"  # ANSI: cursor home, clear to the end of the screen
# The view's rows, in order (the diagnostics take one line per status)
ROWS = ("inputs", "P(squeak)", "unstable", "safe speed", "diagnostics", "recording", "listening")
LABEL_WIDTH = 12


class WatchNode(SqueakMonitor):
    """The outputs of the predictor `target` (its fully qualified name), as they arrive: those
    of `SqueakMonitor`, this node's diagnostic statuses by task, and what it hears.

    Parameters
    ----------
    target : str
        The predictor's fully qualified name ('/seat_left/squeak_predictor').
    **kwargs
        Passed to `rclpy.node.Node` (context, namespace: the predictor's).
    """

    def __init__(self, target: str, **kwargs: Any):
        # A leading underscore hides it from `ros2 node list`, as for the ros2 CLI's own nodes
        super().__init__(f"_leadscrew_squeak_watch_{os.getpid()}", **kwargs)
        self.target = target
        self.statuses: dict[str, DiagnosticStatus] = {}  # task -> its latest status
        self.heard: bool | None = None  # squeak/heard (None: nothing received)
        self.heard_frequency_hz: float | None = None
        self.received: set[str] = set()  # output topics with a message
        for topic, callback in (
            (messages.HEARD, self._on_heard),
            (messages.HEARD_FREQUENCY, self._on_heard_frequency),
        ):
            self.create_subscription(
                LISTEN_CLASSES[topic], topic, self._decoding(callback), LATCHED, raw=True
            )

    # ------------------------------------------------------------------ callbacks
    def _decoding(self, callback):
        """`SqueakMonitor._decoding`, each message counted (`taken`)."""
        run = super()._decoding(callback)

        def counted(data: bytes) -> None:
            self.taken = getattr(self, "taken", 0) + 1
            run(data)

        return counted

    def _on_risk(self, data: bytes) -> None:
        super()._on_risk(data)
        self.received.add(messages.RISK)

    def _on_modes(self, data: bytes) -> None:
        super()._on_modes(data)
        self.received.add(messages.MODES)

    def _on_active(self, data: bytes) -> None:
        super()._on_active(data)
        self.received.add(messages.ACTIVE)

    def _on_safe_speed(self, data: bytes) -> None:
        super()._on_safe_speed(data)
        self.received.add(messages.SAFE_SPEED)

    def _on_heard(self, data: bytes) -> None:
        self.heard = cdr.decode_bool(data)

    def _on_heard_frequency(self, data: bytes) -> None:
        self.heard_frequency_hz = cdr.decode_float64(data)

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        """Keep the statuses of `target` only (every node publishes on /diagnostics), the
        prediction's first, as `SqueakMonitor` reads it."""
        self.taken = getattr(self, "taken", 0) + 1
        prefix = f"{self.target}: "
        own = [s for s in msg.status if s.name.startswith(prefix)]
        if not own:
            return
        self.statuses = {s.name[len(prefix) :]: s for s in own}
        msg.status = own
        super()._on_diagnostics(msg)

    # ------------------------------------------------------------------ state
    def values(self, task: str) -> dict[str, str]:
        """The key-values of the latest status of `task` ({} before one)."""
        status = self.statuses.get(task)
        return {kv.key: kv.value for kv in status.values} if status else {}

    def ready(self) -> bool:
        """Everything the node has published is in: its statuses and, when they say so, the
        prediction, the safe speed and what it heard (what `--once` waits for)."""
        if PREDICTION_TASK not in self.statuses or RECORDING_TASK not in self.statuses:
            return False
        values = self.values(PREDICTION_TASK)
        wanted = set()
        if values.get(KEY_VALID) == "true":
            wanted |= {messages.RISK, messages.MODES, messages.ACTIVE}
        if values.get(KEY_SAFE_SPEED):
            wanted.add(messages.SAFE_SPEED)
        heard = MEASUREMENT_TASK not in self.statuses or self.heard is not None
        return wanted <= self.received and heard


# ----------------------------------------------------------------------------- text
def _quantity(text: str, unit: str) -> str:
    return f"{text} {unit}" if text else "none yet"


def view_lines(node: WatchNode) -> list[str]:
    """The view of the predictor's state (without the header): one row per entry of `ROWS`,
    one more per further diagnostic status."""
    r, inputs = node.record, node.values(PREDICTION_TASK)
    texts = {
        "inputs": f"speed {_quantity(inputs.get(KEY_SPEED, ''), 'rad/s')}, "
        f"load {_quantity(inputs.get(KEY_LOAD, ''), 'N')}, "
        f"nut {_quantity(inputs.get(KEY_NUT_POSITION, ''), 'm')}",
        "P(squeak)": "no prediction yet",
        "unstable": "no prediction yet",
    }
    if r.probability is not None:
        active = (
            "yes (a mode squeaks at the nominal parameters)"
            if r.active
            else "no (every mode stable at the nominal parameters)"
        )
        margin = inputs.get(KEY_MARGIN, "")
        texts["P(squeak)"] = f"{r.probability:.3f}   active: {active}" + (
            f"   margin {margin}" if margin else ""
        )
        modes = [f"{label} {f:.1f} Hz" for label, f in r.squeak_modes] or [
            f"{f:.1f} Hz" for f in r.frequencies
        ]
        texts["unstable"] = ", ".join(modes) or "none"
    texts["safe speed"] = "none yet" if r.safe_speed is None else f"{r.safe_speed:.2f} rad/s"
    if inputs.get(KEY_SAFE_SPEED_PENDING) == "true":
        texts["safe speed"] += " (a new search is under way)"
    recording = node.statuses.get(RECORDING_TASK)
    texts["recording"] = (
        RecordingState.from_status(recording).text() if recording else "no status yet"
    )
    texts["listening"] = _listening(node)
    statuses = [
        f"{Level(status.level[0]).name:<5} {task}: {status.message}"
        for task, status in node.statuses.items()
    ]
    rows = {**{label: [text] for label, text in texts.items()}, "diagnostics": statuses}
    return [
        f"{label if i == 0 else '':<{LABEL_WIDTH}}{text}"
        for label in ROWS
        for i, text in enumerate(rows[label] or ["none yet"])
    ]


def _listening(node: WatchNode) -> str:
    if not node.statuses:
        return "no status yet"
    measurement = node.statuses.get(MEASUREMENT_TASK)
    if measurement is None:
        return "off (listen.enabled is false)"
    if node.heard is None:
        heard = "nothing received on squeak/heard yet"
    elif node.heard:
        heard = f"squeak heard at {node.heard_frequency_hz or 0:.1f} Hz"
    else:
        heard = "no squeak heard"
    return f"{heard}; {measurement.message}"


def header(target: str, found: bool, seen_at: float | None) -> tuple[str, str]:
    """The first line, on either side of the time of the view: which node on which domain, and
    '' or '   NOT FOUND since HH:MM:SS' (the node's last sighting)."""
    state = (
        ""
        if found
        else "   NOT FOUND"
        + (f" since {time.strftime('%H:%M:%S', time.localtime(seen_at))}" if seen_at else "")
    )
    return (
        f"squeak_node {target} (ROS_DOMAIN_ID {os.environ.get('ROS_DOMAIN_ID') or 0}, "
        f"discovery {os.environ.get('ROS_AUTOMATIC_DISCOVERY_RANGE', '')})",
        state,
    )


class Screen:
    """Where the view goes: on a terminal redrawn in place (cut to its width and height), else
    appended as plain text when it changed (the time aside)."""

    def __init__(self, out: TextIO):
        self.out, self.tty = out, out.isatty()
        self._last: list[str] | None = None

    def show(self, head: tuple[str, str], lines: list[str]) -> None:
        """Show the view: the first line from `head` (`header`) with the time, then `lines`."""
        view = [f"{head[0]}   {time.strftime('%H:%M:%S')}{head[1]}", *lines]
        if self.tty:  # within the terminal: a longer view would scroll away the cursor's home
            width, height = shutil.get_terminal_size()
            fits = [line[: width - 1] for line in view[: max(height - 1, 1)]]
            self.out.write(CLEAR + "\n".join(fits) + "\n")
        elif [*head, *lines] != self._last:  # a blank line between two views
            blank = [""] if self._last is not None else []
            self.out.write("\n".join([*blank, *view]) + "\n")
        self._last = [*head, *lines]
        self.out.flush()


def run_watch(
    namespace: str = "/",
    once: bool = False,
    timeout_s: float | None = None,
    out: TextIO | None = None,
) -> int:
    """Watch the squeak_predictor in `namespace` until Ctrl-C (or `timeout_s`).

    Parameters
    ----------
    namespace : str
        The predictor's namespace.
    once : bool
        Print the view once, when everything the node has published is in (at most
        `OUTPUT_WAIT_S` after it was found), and return.
    timeout_s : float, optional
        Return after this long [s]; with `once`, the longest wait for the node (default
        `NODE_WAIT_S`).
    out : text file, optional
        Where the view goes; default stdout.

    Returns
    -------
    int
        0; after SIGTERM also 0, with `StopSignals.exit_status`'s line on stderr.

    Raises
    ------
    NodeNotFound
        With `once` or `timeout_s`: no node appeared in time (the message says how to start
        one). In any case one line on stderr says so after `DISCOVERY_S`.
    KeyboardInterrupt
        Ctrl-C (SIGINT), after the client node was closed.
    ValueError
        An invalid namespace.
    """
    screen = Screen(out or sys.stdout)
    start = time.monotonic()
    end = None if timeout_s is None else start + timeout_s
    give_up = start + (NODE_WAIT_S if timeout_s is None else timeout_s) if once else end
    with StopSignals() as stop, Remote(namespace, _watch_node) as remote:
        node, executor = remote.node, remote.executor
        assert isinstance(node, WatchNode) and executor is not None
        seen_at: float | None = None  # wall time the node was last in the graph
        found_at: float | None = None  # monotonic time it was first found
        said_missing, shown, next_draw = False, False, start
        while not stop.signum:
            now = time.monotonic()
            found = remote.found()
            if found:
                seen_at, found_at = time.time(), found_at or now
            elif found_at is None:  # not seen yet
                if give_up is not None and now >= give_up:
                    raise NodeNotFound(not_found(remote.namespace))
                if now - start >= DISCOVERY_S and not said_missing:
                    until = "Ctrl-C stops" if give_up is None else f"up to {give_up - start:g} s"
                    print(
                        f"{PROGRAM}: {not_found(remote.namespace)}; still looking ({until})",
                        file=sys.stderr,
                        flush=True,
                    )
                    said_missing = True
            # the first view once the node's latched outputs are in (or they are late)
            if found_at is not None and (shown or node.ready() or now - found_at >= OUTPUT_WAIT_S):
                if once and not _settled(node, executor) and now - found_at < OUTPUT_WAIT_S:
                    continue  # a latched history still coming in: judged on its newest
                if once:
                    screen.tty = False  # plain text, also on a terminal
                    screen.show(header(remote.target, True, seen_at), view_lines(node))
                    return 0
                if now >= next_draw:
                    screen.show(header(remote.target, found, seen_at), view_lines(node))
                    shown, next_draw = True, now + REFRESH_S
            if end is not None and now >= end:
                break
            executor.spin_once(timeout_sec=SPIN_STEP_S)
    if stop.signum == signal.SIGINT:
        raise KeyboardInterrupt
    return stop.exit_status()


def _settled(node: WatchNode, executor: Any) -> bool:
    """Spin until a spin of `SETTLE_S` takes no message: True when `node` is still ready
    then. A node's latched /diagnostics come as a history, oldest first; an older status (the
    advice search of the first prediction under way) must not decide what `--once` shows."""
    taken = None
    while taken != getattr(node, "taken", 0):
        taken = getattr(node, "taken", 0)
        executor.spin_once(timeout_sec=SETTLE_S)
    return node.ready()


def _watch_node(context: Context, namespace: str) -> WatchNode:
    return WatchNode(node_name(namespace), context=context, namespace=namespace)
