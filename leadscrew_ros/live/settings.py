# SPDX-License-Identifier: Apache-2.0
"""Settings of the live predictor, declared once: default, unit, range and description are the
field metadata (`model.physics.metadata.setting`), from which the node's parameter descriptors, the
YAML config, the replay's CLI help and the README tables are made.

`LiveSettings` is the recompute policy and the verdict; `JointSettings` says how a
sensor_msgs/JointState maps to speed and nut position. The node and the offline replay use both.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..model.physics.metadata import check, documented, setting


@documented
@dataclass(frozen=True)
class LiveSettings:
    """When to recompute and what the verdict says (SI units; see the field metadata)."""

    speed_deadband_rad_s: float = setting(
        0.1, "rad/s", "recompute when the speed moved more than this", 0.0, 1000.0
    )
    load_deadband_n: float = setting(
        1.0, "N", "recompute when the load moved more than this", 0.0, 1e5
    )
    nut_deadband_m: float = setting(
        0.0005, "m", "re-integrate the contact when the nut moved more than this", 0.0, 1.0
    )
    max_rate_hz: float = setting(
        100.0, "Hz", "maximum recompute rate (bursts are coalesced)", 0.1, 10000.0
    )
    warn_probability: float = setting(
        0.1, "1", "diagnostic WARN at or above this P(squeak)", 0.0, 1.0
    )
    error_probability: float = setting(
        0.5, "1", "diagnostic ERROR at or above this P(squeak)", 0.0, 1.0
    )
    safe_probability: float = setting(
        0.01,
        "1",
        "squeak/safe_speed: nearest speed whose P(squeak) is below this",
        0.0,
        1.0,
        lo_open=True,
    )
    stale_timeout_s: float = setting(
        1.0, "s", "diagnostic STALE when speed or load is older than this", 0.01, 3600.0
    )
    safe_speed_margin: float = setting(
        0.05, "1", "relative distance kept from a squeak band edge by squeak/safe_speed", 0.0, 0.5
    )

    def __post_init__(self) -> None:
        check(self)
        if self.warn_probability > self.error_probability:
            raise ValueError(
                f"warn_probability = {self.warn_probability:g} exceeds "
                f"error_probability = {self.error_probability:g}"
            )


@documented
@dataclass(frozen=True)
class JointSettings:
    """Which joint of sensor_msgs/JointState is the screw, and where the nut is at angle 0.

    An empty `joint_name` (the default) ignores joint_states altogether, in the node and in the
    offline replay alike (which counts them as ignored): using a JointState is an explicit
    opt-in, so one from another driver never moves the operating point. With a name, the
    joint's velocity is the speed and its angle theta gives the nut position
    `nut_position_at_zero_angle_m + theta * ScrewParameters.lead_per_rad_m` (`live.rules`).
    """

    joint_name: str = setting("", "", "screw joint in joint_states ('' ignores joint_states)")
    nut_position_at_zero_angle_m: float = setting(
        0.15,
        "m",
        "nut position when the screw joint angle is 0; the nut travels R tan(beta) per radian",
        -100.0,
        100.0,
    )

    def __post_init__(self) -> None:
        check(self)


@documented
@dataclass(frozen=True)
class ListenSettings:
    """The optional microphone input: whether the node listens, how the sound is taken and
    over which window the measurement status compares what was heard with what was predicted
    (the detector's own settings are `model.acoustics.DetectorSettings`, `listen.*` too)."""

    enabled: bool = setting(
        False,
        "",
        "subscribe to microphone and publish squeak/heard, squeak/heard_frequency "
        "and the measurement status",
        read_only=True,
    )
    sample_rate_hz: float = setting(
        48000.0,
        "Hz",
        "sample rate of the std_msgs/Float32MultiArray chunks on microphone "
        "(the message carries none)",
        1000.0,
        1e6,
    )
    window_s: float = setting(
        2.0,
        "s",
        "the measurement status compares heard and predicted squeak over this "
        "window; STALE when no sound arrived for as long",
        0.1,
        600.0,
    )
    scale_pa: float = setting(
        0.0,
        "Pa",
        "sound pressure of a full-scale sample (calibrated microphone: levels in "
        "dB SPL); 0: not calibrated",
        0.0,
        1e6,
    )
    queue_chunks: int = setting(
        64,
        "1",
        "chunks waiting for the analysis thread; a chunk arriving when it is full "
        "is dropped and counted",
        1,
        100000,
    )

    def __post_init__(self) -> None:
        check(self)


@documented
@dataclass(frozen=True)
class InputField:
    """Where an input's number is in the messages of its topic: the input is `scale` times the
    number at the path `field` in a message of type `type` (`bag.fieldpath`; the path is
    checked against the type's definition when the node starts or the parameter is set).

    A message whose type has a std_msgs/Header `header` is ordered by its header stamp (one
    older than the last taken on that input is stale and not taken; a zero stamp counts as
    none), else by its arrival (the node) or its log time (the replay).
    """

    type: str = setting(
        "std_msgs/msg/Float64",
        "",
        "message type of the input topic, pkg/msg/Type (any installed message type)",
        read_only=True,
    )
    field: str = setting(
        "data",
        "",
        "path of the number in the message, e.g. data, twist.twist.angular.z, velocity[2]",
    )
    scale: float = setting(
        1.0,
        "1",
        "factor from the field's unit to the input's SI unit (rpm to rad/s: 0.10472; a gear "
        "ratio; negative reverses the direction)",
        -1e6,
        1e6,
    )

    def __post_init__(self) -> None:
        check(self)
        for name in ("type", "field"):
            if not getattr(self, name).strip():
                raise ValueError(f"{name} must not be empty")
        if self.scale == 0.0:
            raise ValueError("scale must not be 0")


@documented
@dataclass(frozen=True)
class SpeedInput(InputField):
    """The speed input (motor_speed) [rad/s]."""


@documented
@dataclass(frozen=True)
class LoadInput(InputField):
    """The axial load input (axial_load) [N]."""


@documented
@dataclass(frozen=True)
class NutInput(InputField):
    """The nut position input (nut_position) [m]."""


# Input -> its settings class (node parameters `inputs.<input>.<field>`, replay options
# `--<input>-field`, `--<input>-scale`, `InputSettings.<input>_field`, ...).
INPUT_FIELDS: dict[str, type[InputField]] = {
    "speed": SpeedInput,
    "load": LoadInput,
    "nut": NutInput,
}
INPUTS_PREFIX = "inputs."
