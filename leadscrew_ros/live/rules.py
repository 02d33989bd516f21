# SPDX-License-Identifier: Apache-2.0
"""The input rules of the live node and of the offline replay, in one place: which values are
taken, how a sensor_msgs/JointState maps to speed and nut position, what the operating point
is, when it moved beyond a deadband, and at which nut position the contact is integrated.

`LivePredictor` (the node) adds arrival times, the rate limit, staleness, the verdict and the
advice; the replay's `Timeline` adds log-time ordering, counters and the trace. Both hold one
`InputRules` and feed it every message in the order they take them, so the same message stream
gives the same recomputes at the same points.

Rules:

- Speed [rad/s] and load [N]: a real number, finite, the load within the upper limit of
  `ScrewParameters.axial_load_n` (`model.squeak_model.check_operating_point`).
- Nut position z_o [m]: a finite real number with 0 <= z_o <= `ScrewParameters.nut_travel_m`.
- A rejected value is not taken: the previous good one stays, and the rejection gives a
  one-line message with the value (`model.physics.display.exact`: never rounded onto the limit) and
  a short reason without the value (the replay counts rejections by it).
- JointState: taken only when `JointSettings.joint_name` is set and the message has that
  joint. An empty `joint_name` ignores joint_states altogether, in the node and in the replay
  alike: using it is an explicit opt-in, so a JointState from another driver (a wheel, an arm)
  never moves the operating point. The joint's velocity is the speed, its angle theta the nut
  position `nut_position_at_zero_angle_m + theta * ScrewParameters.lead_per_rad_m`; `velocity`
  or `position` may be empty (that value is not given). A malformed message is rejected as a
  whole (reason 'joint_states malformed: ...'), never read by index: no names, a name twice,
  or a `position` / `velocity` that is neither empty nor one entry per name (sensor_msgs'
  rule). Both values are taken first, then one recompute decision follows, none if either was
  rejected.
- Order (`SampleOrder`): per input topic, a message whose sample time is earlier than that of
  the last one taken is stale and not taken. The replay's sample time is the header stamp of a
  type with a std_msgs/Header (not zero), else the log time; the node checks header stamps
  only (without one, arrival order is the order).
- Operating point (speed, load, nut): none until both a speed and a load were taken; the nut
  is `ScrewParameters.nut_position_m` until a nut input was taken.
- A recompute is due when the point moved more than a deadband (`LiveSettings`) from the point
  last computed, or when none was computed yet; the contact is re-integrated only when the nut
  moved more than `nut_deadband_m` from where it was last integrated.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple, TypeGuard

from ..model import OperatingPointError, ScrewParameters
from ..model.physics.display import exact
from ..model.physics.parameters import field_info
from ..model.squeak_model import check_operating_point
from .settings import JointSettings, LiveSettings

# As check_operating_point: the upper limit of the axial_load_n field (for the reason text).
_LOAD_LIMIT_N = field_info("axial_load_n")["hi"]

Point = tuple[float, float, float]  # speed [rad/s], load [N], nut position [m]


@dataclass(frozen=True)
class Rejection:
    """A value not taken: `reason` is short and without the value (counted by it), `message`
    one line with the exact value."""

    reason: str
    message: str


class Outcome(NamedTuple):
    """What one input message did (a NamedTuple: one per input message, so cheap)."""

    taken: tuple[str, ...] = ()  # inputs taken: 'speed', 'load', 'nut'
    rejected: tuple[Rejection, ...] = ()  # values not taken
    ignored: str = ""  # why the whole message was ignored, else ''

    @property
    def error(self) -> str:
        """The rejections' messages in one line ('' if none)."""
        return "; ".join(r.message for r in self.rejected)

    @property
    def applies(self) -> bool:
        """Something was taken and nothing rejected: a recompute decision follows."""
        return bool(self.taken) and not self.rejected


_TAKEN = {kind: Outcome(taken=(kind,)) for kind in ("speed", "load", "nut")}


@dataclass
class Inputs:
    """The latest value taken of each input (None until one was)."""

    speed_rad_s: float | None = None
    load_n: float | None = None
    nut_position_m: float | None = None


@dataclass(frozen=True)
class JointReading:
    """A JointState read for the screw joint: 'speed' [rad/s] and 'nut' [m] as far as the
    message has them (unchecked; the nut is the angle itself if that is not a number), or why
    the message is ignored."""

    values: dict[str, object]
    ignored: str = ""
    rejected: Rejection | None = None  # a malformed message


def moved(point: Point, last: Point, deadbands: LiveSettings) -> bool:
    """`point` moved beyond a deadband of `deadbands` from `last`.

    Parameters
    ----------
    point, last : tuple of float
        (speed [rad/s], load [N], nut position [m]).
    deadbands : LiveSettings
        Its speed_deadband_rad_s, load_deadband_n and nut_deadband_m.

    Returns
    -------
    bool
    """
    return (
        abs(point[0] - last[0]) > deadbands.speed_deadband_rad_s
        or abs(point[1] - last[1]) > deadbands.load_deadband_n
        or abs(point[2] - last[2]) > deadbands.nut_deadband_m
    )


def read_joint_state(
    names: Sequence[str],
    positions: Sequence[float],
    velocities: Sequence[float],
    joints: JointSettings,
    lead_per_rad_m: float,
) -> JointReading:
    """The screw joint's speed and nut position in a JointState (see the module docstring).

    Parameters
    ----------
    names, positions, velocities : sequence
        The message's fields (angles [rad], angular velocities [rad/s]).
    joints : JointSettings
        The screw joint's name ('' ignores every message) and the nut position at angle 0.
    lead_per_rad_m : float
        Nut travel per screw radian [m/rad].

    Returns
    -------
    JointReading
        Values are returned as they are (not checked): the caller takes them through its
        checks.
    """
    name = joints.joint_name
    if not name:
        return JointReading({}, "joint_name not set")
    problem = _malformed(list(names), len(positions), len(velocities))
    if problem:
        return JointReading(
            {},
            rejected=Rejection(
                f"joint_states malformed: {problem[0]}", f"joint_states rejected: {problem[1]}"
            ),
        )
    try:
        i = list(names).index(name)
    except ValueError:
        return JointReading({}, f"no joint {name!r}")
    values: dict[str, object] = {}
    if velocities:
        values["speed"] = velocities[i]
    if positions:
        theta = _real(positions[i])
        values["nut"] = (
            positions[i]
            if theta is None
            # else the nut check names it
            else (joints.nut_position_at_zero_angle_m + theta * lead_per_rad_m)
        )
    if not values:
        return JointReading({}, f"joint {name!r} without position or velocity")
    return JointReading(values)


def _malformed(names: list, positions: int, velocities: int) -> tuple[str, str] | None:
    """(reason, message) when a JointState's names and arrays do not pair up, else None."""
    if not names:
        return "no names", f"no joint names ({positions} positions, {velocities} velocities)"
    repeated = sorted({str(n) for n in names if names.count(n) > 1})
    if repeated:
        return "a name twice", f"joint name(s) {', '.join(map(repr, repeated))} given twice"
    if positions not in (0, len(names)) or velocities not in (0, len(names)):
        return (
            "array lengths differ",
            f"{len(names)} names but {positions} positions and "
            f"{velocities} velocities (each empty or one per name)",
        )
    return None


def _is_real(value: object) -> TypeGuard[numbers.Real]:
    """A real number, not a bool (numpy scalars included)."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def _real(value: object) -> float | None:
    """`value` as a float if it is a real number (not a bool) within the float range, else
    None."""
    if type(value) is float:  # the common case, per input message: no ABC check
        return value
    if not _is_real(value):
        return None
    try:
        return float(value)
    except OverflowError:  # an int beyond the float range
        return None


class SampleOrder:
    """Per input topic, the sample time [ns] of the last message taken: which messages are
    stale (earlier than it), in the node and in the replay alike."""

    def __init__(self) -> None:
        self.last: dict[str, int] = {}

    def step_back_ns(self, topic: str, t_ns: int) -> int | None:
        """How far sample time `t_ns` on `topic` is behind the last one taken there [ns]:
        None when it is later (or the first; it becomes the last), 0 for the same time (taken),
        > 0 for a stale sample (not taken; the last one stays)."""
        last = self.last.get(topic)
        if last is not None and t_ns <= last:
            return last - t_ns
        self.last[topic] = t_ns
        return None


class InputRules:
    """Latest accepted inputs, the point last computed and where the contact is integrated.

    Parameters
    ----------
    params : ScrewParameters
        Nut travel, lead per radian and the default nut position.
    live : LiveSettings
        The deadbands.
    joints : JointSettings
        The screw joint of JointState messages (may be replaced at any time: the node reads it
        from its parameters).
    """

    def __init__(
        self,
        params: ScrewParameters,
        live: LiveSettings = LiveSettings(),
        joints: JointSettings = JointSettings(),
    ):
        self.params, self.live, self.joints = params, live, joints
        self.inputs = Inputs()
        self.errors: dict[str, Rejection] = {}  # input -> its latest value's rejection,
        #                                                 until a good value arrives
        self.computed_at: Point | None = None  # the point last computed
        self.contact_nut_m = params.nut_position_m  # where the contact is integrated

    def reset(self, params: ScrewParameters, live: LiveSettings) -> None:
        """New parameters or settings: the next point is computed whatever it is, with the
        contact at the parameters' nut position until the nut moves beyond the deadband.

        Parameters
        ----------
        params : ScrewParameters
            The new parameters.
        live : LiveSettings
            The new deadbands.
        """
        self.params, self.live = params, live
        self.computed_at, self.contact_nut_m = None, params.nut_position_m

    # ---------------------------------------------------------------- single values
    def set_speed(self, value: object) -> Outcome:
        """Take a speed.

        Parameters
        ----------
        value : object
            Speed Omega [rad/s], as received.

        Returns
        -------
        Outcome
            What was taken, and what was rejected and why.
        """
        return self._operating_value("speed", value)

    def set_load(self, value: object) -> Outcome:
        """Take an axial load.

        Parameters
        ----------
        value : object
            Axial load F_z [N], as received.

        Returns
        -------
        Outcome
            What was taken, and what was rejected and why.
        """
        return self._operating_value("load", value)

    def set_nut_position(self, value: object) -> Outcome:
        """Take a nut position.

        Parameters
        ----------
        value : object
            Nut position z_o [m], 0 <= z_o <= nut_travel_m, as received.

        Returns
        -------
        Outcome
            What was taken, and what was rejected and why.
        """
        z, travel = _real(value), self.params.nut_travel_m
        if z is None:
            return self._reject(
                "nut",
                Rejection("nut position not a number", f"nut position {value!r} is not a number"),
            )
        if not math.isfinite(z):  # not 'nan m is off the screw'
            return self._reject(
                "nut",
                Rejection("nut position not finite", f"nut position {z} m is not a finite number"),
            )
        if not 0.0 <= z <= travel:
            return self._reject(
                "nut",
                Rejection(
                    f"nut position off the screw [0, {exact(travel)}] m",
                    f"nut position {exact(z)} m is off the screw: allowed [0, {exact(travel)}] m "
                    f"(z_o + b <= L)",
                ),
            )
        self.inputs.nut_position_m = z
        return self._taken("nut")

    def missing(self, kind: str, path: str, detail: str) -> Outcome:
        """A message of input `kind` ('speed', 'load', 'nut') without the number at its field
        path `path` (an index beyond an array of that message): rejected as a bad value is,
        the previous good one stays.

        Parameters
        ----------
        kind : str
            The input.
        path : str
            Its field path.
        detail : str
            What the message lacks, one line.

        Returns
        -------
        Outcome
            The rejection.
        """
        return self._reject(
            kind,
            Rejection(f"{kind} field {path} not in the message", f"{kind} field {path}: {detail}"),
        )

    def _operating_value(self, kind: str, value: object) -> Outcome:
        try:
            if kind == "speed":
                self.inputs.speed_rad_s, _ = check_operating_point(value, 0.0)
            else:
                _, self.inputs.load_n = check_operating_point(0.0, value)
        except OperatingPointError as exc:
            v = _real(value)  # None also for an int beyond the floats
            reason = (
                f"{kind} not a number"
                if not _is_real(value)
                else f"{kind} not finite"
                if v is None or not math.isfinite(v)
                else f"load beyond {exact(_LOAD_LIMIT_N)} N"
            )
            return self._reject(kind, Rejection(reason, str(exc)))
        return self._taken(kind)

    def _taken(self, kind: str) -> Outcome:
        if self.errors:
            self.errors.pop(kind, None)
        return _TAKEN[kind]

    def _reject(self, kind: str, rejection: Rejection) -> Outcome:
        self.errors[kind] = rejection
        return Outcome(rejected=(rejection,))

    # ---------------------------------------------------------------- JointState
    def set_joint_state(
        self, names: Sequence[str], positions: Sequence[float], velocities: Sequence[float]
    ) -> Outcome:
        """Take the screw joint's speed and nut position (both before any recompute decision);
        ignored without `joints.joint_name` or without that joint.

        Parameters
        ----------
        names : sequence of str
            Joint names of the JointState.
        positions, velocities : sequence of float
            Its angles [rad] and speeds [rad/s] (either may be empty).

        Returns
        -------
        Outcome
            What was taken, and what was rejected or ignored and why.
        """
        reading = read_joint_state(
            names, positions, velocities, self.joints, self.params.lead_per_rad_m
        )
        if reading.ignored:
            return Outcome(ignored=reading.ignored)
        if reading.rejected:
            return self._reject("joint_states", reading.rejected)
        self.errors.pop("joint_states", None)  # a well-formed one ends that error
        setters = {"speed": self.set_speed, "nut": self.set_nut_position}
        outcomes = [setters[kind](value) for kind, value in reading.values.items()]
        return Outcome(
            tuple(k for o in outcomes for k in o.taken),
            tuple(r for o in outcomes for r in o.rejected),
        )

    # ---------------------------------------------------------------- operating point
    @property
    def nut_measured(self) -> bool:
        """A nut input was taken (else the nut is the parameters' nut_position_m)."""
        return self.inputs.nut_position_m is not None

    @property
    def nut_position_m(self) -> float:
        """The nut position in use [m]: the latest taken, else the parameters' one."""
        nut = self.inputs.nut_position_m
        return self.params.nut_position_m if nut is None else nut

    def point(self) -> Point | None:
        """The operating point at the latest inputs.

        Returns
        -------
        Point or None
            (speed, load, nut); None before a speed and a load.
        """
        i = self.inputs
        if i.speed_rad_s is None or i.load_n is None:
            return None
        return i.speed_rad_s, i.load_n, self.nut_position_m

    def changed(self) -> bool:
        """Whether there is a point and it moved beyond a deadband since the last `compute`
        (or none was computed yet).

        Returns
        -------
        bool
            True: a recompute would give something new.
        """
        point = self.point()
        return point is not None and (
            self.computed_at is None or moved(point, self.computed_at, self.live)
        )

    def compute(self) -> tuple[Point, float] | None:
        """Mark the current point as computed.

        Returns
        -------
        tuple of (Point, float) or None
            The point and the nut position [m] the contact is integrated at for it (moved only
            beyond nut_deadband_m); None without a point.
        """
        point = self.point()
        if point is None:
            return None
        self.computed_at = point
        if abs(point[2] - self.contact_nut_m) > self.live.nut_deadband_m:
            self.contact_nut_m = point[2]
        return point, self.contact_nut_m
