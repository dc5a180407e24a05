"""The calibration steps' results as a standard message: topic ``identification/calibration``.

The identification node (:mod:`..online.node`) publishes, when a calibration step of a goal ends (docs/identification.md
§6.1, "On the ROS graph"), one ``diagnostic_msgs/msg/DiagnosticArray`` holding every step result measured since the node
started, one ``DiagnosticStatus`` per result, transient-local (depth 1); ``hindrax ident bag`` (:mod:`.from_bag`) reads
it back into the :class:`~.campaign_record.CampaignRecord`'s ``calibration``, ``inclining`` and ``decays``.

Each status: ``level`` OK, ``hardware_id`` :data:`HARDWARE_ID`, ``name`` ``<kind>/<key>``, ``message`` a
one-line summary, ``values`` KeyValue pairs (numbers as Python ``repr`` of the float: exact round trip):

``thrust_scale/vertical`` (ballast), ``thrust_scale/vertical_negative`` (float), ``thrust_scale/surge``,
``thrust_scale/sway`` (line pull along +x, +y), ``thrust_scale/surge_negative``, ``thrust_scale/sway_negative`` (-x, -y)
    ``step`` (ballast | float | line_pull), ``axis`` (the key), ``group`` (vertical | horizontal: the
    thrusters that held the force, docs/identification.md §6.2), ``direction`` (body FRD axis and sense of the known
    force: ``+z`` the ballast's weight, ``-z`` the float's buoyancy, ``+x`` / ``-x`` / ``+y`` / ``-y`` the line),
    ``scale`` and ``scale_std`` (true thrust / curve's assuming one scale for both rotation directions,
    dimensionless), ``known_force_n`` (N, magnitude), ``holding_force_without_n``, ``holding_force_with_n`` and their
    ``..._std_n`` (mean thrust-model force on the axis without and with the known force, N, FRD), and
    ``forward_force_without_n``, ``forward_force_with_n``, ``reverse_force_without_n``, ``reverse_force_with_n``: the
    parts of those holding forces made by thrusters turning forward and in reverse (N, FRD; their sum is the holding
    force), from which the per-direction scales are estimated (:func:`~hindrax_fit.fit.calibration.scale_model`).
    A message of an older node without the four parts still reads: its scale then measures the two directions' mean.
``inclining/roll``, ``inclining/pitch``
    ``step`` inclining, ``dof``, ``stiffness_n_m_per_rad`` and ``stiffness_n_m_per_rad_std`` (restoring C),
    ``known_moment_n_m``, ``thruster_moment_without_n_m``, ``thruster_moment_with_n_m`` (N m), ``tilt_without_rad``,
    ``tilt_with_rad`` and their ``..._std_rad`` (rad).
``tilt_decay/roll``, ``tilt_decay/pitch``
    ``step`` tilt_decay, ``dof``, ``release_time_s`` and ``end_time_s``: the recorded decay's window in ROS time (s,
    header stamps' time base); the gyro gives the inertia offline (:func:`~hindrax_fit.fit.calibration.decay_inertia`).

Pure apart from the message import in :func:`calibration_array`; :func:`results_from_array` duck-types the
message (rclpy or bag-decoded objects)."""
from __future__ import annotations

from typing import Any, Iterable, Mapping

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

__all__ = ["TOPIC", "HARDWARE_ID", "statuses", "calibration_array", "results_from_array", "merge_results",
           "KNOWN_FORCE_AXES"]

#: topic name (relative: the node's namespace)
TOPIC = "identification/calibration"
#: ``DiagnosticStatus.hardware_id`` of the statuses
HARDWARE_ID = "hindrax identification"
#: Calibration keys of the known-force steps -> (thruster group, FRD axis index, sense of the known force).
KNOWN_FORCE_AXES = {"vertical": ("vertical", 2, 1), "vertical_negative": ("vertical", 2, -1),
                    "surge": ("horizontal", 0, 1), "surge_negative": ("horizontal", 0, -1),
                    "sway": ("horizontal", 1, 1), "sway_negative": ("horizontal", 1, -1)}

_GROUP = {"vertical": "vertical", "vertical_negative": "vertical", "surge": "horizontal", "sway": "horizontal",
          "surge_negative": "horizontal", "sway_negative": "horizontal"}
_DIRECTION = {"vertical": "+z", "vertical_negative": "-z", "surge": "+x", "sway": "+y", "surge_negative": "-x",
              "sway_negative": "-y"}


def _num(x: Any) -> str:
    return repr(float(x))


def _pairs(stem: str, unit: str, values: Any = (0.0, 0.0)) -> list[tuple[str, str]]:
    """KeyValue pairs ``<stem>_without_<unit>``, ``<stem>_with_<unit>`` of a [without, with] pair (the record's key
    is ``<stem>_<unit>``, e.g. holding_force + std_n)."""
    return [(f"{stem}_without_{unit}", _num(values[0])), (f"{stem}_with_{unit}", _num(values[1]))]


def statuses(calibration: Mapping[str, Mapping] | None, inclining: Mapping[str, Mapping] | None = None,
             decays: Mapping[str, Any] | None = None) -> list[tuple[str, str, list[tuple[str, str]]]]:
    """(name, message, [(key, value)]) of every result (module docstring) of an executive's or record's
    ``calibration`` ({axis: {value, std, known_force_n, holding_force_n, holding_force_std_n, method}}),
    ``inclining`` ({dof: {value, std, known_moment_n_m, thruster_moment_n_m, tilt_rad, tilt_std_rad, method}}) and
    ``decays`` ({dof: (t_release, t_end) s})."""
    out = []
    for axis, e in (calibration or {}).items():
        kv = [("step", str(e.get("method", ""))), ("axis", axis), ("group", _GROUP.get(axis, axis)),
              ("direction", _DIRECTION.get(axis, "")), ("scale", _num(e["value"])), ("scale_std", _num(e["std"])),
              ("known_force_n", _num(e["known_force_n"]))]
        kv += _pairs("holding_force", "n", e["holding_force_n"]) + _pairs("holding_force", "std_n",
                                                                         e["holding_force_std_n"])
        if "forward_force_n" in e and "reverse_force_n" in e:
            kv += _pairs("forward_force", "n", e["forward_force_n"]) + _pairs("reverse_force", "n",
                                                                             e["reverse_force_n"])
        out.append((f"thrust_scale/{axis}", f"{axis} thrust scale {float(e['value']):.4f} +- {float(e['std']):.4f} "
                    f"({e.get('method', '')}, known force {float(e['known_force_n']):.4g} N)", kv))
    for dof, e in (inclining or {}).items():
        kv = [("step", str(e.get("method", "inclining"))), ("dof", dof),
              ("stiffness_n_m_per_rad", _num(e["value"])), ("stiffness_n_m_per_rad_std", _num(e["std"])),
              ("known_moment_n_m", _num(e["known_moment_n_m"]))]
        kv += _pairs("thruster_moment", "n_m", e["thruster_moment_n_m"]) + _pairs("tilt", "rad", e["tilt_rad"])
        kv += _pairs("tilt", "std_rad", e["tilt_std_rad"])
        out.append((f"inclining/{dof}", f"{dof} restoring stiffness {float(e['value']):.4g} +- {float(e['std']):.2g} "
                    "N m/rad (inclining)", kv))
    for dof, (t0, t1) in (decays or {}).items():
        out.append((f"tilt_decay/{dof}", f"{dof} free decay recorded from {float(t0):.2f} s to {float(t1):.2f} s",
                    [("step", "tilt_decay"), ("dof", dof), ("release_time_s", _num(t0)), ("end_time_s", _num(t1))]))
    return out


def calibration_array(results: Iterable[tuple[str, str, list[tuple[str, str]]]], stamp) -> Any:
    """``diagnostic_msgs/msg/DiagnosticArray`` of :func:`statuses` output, header ``stamp``
    (builtin_interfaces/Time)."""
    arr = DiagnosticArray()
    arr.header.stamp = stamp
    arr.status = [DiagnosticStatus(level=DiagnosticStatus.OK, name=name, message=message, hardware_id=HARDWARE_ID,
                                   values=[KeyValue(key=k, value=v) for k, v in kv])
                  for name, message, kv in results]
    return arr


def results_from_array(msg: Any) -> tuple[dict, dict, dict]:
    """(calibration, inclining, decays) of one DiagnosticArray (the inverse of :func:`statuses`, the same dict
    layout as :class:`~.campaign_record.CampaignRecord`); statuses of another ``hardware_id`` or name are ignored.
    Raises ``ValueError`` naming the status when a needed key is missing or not a number."""
    cal: dict = {}
    incl: dict = {}
    decays: dict = {}
    for st in msg.status:
        if st.hardware_id != HARDWARE_ID or "/" not in st.name:
            continue
        kind, key = st.name.split("/", 1)
        kv = {v.key: v.value for v in st.values}

        def num(k: str) -> float:
            try:
                return float(kv[k])
            except (KeyError, ValueError) as exc:
                raise ValueError(f"{TOPIC}: status {st.name!r}: key {k!r} missing or not a number "
                                 f"({kv.get(k)!r})") from exc

        def pair(stem: str, unit: str) -> list[float]:
            return [num(a) for a, _ in _pairs(stem, unit)]

        if kind == "thrust_scale":
            cal[key] = {"value": num("scale"), "std": num("scale_std"), "known_force_n": num("known_force_n"),
                        "holding_force_n": pair("holding_force", "n"),
                        "holding_force_std_n": pair("holding_force", "std_n"), "method": kv.get("step", "")}
            if "direction" in kv and kv["direction"]:
                cal[key]["direction"] = kv["direction"]
            if "group" in kv:
                cal[key]["group"] = kv["group"]
            if "forward_force_without_n" in kv:  # newer nodes: the per-direction parts
                cal[key]["forward_force_n"] = pair("forward_force", "n")
                cal[key]["reverse_force_n"] = pair("reverse_force", "n")
        elif kind == "inclining":
            incl[key] = {"value": num("stiffness_n_m_per_rad"), "std": num("stiffness_n_m_per_rad_std"),
                         "known_moment_n_m": num("known_moment_n_m"),
                         "thruster_moment_n_m": pair("thruster_moment", "n_m"), "tilt_rad": pair("tilt", "rad"),
                         "tilt_std_rad": pair("tilt", "std_rad"), "method": kv.get("step", "inclining")}
        elif kind == "tilt_decay":
            decays[key] = (num("release_time_s"), num("end_time_s"))
    return cal, incl, decays


def merge_results(messages: Iterable[Any]) -> tuple[dict, dict, dict]:
    """(calibration, inclining, decays) of several DiagnosticArrays in time order: a later result of the same name
    replaces an earlier one (the node's messages are cumulative, so the last one normally holds everything)."""
    out: tuple[dict, dict, dict] = ({}, {}, {})
    for m in messages:
        for merged, part in zip(out, results_from_array(m)):
            merged.update(part)
    return out
