# SPDX-License-Identifier: Apache-2.0
"""Fuzzing the log path: truncated and bit-flipped MCAP files (zstd, lz4 and uncompressed
chunks, and unchunked) never crash or hang `replay`, `info` or `recover`: each run ends, within a
deadline, either successfully or with exit code 2 and one line naming the file. A truncated
file read with strict=False yields a prefix of the original messages."""

import signal
import time
from contextlib import contextmanager
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.writer import Writer

from leadscrew_ros.bag.logfile import LogError, read_messages
from leadscrew_ros.bag.synthetic import DutyCycle, write_log
from leadscrew_ros.cli import main
from leadscrew_ros.live.profile import StrokeProfile

CYCLE = DutyCycle(duration_s=4.0, rate_hz=20.0, rest_s=0.5, stroke=StrokeProfile(duration_s=3.0))
LAYOUTS = ("zstd", "lz4", "none", "unchunked")
DEADLINE_S = 30.0  # per run; a normal one takes ~50 ms
FUZZ = settings(
    max_examples=25,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)


@contextmanager
def deadline(seconds: float):
    """TimeoutError in this (main) thread if the block runs longer: a hang fails the test.
    pytest-timeout's per-test timer (signal method) uses the same SIGALRM timer: it gets back
    what is left of it afterwards, and is left alone when it would expire first anyway."""
    outer = signal.getitimer(signal.ITIMER_REAL)[0]
    if outer and outer <= seconds:
        yield
        return

    def expire(signum, frame):
        raise TimeoutError(f"still running after {seconds} s")

    old = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    start = time.monotonic()
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
        if outer:
            signal.setitimer(signal.ITIMER_REAL, max(outer - (time.monotonic() - start), 1e-3))


def unchunked_copy(src: Path, dst: Path) -> Path:
    """The same messages without chunks (and so without CRCs over the messages)."""
    with open(dst, "wb") as f:
        w = Writer(f, use_chunking=False)
        w.start(profile="ros2", library="test")
        ids = {}
        for m in read_messages(src):
            t = m.topic
            if t.name not in ids:
                schema = w.register_schema(t.type_name, t.schema_encoding, t.schema.encode())
                ids[t.name] = w.register_channel(t.name, t.message_encoding, schema, t.metadata)
            w.add_message(ids[t.name], m.log_time_ns, m.data, m.publish_time_ns, m.sequence)
        w.finish()
    return dst


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> dict[str, bytes]:
    root = tmp_path_factory.mktemp("fuzz_logs")
    out = {}
    for layout in LAYOUTS[:3]:
        bag = write_log(CYCLE, root / layout, split_duration_s=0.0, compression=layout)
        (out[layout],) = bag.glob("*.mcap")
    out["unchunked"] = unchunked_copy(out["zstd"], root / "unchunked.mcap")
    return {k: p.read_bytes() for k, p in out.items()}


def check_commands(path: Path, out: Path, capsys) -> list[int]:
    """replay, info and recover of `path`: exit 0, or 2 with one line naming the file."""
    codes = []
    for argv in (
        ["replay", path, "--out", out, "--no-report", "--quiet", "--workers", "0"],
        ["info", path],
        ["recover", path, "-o", out / "recovered.mcap"],
    ):
        with deadline(DEADLINE_S):
            code = main([str(a) for a in argv])
        _, err = capsys.readouterr()
        assert code in (0, 2), (argv, code, err)
        if code == 2:
            assert err.count("\n") == 1 and err.startswith("leadscrew-squeak: error: "), err
            assert str(path) in err, err
        codes.append(code)
    return codes


def test_the_undamaged_logs_replay(logs, tmp_path, capsys):
    for layout, data in logs.items():
        path = tmp_path / f"{layout}.mcap"
        path.write_bytes(data)
        assert check_commands(path, tmp_path / layout, capsys) == [0, 0, 0]


@pytest.mark.parametrize("layout", LAYOUTS)
@FUZZ
@given(fraction=st.floats(0.0, 1.0, exclude_max=True))
def test_truncated_logs_fail_cleanly_and_read_as_a_prefix(logs, tmp_path, capsys, layout, fraction):
    data = logs[layout]
    path = tmp_path / "cut.mcap"
    path.write_bytes(data[: int(len(data) * fraction)])
    replay_code, _, _ = check_commands(path, tmp_path / "out", capsys)
    assert replay_code == 2  # no footer: refused, recover is named
    original = tmp_path / "whole.mcap"
    original.write_bytes(data)
    whole = [(m.topic.name, m.log_time_ns, m.data) for m in read_messages(original)]
    try:
        with deadline(DEADLINE_S):
            prefix = [
                (m.topic.name, m.log_time_ns, m.data) for m in read_messages(path, strict=False)
            ]
    except LogError as exc:  # cut inside the magic or the header
        assert str(path) in str(exc)
        return
    assert prefix == whole[: len(prefix)]


@pytest.mark.parametrize("layout", LAYOUTS)
@FUZZ
@given(data=st.data())
def test_bit_flipped_logs_fail_cleanly(logs, tmp_path, capsys, layout, data):
    raw = bytearray(logs[layout])
    for _ in range(data.draw(st.integers(1, 8), label="flips")):
        i = data.draw(st.integers(0, len(raw) - 1), label="offset")
        if data.draw(st.booleans(), label="whole byte"):
            raw[i] = data.draw(st.integers(0, 255), label="byte")
        else:
            raw[i] ^= 1 << data.draw(st.integers(0, 7), label="bit")
    path = tmp_path / "flipped.mcap"
    path.write_bytes(bytes(raw))
    check_commands(path, tmp_path / "out", capsys)
