"""The vehicle's internal graph is sealed from the tether (docs/architecture.md §8.2): no internal participant, the
gateway's included, can be reached from a non-loopback address.

Everything here runs in a private network namespace (``unshare -n``), the "Pi", joined by a veth pair to a second
namespace, the "laptop": 10.77.0.1 on the Pi's side, 10.77.0.2 on the laptop's, a separate host as far as DDS can
tell. On the Pi: the gateway as vehicle.launch.xml starts it and a control participant on the internal domain with
Fast DDS's default transports (what any process listening on every address looks like). On the laptop: a participant
with ``ROS_STATIC_PEERS=10.77.0.1`` and the vehicle's internal domain id, as an engineer on the pool's network would
set them. The laptop must discover the control (the path works) and, in the same time and 5 s more, no node of the
vehicle. The gateway before its split into two processes fails both halves: the laptop found /hindrax/gateway and
its internal participant had a socket on 0.0.0.0. The probe prints one JSON line with what the laptop saw and the UDP
sockets of the gateway's processes.
"""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from hindrax_common.testing import child_env

pytestmark = pytest.mark.ros

REPO = Path(__file__).resolve().parents[1]

#: run as root in a fresh network namespace: addresses, the three processes, the laptop's view; one JSON line
PROBE = r'''
import json, os, subprocess, sys, time
from pathlib import Path

repo, config, out = Path(sys.argv[1]), sys.argv[2], Path(sys.argv[3])
NS = f"hindrax-laptop-{os.getpid()}"
for cmd in (["ip", "link", "set", "lo", "up"], ["ip", "link", "add", "pi0", "type", "veth", "peer", "name", "lap0"],
            ["ip", "netns", "add", NS], ["ip", "link", "set", "lap0", "netns", NS],
            ["ip", "addr", "add", "10.77.0.1/24", "dev", "pi0"], ["ip", "link", "set", "pi0", "up"],
            ["ip", "netns", "exec", NS, "ip", "addr", "add", "10.77.0.2/24", "dev", "lap0"],
            ["ip", "netns", "exec", NS, "ip", "link", "set", "lap0", "up"],
            ["ip", "netns", "exec", NS, "ip", "link", "set", "lo", "up"]):
    subprocess.run(cmd, check=True)
INTERNAL, TOPSIDE = "11", "12"

def env(**extra):
    e = dict(os.environ, ROS_DOMAIN_ID=INTERNAL, PYTHONUNBUFFERED="1")
    e.update(extra)
    return {k: v for k, v in e.items() if v}

vehicle_env = env(ROS_STATIC_PEERS="")
procs = {
    "gateway": subprocess.Popen([sys.executable, "-m", "hindrax_bringup.gateway.node", "--ros-args", "--params-file",
                                 config, "-p", f"topside_domain_id:={TOPSIDE}", "-p",
                                 "topside_discovery_range:=SUBNET"],
                                env=vehicle_env,
                                stdout=open(out / "gateway.log", "w"), stderr=subprocess.STDOUT),
    "control": subprocess.Popen([sys.executable, "-c", "import rclpy; rclpy.init(); "
                                 "rclpy.spin(rclpy.create_node('control'))"],
                                env=env(ROS_AUTOMATIC_DISCOVERY_RANGE="SUBNET", FASTRTPS_DEFAULT_PROFILES_FILE="")),
}

from hindrax_common.process.proc_sockets import child_pids as children, udp_sockets

def udp(pid):
    return sorted({a for a, _ in udp_sockets(pid)})

LAPTOP = r"""
import json, os, sys, time
from pathlib import Path
import rclpy
out = Path(sys.argv[1])
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
print(json.dumps({"seen": sorted(seen), "control_seen": control_at is not None}))
"""
try:  # the named namespace is a mount outside this one: always removed
    lap = subprocess.run(["ip", "netns", "exec", NS, sys.executable, "-c", LAPTOP, str(out)], capture_output=True,
                         text=True, env=env(ROS_AUTOMATIC_DISCOVERY_RANGE="SUBNET", ROS_STATIC_PEERS="10.77.0.1",
                                            FASTRTPS_DEFAULT_PROFILES_FILE=""), timeout=150)
finally:
    subprocess.run(["ip", "netns", "del", NS], check=False)
if lap.returncode:
    sys.exit(lap.stderr[-3000:])
laptop_saw = json.loads(lap.stdout.strip().splitlines()[-1])
gateway_ready = lambda: "internal domain" in (out / "gateway.log").read_text()
sockets = {"gateway": udp(procs["gateway"].pid)}
for child in children(procs["gateway"].pid):
    sockets[f"gateway child {child}"] = udp(child)
procs["gateway"].terminate()  # the gateway ends on SIGTERM; the control (rclpy's handler) only on SIGKILL
procs["control"].kill()
for p in procs.values():
    p.wait(timeout=30)
print(json.dumps({**laptop_saw, "gateway_ready": gateway_ready(),
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
