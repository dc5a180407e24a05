"""The control model of each DOF: inertia, damping, net buoyancy and restoring, and where each value came from.

The controller (:mod:`.law`) needs, per DOF, the rigid + added inertia M (its feedback gains), the
damping D(v) = linear v + quadratic |v| v per direction (feedforward), the constant force that holds
the vehicle still (heave: the net buoyancy B - W, FRD down; feedforward) and, for roll and pitch,
the restoring coefficient z_g W - z_b B (moment = restoring sin(angle); feedforward). Two sources
(docs/control.md §4 gives the rules and why):

* :func:`model_from_config` - the vehicle file (``hydrodynamics.*``, mass, volume, geometry), with the declared
  thrust-curve uncertainty as the inertia's (a lower bound: the file states none for its added masses).
* :func:`load_model` - ``identification.yaml`` (:mod:`hindrax_fit.assessment.results`), read by this small tolerant
  loader (``provenance.vehicle_parameters`` or ``provenance.configuration_sha256``,
  ``dofs.<dof>.<parameter>.value / std / verdict / reasons`` and ``joint.scales``; other keys are ignored). Values are
  in commanded-thrust units: a calibrated file's are divided by the thrust scale of their group. A ``suspect``
  parameter, a value that is not a finite number, or a negative inertia or damping falls back to the vehicle file's,
  except for the reasons of :data:`CONTROL_IRRELEVANT_REASONS`; a heave bias no thrust scale explains
  (:func:`unexplained_bias`) makes the bias and damping fall back. Each value carries its source
  (:attr:`AxisModel.sources`).

**Bad input** is an error, never a silent fallback: a missing or unreadable file, invalid YAML, no ``dofs`` mapping,
or an identification of another vehicle (matched by :mod:`hindrax_onboard.vehicle.vehicle_match`) raise
:class:`ModelFileError` (one line).

Frames: body FRD, SNAME order (docs/architecture.md §3); the heave direction ``positive`` is downwards."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import yaml

from hindrax_common.config import DOFS, ROTATIONAL_DOFS, VehicleConfig

from ..vehicle.vehicle_match import parameter_differences
from ..vehicle.uncertainty import declared_rel

__all__ = ["AxisModel", "ControlModel", "ModelFileError", "model_from_config", "load_model", "rigid_inertia",
           "prior_inertia", "declared_inertia_uncertainty_rel", "CONTROL_IRRELEVANT_REASONS",
           "VEHICLE_FILE", "BIAS_THRUST_SCALE_SIGMAS", "unexplained_bias"]

#: Source name of a value taken from the vehicle file.
VEHICLE_FILE = "vehicle file"
#: Substrings of verdict reasons (:mod:`hindrax_fit.assessment.verdicts`) that do not disqualify a
#: parameter for control in commanded-thrust units (docs/control.md §4, "Verdicts"); any other
#: reason makes it fall back (if the wording changes, it falls back: safe).
CONTROL_IRRELEVANT_REASONS = ("differs from the expected", "the thrust curves do not match the vehicle")
#: Width of the thrust scales that explain an identified holding force, in declared thrust-curve
#: 1-sigmas (:func:`unexplained_bias`).
BIAS_THRUST_SCALE_SIGMAS = 3.0

_DAMPING = ("linear_damping_positive", "linear_damping_negative", "quadratic_damping_positive",
            "quadratic_damping_negative")


@dataclass(frozen=True)
class AxisModel:
    """The control model of one DOF (module docstring), in commanded-thrust units.

    inertia: rigid + added, kg (surge, sway, heave) or kg m^2 (roll, pitch, yaw), > 0.
    inertia_rel_std: 1-sigma relative uncertainty of ``inertia`` (the bandwidth is lowered by it, :mod:`.law`).
    linear_damping_positive / _negative (kg/s or kg m^2/s), quadratic_damping_positive / _negative (kg/m or kg m^2),
    chosen by the sign of the velocity (heave: positive = down). bias: the constant force or moment holding the
    vehicle still (heave: B - W, N, FRD; others 0 from the vehicle file). restoring: z_g W - z_b B (N m; roll and pitch,
    0 otherwise). sources: parameter name -> where the value came from."""

    dof: str
    inertia: float
    inertia_rel_std: float
    linear_damping_positive: float
    linear_damping_negative: float
    quadratic_damping_positive: float
    quadratic_damping_negative: float
    bias: float = 0.0
    restoring: float = 0.0
    sources: Mapping[str, str] = field(default_factory=dict)

    def damping(self, velocity: float) -> float:
        """Damping force (N) or moment (N m) at ``velocity`` (m/s or rad/s), signed like the velocity
        ([Hindrax-Drag] eq. 2: linear v + quadratic |v| v, the coefficients of the velocity's direction)."""
        v = float(velocity)
        if v >= 0.0:
            return self.linear_damping_positive * v + self.quadratic_damping_positive * v * v
        return self.linear_damping_negative * v - self.quadratic_damping_negative * v * v


@dataclass(frozen=True)
class ControlModel:
    """The six :class:`AxisModel` (SNAME order), the file they came from and the notes of the loader (fallbacks)."""

    axes: Mapping[str, AxisModel]
    source: str
    notes: tuple[str, ...] = ()

    def axis(self, dof: str) -> AxisModel:
        """The model of one DOF. Raises ``KeyError`` for an unknown DOF."""
        return self.axes[dof]


def rigid_inertia(cfg: VehicleConfig, dof: str) -> float:
    """Rigid-body inertia of one DOF: the mass (kg) or the principal moment of inertia about the CG (kg m^2)."""
    i = DOFS.index(dof)
    return float(cfg.vehicle.mass_kg) if i < 3 else float(cfg.inertia_matrix_kg_m2[i - 3, i - 3])


def prior_inertia(cfg: VehicleConfig, dof: str) -> float:
    """A-priori rigid + added inertia of one DOF from the vehicle file (kg or kg m^2)."""
    i = DOFS.index(dof)
    return rigid_inertia(cfg, dof) + float(cfg.added_mass_matrix[i, i])


def declared_inertia_uncertainty_rel(cfg: VehicleConfig) -> float:
    """Relative 1-sigma uncertainty the vehicle file declares for its force model: the RMS of the two thrust-curve
    directions' relative uncertainty (the rule of the identification intervals,
    :mod:`hindrax_fit.assessment.verdicts`)."""
    neg, pos = declared_rel(cfg)
    return float(math.sqrt(0.5 * (neg * neg + pos * pos)))


def model_from_config(cfg: VehicleConfig, source: str = VEHICLE_FILE) -> ControlModel:
    """The control model of the vehicle file (module docstring); every value's source is ``source``."""
    rel = declared_inertia_uncertainty_rel(cfg)
    axes = {}
    for dof in DOFS:
        h = cfg.dof_hydrodynamics(dof)
        bias = float(cfg.buoyancy_n - cfg.weight_n) if dof == "heave" else 0.0
        v = cfg.vehicle
        restoring = float(v.centre_of_gravity_frd_m[2] * cfg.weight_n
                          - v.centre_of_buoyancy_frd_m[2] * cfg.buoyancy_n) if dof in ("roll", "pitch") else 0.0
        axes[dof] = AxisModel(dof, prior_inertia(cfg, dof), rel,
                              h.linear_damping_positive, h.linear_damping_negative, h.quadratic_damping_positive,
                              h.quadratic_damping_negative, bias, restoring,
                              {k: source for k in ("inertia", "damping", "bias", "restoring")})
    return ControlModel(axes, source)


def _number(x: Any) -> float | None:
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        return None
    v = float(x)
    return v if math.isfinite(v) else None


def _disqualifying(entry: Mapping) -> list[str]:
    """The reasons of a suspect parameter that matter for control (module docstring), [] when it may be used."""
    if entry.get("verdict", "trusted") != "suspect":
        return []
    reasons = [str(r) for r in (entry.get("reasons") or [])]
    if not reasons:
        return ["suspect"]
    return [r for r in reasons if not any(p in r for p in CONTROL_IRRELEVANT_REASONS)]


def unexplained_bias(entry: Mapping, file_bias: float, cfg: VehicleConfig, scale: float = 1.0) -> str | None:
    """Why a DOF's identified constant force disqualifies its force terms, or None (docs/control.md §4, "Verdicts").

    ``entry``: the DOF's mapping of identification.yaml; ``file_bias``: the vehicle file's holding
    force (N; heave B - W, FRD down); ``scale``: the calibrated thrust scale the values are divided
    by. Only a bias ``suspect`` for differing from a nonzero ``file_bias`` is judged: a ratio b /
    file_bias within 1 / (1 +- r), r = :data:`BIAS_THRUST_SCALE_SIGMAS` x the larger declared
    thrust-curve 1-sigma, is a thrust scale (None)."""
    par = entry.get("bias")
    if not isinstance(par, Mapping) or file_bias == 0.0 or par.get("verdict", "trusted") != "suspect":
        return None
    if not any("differs from the expected" in str(r) for r in (par.get("reasons") or [])):
        return None
    b = _number(par.get("value"))
    if b is None:
        return None  # falls back anyway (not a number)
    r = min(0.9, BIAS_THRUST_SCALE_SIGMAS * max(declared_rel(cfg)))
    ratio = (b / scale) / file_bias
    lo, hi = 1.0 / (1.0 + r), 1.0 / (1.0 - r)
    if lo <= ratio <= hi:
        return None
    return (f"bias {b / scale:+.3g} N is {ratio:.2f} x the file's {file_bias:+.3g} N, outside the thrust scales "
            f"{lo:.2f}-{hi:.2f}: a force error, not a thrust scale")


def _scales(doc: Mapping) -> dict[str, float]:
    """DOF -> thrust scale of a calibrated identification (``joint.scales.<group>.value`` for the group's ``dofs``)."""
    out: dict[str, float] = {}
    scales = (doc.get("joint") or {}).get("scales") if isinstance(doc.get("joint"), Mapping) else None
    if not isinstance(scales, Mapping):
        return out
    for g in scales.values():
        if not isinstance(g, Mapping):
            continue
        v = _number(g.get("value"))
        dofs = g.get("dofs") or []
        if v is not None and v > 0 and isinstance(dofs, (list, tuple)):
            for d in dofs:
                if d in DOFS:
                    out[d] = v
    return out


class ModelFileError(ValueError):
    """An identification file the controller cannot use (one line naming the file and why)."""


def load_model(path: str | Path, cfg: VehicleConfig) -> ControlModel:
    """The control model from ``identification.yaml`` at ``path`` over the vehicle file ``cfg`` (module docstring).

    Raises :class:`ModelFileError` (one line) for a file that cannot be read, is not an identification or belongs
    to another vehicle. DOFs the file does not hold, and parameters that are missing, unusable or suspect (for
    control), keep the vehicle file's value, each with its reason in :attr:`AxisModel.sources` (and the DOFs in
    :attr:`ControlModel.notes`)."""
    base = model_from_config(cfg)
    p = Path(path)

    def fallback(why: str) -> ControlModel:
        raise ModelFileError(f"{p}: {why}")

    try:
        doc = yaml.safe_load(p.read_text())
    except OSError as exc:
        return fallback(f"cannot read ({exc.strerror or exc})")
    except yaml.YAMLError as exc:
        return fallback(f"not valid YAML ({str(exc).splitlines()[0]})")
    except UnicodeDecodeError as exc:
        return fallback(f"not a text file (byte {exc.start}: {exc.reason})")
    except RecursionError:
        return fallback("YAML nested too deeply for the parser")
    if not isinstance(doc, Mapping) or not isinstance(doc.get("dofs"), Mapping) or not doc["dofs"]:
        return fallback("not an identification file (no 'dofs' mapping)")
    prov = doc.get("provenance") if isinstance(doc.get("provenance"), Mapping) else {}
    recorded = prov.get("vehicle_parameters")
    sha = prov.get("configuration_sha256")
    if isinstance(recorded, Mapping):
        changed = parameter_differences(recorded, cfg)
        if changed:
            more = f" and {len(changed) - 3} more" if len(changed) > 3 else ""
            return fallback(f"identified for another vehicle: {'; '.join(changed[:3])}{more} "
                            f"(provenance.vehicle_parameters -> {cfg.source})")
    elif not isinstance(sha, str) or not sha:
        return fallback("no provenance.vehicle_parameters (identified without the vehicle file: give --config to "
                        "hindrax ident fit)")
    elif sha != cfg.sha256:
        return fallback(f"written before provenance.vehicle_parameters, for another vehicle file text "
                        f"(configuration_sha256 {sha[:12]}, {cfg.source}: {cfg.sha256[:12] or 'unknown'}); "
                        f"identify the bag again")
    scales = _scales(doc)
    notes: list[str] = []
    axes = dict(base.axes)
    used = []
    for dof, entry in doc["dofs"].items():
        if dof not in DOFS or not isinstance(entry, Mapping):
            continue
        axes[dof] = _axis_from_entry(dof, entry, base.axes[dof], cfg, scales.get(dof))
        used.append(dof)
    if not used:
        return fallback("no DOF of surge, sway, heave, roll, pitch, yaw in 'dofs'")
    if scales:
        notes.append("calibrated identification: values divided by the thrust scale of their group ("
                     + ", ".join(f"{d} {s:.4f}" for d, s in scales.items() if d in used) + ")")
    missing = [d for d in DOFS if d not in used]
    if missing:
        notes.append(f"not identified, vehicle file used: {', '.join(missing)}")
    return ControlModel(axes, str(p), tuple(notes))


def _axis_from_entry(dof: str, entry: Mapping, file_axis: AxisModel, cfg: VehicleConfig,
                     scale: float | None) -> AxisModel:
    """One DOF of identification.yaml over the vehicle file's axis (module docstring)."""
    s = 1.0 if scale is None else scale
    sources: dict[str, str] = {}

    force_error = unexplained_bias(entry, file_axis.bias, cfg, s)

    def pick(name: str, file_value: float, allow_negative: bool = False,
             force_term: bool = False) -> tuple[float, str, float | None]:
        par = entry.get(name)
        if not isinstance(par, Mapping):
            return file_value, f"{VEHICLE_FILE} (not identified)", None
        v = _number(par.get("value"))
        if v is None:
            return file_value, f"{VEHICLE_FILE} (identified value not a number)", None
        if v < 0 and not allow_negative:
            return file_value, f"{VEHICLE_FILE} (identified {v:.4g} < 0)", None
        bad = _disqualifying(par) or ([force_error] if (force_term and force_error) else [])
        if bad:
            return file_value, f"{VEHICLE_FILE} (identified value suspect: {bad[0]})", None
        sd = _number(par.get("std"))
        return v / s, "identified" + (f" / thrust scale {s:.4f}" if scale is not None else ""), \
            (None if sd is None else abs(sd) / s)

    inertia_entry = entry.get("inertia")
    if not isinstance(inertia_entry, Mapping) and isinstance(entry.get("added_mass"), Mapping):
        # only the added mass: rigid part from the vehicle file (identification.yaml always has both today)
        am = dict(entry["added_mass"])
        v = _number(am.get("value"))
        am["value"] = None if v is None else v + rigid_inertia(cfg, dof) * s
        entry = {**entry, "inertia": am}
    inertia, src, sd = pick("inertia", file_axis.inertia)
    if src == "identified" or src.startswith("identified /"):
        if not inertia > 0:
            inertia, src, sd = file_axis.inertia, f"{VEHICLE_FILE} (identified inertia not > 0)", None
    rel = file_axis.inertia_rel_std if sd is None else sd / inertia
    sources["inertia"] = src
    if dof == "heave":
        names = {n: n for n in _DAMPING}
    else:
        names = {n: n.rsplit("_", 1)[0] for n in _DAMPING}  # one coefficient for both directions
    values = {}
    dsrc = set()
    for n, key in names.items():
        v, ssrc, _ = pick(key, getattr(file_axis, n), force_term=True)
        values[n] = v
        dsrc.add(ssrc)
    sources["damping"] = "; ".join(sorted(dsrc))
    bias, bsrc, _ = pick("bias", file_axis.bias, allow_negative=True, force_term=True)
    sources["bias"] = bsrc
    restoring = file_axis.restoring
    if dof in ROTATIONAL_DOFS and dof != "yaw":
        restoring, rsrc, _ = pick("restoring", file_axis.restoring)
        sources["restoring"] = rsrc
    else:
        sources["restoring"] = VEHICLE_FILE
    return AxisModel(dof, float(inertia), float(rel), float(values["linear_damping_positive"]),
                     float(values["linear_damping_negative"]), float(values["quadratic_damping_positive"]),
                     float(values["quadratic_damping_negative"]), float(bias), float(restoring), sources)
