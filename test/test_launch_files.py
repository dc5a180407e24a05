"""Launch files (ROS 2 launch XML) checked without the `launch` package, which is not installable here.

Every ``src/*/launch/*.launch.xml`` is parsed with xml.etree; ``$(var ...)`` and ``$(find-pkg-share ...)`` are
substituted the way ros2 launch does, with find-pkg-share resolved through the packages' setup.py data_files (what
colcon installs under share/). Checked: each ``<node pkg exec>`` of our packages is a console script of that
package's setup.py (an external package only behind a condition that is off by default, never a hard exec_depend,
its apt package named in docs/deployment.md), each ``<param from>`` file and ``<include file>`` resolves to a file
that is installed, include arguments are declared by the included file, and conditions are booleans. The README's
``ros2 launch`` and ``ros2 run`` lines name existing launch files, declared arguments and installed executables.
"""
from __future__ import annotations

import re
import shlex
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import yaml
from hindrax_test_support.packages import setup_kwargs

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("hindrax_common", "hindrax_drivers", "hindrax_bringup", "hindrax_onboard", "hindrax_fit", "hindrax_sim",
            "hindrax_tools")


@pytest.fixture(scope="module")
def packages():
    """package -> (console script names, {installed share path relative to the prefix: source file})."""
    out = {}
    for pkg in PACKAGES:
        kw = setup_kwargs(pkg)
        console_scripts = kw.get("entry_points", {}).get("console_scripts", [])
        scripts = {s.split("=")[0].strip() for s in console_scripts}
        for s in console_scripts:
            module = s.split("=")[1].split(":")[0].strip()
            assert (REPO / "src" / pkg / (module.replace(".", "/") + ".py")).is_file(), s
        installed = {}
        for dest, files in kw["data_files"]:
            for f in files:
                installed[f"{dest}/{Path(f).name}"] = REPO / "src" / pkg / f
        out[pkg] = (scripts, installed)
    return out


def find_pkg_share(packages, pkg: str, rel: str) -> Path:
    key = f"share/{pkg}/{rel.lstrip('/')}"
    assert pkg in packages, f"$(find-pkg-share {pkg}): not a package of this workspace"
    assert key in packages[pkg][1], f"{key} is not installed by {pkg}'s setup.py"
    return packages[pkg][1][key]


def substitute(text: str, args: dict[str, str], packages) -> str:
    def var(m):
        assert m.group(1) in args, f"$(var {m.group(1)}) is not a declared argument"
        return args[m.group(1)]
    text = re.sub(r"\$\(var (\w+)\)", var, text)
    m = re.fullmatch(r"\$\(find-pkg-share (\w+)\)(/.*)?", text)
    if m:
        return str(find_pkg_share(packages, m.group(1), m.group(2) or ""))
    assert "$(" not in text, f"unsupported substitution in {text!r}"
    return text


def declared_args(path: Path) -> dict[str, str | None]:
    return {a.get("name"): a.get("default") for a in ET.parse(path).getroot().findall("arg")}


def check_launch(path: Path, packages, given: dict[str, str] | None = None) -> list[tuple[str, str]]:
    """Validate one launch file with the given argument values; returns the (pkg, exec) of its nodes, includes too."""
    root = ET.parse(path).getroot()
    assert root.tag == "launch"
    args: dict[str, str] = {}
    for a in root.findall("arg"):
        assert a.get("description"), f"{path.name}: argument {a.get('name')} has no description"
        value = (given or {}).get(a.get("name"), a.get("default"))
        assert value is not None, f"{path.name}: argument {a.get('name')} has no value"
        args[a.get("name")] = substitute(value, args, packages)
    for name in given or {}:
        assert name in args, f"{path.name}: no argument {name!r}"
    nodes = []
    elements = list(root)
    while elements:
        el = elements.pop(0)
        cond = el.get("if")
        enabled = True
        for attr, want in (("if", "true"), ("unless", "false")):
            if el.get(attr) is not None:
                value = substitute(el.get(attr), args, packages)
                assert value in ("true", "false"), f"{path.name}: condition {el.get(attr)} is not a boolean"
                enabled = enabled and value == want
        if el.tag == "node":
            pkg, exe = el.get("pkg"), el.get("exec")
            if pkg in packages:
                assert exe in packages[pkg][0], f"{path.name}: {pkg}/{exe} is not an installed executable"
            else:  # an external package: optional, off by default, not a hard dependency, documented
                default = substitute(cond, {k: v or "" for k, v in declared_args(path).items()}, packages) \
                    if cond else "true"
                assert default == "false", f"{path.name}: external {pkg}/{exe} must be optional and off by default"
                deps = "".join((REPO / "src" / p / "package.xml").read_text() for p in PACKAGES)
                assert f"<exec_depend>{pkg}</exec_depend>" not in deps, \
                    f"{pkg} is optional: rosdep must not install it with every vehicle (package.xml exec_depend)"
                apt = "ros-jazzy-" + pkg.replace("_", "-")
                assert apt in (REPO / "docs" / "deployment.md").read_text(), f"docs/deployment.md: how to install {apt}"
            for p in el.findall("param"):
                if p.get("from"):
                    f = Path(substitute(p.get("from"), args, packages))
                    assert f.is_file(), f"{path.name}: parameter file {f} does not exist"
                    doc = yaml.safe_load(f.read_text())
                    assert any("ros__parameters" in v for v in doc.values()), f"{f} is not a params file"
                else:
                    assert p.get("name") and p.get("value") is not None
                    substitute(p.get("value"), args, packages)
            if enabled:
                nodes.append((pkg, exe))
        elif el.tag == "include":
            inc = Path(substitute(el.get("file"), args, packages))
            assert inc.is_file(), f"{path.name}: include {inc} does not exist"
            passed = {a.get("name"): substitute(a.get("value"), args, packages) for a in el.findall("arg")}
            if enabled:
                nodes += check_launch(inc, packages, passed)
        elif el.tag == "group":  # scoped (ROS 2 launch's default): what an <include> in it sets stays inside
            assert el.get("scoped", "true") == "true", f"{path.name}: an unscoped <group>"
            if enabled:
                elements[:0] = list(el)
        elif el.tag == "set_env":  # the DDS transport (hindrax_common.process.dds_transport): its files must exist
            value = substitute(el.get("value"), args, packages)
            if el.get("name") == "FASTRTPS_DEFAULT_PROFILES_FILE":
                assert Path(value).is_file(), f"{path.name}: DDS profile {value} does not exist"
        else:
            assert el.tag == "arg", f"{path.name}: unexpected element <{el.tag}>"
    return nodes


def launch_files():
    return sorted(REPO.glob("src/*/launch/*.launch.xml"))


def test_there_are_vehicle_and_pool_test_launch_files():
    names = {p.name for p in launch_files()}
    assert {"vehicle.launch.xml", "pool_test.launch.xml"} <= names


@pytest.mark.parametrize("path", launch_files(), ids=lambda p: p.name)
def test_launch_file_executables_and_parameter_files_resolve(path, packages):
    nodes = check_launch(path, packages)
    assert nodes
    # every launch file is installed
    pkg = path.parents[1].name
    assert find_pkg_share(packages, pkg, f"launch/{path.name}") == path


def test_vehicle_and_pool_test_start_what_the_campaign_needs(packages):
    from hindrax_bringup.layout.composition import GROUPS, IDENT_GROUPS

    root = REPO / "src"
    vehicle = dict.fromkeys(check_launch(root / "hindrax_bringup/launch/vehicle.launch.xml", packages))
    # every node runs once, alone (its own executable) or in a composed process (hindrax_bringup.layout.composition)
    alone = {"allocation_node": "thrust_allocation"}  # executables named otherwise than their node
    nodes = [n for pkg, exe in vehicle if pkg == "hindrax_bringup"
             for n in GROUPS.get(exe, (alone.get(exe, exe.removesuffix("_node")),))]
    for node in ("dvl75", "ping1d", "ms5837", "icm20948", "esc", "thrust_allocation", "static_tf", "supervisor",
                 "output_guard"):
        assert nodes.count(node) == 1, node
    # the ESC shares its process with its one commander only; the supervisor and the output guard run alone
    # (docs/architecture.md §8, §10.1)
    assert GROUPS["actuation_node"] == ("thrust_allocation", "esc")
    for exe in ("supervisor_node", "output_guard_node"):
        assert ("hindrax_bringup", exe) in vehicle and exe not in GROUPS
    assert ("hindrax_bringup", "recorder_node") not in vehicle  # recording is optional there
    recorded = check_launch(root / "hindrax_bringup/launch/vehicle.launch.xml", packages,
                            {"record": "true", "output_dir": "/ws/runs"})
    assert ("hindrax_bringup", "recorder_node") in recorded
    pool = check_launch(root / "hindrax_onboard/launch/pool_test.launch.xml", packages)
    # the pool test records in the identification's process (hindrax_onboard.composition), never twice
    assert ("hindrax_bringup", "recorder_node") not in pool and ("hindrax_onboard", "ident_record_node") in pool
    assert IDENT_GROUPS["ident_record_node"] == ("identification", "controller", "recorder")
    unrecorded = check_launch(root / "hindrax_onboard/launch/pool_test.launch.xml", packages, {"record": "false"})
    assert ("hindrax_onboard", "ident_control_node") in unrecorded
    assert not {exe for _pkg, exe in unrecorded} & {"recorder_node", "ident_record_node"}
    assert ("foxglove_bridge", "foxglove_bridge") not in pool
    live = check_launch(root / "hindrax_onboard/launch/pool_test.launch.xml", packages, {"foxglove": "true"})
    assert ("foxglove_bridge", "foxglove_bridge") in live
    # the pool test runs the identification node and the controller in one process (hindrax_onboard.composition);
    # the controller is optional (off by default) in the vehicle, alone there
    assert IDENT_GROUPS["ident_control_node"] == ("identification", "controller")
    assert ("hindrax_onboard", "controller_node") not in vehicle
    held = check_launch(root / "hindrax_bringup/launch/vehicle.launch.xml", packages,
                        {"controller": "true", "model_file": "/ws/runs/x/identification.yaml"})
    assert ("hindrax_onboard", "controller_node") in held


def test_checker_rejects_a_missing_executable_and_a_missing_parameter_file(packages, tmp_path):
    bad = tmp_path / "bad.launch.xml"
    bad.write_text('<launch><node pkg="hindrax_drivers" exec="no_such_node"/></launch>')
    with pytest.raises(AssertionError, match="no_such_node"):
        check_launch(bad, packages)
    bad.write_text('<launch><node pkg="hindrax_drivers" exec="dvl75_node">'
                   '<param from="$(find-pkg-share hindrax_common)/config/missing.yaml"/></node></launch>')
    with pytest.raises(AssertionError, match="missing.yaml"):
        check_launch(bad, packages)


def readme_commands(section: str = "## Running on the Pi") -> list[str]:
    text = (REPO / "README.md").read_text()
    start = text.index(section)
    end = text.find("\n## ", start + 1)
    body = text[start:end if end > 0 else None]
    lines = []
    for block in re.findall(r"```(?:bash|sh)?\n(.*?)```", body, re.S):
        for line in block.splitlines():
            line = line.split(" #")[0].strip()
            if line and not line.startswith("#"):
                lines.append(line)
    return lines


def test_readme_ros2_launch_and_run_lines_name_installed_files_and_arguments(packages):
    commands = readme_commands()
    launches = [c for c in commands if c.startswith("ros2 launch ")]
    runs = [c for c in commands if c.startswith("ros2 run ")]
    assert launches and runs
    for c in launches:
        words = shlex.split(c)
        pkg, name = words[2], words[3]
        path = find_pkg_share(packages, pkg, f"launch/{name}")
        given = dict(w.split(":=", 1) for w in words[4:])
        check_launch(path, packages, given)
    for c in runs:
        words = shlex.split(c)
        assert words[3] in packages[words[2]][0], c


#: The build-and-run lines of the README's "Running on the Pi", as test/test_ros_install.py runs them (there in a
#: temporary copy of the workspace, with the install space's absolute paths).
TESTED_BY_INSTALL_TEST = {
    "make ros-install",
    "source .venv/bin/activate && source ros_ws/install/setup.bash",
    "hindrax config check",
    "ros_ws/install/lib/hindrax_bringup/allocation_node --ros-args --params-file "
    "ros_ws/install/share/hindrax_common/config/hindrax.yaml",
    "ros_ws/install/lib/hindrax_drivers/static_tf_node --ros-args --params-file "
    "ros_ws/install/share/hindrax_common/config/hindrax.yaml",
}


#: README lines run by other tests: the installed `hindrax health` against the launch layout (test/test_pool_day.py;
#: its verdicts in src/hindrax_tools/test/test_cli_health.py) and the symlink build (test/test_ros_install.py)
TESTED_ELSEWHERE = ("hindrax health", "make ros-install COLCON_ARGS=--symlink-install")


def test_every_readme_pi_command_is_a_tested_one():
    commands = readme_commands()
    assert TESTED_BY_INSTALL_TEST <= set(commands)
    for c in commands:
        assert c in TESTED_BY_INSTALL_TEST or c.startswith(("ros2 launch ", "ros2 run ") + TESTED_ELSEWHERE), \
            f"untested README line: {c}"


#: argument sets each launch file is read with below (the defaults, and what the vehicle and the pool day pass)
READER_CASES = [
    ("hindrax_bringup/launch/vehicle.launch.xml", {}),
    ("hindrax_bringup/launch/vehicle.launch.xml", {"record": "true", "output_dir": "/var/lib/hindrax/runs"}),
    ("hindrax_onboard/launch/pool_test.launch.xml", {}),
    ("hindrax_onboard/launch/pool_test.launch.xml", {"output_dir": "/tmp/runs", "foxglove": "true"}),
]


@pytest.mark.parametrize("rel,given", READER_CASES, ids=lambda c: str(c))
def test_process_runner_list_is_what_the_launch_file_declares(rel, given, packages):
    """The pool-day test runs the process list of hindrax_bringup.layout.launch_xml through the project's runner; it
    must be the one the launch file declares, read here by this module's own parser (check_launch)."""
    from hindrax_bringup.layout.launch_xml import read_launch

    path = REPO / "src" / rel
    declared = check_launch(path, packages, given)
    read = read_launch(path, given, find_share=lambda pkg: REPO / "src" / pkg)
    assert [(p.package, p.executable) for p in read] == declared
    # each node: its name, the vehicle file, respawn with a delay, exactly as the XML says
    xml_nodes = {}
    for f in (path, REPO / "src/hindrax_bringup/launch/vehicle.launch.xml"):
        for el in ET.parse(f).getroot().iter("node"):
            xml_nodes[el.get("name") or el.get("exec")] = el  # a composed process has no name (its nodes keep theirs)
    for p in read:
        el = xml_nodes[p.label]
        assert (el.get("pkg"), el.get("exec")) == (p.package, p.executable)
        assert p.respawn and el.get("respawn") == "true" and p.respawn_delay_s == float(el.get("respawn_delay")) > 0
        if p.package in PACKAGES:
            assert p.parameters[0].resolve() == (REPO / "ros_ws/config/hindrax.yaml").resolve()


def test_every_node_of_the_vehicle_respawns_and_the_recorder_gets_output_dir_as_its_root(packages):
    from hindrax_bringup.layout.launch_xml import read_launch
    from hindrax_bringup.recording.selection import TopicSelection

    for path in launch_files():
        for el in ET.parse(path).getroot().iter("node"):
            assert el.get("respawn") == "true" and float(el.get("respawn_delay", "0")) > 0, \
                f"{path.name}: {el.get('name')} does not respawn after a delay"
    read = read_launch(REPO / "src/hindrax_bringup/launch/vehicle.launch.xml", {"record": "true", "output_dir": "/x"},
                       find_share=lambda pkg: REPO / "src" / pkg)
    pool = read_launch(REPO / "src/hindrax_onboard/launch/pool_test.launch.xml", {"output_dir": "/x"},
                       find_share=lambda pkg: REPO / "src" / pkg)
    for recorder in (next(p for p in read if p.executable == "recorder_node"),
                     next(p for p in pool if p.executable == "ident_record_node")):
        values = {k: v for p in recorder.parameters if isinstance(p, dict) for k, v in p.items()}
        # the root of new timestamped bags (recording/bag_dir.py), not one bag directory the next launch would find
        assert values["recording.output_root"] == "/x" and "output_dir" not in values
        assert values["autostart"] is True and values["all_topics"] is True
    # the pool test's recorder leaves out what would cross a process for it alone (docs/pi_budget.md), nothing else
    values = {k: v for p in next(p for p in pool if p.executable == "ident_record_node").parameters
              if isinstance(p, dict) for k, v in p.items()}
    sel = TopicSelection(all_topics=True, exclude_regex=values["exclude_regex"])
    assert not [t for t in ("/esc/heartbeat", "/guard/heartbeat", "/supervisor/heartbeat",
                            "/thrusters/command_pulse_width", "/dvl/twist", "/dvl/altitude", "/ping/confidence",
                            "/pressure/temperature", "/imu/temperature", "/imu/mag") if sel.matches(t)]
    assert all(sel.matches(t) for t in ("/wrench", "/thrusters/pulse_width", "/supervisor/status", "/imu/data_raw",
                                        "/allocation/status", "/esc/output_state", "/diagnostics", "/dvl/data",
                                        "/ping/altitude", "/pressure/fluid_pressure", "/pressure/depth",
                                        "/raw/dvl75", "/raw/ping1d", "/raw/ms5837", "/raw/icm20948", "/raw/pca9685"))


def test_deployment_doc_names_installed_launch_files_declared_arguments_and_real_commands(packages):
    """docs/deployment.md, the "Running on the Pi" steps: each `ros2 launch PKG FILE [name:=value]` names an installed
    launch file and arguments it declares; each `hindrax <command>` is a registered command."""
    from hindrax_tools.cli import COMMANDS

    text = (REPO / "docs" / "deployment.md").read_text()
    launches = re.findall(r"ros2 launch (\w+) ([\w.]+\.launch\.xml)((?: \w+:=[^\s`]*)*)", text)
    assert len(launches) >= 2
    for pkg, name, args in launches:
        path = find_pkg_share(packages, pkg, f"launch/{name}")
        given = dict(a.split(":=", 1) for a in args.split())
        check_launch(path, packages, {k: v or "x" for k, v in given.items() if "$" not in v})
    registered = {" ".join(words) for words, _m, _h in COMMANDS}
    used = set(re.findall(r"`(?:docker exec -it hindrax )?hindrax ((?:[a-z][a-z0-9-]*)(?: [a-z-]+)?)", text))
    assert used and all(u in registered or u.split()[0] in registered for u in used), used - registered


def test_the_safety_processes_start_at_a_higher_priority_and_the_runner_applies_it(packages, tmp_path):
    """docs/deployment.md §1: the ESC (actuation_node), the supervisor, the output guard and the sensor drivers
    (whose rates the supervisor checks) ask for real-time scheduling (HINDRAX_REALTIME_PRIORITY, the guard highest,
    the sensors lowest; hindrax_common/process/scheduling.py) and run at nice -5 through launch-prefix where it is
    refused, nothing else does either, and the project's runner (pool-day test, bench) puts the prefix first and the
    variable in the environment as launch_ros does; the bare-metal unit and the compose file allow both."""
    from hindrax_bringup.layout.launch_xml import read_launch
    from hindrax_bringup.layout.process_runner import ProcessRunner

    read = read_launch(REPO / "src/hindrax_onboard/launch/pool_test.launch.xml", {},
                       find_share=lambda pkg: REPO / "src" / pkg)
    prefixed = {p.executable: p.launch_prefix for p in read if p.launch_prefix}
    assert prefixed == {e: ("nice", "-n", "-5") for e in ("sensors_node", "actuation_node", "supervisor_node",
                                                                   "output_guard_node")}
    # Jazzy's launch labels a prefixed process after the prefix ("[nice-3]") unless exec_name says otherwise
    assert {p.executable: p.exec_name for p in read if p.launch_prefix} == {e: e for e in prefixed}
    runner = ProcessRunner(read, log_dir=tmp_path, command=lambda p: ["/opt/x/" + p.executable])
    for p in read:
        argv = runner.argv(p)
        assert argv[:len(p.launch_prefix) + 2] == [*p.launch_prefix, "/opt/x/" + p.executable, "--ros-args"]
    assert "LimitNICE=-5" in (REPO / "docker/hindrax-bare-metal.service").read_text()
    assert "nice: 25" in (REPO / "docker/compose.yaml").read_text()
    from hindrax_common.process.scheduling import PRIORITY_ENV, PRIORITY_RANGE, requested_priority
    priority = {p.executable: requested_priority(dict(p.env)) for p in read}
    assert {e for e, v in priority.items() if v} == set(prefixed), priority
    assert priority["output_guard_node"] > priority["supervisor_node"] > priority["actuation_node"] \
        > priority["sensors_node"] >= PRIORITY_RANGE[0], priority
    for p in read:
        assert runner.environment(p).get(PRIORITY_ENV, "") == dict(p.env).get(PRIORITY_ENV, ""), p.label
    top = max(priority.values())
    assert f"LimitRTPRIO={top}" in (REPO / "docker/hindrax-bare-metal.service").read_text()
    assert f"rtprio: {top}" in (REPO / "docker/compose.yaml").read_text()


#: Node parameters outside the vehicle file that widen a safety timeout for a single-process graph (hindrax bringup:
#: config.node_parameters.declare_node_parameter); their defaults are the vehicle file's keys.
SINGLE_PROCESS_WIDENINGS = ("heartbeat_timeout_s", "steady_watchdog_timeout_s", "clock_stall_timeout_s")


@pytest.mark.parametrize("rel,given", READER_CASES, ids=lambda c: str(c))
def test_the_vehicle_launches_keep_the_vehicle_files_safety_timeouts(rel, given):
    """The launch files, where each safety node is a process of its own, set none of the single-process widenings:
    the ESC, the guard and the supervisor take esc.heartbeat_timeout_s, esc.guard_heartbeat_timeout_s,
    esc.watchdog_timeout_s and supervisor.rate_window_s from the vehicle file (0.2 s, not bringup's 2 s)."""
    from hindrax_common.config import flatten
    from hindrax_bringup.layout.launch_xml import read_launch

    processes = read_launch(REPO / "src" / rel, given, find_share=lambda pkg: REPO / "src" / pkg)
    seen: set[str] = set()
    for proc in processes:
        names: set[str] = set()
        for p in proc.parameters:
            if isinstance(p, dict):
                names |= set(p)
            else:
                doc = yaml.safe_load(Path(p).read_text())
                names |= {k for body in doc.values() for k in flatten(body.get("ros__parameters", {}))}
        assert not names & set(SINGLE_PROCESS_WIDENINGS), (proc.executable, sorted(names))
        seen |= names
    assert {"esc.heartbeat_timeout_s", "esc.guard_heartbeat_timeout_s"} <= seen  # the vehicle file was read
