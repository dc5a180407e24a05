"""Every node validates the vehicle it is started with as ``hindrax config check`` validates the file: a vehicle
file that ``config check`` refuses stops the node at start-up with the same one line (key, value, allowed range),
also for keys the node itself does not read (issue: ROS 2 ignores undeclared overrides, so a misspelt key used to
fall back silently to the shipped value)."""
import subprocess
import sys

import pytest
import yaml
from rclpy.parameter import Parameter

from hindrax_common.config import ConfigError, default_config_path, load_config
from hindrax_common.config.node_parameters import check_whole_vehicle
from hindrax_common.testing import child_env


def vehicle_doc() -> dict:
    return yaml.safe_load(default_config_path().read_text())


def mistakes() -> list[tuple[str, str, callable, str]]:
    """(node module, case, edit of the vehicle file, the line config check prints)."""
    def misspelt_depth(p):
        p["supervisor"]["max_dpth_m"] = p["supervisor"].pop("max_depth_m")

    def degrees_for_radians(p):
        p["limits"]["max_roll_rad"] = 46

    def misspelt_mass(p):
        p["vehicle"]["mas_kg"] = p["vehicle"].pop("mass_kg")

    return [
        ("hindrax_bringup.supervisor.node", "max_dpth_m", misspelt_depth,
         "supervisor.max_dpth_m = 1.65: unknown key (did you mean supervisor.max_depth_m?)"),
        # the supervisor and the ESC do not read limits.*: refused all the same
        ("hindrax_bringup.supervisor.node", "max_roll_rad", degrees_for_radians,
         "limits.max_roll_rad = 46: allowed number in [0, 3.14159]"),
        ("hindrax_drivers.pca9685.node", "mas_kg", misspelt_mass,
         "vehicle.mas_kg = 15.22: unknown key (did you mean vehicle.mass_kg?)"),
    ]


def test_config_check_refuses_each_file_with_the_line(tmp_path):
    for _module, case, edit, line in mistakes():
        doc = vehicle_doc()
        edit(doc["/**"]["ros__parameters"])
        path = tmp_path / f"{case}.yaml"
        path.write_text(yaml.safe_dump(doc))
        with pytest.raises(ConfigError) as err:
            load_config(path)
        assert line in err.value.lines(), err.value.lines()


def test_a_node_started_with_a_refused_file_exits_non_zero_with_the_line(tmp_path):
    procs = []
    path_of = {}
    for module, case, edit, line in mistakes():
        doc = vehicle_doc()
        edit(doc["/**"]["ros__parameters"])
        path = path_of[line] = tmp_path / f"{case}.yaml"
        path.write_text(yaml.safe_dump(doc))
        procs.append((line, subprocess.Popen(
            [sys.executable, "-m", module, "--ros-args", "--params-file", str(path)], env=child_env(),
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)))
    for line, proc in procs:
        try:
            _out, err = proc.communicate(timeout=120)
        finally:
            proc.kill()
        assert proc.returncode == 1, err
        stderr_lines = [x for x in err.splitlines() if x.startswith("invalid configuration: ")]
        assert len(stderr_lines) == 1 and line in stderr_lines[0], err
        # issue 74.8: the file passed is named (not the default file), and the line is said once (no log copy)
        assert f"(from {path_of[line]})" in stderr_lines[0] and err.count("invalid configuration") == 1, err


def test_overrides_equal_to_the_file_or_absent_are_not_checked_again():
    defaults = load_config(default_config_path()).to_ros_parameters()
    check_whole_vehicle({}, defaults, "x")
    check_whole_vehicle({"vehicle.mass_kg": defaults["vehicle.mass_kg"]}, defaults, "x")
    with pytest.raises(ConfigError, match=r"^x: supervisor\.rate_window_s = 60\.0: allowed at most"):
        check_whole_vehicle({"supervisor.rate_window_s": 60.0}, defaults, "x")


def test_an_in_process_node_refuses_an_unknown_vehicle_key_it_does_not_read():
    import rclpy

    from hindrax_bringup.guard.node import OutputGuardNode

    rclpy.init()
    try:
        with pytest.raises(ConfigError, match=r"vehicle\.colour = 'yellow': unknown key"):
            OutputGuardNode(parameter_overrides=[Parameter("vehicle.colour", value="yellow")])
    finally:
        rclpy.shutdown()


def test_the_output_guard_reads_its_own_heartbeat_timeout():
    """The guard ages the ESC's and the supervisor's heartbeats against esc.guard_heartbeat_timeout_s, not the
    ESC's esc.heartbeat_timeout_s (shipped 0.2 s each)."""
    import rclpy

    from hindrax_bringup.guard.node import OutputGuardNode

    assert load_config(default_config_path()).flat["esc.heartbeat_timeout_s"] == 0.2
    rclpy.init()
    try:
        guard = OutputGuardNode(parameter_overrides=[Parameter("esc.guard_heartbeat_timeout_s", value=0.35)])
        try:
            assert guard.timeout_s == guard.core.timeout_s == 0.35
            assert guard.get_parameter("heartbeat_timeout_s").value == 0.35  # its node parameter's default
            assert guard.esc_age.max_step_s == guard.supervisor_age.max_step_s == 0.35
        finally:
            guard.destroy_node()
    finally:
        rclpy.shutdown()


def test_the_esc_reads_its_bus_call_timeout():
    """The ESC's chip worker gives up on a bus call after esc.bus_call_timeout_s (shipped 0.15 s), so a vehicle
    file can set it."""
    import rclpy

    from hindrax_drivers.pca9685.node import EscNode

    assert load_config(default_config_path()).flat["esc.bus_call_timeout_s"] == 0.15
    rclpy.init()
    try:
        esc = EscNode(bus=None, chip_thread=False,
                      parameter_overrides=[Parameter("esc.bus_call_timeout_s", value=0.12)])
        try:
            assert esc.chip_io.call_timeout_s == 0.12
        finally:
            esc.destroy_node()
    finally:
        rclpy.shutdown()
