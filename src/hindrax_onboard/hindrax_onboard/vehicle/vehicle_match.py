"""Which vehicle an identification belongs to: the vehicle-file parameters its values depend on.

An identification (``identification.yaml``) measures forces through the thrust model (the curves, the neutral and
deadband, each thruster's ESC channel, direction, position, trim and reversal), separates added from rigid mass and
inertia with the vehicle's mass properties (mass, inertia, products of inertia, centres of gravity and buoyancy,
displaced volume, net buoyancy) and the environment (water density, gravity), and reads its velocities and attitude
through the sensors' mounting (position and orientation keys of ``sensors.*``). Those values, as the vehicle file
held them, are written to ``provenance.vehicle_parameters``; the controller uses the identification only for a
vehicle file whose values are the same (:func:`parameter_differences`). Anything else in the file (comments, the disk
floor, ESC calibration, supervisor limits, the hydrodynamic priors) can change without invalidating it."""
from __future__ import annotations

import math
from typing import Any, Mapping

__all__ = ["vehicle_parameters", "parameter_differences", "depends_on"]

_EXACT = ("vehicle.mass_kg", "vehicle.inertia_kg_m2", "vehicle.products_of_inertia_kg_m2",
          "vehicle.centre_of_gravity_frd_m", "vehicle.centre_of_buoyancy_frd_m", "vehicle.displaced_volume_m3",
          "vehicle.net_buoyancy_n", "environment.water_density_kg_m3", "environment.gravity_m_s2",
          "thrusters.names", "thrusters.curve_positive", "thrusters.curve_negative",
          "thrusters.pulse_width_neutral_us", "thrusters.deadband_us")
#: per-thruster keys (``thrusters.<name>.<key>``) the thrust model uses
_THRUSTER = ("esc_channel", "direction_frd", "position_frd_m", "reversed", "trim_us")
#: ``sensors.<device>.<key>`` suffixes of a sensor's mounting
_MOUNTING = ("position_frd_m", "orientation", "rotation", "mounting")
#: relative tolerance of a numeric comparison (a value written to YAML and read back is equal within it)
REL_TOL = 1e-9


def depends_on(key: str) -> bool:
    """Whether the flat vehicle-file ``key`` (dotted) is one an identification depends on (module docstring)."""
    parts = key.split(".")
    if key in _EXACT:
        return True
    if parts[0] == "thrusters" and len(parts) == 3 and parts[2] in _THRUSTER:
        return True
    return parts[0] == "sensors" and any(s in parts[-1] for s in _MOUNTING)


def vehicle_parameters(cfg) -> dict[str, Any]:
    """The parameters of the vehicle file ``cfg`` (a VehicleConfig) an identification depends on: dotted key ->
    value (numbers, booleans, strings and lists of them, as YAML writes them), sorted by key."""
    flat = cfg.to_ros_parameters()
    return {k: _plain(flat[k]) for k in sorted(flat) if depends_on(k)}


def parameter_differences(recorded: Mapping[str, Any], cfg) -> list[str]:
    """The keys whose value in the vehicle file ``cfg`` differs from ``recorded`` (an identification's
    ``provenance.vehicle_parameters``), each as ``key recorded -> now``; a key present on one side only counts.
    Empty when the identification belongs to this vehicle."""
    now = vehicle_parameters(cfg)
    out = []
    for key in sorted(set(recorded) | set(now)):
        a, b = recorded.get(key, "(absent)"), now.get(key, "(absent)")
        if not _same(a, b):
            out.append(f"{key} {a} -> {b}")
    return out


def _plain(value):
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, bool) or isinstance(value, str):
        return value
    if isinstance(value, (int, float)):
        return float(value) if isinstance(value, float) else int(value)
    return value.tolist() if hasattr(value, "tolist") else value


def _same(a, b) -> bool:
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, bool) or isinstance(b, bool) or isinstance(a, str) or isinstance(b, str):
        return a == b
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return math.isclose(float(a), float(b), rel_tol=REL_TOL, abs_tol=1e-12)
    return a == b
