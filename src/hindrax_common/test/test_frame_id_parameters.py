"""Frame ids are node parameters (REP-103/105 defaults); a value tf2 cannot use stops start-up with one line."""
from __future__ import annotations

import pytest
import rclpy
from rclpy.parameter import Parameter

from hindrax_common.node_support.node_common import declare_frame_ids
from hindrax_common.testing import ros_context

pytestmark = pytest.mark.ros


def test_defaults_overrides_and_bad_values():
    with ros_context() as ctx:
        node = rclpy.create_node("frames_default", context=ctx)
        assert declare_frame_ids(node, {"frame_id": "imu_link"}) == {"frame_id": "imu_link"}
        assert node.describe_parameter("frame_id").read_only
        node.destroy_node()
        node = rclpy.create_node("frames_set", context=ctx, parameter_overrides=[Parameter("frame_id", value="imu2")])
        assert declare_frame_ids(node, {"frame_id": "imu_link"}) == {"frame_id": "imu2"}
        node.destroy_node()
        for bad in ("", "/imu_link"):
            node = rclpy.create_node("frames_bad", context=ctx, parameter_overrides=[Parameter("frame_id", value=bad)])
            with pytest.raises(ValueError, match=r"^parameter frame_id: .* is not a tf2 frame id"):
                declare_frame_ids(node, {"frame_id": "imu_link"})
            node.destroy_node()
