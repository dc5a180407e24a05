"""``thrusters.*``: names, pulse-width range, thrust curves, allocation settings and the per-thruster keys
(``thrusters.<name>.esc_channel``; [Hindrax-Drag] §2.2, eq. 1, Table 2, §4 eq. 9), and their hand-written typed view
(:class:`ThrustersConfig`: its keys are per thruster name, so it is not generated)."""
from __future__ import annotations

import re
from dataclasses import fields
from typing import Any, ClassVar, Mapping

import numpy as np

from ...base.thrust_curve import ThrustCurve, ThrustCurveError
from ...base.hardware_limits import ESC_DEADBAND_US, ESC_NEUTRAL_US
from ..spec import DOFS, STRS, THRUSTER, ConfigIssue, Spec, flag, integer, real, section, text, vector
from ..typed_sections import ABSENT, Section

_KEYS: dict[str, Spec] = {
    "names": Spec(STRS, "thruster names in allocation order"),
    "pulse_width_min_us": real("lowest pulse width (full reverse), us ([Hindrax-Drag] §2.2.1)", 500.0, 2500.0),
    "pulse_width_neutral_us": real("neutral pulse width (stop), us ([Hindrax-Drag] §2.2.1)", 500.0, 2500.0),
    "pulse_width_max_us": real("highest pulse width (full forward), us ([Hindrax-Drag] §2.2.1)", 500.0, 2500.0),
    "deadband_us": real("half-width of the ESC deadband around neutral, us (docs/devices.md §5.2)", 0.0, 200.0),
    "curve_negative": vector("cubic [c4, c3, c2, c1] for P below neutral, N ([Hindrax-Drag] eq. 1)", 4),
    "curve_positive": vector("cubic [c4, c3, c2, c1] for P above neutral, N ([Hindrax-Drag] eq. 1)", 4),
    "time_constant_s": real("first-order thruster lag time constant, s", 0.0, 5.0),
    "allocation_mode": text("saturation handling", ("uniform", "priority")),
    "priority_dofs": Spec(STRS, "DOFs kept exact in priority mode", choices=DOFS),
    "max_wrench_excess_ratio": real("a wrench beyond this many times what the thrusters can produce on an "
                                    "axis is rejected (neutral), not scaled into full thrust", 1.0, 100.0),
    "wrench_timeout_s": real("wrench older than this is rejected as stale, s", 0.01, 10.0),
    "wrench_future_margin_s": real("wrench stamped further than this in the future is rejected (clock "
                                   "offset allowed between the controller and this node), s", 0.0, 5.0),
    f"{THRUSTER}.position_frd_m": vector("thruster position relative to the CG, FRD, m", 3, -5.0, 5.0),
    f"{THRUSTER}.direction_frd": vector("unit thrust direction for positive thrust, FRD", 3, -1.0, 1.0, unit=True),
    f"{THRUSTER}.esc_channel": integer("PCA9685 output channel (15 carries the reference pulse for "
                                                 "`hindrax esc calibrate`)", 0, 14),
    f"{THRUSTER}.reversed": flag("mirror the pulse width about neutral (propeller/wiring reversed)"),
    f"{THRUSTER}.trim_us": real("pulse-width trim added after allocation, us", -100.0, 100.0),
    f"{THRUSTER}.allocation_weight": real("weight of this thruster in the weighted pseudo-inverse", 1e-3, 1e3),
}
_KEYS["thrust_uncertainty_rel"] = vector(
        "declared 1-sigma relative uncertainty of the thrust curves [negative, positive direction] (battery state, "
        "curve fit), added to the identification intervals", 2, 0.0, 1.0)
_KEYS["thrust_fit_uncertainty_rel"] = vector(
        "1-sigma relative uncertainty of the thrust curves [negative, positive direction] from the bollard-pull fit "
        "(written by hindrax ident thruster-fit --write); replaces thrust_uncertainty_rel in the intervals",
        2, 0.0, 1.0)
SCHEMA, OPTIONAL = section("thrusters", _KEYS, optional=("thrust_uncertainty_rel", "thrust_fit_uncertainty_rel"))


def cross_checks(c: Mapping[str, Any]) -> list[ConfigIssue]:
    """Checks of the thruster set, one issue (one line) each.

    * ``thrusters.names`` unique, each matching ``[a-z][a-z0-9_]*`` (a path segment of the per-thruster keys);
      ``pulse_width_min_us < pulse_width_neutral_us < pulse_width_max_us``, ``deadband_us`` below the smaller half
      range; no two thrusters on one ``esc_channel``.
    * ``thrusters.pulse_width_neutral_us`` and every neutral + ``trim_us`` (what a disarmed ESC node holds on the
      wire) strictly inside the Basic ESC's own deadband, 1500 +- 25 us (docs/devices.md §5.2; ESC_NEUTRAL_US and
      ESC_DEADBAND_US of :mod:`hindrax_common.base.hardware_limits`): outside it a vehicle that was never armed
      thrusts (1560 us; deadband 120 with trim 100 gives 1600 us).
    * ``thrusters.curve_negative`` / ``curve_positive``: each side increasing with the right sign at its range end
      (negative thrust at ``pulse_width_min_us``, positive at ``pulse_width_max_us``) with a usable monotone branch
      toward the deadband, the condition :class:`~hindrax_common.base.thrust_curve.ThrustCurve` needs to
      start ([Hindrax-Drag] eq. 1); a negated curve is refused here rather than by the allocation at start-up."""
    issues: list[ConfigIssue] = []
    if "thrusters.names" in c:
        names = c["thrusters.names"]
        if len(set(names)) != len(names):
            issues.append(ConfigIssue("thrusters.names", names, "unique names"))
        for n in names:
            if not re.fullmatch(r"[a-z][a-z0-9_]*", n):
                issues.append(ConfigIssue("thrusters.names", names, "names matching [a-z][a-z0-9_]*"))
        if "thrusters.pulse_width_min_us" in c:
            lo, mid, hi = (c["thrusters.pulse_width_min_us"], c["thrusters.pulse_width_neutral_us"],
                           c["thrusters.pulse_width_max_us"])
            if not lo < mid < hi:
                issues.append(ConfigIssue("thrusters.pulse_width_neutral_us", mid,
                                          f"strictly between pulse_width_min_us ({lo:g}) and "
                                          f"pulse_width_max_us ({hi:g})"))
            db = c["thrusters.deadband_us"]
            if db >= min(mid - lo, hi - mid):
                issues.append(ConfigIssue("thrusters.deadband_us", db, f"below {min(mid - lo, hi - mid):g}"))
        channels: dict[Any, str] = {}
        for n in names:
            ch = c.get(f"thrusters.{n}.esc_channel")
            if ch in channels:
                issues.append(ConfigIssue(f"thrusters.{n}.esc_channel", ch,
                                          f"a channel not already used by thrusters.{channels[ch]}"))
            channels[ch] = n
    lo_us, hi_us = ESC_NEUTRAL_US - ESC_DEADBAND_US, ESC_NEUTRAL_US + ESC_DEADBAND_US
    esc_band = f"the ESC's deadband ({lo_us:g}, {hi_us:g}) us (Basic ESC, docs/devices.md §5.2)"
    mid = c.get("thrusters.pulse_width_neutral_us")
    if mid is not None:
        if not lo_us < mid < hi_us:
            issues.append(ConfigIssue("thrusters.pulse_width_neutral_us", mid,
                                      f"inside {esc_band}: a disarmed ESC output would thrust"))
        else:
            for n in c.get("thrusters.names", ()):
                trim = c.get(f"thrusters.{n}.trim_us")
                if trim is not None and not lo_us < mid + trim < hi_us:
                    issues.append(ConfigIssue(f"thrusters.{n}.trim_us", trim,
                                              f"neutral + trim ({mid + trim:g} us) inside {esc_band}: the "
                                              "disarmed hold would thrust"))
    curve_keys = ("thrusters.curve_negative", "thrusters.curve_positive", "thrusters.pulse_width_min_us",
                  "thrusters.pulse_width_neutral_us", "thrusters.pulse_width_max_us", "thrusters.deadband_us")
    if all(k in c for k in curve_keys):
        try:
            ThrustCurve(*(c[k] for k in curve_keys))
        except ThrustCurveError as exc:
            side = "positive" if str(exc).startswith("positive") else "negative"
            key = f"thrusters.curve_{side}"
            issues.append(ConfigIssue(key, c[key], f"a cubic increasing with the right sign toward its range end "
                                                   f"([Hindrax-Drag] eq. 1): {exc}"))
    return issues


class ThrusterConfig(Section):
    """One thruster: name, position relative to the CG (FRD, m), unit direction of positive thrust (FRD),
    PCA9685 channel, reversal, trim (us) and allocation weight."""

    name: str
    position_frd_m: np.ndarray
    direction_frd: np.ndarray
    esc_channel: int
    reversed: bool
    trim_us: float
    allocation_weight: float

    PREFIX: ClassVar[str] = "thrusters.<thruster>"  # per instance: thrusters.<name> (KeyError messages)


class ThrustersConfig(Section):
    """Thruster set: per-thruster geometry and the shared cubic thrust curves ([Hindrax-Drag] eq. 1, Table 2).

    curve_negative/curve_positive: [c4, c3, c2, c1] with thrust_N = c4 P^3 + c3 P^2 + c2 P + c1, P in us."""

    PREFIX: ClassVar[str] = "thrusters"

    thrusters: tuple[ThrusterConfig, ...]
    pulse_width_min_us: float
    pulse_width_neutral_us: float
    pulse_width_max_us: float
    deadband_us: float
    curve_negative: tuple[float, float, float, float]
    curve_positive: tuple[float, float, float, float]
    time_constant_s: float
    allocation_mode: str
    priority_dofs: tuple[str, ...]
    max_wrench_excess_ratio: float
    wrench_timeout_s: float
    wrench_future_margin_s: float
    thrust_uncertainty_rel: tuple[float, ...] | None
    thrust_fit_uncertainty_rel: tuple[float, ...] | None

    @property
    def names(self) -> list[str]:
        """Thruster names in allocation order."""
        return [t.name for t in self.thrusters]

    @property
    def positions_frd_m(self) -> np.ndarray:
        """(n, 3) positions relative to the CG, FRD, m."""
        return np.array([t.position_frd_m for t in self.thrusters])

    @property
    def directions_frd(self) -> np.ndarray:
        """(n, 3) unit directions of positive thrust, FRD."""
        return np.array([t.direction_frd for t in self.thrusters])


def thrusters_config(f: Mapping[str, Any]) -> ThrustersConfig:
    """The typed thruster set from validated flat keys (positions/directions FRD relative to the CG). Needs
    ``thrusters.names``; other keys a node did not declare raise KeyError naming them when read."""

    def get(key: str, convert: Any = None) -> Any:
        if key not in f:
            return None if key.startswith(OPTIONAL) else ABSENT
        return f[key] if convert is None else convert(f[key])

    def unit(v: Any) -> np.ndarray:
        return np.asarray(v, dtype=float) / np.linalg.norm(v)

    def build(cls: Any, prefix: str, convert: Mapping[str, Any], **given: Any) -> Any:
        values = {k.name: get(f"{prefix}.{k.name}", convert.get(k.name)) for k in fields(cls) if k.name not in given}
        return cls.build({**values, **given}, prefix=prefix)

    per_thruster = {"position_frd_m": lambda v: np.asarray(v, dtype=float), "direction_frd": unit}
    shared = {"curve_negative": tuple, "curve_positive": tuple, "priority_dofs": tuple,
              "thrust_uncertainty_rel": _float_tuple, "thrust_fit_uncertainty_rel": _float_tuple}
    ts = tuple(build(ThrusterConfig, f"thrusters.{n}", per_thruster, name=n) for n in f["thrusters.names"])
    return build(ThrustersConfig, "thrusters", shared, thrusters=ts)


def _float_tuple(value: Any) -> tuple[float, ...]:
    return tuple(float(v) for v in value)
