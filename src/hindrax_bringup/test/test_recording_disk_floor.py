"""The recorder stops cleanly when free disk space falls below recording.min_free_disk_mb (fake statvfs)."""
from __future__ import annotations

import types

import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from std_msgs.msg import String

from hindrax_bringup.recording.reader import BagReader
from hindrax_bringup.recording.recorder_node import RecorderNode
from hindrax_common.testing import config_parameters, ros_context, wait_until


class FakeDisk:
    """statvfs stand-in: ``free_mb`` megabytes available, 4 KiB blocks."""

    def __init__(self, free_mb: float):
        self.free_mb = free_mb
        self.calls = 0

    def __call__(self, path: str):
        self.calls += 1
        return types.SimpleNamespace(f_bavail=int(self.free_mb * 1e6 / 4096), f_frsize=4096)


@pytest.fixture()
def rig(tmp_path):
    disk = FakeDisk(free_mb=2000.0)
    with ros_context() as ctx:
        params = config_parameters({"recording.min_free_disk_mb": 100.0}) + [
            Parameter("topics", value=["/floor_test"]), Parameter("disk_check_period_s", value=0.05),
            Parameter("status_period_s", value=0.05)]
        node = RecorderNode(context=ctx, parameter_overrides=params, statvfs=disk)
        peer = node.create_publisher(String, "/floor_test", 10)  # same context, seen by discovery
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        try:
            yield types.SimpleNamespace(node=node, disk=disk, pub=peer, spin=lambda: ex.spin_once(timeout_sec=0.02),
                                        out=tmp_path / "bag")
        finally:
            node.shutdown()
            ex.shutdown()
            node.destroy_node()


def test_recording_stops_cleanly_below_the_floor_and_refuses_to_restart(rig):
    node = rig.node
    bag = node.start_recording(str(rig.out))
    n = {"sent": 0}

    def send():
        rig.pub.publish(String(data=f"m{n['sent']}"))
        n["sent"] += 1
        rig.spin()
    wait_until(lambda: node.subscribed_to(["/floor_test"]), 10, rig.spin, "recorder subscribed")
    wait_until(lambda: node.status().values and dict((v.key, v.value) for v in node.status().values)
               .get("topic:/floor_test", "0") not in ("0",), 10, send, "messages recorded")
    assert node.recording
    rig.disk.free_mb = 50.0  # below the 100 MB floor
    wait_until(lambda: not node.recording, 10, send, "recording stopped at the disk floor")
    st = node.status()
    assert st.level == st.ERROR and "recording.min_free_disk_mb = 100" in st.message and "50.0 MB" in st.message
    # the bag was finished: metadata.yaml written and every message readable
    assert (bag / "metadata.yaml").is_file()
    count = sum(1 for _ in BagReader(bag).messages())
    assert count >= 1 and node._last_metadata.message_count == count  # noqa: SLF001 - the stop's own result
    with pytest.raises(OSError, match="min_free_disk_mb"):
        node.start_recording(str(rig.out.parent / "again"))
    rig.disk.free_mb = 5000.0
    wait_until(lambda: node.status().level == node.status().OK, 10, rig.spin, "error cleared once space is back")
    assert node.start_recording(str(rig.out.parent / "again")).is_dir()


def test_no_check_when_the_floor_is_zero(tmp_path):
    disk = FakeDisk(free_mb=1.0)
    with ros_context() as ctx:
        node = RecorderNode(context=ctx, statvfs=disk,
                            parameter_overrides=config_parameters({"recording.min_free_disk_mb": 0.0}))
        try:
            assert node.start_recording(str(tmp_path / "bag")).is_dir() and disk.calls == 0
        finally:
            node.shutdown()
            node.destroy_node()
