"""The vehicle's internal graph is sealed from the tether (docs/architecture.md §8.2): no internal participant, the
gateway's included, can be reached from a non-loopback address.

Everything here runs in a private network namespace (``unshare -n``: its own loopback, no real interface) that also
carries two non-loopback addresses, 10.77.0.1 (the "vehicle") and 10.77.0.2 (the "laptop"). In it: the gateway as
vehicle.launch.xml starts it, a control participant on the internal domain with Fast DDS's default transports (what
any process listening on every address looks like), and the laptop: a participant bound to 10.77.0.2 only, with
``ROS_STATIC_PEERS=10.77.0.1`` and the vehicle's internal domain id, as an engineer on the pool's network would
set them. The laptop must discover the control (the path works) and, in the same time and 5 s more, no node of the
vehicle. The probe script prints one JSON line with what it saw and the UDP sockets of every process.
"""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from hindrax_drivers.testing import child_env

pytestmark = pytest.mark.ros

REPO = Path(__file__).resolve().parents[1]

#: run as root in a fresh network namespace: addresses, the three processes, the laptop's view; one JSON line
PROBE = r'''
import json, os, subprocess, sys, time
from pathlib import Path

repo, config, out = Path(sys.argv[1]), sys.argv[2], Path(sys.argv[3])
for cmd in (["ip", "link", "set", "lo", "up"], ["ip", "addr", "add", "10.77.0.1/32", "dev", "lo"],
            ["ip", "addr", "add", "10.77.0.2/32", "dev", "lo"]):
    subprocess.run(cmd, check=True)
INTERNAL, TOPSIDE = "11", "12"

def env(**extra):
    e = dict(os.environ, ROS_DOMAIN_ID=INTERNAL, PYTHONUNBUFFERED="1")
    e.update(extra)
    return {k: v for k, v in e.items() if v}

laptop_profile = out / "laptop.xml"
laptop_profile.write_text("""<?xml version="1.0" encoding="UTF-8"?>
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <transport_descriptors><transport_descriptor><transport_id>lan</transport_id><type>UDPv4</type>
    <interfaceWhiteList><address>10.77.0.2</address></interfaceWhiteList></transport_descriptor></transport_descriptors>
  <participant profile_name="laptop" is_default_profile="true"><rtps>
    <userTransports><transport_id>lan</transport_id></userTransports>
    <useBuiltinTransports>false</useBuiltinTransports></rtps></participant>
</profiles>""")
vehicle_env = env(ROS_STATIC_PEERS="")
procs = {
    "gateway": subprocess.Popen([sys.executable, "-m", "hindrax_drivers.gateway.node", "--ros-args", "--params-file",
                                 config, "-p", f"topside_domain_id:={TOPSIDE}", "-p",
                                 "topside_discovery_range:=SUBNET"],
                                env=vehicle_env,
                                stdout=open(out / "gateway.log", "w"), stderr=subprocess.STDOUT),
    "control": subprocess.Popen([sys.executable, "-c", "import rclpy; rclpy.init(); "
                                 "rclpy.spin(rclpy.create_node('control'))"],
                                env=env(ROS_AUTOMATIC_DISCOVERY_RANGE="SUBNET", FASTRTPS_DEFAULT_PROFILES_FILE="")),
}

from hindrax_drivers.proc_sockets import child_pids as children, udp_sockets

def udp(pid):
    return sorted({a for a, _ in udp_sockets(pid)})

import rclpy
os.environ.update(ROS_DOMAIN_ID=INTERNAL, ROS_AUTOMATIC_DISCOVERY_RANGE="SUBNET", ROS_STATIC_PEERS="10.77.0.1",
                  FASTRTPS_DEFAULT_PROFILES_FILE=str(laptop_profile))
rclpy.init()
laptop = rclpy.create_node("laptop")
seen, control_at, deadline = set(), None, time.monotonic() + 90
gateway_ready = lambda: "internal domain" in (out / "gateway.log").read_text()
while time.monotonic() < deadline:
    rclpy.spin_once(laptop, timeout_sec=0.1)
    seen |= {ns.rstrip("/") + "/" + n for n, ns in laptop.get_node_names_and_namespaces() if n != "laptop"}
    if control_at is None and "/control" in seen and gateway_ready():
        control_at = time.monotonic()
    if control_at is not None and time.monotonic() - control_at > 5.0:
        break
sockets = {"gateway": udp(procs["gateway"].pid), "laptop": udp(os.getpid())}
for child in children(procs["gateway"].pid):
    sockets[f"gateway child {child}"] = udp(child)
procs["gateway"].terminate()  # the gateway ends on SIGTERM; the control (rclpy's handler) only on SIGKILL
procs["control"].kill()
for p in procs.values():
    p.wait(timeout=30)
print(json.dumps({"seen": sorted(seen), "control_seen": control_at is not None, "gateway_ready": gateway_ready(),
                  "sockets": sockets}))
'''


@pytest.mark.timeout(300)
def test_no_internal_participant_is_reachable_from_a_non_loopback_address(tmp_path):
    if shutil.which("unshare") is None or shutil.which("ip") is None:
        raise AssertionError("needs unshare and ip (util-linux, iproute2) and root to make a private network namespace")
    config = REPO / "ros_ws" / "config" / "hindrax.yaml"
    r = subprocess.run(["unshare", "-n", sys.executable, "-c", PROBE, str(REPO), str(config), str(tmp_path)],
                       capture_output=True, text=True, env=child_env(), timeout=240)
    assert r.returncode == 0, r.stderr[-3000:]
    got = json.loads(r.stdout.strip().splitlines()[-1])
    log = (tmp_path / "gateway.log").read_text()
    assert got["gateway_ready"], log[-2000:]
    assert got["control_seen"], got  # the laptop's path to 10.77.0.1 works: it finds a participant listening there
    assert got["seen"] == ["/control"], (got, log[-2000:])  # and no node of the vehicle: not the gateway's either
    # the gateway's processes: one on the topside (any address: it must reach the tether), one on the internal domain,
    # every socket of which is on loopback (or the discovery multicast group, joined on loopback)
    internal = [s for name, s in got["sockets"].items() if name.startswith("gateway child")]
    assert len(internal) == 1, got["sockets"]
    assert internal[0] and all(a == "127.0.0.1" or a.startswith("239.") for a in internal[0]), got["sockets"]
