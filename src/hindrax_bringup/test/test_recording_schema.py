"""Schemas, type hashes, QoS metadata and topic selection as rosbag2 (Jazzy) writes them.

Expected values follow the rules in docs/architecture.md §11.6 and rosbag2's
local_message_definition_source.cpp / qos.cpp; the type hash is cross-checked against the hash the
ROS graph itself reports for a live publisher.
"""
from __future__ import annotations

import sys
from pathlib import Path

import pytest
import yaml
from hindrax_common.cdr import msgdefs
from hindrax_bringup.recording.qos import (INFINITE_NS, default_profile, duration_to_dict,
                                           playback_profile, profile_from_rclpy, profiles_from_yaml,
                                           profiles_to_yaml, recorder_policies, subscription_policies)
from hindrax_bringup.recording.selection import TopicSelection

SHARE = Path(sys.prefix) / "share"
SEP = "\n" + "=" * 80 + "\n"


def msg_text(pkg: str, name: str) -> str:
    return (SHARE / pkg / "msg" / f"{name}.msg").read_text()


def test_imu_definition_is_msg_text_then_sorted_dependencies_depth_first():
    # sensor_msgs/Imu uses std_msgs/Header, geometry_msgs/Quaternion, geometry_msgs/Vector3; Header uses
    # builtin_interfaces/Time. Sorted: Quaternion, Vector3, Header (then its Time, depth first).
    expected = (msg_text("sensor_msgs", "Imu")
                + SEP + "MSG: geometry_msgs/Quaternion\n" + msg_text("geometry_msgs", "Quaternion")
                + SEP + "MSG: geometry_msgs/Vector3\n" + msg_text("geometry_msgs", "Vector3")
                + SEP + "MSG: std_msgs/Header\n" + msg_text("std_msgs", "Header")
                + SEP + "MSG: builtin_interfaces/Time\n" + msg_text("builtin_interfaces", "Time"))
    assert msgdefs.message_definition("sensor_msgs/msg/Imu") == expected


def definitions_in(full_text: str) -> list[str]:
    """The ``pkg/Type`` names listed by ``MSG:`` lines of a full definition, in order."""
    return [line[5:].strip() for line in full_text.split("\n") if line.startswith("MSG: ")]


def test_bare_type_names_resolve_in_the_same_package_and_dependencies_appear_once():
    # geometry_msgs/Wrench.msg says "Vector3 force" and "Vector3 torque" (no package): geometry_msgs/Vector3,
    # listed once, right after Wrench (depth first), before std_msgs/Header.
    text = msgdefs.message_definition("geometry_msgs/msg/WrenchStamped")
    assert definitions_in(text) == ["geometry_msgs/Wrench", "geometry_msgs/Vector3",
                                    "std_msgs/Header", "builtin_interfaces/Time"]


def test_custom_message_definitions_come_from_the_installed_share_directory():
    raw = msgdefs.message_definition("hindrax_msgs/msg/RawDeviceData")
    assert raw.startswith(msg_text("hindrax_msgs", "RawDeviceData"))
    assert definitions_in(raw) == ["std_msgs/Header", "builtin_interfaces/Time"]
    dvl = msgdefs.message_definition("hindrax_msgs/Dvl")  # short form accepted
    assert definitions_in(dvl) == ["geometry_msgs/Quaternion", "geometry_msgs/Vector3",
                                   "std_msgs/Header", "builtin_interfaces/Time"]


def test_every_definition_parses_with_mcap_ros2():
    from mcap_ros2._dynamic import generate_dynamic

    for t in ("sensor_msgs/msg/Imu", "sensor_msgs/msg/MagneticField", "sensor_msgs/msg/Range",
              "sensor_msgs/msg/FluidPressure", "geometry_msgs/msg/WrenchStamped", "hindrax_msgs/msg/Dvl",
              "hindrax_msgs/msg/RawDeviceData", "hindrax_msgs/msg/ThrusterPwm", "diagnostic_msgs/msg/DiagnosticArray"):
        assert t in generate_dynamic(t, msgdefs.message_definition(t))


def test_unknown_or_malformed_types_raise_clear_errors():
    with pytest.raises(msgdefs.DefinitionNotFoundError, match="nonexistent_msgs/msg/Foo.msg"):
        msgdefs.message_definition("nonexistent_msgs/msg/Foo")
    with pytest.raises(ValueError, match="not understood"):
        msgdefs.message_definition("no slash")
    with pytest.raises(msgdefs.DefinitionNotFoundError):
        msgdefs.type_description_hash("nonexistent_msgs/msg/Foo")


@pytest.mark.ros
def test_type_hash_matches_the_hash_the_ros_graph_reports():
    import rclpy
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Imu

    from hindrax_common.testing import ros_context
    from hindrax_msgs.msg import RawDeviceData

    with ros_context() as ctx:
        node = rclpy.create_node("hash_probe", context=ctx)
        node.create_publisher(Imu, "/hash_probe/imu", qos_profile_sensor_data)
        node.create_publisher(RawDeviceData, "/hash_probe/raw", 10)
        for topic, type_name in (("/hash_probe/imu", "sensor_msgs/msg/Imu"),
                                 ("/hash_probe/raw", "hindrax_msgs/msg/RawDeviceData")):
            (info,) = node.get_publishers_info_by_topic(topic)
            assert msgdefs.type_description_hash(type_name) == str(info.topic_type_hash)
            assert str(info.topic_type_hash).startswith("RIHS01_")
        # QoS of a sensor-data publisher as the graph reports it, in rosbag2 version-9 form
        (imu,) = node.get_publishers_info_by_topic("/hash_probe/imu")
        prof = profile_from_rclpy(imu.qos_profile)
        assert prof["reliability"] == "best_effort" and prof["durability"] == "volatile"
        assert prof["deadline"] == {"sec": 9223372036, "nsec": 854775807}
        assert prof["liveliness"] == "automatic"
        node.destroy_node()


def test_a_recorded_type_matches_the_installed_one_only_with_the_same_fields():
    """Comments do not matter; a missing field does (a bag from before ThrusterPwm gained output_state must be
    decoded from its own stored definition, not by the installed class)."""
    name = "hindrax_msgs/msg/ThrusterPwm"
    now = msgdefs.message_definition(name)
    assert msgdefs.matches_installed(name, now)
    commented = "# a comment the recording had\n" + now.replace("bool armed", "bool  armed # x")
    assert msgdefs.matches_installed(name, commented)
    before = "\n".join(line for line in now.split("\n") if not line.startswith("uint8 "))  # fields of issue 23 gone
    assert before != now and not msgdefs.matches_installed(name, before)
    assert msgdefs.matches_installed(name, before, msgdefs.type_description_hash(name))  # the hash decides
    assert not msgdefs.matches_installed(name, now, "RIHS01_" + "0" * 64)
    assert not msgdefs.matches_installed("hindrax_msgs/msg/NoSuchType", now)


def test_qos_yaml_layout_and_round_trip():
    p = default_profile("best_effort", "transient_local", depth=5)
    text = profiles_to_yaml([p])
    doc = yaml.safe_load(text)
    assert list(doc[0]) == ["history", "depth", "reliability", "durability", "deadline", "lifespan", "liveliness",
                            "liveliness_lease_duration", "avoid_ros_namespace_conventions"]
    assert profiles_from_yaml(text) == [p]
    assert profiles_to_yaml([]) == "[]" and profiles_from_yaml("") == []
    # version <= 8 integer enums (RMW values) are read as names
    old = "- history: 1\n  depth: 10\n  reliability: 2\n  durability: 1\n  liveliness: 1\n"
    (q,) = profiles_from_yaml(old)
    assert (q["history"], q["reliability"], q["durability"], q["liveliness"]) == (
        "keep_last", "best_effort", "transient_local", "automatic")


def test_infinite_duration_is_rmw_duration_infinite():
    assert duration_to_dict(INFINITE_NS) == {"sec": 9223372036, "nsec": 854775807}
    assert duration_to_dict(1_500_000_000) == {"sec": 1, "nsec": 500_000_000}


def test_subscription_matches_every_publisher():
    rel, be = default_profile("reliable"), default_profile("best_effort")
    tl = default_profile("reliable", "transient_local")
    assert subscription_policies([rel, rel]) == ("reliable", "volatile")
    assert subscription_policies([rel, be]) == ("best_effort", "volatile")  # reliable sub would miss `be`
    assert subscription_policies([tl]) == ("reliable", "transient_local")
    assert subscription_policies([tl, rel]) == ("reliable", "volatile")
    assert subscription_policies([]) == ("reliable", "volatile")


def test_recorder_requests_best_effort_except_for_transient_local_topics():
    rel, be = default_profile("reliable"), default_profile("best_effort")
    tl = default_profile("reliable", "transient_local")
    assert recorder_policies([rel]) == ("best_effort", "volatile")
    assert recorder_policies([rel, be]) == ("best_effort", "volatile")
    assert recorder_policies([tl]) == ("reliable", "transient_local")  # the latched history needs a reliable reader
    assert recorder_policies([tl, rel]) == ("best_effort", "volatile")
    assert recorder_policies([]) == ("best_effort", "volatile")


def test_playback_offers_the_recorded_profile_when_publishers_agreed():
    be = default_profile("best_effort", depth=1)
    out = playback_profile([be, be])
    assert out["reliability"] == "best_effort" and out["history"] == "keep_last" and out["depth"] == 10
    mixed = playback_profile([be, default_profile("reliable")])
    assert mixed["reliability"] == "reliable" and mixed["durability"] == "volatile"


def test_topic_selection():
    s = TopicSelection(("imu/data", "/dvl/data"), regex=r"^/raw/")
    assert s.matches("/imu/data") and s.matches("/dvl/data") and s.matches("/raw/dvl75")
    assert not s.matches("/imu/mag")
    a = TopicSelection(all_topics=True, exclude_regex="rosout")
    assert a.matches("/imu/mag") and not a.matches("/_hidden/x") and not a.matches("/rosout")
    assert TopicSelection().empty and not TopicSelection().matches("/imu/data")
    with pytest.raises(ValueError, match="not a valid regular expression"):
        TopicSelection(regex="(")
