# SPDX-License-Identifier: Apache-2.0
"""Fleet review (`leadscrew-squeak review`, `review.fleet`) on Dask clusters on 127.0.0.1.

Twelve generated logs: node-style bags of our Recorder (`synthetic.write_log`; two carry the
`leadscrew_ros` metadata record, written here as the node will, two share a name in different
folders), bags of rosbags' writer, one cut off (as by a crash) and one foreign MCAP. The foreign
log is an error row; the cut-off one is reviewed up to its last whole record (a copy mended as
`recover` does, with a note), and its row, like the other ten, carries the numbers of `replay`
of the same (mended) log. The same table comes from a local cluster
of two workers, from an external `dask scheduler` with two `dask worker` processes, and from a
run whose worker is killed in the middle; a second run into the same directory reviews nothing.
"""

import csv
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from harness.logs import rosbags_log
from leadscrew_ros.bag import logmeta
from leadscrew_ros.bag.logfile import recover
from leadscrew_ros.bag.synthetic import DutyCycle, write_log
from leadscrew_ros.cli import main
from leadscrew_ros.cli.fleet import exit_status
from leadscrew_ros.model import ScrewParameters, SqueakModel
from leadscrew_ros.review import fleet
from leadscrew_ros.review.fleet import INDEX_FILE, find_logs, output_names, squeak_frequencies
from leadscrew_ros.review.replay import ReplaySettings, log_name, replay
from leadscrew_ros.review.timeline import InputSettings

pytest.importorskip("distributed")

JOINT = "screw"  # the rosbags logs' joint; the Recorder's logs have /motor_speed
NUMBERS = [
    "duration_s",
    "time_in_squeak_s",
    "episodes",
    "peak_probability",
    "time_above_warn_s",
    "time_above_error_s",
    "messages",
    "predictions",
]
DASK = [sys.executable, "-m"]  # + distributed.cli.dask_scheduler / dask_worker
REPO = Path(__file__).resolve().parents[1]


def cycle(seed: int) -> DutyCycle:
    return DutyCycle(duration_s=8.0, rate_hz=25.0, rest_s=0.5, seed=seed)


def the_mcap(bag: Path) -> Path:
    (file,) = bag.glob("*.mcap")
    return file


def add_metadata(path: Path, meta: logmeta.LogMetadata) -> None:
    """Rewrite an MCAP file with the `leadscrew_ros` record (as the node writes it)."""
    with open(path, "rb") as f:
        items = list(make_reader(f).iter_messages(log_time_order=False))
    with open(path, "wb") as f:
        w = Writer(f)
        w.start("ros2", "test")
        schemas, channels = {}, {}
        for schema, channel, message in items:
            if schema.id not in schemas:
                schemas[schema.id] = w.register_schema(schema.name, schema.encoding, schema.data)
            if channel.id not in channels:
                channels[channel.id] = w.register_channel(
                    channel.topic, channel.message_encoding, schemas[schema.id], channel.metadata
                )
            w.add_message(
                channels[channel.id],
                message.log_time,
                message.data,
                message.publish_time,
                message.sequence,
            )
        w.add_metadata(logmeta.RECORD_NAME, meta.record())
        w.finish()


def foreign_mcap(path: Path) -> Path:
    with open(path, "wb") as f:
        w = Writer(f)
        w.start("", "someone else")
        schema = w.register_schema("Point", "jsonschema", b"{}")
        channel = w.register_channel("/point", "json", schema)
        for k in range(20):
            w.add_message(channel, k * 10**8, json.dumps({"x": k}).encode(), k * 10**8)
        w.finish()
    return path


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """Twelve logs in a folder tree: (root, the unit ids expected of the two with a record)."""
    root = tmp_path_factory.mktemp("fleet_logs")
    for k in range(4):
        write_log(cycle(k), root / "bench" / f"station{k}")
    for k, unit in ((4, "seat-0042"), (5, "seat-0043")):
        bag = write_log(cycle(k), root / "vehicles" / unit)
        meta = logmeta.LogMetadata(
            ScrewParameters().as_dict(),
            {"samples": 1024},
            {"joint_name": ""},
            unit_id=unit,
            hardware_id="hw",
        )
        add_metadata(the_mcap(bag), meta)
    for k in range(2):  # the same log name in two folders
        rosbags_log(root / "line" / f"day{k}" / "run", [JOINT], samples=100 + 40 * k)
    for k in range(2):
        rosbags_log(root / "line" / f"cell_{k}", ["wheel", JOINT], samples=120)
    cut = the_mcap(write_log(cycle(9), root / "broken" / "cut"))
    cut.write_bytes(cut.read_bytes()[: int(cut.stat().st_size * 0.6)])
    foreign_mcap(root / "foreign.mcap")
    return root


@pytest.fixture(scope="module")
def expected(logs, tmp_path_factory):
    """log path -> (replay summary, episodes) of `replay` itself, for the eleven readable logs
    (the cut-off one mended by `recover` first)."""
    out, model = tmp_path_factory.mktemp("single"), SqueakModel()
    found = {}
    for log in find_logs([str(logs)]):
        if log.name == "foreign.mcap":
            continue
        key = str(log)
        if log.parent.name == "cut":  # reviewed as `recover` leaves it: the whole messages
            mended = out / "recovered" / log.name
            mended.mkdir(parents=True)
            for f in log.glob("*.mcap"):
                recover(f, mended / f.name)
            log = mended
        r = replay(
            log,
            model,
            out / str(len(found)),
            ReplaySettings(InputSettings(joint_name=JOINT), workers=0, progress=False),
        )
        found[key] = (r.summary(), [e.as_dict() for e in r.episodes])
    assert len(found) == 11
    return found


def review(logs, out, *options):
    return main(
        [
            "review",
            str(logs),
            "--out",
            str(out),
            "--joint-name",
            JOINT,
            "--quiet",
            *map(str, options),
        ]
    )


def table(out: Path) -> list[dict]:
    with open(out / "fleet.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    for r in rows:
        r.pop("wall_s")
    return rows


def check_table(out: Path, expected: dict) -> list[dict]:
    rows = table(out)
    assert len(rows) == 12
    bad = [r for r in rows if r["status"] == "error"]
    assert [Path(r["log"]).name for r in bad] == ["foreign.mcap"]
    cut = next(r for r in rows if "/cut/" in r["log"])
    assert cut["status"] == "ok" and cut["note"].startswith("cut off (")
    assert "whole messages before the cut" in cut["note"] and len(cut["note"].splitlines()) == 1
    assert all(r["note"] == "" for r in rows if r is not cut)
    assert "foreign MCAP" in next(r["error"] for r in bad if r["log"].endswith("foreign.mcap"))
    assert all(len(r["error"].splitlines()) == 1 for r in bad)
    by_log = {r["log"]: r for r in rows}
    doc = {r["log"]: r for r in json.loads((out / "fleet.json").read_text())["rows"]}
    for log, (summary, episodes) in expected.items():
        row, exact = by_log[log], doc[log]
        assert row["status"] == "ok" and row["error"] == "", (log, row["error"])
        for key in NUMBERS:
            assert exact[key] == summary[key], (log, key)
            assert float(row[key]) == summary[key], (log, key)
        growth = max(e["peak_growth_rate"] for e in episodes)
        assert exact["peak_growth_rate"] == float(row["peak_growth_rate"]) == growth
        assert exact["squeak_frequencies_hz"] == squeak_frequencies(episodes)
        assert summary["episodes"] > 0
    units = {Path(r["log"]).parent.name: r["unit_id"] for r in rows}
    assert units["seat-0042"] == "seat-0042" and units["seat-0043"] == "seat-0043"
    names = [r["name"] for r in rows]
    assert len(set(names)) == 12
    assert sum(n.startswith("run-") for n in names) == 2  # the shared name, made unique
    return rows


def test_log_discovery_and_names(logs, tmp_path):
    found = find_logs([str(logs)])
    assert len(found) == 12
    # a split file stands for its bag, globs and overlapping inputs give each log once
    assert find_logs([str(logs / "bench" / "**" / "*.mcap"), str(logs / "bench")]) == find_logs(
        [str(logs / "bench")]
    )
    assert len(find_logs([str(logs)], skip=logs / "line")) == 8
    names = output_names(found)
    assert names == output_names(list(reversed(found)))[::-1]  # the same in every order
    # a name an earlier review gave another log in the same directory is not taken again
    other = {"/elsewhere/station0": names[0]}
    assert output_names(found[:1], other)[0].startswith(names[0] + "-")
    assert output_names(found[:1], {str(found[0]): "kept"}) == ["kept"]
    with pytest.raises(fleet.LogError, match="matches"):
        find_logs([str(tmp_path / "*.mcap")])
    assert exit_status(0) == 0 and exit_status(1) == 11 and exit_status(500) == 110


def test_local_cluster_reviews_every_log_and_resumes(logs, expected, tmp_path):
    out = tmp_path / "review"
    assert review(logs, out, "--workers", 2, "--no-report") == exit_status(1)
    rows = check_table(out, expected)
    ok = next(r for r in rows if r["status"] == "ok")
    outputs = sorted(p.name for p in (out / ok["name"]).iterdir())
    assert outputs == sorted(
        [
            "episodes.json",
            "summary.json",
            "summary.txt",
            f"{log_name(Path(ok['log']))}.annotated.mcap",
        ]
    )
    assert (out / "fleet.png").read_bytes().startswith(b"\x89PNG")
    # the annotated logs in the output directory are not logs to review
    assert find_logs([str(logs), str(out / "**" / "*.mcap")], skip=out) == find_logs([str(logs)])
    doc = json.loads((out / "fleet.json").read_text())
    assert (doc["ok"], doc["errors"], doc["reviewed"], doc["skipped"]) == (11, 1, 12, 0)
    assert doc["parameters"]["inputs"]["joint_name"] == JOINT

    # a re-run reviews nothing again (the failed logs fail the same way: not again either)
    assert review(logs, out, "--workers", 2, "--no-report") == exit_status(1)
    doc = json.loads((out / "fleet.json").read_text())
    assert (doc["reviewed"], doc["skipped"]) == (0, 12)
    assert table(out) == [dict(r) for r in rows]
    # a touched log is hashed, found unchanged and not replayed; other parameters replay all
    os.utime(the_mcap(next((logs / "vehicles" / "seat-0042").iterdir())))
    assert review(logs, out, "--workers", 1, "--no-report") == exit_status(1)
    doc = json.loads((out / "fleet.json").read_text())
    assert (doc["reviewed"], doc["skipped"]) == (0, 12)
    assert len((out / INDEX_FILE).read_text().splitlines()) == 12
    vehicles = [r for r in rows if "/vehicles/" in r["log"]]
    assert (
        review(logs / "vehicles", out, "--workers", 1, "--summary-only", "--scatter", "none") == 0
    )
    doc = json.loads((out / "fleet.json").read_text())
    assert (doc["logs"], doc["reviewed"], doc["skipped"]) == (2, 2, 0)
    assert [r["peak_probability"] for r in doc["rows"]] == [1.0, 1.0]  # the 0/1 verdict
    for r in vehicles:
        assert sorted(p.name for p in (out / r["name"]).iterdir()) == [
            "summary.json",
            "summary.txt",
        ]


def test_use_log_params(logs, tmp_path, capsys):
    out = tmp_path / "own"
    code = main(
        [
            "review",
            str(logs / "vehicles"),
            str(logs / "bench" / "station0"),
            "--out",
            str(out),
            "--use-log-params",
            "--workers",
            "1",
            "--quiet",
            "--summary-only",
        ]
    )
    capsys.readouterr()
    assert code == exit_status(1)
    rows = {Path(r["log"]).parent.name: r for r in table(out)}
    assert rows["seat-0042"]["status"] == rows["seat-0043"]["status"] == "ok"
    assert "no 'leadscrew_ros' metadata record" in rows["station0"]["error"]
    code = main(
        ["review", str(logs), "--out", str(out), "--use-log-params", "--param", "radius_m=0.01"]
    )
    assert code == 2 and "exclude each other" in capsys.readouterr().err


def test_bad_arguments_exit_2(logs, tmp_path, capsys):
    for argv in (
        ["review", str(tmp_path / "nothing"), "--out", str(tmp_path / "o")],
        ["review", str(logs), "--out", str(tmp_path / "o"), "--workers", "0"],
        [
            "review",
            str(logs),
            "--out",
            str(tmp_path / "o"),
            "--workers",
            "2",
            "--scheduler",
            "tcp://127.0.0.1:1",
        ],
        ["review", str(tmp_path), "--out", str(tmp_path / "o")],
    ):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and err.startswith("leadscrew-squeak: error")


# ----------------------------------------------------------------------------- external cluster
def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def external_cluster(tmp_path):
    """`dask scheduler` and two `dask worker` processes on 127.0.0.1 (one thread each, no
    dashboard); yields the scheduler address, stops them all afterwards."""
    from distributed import Client

    env = dict(
        os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])
    )
    address = f"tcp://127.0.0.1:{free_port()}"
    procs = [
        subprocess.Popen(
            DASK
            + [
                "distributed.cli.dask_scheduler",
                "--host",
                "127.0.0.1",
                "--port",
                address.rsplit(":", 1)[1],
                "--no-dashboard",
            ],
            env=env,
            cwd=tmp_path,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
        )
    ]
    try:
        for _ in range(2):
            procs.append(
                subprocess.Popen(
                    DASK
                    + [
                        "distributed.cli.dask_worker",
                        address,
                        "--host",
                        "127.0.0.1",
                        "--nthreads",
                        "1",
                        "--nworkers",
                        "1",
                        "--no-dashboard",
                    ],
                    env=env,
                    cwd=tmp_path,
                    stdout=subprocess.DEVNULL,
                    stderr=subprocess.DEVNULL,
                    start_new_session=True,
                )
            )
        with Client(address, timeout="120s") as client:
            client.wait_for_workers(2, timeout=180)
            assert all(w.startswith("tcp://127.0.0.1:") for w in client.nthreads())
        yield address
    finally:
        for p in procs:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGTERM)
        for p in procs:
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()


def test_external_cluster_and_a_worker_killed_mid_run(logs, expected, external_cluster, tmp_path):
    from distributed import Client

    out = tmp_path / "external"
    assert review(logs, out, "--scheduler", external_cluster, "--no-report") == exit_status(1)
    reference = check_table(out, expected)

    # again into a new directory, and one worker process is killed once the first log is in
    out = tmp_path / "killed"
    result = {}
    thread = threading.Thread(
        target=lambda: result.setdefault(
            "code", review(logs, out, "--scheduler", external_cluster, "--no-report")
        )
    )
    thread.start()
    index = out / INDEX_FILE
    while thread.is_alive() and not (index.exists() and index.read_text().strip()):
        time.sleep(0.05)
    with Client(external_cluster, timeout="60s") as client:
        pids = client.run(os.getpid)
        os.kill(sorted(pids.values())[0], signal.SIGKILL)
    thread.join(timeout=600)
    assert not thread.is_alive()
    assert result["code"] == exit_status(1)
    assert table(out) == reference
    check_table(out, expected)
    shutil.rmtree(out)
