# SPDX-License-Identifier: Apache-2.0
"""Hostile arguments to every command of `leadscrew-squeak` and to `squeak_node`: each is one
line `<program>: error: <message>` and exit code 2 (or exit 0 where the input is valid),
never a traceback (issue 19)."""

import json
import os
import struct
import subprocess
import sys
import time
import zlib
from pathlib import Path

import pytest

from leadscrew_ros.bag.synthetic import DutyCycle, write_log
from leadscrew_ros.cli import main

REPO = Path(__file__).resolve().parents[1]


def png_bytes() -> bytes:
    """A valid 1 x 1 PNG: binary, not UTF-8, not YAML, not MCAP."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (
            struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
        )

    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", struct.pack(">IIBBBBB", 1, 1, 8, 2, 0, 0, 0))
        + chunk(b"IDAT", zlib.compress(b"\x00\x00\x00\x00"))
        + chunk(b"IEND", b"")
    )


def make_files(d: Path) -> Path:
    """Hostile input files in `d`: a PNG, an empty file, an empty directory; and one small
    valid log (a bag directory), for the options that need one."""
    (d / "picture.png").write_bytes(png_bytes())
    (d / "empty.yaml").write_bytes(b"")
    (d / "folder").mkdir()
    bag = write_log(DutyCycle(duration_s=2.0, rate_hz=20.0, rest_s=0.5), d / "logs")
    bag.rename(d / "logs" / "bag")
    return d


@pytest.fixture
def files(tmp_path):
    return make_files(tmp_path)


@pytest.fixture(scope="module")
def table_files(tmp_path_factory):
    return make_files(tmp_path_factory.mktemp("hostile"))


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
    from leadscrew_ros.ros.node import PROG
    from leadscrew_ros.ros.node import main as node_main

    code = node_main(["squeak_node", "--ros-args", *(a.format(d=files) for a in ros_args)])
    out, err = capfd.readouterr()
    assert code == 2 and not out
    assert_one_error_line(err, PROG)
    assert words in err


def test_squeak_node_process_with_a_missing_params_file_exits_2_in_one_line(files):
    """The console script itself (it was RCLInvalidROSArgsError's traceback, exit 1)."""
    from leadscrew_ros.ros.node import PROG

    script = Path(sys.executable).with_name("squeak_node")
    command = [str(script)] if script.exists() else [sys.executable, "-m", "leadscrew_ros.ros.node"]
    proc = subprocess.run(
        [*command, "--ros-args", "--params-file", str(files / "none.yaml")],
        capture_output=True,
        text=True,
        timeout=60,
        env=dict(os.environ),
    )
    assert proc.returncode == 2, proc.stderr
    assert_one_error_line(proc.stderr, PROG)


# ----------------------------------------------------------------------------- every command
# argv ({d}: the folder of `make_files`; LOG: its valid bag) -> the exit code: 2, or 0 where
# the input is valid. Long computations are kept cheap (--quick, tiny durations, few modes).
LOG = "{d}/logs/bag"
NUMBERS = {"nan": "nan", "inf": "inf", "-inf": "-inf", "huge": "1e308"}
PARAMS_FILES = {
    "missing file": "{d}/missing.yaml",
    "directory": "{d}/folder",
    "PNG": "{d}/picture.png",
    "empty file": "{d}/empty.yaml",
}
CASES = [
    # model options, through the cheapest model command
    *[(["modes", "--param", f"radius_m={v}"], 2) for v in (*NUMBERS.values(), "-1", "0")],
    *[(["modes", "--params-file", f], 2) for f in PARAMS_FILES.values()],
    (["modes", "--param", "n_bending=2.5"], 2),
    (["modes", "--param", "n_bending=nan"], 2),
    (["modes", "--samples", "0"], 2),
    (["modes", "--samples", "-8"], 2),
    (["modes", "--scatter", "mu_kinetic=nan"], 2),
    (["modes", "--scatter", "mu_kinetic=-1"], 2),
    (["modes", "--formulation", "bogus"], 2),
    # predict
    *[(["predict", "--speed", v], 2) for v in ("nan", "inf", "-inf", "abc")],
    *[(["predict", "--speed", "20", "--load", v], 2) for v in ("nan", "-inf", "1e308", "-1e8")],
    *[(["predict", "--speed", "20", "--params-file", f], 2) for f in PARAMS_FILES.values()],
    (["predict", "--speed", "-20", "--scatter", "none"], 0),  # reverse rotation
    (["predict", "--speed", "20", "--load", "-1e7", "--scatter", "none"], 0),  # other flank
    (["predict", "--speed", "0", "--scatter", "none"], 0),  # valid: "no prediction: ..."
    (["predict", "--speed", "1e308", "--scatter", "none"], 0),  # above the critical speed
    # sweep
    *[
        (["sweep", "--speed", spec], 2)
        for spec in ("nan:1:3", "1:inf:3", "-inf:1:3", "1:2:0", "1:2:-5", "1:2:1e9", "1:1:3", "1:2")
    ],
    (["sweep", "--speed", "0.5:120:3", "--plot", "out.txt"], 2),
    (["sweep", "--speed", "0.5:120:3", "--plot", "{d}/folder"], 2),
    (["sweep", "--speed", "0.5:120:3", "--plot", "{d}/missing/s.png"], 2),
    (["sweep", "--speed", "0.5:120:3", "--load", "-inf"], 2),
    (["sweep", "--axis", "n_bending", "--values", "2:4:5", "--speed", "20"], 2),
    (["sweep", "--axis", "n_bending", "--values", "2.5:4", "--speed", "20"], 2),
    (["sweep", "--axis", "bogus", "--values", "1:2:3"], 2),
    (["sweep", "--speed", "-10:-1:3", "--load", "-200", "--scatter", "none"], 0),
    # map
    (["map", "--x", "speed_rad_s:nan:1:3", "--y", "load_n:5:600:3"], 2),
    (["map", "--x", "speed_rad_s:1:100:3", "--y", "load_n:5:600:3", "--plot", "out.txt"], 2),
    (["map", "--x", "speed_rad_s:1:100:3", "--y", "speed_rad_s:5:600:3"], 2),
    (["map", "--x", "load_n:1:100:3", "--y", "radius_m:0.003:0.01:3", "--speed", "-inf"], 2),
    (["map", "--x", "speed_rad_s:1:100:100000", "--y", "load_n:5:600:100000"], 2),
    # figures
    (["figures", "--out", "{d}/picture.png", "--quick"], 2),
    (["figures", "--out", "{d}/f", "--quick", "--param", "radius_m=nan"], 2),
    # transient
    *[
        (["transient", "--speed", v, "--duration", "0.006"], 2)
        for v in ("nan", "inf", "-inf", "1e308", "1e-300", "-1e-300", "0")
    ],
    *[
        (["transient", "--speed", "20", "--duration", v], 2)
        for v in ("nan", "-1", "0", "1e308", "1e-300")
    ],
    (["transient", "--speed", "20", "--load", "1e308", "--duration", "0.006"], 2),
    (["transient", "--speed", "20", "--modes", "-1", "--duration", "0.006"], 2),
    (["transient", "--speed", "20", "--regularisation", "-1", "--duration", "0.006"], 2),
    (["transient", "--speed", "20", "--seed", "-1", "--duration", "0.006"], 2),
    (["transient", "--speed", "20", "--duration", "0.006", "--plot", "out.txt"], 2),
    (["transient", "--speed", "20", "--duration", "0.006", "--wav", "out.txt"], 2),
    (["transient", "--speed", "20", "--duration", "0.006", "--wav", "{d}/folder"], 2),
    (["transient", "--speed", "-20", "--duration", "0.003", "--modes", "4"], 0),
    # demo, simulate (rcl refuses the ROS arguments before anything runs)
    *[(["demo", "--duration", v], 2) for v in ("nan", "inf", "-1", "0", "1e308")],
    (["demo", "--record-dir", "{d}/picture.png", "--duration", "1"], 2),
    *[(["simulate", "--duration", v], 2) for v in ("nan", "-inf", "-1", "1e308")],
    *[(["simulate", "--rate", v], 2) for v in ("nan", "inf", "-inf", "0", "-5", "1e308")],
    (["simulate", "--ros-args", "-r", "__ns:=bad//ns"], 2),
    *[
        (["simulate", "--ros-args", "--params-file", f], 2)
        for f in ("{d}/missing.yaml", "{d}/picture.png", "{d}/folder")
    ],
    (["modes", "--ros-args", "-r", "__ns:=/x"], 2),
    # replay (offline)
    *[(["replay", f, "--out", "{d}/r"], 2) for f in PARAMS_FILES.values()],
    (["replay", LOG, "--out", "{d}/picture.png"], 2),
    (["replay", LOG, "--out", "{d}/r", "--params-file", "{d}/picture.png"], 2),
    *[
        (["replay", LOG, "--out", "{d}/r", option, v], 2)
        for option in ("--speed-deadband", "--warn-probability", "--nut-deadband")
        for v in ("nan", "-inf", "-1", "1e308")
    ],
    *[(["replay", LOG, "--out", "{d}/r", "--load", v], 2) for v in ("nan", "-inf", "1e308")],
    (["replay", LOG, "--out", "{d}/r", "--episodes", "-1"], 2),
    (["replay", LOG, "--out", "{d}/r", "--workers", "-1"], 2),
    (["replay", LOG, "--out", "{d}/r", "--namespace", "bad//ns"], 2),
    (["replay", LOG, "--out", "{d}/r", "--rate", "2"], 2),  # needs --publish
    # replay --publish
    *[(["replay", f, "--publish", "--no-wait"], 2) for f in PARAMS_FILES.values()],
    *[
        (["replay", LOG, "--publish", "--no-wait", "--rate", v], 2)
        for v in ("nan", "inf", "-inf", "0", "-1")
    ],
    *[
        (["replay", LOG, "--publish", "--no-wait", "--start-offset", v], 2)
        for v in ("nan", "-1", "1e308")
    ],
    (["replay", LOG, "--publish", "--no-wait", "--remap", "bogus"], 2),
    (["replay", LOG, "--publish", "--no-wait", "--topics", "/nope"], 2),
    (["replay", LOG, "--publish", "--no-wait", "--out", "{d}/r"], 2),
    (["replay", LOG, "--publish", "--no-wait", "--ros-args", "-r", "__ns:=bad//ns"], 2),
    (
        ["replay", LOG, "--publish", "--no-wait", "--ros-args", "--params-file", "{d}/picture.png"],
        2,
    ),
    # info, recover
    *[(["info", f], 2) for f in PARAMS_FILES.values()],
    *[(["recover", f], 2) for f in ("{d}/missing.yaml", "{d}/picture.png", "{d}/empty.yaml")],
    (["recover", "{d}/folder"], 0),  # "nothing to recover": valid
    (["recover", LOG, "-o", "{d}/out.txt"], 2),
    (["recover", LOG, "-o", "{d}/r.mcap"], 2),  # -o is for one file
    # review (the table's scheduler never exists: the probe fails fast)
    (["review", "{d}/missing", "--out", "{d}/v"], 2),
    (["review", "{d}/folder", "--out", "{d}/v"], 2),
    (["review", "{d}/logs", "--out", "{d}/picture.png"], 2),
    *[(["review", "{d}/logs", "--out", "{d}/v", "--workers", v], 2) for v in ("0", "-1", "1e9")],
    *[
        (["review", "{d}/logs", "--out", "{d}/v", "--scheduler", a], 2)
        for a in ("garbage", "foo://x:1", "tcp://127.0.0.1", "tcp://127.0.0.1:99999")
    ],
    (
        [
            "review",
            "{d}/logs",
            "--out",
            "{d}/v",
            "--scheduler",
            "tcp://127.0.0.1:1",
            "--connect-timeout",
            "0.2",
        ],
        2,
    ),
    *[
        (
            [
                "review",
                "{d}/logs",
                "--out",
                "{d}/v",
                "--scheduler",
                "tcp://127.0.0.1:1",
                "--connect-timeout",
                v,
            ],
            2,
        )
        for v in ("nan", "-1", "0", "1e308")
    ],
    (["review", "{d}/logs", "--out", "{d}/v", "--connect-timeout", "1"], 2),
    (["review", "{d}/logs", "--out", "{d}/v", "--warn-probability", "nan"], 2),
    (["review", "{d}/logs", "--out", "{d}/v", "--use-log-params", "--param", "radius_m=1"], 2),
    # calibrate (refused before any work, but the log without sound: after its replay)
    (["calibrate", "{d}/missing", "--out", "{d}/k"], 2),
    (["calibrate", "{d}/folder", "--out", "{d}/k"], 2),
    (["calibrate", LOG, "--out", "{d}/picture.png"], 2),
    (["calibrate", LOG, "--out", "{d}/k", "--workers", "1"], 2),  # no sound: nothing to learn from
    *[
        (["calibrate", LOG, "--out", "{d}/k", "--holdout", v], 2)
        for v in ("1.5", "1", "-0.1", "nan")
    ],
    *[
        (["calibrate", LOG, "--out", "{d}/k", option, v], 2)
        for option in ("--false-alarm", "--miss", "--prior-widen", "--speed-step-rad-s")
        for v in ("nan", "inf", "-1", "0.5e308")
    ],
    *[(["calibrate", LOG, "--out", "{d}/k", "--steps", v], 2) for v in ("-1", "2.5", "nan")],
    (["calibrate", LOG, "--out", "{d}/k", "--steps", "100", "--burn", "100"], 2),
    (["calibrate", LOG, "--out", "{d}/k", "--walkers", "33"], 2),
    *[
        (["calibrate", LOG, "--out", "{d}/k", "--calibrate", n], 2)
        for n in ("radius", "nut_position_m", "formulation")
    ],
    (
        [
            "calibrate",
            LOG,
            "--out",
            "{d}/k",
            "--calibrate",
            "mu_static",
            "--calibrate",
            "mu_static",
        ],
        2,
    ),
    (["calibrate", LOG, "--out", "{d}/k", "--formulation", "bogus"], 2),
    (["calibrate", LOG, "--out", "{d}/k", "--scatter", "mu_static=nan"], 2),
    (["calibrate", LOG, "--out", "{d}/k", "--param", "mu_static=nan"], 2),
    (["calibrate", LOG, "--out", "{d}/k", "--params-file", "{d}/picture.png"], 2),
    (["calibrate", LOG, "--out", "{d}/k", "--connect-timeout", "1"], 2),
    (["calibrate", LOG, "--out", "{d}/k", "--scheduler", "tcp://127.0.0.1"], 2),
    (["calibrate", LOG, "--out", "{d}/k", "--workers", "0"], 2),
]


@pytest.mark.parametrize("argv, code", CASES, ids=[" ".join(a) for a, _ in CASES])
def test_hostile_arguments_are_one_error_line_or_valid(capsys, table_files, argv, code):
    got = main([a.format(d=table_files) for a in argv])
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err, err
    assert got == code, err
    if code == 2:
        assert_one_error_line(err)
    else:
        assert "error:" not in err, err


def test_an_integer_axis_steps_by_one(capsys):
    """n_bending 2:4 is 2, 3, 4 (a linspace gave 2.5, which the model rounded silently)."""
    assert (
        main(
            [
                "sweep",
                "--axis",
                "n_bending",
                "--values",
                "2:4",
                "--speed",
                "20",
                "--scatter",
                "none",
                "--json",
            ]
        )
        == 0
    )
    out, _ = capsys.readouterr()
    assert json.loads(out)["n_bending"] == [2.0, 3.0, 4.0]


def test_an_unreachable_scheduler_is_one_line_after_the_connect_timeout(table_files):
    """The console script: the line says it timed out after S s, and the process ends at once
    (a Client that failed to connect hung 10 s in __del__ with a traceback at exit). "At once"
    is against the same machine's time to import the CLI and Dask in a child, measured just
    before: a fixed bound of 9 s was passed with the load at 16 on 2 cores."""
    script = Path(sys.executable).with_name("leadscrew-squeak")
    command = [str(script)] if script.exists() else [sys.executable, "-m", "leadscrew_ros.cli"]
    start = time.monotonic()
    subprocess.run(
        [sys.executable, "-c", "import leadscrew_ros.cli, distributed"], check=True, timeout=120
    )
    imports = time.monotonic() - start
    start = time.monotonic()
    proc = subprocess.run(
        [
            *command,
            "review",
            str(table_files / "logs"),
            "--out",
            str(table_files / "v"),
            "--scheduler",
            "tcp://127.0.0.1:1",
            "--connect-timeout",
            "0.5",
        ],
        capture_output=True,
        text=True,
        timeout=120,
        env=dict(os.environ),
    )
    elapsed = time.monotonic() - start
    assert proc.returncode == 2
    assert_one_error_line(proc.stderr)
    assert "timed out after 0.5 s" in proc.stderr
    assert elapsed < 2 * imports + 5, (elapsed, imports)  # __del__ added 10 s


def test_review_leaves_its_output_folder_out_of_the_inputs_and_says_so(capsys, files):
    """--out in the input folder: one info line, the log reviewed; --out = the input folder:
    the error says why there are no logs (it said only 'no logs')."""
    logs = files / "logs"
    assert main(["review", str(logs), "--out", str(logs), "--workers", "1"]) == 2
    _, err = capsys.readouterr()
    assert_one_error_line(err)
    assert f"(the output folder {logs} is left out of the inputs)" in err
    out_dir = logs / "review"
    assert (
        main(["review", str(logs), "--out", str(out_dir), "--workers", "1", "--summary-only"]) == 0
    )
    out, err = capsys.readouterr()
    assert out.splitlines()[0] == (
        f"review: the output folder {out_dir} is inside {logs}: left out of the inputs"
    )
    assert "1 reviewed" in out and "Traceback" not in err


@pytest.mark.parametrize("storage", ["MCAP", "SQLITE3"])
@pytest.mark.parametrize("mode", ["FILE", "MESSAGE"])
def test_a_compressed_rosbag2_bag_names_its_compression_and_the_conversion(
    capsys, tmp_path, storage, mode
):
    """rosbags' writer with FILE or MESSAGE compression: one line with the storage, the
    compression and a conversion command (it said 'no .mcap files', or read compressed
    payloads as messages)."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.writer import CompressionFormat, CompressionMode
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    float64 = store.types["std_msgs/msg/Float64"]
    bag = tmp_path / "bag"
    writer = Writer(bag, version=9, storage_plugin=getattr(StoragePlugin, storage))
    writer.set_compression(getattr(CompressionMode, mode), CompressionFormat.ZSTD)
    with writer:
        c = writer.add_connection("/motor_speed", "std_msgs/msg/Float64", typestore=store)
        for i in range(10):
            writer.write(c, i, store.serialize_cdr(float64(data=1.0), "std_msgs/msg/Float64"))
    for argv in (["info", str(bag)], ["replay", str(bag), "--out", str(tmp_path / "r")]):
        assert main(argv) == 2
        _, err = capsys.readouterr()
        assert_one_error_line(err)
        assert (
            f"rosbag2 bag with {mode} compression (zstd, storage {storage.lower()})" in err
            and f"rosbags-convert --src {bag}" in err
        ), err
