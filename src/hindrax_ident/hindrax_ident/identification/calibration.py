"""Known-force thrust calibration applied to a campaign (issue 17 items 1-2; [Hindrax-Drag] (seed 003) §6).

A self-propelled test only sees force / inertia and force / damping: if every thruster gives s times its curve,
inertia, damping and bias all come out s times too (docs/identification.md). The ballast step of the executive
(:meth:`~.executive.Executive._ballast`) measures s against a known weight; here it enters the identification:

* :func:`apply_thrust_calibration` returns the record with its thrust-model wrenches (``wrench_frd``,
  ``wrench_cmd_frd``) multiplied by the calibrated scale. For parameters that scale linearly with the force
  (inertia, damping, bias: tau = M nu_dot + D(nu) nu + b) this is the joint estimate: the ladders carry no
  information on s, so the joint maximum-likelihood estimate of (s, theta) is the calibration's s and theta of
  the scaled force.
* :func:`calibration_relative_std` gives s's relative std as the thrust uncertainty [negative, positive] for
  :func:`~.verdicts.apply_verdicts` (``thruster_fit_rel``), which then adds it to every interval in place of the
  declared thrust-curve uncertainty: the intervals carry the calibration's own uncertainty.

Scales: ``vertical`` (ballast: heave, roll, pitch columns Z, K, M, the vertical thrusters) and ``horizontal``
(line pull in surge and sway, their inverse-variance mean: X, Y, N, the horizontal thrusters). ASSUMPTION when only
one of the two was measured: the other thrusters get the same scale (a common cause such as the battery voltage,
docs/devices.md §5.3); the section says so. The RLS comparison values in ``record.online`` stay in curve units.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping

import numpy as np

__all__ = ["apply_thrust_calibration", "calibration_relative_std", "calibration_section", "thrust_scales",
           "DOF_GROUP"]

#: Which thrusters (scale) act in each DOF, and the wrench columns of each group.
DOF_GROUP = {"surge": "horizontal", "sway": "horizontal", "yaw": "horizontal",
             "heave": "vertical", "roll": "vertical", "pitch": "vertical"}
_COLUMNS = {"horizontal": [0, 1, 5], "vertical": [2, 3, 4]}


def _entry(calibration: Mapping[str, Any], key: str) -> tuple[float, float] | None:
    v = calibration.get(key) if calibration else None
    if not isinstance(v, Mapping) or "value" not in v:
        return None
    s, sd = float(v["value"]), float(v["std"])
    if not (math.isfinite(s) and s > 0 and math.isfinite(sd) and sd >= 0):
        raise ValueError(f"calibration.{key}: scale must be > 0 with std >= 0, got {s} +- {sd}")
    return s, sd


def thrust_scales(calibration: Mapping[str, Any] | None) -> dict[str, dict]:
    """{"vertical"|"horizontal": {value, std, source}} from the raw step results (``vertical`` from the ballast;
    ``surge``/``sway`` line pulls -> ``horizontal``, inverse-variance mean); a group without its own measurement
    takes the other's (source says "assumed"). {} without any calibration. Raises ``ValueError`` on a bad scale."""
    cal = calibration or {}
    out: dict[str, dict] = {}
    v = _entry(cal, "vertical")
    if v is not None:
        out["vertical"] = {"value": v[0], "std": v[1], "source": "ballast"}
    hs = [(k, e) for k in ("surge", "sway") if (e := _entry(cal, k)) is not None]
    if hs:
        w = np.array([1.0 / max(e[1], 1e-12) ** 2 for _, e in hs])
        val = float(np.sum(w * [e[0] for _, e in hs]) / np.sum(w))
        out["horizontal"] = {"value": val, "std": float(1.0 / math.sqrt(np.sum(w))),
                             "source": "line pull (" + ", ".join(k for k, _ in hs) + ")"}
    if len(out) == 1:
        have, other = next(iter(out)), ("horizontal" if "vertical" in out else "vertical")
        out[other] = dict(out[have], source=f"assumed equal to the {have} scale (not measured)")
    return out


def apply_thrust_calibration(record: Any, calibration: Mapping[str, Any] | None = None) -> Any:
    """A copy of ``record`` (:class:`~.executive.CampaignRecord`) with both wrench arrays (n, 6) scaled per
    thruster group (:func:`thrust_scales`; ``calibration`` default ``record.calibration``); the record itself
    without a calibration. Raises ``ValueError`` on a non-positive scale."""
    cal = record.calibration if calibration is None else calibration
    sc = thrust_scales(cal)
    if not sc:
        return record
    factor = np.ones(6)
    for group, cols in _COLUMNS.items():
        factor[cols] = sc[group]["value"]
    return dataclasses.replace(record, wrench_frd=np.asarray(record.wrench_frd) * factor,
                               wrench_cmd_frd=np.asarray(record.wrench_cmd_frd) * factor)


def calibration_relative_std(calibration: Mapping[str, Any] | None, dof: str = "heave") -> list[float] | None:
    """[negative, positive] relative 1-sigma thrust uncertainty of ``dof``'s thrusters after calibration, or None."""
    sc = thrust_scales(calibration)
    if not sc:
        return None
    g = sc[DOF_GROUP[dof]]
    rel = g["std"] / g["value"]
    return [rel, rel]


def calibration_section(calibration: Mapping[str, Any] | None) -> dict:
    """The ``calibration`` section of identification.yaml: ``vertical_thrust_scale`` / ``horizontal_thrust_scale``
    ({value, std, source} plus, for a measured one, the step's known force and holding forces) and each raw step
    (``surge``/``sway`` line pulls)."""
    sc = thrust_scales(calibration)
    if not sc:
        return {}

    def plain(d):
        return {k: ([float(x) for x in v] if isinstance(v, (list, tuple)) else
                    (float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else v)) for k, v in d.items()}

    out = {}
    for group in ("vertical", "horizontal"):
        e = dict(sc[group])
        if group == "vertical" and "vertical" in calibration:
            e = {**dict(calibration["vertical"]), **e}
        out[f"{group}_thrust_scale"] = plain(e)
    for axis in ("surge", "sway"):
        if axis in calibration:
            out[f"line_pull_{axis}"] = plain(dict(calibration[axis]))
    return out
