"""A second vehicle graph is refused (issue 43.3): ``hindrax bringup --sim`` and ``hindrax run`` started on a domain
where another ESC or supervisor is visible exit 1 with one line naming the domain and the process, before arming;
one that appears after their start ends them the same way.

The other vehicle is a node of this test process carrying the name the launch layout gives the supervisor or the
ESC, publishing its heartbeat topic: what the graph shows of a live one.
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import rclpy
from hindrax_msgs.msg import Heartbeat
from rclpy.executors import SingleThreadedExecutor

from hindrax_common.testing import child_env, ros_context, wait_until

pytestmark = pytest.mark.ros


def _refusal(args: list[str], role_node: str, tmp_path: Path) -> tuple[int, list[str], int]:
    """Run ``hindrax ARGS`` while a node named ``role_node`` publishes its heartbeat on this test's domain; returns
    (exit status, stderr lines, domain). The domain is a fresh one: a node named esc or supervisor that an earlier
    test of this worker left would still be in the worker's domain's discovery caches and be named too."""
    from hindrax_test_support.helpers import fresh_domain

    with fresh_domain() as fresh, ros_context(domain_id=fresh) as ctx:
        other = rclpy.create_node(role_node, context=ctx)
        beat = other.create_publisher(Heartbeat, f"{role_node}/heartbeat", 10)
        other.create_timer(0.05, lambda: beat.publish(Heartbeat(level=Heartbeat.OK, boot_id=1, seq=1)))
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(other)
        hindrax = str(Path(sys.executable).with_name("hindrax"))
        with open(tmp_path / "stdout", "w") as out, open(tmp_path / "stderr", "w") as errf:
            proc = subprocess.Popen([hindrax, *args], env=child_env(ROS_DOMAIN_ID=str(fresh)), cwd=tmp_path,
                                    stdout=out, stderr=errf)
        try:
            wait_until(lambda: proc.poll() is not None, 180, lambda: ex.spin_once(timeout_sec=0.05),
                       f"hindrax {args[0]} refusing")
            err = (tmp_path / "stderr").read_text().strip().splitlines()
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
            ex.shutdown()
            other.destroy_node()
        return proc.returncode, err, ctx.get_domain_id()


def named(role: str, node: str) -> tuple[str, str]:
    """The two ways a refusal names another vehicle's ``node`` (vehicle_graph.foreign_vehicle_processes): by its
    node name, or by its heartbeat publisher when the graph shows the publisher before the node (on a loaded
    machine the two discoveries arrive in either order, and our own graph has a node of the same name)."""
    return f"{role} /{node}", f"{role} heartbeat publisher /{node} on /{node}/heartbeat"


def test_bringup_sim_refuses_a_domain_with_another_supervisor(tmp_path):
    status, err, domain = _refusal(["bringup", "--sim"], "supervisor", tmp_path)
    assert status == 1, err
    assert err[-1] in [f"hindrax bringup: refused: ROS domain {domain} already has {other}; refusing to start a "
                       "second vehicle graph on it (set ROS_DOMAIN_ID to a free domain)"
                       for other in named("supervisor", "supervisor")], err


def test_run_refuses_a_domain_with_another_esc_before_arming(tmp_path):
    status, err, domain = _refusal(["run", "--dofs", "surge", "--levels", "1", "--out", str(tmp_path / "run")],
                                   "esc", tmp_path)
    assert status == 1, err
    assert any(err[-1].startswith(f"hindrax run: refused: ROS domain {domain} already has {other}; refusing to run a "
                                  "campaign beside another vehicle graph") for other in named("ESC", "esc")), err
    assert not (tmp_path / "run").exists()  # issue 74.8: a refused run leaves no empty folder


@pytest.mark.parametrize("args, started, role, role_name", [
    (["bringup", "--sim"], "bringup:", "supervisor", "supervisor"),
    (["run", "--dofs", "surge", "--levels", "1", "--out", "run"], "armed through esc/set_armed", "esc", "ESC"),
], ids=["bringup", "run"])
def test_a_vehicle_graph_ends_when_another_vehicle_appears_after_its_start(tmp_path, args, started, role, role_name):
    """Discovery on a loaded machine can outlast the start-up window, and a second graph may start later: an ESC or
    supervisor seen after the start (``bringup`` running, ``run`` armed) ends it the same way (one line, exit 1)."""
    from hindrax_test_support.helpers import fresh_domain

    hindrax = str(Path(sys.executable).with_name("hindrax"))
    # a domain of its own: the other tests here leave a node named esc or supervisor in this worker's domain's
    # discovery caches for a while, which would refuse the start itself
    with fresh_domain() as fresh, ros_context(domain_id=fresh) as ctx, \
            open(tmp_path / "stdout", "w") as out, open(tmp_path / "stderr", "w") as errf:
        proc = subprocess.Popen([hindrax, *args], env=child_env(ROS_DOMAIN_ID=str(fresh)), cwd=tmp_path,
                                stdout=out, stderr=errf)
        ex = SingleThreadedExecutor(context=ctx)
        other = None
        try:
            wait_until(lambda: started in (tmp_path / "stdout").read_text() or proc.poll() is not None, 180,
                       message=f"{args[0]} started")
            assert proc.poll() is None, (tmp_path / "stderr").read_text()
            other = rclpy.create_node(role, context=ctx)
            beat = other.create_publisher(Heartbeat, f"{role}/heartbeat", 10)
            other.create_timer(0.05, lambda: beat.publish(Heartbeat(level=Heartbeat.OK, boot_id=1, seq=1)))
            ex.add_node(other)
            wait_until(lambda: proc.poll() is not None, 120, lambda: ex.spin_once(timeout_sec=0.05),
                       f"{args[0]} ending")
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
            ex.shutdown()
            if other is not None:
                other.destroy_node()
        err = (tmp_path / "stderr").read_text().strip().splitlines()
        domain = ctx.get_domain_id()
    assert proc.returncode == 1, err
    assert any(err[-1].startswith(f"hindrax {args[0]}: refused: ROS domain {domain} already has {other};")
               for other in named(role_name, role)), err
    assert not (tmp_path / "run" / "identification.yaml").exists()


def test_pool_rehearse_refuses_a_domain_with_another_esc_before_starting_anything(tmp_path):
    """Issue 74.2: a second rehearsal on a domain in use cut the first vehicle's thrusters and filled its bags."""
    status, err, domain = _refusal(["pool", "rehearse", "--dir", str(tmp_path / "day")], "esc", tmp_path)
    assert status == 1, err
    assert err[-1] in [f"hindrax pool rehearse: refused: ROS domain {domain} already has {other}; refusing to start "
                       "a second vehicle on it (set ROS_DOMAIN_ID to a free domain)" for other in named("ESC", "esc")]
    assert not (tmp_path / "day").exists()  # no pool, no vehicle file, no launch


def test_health_names_a_second_vehicle_on_its_domain(tmp_path):
    """Issue 74.2: the first vehicle's health said READY beside a second one; two ESCs on the domain are named."""
    from hindrax_test_support.helpers import fresh_domain

    with fresh_domain() as fresh, ros_context(domain_id=fresh) as ctx:
        escs = [rclpy.create_node("esc", context=ctx) for _ in range(2)]
        ex = SingleThreadedExecutor(context=ctx)
        for esc in escs:
            beat = esc.create_publisher(Heartbeat, "esc/heartbeat", 10)
            esc.create_timer(0.05, lambda b=beat: b.publish(Heartbeat(level=Heartbeat.OK, boot_id=1, seq=1)))
            ex.add_node(esc)
        hindrax = str(Path(sys.executable).with_name("hindrax"))
        proc = subprocess.Popen([hindrax, "health", "--timeout", "8"], env=child_env(ROS_DOMAIN_ID=str(fresh)),
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        try:
            wait_until(lambda: proc.poll() is not None, 120, lambda: ex.spin_once(timeout_sec=0.05), "health")
        finally:
            if proc.poll() is None:
                proc.kill()
            ex.shutdown()
            for esc in escs:
                esc.destroy_node()
    out = proc.stdout.read()
    assert proc.returncode == 1, out
    assert "  FAIL  a second vehicle on this domain: ESC /esc: " in out, out
