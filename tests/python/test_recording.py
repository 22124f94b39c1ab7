"""`sorting-line-bag record` that loses nothing the machine survived: a recorder killed outright
(SIGKILL) leaves a bag `reindex` recovers, split and compressed bags read back exactly, and a full
disk ends the recording with a message and a readable bag. Real node, real rclpy over DDS.

Runs inside the loopback-only network namespace that launch_scripts/test.sh makes:

    unshare -n bash -c 'ip link set lo up; source launch_scripts/env.sh; export ROS_DOMAIN_ID=132;
                        python -m pytest tests/python/test_recording.py -q'

The full-disk test mounts a small tmpfs in a mount namespace of its own (`unshare -m`, as root,
which the CI tests are). Cost: 30 s in all on the 2-core machine at load ~5, 95 s at load 15
(the killed recorder 9-26 s, the full disk 7-22 s, two golden replays 4-25 s each).
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from sorting_line_gym.bag import open_bag, rewrite_bag
from sorting_line_gym.bag.format.options import WriteOptions
from sorting_line_gym.bag.format.topics import PUBLISHED, relative_to
from sorting_line_gym.bag.storage.losses import header_stamp
from support import ros_harness as h
from support.bag_golden import DATA, BagProcess

#: The killed recorder must hold everything the node published up to this long before the kill
#: (it fsyncs every 0.5 s; the rest is slack for a busy 2-core machine).
KILL_MARGIN = 1.5


pytestmark = pytest.mark.usefixtures("same_binary")  # conftest: the tools start the tests' binary


def _line_messages(bag, namespace: str, t0: int, t1: int) -> dict[str, int]:
    """Per line topic the node publishes: messages stamped in (t0, t1]."""
    counts: dict[str, int] = {}
    for m in bag.messages:
        rel = relative_to(namespace, m.topic)
        if rel in PUBLISHED and t0 < header_stamp(m.data) <= t1:
            counts[rel] = counts.get(rel, 0) + 1
    return counts


def _reports(diag, namespace: str) -> list[tuple[float, int, int]]:
    """(when received, sim_time ns, messages_published) of the line's /diagnostics reports."""
    out = []
    for received, array in diag:
        values = h.diagnostic_values(array, namespace)
        if values:
            sec, _, frac = values["sim_time"].partition(".")
            out.append((received, int(sec) * 10**9 + int(frac), int(values["messages_published"])))
    return out


def test_a_killed_recorder_leaves_a_bag_reindex_recovers(ros, probe, start_node, namespace, tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray

    ns = namespace("killed")
    start_node("--mode", "realtime", "--rate", "50", "--ros-args", "-r", f"__ns:={ns}")
    diag: list = []
    probe.create_subscription(DiagnosticArray, "/diagnostics", lambda a: diag.append((time.monotonic(), a)), 50)
    out = tmp_path / "run"
    # One MCAP file (no splitting, which finishes files), so only the flushes by time put it on disk.
    recorder = BagProcess(["record", "--namespace", ns, "-o", out, "--compression", "zstd"], tmp_path / "record.log")
    recorder.wait_for_output("recording", 30.0, ros)
    recording = time.monotonic()
    ros.spin_for(6.0)
    recorder.proc.send_signal(signal.SIGKILL)
    killed = time.monotonic()
    assert recorder.wait(10) == -signal.SIGKILL, recorder.describe()

    from sorting_line_gym.bag.cli import main

    assert main(["info", str(out)]) == 2  # says how to recover (checked by the reading tools' test below)
    cut = [(received, t, n) for received, t, n in _reports(diag, ns) if recording + 1.0 <= received]
    window = [r for r in cut if r[0] <= killed - KILL_MARGIN]
    assert len(window) >= 2, f"reports of the line: {cut} (recording at {recording}, killed at {killed})"
    (_, t0, p0), (_, t1, p1) = window[0], window[-1]

    fixer = BagProcess(["reindex", out], tmp_path / "reindex.log")
    assert fixer.wait(60) == 0, fixer.describe()
    bag = open_bag(out)
    got = _line_messages(bag, ns, t0, t1)
    ticks = (t1 - t0) // 10**9
    assert sum(got.values()) == p1 - p0 and got["state"] == ticks, (got, p1 - p0, ticks, fixer.log())
    info = yaml.safe_load((out / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["message_count"] == len(bag.messages) == sum(f["message_count"] for f in info["files"])
    assert bag.info.namespace == ns and bag.info.node["mode"] == "realtime"


@pytest.mark.parametrize(
    "name,options",
    [
        ("advanced_b", WriteOptions(max_bag_size=48 * 1024)),
        ("basic_d", WriteOptions(compression="zstd")),
    ],
    ids=["split", "zstd"],
)
def test_split_and_compressed_bags_round_trip_through_info_and_replay(name, options, tmp_path, capsys):
    from mcap.reader import make_reader
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    from sorting_line_gym.bag.cli import main

    out = tmp_path / name
    rewrite_bag(DATA / name, out, options=options)
    golden, bag = open_bag(DATA / name), open_bag(out)
    assert [(m.topic, m.log_time, m.data) for m in bag.messages] == [
        (m.topic, m.log_time, m.data) for m in golden.messages
    ]

    info = yaml.safe_load((out / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    files = info["relative_file_paths"]
    assert [f["path"] for f in info["files"]] == files == [f"{name}_{k}.mcap" for k in range(len(files))]
    assert sum(f["message_count"] for f in info["files"]) == info["message_count"] == len(golden.messages)
    if options.max_bag_size:
        assert len(files) >= 3 and all((out / f).stat().st_size < 1.1 * options.max_bag_size for f in files)
    compressions = set()
    for f in files:
        with open(out / f, "rb") as stream:
            compressions |= {c.compression for c in make_reader(stream).get_summary().chunk_indexes}
    assert compressions == {"" if options.compression == "none" else options.compression}
    with AnyReader([out], default_typestore=get_typestore(Stores.EMPTY)) as reader:  # rosbags, schemas from the bag
        assert sum(1 for _ in reader.messages()) == len(golden.messages)

    assert main(["info", str(out)]) == 0
    described = capsys.readouterr().out
    assert f"{len(golden.messages)} messages" in described and "state" in described, described
    tool = BagProcess(["replay", out], tmp_path / "replay.log")
    assert tool.wait(90) == 0, tool.describe()
    assert "identical" in tool.log() and "state 255" in tool.log() and "events/reset 5" in tool.log(), tool.log()


def test_reading_tools_say_how_to_recover_a_cut_bag(tmp_path, capsys):
    """info, replay and play (and everything else that opens a bag through open_bag)."""
    from sorting_line_gym.bag.cli import main

    cut = tmp_path / "cut"
    rewrite_bag(DATA / "basic_d", cut, options=WriteOptions(max_bag_size=48 * 1024))
    last = sorted(cut.glob("*.mcap"))[-1]
    last.write_bytes(last.read_bytes()[: last.stat().st_size // 2])
    bare = tmp_path / "bare"
    shutil.copytree(cut, bare)
    (bare / "metadata.yaml").unlink()
    unlisted = tmp_path / "unlisted"  # killed right after starting a split file, before metadata.yaml said so
    rewrite_bag(DATA / "basic_d", unlisted, options=WriteOptions(max_bag_size=48 * 1024))
    meta = yaml.safe_load((unlisted / "metadata.yaml").read_text())
    last_file = meta["rosbag2_bagfile_information"]["relative_file_paths"].pop()
    meta["rosbag2_bagfile_information"]["files"].pop()
    (unlisted / "metadata.yaml").write_text(yaml.safe_dump(meta))
    for args, message in [
        (("info", cut), f"`sorting-line-bag reindex {cut}` recovers"),
        (("replay", cut), "without the MCAP summary and footer"),
        (("play", cut, "--no-wait"), f"`sorting-line-bag reindex {cut}`"),
        (("info", bare), f"`sorting-line-bag reindex {bare}` rebuilds metadata.yaml"),
        (("info", unlisted), f"metadata.yaml does not list {last_file}"),
    ]:
        code = main([str(a) for a in args])
        err = capsys.readouterr().err
        assert (code, message in err) == (2, True), f"{args}: exit {code}, stderr {err!r}"
    for path in (cut, bare):
        assert main(["reindex", str(path)]) == 0, capsys.readouterr()
        assert 0 < len(open_bag(path).messages) < len(open_bag(DATA / "basic_d").messages)
    assert main(["reindex", str(unlisted)]) == 0, capsys.readouterr()
    assert len(open_bag(unlisted).messages) == len(open_bag(DATA / "basic_d").messages)
    assert main(["reindex", str(tmp_path / "nothing")]) == 2


def test_bad_recording_options_fail_at_start_naming_value_and_range(tmp_path, capsys):
    from sorting_line_gym.bag.cli import main

    cases = [
        (["--max-bag-size", "5"], "--max-bag-size 5: must be 0 (no splitting) or a whole number of bytes >= 16"),
        (["--max-bag-size", "1e9"], "'1e9' is not a whole number"),
        (["--max-bag-duration", "0.2"], "--max-bag-duration 0.2: must be 0 (no splitting) or a finite number"),
        (["--compression", "gzip"], "--compression gzip: must be one of none, zstd, lz4"),
    ]
    for flags, message in cases:
        with pytest.raises(SystemExit) as exit_:
            main(["record", "--namespace", "/x", "-o", str(tmp_path / "out"), *flags])
        err = capsys.readouterr().err
        assert (exit_.value.code, message in err) == (2, True), f"{flags}: {err!r}"
    assert main(["record", "--namespace", "/x", "-o", str(tmp_path / "no" / "out")]) == 2
    assert "cannot create the bag directory" in capsys.readouterr().err


def test_a_full_disk_ends_the_recording_with_a_message_and_a_readable_bag(start_node, namespace, tmp_path):
    if os.geteuid() != 0 or not shutil.which("unshare"):
        pytest.skip("needs root and unshare (a tmpfs in a mount namespace of the test's own)")
    ns = namespace("full")
    start_node("--variant", "advanced", "--mode", "realtime", "--rate", "200", "--ros-args", "-r", f"__ns:={ns}")
    disk, copied = tmp_path / "disk", tmp_path / "copied"
    disk.mkdir()
    tool = Path(sys.executable).parent / "sorting-line-bag"
    # 4 MiB, of which a file takes all but ~850 KiB: the reserve (512 KiB) and ~2 s of this line.
    script = f"""
        mount -t tmpfs -o size=4m tmpfs {disk}
        fallocate -l {4 * 1024 * 1024 - 850 * 1024} {disk}/filler
        {tool} record --namespace {ns} -o {disk}/bag --duration 60 --max-bag-duration 1; echo "record exit $?"
        {tool} info {disk}/bag; echo "info exit $?"
        cp -a {disk}/bag {copied}
    """
    run = subprocess.run(
        ["unshare", "-m", "--propagation", "private", "bash", "-c", script],
        capture_output=True,
        text=True,
        timeout=120,
        env=dict(os.environ, PYTHONUNBUFFERED="1"),
    )
    log = run.stdout + run.stderr
    assert "record exit 3" in log and "info exit 0" in log, log
    assert "No space left on device (errno ENOSPC)" in log and "Recording stopped" in log, log
    assert "and the bag is readable" in log and "recording: failed" in log, log
    bag = open_bag(copied)
    stated = int(log.split("Recording stopped; the ")[1].split(" messages")[0])
    assert stated == len(bag.messages) > 200, log
    assert not (copied / ".sorting_line_reserve").exists()
    assert len(list(copied.glob("*.mcap"))) >= 2  # split by time, the last file ends at the full disk


def _cdr_with_stamp(stamp_ns: int) -> bytes:
    """A line message's first bytes as far as the loss counter reads them: CDR_LE header, stamp."""
    import struct

    return b"\x00\x01\x00\x00" + struct.pack("<iI", stamp_ns // 10**9, stamp_ns % 10**9) + bytes(16)


def test_the_loss_counter_names_what_the_node_published_and_the_recorder_missed():
    """No ROS: the node's reports (sim_time, messages_published) against the stamps received."""
    from sorting_line_gym.bag.storage.losses import LossCounter, describe_losses

    ns, s = "/l", 10**9
    topics = [f"{ns}/{t}" for t in ("input", "belt/occupancy", "state", "events/reset", "cmd/speed")]
    counter = LossCounter(ns, topics, "basic", False, 1.0)
    counter.on_message(f"{ns}/state", _cdr_with_stamp(5 * s))  # before the first report: outside the window
    counter.on_status({"sim_time": "5.000000000", "messages_published": "100"})
    for tick in range(6, 16):  # ticks 6..15: 3 per-tick messages each, a reset at tick 10
        for rel in ("input", "belt/occupancy", "state"):
            if not (rel == "state" and tick in (8, 9)) and not (rel == "input" and tick == 12):
                counter.on_message(f"{ns}/{rel}", _cdr_with_stamp(tick * s))
        if tick == 10:
            counter.on_message(f"{ns}/events/reset", _cdr_with_stamp(tick * s))
        if tick == 13:
            counter.on_status({"sim_time": "13.000000000", "messages_published": str(100 + 8 * 3 + 1)})
    report = counter.report()
    assert report == {
        "compared": True,
        "window_ns": [5 * s, 13 * s],
        "ticks": 8,
        "published": 25,
        "received": 22,
        "missing": 3,
        "topics": {"state": 2, "input": 1},
    }, report
    assert "MESSAGES MISSED: 3 of the 25" in describe_losses(report) and "state 2" in describe_losses(report)
    partial = LossCounter(ns, topics[:2], "basic", False, 1.0)
    assert not partial.report()["compared"] and "state" in partial.report()["why"]


def test_a_recording_says_it_missed_nothing(ros, start_node, namespace, tmp_path, capsys):
    ns = namespace("complete")
    start_node("--mode", "realtime", "--rate", "50", "--ros-args", "-r", f"__ns:={ns}")
    out = tmp_path / "run"
    recorder = BagProcess(["record", "--namespace", ns, "-o", out, "--duration", "3"], tmp_path / "record.log")
    assert recorder.wait(60) == 0, recorder.describe()
    assert "messages missed: none (the node published" in recorder.log(), recorder.log()
    from sorting_line_gym.bag.cli import main

    assert main(["info", str(out)]) == 0
    assert "messages missed: none" in capsys.readouterr().out


def test_a_bag_being_recorded_is_named_so_and_reindex_leaves_it_alone(tmp_path):
    """No ROS: a writer of this process, mid-recording (its metadata.yaml names this live pid)."""
    from sorting_line_gym.bag import BagError
    from sorting_line_gym.bag.storage.recovery import reindex
    from sorting_line_gym.bag.storage.writer import BagWriter

    golden = open_bag(DATA / "basic_d")
    writer = BagWriter(tmp_path / "live", golden.custom)
    for topic, msgtype in golden.types.items():
        writer.add_topic(topic, msgtype)
    for m in golden.messages[:100]:
        writer.write(m.topic, m.log_time, m.data)
    writer.flush()
    with pytest.raises(BagError, match=f"it is still being recorded: its recorder \\(pid {os.getpid()}\\)"):
        open_bag(tmp_path / "live")
    with pytest.raises(BagError, match="is being recorded"):
        reindex(tmp_path / "live")
    writer.close()
    assert len(open_bag(tmp_path / "live").messages) == 100
