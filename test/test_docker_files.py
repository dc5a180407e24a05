"""Deployment files that can be checked without Docker or systemd (docs/deployment.md §10): the entry point's
behaviour (run with fake ROS setup scripts and a fake ``ros2``/``hindrax``), and the image, compose file, units,
udev rules and chrony files read as text against what the vehicle needs: the launch layout (not the one-process
bringup), a health check, a non-root user in the device groups, devices through a /dev bind with cgroup rules,
layers ordered for rebuilds, a .dockerignore, rotated logs, a configurable recording folder, a per-vehicle domain
and time sync."""
import fnmatch
import os
import re
import subprocess
from pathlib import Path

import pytest
import yaml

from hindrax_common.config import default_config_path, load_config
from hindrax_bringup.layout.launch_xml import read_launch

REPO = Path(__file__).resolve().parents[1]
DOCKER = REPO / "docker"


def run_entrypoint(tmp_path, args, **env):
    ros = tmp_path / "ros_setup.bash"
    ros.write_text("export FAKE_ROS_SOURCED=1\n")
    ws = tmp_path / "ws_setup.bash"
    ws.write_text("export FAKE_WS_SOURCED=1\n")
    bindir = tmp_path / "bin"
    bindir.mkdir(exist_ok=True)
    for name in ("hindrax", "ros2"):
        fake = bindir / name
        fake.write_text(f"#!/usr/bin/env bash\necho \"RUN={name} $*\"\necho \"RANGE=$ROS_AUTOMATIC_DISCOVERY_RANGE\"\n"
                        "echo \"SECURITY=${ROS_SECURITY_ENABLE-unset} ${ROS_SECURITY_STRATEGY-} "
                        "${ROS_SECURITY_KEYSTORE-} "
                        "${ROS_SECURITY_ENCLAVE_OVERRIDE-}\"\n"
                        "echo \"DOMAIN=$ROS_DOMAIN_ID\"\necho \"SOURCED=$FAKE_ROS_SOURCED$FAKE_WS_SOURCED\"\n"
                        "echo \"CONFIG=${HINDRAX_CONFIG-unset}\"\n")
        fake.chmod(0o755)
    e = {k: v for k, v in os.environ.items() if not k.startswith(("ROS_", "HINDRAX_"))}
    (tmp_path / "keystore" / "enclaves").mkdir(parents=True, exist_ok=True)
    e.update(ROS_SETUP=str(ros), WS_SETUP=str(ws), PATH=f"{bindir}:{os.environ['PATH']}",
             HINDRAX_RUNS_DIR=str(tmp_path / "runs"), HINDRAX_KEYSTORE=str(tmp_path / "keystore"))
    e.update(env)
    return subprocess.run([str(DOCKER / "entrypoint.sh"), *args], capture_output=True, text=True, env=e, timeout=30)


def entrypoint_launch_arguments(tmp_path, **env) -> tuple[str, str, dict]:
    r = run_entrypoint(tmp_path, [], ROS_DOMAIN_ID="42", **env)
    assert r.returncode == 0, r.stderr
    words = next(line for line in r.stdout.splitlines() if line.startswith("RUN=")).split()
    assert words[:2] == ["RUN=ros2", "launch"]
    return words[2], words[3], dict(w.split(":=", 1) for w in words[4:])


# ---------------------------------------------------------------------------------------------- entry point
def test_entrypoint_runs_the_launch_layout_on_the_tether(tmp_path):
    r = run_entrypoint(tmp_path, [], ROS_DOMAIN_ID="42")
    assert r.returncode == 0, r.stderr
    runs = tmp_path / "runs"
    assert (f"RUN=ros2 launch hindrax_bringup vehicle.launch.xml record:=true output_dir:={runs} "
            "topside_domain_id:=42 topside_discovery_range:=SUBNET") in r.stdout
    # the vehicle's own processes: the internal domain, loopback only; only the gateway joins domain 42 (SUBNET)
    assert "RANGE=LOCALHOST" in r.stdout and "DOMAIN=0" in r.stdout and "SOURCED=11" in r.stdout
    assert "CONFIG=unset" in r.stdout  # the installed vehicle file, unless one is named
    assert runs.is_dir()  # created for the recorder
    # SROS2 on as shipped: the keystore's enclaves, enforced (the launch passes each process its --enclave)
    assert f"SECURITY=true Enforce {tmp_path / 'keystore'} " in r.stdout, r.stdout


def test_entrypoint_ships_sros2_on_and_refuses_a_vehicle_without_its_keystore(tmp_path):
    r = run_entrypoint(tmp_path, [], ROS_DOMAIN_ID="42", HINDRAX_KEYSTORE=str(tmp_path / "none"))
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert f"HINDRAX_KEYSTORE={tmp_path / 'none'}: no SROS2 keystore (create it with `hindrax sros2 keystore" \
        in r.stderr
    r = run_entrypoint(tmp_path, [], ROS_DOMAIN_ID="42", HINDRAX_KEYSTORE=str(tmp_path / "none"), HINDRAX_SROS2="0")
    assert r.returncode == 0 and "SECURITY=unset" in r.stdout, r.stderr  # a bench without DDS Security
    r = run_entrypoint(tmp_path, ["hindrax", "health", "--quiet"], ROS_DOMAIN_ID="42")
    assert r.returncode == 0 and "/vehicle/tools" in r.stdout, r.stdout + r.stderr  # a command gets the tools' enclave


def test_the_launch_arguments_the_entrypoint_passes_are_declared_by_both_launch_files(tmp_path):
    share = lambda pkg: REPO / "src" / pkg  # noqa: E731
    cfg = tmp_path / "vehicle.yaml"
    cfg.write_text(default_config_path().read_text())
    for launch in ("hindrax_bringup vehicle.launch.xml", "hindrax_onboard pool_test.launch.xml"):
        for extra in ({}, {"HINDRAX_RECORD": "0", "HINDRAX_CONFIG": str(cfg)}):
            pkg, name, given = entrypoint_launch_arguments(tmp_path, HINDRAX_LAUNCH=launch, **extra)
            processes = read_launch(share(pkg) / "launch" / name, given, find_share=share)  # refuses undeclared ones
            nodes = [n for p in processes for n in p.node_names]  # the recorder alone or composed (pool test)
            assert ("recorder" in nodes) == (extra.get("HINDRAX_RECORD", "1") == "1"), (launch, extra, nodes)
            assert all(p.parameters[0] == (cfg if extra else share("hindrax_common") / "config/hindrax.yaml")
                       for p in processes)


def test_entrypoint_refuses_domain_0_and_bad_settings_in_one_line(tmp_path):
    for env, message in (({}, "ROS_DOMAIN_ID=unset: set this vehicle's own domain (1-101)"),
                         ({"ROS_DOMAIN_ID": "0"}, "ROS_DOMAIN_ID=0: set this vehicle's own domain (1-101)"),
                         ({"ROS_DOMAIN_ID": "300"}, "ROS_DOMAIN_ID=300: allowed integer 1-101"),
                         ({"ROS_DOMAIN_ID": "7", "HINDRAX_INTERNAL_DOMAIN_ID": "7"},
                          "HINDRAX_INTERNAL_DOMAIN_ID=7: allowed integer 0-101, not the topside domain"),
                         ({"ROS_DOMAIN_ID": "7", "HINDRAX_DISCOVERY_RANGE": "EVERYWHERE"},
                          "HINDRAX_DISCOVERY_RANGE=EVERYWHERE"),
                         ({"ROS_DOMAIN_ID": "7", "HINDRAX_CONFIG": "/nonexistent/v.yaml"},
                          "HINDRAX_CONFIG=/nonexistent/v.yaml: no such file"),
                         ({"ROS_DOMAIN_ID": "7", "HINDRAX_RECORD": "yes"}, "HINDRAX_RECORD=yes: allowed 1 or 0"),
                         ({"ROS_DOMAIN_ID": "7", "HINDRAX_LAUNCH": "vehicle.launch.xml"}, "HINDRAX_LAUNCH=")):
        r = run_entrypoint(tmp_path, [], **env)
        assert r.returncode == 2 and message in r.stderr and r.stderr.count("\n") == 1, (env, r.stderr)
        assert "RUN=" not in r.stdout


def test_entrypoint_runs_a_given_command_and_health_checks_the_same_launch(tmp_path):
    r = run_entrypoint(tmp_path, ["hindrax", "bringup", "--sim"], HINDRAX_DISCOVERY_RANGE="LOCALHOST")
    assert r.returncode == 0, r.stderr  # an explicit command needs no vehicle domain
    assert "RUN=hindrax bringup --sim" in r.stdout and "RANGE=LOCALHOST" in r.stdout and "DOMAIN=0" in r.stdout
    runs = tmp_path / "runs"
    # the HEALTHCHECK runs /usr/local/bin/hindrax, which passes the installed command's full path
    r = run_entrypoint(tmp_path, [str(tmp_path / "bin" / "hindrax"), "health", "--quiet"], ROS_DOMAIN_ID="42",
                       HINDRAX_LAUNCH="hindrax_onboard pool_test.launch.xml")
    assert f"RUN=hindrax health --quiet --launch hindrax_onboard/pool_test.launch.xml record:=true output_dir:={runs}" \
        in r.stdout
    r = run_entrypoint(tmp_path, ["hindrax", "health", "--launch", "x/y.launch.xml"], ROS_DOMAIN_ID="42")
    assert "RUN=hindrax health --launch x/y.launch.xml" in r.stdout.splitlines()[0]  # given: left alone


# ---------------------------------------------------------------------------------------------- image
def dockerfile() -> str:
    return (DOCKER / "Dockerfile").read_text()


def instructions() -> list[tuple[str, str]]:
    """(INSTRUCTION, rest) of the Dockerfile, continuation lines joined, comments left out."""
    lines = [line for line in dockerfile().splitlines() if not line.lstrip().startswith("#")]
    text = re.sub(r"\\\n", " ", "\n".join(lines))
    return [(m.group(1).upper(), m.group(2)) for m in re.finditer(r"^\s*([A-Za-z]+)\s+(.*)$", text, re.M)]


def test_image_starts_the_launch_layout_with_a_health_check_not_the_one_process_bringup():
    ins = instructions()
    assert ("FROM", "ros:jazzy-ros-base") in ins
    assert ("ENTRYPOINT", '["/entrypoint.sh"]') in ins
    cmd = [rest for kind, rest in ins if kind == "CMD"]
    assert cmd == ["[]"]  # the entry point's default: ros2 launch (test_entrypoint_runs_the_launch_layout...)
    assert "bringup" not in " ".join(rest for kind, rest in ins if kind in ("CMD", "ENTRYPOINT"))
    health = [rest for kind, rest in ins if kind == "HEALTHCHECK"]
    assert len(health) == 1 and re.search(r'CMD \["hindrax", "health"', health[0]), health
    assert re.search(r"--start-period=(\d+)s", health[0]) and int(re.search(r"--start-period=(\d+)s",
                                                                              health[0]).group(1)) >= 30


def test_image_runs_as_a_user_in_the_device_groups():
    ins = instructions()
    users = [rest for kind, rest in ins if kind == "USER"]
    assert users and users[-1] not in ("root", "0")
    useradd = next(rest for kind, rest in ins if kind == "RUN" and "useradd" in rest)
    assert re.search(rf"useradd .*--groups \S*DIALOUT_GID\S*I2C_GID\S*GPIO_GID\S* .*{users[-1]}\b", useradd)
    args = {rest.split("=")[0] for kind, rest in ins if kind == "ARG"}
    assert {"DIALOUT_GID", "I2C_GID", "GPIO_GID", "HINDRAX_UID"} <= args
    # the groups the udev rules give the devices
    rules = (DOCKER / "99-hindrax.rules").read_text()
    assert {"dialout", "i2c", "gpio"} == set(re.findall(r'GROUP="(\w+)"', rules))


def test_image_layers_put_the_dependencies_before_the_sources():
    ins = instructions()
    idx = {i: rest for i, (kind, rest) in enumerate(ins)}
    rosdep_install = next(i for i, r in idx.items() if ins[i][0] == "RUN" and "rosdep install" in r)
    copy_src = next(i for i, r in idx.items() if ins[i][0] == "COPY" and r.split()[0] == "src")
    colcon = next(i for i, r in idx.items() if ins[i][0] == "RUN" and "colcon build" in r)
    manifests = [i for i, r in idx.items() if ins[i][0] == "COPY" and r.split()[0].endswith("/package.xml")]
    assert len(manifests) == 5 and max(manifests) < rosdep_install < copy_src < colcon
    # the vehicle's packages only; the topside ones stay out of the build context (issue 75)
    vehicle = {"hindrax_msgs", "hindrax_common", "hindrax_drivers", "hindrax_bringup", "hindrax_onboard"}
    assert {idx[i].split()[0].split("/")[1] for i in manifests} == vehicle
    ignored = (REPO / ".dockerignore").read_text().split()
    topside = {p.parent.name for p in REPO.glob("src/*/package.xml")} - vehicle
    assert topside == {"hindrax_fit", "hindrax_sim", "hindrax_tools"} and all(f"src/{p}" in ignored for p in topside)
    assert "COPY rosdep.yaml" in dockerfile() and "rosdep install --from-paths src --ignore-src" in dockerfile()


def test_image_names_no_vehicle_file_and_no_domain():
    env = " ".join(rest for kind, rest in instructions() if kind == "ENV")
    assert "HINDRAX_CONFIG" not in env  # the installed vehicle file unless a mounted one is named at run time
    assert "ROS_DOMAIN_ID" not in env  # per vehicle: the entry point refuses to launch without it
    assert "HINDRAX_RUNS_DIR=/var/lib/hindrax/runs" in env and "ROS_LOG_DIR=" in env


def _ignored(path: str, patterns: list[str]) -> bool:
    return any(fnmatch.fnmatch(path, p) or path.startswith(p.rstrip("/") + "/") for p in patterns)


def test_dockerignore_keeps_the_context_small_and_the_copied_files_in():
    patterns = [line.strip() for line in (REPO / ".dockerignore").read_text().splitlines()
                if line.strip() and not line.startswith("#")]
    for heavy in (".git", ".venv", "build", "runs", "ros_ws/install", "ros_ws/build", "src/hindrax_bringup/test"):
        assert _ignored(heavy, patterns), heavy
    for kind, rest in instructions():
        if kind == "COPY":
            source = rest.split()[0]
            assert not _ignored(source, patterns), f"COPY {source} is excluded by .dockerignore"


# ---------------------------------------------------------------------------------------------- compose, units
def compose_service() -> dict:
    return yaml.safe_load((DOCKER / "compose.yaml").read_text())["services"]["hindrax"]


def test_compose_binds_dev_with_cgroup_rules_so_a_missing_adapter_degrades_only_its_driver():
    svc = compose_service()
    assert svc["network_mode"] == "host" and not svc.get("privileged")
    assert "devices" not in svc  # a listed device that is absent stops the container from being created
    assert "/dev:/dev" in svc["volumes"]
    majors = {int(m) for m in re.findall(r"^c (\d+):\* rmw$", "\n".join(svc["device_cgroup_rules"]), re.M)}
    assert {188, 166, 89} <= majors  # ttyUSB, ttyACM, i2c-dev (Linux devices.txt)
    cfg = load_config(default_config_path())
    for port in (cfg.sensors.dvl75.port, cfg.sensors.ping1d.port):
        assert port.startswith("/dev/")  # reached through the bind, created by the udev rules
    assert svc["stop_signal"] == "SIGINT" and svc["init"] is True
    grace = int(str(svc["stop_grace_period"]).rstrip("s"))
    assert grace >= 15  # ros2 launch: SIGTERM after 5 s, SIGKILL after 5 s more


def test_compose_rotates_logs_and_takes_the_vehicle_settings_from_its_env_file():
    svc = compose_service()
    assert svc["logging"]["driver"] == "json-file"
    assert svc["logging"]["options"]["max-size"] and int(svc["logging"]["options"]["max-file"]) >= 2
    # ROS log files survive a restart (host disk) and are rotated there (issue 45.5)
    assert any(v.endswith(":/var/log/hindrax") for v in svc["volumes"]) and "tmpfs" not in svc
    rotate = (DOCKER / "logrotate" / "hindrax").read_text()
    assert "/var/log/hindrax/" in rotate and "maxsize" in rotate and "rotate " in rotate
    assert svc["restart"] == "no"  # one supervisor: systemd's unit restarts compose up
    env = svc["environment"]
    assert ":?" in env["ROS_DOMAIN_ID"]  # compose refuses to start without this vehicle's domain
    # one runs-folder variable on every path (issue 45.5): the bare-metal entry point reads HINDRAX_RUNS_DIR too
    assert any(v.endswith(":/var/lib/hindrax/runs") and v.startswith("${HINDRAX_RUNS_DIR") for v in svc["volumes"])
    assert "HINDRAX_RUNS_DIR" in (DOCKER / "entrypoint.sh").read_text()
    example = dict(line.split("=", 1) for line in (DOCKER / "hindrax.env.example").read_text().splitlines()
                   if line and not line.startswith("#"))
    assert example["ROS_DOMAIN_ID"] == ""  # no shared example domain: every vehicle's file must name its own
    assert {"HINDRAX_RUNS_DIR", "HINDRAX_LAUNCH", "HINDRAX_RECORD"} <= set(example)
    assert not any("RUNS_HOST" in p.read_text() for p in DOCKER.iterdir() if p.is_file())


def test_systemd_units_start_the_same_entry_point_after_time_sync():
    compose_unit = (DOCKER / "hindrax.service").read_text()
    bare = (DOCKER / "hindrax-bare-metal.service").read_text()
    for unit in (compose_unit, bare):
        assert re.search(r"^After=.*time-sync\.target", unit, re.M)
        assert re.search(r"^Wants=.*time-sync\.target", unit, re.M)
    assert "--env-file /etc/hindrax/hindrax.env" in compose_unit
    assert re.search(r"^ExecStart=/opt/hindrax/docker/entrypoint\.sh$", bare, re.M)
    assert re.search(r"^EnvironmentFile=/etc/hindrax/hindrax.env$", bare, re.M)
    assert re.search(r"^KillSignal=SIGINT$", bare, re.M) and re.search(r"^User=(?!root)\w+", bare, re.M)


def test_chrony_keeps_the_pi_on_the_topside_clock():
    pi = (DOCKER / "chrony" / "hindrax-pi.conf").read_text()
    topside = (DOCKER / "chrony" / "topside.conf").read_text()
    assert re.search(r"^server \S+ iburst", pi, re.M) and re.search(r"^makestep 1 -1$", pi, re.M)
    assert re.search(r"^allow \S+", topside, re.M) and re.search(r"^local stratum \d+$", topside, re.M)


def test_udev_names_match_the_configuration():
    rules = (DOCKER / "99-hindrax.rules").read_text()
    links = set(re.findall(r'SYMLINK\+="([^"]+)"', rules))
    cfg = load_config(default_config_path())
    assert {Path(cfg.sensors.dvl75.port).name, Path(cfg.sensors.ping1d.port).name} <= links
    for key in ("sensors.ms5837.i2c_bus", "sensors.icm20948.i2c_bus", "esc.i2c_bus"):
        assert f'KERNEL=="i2c-{cfg.get(key)}"' in rules


@pytest.mark.parametrize("script", ["entrypoint.sh", "hindrax-exec.sh"])
def test_scripts_are_executable_and_parse(script):
    path = DOCKER / script
    assert os.access(path, os.X_OK)
    assert subprocess.run(["bash", "-n", str(path)], capture_output=True, timeout=30).returncode == 0


def test_build_finds_this_hosts_group_ids(tmp_path):
    """Issue 45.5: the image's device groups take the IDs of this host's groups, found at build (docker/build.sh)."""
    import subprocess

    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    fakes = {"getent": 'case "$2" in dialout) echo dialout:x:20:;; i2c) echo i2c:x:994:;; gpio) echo gpio:x:993:;; '
                       'esac',
             "id": "echo 1001",
             "docker": 'echo "DOCKER $* UID=$HINDRAX_UID DIALOUT=$DIALOUT_GID I2C=$I2C_GID GPIO=$GPIO_GID"'}
    for name, body in fakes.items():
        (bin_dir / name).write_text(f"#!/usr/bin/env bash\n{body}\n")
        (bin_dir / name).chmod(0o755)
    env = {"PATH": f"{bin_dir}:/usr/bin:/bin", "HINDRAX_ENV": str(tmp_path / "hindrax.env")}
    r = subprocess.run([str(DOCKER / "build.sh"), "--pull"], env=env, capture_output=True, text=True, timeout=30)
    assert r.returncode == 0, r.stderr
    assert (f"DOCKER compose --env-file {tmp_path / 'hindrax.env'} -f docker/compose.yaml build --pull UID=1001 "
            "DIALOUT=20 I2C=994 GPIO=993") in r.stdout
    (bin_dir / "getent").write_text("#!/usr/bin/env bash\nexit 2\n")  # a host without the groups: one line, no build
    r = subprocess.run([str(DOCKER / "build.sh")], env=env, capture_output=True, text=True, timeout=30)
    assert r.returncode == 1 and "no group dialout" in r.stderr and "DOCKER" not in r.stdout


def test_both_units_silence_the_outputs_after_every_stop_with_the_installed_command():
    """Issue 71.6: ``ExecStopPost=`` runs ``outputs_off`` (a console script of hindrax_bringup, no ROS) after a stop,
    a crash or the watchdog's SIGKILL; the command exists where the units look for it."""
    setup = (DOCKER.parent / "src/hindrax_bringup/setup.py").read_text()
    assert '"outputs_off": "hindrax_bringup.guard.outputs_off:main"' in setup
    for unit in ("hindrax.service", "hindrax-bare-metal.service"):
        text = (DOCKER / unit).read_text()
        (line,) = re.findall(r"^ExecStopPost=(.*)$", text, re.M)
        assert "install/lib/hindrax_bringup/outputs_off" in line, (unit, line)
    assert "rclpy" not in (DOCKER.parent / "src/hindrax_bringup/hindrax_bringup/guard/outputs_off.py").read_text()
