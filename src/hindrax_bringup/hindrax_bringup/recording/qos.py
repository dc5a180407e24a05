"""QoS profiles as rosbag2 (Jazzy, metadata version 9) stores them, and the recorder/player choices.

A profile is a plain dict in rosbag2's YAML layout (rosbag2_storage ``qos.cpp``, version >= 9)::

    {"history": "keep_last", "depth": 10, "reliability": "reliable", "durability": "volatile",
     "deadline": {"sec": 9223372036, "nsec": 854775807}, "lifespan": {...}, "liveliness": "automatic",
     "liveliness_lease_duration": {...}, "avoid_ros_namespace_conventions": False}

Policy names are rmw's (``rmw_qos_*_policy_to_str``: keep_last, keep_all, system_default, reliable,
best_effort, best_available, volatile, transient_local, automatic, manual_by_topic) or ``unknown``;
durations are ``{sec, nsec}`` with infinity = 2^63-1 ns = {9223372036, 854775807}.

- The MCAP channel metadata ``offered_qos_profiles`` is the YAML *string* of the list
  (:func:`profiles_to_yaml`); metadata.yaml (version 9) holds the list itself.
- :func:`subscription_policies` is rosbag2's ``adapt_request_to_offers``: reliable only if every publisher is reliable
  (a reliable subscription never matches a best-effort publisher), transient local only if every publisher is.
- :func:`recorder_policies` is what this project's recorder requests: best effort for every
  volatile topic (why: :func:`hindrax_common.node_support.node_common.sensor_input_qos`), rosbag2's rule for the
  transient-local ones (their history reaches a late reader only when it is reliable).
- :func:`playback_profile` is rosbag2's ``adapt_offer_to_recorded_offers``: the recorded profile when
  all publishers agree on the compatibility-relevant policies (history reset to keep_last 10), else
  the default (reliable, volatile, keep_last 10).

Pure (no rclpy import); :func:`profile_from_rclpy` duck-types an ``rclpy.qos.QoSProfile``."""
from __future__ import annotations

from typing import Any, Iterable, Mapping

import yaml

INFINITE_NS = 2**63 - 1
"""RMW_DURATION_INFINITE in nanoseconds."""

_COMPAT_KEYS = ("reliability", "durability", "deadline", "liveliness", "liveliness_lease_duration")


def duration_to_dict(ns: int) -> dict[str, int]:
    """Nanoseconds -> ``{"sec", "nsec"}`` (rmw_time_t as rosbag2 writes it)."""
    ns = int(ns)
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def default_profile(reliability: str = "reliable", durability: str = "volatile", depth: int = 10) -> dict:
    """A rosbag2-layout profile with default deadline/lifespan/liveliness (all infinite / automatic)."""
    inf = duration_to_dict(INFINITE_NS)
    return {"history": "keep_last", "depth": int(depth), "reliability": reliability, "durability": durability,
            "deadline": dict(inf), "lifespan": dict(inf), "liveliness": "automatic",
            "liveliness_lease_duration": dict(inf), "avoid_ros_namespace_conventions": False}


def _policy_name(value: Any) -> str:
    return str(getattr(value, "name", value)).lower()


def _duration_ns(value: Any) -> int:
    return int(getattr(value, "nanoseconds", value))


def profile_from_rclpy(qos: Any) -> dict:
    """Convert an ``rclpy.qos.QoSProfile`` (e.g. from ``get_publishers_info_by_topic``) to a profile dict."""
    return {
        "history": _policy_name(qos.history),
        "depth": int(qos.depth),
        "reliability": _policy_name(qos.reliability),
        "durability": _policy_name(qos.durability),
        "deadline": duration_to_dict(_duration_ns(qos.deadline)),
        "lifespan": duration_to_dict(_duration_ns(qos.lifespan)),
        "liveliness": _policy_name(qos.liveliness),
        "liveliness_lease_duration": duration_to_dict(_duration_ns(qos.liveliness_lease_duration)),
        "avoid_ros_namespace_conventions": bool(qos.avoid_ros_namespace_conventions),
    }


def profiles_to_yaml(profiles: Iterable[Mapping[str, Any]]) -> str:
    """The ``offered_qos_profiles`` channel-metadata string (YAML list; ``[]`` when empty)."""
    profiles = [dict(p) for p in profiles]
    if not profiles:
        return "[]"
    return yaml.safe_dump(profiles, sort_keys=False, default_flow_style=False).rstrip("\n")


def profiles_from_yaml(text: str | None) -> list[dict]:
    """Parse an ``offered_qos_profiles`` string (version 9 names; older integer enums are mapped)."""
    if not text:
        return []
    doc = yaml.safe_load(text)
    if not isinstance(doc, list):
        raise ValueError(f"offered_qos_profiles is not a YAML list: {text[:60]!r}")
    return [_upgrade_profile(p) for p in doc if isinstance(p, Mapping)]


_OLD_ENUMS = {
    "history": {0: "system_default", 1: "keep_last", 2: "keep_all", 3: "unknown"},
    "reliability": {0: "system_default", 1: "reliable", 2: "best_effort", 3: "unknown", 4: "best_available"},
    "durability": {0: "system_default", 1: "transient_local", 2: "volatile", 3: "unknown", 4: "best_available"},
    "liveliness": {0: "system_default", 1: "automatic", 3: "manual_by_topic", 4: "unknown", 5: "best_available"},
}


def _upgrade_profile(p: Mapping[str, Any]) -> dict:
    out = dict(p)
    for key, table in _OLD_ENUMS.items():
        if isinstance(out.get(key), int):
            out[key] = table.get(out[key], "unknown")
    return out


def subscription_policies(offered: Iterable[Mapping[str, Any]]) -> tuple[str, str]:
    """(reliability, durability) a recorder must request to match every publisher (rosbag2 rule).

    No publishers -> ("reliable", "volatile") (rosbag2's default request)."""
    offered = list(offered)
    if not offered:
        return "reliable", "volatile"
    reliability = "reliable" if all(p.get("reliability") == "reliable" for p in offered) else "best_effort"
    durability = ("transient_local" if all(p.get("durability") == "transient_local" for p in offered) else "volatile")
    return reliability, durability


def recorder_policies(offered: Iterable[Mapping[str, Any]]) -> tuple[str, str]:
    """(reliability, durability) the recorder requests (module docstring): :func:`subscription_policies`, with best
    effort for a volatile topic."""
    reliability, durability = subscription_policies(offered)
    return ("best_effort" if durability == "volatile" else reliability), durability


def playback_profile(recorded: Iterable[Mapping[str, Any]]) -> dict:
    """Profile a player offers for a topic recorded with these publisher profiles (rosbag2 rule)."""
    recorded = [dict(p) for p in recorded]
    if not recorded:
        return default_profile()
    ref = recorded[0]
    if all(all(p.get(k) == ref.get(k) for k in _COMPAT_KEYS) for p in recorded[1:]):
        out = dict(ref)
        out["history"] = "keep_last"
        out["depth"] = 10
        if out.get("reliability") not in ("reliable", "best_effort"):
            out["reliability"] = "reliable"
        if out.get("durability") not in ("volatile", "transient_local"):
            out["durability"] = "volatile"
        return out
    return default_profile()
