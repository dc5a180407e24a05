"""identification.yaml: identified hydrodynamic parameters with provenance, and configuration overrides.

Schema (docs/architecture.md §5; version :data:`SCHEMA_VERSION`)::

    schema_version: 1
    provenance: {source: "simulation" | <bag path>, date: <UTC ISO 8601>, configuration_sha256: <hex>,
                 water_density_kg_m3: <float>, method: <text>, seed: <int or null>}
    dofs:
      <dof>:                        # surge sway heave roll pitch yaw
        <parameter>: {value: <float>, std: <float>, unit: <text>, ci95: [<low>, <high>], std_fit: <float>,
                      verdict: trusted | suspect, reasons: [<text>, ...]}   # identification/assessment/verdicts.py
        verdict: trusted | suspect | no model beats holding the velocity   # suspect when any parameter is
        reasons: [<text>, ...]              # the DOF-wide checks that failed
        model: <text>                       # the fit core's terms chosen by cross-validation
        model_selection: [{terms, parameters, cv_nrmse, cv_nrmse_hold, chosen}, ...]  # + persistence and zero
        persistence: {nrmse, nrmse_hold, nrmse_zero, margin, beats}   # fit_core.persistence
        method: "output-error" | "equation-error"
        pool_time_s: <float>
        comparison: {equation_error: {<parameter>: [value, std]}, rls: {...}, steady_state: {...} | null,
                     steady_state_note: <text>, rls_time_s: <float|null>, steady_state_time_s: <float|null>}
        configured: {<parameter>: <float>}     # optional: the configuration's values (simulation runs)
        prior: {added_mass, linear_damping, quadratic_damping: <float|null>, source: <text>}  # [NTNU-Thesis] App. A
        # a parameter weighted by an empirical prior also carries prior: [mean, std] (identification.prior_std_rel)
    joint: {prior_std_rel, method, scales: {<vertical|horizontal|common>: {value, std, prior: [1, std],
            measurements: [{step, value, std}], dofs}}}      # calibration.joint_estimate, docs/identification.md §6
    calibration: {...}                                      # with calibration steps: calibration.calibration_section
        drag_coefficient: {c_d: [value, std] (heave: c_d_positive, c_d_negative), projected_area_m2,
                           characteristic_length_m, reynolds_range: [low, high], definition}  # surge/sway/heave

<parameter>: ``inertia`` (rigid + added; kg or kg m^2), ``added_mass`` (inertia - rigid),
``quadratic_damping`` and ``linear_damping`` (heave: ``*_positive`` and ``*_negative``, positive heave = down,
[Hindrax-Drag] §4.1), ``bias`` (N or N m; heave: the FRD force holding depth), roll/pitch also ``restoring`` (N m).
Values are positive Fossen/SNAME coefficients in SI (as the configuration, ros_ws/config/hindrax.yaml).

:func:`to_config_overrides` maps the file onto ``hydrodynamics.*`` configuration keys, so
``load_config(path, overrides=...)`` (and hence the simulator) can use the identified model.
"""
from __future__ import annotations

import datetime as _dt
import math
from pathlib import Path
from typing import Any, Mapping

import yaml

from hindrax_drivers.config import DOFS, ROTATIONAL_DOFS, VehicleConfig

from ...estimation.drag_coefficient import (
    characteristic_length_from_volume,
    drag_coefficient,
    reynolds_range,
)
from ...estimation.least_squares import EstimationError
from ..fit.posterior import prior_entries
from ..fit.calibration import calibration_section, joint_estimate
from ...vehicle.vehicle_match import vehicle_parameters
from .verdicts import apply_verdicts, model_selection, rls_published_std

__all__ = ["SCHEMA_VERSION", "IdentificationFileError", "build_results", "drag_coefficient_entry",
           "write_identification", "read_identification", "to_config_overrides", "REQUIRED_PARAMETERS"]

SCHEMA_VERSION = 1


class IdentificationFileError(ValueError):
    """identification.yaml is unreadable or does not follow the schema (message names the key)."""


def REQUIRED_PARAMETERS(dof: str) -> tuple[str, ...]:  # noqa: N802 - reads like a table
    """Parameters every DOF entry must carry."""
    damping = (("quadratic_damping_positive", "quadratic_damping_negative", "linear_damping_positive",
                "linear_damping_negative") if dof == "heave" else ("quadratic_damping", "linear_damping"))
    extra = ("restoring",) if dof in ("roll", "pitch") else ()
    return ("inertia", "added_mass") + damping + ("bias",) + extra


def _f(x) -> float | None:
    return None if x is None or (isinstance(x, float) and not math.isfinite(x)) else float(x)


#: Projected area of each translational DOF from the configured bounding box (vehicle.length_m, width_m,
#: height_m): the two dimensions normal to the motion. ASSUMPTION: [Hindrax-Drag] Table 4 prints no areas.
_AREA_DIMENSIONS = {"surge": ("width_m", "height_m"), "sway": ("length_m", "height_m"),
                    "heave": ("length_m", "width_m")}
#: Speeds at or below this are left out of the Reynolds range (the vehicle between levels), m/s.
REYNOLDS_MIN_SPEED_M_S = 0.05


def drag_coefficient_entry(r: Any, cfg: VehicleConfig) -> dict | None:
    """[Hindrax-Drag] Table 4 for a translational DOF: C_D = 2 k_q / (rho A_p) with its std from the std of k_q
    (:func:`~hindrax_ident.estimation.drag_coefficient.drag_coefficient`; heave per direction), A_p the
    bounding-box area normal to the motion (:data:`_AREA_DIMENSIONS`), and the Reynolds range Re = |v| L / nu
    with L = V^(1/3) ([Hindrax-AM] eq. 10) over the DOF's filtered speeds above :data:`REYNOLDS_MIN_SPEED_M_S`.
    None for rotational DOFs ([Hindrax-Drag] defines neither their area nor their radius)."""
    if r.dof not in _AREA_DIMENSIONS:
        return None
    a, b = _AREA_DIMENSIONS[r.dof]
    area = float(getattr(cfg.vehicle, a)) * float(getattr(cfg.vehicle, b))
    rho = float(cfg.environment.water_density_kg_m3)
    length = characteristic_length_from_volume(float(cfg.vehicle.displaced_volume_m3))
    out: dict = {}
    names = (("c_d_positive", "quadratic_damping_positive"), ("c_d_negative", "quadratic_damping_negative")) \
        if r.dof == "heave" else (("c_d", "quadratic_damping"),)
    for key, name in names:
        c, sd = drag_coefficient(max(float(r.values[name]), 0.0), area, rho, float(r.std[name]))
        out[key] = [c, sd]
    out["projected_area_m2"] = area
    out["characteristic_length_m"] = length
    try:
        lo, hi = reynolds_range(r.signals.get("velocity", []), length, min_speed=REYNOLDS_MIN_SPEED_M_S)
        out["reynolds_range"] = [lo, hi]
    except (EstimationError, ValueError):
        out["reynolds_range"] = None
    out["definition"] = (f"C_D = 2 k_q / (rho A_p), A_p = {a} x {b} of the configuration "
                         "(assumed: [Hindrax-Drag] prints no areas); Re = |v| V^(1/3) / 1.01e-6 m^2/s "
                         f"over speeds above {REYNOLDS_MIN_SPEED_M_S:g} m/s")
    return out


def _rls_entry(dof: str, r: Any, cfg: VehicleConfig) -> dict:
    """{name: [value, std or None]} of the online RLS, the std as published (:func:`~.verdicts.rls_published_std`:
    None = not converged / not trusted)."""
    names = [n for n in r.names if n in r.online]
    vals = [float(r.online[n][0]) for n in names]
    stds = [math.nan if r.online[n][1] is None else float(r.online[n][1]) for n in names]
    pub = rls_published_std(dof, names, vals, stds, cfg)
    return {n: [v, _f(float(s))] for n, v, s in zip(names, vals, pub)}


def build_results(identifications: Mapping[str, Any], cfg: VehicleConfig, source: str = "simulation",
                  seed: int | None = None, method: str | None = None,
                  include_configured: bool = True, calibration: Mapping[str, Any] | None = None) -> dict:
    """The identification.yaml document from :class:`~..fit.dof_model.DofIdentification` objects (per DOF).

    The intervals are the honest ones of :func:`~.verdicts.apply_verdicts` (fit covariance + thrust-curve
    uncertainty, Student t on the independent segments; applied here if not yet), each parameter with ``std_fit``
    (the fit alone), ``verdict`` (trusted | suspect) and ``reasons``; each DOF with ``verdict`` and ``reasons``.

    Before the verdicts the empirical priors (``identification.prior_std_rel``) and, with ``calibration`` (the
    record's calibration steps; the identifications then come from the record scaled by
    :func:`~..fit.calibration.apply_thrust_calibration`), the thrust scales are estimated jointly with the fits
    (:func:`~..fit.calibration.joint_estimate`, in place, skipped for DOFs already assessed); each parameter that had a
    prior shows it as ``prior: [mean, std]`` beside its value, the document gains ``joint`` (the scales' posterior)
    and, with a calibration, ``calibration`` (:func:`~..fit.calibration.calibration_section`).
    """
    joint = joint_estimate(identifications, cfg, calibration)
    assessments = apply_verdicts(identifications, cfg)
    priors = prior_entries(cfg)
    dofs: dict = {}
    for dof, r in identifications.items():
        entry: dict = {}
        a = assessments[dof]
        for name in REQUIRED_PARAMETERS(dof):
            lo, hi = r.ci95[name]
            pa = a["parameters"].get(name, {})
            entry[name] = {"value": float(r.values[name]), "std": float(r.std[name]), "unit": r.units[name],
                           "ci95": [float(lo), float(hi)], "std_fit": float(pa.get("std_fit", r.std[name])),
                           "verdict": pa.get("verdict", "trusted"), "reasons": list(pa.get("reasons", []))}
            if pa.get("advice"):  # what data would fix a suspect parameter (verdicts.data_advice)
                entry[name]["advice"] = pa["advice"]
            if "t_dof" in pa:
                entry[name]["t_dof"] = int(pa["t_dof"])
            if "at_bound" in pa:  # the interval means nothing there: say so next to it (as hindrax ident fit)
                entry[name]["at_bound"] = float(pa["at_bound"])
            pri = (r.signals.get("joint") or {}).get("priors", {})
            if name == "added_mass" and "inertia" in pri:  # the inertia's prior less the (known) rigid part
                rigid = float(r.values["inertia"]) - float(r.values["added_mass"])
                entry[name]["prior"] = [float(pri["inertia"][0]) - rigid, float(pri["inertia"][1])]
            elif name in pri:
                entry[name]["prior"] = [float(pri[name][0]), float(pri[name][1])]
        entry["verdict"] = a["verdict"]
        entry["reasons"] = list(a["reasons"])
        core = r.signals.get("core")
        if core is not None:  # the fit core's choice, scored against holding the velocity and 0 (fit_core.persistence)
            entry["model"] = core.terms.label
            entry["model_selection"] = _plain_rows(model_selection(core))
            if core.persistence is not None:
                entry["persistence"] = {k: (bool(v) if k == "beats" else float(v))
                                        for k, v in core.persistence.items()}
        entry["method"] = r.method
        entry["pool_time_s"] = float(r.pool_time_s)
        entry["comparison"] = {
            "equation_error": {k: [float(v), float(s)] for k, (v, s) in r.equation_error.items()},
            "rls": _rls_entry(dof, r, cfg),
            "steady_state": None if r.steady is None else {k: [float(v), _f(s)] for k, (v, s) in r.steady.items()},
            "steady_state_note": r.steady_note,
            "rls_time_s": _f(r.rls_time_s),
            "steady_state_time_s": _f(r.steady_time_s),
        }
        if include_configured:
            entry["configured"] = {k: float(v) for k, v in r.truth.items()}
        if dof in priors:
            entry["prior"] = priors[dof]
        drag = drag_coefficient_entry(r, cfg)
        if drag is not None:
            entry["drag_coefficient"] = drag
        dofs[dof] = entry
    doc = {
        "schema_version": SCHEMA_VERSION,
        "provenance": {
            "source": source,
            "date": _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat(),
            "configuration_sha256": cfg.sha256,
            "vehicle_parameters": vehicle_parameters(cfg),  # what the values depend on (vehicle_match.py)
            "water_density_kg_m3": float(cfg.environment.water_density_kg_m3),
            "method": method or ("[Hindrax-Drag] §4 self-propelled ladder; the fit core's segment-wise output error on "
                                 "the raw sensor samples (docs/identification.md §7); equation-error batch LS "
                                 "([Hindrax-Drag] eqs. 6-8), RLS online and steady-state LS ([Hindrax-Drag] "
                                 "eqs. 2-8) for comparison"),
            "seed": seed,
        },
        "dofs": dofs,
    }
    if joint:
        doc["joint"] = joint
    if calibration:
        doc["calibration"] = calibration_section(calibration, cfg)
    return doc


def _plain_rows(rows: list) -> list:
    """:func:`~.verdicts.model_selection` rows with plain ``int``/``float``/``bool`` values (safe_dump)."""
    return [{k: (v if isinstance(v, (str, bool)) or v is None else int(v) if k == "parameters" else float(v))
             for k, v in row.items()} for row in rows]


def write_identification(path: str | Path, document: Mapping) -> Path:
    """Validate ``document`` (:func:`validate`) and write it as YAML; returns the path."""
    validate(document)
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text("# Hindrax identified hydrodynamics (hindrax_ident.identification.assessment.results, schema "
                 f"{SCHEMA_VERSION})\n" + yaml.safe_dump(dict(document), sort_keys=False, default_flow_style=None))
    return p


def validate(doc: Any) -> dict:
    """Check the schema; returns the document. Raises :class:`IdentificationFileError` naming the bad key."""
    if not isinstance(doc, Mapping):
        raise IdentificationFileError("identification file: top level must be a mapping")
    if doc.get("schema_version") != SCHEMA_VERSION:
        raise IdentificationFileError(f"schema_version: expected {SCHEMA_VERSION}, got {doc.get('schema_version')!r}")
    prov = doc.get("provenance")
    if not isinstance(prov, Mapping):
        raise IdentificationFileError("provenance: missing mapping")
    for key in ("source", "date", "configuration_sha256", "water_density_kg_m3", "method", "seed"):
        if key not in prov:
            raise IdentificationFileError(f"provenance.{key}: missing")
    dofs = doc.get("dofs")
    if not isinstance(dofs, Mapping) or not dofs:
        raise IdentificationFileError("dofs: missing or empty mapping")
    for dof, entry in dofs.items():
        if dof not in DOFS:
            raise IdentificationFileError(f"dofs.{dof}: unknown DOF (one of {', '.join(DOFS)})")
        if not isinstance(entry, Mapping):
            raise IdentificationFileError(f"dofs.{dof}: must be a mapping")
        for name in REQUIRED_PARAMETERS(dof):
            par = entry.get(name)
            if not isinstance(par, Mapping):
                raise IdentificationFileError(f"dofs.{dof}.{name}: missing")
            for key in ("value", "std", "unit"):
                if key not in par:
                    raise IdentificationFileError(f"dofs.{dof}.{name}.{key}: missing")
            for key in ("value", "std"):
                v = par[key]
                if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(float(v)):
                    raise IdentificationFileError(f"dofs.{dof}.{name}.{key}: must be a finite number, got {v!r}")
            if par["std"] < 0:
                raise IdentificationFileError(f"dofs.{dof}.{name}.std: must be >= 0")
    return dict(doc)


def read_identification(path: str | Path) -> dict:
    """Read and validate identification.yaml. Raises :class:`IdentificationFileError` (one-line message)."""
    p = Path(path)
    try:
        doc = yaml.safe_load(p.read_text())
    except OSError as exc:
        raise IdentificationFileError(f"{p}: cannot read ({exc.strerror})") from exc
    except yaml.YAMLError as exc:
        raise IdentificationFileError(f"{p}: not valid YAML ({str(exc).splitlines()[0]})") from exc
    return validate(doc)


def to_config_overrides(document: Mapping) -> dict[str, float]:
    """``hydrodynamics.*`` configuration keys -> identified values (for ``load_config(..., overrides=)``).

    Added mass and damping only (the configuration's inertia and buoyancy come from mass, volume and
    geometry). Negative damping estimates (unphysical; the schema requires >= 0) are clipped to 0.
    Raises :class:`IdentificationFileError` (a ValueError, one line) for a file that is not config-ready: one of
    ``hindrax ident fit`` without ``--config`` (``config_ready: false``, or an ``inertia`` without ``added_mass``:
    without the vehicle file only the rigid + added inertia is known), or one that fails :func:`validate`.
    """
    if isinstance(document, Mapping) and isinstance(document.get("dofs"), Mapping):
        bare = [d for d, e in document["dofs"].items() if isinstance(e, Mapping) and "inertia" in e
                and "added_mass" not in e]
        if document.get("config_ready") is False or bare:
            raise IdentificationFileError(
                f"identification file not config-ready: no added_mass ({', '.join(bare) or 'any DOF'}): written by "
                "`hindrax ident fit` without --config, which knows only the rigid + added inertia; rerun it with "
                "--config FILE (the vehicle file giving the rigid-body inertia) to apply it to a vehicle file")
    validate(document)
    out: dict[str, float] = {}
    for dof, e in document["dofs"].items():
        base = f"hydrodynamics.{dof}."
        val = {k: float(v["value"]) for k, v in e.items() if isinstance(v, Mapping) and "value" in v}
        if dof in ROTATIONAL_DOFS:
            out[base + "added_mass_kg_m2"] = max(0.0, val["added_mass"])
            out[base + "linear_damping_kg_m2_s"] = max(0.0, val["linear_damping"])
            out[base + "quadratic_damping_kg_m2"] = max(0.0, val["quadratic_damping"])
        elif dof == "heave":
            out[base + "added_mass_kg"] = max(0.0, val["added_mass"])
            for d in ("positive", "negative"):
                out[base + f"linear_damping_{d}_kg_s"] = max(0.0, val[f"linear_damping_{d}"])
                out[base + f"quadratic_damping_{d}_kg_m"] = max(0.0, val[f"quadratic_damping_{d}"])
        else:
            out[base + "added_mass_kg"] = max(0.0, val["added_mass"])
            out[base + "linear_damping_kg_s"] = max(0.0, val["linear_damping"])
            out[base + "quadratic_damping_kg_m"] = max(0.0, val["quadratic_damping"])
    return out
