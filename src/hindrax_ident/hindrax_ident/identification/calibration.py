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
           "DOF_GROUP", "decay_inertia"]

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


def decay_inertia(record: Any, dof: str, stiffness_n_m_per_rad: float, stiffness_std: float = 0.0,
                  rigid_inertia_kg_m2: float | None = None) -> dict:
    """Rigid + added inertia of ``dof`` (roll | pitch) from the campaign's free decay (issue 17 item 3).

    The de-biased gyro rate of the recorded window ``record.decays[dof]`` (from its largest excursion on) is
    fitted with I x'' + b1 x' + b2 |x'| x' + C x = 0 (:func:`~hindrax_ident.estimation.free_decay.
    fit_quadratic_free_decay`, output = velocity), C the restoring stiffness of an inclining test (``hindrax ident
    inclining``). The thrusters only tilted the vehicle, so the result does not depend on the thrust curve.
    Returns {total_inertia_kg_m2, total_inertia_kg_m2_std (fit and C's std combined), total_inertia_kg_m2_std_fit,
    added_inertia_kg_m2 (None without the rigid inertia), linear_damping_kg_m2_s, quadratic_damping_kg_m2 (with
    _std), stiffness_n_m_per_rad, window_s}. Raises ``KeyError`` when the DOF has no recorded decay and
    :class:`~hindrax_ident.estimation.least_squares.EstimationError` when the fit fails.
    """
    from ..estimation.free_decay import fit_quadratic_free_decay

    t0, t1 = record.decays[dof]
    k = {"roll": 0, "pitch": 1}[dof]
    rows = [(s, r[k]) for s, r in record.sensors["gyro"] if t0 <= s <= t1 and math.isfinite(r[k])]
    t = np.array([a for a, _ in rows])
    y = np.array([b for _, b in rows])
    i0 = int(np.argmax(np.abs(y - np.median(y)))) if y.size else 0
    fit = fit_quadratic_free_decay(t[i0:], y[i0:], stiffness_n_m_per_rad, rigid_inertia=rigid_inertia_kg_m2,
                                   output="velocity")
    std = math.hypot(fit.total_inertia_std, fit.total_inertia * float(stiffness_std) / float(stiffness_n_m_per_rad))
    return {"total_inertia_kg_m2": fit.total_inertia, "total_inertia_kg_m2_std": std,
            "total_inertia_kg_m2_std_fit": fit.total_inertia_std,
            "added_inertia_kg_m2": None if math.isnan(fit.added_inertia) else fit.added_inertia,
            "linear_damping_kg_m2_s": fit.linear_damping, "linear_damping_kg_m2_s_std": fit.linear_damping_std,
            "quadratic_damping_kg_m2": fit.quadratic_damping,
            "quadratic_damping_kg_m2_std": fit.quadratic_damping_std,
            "stiffness_n_m_per_rad": float(stiffness_n_m_per_rad), "stiffness_std": float(stiffness_std),
            "window_s": [float(t0), float(t1)]}
