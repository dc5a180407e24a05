"""What speaks for a vehicle on a ROS graph (:mod:`hindrax_common.node_support.vehicle_graph`), pure: the topics a bag
must not replay by default, and the ESCs and supervisors a graph shows beyond the caller's own."""
from __future__ import annotations

from types import SimpleNamespace

import pytest

from hindrax_common.node_support.vehicle_graph import ForeignVehicleError, ForeignVehicleWatch, GraphView, \
    _refuse_heartbeat_endpoint, foreign_vehicle_processes, split_vehicle_topics, vehicle_topic_reason

#: topics of the vehicle's launch layout that command the thrusters or vouch for a safety process
SPEAKS = ["/supervisor/heartbeat", "guard/heartbeat", "/esc/heartbeat", "/esc/output_state",
          "/thrusters/command_pulse_width", "/thrusters/pulse_width", "/thrusters/forces", "/supervisor/status",
          "/supervisor/abort", "/wrench",
          "/controller/setpoint", "/run_identification/_action/status", "/run_identification/_action/feedback",
          "/rov1/esc/heartbeat", "/rov1/wrench", "/output_guard/state", "rq/esc/set_armedRequest"]
#: sensor data and status a bag may replay onto any graph
FREE = ["/dvl/data", "/imu/data_raw", "/pressure/fluid_pressure", "/ping/altitude", "/tf_static", "/clock",
        "/diagnostics", "/sim/wrench", "/sim/odometry", "/identification/status", "/allocation/status",
        "/controller/status", "/raw/dvl75", "/escape/data", "/heartbeats_seen"]


@pytest.mark.parametrize("topic", SPEAKS)
def test_safety_and_actuation_topics_are_named_with_a_reason(topic):
    assert vehicle_topic_reason(topic)


@pytest.mark.parametrize("topic", FREE)
def test_sensor_and_status_topics_replay_freely(topic):
    assert vehicle_topic_reason(topic) is None


def test_split_keeps_order_and_reasons():
    free, withheld = split_vehicle_topics(["/dvl/data", "/esc/heartbeat", "/imu/data_raw", "/wrench"])
    assert free == ["/dvl/data", "/imu/data_raw"]
    assert list(withheld) == ["/esc/heartbeat", "/wrench"]
    assert "heartbeat" in withheld["/esc/heartbeat"] and "allocation" in withheld["/wrench"]


def test_a_graph_with_only_its_own_safety_nodes_has_nothing_foreign():
    own = GraphView(("/esc", "/supervisor", "/dvl75"), {"/esc/heartbeat": ("/esc",),
                                                       "/supervisor/heartbeat": ("/supervisor",)})
    seen = GraphView(("/esc", "/supervisor", "/dvl75", "/hindrax_health"), own.heartbeat_publishers)
    assert foreign_vehicle_processes(seen, own) == []
    # sensors of another graph are not a vehicle's safety graph
    assert foreign_vehicle_processes(GraphView(("/dvl75", "/recorder")), GraphView()) == []


def test_a_second_node_of_the_same_name_is_foreign():
    own = GraphView(("/esc", "/supervisor"), {"/supervisor/heartbeat": ("/supervisor",)})
    seen = GraphView(("/esc", "/supervisor", "/supervisor"), {"/supervisor/heartbeat": ("/supervisor", "/supervisor")})
    assert foreign_vehicle_processes(seen, own) == ["supervisor /supervisor"]


def test_namespaced_and_forged_publishers_are_named():
    seen = GraphView(("/rov2/esc", "/forger"), {"/esc/heartbeat": ("/forger",), "/rov2/esc/heartbeat": ("/rov2/esc",),
                                                "/dvl/heartbeat": ("/x",)})
    assert foreign_vehicle_processes(seen) == ["ESC /rov2/esc", "ESC heartbeat publisher /forger on /esc/heartbeat"]


class _Graph:
    """Stands in for an rclpy node's graph API."""

    def __init__(self, nodes, pubs=None, domain=7):
        self.nodes, self.pubs = nodes, dict(pubs or {})
        self.context = type("Ctx", (), {"get_domain_id": lambda _self: domain})()
        self.timers = []  # (period_s, callback) of create_timer

    def create_timer(self, period_s, callback):
        self.timers.append((period_s, callback))
        return len(self.timers)

    def get_node_names_and_namespaces(self):
        return [(n.rsplit("/", 1)[1], n.rsplit("/", 1)[0] or "/") for n in self.nodes]

    def get_topic_names_and_types(self):
        return [(t, ["diagnostic_msgs/msg/DiagnosticStatus"]) for t in self.pubs]

    def get_publishers_info_by_topic(self, topic):
        return [type("Info", (), {"node_name": n.rsplit("/", 1)[1], "node_namespace": n.rsplit("/", 1)[0] or "/"})()
                for n in self.pubs[topic]]


def test_watch_settles_after_the_window_and_refuses_with_one_line_naming_domain_and_node():
    t = [0.0]
    graph = _Graph(["/run", "/dvl75"])
    watch = ForeignVehicleWatch(graph, "refused", "no second graph", window_s=2.5, clock=lambda: t[0])
    assert not watch.settled()
    t[0] = 2.5
    assert watch.settled()
    graph.nodes.append("/supervisor")
    graph.pubs["/supervisor/heartbeat"] = ["/supervisor"]
    with pytest.raises(ForeignVehicleError) as err:
        watch.settled()
    msg = str(err.value)
    assert "\n" not in msg
    assert msg == "refused: ROS domain 7 already has supervisor /supervisor; no second graph"


def test_after_the_window_the_watch_checks_every_second_and_names_a_late_vehicle_once_per_name():
    """``hindrax bringup`` and ``hindrax run`` keep checking after the window (a loaded machine discovers late, a
    second graph may start later): one timer of CHECK_PERIOD_S whose every tick looks at the graph again."""
    t = [0.0]
    graph = _Graph(["/run", "/esc"], {"/esc/heartbeat": ["/esc"]})
    own = GraphView(("/run", "/esc"), {"/esc/heartbeat": ("/esc",)})
    watch = ForeignVehicleWatch(graph, "refused", "no second graph", own=lambda: own, clock=lambda: t[0])
    t[0] = 2.5
    assert watch.settled()
    assert watch.check_every() == 1
    [(period_s, tick)] = graph.timers
    assert period_s == 1.0
    tick()  # only its own ESC: nothing raised
    graph.nodes += ["/esc", "/esc"]  # two more processes named /esc appear after the window
    assert watch.found() == ["ESC /esc", "ESC /esc"]  # one phrase per process
    with pytest.raises(ForeignVehicleError) as err:
        tick()
    assert str(err.value) == "refused: ROS domain 7 already has ESC /esc (2 processes); no second graph"


def test_poll_looks_at_the_graph_once_per_period_of_its_clock():
    """A loop of the tool's own (``hindrax bag play``) calls poll() at every turn: the graph is read once per
    period_s, and a vehicle appearing in between is refused at the next due poll."""
    t = [0.0]
    graph = _Graph(["/player"])
    reads = []
    names = graph.get_node_names_and_namespaces
    graph.get_node_names_and_namespaces = lambda: reads.append(t[0]) or names()
    watch = ForeignVehicleWatch(graph, "refused", "no replay", period_s=0.2, clock=lambda: t[0])
    for t[0] in (0.0, 0.05, 0.1, 0.19, 0.2, 0.3, 0.41):
        watch.poll()
    assert reads == [0.0, 0.2, 0.41]
    graph.nodes.append("/supervisor")
    t[0] = 0.5
    watch.poll()  # not due yet (next at 0.61 s)
    t[0] = 0.65
    with pytest.raises(ForeignVehicleError, match="^refused: ROS domain 7 already has supervisor /supervisor; no "
                                                  "replay$"):
        watch.poll()


def test_an_unnamed_heartbeat_publisher_refuses_once_the_window_has_passed():
    """rmw lists a publisher before its node's name arrives (``_NODE_NAME_UNKNOWN_``): the look-out, which has no
    publisher of its own, refuses on the endpoint alone; a subscriber or another topic refuses nothing."""
    def lookout(publishers: dict[str, int]):
        return SimpleNamespace(
            get_topic_names_and_types=lambda: [(t, ["diagnostic_msgs/msg/DiagnosticStatus"]) for t in publishers],
            count_publishers=lambda name: publishers[name],
            context=SimpleNamespace(get_domain_id=lambda: 42))

    watch = SimpleNamespace(what="refused", consequence="refusing to start")
    _refuse_heartbeat_endpoint(lookout({"/esc/heartbeat": 0, "/imu/data_raw": 1}), watch)  # a reader only: fine
    with pytest.raises(ForeignVehicleError, match=r"^refused: ROS domain 42 already has a publisher of "
                                                  r"/pool/esc/heartbeat \(ESC\); refusing to start$"):
        _refuse_heartbeat_endpoint(lookout({"/pool/esc/heartbeat": 1}), watch)
    with pytest.raises(ForeignVehicleError, match=r"supervisor/heartbeat \(supervisor\)"):
        _refuse_heartbeat_endpoint(lookout({"/supervisor/heartbeat": 2}), watch)
