"""The vehicle's SROS2 permissions policy: which enclave may publish, subscribe, call or serve what.

SROS2 (ROS 2's DDS Security tooling) turns a policy file (format 0.2.0, sros2's ``policy.xsd``) into one signed DDS
permissions document per *enclave*; a process joins the graph with its enclave's certificate and may use only what
its permissions grant (default deny). This module writes the policy that matches docs/architecture.md §8.2:

- **internal domain** (the vehicle's loopback graph): one enclave per process of the launch layout, named by the
  ``--enclave`` its ``<node>`` passes (``/vehicle/<process>``, :func:`launch_enclaves`), plus ``/vehicle/gateway`` (the
  gateway's internal side) and ``/vehicle/tools`` (the ``hindrax`` commands run on the vehicle). Each may use every
  topic, service and action of the internal graph (:data:`INTERNAL_TOPICS`, :data:`INTERNAL_SERVICES`,
  :data:`INTERNAL_ACTIONS`): the vehicle trusts its own processes; what it keeps from the topside is the domain itself.
- **topside domain**, under ``/<vehicle.name>/``: ``/<name>/gateway`` serves the gateway's interface
  (:data:`hindrax_bringup.gateway.interface.INTERFACE`); ``/<name>/operator`` may call all of it (arm, disarm,
  reset, setpoints, campaign, recorder); ``/<name>/topside`` (every other topside participant) may call ``estop``
  and read the telemetry, nothing else. No topside enclave is granted an internal topic (heartbeats,
  ``thrusters/*``, ``esc/*``): they exist on the internal domain only.

**Governance** (:func:`governance`): sros2's default governance refuses every participant without a certificate,
which would refuse an e-stop from a laptop without credentials ("stopping never needs credentials"). The vehicle's
governance (DDS Security 1.1 §9.4.1.2) allows unauthenticated participants on the topside domain and leaves exactly
the e-stop's two DDS topics (``rq/<name>/estopRequest``, ``rr/<name>/estopReply``) open, without access control or
protection; every other topic of the topside, and the whole internal domain, needs a certificate and its
permissions, encrypted. ``hindrax sros2 keystore`` writes it into the keystore and signs it with the permissions CA.

DDS permissions name one domain per grant (sros2 writes ``ROS_DOMAIN_ID`` into every grant), so the internal and the
topside enclaves are two policies, :func:`internal_policy` and :func:`topside_policy`, turned into permissions with
the internal and the topside domain id respectively (``hindrax sros2 keystore``).

Pure: strings in, XML text out (``xml.etree``); no rclpy, no sros2."""
from __future__ import annotations

import xml.etree.ElementTree as ET
from typing import Iterable, Mapping

from .interface import GATEWAY_NODE, INTERFACE

__all__ = ["TOOLS_ENCLAVE", "governance", "INTERNAL_ACTIONS", "INTERNAL_ENCLAVE_ROOT", "INTERNAL_SERVICES",
           "INTERNAL_TOPICS", "NODE_SERVICES", "NODE_TOPICS", "POLICY_VERSION", "enclave_of",
           "gateway_internal_enclave", "internal_policy", "launch_enclaves", "topside_enclaves", "topside_policy"]

#: sros2's policy format (``policy.xsd`` fixes the attribute ``version`` to it)
POLICY_VERSION = "0.2.0"
#: prefix of the internal enclaves (one vehicle per keystore: the name is not needed on the loopback graph)
INTERNAL_ENCLAVE_ROOT = "/vehicle"

#: the enclave of the ``hindrax`` commands run on the vehicle (``hindrax health``, the container's health check):
#: the entry point gives it through ``ROS_SECURITY_ENCLAVE_OVERRIDE``
TOOLS_ENCLAVE = f"{INTERNAL_ENCLAVE_ROOT}/tools"
#: every topic of the vehicle's internal graph (what its nodes publish or subscribe; checked against the nodes by
#: test_sros2_policy.py)
INTERNAL_TOPICS = (
    "/allocation/status", "/controller/setpoint", "/controller/status", "/diagnostics", "/dvl/altitude", "/dvl/data",
    "/dvl/twist", "/esc/heartbeat", "/esc/output_state", "/guard/heartbeat", "/identification/calibration",
    "/identification/estimates", "/identification/status", "/imu/data_raw", "/imu/mag", "/imu/temperature",
    "/lights/brightness", "/odom", "/ping/altitude", "/ping/confidence", "/pressure/depth",
    "/pressure/fluid_pressure", "/pressure/temperature", "/raw/dvl75", "/raw/icm20948", "/raw/ms5837",
    "/raw/pca9685", "/raw/ping1d", "/supervisor/abort", "/supervisor/heartbeat", "/supervisor/status", "/tf",
    "/tf_static", "/thrusters/command_pulse_width", "/thrusters/forces", "/thrusters/pulse_width",
    "/thrusters/test_forces", "/wrench",
)
#: every service of the internal graph besides the nodes' parameter services
INTERNAL_SERVICES = (
    "/controller/enable", "/controller/hold", "/esc/set_armed", "/identification/continue", "/pressure/zero_depth",
    "/recorder/start", "/recorder/stop", "/supervisor/estop", "/supervisor/reset",
)
#: the internal graph's actions
INTERNAL_ACTIONS = ("/run_identification",)
#: what every rclpy node publishes and subscribes on its own (``/rosout`` logging, parameter events)
NODE_TOPICS = ("/rosout", "/parameter_events")
#: the parameter and type-description services every rclpy node serves (private names, ``~/``)
NODE_SERVICES = ("~/describe_parameters", "~/get_parameter_types", "~/get_parameters", "~/get_type_description",
                 "~/list_parameters", "~/set_parameters", "~/set_parameters_atomically")


def enclave_of(arguments: Iterable[str]) -> str | None:
    """The ``--enclave`` a process's command-line arguments give (``--ros-args ... --enclave PATH``), or None."""
    args = list(arguments)
    for i, a in enumerate(args[:-1]):
        if a in ("--enclave", "-e"):
            return args[i + 1]
    return None


def launch_enclaves(processes: Iterable) -> dict[str, tuple[str, ...]]:
    """{enclave: node names} of the launch layout's processes (:class:`~hindrax_bringup.layout.launch_xml.NodeProcess`,
    from :func:`~hindrax_bringup.layout.launch_xml.read_launch`). A process of this package without ``--enclave`` is an
    error (ValueError naming it); the gateway is left out (its two contexts have :func:`gateway_internal_enclave`
    and the topside enclave)."""
    out: dict[str, list[str]] = {}
    for p in processes:
        if p.executable == "gateway_node":
            continue
        enclave = enclave_of(p.arguments)
        if enclave is None:
            if p.package.startswith("hindrax"):
                raise ValueError(f"launch process {p.executable} ({p.source}): no --enclave in its args")
            continue
        out.setdefault(enclave, []).extend(p.node_names)
    return {k: tuple(v) for k, v in sorted(out.items())}


def gateway_internal_enclave() -> str:
    """The enclave of the gateway's internal context."""
    return f"{INTERNAL_ENCLAVE_ROOT}/gateway"


def topside_enclaves(vehicle_name: str) -> dict[str, str]:
    """{role: enclave} on the topside domain: ``gateway``, ``operator``, ``topside``."""
    return {role: f"/{vehicle_name}/{role}" for role in ("gateway", "operator", "topside")}


def _policy(enclaves: Mapping[str, list[tuple[str, str, list[tuple[str, dict[str, str], list[str]]]]]]) -> str:
    """XML text of a policy: {enclave path: [(profile ns, profile node, [(element kind, attributes, names)])]}."""
    root = ET.Element("policy", version=POLICY_VERSION)
    encl = ET.SubElement(root, "enclaves")
    for path, profiles in enclaves.items():
        e = ET.SubElement(ET.SubElement(encl, "enclave", path=path), "profiles")
        for ns, node, rules in profiles:
            prof = ET.SubElement(e, "profile", ns=ns, node=node)
            for kind, attrs, names in rules:
                if not names:
                    continue
                lst = ET.SubElement(prof, kind, attrs)
                for n in names:
                    ET.SubElement(lst, kind[:-1]).text = n
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def _node_rules() -> list:
    return [("topics", {"publish": "ALLOW", "subscribe": "ALLOW"}, list(NODE_TOPICS)),
            ("services", {"reply": "ALLOW", "request": "ALLOW"}, list(NODE_SERVICES))]


def internal_policy(enclaves: Mapping[str, Iterable[str]]) -> str:
    """The internal domain's policy: each enclave of ``enclaves`` ({enclave: node names},
    :func:`launch_enclaves`) and the gateway's internal context may use the whole internal graph."""
    graph = [("topics", {"publish": "ALLOW", "subscribe": "ALLOW"}, list(INTERNAL_TOPICS)),
             ("services", {"reply": "ALLOW", "request": "ALLOW"}, list(INTERNAL_SERVICES)),
             ("actions", {"call": "ALLOW", "execute": "ALLOW"}, list(INTERNAL_ACTIONS))]
    doc: dict = {}
    own = {gateway_internal_enclave(): ("gateway",), TOOLS_ENCLAVE: ("tools",)}
    for enclave, nodes in {**dict(enclaves), **own}.items():
        doc[enclave] = [("/", n, _node_rules() + graph) for n in nodes]
    return _policy(doc)


def topside_policy(vehicle_name: str) -> str:
    """The topside domain's policy for ``vehicle_name`` (module docstring): the gateway serves
    the interface (:data:`~hindrax_bringup.gateway.interface.INTERFACE`), the operator may use
    all of it, every other topside participant e-stop (``who == "anyone"``) and telemetry."""
    ns = f"/{vehicle_name}"

    def names(kind: str, who: tuple[str, ...] | None = None) -> list[str]:
        return [f"{ns}/{r.topside}" for r in INTERFACE if r.kind == kind and (who is None or r.who in who)]

    roles = topside_enclaves(vehicle_name)
    gateway = _node_rules() + [
        ("topics", {"publish": "ALLOW"}, names("topic_out")),
        ("topics", {"subscribe": "ALLOW"}, names("topic_in")),
        ("services", {"reply": "ALLOW"}, names("service")),
        ("actions", {"execute": "ALLOW"}, names("action"))]
    operator = [("topics", {"publish": "ALLOW", "subscribe": "ALLOW"}, list(NODE_TOPICS)),
                ("topics", {"subscribe": "ALLOW"}, names("topic_out")),
                ("topics", {"publish": "ALLOW"}, names("topic_in")),
                ("services", {"request": "ALLOW"}, names("service")), ("actions", {"call": "ALLOW"}, names("action"))]
    anyone = [("topics", {"publish": "ALLOW", "subscribe": "ALLOW"}, list(NODE_TOPICS)),
              ("topics", {"subscribe": "ALLOW"}, names("topic_out", ("read", "anyone"))),
              ("services", {"request": "ALLOW"}, names("service", ("anyone",))),
              ("services", {"request": "DENY"}, names("service", ("operator",))),
              ("actions", {"call": "DENY"}, names("action", ("operator",))),
              ("topics", {"publish": "DENY"}, names("topic_in", ("operator",)))]
    # the gateway's topside context holds GATEWAY_NODE and its _operator and _campaign siblings (gateway/node.py):
    # the interface on the first profile, each node's own parameter services on its own
    siblings = [(ns, f"{GATEWAY_NODE}_{suffix}", _node_rules()) for suffix in ("operator", "campaign")]
    return _policy({roles["gateway"]: [(ns, GATEWAY_NODE, gateway), *siblings],
                    roles["operator"]: [("/", "hindrax_operator", operator)],
                    roles["topside"]: [("/", "hindrax_topside", anyone)]})


def _rule(parent: ET.Element, expression: str, open_: bool) -> None:
    rule = ET.SubElement(parent, "topic_rule")
    ET.SubElement(rule, "topic_expression").text = expression
    for key in ("enable_discovery_protection", "enable_liveliness_protection", "enable_read_access_control",
                "enable_write_access_control"):
        ET.SubElement(rule, key).text = "false" if open_ else "true"
    for key in ("metadata_protection_kind", "data_protection_kind"):
        ET.SubElement(rule, key).text = "NONE" if open_ else "ENCRYPT"


def governance(vehicle_name: str, internal_domain: int, topside_domain: int) -> str:
    """XML text of the vehicle's DDS Security governance (module docstring, "Governance"): the internal domain closed
    to participants without a certificate; on the topside domain those may use the e-stop of ``vehicle_name`` and
    nothing else. Raises ValueError when the two domains are the same."""
    if internal_domain == topside_domain:
        raise ValueError(f"internal and topside domain are both {internal_domain}: the vehicle needs two")
    root = ET.Element("dds", {"xmlns:xsi": "http://www.w3.org/2001/XMLSchema-instance",
                              "xsi:noNamespaceSchemaLocation":
                              "http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_governance.xsd"})
    rules = ET.SubElement(root, "domain_access_rules")
    for domain, unauthenticated in ((internal_domain, False), (topside_domain, True)):
        rule = ET.SubElement(rules, "domain_rule")
        ET.SubElement(ET.SubElement(rule, "domains"), "id").text = str(domain)
        ET.SubElement(rule, "allow_unauthenticated_participants").text = "true" if unauthenticated else "false"
        ET.SubElement(rule, "enable_join_access_control").text = "true"
        # an unauthenticated participant can discover and talk RTPS only where these are NONE
        for key, closed in (("discovery_protection_kind", "ENCRYPT"), ("liveliness_protection_kind", "ENCRYPT"),
                            ("rtps_protection_kind", "SIGN")):
            ET.SubElement(rule, key).text = "NONE" if unauthenticated else closed
        topics = ET.SubElement(rule, "topic_access_rules")
        if unauthenticated:
            (estop,) = [r for r in INTERFACE if r.who == "anyone"]
            for prefix, suffix in (("rq", "Request"), ("rr", "Reply")):
                _rule(topics, f"{prefix}/{vehicle_name}/{estop.topside}{suffix}", True)
        _rule(topics, "*", False)
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
