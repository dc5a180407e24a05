"""Crash safety (docs/architecture.md §7): a recorder SIGKILLed mid-run loses at most the chunk it was filling.

The recorder runs in a child process (python -m hindrax_bringup.recording.recorder_node) with small chunks;
this test publishes N numbered RawDeviceData messages, waits until the recorder reports (on /diagnostics)
that it has written all N, SIGKILLs it, recovers the bag and compares with what was published.
"""
from __future__ import annotations

import signal
import subprocess

import pytest
import rclpy
import yaml
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import SingleThreadedExecutor
from rclpy.serialization import serialize_message

from hindrax_common.process.conditions import ConditionTimeout
from hindrax_common.config import default_config_path
from hindrax_bringup.recording.reader import BagReader
from hindrax_bringup.recording.recover import is_complete, iter_file_records, recover_bag
from hindrax_common.testing import child_env, python_executable, ros_context, wait_until
from hindrax_test_support.helpers import burst_qos
from hindrax_msgs.msg import RawDeviceData

pytestmark = pytest.mark.ros
TOPIC = "/crash/raw"
N = 300
CHUNK_SIZE_BYTES = 4096


def params_file(tmp_path, **recording) -> str:
    """hindrax.yaml with some recording.* keys replaced, as a params file for the child."""
    doc = yaml.safe_load(default_config_path().read_text())
    doc["/**"]["ros__parameters"]["recording"].update(recording)
    path = tmp_path / "params.yaml"
    path.write_text(yaml.safe_dump(doc))
    return str(path)


def numbered(i: int) -> RawDeviceData:
    m = RawDeviceData(device_name="dvl75", transport=RawDeviceData.TRANSPORT_SERIAL, i2c_register=-1)
    m.data = i.to_bytes(4, "little") + bytes(96)
    return m


def start_recorder(tmp_path, bag, **recording) -> subprocess.Popen:
    cmd = [python_executable(), "-m", "hindrax_bringup.recording.recorder_node", "--ros-args",
           "--params-file", params_file(tmp_path, **recording), "-p", "autostart:=true", "-p", f"output_dir:={bag}",
           "-p", f"topics:=[{TOPIC}]", "-p", "discovery_period_s:=0.2", "-p", "status_period_s:=0.2"]
    return subprocess.Popen(cmd, env=child_env(), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)


def run_until_written(proc, ctx) -> None:
    """Publish N numbered messages once the recorder subscribed; return when it reports N written."""
    node = rclpy.create_node("crash_publisher", context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    written = {"n": -1}

    def on_diag(msg: DiagnosticArray) -> None:
        for st in msg.status:
            for kv in st.values:
                if kv.key == f"topic:{TOPIC}":
                    written["n"] = int(kv.value)

    node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, 10)
    pub = node.create_publisher(RawDeviceData, TOPIC, burst_qos())  # the whole burst, however the match ends
    spin = lambda: ex.spin_once(timeout_sec=0.02)  # noqa: E731
    try:
        wait_until(lambda: pub.get_subscription_count() > 0 or proc.poll() is not None, 20, spin,
                   "recorder subscribed")
        assert proc.poll() is None, proc.stderr.read().decode()
        for i in range(N):
            pub.publish(numbered(i))
        try:
            wait_until(lambda: written["n"] == N, 20, spin, f"recorder reports {N} messages written")
        except ConditionTimeout as exc:
            raise AssertionError(f"{exc}; its last report: {written['n']}") from None
    finally:
        ex.shutdown()
        node.destroy_node()


def recovered_indices(bag) -> list[int]:
    recover_bag(bag)
    from rclpy.serialization import deserialize_message

    return [int.from_bytes(bytes(deserialize_message(m.data, RawDeviceData).data[:4]), "little")
            for m in BagReader(bag).messages([TOPIC])]


def messages_per_chunk_max() -> int:
    """Upper bound of messages in one chunk: a chunk closes once it exceeds CHUNK_SIZE_BYTES, so it holds at
    most floor(CHUNK_SIZE_BYTES / record) + 1 message records (+ its schema and channel records)."""
    record = len(serialize_message(numbered(0))) + len(TOPIC) + 31  # MCAP message record overhead: 31 bytes
    return CHUNK_SIZE_BYTES // record + 1


def test_sigkill_loses_at_most_the_open_chunk(tmp_path):
    bag = tmp_path / "killed"
    # flush_interval_s 0: chunks are written only when full, so the open chunk really is lost
    proc = start_recorder(tmp_path, bag, chunk_size_bytes=CHUNK_SIZE_BYTES, flush_interval_s=0.0)
    try:
        with ros_context() as ctx:
            run_until_written(proc, ctx)
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
    assert not is_complete(bag / "killed_0.mcap")  # killed before a clean close: no summary, no footer
    got = recovered_indices(bag)
    lost = N - len(got)
    assert 0 <= lost <= messages_per_chunk_max()
    assert got == list(range(len(got)))  # what survived is the published prefix, in order, intact


def test_flush_interval_puts_the_open_chunk_on_disk_before_a_kill(tmp_path):
    bag = tmp_path / "flushed"
    proc = start_recorder(tmp_path, bag, chunk_size_bytes=CHUNK_SIZE_BYTES, flush_interval_s=0.3)
    try:
        with ros_context() as ctx:
            run_until_written(proc, ctx)
        mcap = bag / "flushed_0.mcap"
        on_disk = lambda: sum(1 for r in iter_file_records(mcap) if type(r).__name__ == "Message")  # noqa: E731
        wait_until(lambda: on_disk() == N, 10, message="open chunk flushed by the flush interval")
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
    assert recovered_indices(bag) == list(range(N))
