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

import contextlib
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
from harness.processes import CLI, domain, output, start, stop
from leadscrew_ros.bag import logmeta
from leadscrew_ros.bag.logfile import recover
from leadscrew_ros.bag.synthetic import DutyCycle, write_log
from leadscrew_ros.cli import main
from leadscrew_ros.cli.fleet import exit_status
from leadscrew_ros.model import ScrewParameters, SqueakModel
from leadscrew_ros.review import fleet
from leadscrew_ros.review.fleet import (
    INDEX_FILE,
    ClusterSettings,
    Machine,
    find_logs,
    local_workers,
    output_names,
    squeak_frequencies,
)
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


# ----------------------------------------------------------------------------- workers, Ctrl-C
GB = 10**9


@pytest.mark.parametrize(
    "requested, machine, expected",
    [
        (1000, Machine(2, 64 * GB), (2, "this machine's cores")),
        (1024, Machine(16, 3 * GB), (3, "what this machine's available memory holds (3.0 GB")),
        (2, Machine(2, 64 * GB), (2, "")),
        (1, Machine(8, 64 * GB), (1, "")),
        (None, Machine(8, 64 * GB), (8, "")),  # the default: what the machine runs
        (None, Machine(8, 2 * GB), (2, "")),
        (4, Machine(8, GB // 10), (1, "what this machine's available memory holds (0.1 GB")),
    ],
)
def test_local_workers_are_capped_at_what_the_machine_runs(requested, machine, expected):
    """Issue 29: `--workers 1000` on 2 cores did no work in 300 s (1000 processes starting)."""
    count, why = local_workers(requested, ClusterSettings(), machine)
    assert count == expected[0]
    assert why.startswith(expected[1]) and bool(why) == bool(expected[1])
    if "memory" in why:
        assert f"at {ClusterSettings().worker_memory_gb:g} GB a worker" in why


def _rss_bytes() -> int:
    import psutil

    return psutil.Process().memory_info().rss


def test_a_worker_that_reviewed_a_log_holds_well_within_its_memory_budget(logs, tmp_path):
    """`ClusterSettings.worker_memory_gb` counts each local worker at 1 GB: one that has
    reviewed a log (with its report) holds less than half of it (measured about 0.23 GB)."""
    model = SqueakModel()
    settings = fleet.FleetSettings(
        model.params, dict(model.scatter.sd), model.sample_count, InputSettings(), {}, None, None
    )
    with fleet.cluster(1) as client:
        [log] = find_logs([str(logs / "bench" / "station0")])
        run = fleet.review_logs([log], tmp_path, settings, client, False)
        [rss] = client.run(_rss_bytes).values()
    assert [r["status"] for r in run.rows] == ["ok"]
    assert rss < ClusterSettings().worker_memory_gb * GB / 2, rss


class FakeCluster:
    """Stands in for `distributed.LocalCluster`: keeps its arguments and starts nothing."""

    calls: list[dict] = []

    def __init__(self, **kwargs):
        FakeCluster.calls.append(kwargs)
        raise OSError("no cluster in this test")


@pytest.mark.parametrize("command", ["review", "calibrate"])
def test_the_local_cluster_gets_the_capped_count_on_loopback_without_dashboard(
    command, logs, tmp_path, monkeypatch, capsys
):
    import distributed

    monkeypatch.setattr(fleet.Machine, "now", classmethod(lambda cls: Machine(2, 64 * GB)))
    monkeypatch.setattr(distributed, "LocalCluster", FakeCluster)
    FakeCluster.calls = []
    log = str(logs / "bench" / "station0")
    code = main([command, log, "--out", str(tmp_path / "o"), "--workers", "1000", "--quiet"])
    err = capsys.readouterr().err.splitlines()
    assert code == 2 and err[-1] == "leadscrew-squeak: error: no cluster in this test"
    assert err[0] == "leadscrew-squeak: --workers 1000: capped at 2, this machine's cores"
    [kwargs] = FakeCluster.calls
    assert kwargs["n_workers"] == 2 and kwargs["threads_per_worker"] == 1
    assert kwargs["host"] == "127.0.0.1" and kwargs["dashboard_address"] is None
    assert kwargs["scheduler_kwargs"] == {"dashboard": False, "dashboard_address": "127.0.0.1:0"}


@pytest.fixture
def port_8787():
    """127.0.0.1:8787, Dask's default HTTP port, in use while the test runs (by this socket,
    or by whatever holds it already)."""
    with socket.socket() as s:
        try:
            s.bind(("127.0.0.1", 8787))
            s.listen()
        except OSError:
            pass  # taken already: in use all the same
        yield


def test_ctrl_c_ends_a_review_with_one_line_and_exit_130_and_a_rerun_resumes(tmp_path, port_8787):
    """Issue 29: a Ctrl-C of `review` gave 466 tracebacks (of the workers, which a terminal's
    Ctrl-C reaches too, and of a cluster closed half started). SIGINT to the process group of a
    `review` child once its first log is in the index: the one line saying how far it got,
    exit 130, no worker left, nothing else on stderr (no Dask warning, no port 8787 notice);
    a rerun reviews only the rest."""
    logs = tmp_path / "logs"
    for k in range(16):
        write_log(cycle(k), logs / f"unit{k:02d}")
    out = tmp_path / "out"
    argv = CLI + ["review", str(logs), "--out", str(out), "--joint-name", JOINT, "--quiet"]
    workers = str(min(2, local_workers(None)[0]))  # two, unless capped (a line more)
    argv += ["--workers", workers, "--summary-only"]  # as `review` below: the same parameters
    proc = start(argv, domain(7), tmp_path, "review", new_session=True)
    try:
        index, deadline = out / INDEX_FILE, time.monotonic() + 300
        while not (index.exists() and index.read_text().strip()):
            assert proc.poll() is None, output(proc)
            assert time.monotonic() < deadline, "no log reviewed in 300 s"
            time.sleep(0.02)
        os.killpg(proc.pid, signal.SIGINT)
        proc.wait(timeout=120)
        _, err = output(proc)
        # nothing of its process group is left (workers, Dask's fork server)
        deadline = time.monotonic() + 60
        while _group_alive(proc.pid) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not _group_alive(proc.pid)
    finally:
        if _group_alive(proc.pid):
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGKILL)
        stop(proc)
    assert proc.returncode == 130, err
    [line] = err.splitlines()
    done = len({json.loads(x)["row"]["log"] for x in index.read_text().splitlines()})
    assert line == f"leadscrew-squeak: interrupted: {done} of 16 logs reviewed, rerun to resume"
    assert 1 <= done < 16
    assert review(logs, out, "--workers", workers, "--summary-only") == 0
    doc = json.loads((out / "fleet.json").read_text())
    assert (doc["logs"], doc["ok"], doc["reviewed"], doc["skipped"]) == (16, 16, 16 - done, done)


def _group_alive(pgid: int) -> bool:
    """A process of group `pgid` still runs (zombies left to a non-reaping init do not)."""
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:  # gone meanwhile
            continue
        if int(fields[2]) == pgid and fields[0] != "Z":  # after 'pid (comm)': state ppid pgrp
            return True
    return False


def test_a_ctrl_c_while_the_cluster_starts_or_closes_is_held_till_after():
    """`fleet._ctrl_c_held`: a SIGINT inside does not interrupt (Dask half started or half
    closed prints tracebacks); it is raised as KeyboardInterrupt when the block ends, and the
    handler before is back."""
    before = signal.getsignal(signal.SIGINT)
    finished = False
    with pytest.raises(KeyboardInterrupt):
        with fleet._ctrl_c_held():
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.05)  # the handler has run: nothing raised here
            finished = True
    assert finished and signal.getsignal(signal.SIGINT) is before
    with fleet._ctrl_c_held():
        pass  # no Ctrl-C: nothing raised


class _Done:
    """A Dask future that finished (or, `interrupt`: whose result a Ctrl-C cut short)."""

    def __init__(self, value, interrupt=False):
        self.value, self.interrupt = value, interrupt

    def done(self):
        return not self.interrupt

    def result(self):
        if self.interrupt:
            raise KeyboardInterrupt
        return self.value


def test_a_ctrl_c_of_calibrate_says_how_many_inputs_were_gathered(tmp_path):
    from leadscrew_ros.review.calibration.gather import gather

    class Client:
        def __init__(self):
            self.n = 0

        def submit(self, fn, *args, **kwargs):
            self.n += 1
            return _Done(self.n, interrupt=self.n == 3)

    inputs = [(tmp_path / f"log{k}", False) for k in range(5)]
    with pytest.raises(KeyboardInterrupt) as caught:
        gather(inputs, tmp_path, None, Client())
    assert str(caught.value) == ("4 of 5 inputs gathered, nothing calibrated; a rerun starts over")
