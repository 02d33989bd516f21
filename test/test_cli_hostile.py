# SPDX-License-Identifier: Apache-2.0
"""Hostile arguments to every command of `leadscrew-squeak` and to `squeak_node`: each is one
line `<program>: error: <message>` and exit code 2 (or exit 0 where the input is valid),
never a traceback (issue 19)."""

import os
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import pytest

from leadscrew_ros.cli import main

REPO = Path(__file__).resolve().parents[1]


def png_bytes() -> bytes:
    """A valid 1 x 1 PNG: binary, not UTF-8, not YAML, not MCAP."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data)))
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", 1, 1, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(b"\x00\x00\x00\x00")) + chunk(b"IEND", b""))


@pytest.fixture
def files(tmp_path):
    """Hostile input files: a PNG, an empty file, a directory."""
    (tmp_path / "picture.png").write_bytes(png_bytes())
    (tmp_path / "empty.yaml").write_bytes(b"")
    (tmp_path / "folder").mkdir()
    return tmp_path


def assert_one_error_line(err: str, program: str = "leadscrew-squeak") -> None:
    assert "Traceback" not in err, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"{program}: error: "), err


# ----------------------------------------------------------------------------- squeak_node
NODE_ARGS = {
    "missing params file": (["--params-file", "{d}/nonexistent.yaml"], "Error opening YAML file"),
    "PNG params file": (["--params-file", "{d}/picture.png"], "Couldn't parse params file"),
    "bad namespace": (["-r", "__ns:=bad//ns"], "Namespace not remapped to a fully qualified"),
    "unknown ROS argument": (["--bogus"], "unknown ROS arguments ['--bogus']"),
}


@pytest.mark.parametrize("ros_args, words", NODE_ARGS.values(), ids=NODE_ARGS.keys())
def test_squeak_node_rejects_bad_ros_arguments_in_one_line(capfd, files, ros_args, words):
    """In-process: rcl refuses them before any node exists (remove_ros_args or init)."""
    from leadscrew_ros.ros.node import NODE_NAME, main as node_main
    code = node_main(["squeak_node", "--ros-args", *(a.format(d=files) for a in ros_args)])
    out, err = capfd.readouterr()
    assert code == 2 and not out
    assert_one_error_line(err, NODE_NAME)
    assert words in err


def test_squeak_node_process_with_a_missing_params_file_exits_2_in_one_line(files):
    """The console script itself (it was RCLInvalidROSArgsError's traceback, exit 1)."""
    from leadscrew_ros.ros.node import NODE_NAME
    script = Path(sys.executable).with_name("squeak_node")
    command = [str(script)] if script.exists() else [sys.executable, "-m",
                                                     "leadscrew_ros.ros.node"]
    proc = subprocess.run([*command, "--ros-args", "--params-file", str(files / "none.yaml")],
                          capture_output=True, text=True, timeout=60, env=dict(os.environ))
    assert proc.returncode == 2, proc.stderr
    assert_one_error_line(proc.stderr, NODE_NAME)
