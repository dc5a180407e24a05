"""Who may command a vehicle (docs/architecture.md §8.2): the gateway is the vehicle's only door to the topside.

Two vehicles, ``alpha`` and ``bravo``, each with its own internal domain, share one topside domain. Each vehicle's
internal graph holds stand-ins of its safety services and topics (the ESC's ``esc/set_armed``, the supervisor's
``supervisor/estop`` and ``supervisor/reset``, the MS5837's ``pressure/zero_depth``, the recorder's ``recorder/stop``,
subscribers of ``thrusters/command_pulse_width`` and ``supervisor/heartbeat``), recording every call and message
that reaches them, and its gateway is started from ``vehicle.launch.xml`` as ``ros2 launch`` would. Then:

* a plain rclpy script on the topside domain (no credentials, not using the interface) tries what a process on the
  vehicle's domain could do before: arm, drive, forge a heartbeat, reset, re-zero, stop the recorder. Nothing
  reaches the vehicle; its e-stop through ``/alpha/estop`` does, and the telemetry reaches the script;
* ``hindrax ident start --vehicle alpha`` runs the campaign (through the gateway's action relay) on alpha only;
* ``hindrax arm --vehicle alpha`` arms alpha and never bravo; ``hindrax arm`` with two vehicles on the domain
  refuses with one line and arms neither; ``hindrax disarm --vehicle bravo`` reaches bravo only.

Who *on the topside* may call ``arm`` is SROS2's on the Pi (the operator enclave); the development wheels have no
DDS Security, so that part is checked on the policy files, not here.
"""
from __future__ import annotations

import json
import subprocess
import sys
import threading
from pathlib import Path

import pytest
import yaml
from hindrax_test_support.helpers import fresh_domain
from rclpy.executors import SingleThreadedExecutor

from hindrax_common.config import default_config_path
from hindrax_bringup.gateway.interface import relays
from hindrax_bringup.gateway.node import QUEUE_GAP_S
from hindrax_bringup.gateway.operator_signing import Signer, create_key, load_key
from hindrax_bringup.layout.launch_xml import read_launch
from hindrax_bringup.layout.process_runner import ProcessRunner
from hindrax_common.testing import child_env, ros_context, wait_until

REPO = Path(__file__).resolve().parents[3]
WAIT_S = 60.0
VEHICLES = ("alpha", "bravo")

#: the plain script: waits for alpha's gateway, then tries the safety graph directly; prints one JSON line
INTRUDER = r'''
import json, sys, time
import rclpy
from diagnostic_msgs.msg import DiagnosticStatus
from hindrax_msgs.msg import Heartbeat, ThrusterPwm
from std_srvs.srv import Trigger
rclpy.init()
node = rclpy.create_node("intruder")
status = []
node.create_subscription(DiagnosticStatus, "/alpha/supervisor/status", status.append, 10)
deadline = time.monotonic() + float(sys.argv[1])
expected = json.loads(sys.argv[2])  # all the gateways offer: discovery is complete when all is seen
def names():
    return {n for n, _ in node.get_service_names_and_types()}
def topics():
    return {n for n, _ in node.get_topic_names_and_types()}
while not (set(expected["services"]) <= names() and set(expected["topics"]) <= topics()) \
        and time.monotonic() < deadline:
    rclpy.spin_once(node, timeout_sec=0.1)
rclpy.spin_once(node, timeout_sec=0.5)
# the graph before this script adds clients and publishers of its own (a client's name is listed too)
graph = {"services": sorted(names()), "topics": sorted(topics())}
pwm = {t: node.create_publisher(ThrusterPwm, t, 10) for t in ("thrusters/command_pulse_width",
                                                              "/alpha/thrusters/command_pulse_width")}
beat = node.create_publisher(Heartbeat, "supervisor/heartbeat", 10)
calls = {}
for name in ("/supervisor/reset", "/pressure/zero_depth", "/alpha/pressure/zero_depth", "/recorder/stop"):
    client = node.create_client(Trigger, name)
    calls[name] = client.wait_for_service(timeout_sec=1.0)
end = time.monotonic() + 1.5
while time.monotonic() < end:
    for p in pwm.values():
        p.publish(ThrusterPwm(pulse_width_us=[1900.0] * 8, armed=True))
    beat.publish(Heartbeat(level=Heartbeat.OK, boot_id=1, seq=1))
    rclpy.spin_once(node, timeout_sec=0.05)
estop = node.create_client(Trigger, "/alpha/estop")
answer = None
if estop.wait_for_service(timeout_sec=10.0):
    future = estop.call_async(Trigger.Request())
    rclpy.spin_until_future_complete(node, future, timeout_sec=10.0)
    answer = future.result() and future.result().success
while not status and time.monotonic() < deadline:
    rclpy.spin_once(node, timeout_sec=0.1)
print(json.dumps(dict(graph, reachable=calls, estop=answer, telemetry=len(status))))
'''


class StandIns:
    """One vehicle's internal graph as the gateway sees it: the safety services and topics, each recording what
    reaches it, and ``supervisor/status`` published at 5 Hz."""

    def __init__(self, ctx) -> None:
        from diagnostic_msgs.msg import DiagnosticStatus
        from hindrax_msgs.msg import Heartbeat, ThrusterPwm
        from hindrax_msgs.srv import SetArmed, StopRecording
        from std_srvs.srv import Trigger

        self.calls: list[object] = []
        self.messages: list[str] = []
        import rclpy

        self.node = rclpy.create_node("vehicle_stand_ins", context=ctx)
        # the ESC on a node and thread of its own: a test holds its answer (arm_gate) while the e-stop goes through
        self.esc = rclpy.create_node("esc_stand_in", context=ctx)
        self.arm_gate, self.arm_entered = threading.Event(), threading.Event()
        self.arm_gate.set()
        self.setpoints: list[float] = []

        def service(kind, name, answer, node=self.node):
            def callback(request, response):
                if getattr(request, "arm", False):
                    self.arm_entered.set()
                    self.arm_gate.wait(30.0)
                self.calls.append(answer(request))
                response.success = True
                if hasattr(response, "armed"):
                    response.armed = bool(request.arm)
                return response
            node.create_service(kind, name, callback)

        service(SetArmed, "esc/set_armed", lambda r: ("set_armed", bool(r.arm)), node=self.esc)
        from hindrax_msgs.msg import ControlSetpoint
        self.node.create_subscription(ControlSetpoint, "controller/setpoint",
                                      lambda m: self.setpoints.append(m.depth_m), 10)
        for name in ("supervisor/estop", "supervisor/reset", "pressure/zero_depth"):
            service(Trigger, name, lambda _r, n=name: n)
        service(StopRecording, "recorder/stop", lambda _r: "recorder/stop")
        self.node.create_subscription(ThrusterPwm, "thrusters/command_pulse_width",
                                      lambda _m: self.messages.append("command_pulse_width"), 10)
        self.node.create_subscription(Heartbeat, "supervisor/heartbeat",
                                      lambda _m: self.messages.append("heartbeat"), 10)
        from hindrax_msgs.action import RunIdentification
        from rclpy.action import ActionServer

        # the identification node on a node and thread of its own: a test holds a campaign (campaign_gate)
        self.ident = rclpy.create_node("identification_stand_in", context=ctx)
        self.campaign_gate, self.campaign_entered = threading.Event(), threading.Event()
        self.campaign_gate.set()

        def campaign(goal_handle):
            self.calls.append(("run_identification", list(goal_handle.request.dofs)))
            self.campaign_entered.set()
            self.campaign_gate.wait(60.0)
            goal_handle.publish_feedback(RunIdentification.Feedback(dof="surge", level_index=0, level_count=1,
                                                                    level_command=5.0, progress=0.5))
            goal_handle.succeed()
            return RunIdentification.Result(success=True, message="stand-in campaign done")

        self.action = ActionServer(self.ident, RunIdentification, "run_identification", campaign)
        status = self.node.create_publisher(DiagnosticStatus, "supervisor/status", 10)
        self.node.create_timer(0.2, lambda: status.publish(DiagnosticStatus(level=DiagnosticStatus.OK,
                                                                           name="supervisor", message="ok")))
        self.executors = [SingleThreadedExecutor(context=ctx) for _ in range(3)]
        for executor, node in zip(self.executors, (self.node, self.esc, self.ident)):
            executor.add_node(node)
        self.threads = [threading.Thread(target=self._spin, args=(ex,), daemon=True) for ex in self.executors]
        for thread in self.threads:
            thread.start()

    @staticmethod
    def _spin(executor) -> None:
        try:
            executor.spin()
        except Exception:  # noqa: BLE001 - the context shut down at the end of the test module
            pass

    def close(self) -> None:
        self.arm_gate.set()
        self.campaign_gate.set()
        for executor, thread in zip(self.executors, self.threads):
            executor.shutdown(timeout_sec=2.0)
            thread.join(timeout=5.0)
        for node in (self.node, self.esc, self.ident):
            node.destroy_node()


def vehicle_file(tmp: Path, name: str) -> Path:
    """The vehicle file with ``vehicle.name`` = ``name`` (and a relay timeout long enough for a held arm)."""
    params = yaml.safe_load(default_config_path().read_text())
    params["/**"]["ros__parameters"]["vehicle"]["name"] = name
    params["/**"]["ros__parameters"]["call_timeout_s"] = 10.0
    config = tmp / f"{name}.yaml"
    config.write_text(yaml.safe_dump(params))
    return config


def gateway_process(config: Path, topside: int):
    """The gateway's process as vehicle.launch.xml declares it."""
    procs = read_launch(REPO / "src/hindrax_bringup/launch/vehicle.launch.xml",
                        {"config": str(config), "topside_domain_id": str(topside)},
                        find_share=lambda pkg: REPO / "src" / pkg)
    (gateway,) = [p for p in procs if p.label == "gateway"]
    return gateway


@pytest.fixture(scope="module")
def pool(tmp_path_factory):
    """Two vehicles (stand-ins + gateway each) on internal domains of their own, one topside domain."""
    tmp = tmp_path_factory.mktemp("pool")
    keys = tmp / "keys"
    for name in VEHICLES:
        create_key(keys / f"{name}.key")
    with fresh_domain() as topside, fresh_domain() as internal_a, fresh_domain() as internal_b:
        vehicles = {}
        runners = []
        try:
            with ros_context(internal_a) as ctx_a, ros_context(internal_b) as ctx_b:
                for name, internal, ctx in (("alpha", internal_a, ctx_a), ("bravo", internal_b, ctx_b)):
                    vehicles[name] = StandIns(ctx)
                    runner = ProcessRunner([gateway_process(vehicle_file(tmp, name), topside)],
                                           env=child_env(ROS_DOMAIN_ID=str(internal), HINDRAX_KEYS_DIR=str(keys)),
                                           log_dir=tmp / name)
                    runner.start()
                    runners.append(runner)
                yield {"topside": topside, "vehicles": vehicles, "runners": runners, "keys": keys, "tmp": tmp}
                for v in vehicles.values():
                    v.close()
        finally:
            for runner in runners:
                runner.stop()


def hindrax(pool, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "hindrax_tools.cli", *args],
                          capture_output=True, text=True,
                          env=child_env(ROS_DOMAIN_ID=str(pool["topside"]), HINDRAX_KEYS_DIR=str(pool["keys"])),
                          timeout=120)


def hindrax_spinning(pool, topside, *args: str) -> subprocess.CompletedProcess:
    """:func:`hindrax` while the topside probe's executor spins in a thread (its servers answer
    the command)."""
    done = threading.Event()
    spinning = threading.Thread(target=lambda: [topside.executor.spin_once(timeout_sec=0.05)
                                                for _ in iter(done.is_set, True)])
    spinning.start()
    try:
        return hindrax(pool, *args)
    finally:
        done.set()
        spinning.join()


def test_a_process_on_the_topside_reaches_only_the_interface(pool):
    alpha = pool["vehicles"]["alpha"]
    action = "/alpha/run_identification/_action/"
    offered = {f"/alpha/{r.topside}" for r in relays("service")} | \
        {action + x for x in ("send_goal", "cancel_goal", "get_result")}
    offered_topics = {f"/alpha/{r.topside}" for r in relays("topic_in") + relays("topic_out")} | \
        {action + "feedback", action + "status"}
    # the intruder snapshots the graph once it has discovered everything both vehicles offer (the
    # action's services came last: a snapshot 0.5 s after the e-stops missed them on a loaded CI)
    both = {kind: sorted(names | {n.replace("/alpha/", "/bravo/", 1) for n in names})
            for kind, names in (("services", offered), ("topics", offered_topics))}
    r = subprocess.run([sys.executable, "-c", INTRUDER, str(WAIT_S), json.dumps(both)],
                       capture_output=True, text=True,
                       env=child_env(ROS_DOMAIN_ID=str(pool["topside"])), timeout=180)
    assert r.returncode == 0, r.stderr[-2000:]
    seen = json.loads(r.stdout.strip().splitlines()[-1])
    assert "/alpha/estop" in seen["services"] and "/bravo/estop" in seen["services"]  # it did see both vehicles
    assert not any(seen["reachable"].values()), seen["reachable"]  # reset, zero_depth, recorder/stop: absent
    graph = seen["services"] + seen["topics"]
    for forbidden in ("set_armed", "heartbeat", "pulse_width", "zero_depth", "supervisor/reset", "supervisor/abort"):
        assert not [n for n in graph if forbidden in n], forbidden  # no vehicle offers them on the topside
    # exactly the interface, nothing more (the operator's relays exist: SROS2 decides who calls them, on the Pi)
    assert {n for n in seen["services"] if n.startswith("/alpha/") and not n.endswith("/get_type_description")} == \
        offered
    assert {n for n in seen["topics"] if n.startswith("/alpha/")} == offered_topics
    assert seen["estop"] is True and seen["telemetry"] > 0
    # on the vehicle: the e-stop arrived, nothing else did; no command or forged heartbeat reached its subscribers
    wait_until(lambda: "supervisor/estop" in alpha.calls, 10.0, message="alpha's supervisor got the e-stop")
    assert alpha.calls == ["supervisor/estop"], alpha.calls
    assert alpha.messages == [], alpha.messages[:5]
    assert pool["vehicles"]["bravo"].calls == []


def test_a_command_aimed_at_one_vehicle_never_moves_the_other(pool):
    alpha, bravo = pool["vehicles"]["alpha"], pool["vehicles"]["bravo"]
    before_a, before_b = len(alpha.calls), len(bravo.calls)
    r = hindrax(pool, "arm")  # two vehicles on the domain and none named: refused, nobody armed
    assert r.returncode == 1 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert "several vehicles" in r.stderr and "alpha, bravo" in r.stderr and "--vehicle" in r.stderr
    r = hindrax(pool, "arm", "--vehicle", "charlie", "--discovery-timeout", "3")
    assert r.returncode == 1 and "vehicle 'charlie' not seen" in r.stderr, r.stderr
    assert len(alpha.calls) == before_a and len(bravo.calls) == before_b
    r = hindrax(pool, "arm", "--vehicle", "alpha")
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "alpha: armed"
    assert alpha.calls[before_a:] == [("set_armed", True)] and len(bravo.calls) == before_b
    r = hindrax(pool, "disarm", "--vehicle", "bravo")
    assert r.returncode == 0, r.stderr
    assert bravo.calls[before_b:] == [("set_armed", False)] and alpha.calls[before_a:] == [("set_armed", True)]


def test_thruster_test_names_its_vehicle_and_never_runs_from_the_topside(pool):
    before = {name: list(v.calls) for name, v in pool["vehicles"].items()}
    r = hindrax(pool, "thruster-test", "--step-s", "0.1")
    assert r.returncode == 1 and "several vehicles" in r.stderr and "\n" not in r.stderr.strip(), r.stderr
    r = hindrax(pool, "thruster-test", "--step-s", "0.1", "--vehicle", "alpha")
    assert r.returncode == 1 and "exist only on the vehicle" in r.stderr, r.stderr
    assert {name: v.calls for name, v in pool["vehicles"].items()} == before  # neither vehicle was armed


def test_a_campaign_started_on_the_topside_runs_on_the_named_vehicle_only(pool):
    alpha, bravo = pool["vehicles"]["alpha"], pool["vehicles"]["bravo"]
    before_b = list(bravo.calls)
    r = hindrax(pool, "ident", "start", "--vehicle", "alpha", "--dofs", "surge", "--server-timeout", "30")
    assert r.returncode == 0, r.stdout + r.stderr
    assert "campaign started: surge" in r.stdout and "result: complete: stand-in campaign done" in r.stdout
    assert ("run_identification", ["surge"]) in alpha.calls and bravo.calls == before_b


def test_the_gateway_starts_without_a_rosout_clash(pool):
    """The topside nodes have no rosout: the front node's logger name is the internal node's, and rcl refused its
    rosout publisher with "Publisher already registered for node name: 'gateway'" at every start."""
    for runner in pool["runners"]:
        wait_until(lambda r=runner: "internal domain" in r.log("gateway"), 60, message="the gateway started")
        log = runner.log("gateway")
        assert "already registered" not in log, log[-2000:]


class Topside:
    """A participant of this test on the topside domain: calls, publishes and reads with the operator's key or not."""

    def __init__(self, ctx, pool) -> None:
        import rclpy

        self.node = rclpy.create_node("operator_test", context=ctx)
        self.executor = SingleThreadedExecutor(context=ctx)
        self.executor.add_node(self.node)
        self.key = load_key(pool["keys"] / "alpha.key")

    def call(self, srv, name: str, request):
        client = self.node.create_client(srv, name)
        wait_until(client.service_is_ready, WAIT_S, lambda: self.executor.spin_once(timeout_sec=0.1), f"{name} seen")
        future = client.call_async(request)
        wait_until(future.done, WAIT_S, lambda: self.executor.spin_once(timeout_sec=0.1), f"{name} answered")
        return future.result()

    def status(self, vehicle: str, done):
        """The gateway's status messages until ``done(last)`` holds."""
        from diagnostic_msgs.msg import DiagnosticStatus

        got: list = []
        sub = self.node.create_subscription(DiagnosticStatus, f"/{vehicle}/gateway/status", got.append, 10)
        wait_until(lambda: got and done(got[-1]), WAIT_S, lambda: self.executor.spin_once(timeout_sec=0.1),
                   f"{vehicle}'s gateway status")
        self.node.destroy_subscription(sub)
        return got[-1]

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()


@pytest.fixture
def topside(pool):
    from hindrax_common.testing import ros_context

    with ros_context(pool["topside"]) as ctx:
        side = Topside(ctx, pool)
        yield side
        side.close()


def counts(status) -> dict:
    return {kv.key: kv.value for kv in status.values}


def test_unsigned_wrong_key_and_replayed_operator_requests_are_refused_and_counted(pool, topside):
    from hindrax_msgs.srv import SignedTrigger

    alpha = pool["vehicles"]["alpha"]
    before = len(alpha.calls)
    unsigned = topside.call(SignedTrigger, "/alpha/arm", SignedTrigger.Request())
    assert not unsigned.success and unsigned.message.startswith("arm: refused: unsigned"), unsigned.message
    wrong = Signer(bytes(32), "alpha").sign_message("arm", SignedTrigger.Request())
    answer = topside.call(SignedTrigger, "/alpha/arm", wrong)
    assert not answer.success and answer.message.startswith("arm: refused: bad signature"), answer.message
    signed = Signer(topside.key, "alpha").sign_message("arm", SignedTrigger.Request())
    assert topside.call(SignedTrigger, "/alpha/arm", signed).success
    replay = topside.call(SignedTrigger, "/alpha/arm", signed)
    assert not replay.success and replay.message.startswith("arm: refused: replayed"), replay.message
    assert "\n" not in unsigned.message + answer.message + replay.message
    assert alpha.calls[before:] == [("set_armed", True)]  # the signed one, once
    status = topside.status("alpha", lambda s: int(counts(s)["requests.replayed"]) >= 1)
    c = counts(status)
    assert int(c["requests.unsigned"]) >= 1 and int(c["requests.bad_signature"]) >= 1, c
    # the e-stop needs no signature
    from std_srvs.srv import Trigger
    assert topside.call(Trigger, "/alpha/estop", Trigger.Request()).success


def test_a_goal_or_setpoint_beyond_the_vehicle_is_refused_before_it_goes_inside(pool, topside):
    from hindrax_msgs.msg import ControlSetpoint
    from rclpy.qos import QoSProfile

    alpha = pool["vehicles"]["alpha"]
    before = len(alpha.calls)
    r = hindrax(pool, "ident", "start", "--vehicle", "alpha", "--dofs", "surge", "--levels", str(2**32 - 1),
                "--server-timeout", "30")
    assert r.returncode == 1, r.stdout + r.stderr
    assert "1 DOFs x 4294967295 levels x 30 s" in r.stdout and "supervisor.max_run_time_s = 1800 s" in r.stdout
    assert alpha.calls[before:] == []  # the stand-in identification node never saw it
    pub = topside.node.create_publisher(ControlSetpoint, "/alpha/controller/setpoint", QoSProfile(depth=10))
    signer = Signer(topside.key, "alpha")
    wait_until(lambda: pub.get_subscription_count() > 0, WAIT_S, lambda: topside.executor.spin_once(timeout_sec=0.1),
               "the gateway's setpoint subscription")
    depth = lambda d: signer.sign_message("controller/setpoint", ControlSetpoint(vertical_mode=1, depth_m=d))  # noqa
    pub.publish(depth(1e30))  # first, on the same reliable publisher: it would arrive before the next ones
    pub.publish(ControlSetpoint(vertical_mode=1, depth_m=0.5))  # unsigned
    wait_until(lambda: 1.0 in alpha.setpoints, WAIT_S,
               lambda: (pub.publish(depth(1.0)), topside.executor.spin_once(timeout_sec=0.2)), "a valid setpoint")
    assert set(alpha.setpoints) == {1.0}, alpha.setpoints
    status = topside.status("alpha", lambda s: "depth_m = 1e+30" in counts(s)["last_refusal"] or
                            int(counts(s)["out_of_bounds"]) >= 2)
    assert int(counts(status)["out_of_bounds"]) >= 2, counts(status)  # the goal and the setpoint


def test_a_second_goal_during_a_campaign_is_rejected_at_once_and_never_runs(pool, topside):
    """Issue 74.4: the gateway's campaign relay blocked its executor for the whole campaign, so a second goal went
    unanswered (the CLI: "no answer to the goal within 10 s"), sat in DDS and could start a second campaign once the
    first ended; a cancel of the running goal was not answered either."""
    import time

    from hindrax_msgs.action import RunIdentification
    from rclpy.action import ActionClient

    alpha = pool["vehicles"]["alpha"]
    signer = Signer(topside.key, "alpha")
    goal = lambda *dofs: signer.sign_message("run_identification", RunIdentification.Goal(dofs=list(dofs)))  # noqa
    spin = lambda: topside.executor.spin_once(timeout_sec=0.05)  # noqa: E731
    client = ActionClient(topside.node, RunIdentification, "/alpha/run_identification")
    wait_until(client.server_is_ready, WAIT_S, spin, "the gateway's run_identification")
    before = len(alpha.calls)
    alpha.campaign_entered.clear()
    alpha.campaign_gate.clear()  # the stand-in campaign runs until the gate opens
    try:
        first = client.send_goal_async(goal("surge"))
        wait_until(lambda: first.done() and alpha.campaign_entered.is_set(), WAIT_S, spin, "the first campaign runs")
        assert first.result().accepted
        t0 = time.monotonic()
        second = client.send_goal_async(goal("sway"))
        wait_until(second.done, 10.0, spin, "an answer to the second goal")
        assert not second.result().accepted and time.monotonic() - t0 < 5.0
        status = topside.status("alpha", lambda s: "already running" in counts(s)["last_refusal"])
        assert counts(status)["last_refusal"] == "run_identification: refused: a campaign is already running"
        r = hindrax(pool, "ident", "start", "--vehicle", "alpha", "--dofs", "sway", "--server-timeout", "30")
        assert r.returncode == 1 and "goal rejected: a campaign is already running" in r.stderr, r.stdout + r.stderr
        cancel = first.result().cancel_goal_async()
        wait_until(cancel.done, 10.0, spin, "the gateway's answer to a cancel")
        assert len(cancel.result().goals_canceling) == 1
        assert alpha.calls[before:] == [("run_identification", ["surge"])]
    finally:
        alpha.campaign_gate.set()
    result = first.result().get_result_async()
    wait_until(result.done, WAIT_S, spin, "the first campaign's result")
    # a goal sent after the first ended runs; had the second waited in DDS, it would have run before this one
    third = client.send_goal_async(goal("heave"))
    wait_until(third.done, WAIT_S, spin, "the third goal's answer")
    assert third.result().accepted
    result = third.result().get_result_async()
    wait_until(result.done, WAIT_S, spin, "the third campaign's result")
    assert result.result().result.message == "stand-in campaign done"
    assert alpha.calls[before:] == [("run_identification", ["surge"]), ("run_identification", ["heave"])]
    client.destroy()


def test_an_arm_an_estop_overtook_is_refused_and_the_vehicle_disarmed(pool, topside):
    from std_srvs.srv import Trigger

    alpha = pool["vehicles"]["alpha"]
    estop = topside.node.create_client(Trigger, "/alpha/estop")
    wait_until(estop.service_is_ready, WAIT_S, lambda: topside.executor.spin_once(timeout_sec=0.1), "estop")
    before = len(alpha.calls)
    alpha.arm_entered.clear()
    alpha.arm_gate.clear()  # the ESC takes the arm and holds its answer
    env = child_env(ROS_DOMAIN_ID=str(pool["topside"]), HINDRAX_KEYS_DIR=str(pool["keys"]))
    with subprocess.Popen([sys.executable, "-m", "hindrax_tools.cli", "arm", "--vehicle",
                           "alpha", "--timeout", "30"],
                          stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env) as arm:
        try:
            wait_until(alpha.arm_entered.is_set, 120, message="the arm reached the ESC")
            future = estop.call_async(Trigger.Request())
            wait_until(future.done, WAIT_S, lambda: topside.executor.spin_once(timeout_sec=0.05), "e-stop answer")
            assert future.result().success
        finally:
            alpha.arm_gate.set()  # now the ESC answers "armed", after the e-stop
        out, err = arm.communicate(timeout=60)
    assert arm.returncode == 1, out + err
    assert "alpha: arm refused: arm: refused: an e-stop arrived before the arm completed; disarmed again" in err, err
    wait_until(lambda: ("set_armed", False) in alpha.calls[before:], 10.0, message="the gateway disarmed again")
    # (the stand-in records the arm when it answers, after the e-stop it let through meanwhile)
    assert alpha.calls[before:] == ["supervisor/estop", ("set_armed", True), ("set_armed", False)], alpha.calls[before:]


def test_a_captured_arm_is_refused_with_2_48_added_and_after_a_gateway_restart(pool, topside):
    """Issue 71 findings 1 and 3 through the real gateway: the copy an eavesdropper keeps is worth nothing, with
    its timestamp raised by 2^48 or replayed unchanged after the gateway restarted; the replay cache is a 0600 file
    next to the key."""
    import stat

    from hindrax_msgs.srv import SignedTrigger

    alpha = pool["vehicles"]["alpha"]
    before = len(alpha.calls)
    signer, answers = Signer(topside.key, "alpha"), []

    def armed() -> bool:  # an e-stop of the test before may still count as overtaking it, and run alone the gateway
        # may not yet see the vehicle's ESC service ("not available on the vehicle"): sign again, send again
        answers.append((signer.sign_message("arm", SignedTrigger.Request()), None))
        answers[-1] = (answers[-1][0], topside.call(SignedTrigger, "/alpha/arm", answers[-1][0]))
        why = answers[-1][1].message
        return answers[-1][1].success or "e-stop arrived" not in why and "not available on the vehicle" not in why
    # Each attempt after a gap longer than QUEUE_GAP_S: a request sooner after the last one counts as
    # queued behind it, so an e-stop before that busy spell began overtakes every back-to-back retry
    # (60 s of them failed a run).
    gap = threading.Event()
    try:
        wait_until(armed, WAIT_S, lambda: gap.wait(2 * QUEUE_GAP_S), "an arm accepted")
    except AssertionError as exc:
        last = answers[-1][1].message
        raise AssertionError(f"{exc}: {len(answers)} attempts, the last answered {last!r}") from exc
    signed, answer = answers[-1]
    assert answer.success, answer.message
    lifted = SignedTrigger.Request()
    lifted.signature.link_id, lifted.signature.mac = signed.signature.link_id, signed.signature.mac
    lifted.signature.timestamp = signed.signature.timestamp + (1 << 48)
    answer = topside.call(SignedTrigger, "/alpha/arm", lifted)
    assert not answer.success and "out of range" in answer.message, answer.message
    assert stat.S_IMODE((pool["keys"] / "alpha.replay").stat().st_mode) == 0o600
    runner = pool["runners"][0]
    runner.stop()
    runner.start()
    wait_until(lambda: runner.log("gateway").count("internal domain") >= 2, 60, message="the gateway restarted")
    answer = topside.call(SignedTrigger, "/alpha/arm", signed)
    assert not answer.success and answer.message.startswith("arm: refused: replayed"), answer.message
    assert alpha.calls[before:] == [("set_armed", True)]  # the accepted one, once

def test_another_server_of_an_operator_service_is_reported_and_arming_refused(pool, topside):
    """Issue 71.2: a second server of /alpha/arm receives every signed request; the gateway's
    status (ERROR, also inside on /diagnostics for hindrax health) and the CLI name it, and the
    gateway refuses to arm meanwhile. The server answers the CLI's arm "armed", and a second
    action server accepts its campaign (a DDS client takes the first answer, and nothing says
    whose): the CLI reports the outcome unknown and exits 1, never "armed" or "started"."""
    from rclpy.action import ActionServer

    from hindrax_msgs.action import RunIdentification
    from hindrax_msgs.srv import SignedTrigger

    alpha = pool["vehicles"]["alpha"]
    before = len(alpha.calls)
    heard: list = []
    lie = threading.Event()

    def answer(req, resp):
        heard.append(req)
        if lie.is_set():
            resp.success, resp.message = True, "armed"
        return resp

    def accept(goal_handle):
        goal_handle.succeed()
        return RunIdentification.Result(success=True, message="campaign complete")

    spy = topside.node.create_service(SignedTrigger, "/alpha/arm", answer)
    spy_action = ActionServer(topside.node, RunIdentification, "/alpha/run_identification", accept)
    try:
        status = topside.status("alpha", lambda s: s.level == b"\x02")
        assert status.message.startswith("another server answers /alpha/arm (2 servers)"), status.message
        # a new client may send before it has matched the second server: again until that one hears it
        runs: list = []
        lie.set()
        try:
            wait_until(lambda: runs.append(hindrax_spinning(pool, topside, "arm", "--vehicle", "alpha")) or heard,
                       WAIT_S, None, "the second server heard a CLI arm")
        finally:
            lie.clear()
        for r in runs:
            assert "warning: vehicle 'alpha': another server answers /alpha/arm (2 servers)" in r.stderr, r.stderr
            assert r.returncode == 1 and "armed" not in r.stdout, (r.stdout, r.stderr)
            assert "/alpha/arm: 2 servers answer it" in r.stderr, r.stderr
            assert "outcome is unknown" in r.stderr, r.stderr
        r = hindrax_spinning(pool, topside, "ident", "start", "--vehicle", "alpha", "--dofs",
                             "surge")
        assert r.returncode == 1 and "campaign started" not in r.stdout, (r.stdout, r.stderr)
        assert "/alpha/run_identification: 2 servers answer its goals" in r.stderr, r.stderr
        signed = Signer(topside.key, "alpha").sign_message("arm", SignedTrigger.Request())
        client = topside.node.create_client(SignedTrigger, "/alpha/arm")
        future = client.call_async(signed)
        wait_until(lambda: heard and len(alpha.calls) >= before, WAIT_S,
                   lambda: topside.executor.spin_once(timeout_sec=0.1), "the spy heard the arm")
        status = topside.status("alpha", lambda s: "another server" in counts(s)["last_refusal"])
        assert counts(status)["last_refusal"].startswith("arm: refused: another server answers /alpha/arm")
        assert ("set_armed", True) not in alpha.calls[before:]
        assert not (future.done() and future.result().success)
    finally:
        topside.node.destroy_service(spy)
        spy_action.destroy()
    status = topside.status("alpha", lambda s: s.level == b"\x00")
    assert status.message == "ok", status.message


def test_a_second_gateway_with_the_same_name_is_reported_and_arming_refused(pool, topside):
    """Runs last: the impostor stays on the topside graph's caches for a while after it stops."""
    from hindrax_msgs.srv import SignedTrigger

    alpha = pool["vehicles"]["alpha"]
    with fresh_domain() as impostor_domain:
        runner = ProcessRunner([gateway_process(vehicle_file(pool["tmp"], "alpha"), pool["topside"])],
                               env=child_env(ROS_DOMAIN_ID=str(impostor_domain), HINDRAX_KEYS_DIR=str(pool["keys"])),
                               log_dir=pool["tmp"] / "impostor")
        runner.start()
        try:
            wait_until(lambda: "internal domain" in runner.log("gateway"), 60, message="the impostor started")
            status = topside.status("alpha", lambda s: s.level == b"\x02")
            assert "is answered by 2 gateways" in status.message, status.message
            before = len(alpha.calls)
            r = hindrax(pool, "arm", "--vehicle", "alpha")
            assert r.returncode == 1 and len(r.stderr.strip().splitlines()) == 1, r.stderr
            line = r.stderr.strip()
            assert "vehicle 'alpha' is answered by 2 gateways (participants " in line, line
            assert len(line.split("(participants ")[1].split(")")[0].split(", ")) == 2, line  # names both
            signed = Signer(topside.key, "alpha").sign_message("arm", SignedTrigger.Request())
            answer = topside.call(SignedTrigger, "/alpha/arm", signed)
            assert not answer.success and "is answered by 2 gateways" in answer.message, answer.message
            assert ("set_armed", True) not in alpha.calls[before:]
        finally:
            runner.stop()

