# SPDX-License-Identifier: Apache-2.0
"""The `leadscrew_ros` MCAP Metadata record round-trips through a real MCAP file."""

import pytest
from mcap.writer import Writer

from leadscrew_ros.bag import logmeta
from leadscrew_ros.model.physics.parameters import ParameterError, ScrewParameters


def _write(path, records):
    with open(path, "wb") as f:
        w = Writer(f)
        w.start("ros2", "test")
        for name, data in records:
            w.add_metadata(name, data)
        w.finish()


def test_round_trip(tmp_path):
    params = ScrewParameters().with_(formulation="consistent", nut_position_m=0.05)
    meta = logmeta.LogMetadata(
        params.as_dict(),
        {"mu_static": 0.05, "samples": 1024},
        {"min_interval_s": 0.01},
        unit_id="seat-7",
        hardware_id="hw",
    )
    path = tmp_path / "a.mcap"
    _write(path, [("other", {"x": "1"}), (logmeta.RECORD_NAME, meta.record())])
    back = logmeta.read(path)
    assert back == meta
    assert back.formulation == "consistent"
    assert back.screw_parameters() == params


def test_foreign_and_broken(tmp_path):
    path = tmp_path / "b.mcap"
    _write(path, [("other", {"x": "1"})])
    assert logmeta.read(path) is None
    _write(path, [(logmeta.RECORD_NAME, {"model_parameters": "{not json"})])
    with pytest.raises(ValueError, match="not readable"):
        logmeta.read(path)
    bad = logmeta.LogMetadata({"radius_m": "nan"})
    with pytest.raises(ParameterError):
        bad.screw_parameters()
