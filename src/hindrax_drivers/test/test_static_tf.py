"""Static TF from the vehicle file: geometry by hand (FRD about the CG -> base_link FLU), latched QoS, frame ids."""
from __future__ import annotations

import math

import numpy as np
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from tf2_msgs.msg import TFMessage

from hindrax_common.config import default_config_path, load_config
from hindrax_common.testing import config_parameters, ros_context, wait_until
from hindrax_drivers.tf.node import StaticTfNode
from hindrax_drivers.tf.static_tf import vehicle_transforms


def by_child(transforms):
    return {t.child: t for t in transforms}


def test_transforms_by_hand():
    cfg = load_config(default_config_path(), {
        "thrusters.t1.position_frd_m": [0.2, 0.15, 0.1], "thrusters.t1.direction_frd": [0.573576, 0.819152, 0.0],
        "thrusters.t5.position_frd_m": [0.2, 0.17, -0.12], "thrusters.t5.direction_frd": [0.0, 0.0, 1.0],
        "sensors.dvl75.position_frd_m": [0.0, 0.0, 0.18], "sensors.ms5837.position_frd_m": [-0.2, 0.0, -0.1],
        "sensors.icm20948.position_frd_m": [0.01, 0.02, 0.03], "sensors.icm20948.mounting_rpy_rad": [0.0, 0.0, 0.5]})
    tf = by_child(vehicle_transforms(cfg))
    assert set(tf) == {"imu_link", "dvl_link", "ping_link", "pressure_link"} | {f"thruster_{i}" for i in range(1, 9)}
    assert all(t.parent == "base_link" for t in tf.values())
    # FRD -> FLU: y and z change sign
    np.testing.assert_allclose(tf["thruster_1"].translation_m, [0.2, -0.15, -0.1])
    np.testing.assert_allclose(tf["thruster_5"].translation_m, [0.2, -0.17, 0.12])
    np.testing.assert_allclose(tf["dvl_link"].translation_m, [0.0, 0.0, -0.18])
    np.testing.assert_allclose(tf["pressure_link"].translation_m, [-0.2, 0.0, 0.1])
    np.testing.assert_allclose(tf["imu_link"].translation_m, [0.01, -0.02, -0.03])
    # T1 pushes forward and to starboard: in FLU a yaw of -55 deg, quaternion (0, 0, sin(-27.5 deg), cos(27.5 deg))
    h = math.radians(-55.0) / 2
    np.testing.assert_allclose(tf["thruster_1"].quaternion_xyzw, [0, 0, math.sin(h), math.cos(h)], atol=1e-5)
    # T5 pushes down (FRD +z): x of its frame along FLU -z, a pitch of +90 deg
    s = math.sqrt(0.5)
    np.testing.assert_allclose(tf["thruster_5"].quaternion_xyzw, [0, s, 0, s], atol=1e-9)
    np.testing.assert_allclose(tf["dvl_link"].quaternion_xyzw, [0, s, 0, s], atol=1e-9)
    np.testing.assert_allclose(tf["pressure_link"].quaternion_xyzw, [0, 0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(tf["imu_link"].quaternion_xyzw, [0, 0, math.sin(0.25), math.cos(0.25)], atol=1e-12)


def test_node_latches_on_tf_static_with_the_static_broadcaster_qos_and_frame_ids_from_parameters():
    with ros_context() as ctx:
        params = config_parameters() + [Parameter("base_frame", value="hull"),
                                        Parameter("thruster_frame_prefix", value="thr_")]
        node = StaticTfNode(context=ctx, parameter_overrides=params)
        listener = rclpy.create_node("tf_listener", context=ctx)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        ex.add_node(listener)
        try:
            got = []
            # a late subscriber still gets the message: transient local, reliable
            listener.create_subscription(TFMessage, "/tf_static", got.append, QoSProfile(
                depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL))
            wait_until(lambda: got, 10, lambda: ex.spin_once(timeout_sec=0.05), "/tf_static latched")
            children = {t.child_frame_id for t in got[0].transforms}
            assert {f"thr_{i}" for i in range(1, 9)} <= children and "imu_link" in children
            assert {t.header.frame_id for t in got[0].transforms} == {"hull"}
            info, = listener.get_publishers_info_by_topic("/tf_static")
            assert info.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
            assert info.qos_profile.reliability == ReliabilityPolicy.RELIABLE
            qos = node.publisher.qos_profile
            assert qos.depth == 1 and qos.history == HistoryPolicy.KEEP_LAST
            assert node.describe_parameter("base_frame").read_only
        finally:
            ex.shutdown()
            listener.destroy_node()
            node.destroy_node()


def test_a_missing_geometry_key_stops_the_node_with_one_line(tmp_path, monkeypatch):
    """With no vehicle file to fall back on, a key the overrides lack is reported as missing (key, allowed)."""
    from hindrax_common.config import ConfigError

    params = [p for p in config_parameters() if p.name != "sensors.dvl75.position_frd_m"]
    monkeypatch.setenv("HINDRAX_CONFIG", str(tmp_path / "absent.yaml"))
    with ros_context() as ctx:
        with pytest.raises(ConfigError, match=r"sensors.dvl75.position_frd_m is missing: allowed list of numbers"):
            StaticTfNode(context=ctx, parameter_overrides=params)
