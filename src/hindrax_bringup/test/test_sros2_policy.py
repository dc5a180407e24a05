"""SROS2 on the Pi: the vehicle's permissions policies validate against sros2's policy schema and grant
what docs/architecture.md §8.2 says: e-stop to any topside enclave, the rest of the gateway's interface to the operator
enclave only, the internal graph's topics to the vehicle's own enclaves only.

The schema is sros2's ``policy.xsd`` (third_party/sros2, vendored: no sros2 wheel exists), validated with lxml, the
XML namespace schema it imports resolved to the vendored copy (no network).
"""
from __future__ import annotations

import copy
import subprocess
import sys
from pathlib import Path

import pytest
from lxml import etree

from hindrax_common.config import default_config_path, load_config
from hindrax_bringup.gateway.interface import INTERFACE
from hindrax_bringup.gateway.sros2_policy import INTERNAL_ACTIONS, INTERNAL_SERVICES, INTERNAL_TOPICS, NODE_SERVICES, \
    NODE_TOPICS, TOOLS_ENCLAVE, gateway_internal_enclave, launch_enclaves, topside_enclaves
from hindrax_onboard.commands.sros2 import write_policies

SCHEMAS = Path(__file__).resolve().parents[3] / "third_party" / "sros2"
XML_XSD_URL = "http://www.w3.org/2001/03/xml.xsd"


class _Local(etree.Resolver):
    """The XML namespace schema policy.xsd imports by URL, from the vendored copy."""

    def resolve(self, url, pubid, context):
        if url == XML_XSD_URL:
            return self.resolve_filename(str(SCHEMAS / "xml.xsd"), context)
        return None


def policy_schema() -> etree.XMLSchema:
    parser = etree.XMLParser(no_network=True)
    parser.resolvers.add(_Local())
    return etree.XMLSchema(etree.parse(str(SCHEMAS / "policy.xsd"), parser))


@pytest.fixture(scope="module")
def policies(tmp_path_factory):
    paths = write_policies(None, tmp_path_factory.mktemp("policies"))
    return {k: etree.parse(str(p)) for k, p in paths.items()}


def grants(tree, enclave: str) -> dict[tuple[str, str, str], set]:
    """{(element, attribute, ALLOW|DENY): names} of one enclave."""
    out: dict = {}
    for lst in tree.find(f"enclaves/enclave[@path='{enclave}']").iter("topics", "services", "actions"):
        for attr, value in lst.attrib.items():
            out.setdefault((lst.tag, attr, value), set()).update(e.text for e in lst)
    return out


def test_both_policies_validate_against_the_sros2_schema(policies):
    schema = policy_schema()
    for name, tree in policies.items():
        assert schema.validate(tree), (name, schema.error_log)


def test_the_schema_rejects_what_sros2_would(policies):
    schema = policy_schema()
    bad = etree.fromstring(etree.tostring(policies["topside"]))
    bad.find(".//services").set("request", "MAYBE")  # only ALLOW and DENY exist
    assert not schema.validate(bad)
    bad = etree.fromstring(etree.tostring(policies["topside"]))
    del bad.attrib["version"]
    assert not schema.validate(bad)


def test_topside_estop_for_anyone_the_rest_for_the_operator_only(policies):
    name = load_config(default_config_path()).vehicle.name
    roles = topside_enclaves(name)
    tree = policies["topside"]
    assert {e.get("path") for e in tree.iter("enclave")} == set(roles.values())
    ns = f"/{name}/"
    operator_calls = {ns + r.topside for r in INTERFACE if r.kind == "service" and r.who == "operator"}
    assert {ns + "arm", ns + "disarm", ns + "reset", ns + "recorder/start", ns + "recorder/stop"} <= operator_calls
    anyone = grants(tree, roles["topside"])
    assert anyone[("services", "request", "ALLOW")] == {ns + "estop"}
    assert anyone[("services", "request", "DENY")] == operator_calls
    assert anyone[("actions", "call", "DENY")] == {ns + "run_identification"}
    assert anyone[("topics", "publish", "DENY")] == {ns + "controller/setpoint"}
    operator = grants(tree, roles["operator"])
    assert operator[("services", "request", "ALLOW")] == operator_calls | {ns + "estop"}
    assert operator[("actions", "call", "ALLOW")] == {ns + "run_identification"}
    assert operator[("topics", "publish", "ALLOW")] - set(NODE_TOPICS) == {ns + "controller/setpoint"}
    gateway = grants(tree, roles["gateway"])
    assert gateway[("services", "reply", "ALLOW")] - set(NODE_SERVICES) == operator_calls | {ns + "estop"}
    # nothing of the internal graph on the topside: every name there is the vehicle's interface or a node's own
    for enclave in roles.values():
        for (_tag, _attr, _q), names in grants(tree, enclave).items():
            outside = {n for n in names if not n.startswith(ns) and n not in NODE_TOPICS and not n.startswith("~/")}
            assert not outside, (enclave, outside)
    assert not any("heartbeat" in e.text or "thrusters" in e.text or "esc/" in e.text for e in tree.iter("topic"))


def test_every_vehicle_process_has_an_enclave_with_the_internal_graph(policies):
    from hindrax_bringup.layout.launch_xml import ament_share, read_launch

    processes = read_launch(ament_share("hindrax_bringup") / "launch" / "vehicle.launch.xml",
                            {"record": "true", "controller": "true"})
    processes += read_launch(ament_share("hindrax_onboard") / "launch" / "pool_test.launch.xml", {})
    hindrax = [p for p in processes if p.package.startswith("hindrax")]
    enclaves = launch_enclaves(hindrax)  # raises for a process without --enclave
    tree = policies["internal"]
    assert {e.get("path") for e in tree.iter("enclave")} == set(enclaves) | {gateway_internal_enclave(), TOOLS_ENCLAVE}
    assert {n for nodes in enclaves.values() for n in nodes} >= {"esc", "supervisor", "output_guard", "recorder",
                                                                  "thrust_allocation", "identification"}
    for enclave in [*enclaves, TOOLS_ENCLAVE]:
        g = grants(tree, enclave)
        assert set(INTERNAL_TOPICS) <= g[("topics", "publish", "ALLOW")]
        assert set(INTERNAL_SERVICES) <= g[("services", "request", "ALLOW")]


@pytest.mark.ros
def test_the_internal_lists_cover_every_name_the_vehicle_nodes_use(tmp_path):
    """The nodes of the stack (the in-process graph, recorder and controller included) use no topic or service the
    internal policy does not grant, and the gateway relays only internal names it grants."""
    from hindrax_common.testing import ros_context
    from hindrax_sim.graph.bringup import build_graph

    with ros_context() as ctx:
        graph = build_graph(default_config_path(), sim=True, context=ctx, record=True, record_dir=str(tmp_path / "b"),
                            controller=True)
        try:
            used_topics, used_services = set(), set()
            for name, node in graph.nodes.items():
                if name == "simulator":  # the virtual pool's, never on the vehicle
                    continue
                used_topics |= {e.topic_name for e in [*node.publishers, *node.subscriptions]}
                used_services |= {"/" + s.srv_name.lstrip("/") for s in [*node.services, *node.clients]}
        finally:
            graph.shutdown()
    simulated = {"/clock", "/sim/odometry", "/sim/wrench", "/sim/contact"}
    assert used_topics - simulated - set(NODE_TOPICS) <= set(INTERNAL_TOPICS), \
        sorted(used_topics - simulated - set(NODE_TOPICS) - set(INTERNAL_TOPICS))
    parameters = {s for s in used_services if "~/" + s.rsplit("/", 1)[-1] in NODE_SERVICES}
    assert used_services - parameters <= set(INTERNAL_SERVICES), sorted(used_services - parameters)
    for relay in INTERFACE:
        internal = {"service": INTERNAL_SERVICES, "action": INTERNAL_ACTIONS}.get(relay.kind, INTERNAL_TOPICS)
        assert relay.internal in internal or (relay.topside, relay.internal) == ("gateway/status", ""), relay


def test_keystore_without_sros2_says_where_it_comes_from(tmp_path):
    r = subprocess.run([sys.executable, "-m", "hindrax_onboard.cli", "sros2", "keystore",
                        str(tmp_path / "ks")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 1
    assert r.stderr.strip().splitlines() == [r.stderr.strip()]
    assert "ros-jazzy-sros2" in r.stderr and "sros2 is not installed" in r.stderr


def governance_schema() -> etree.XMLSchema:
    """The DDS Security 1.1 governance schema, vendored (third_party/sros2/README.md)."""
    return etree.XMLSchema(etree.parse(str(SCHEMAS / "governance.xsd")))


def test_the_governance_validates_against_the_dds_security_schema():
    from hindrax_bringup.gateway.sros2_policy import governance

    schema = governance_schema()
    root = etree.fromstring(governance("alpha", 3, 42).encode())
    assert schema.validate(root), schema.error_log
    # and the schema is strict enough to catch what Fast DDS would refuse to load
    bad = copy.deepcopy(root)
    bad.find("domain_access_rules/domain_rule/rtps_protection_kind").text = "OPEN"
    assert not schema.validate(bad)
    bad = copy.deepcopy(root)
    rule = bad.find("domain_access_rules/domain_rule")
    rule.remove(rule.find("enable_join_access_control"))
    assert not schema.validate(bad)


def test_the_governance_opens_the_topside_estop_to_unauthenticated_participants_and_nothing_else():
    """The DDS Security governance (sros2's default refuses every participant without a certificate, the e-stop
    included): its rules, read from the XML."""
    from hindrax_bringup.gateway.sros2_policy import governance

    root = etree.fromstring(governance("alpha", 3, 42).encode())
    rules = {int(r.findtext("domains/id")): r for r in root.iterfind("domain_access_rules/domain_rule")}
    assert sorted(rules) == [3, 42]
    assert rules[3].findtext("allow_unauthenticated_participants") == "false"
    assert rules[42].findtext("allow_unauthenticated_participants") == "true"
    assert {rules[42].findtext(k) for k in ("discovery_protection_kind", "liveliness_protection_kind",
                                            "rtps_protection_kind")} == {"NONE"}

    def topics(rule):
        return [(t.findtext("topic_expression"), t.findtext("enable_read_access_control"),
                 t.findtext("enable_write_access_control"), t.findtext("data_protection_kind"))
                for t in rule.iterfind("topic_access_rules/topic_rule")]
    # first match wins: the e-stop's request and reply open, then everything else closed and encrypted
    assert topics(rules[42]) == [("rq/alpha/estopRequest", "false", "false", "NONE"),
                                 ("rr/alpha/estopReply", "false", "false", "NONE"), ("*", "true", "true", "ENCRYPT")]
    assert topics(rules[3]) == [("*", "true", "true", "ENCRYPT")]
    with pytest.raises(ValueError, match="both 7"):
        governance("alpha", 7, 7)
