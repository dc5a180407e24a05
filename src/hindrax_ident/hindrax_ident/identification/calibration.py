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

ASSUMPTION (until the line-pull step exists): the horizontal thrusters get the vertical scale (a common cause such
as the battery voltage, docs/devices.md §5.3); a loss specific to some thrusters is not calibrated. The RLS
comparison values in ``record.online`` stay in curve units.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping

import numpy as np

__all__ = ["apply_thrust_calibration", "calibration_relative_std", "calibration_section"]


def _scale(calibration: Mapping[str, Any]) -> tuple[float, float] | None:
    v = calibration.get("vertical") if calibration else None
    if not v:
        return None
    s, sd = float(v["value"]), float(v["std"])
    if not (math.isfinite(s) and s > 0 and math.isfinite(sd) and sd >= 0):
        raise ValueError(f"calibration.vertical: scale must be > 0 with std >= 0, got {s} +- {sd}")
    return s, sd


def apply_thrust_calibration(record: Any, calibration: Mapping[str, Any] | None = None) -> Any:
    """A copy of ``record`` (:class:`~.executive.CampaignRecord`) with both wrench arrays (n, 6) times the
    calibrated thrust scale (``calibration`` default: ``record.calibration``); the record itself when there
    is no calibration. Raises ``ValueError`` on a non-positive scale."""
    cal = record.calibration if calibration is None else calibration
    sc = _scale(cal)
    if sc is None:
        return record
    s = sc[0]
    return dataclasses.replace(record, wrench_frd=np.asarray(record.wrench_frd) * s,
                               wrench_cmd_frd=np.asarray(record.wrench_cmd_frd) * s)


def calibration_relative_std(calibration: Mapping[str, Any] | None) -> list[float] | None:
    """[negative, positive] relative 1-sigma thrust uncertainty after calibration (std / value), or None."""
    sc = _scale(calibration or {})
    if sc is None:
        return None
    rel = sc[1] / sc[0]
    return [rel, rel]


def calibration_section(calibration: Mapping[str, Any] | None) -> dict:
    """The ``calibration`` section of identification.yaml: per scale {value, std, known_force_n, holding_force_n,
    method}, plus ``applied_to`` and the assumption above."""
    sc = _scale(calibration or {})
    if sc is None:
        return {}
    v = dict(calibration["vertical"])
    return {"vertical_thrust_scale": {k: (list(map(float, x)) if isinstance(x, (list, tuple)) else
                                          (float(x) if isinstance(x, (int, float)) else x)) for k, x in v.items()},
            "applied_to": "all thrusters (no line-pull step yet: horizontal scale assumed equal to the vertical)"}
