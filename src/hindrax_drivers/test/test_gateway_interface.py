"""The gateway's interface list and the choice of a vehicle by name (pure: hindrax_drivers.gateway.interface)."""
import pytest

from hindrax_drivers.gateway.interface import (INTERFACE, VehicleChoiceError, choose_vehicle, relays,
                                               vehicles_seen)


def test_the_safety_graph_has_no_entry_in_the_interface():
    internal = {r.internal for r in INTERFACE}
    for name in ("/supervisor/heartbeat", "/esc/heartbeat", "/esc/output_state", "/guard/heartbeat",
                 "/thrusters/command_pulse_width",
                 "/pressure/zero_depth", "/supervisor/abort", "/wrench"):
        assert name not in internal
    assert {r.who for r in INTERFACE if r.topside == "estop"} == {"anyone"}  # stopping needs no credentials
    assert all(r.who == "operator" for r in relays("service") + relays("action") + relays("topic_in")
               if r.topside != "estop")
    assert all(r.who == "read" for r in relays("topic_out"))
    assert len({r.topside for r in INTERFACE}) == len(INTERFACE)


def test_vehicles_are_the_namespaces_of_gateway_nodes():
    nodes = [("gateway", "/alpha"), ("gateway_operator", "/alpha"), ("gateway", "/bravo"), ("esc", "/"),
             ("gateway", "/")]
    assert vehicles_seen(nodes) == ["alpha", "bravo"]


def test_choose_exactly_one_or_refuse_in_one_line():
    assert choose_vehicle(["alpha"], None) == "alpha"
    assert choose_vehicle(["alpha", "bravo"], "bravo") == "bravo"
    for seen, wanted, words in (([], None, "no vehicle on domain 7"),
                                (["alpha", "bravo"], None, "several vehicles on domain 7 (alpha, bravo)"),
                                (["alpha"], "bravo", "vehicle 'bravo' not seen on domain 7 (seen: alpha)")):
        with pytest.raises(VehicleChoiceError) as exc:
            choose_vehicle(seen, wanted, "domain 7")
        assert words in str(exc.value) and "\n" not in str(exc.value)
