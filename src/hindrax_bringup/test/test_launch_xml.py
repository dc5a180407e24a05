"""The launch XML reader (hindrax_bringup/layout/launch_xml.py): what ros2 launch would start, or a clear refusal.

Expected commands are written out by hand from launch_ros 0.26's Node (``--ros-args``, ``-r __node:=``, one
``--params-file`` per ``<param from>`` and per run of ``<param name value>``, then ``-r from:=to``)."""
from __future__ import annotations

from pathlib import Path

import pytest

from hindrax_bringup.layout.launch_xml import LaunchFileError, read_launch


def write(tmp_path: Path, name: str, text: str) -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.fixture
def share(tmp_path):
    (tmp_path / "pkg_a" / "config").mkdir(parents=True)
    (tmp_path / "pkg_a" / "config" / "v.yaml").write_text("/**:\n  ros__parameters: {}\n")
    return lambda pkg: tmp_path / pkg


def test_nodes_includes_groups_and_substitutions(tmp_path, share, monkeypatch):
    monkeypatch.setenv("HX_TEST_NS", "rov")
    write(tmp_path, "inner.launch.xml", """<launch>
      <arg name="cfg" description="x"/>
      <arg name="rec" default="false" description="x"/>
      <node pkg="pkg_a" exec="driver_node" name="driver" respawn="true" respawn_delay="1.5" output="screen">
        <param from="$(var cfg)"/>
        <param name="autostart" value="true"/>
        <param name="rate_hz" value="20.0"/>
        <param name="label" value="$(env HX_TEST_NS)"/>
        <remap from="imu" to="imu/raw"/>
      </node>
      <node pkg="pkg_a" exec="recorder_node" name="rec" if="$(var rec)"/>
    </launch>""")
    outer = write(tmp_path, "outer.launch.xml", """<launch>
      <arg name="record" default="false" description="x"/>
      <let name="cfg" value="$(find-pkg-share pkg_a)/config/v.yaml"/>
      <include file="%s/inner.launch.xml">
        <arg name="cfg" value="$(var cfg)"/>
        <arg name="rec" value="$(var record)"/>
      </include>
      <group if="$(var record)">
        <node pkg="pkg_a" exec="extra_node" name="extra" namespace="/$(env HX_TEST_NS)" args="--fast 2"/>
      </group>
      <node pkg="pkg_a" exec="tool" unless="$(var record)" name="tool"/>
    </launch>""" % tmp_path)
    off = read_launch(outer, {}, share)
    assert [(p.package, p.executable, p.name) for p in off] == [("pkg_a", "driver_node", "driver"),
                                                              ("pkg_a", "tool", "tool")]
    on = read_launch(outer, {"record": "TRUE"}, share)
    assert [p.name for p in on] == ["driver", "rec", "extra"]
    driver, _rec, extra = on
    assert driver.respawn and driver.respawn_delay_s == 1.5 and not extra.respawn
    written = []

    def values_file(values):
        written.append(dict(values))
        return Path(f"/tmp/values{len(written)}.yaml")
    assert driver.ros_arguments(values_file) == [
        "--ros-args", "-r", "__node:=driver", "--params-file", str(tmp_path / "pkg_a/config/v.yaml"),
        "--params-file", "/tmp/values1.yaml", "-r", "imu:=imu/raw"]
    # typed as launch_ros types a <param value>: YAML scalars
    assert written == [{"autostart": True, "rate_hz": 20.0, "label": "rov"}]
    assert extra.ros_arguments(values_file) == ["--fast", "2", "--ros-args", "-r", "__node:=extra", "-r",
                                                "__ns:=/rov"]


@pytest.mark.parametrize("body,given,message", [
    ('<node pkg="p" exec="e"/><timer period="1"/>', {}, "element <timer> is not supported"),
    ('<node pkg="p" exec="e" name="$(eval 1+1)"/>', {}, "substitution"),
    ('<arg name="a" description="x"/>', {}, "argument 'a' has no default"),
    ('<arg name="a" default="1" description="x"/>', {"b": "2"}, "b not declared"),
    ('<node pkg="p" exec="e" if="maybe"/>', {}, "expected true, false, 1 or 0"),
    ('<node pkg="p" exec="e" respawn_delay="-1"/>', {}, "non-negative"),
    ('<node pkg="p" exec="e" respawn_delay="$(var d)"/>', {}, "number of seconds"),
    ('<node pkg="p" exec="e" output_prefix="gdb"/>', {}, "output_prefix not supported"),
    ('<node pkg="p" exec="e"><param name="x"/></node>', {}, "without value="),
    ('<node pkg="p" exec="e" name="$(var nope)"/>', {}, "no such argument"),
])
def test_what_it_cannot_read_is_refused_in_one_line(tmp_path, share, body, given, message):
    f = write(tmp_path, "bad.launch.xml", f"<launch>{body}</launch>")
    with pytest.raises(LaunchFileError, match=message) as exc:
        read_launch(f, given, share)
    assert "\n" not in str(exc.value) and "bad.launch.xml" in str(exc.value)


def test_launch_prefix_is_split_as_a_shell_would_and_substituted(tmp_path, share):
    f = write(tmp_path, "p.launch.xml", '<launch><arg name="n" default="-5"/>'
              '<node pkg="p" exec="e" launch-prefix="nice -n $(var n)"/><node pkg="p" exec="f"/></launch>')
    first, second = read_launch(f, find_share=share)
    assert first.launch_prefix == ("nice", "-n", "-5") and second.launch_prefix == ()


def test_a_missing_file_and_a_wrong_root_are_refused(tmp_path, share):
    with pytest.raises(LaunchFileError, match="cannot read"):
        read_launch(tmp_path / "none.launch.xml", {}, share)
    with pytest.raises(LaunchFileError, match="expected <launch>"):
        read_launch(write(tmp_path, "x.launch.xml", "<node/>"), {}, share)

