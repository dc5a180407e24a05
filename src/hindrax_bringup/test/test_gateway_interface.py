"""The gateway's interface list and the choice of a vehicle by name (pure: hindrax_bringup.gateway.interface)."""
import pytest

from hindrax_bringup.gateway.interface import (INTERFACE, VehicleChoiceError, choose_vehicle, relays,
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


def test_two_gateways_with_one_name_are_named_in_one_line():
    from hindrax_bringup.gateway.interface import duplicate_problem, participants

    one = bytes(range(12)) + b"\x00\x00\x01\x03"
    same_participant = bytes(range(12)) + b"\x00\x00\x02\x03"  # another endpoint of the same gateway
    other = bytes(range(100, 112)) + b"\x00\x00\x01\x03"
    assert participants([one, same_participant]) == ["00.01.02.03.04.05.06.07.08.09.0a.0b"]
    assert duplicate_problem("alpha", participants([one, same_participant])) == ""
    line = duplicate_problem("alpha", participants([one, other]))
    assert line == ("vehicle 'alpha' is answered by 2 gateways (participants 00.01.02.03.04.05.06.07.08.09.0a.0b, "
                    "64.65.66.67.68.69.6a.6b.6c.6d.6e.6f): two vehicles share the name; give one another vehicle.name")


def test_every_operator_element_carries_a_signature_and_the_estop_none():
    from hindrax_bringup.gateway.internal import interface_type

    for relay in INTERFACE:
        cls = interface_type(relay.type)
        fields = (cls.Request if relay.kind == "service" else cls.Goal if relay.kind == "action" else cls)
        signed = "signature" in fields.get_fields_and_field_types()
        assert signed == (relay.who == "operator"), relay
