"""Static TF node: publishes ``base_link`` -> every sensor and thruster frame on ``/tf_static``.

``ros2 run hindrax_drivers static_tf_node --ros-args --params-file hindrax.yaml``

Publishes one ``tf2_msgs/TFMessage`` holding all transforms (:func:`hindrax_drivers.tf.static_tf.vehicle_transforms`)
on ``/tf_static`` with the QoS of tf2_ros's ``StaticTransformBroadcaster``: reliable, transient local,
keep last, depth 1, so late subscribers (RViz, Foxglove, robot_localization) receive it. Stamped with the
node's clock at start-up (``use_sim_time`` supported; static transforms are valid at any time).

Parameters: the geometry keys of the vehicle file (:data:`hindrax_drivers.tf.static_tf.TF_KEYS`, read-only),
and the frame ids ``base_frame``, ``imu_frame``, ``dvl_frame``, ``ping_frame``, ``pressure_frame``,
``thruster_frame_prefix`` (read-only; defaults REP-103/105 names ``base_link``, ``imu_link`` ...)."""
from __future__ import annotations

from typing import Any

from geometry_msgs.msg import TransformStamped
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from tf2_msgs.msg import TFMessage

from hindrax_common.node_support.node_common import load_node_config, run_node
from hindrax_common.node_support.vehicle_node import VehicleNode
from .static_tf import DEFAULT_FRAME_IDS, TF_KEYS, vehicle_transforms

__all__ = ["StaticTfNode", "STATIC_TF_QOS", "main"]

#: tf2_ros StaticBroadcasterQoS: reliable, transient local, keep last 1.
STATIC_TF_QOS = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.TRANSIENT_LOCAL)

_FRAME_PARAMS = {"base": "base_frame", "imu": "imu_frame", "dvl": "dvl_frame", "ping": "ping_frame",
                 "pressure": "pressure_frame", "thruster_prefix": "thruster_frame_prefix"}


class StaticTfNode(VehicleNode):
    """Publishes the vehicle's static transforms once at start-up (latched). Raises ConfigError."""

    def __init__(self, node_name: str = "static_tf", **kwargs: Any):
        super().__init__(node_name, **kwargs)
        cfg = load_node_config(self, TF_KEYS)
        ids = {}
        for key, param in _FRAME_PARAMS.items():
            what = "prefix of the thruster frame ids (thruster_1 ...)" if key == "thruster_prefix" else \
                f"frame id of the {key} frame"
            ids[key] = str(self.declare_parameter(
                param, DEFAULT_FRAME_IDS[key],
                ParameterDescriptor(description=what + " (restart to change)", read_only=True)).value)
        self.transforms = vehicle_transforms(cfg, ids)
        self.publisher = self.create_publisher(TFMessage, "/tf_static", STATIC_TF_QOS)
        stamp = self.get_clock().now().to_msg()
        msg = TFMessage()
        for t in self.transforms:
            m = TransformStamped()
            m.header.stamp, m.header.frame_id, m.child_frame_id = stamp, t.parent, t.child
            m.transform.translation.x, m.transform.translation.y, m.transform.translation.z = (
                float(v) for v in t.translation_m)
            (m.transform.rotation.x, m.transform.rotation.y, m.transform.rotation.z,
             m.transform.rotation.w) = (float(v) for v in t.quaternion_xyzw)
            msg.transforms.append(m)
        self.message = msg
        self.publisher.publish(msg)
        self.get_logger().info(f"/tf_static: {len(msg.transforms)} transforms from {ids['base']} "
                               f"({', '.join(t.child for t in self.transforms)})")


def main(args=None) -> int:
    """Entry point ``static_tf_node``."""
    return run_node(StaticTfNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
