"""``hindrax bag info`` and ``hindrax bag record`` (the latter in its own process, stopped by SIGINT or by
--duration). ``hindrax bag recover`` is covered in test_recording_recover.py, ``play`` in test_player.py."""
from __future__ import annotations

import re
import signal
import subprocess
from pathlib import Path

import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import SingleThreadedExecutor
from std_msgs.msg import String

from hindrax_bringup.recording.info import bag_info
from hindrax_bringup.recording.make_test_bags import STREAMS
from hindrax_bringup.recording.metadata import read_metadata
from hindrax_common.testing import child_env, python_executable, ros_context, wait_until
from hindrax_test_support.helpers import burst_qos
from hindrax_onboard.cli import main as cli_main

DATA = Path(__file__).parent / "data"


def test_bag_info_reports_topics_types_counts_rates_duration_and_size(capsys):
    assert cli_main(["bag", "info", str(DATA / "sensors_4s")]) == 0
    out = capsys.readouterr().out
    # 4 s of samples at t = k / rate (k = 0 .. 4 rate - 1): the span is 4 s - one period of the fastest stream
    assert re.search(r"Duration:\s+3\.990 s", out)
    for s in STREAMS:
        n = int(4 * s.rate_hz)
        line = next(ln for ln in out.splitlines() if ln.strip().startswith(s.topic + " "))
        cols = line.split()
        assert cols[1] == s.type and int(cols[2]) == n
        assert float(cols[3]) == pytest.approx(s.rate_hz, rel=1e-6)  # (n - 1) / span = rate exactly
    assert f"Messages:     {sum(int(4 * s.rate_hz) for s in STREAMS)}" in out
    size = (DATA / "sensors_4s" / "sensors_4s_0.mcap").stat().st_size
    assert bag_info(DATA / "sensors_4s").size_bytes == size
    assert "chunk compression zstd" in out


def test_bag_info_on_split_bag_and_single_file():
    info = bag_info(DATA / "split_3s")
    assert [f.name for f in info.files] == ["split_3s_0.mcap", "split_3s_1.mcap", "split_3s_2.mcap"]
    assert info.message_count == read_metadata(DATA / "split_3s").message_count == sum(
        int(3 * s.rate_hz) for s in STREAMS)
    one = bag_info(DATA / "split_3s" / "split_3s_1.mcap")
    assert 0 < one.message_count < info.message_count


def test_bag_info_bad_input_is_one_line(tmp_path, capsys):
    assert cli_main(["bag", "info", str(tmp_path / "missing")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no such bag" in err[0]
    (tmp_path / "empty").mkdir()
    assert cli_main(["bag", "info", str(tmp_path / "empty")]) == 1
    assert "no .mcap files" in capsys.readouterr().err


@pytest.mark.ros
def test_bag_record_until_interrupted(tmp_path):
    bag = tmp_path / "cli_bag"
    proc = subprocess.Popen([python_executable(), "-m", "hindrax_onboard.cli", "bag", "record",
                             "--topics", "/cli/a",
                             "--regex", "^/cli/re", "--out", str(bag)],
                            env=child_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        with ros_context() as ctx:
            node = rclpy.create_node("cli_record_test", context=ctx)
            ex = SingleThreadedExecutor(context=ctx)
            ex.add_node(node)
            spin = lambda: ex.spin_once(timeout_sec=0.02)  # noqa: E731
            counts = {}
            node.create_subscription(DiagnosticArray, "/diagnostics", lambda m: counts.update(
                {kv.key[6:]: int(kv.value) for st in m.status for kv in st.values if kv.key.startswith("topic:")}),
                10)
            a = node.create_publisher(String, "/cli/a", burst_qos())  # all 7, however the match ends
            b = node.create_publisher(String, "/cli/regex_match", burst_qos())
            c = node.create_publisher(String, "/cli/other", 10)
            wait_until(lambda: (a.get_subscription_count() and b.get_subscription_count()) or proc.poll() is not None,
                       20, spin, "record subscribed")
            assert proc.poll() is None, proc.stderr.read().decode()
            for i in range(7):
                a.publish(String(data=f"a{i}"))
                b.publish(String(data=f"b{i}"))
                c.publish(String(data=f"c{i}"))
            wait_until(lambda: counts.get("/cli/a") == 7 and counts.get("/cli/regex_match") == 7, 20, spin,
                       "14 messages recorded")
            ex.shutdown()
            node.destroy_node()
        proc.send_signal(signal.SIGINT)
        assert proc.wait(20) == 0
        out = proc.stdout.read().decode()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
    assert f"{bag}: 14 messages on 2 topics" in out
    meta = read_metadata(bag)
    assert {t.name: t.message_count for t in meta.topics} == {"/cli/a": 7, "/cli/regex_match": 7}


@pytest.mark.ros
def test_bag_record_duration_stops_by_itself_and_finishes_the_bag(tmp_path):
    bag = tmp_path / "timed"
    proc = subprocess.Popen([python_executable(), "-m", "hindrax_onboard.cli", "bag", "record",
                             "--all", "--out",
                             str(bag), "--duration", "0.5"], env=child_env(), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    try:
        assert proc.wait(30) == 0, proc.stderr.read().decode()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
    meta = read_metadata(bag)  # finished: metadata.yaml and a complete file
    assert meta.relative_file_paths == ["timed_0.mcap"]
    from hindrax_bringup.recording.recover import is_complete

    assert is_complete(bag / "timed_0.mcap")


def test_bag_record_rejects_a_bad_regex_and_existing_bag(tmp_path, capsys):
    # runs in-process: the error comes before anything is recorded
    assert cli_main(["bag", "record", "--regex", "(", "--out", str(tmp_path / "x"), "--duration", "0.1"]) == 1
    assert "regular expression" in capsys.readouterr().err
    assert cli_main(["bag", "record", "--out", str(DATA / "sensors_4s"), "--duration", "0.1"]) == 1
    assert "already holds a bag" in capsys.readouterr().err
