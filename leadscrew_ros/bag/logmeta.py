# SPDX-License-Identifier: Apache-2.0
"""The `leadscrew_ros` MCAP Metadata record: what a recording was made with.

A node's recording carries one Metadata record named `leadscrew_ros` (MCAP metadata is a
string -> string map) in every file: the package version, the formulation, every model
parameter, the scatter behind P(squeak), every node parameter, the hardware id and the unit id,
as they were when the file was opened (the node starts a new file when they change). A fleet
review reads the unit id from it and, asked to, predicts each log with the log's own
parameters. A replay's annotated log carries the input log's record unchanged and one named
`leadscrew_ros.replay` with the same keys: the replay's model, scatter and input settings.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from leadscrew_ros import __version__
from leadscrew_ros.model.physics.parameters import ParameterError, ScrewParameters, coerce

RECORD_NAME = "leadscrew_ros"
REPLAY_RECORD_NAME = "leadscrew_ros.replay"


@dataclass(frozen=True)
class LogMetadata:
    """What a recording was made with.

    Attributes
    ----------
    params : dict
        Every `ScrewParameters` field (SI units) -> value, including `formulation`.
    scatter : dict
        Scattered parameter -> relative SD (`Scatter.sd`), and `samples` -> sample count.
    node : dict
        Every other node parameter (ROS name -> value).
    unit_id : str
        The drive's identity ('' when not set).
    hardware_id : str
        The node's diagnostics hardware id.
    version : str
        Package version that wrote the record.
    """

    params: dict[str, Any]
    scatter: dict[str, float] = field(default_factory=dict)
    node: dict[str, Any] = field(default_factory=dict)
    unit_id: str = ""
    hardware_id: str = ""
    version: str = __version__

    @property
    def formulation(self) -> str:
        """The parameter formulation recorded ('' if none)."""
        return str(self.params.get("formulation", ""))

    def record(self) -> dict[str, str]:
        """The MCAP Metadata map (string values; dicts as JSON)."""
        return {
            "package_version": self.version,
            "formulation": self.formulation,
            "unit_id": self.unit_id,
            "hardware_id": self.hardware_id,
            "model_parameters": json.dumps(self.params, sort_keys=True),
            "scatter": json.dumps(self.scatter, sort_keys=True),
            "node_parameters": json.dumps(self.node, sort_keys=True),
        }

    @classmethod
    def from_record(cls, record: Mapping[str, str]) -> LogMetadata:
        """Parse a Metadata map; ValueError (one line) when it is not a valid record."""
        try:
            params = json.loads(record["model_parameters"])
            scatter = json.loads(record.get("scatter", "{}"))
            node = json.loads(record.get("node_parameters", "{}"))
        except (KeyError, TypeError, json.JSONDecodeError) as exc:
            raise ValueError(f"metadata '{RECORD_NAME}' is not readable: {exc}") from None
        if not all(isinstance(d, dict) for d in (params, scatter, node)):
            raise ValueError(f"metadata '{RECORD_NAME}': parameters are not JSON objects")
        return cls(
            params,
            scatter,
            node,
            str(record.get("unit_id", "")),
            str(record.get("hardware_id", "")),
            str(record.get("package_version", "")),
        )

    def screw_parameters(self) -> ScrewParameters:
        """The recorded model parameters (unknown names ignored: a newer writer); ParameterError
        when a value is invalid."""
        known = set(ScrewParameters.__dataclass_fields__)
        values = {k: coerce(k, v) for k, v in self.params.items() if k in known}
        try:
            return ScrewParameters(**values)
        except TypeError as exc:
            raise ParameterError(f"recorded parameters: {exc}") from None


def read_record(path: Path | str, name: str = RECORD_NAME) -> dict[str, str] | None:
    """The first Metadata record `name` of one MCAP file as it is stored (string -> string),
    or None when it has none. A file cut off by a crash (no summary) is read from its start as
    far as it goes: the recorder writes the record right after the header. Raises ValueError
    when the file's metadata cannot be read, OSError when the file cannot be opened."""
    from mcap.reader import make_reader
    from mcap.records import Metadata
    from mcap.stream_reader import StreamReader

    with open(path, "rb") as stream:
        try:
            records = list(make_reader(stream).iter_metadata())
        except Exception as exc:  # the mcap reader raises several unrelated types
            error = ValueError(f"{Path(path).name}: metadata not readable: {exc}")
            stream.seek(0)
            records = []
            try:
                for record in StreamReader(stream, emit_chunks=True).records:
                    if isinstance(record, Metadata):
                        records.append(record)
            except Exception:  # where the cut-off file ends
                pass
            if not any(rec.name == name for rec in records):
                raise error from None
    return next((dict(rec.metadata) for rec in records if rec.name == name), None)


def read(path: Path | str, name: str = RECORD_NAME) -> LogMetadata | None:
    """The `leadscrew_ros` record (or another of its form, e.g. `REPLAY_RECORD_NAME`) of one
    MCAP file, or None when it has none (a foreign or an older recording). Raises ValueError
    when the record is there but unreadable, OSError when the file cannot be read."""
    record = read_record(path, name)
    return None if record is None else LogMetadata.from_record(record)
