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
        terms: {damping, by_direction, ...}, cross_dofs: [<dof>], force_dofs: [<dof>], bias_runs: <int>,
        parameters: [<parameter>, ...]      # hindrax ident fit's model, in layout order (model_spec reads it)
        model_selection: [{terms, parameters, cv_nrmse, cv_nrmse_hold, chosen}, ...]  # + persistence and zero
        persistence: {nrmse, nrmse_hold, nrmse_zero, margin, beats}   # fit_core.persistence
        training: {initial_state: {used, cv_nrmse: {<rule>: <float>}},        # fit_core.training_rules
                   segments: {used: moving_only, moving_only | all_segments: {cv_nrmse, segments, parameters}}}
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
``load_config(path, overrides=...)`` (and hence the simulator) can use the identified model."""
from __future__ import annotations

import dataclasses
import datetime as _dt
import math
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import yaml

from hindrax_common.config import DOFS, ROTATIONAL_DOFS, VehicleConfig

from hindrax_onboard.estimation.drag_coefficient import (characteristic_length_from_volume, drag_coefficient,
                                            reynolds_range)
from hindrax_onboard.estimation.least_squares import EstimationError
from ..fit.calibration import calibration_section, decay_inertia, joint_estimate
from hindrax_onboard.identification.model.dof_model import parameter_units, rigid_inertia, rls_published_std
from ..fit import fit_core
from ..fit.fit_core import NO_MODEL_VERDICT
from hindrax_onboard.identification.model.posterior import (finite_or_none as _f, prior_entries, prior_posterior,
                             prior_std_rel_of, theta_priors)
from hindrax_onboard.vehicle.uncertainty import declared_rel
from hindrax_onboard.vehicle.vehicle_match import vehicle_parameters
from .verdicts import (FitEvidence, apply_reference_verdicts, apply_verdicts, assess, core_evidence, model_selection,
                       thrust_curve_check, with_added_mass)

__all__ = ["SCHEMA_VERSION", "IdentificationFileError", "build_results", "build_document", "assessment",
           "reference_sections", "training_lines", "drag_coefficient_entry", "write_identification",
           "read_identification", "to_config_overrides", "model_spec", "model_lists", "REQUIRED_PARAMETERS",
           "TERM_MEANING", "CONFIG_READY_REASON"]

SCHEMA_VERSION = 1


class IdentificationFileError(ValueError):
    """identification.yaml is unreadable or does not follow the schema (message names the key)."""


def REQUIRED_PARAMETERS(dof: str) -> tuple[str, ...]:  # noqa: N802 - reads like a table
    """Parameters every DOF entry must carry."""
    damping = (("quadratic_damping_positive", "quadratic_damping_negative", "linear_damping_positive",
                "linear_damping_negative") if dof == "heave" else ("quadratic_damping", "linear_damping"))
    extra = ("restoring",) if dof in ("roll", "pitch") else ()
    return ("inertia", "added_mass") + damping + ("bias",) + extra


#: Projected area of each translational DOF from the configured bounding box (vehicle.length_m, width_m,
#: height_m): the two dimensions normal to the motion. ASSUMPTION: [Hindrax-Drag] Table 4 prints no areas.
_AREA_DIMENSIONS = {"surge": ("width_m", "height_m"), "sway": ("length_m", "height_m"),
                    "heave": ("length_m", "width_m")}
#: Speeds at or below this are left out of the Reynolds range (the vehicle between levels), m/s.
REYNOLDS_MIN_SPEED_M_S = 0.05


def drag_coefficient_entry(r: Any, cfg: VehicleConfig) -> dict | None:
    """[Hindrax-Drag] Table 4 for a translational DOF: C_D = 2 k_q / (rho A_p) with its std from the std of k_q
    (:func:`~hindrax_onboard.estimation.drag_coefficient.drag_coefficient`; heave per direction), A_p the
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
    """{name: [value, std or None]} of the online RLS, the std as published (:func:`rls_published_std`:
    None = not converged / not trusted)."""
    names = [n for n in r.names if n in r.online]
    vals = [float(r.online[n][0]) for n in names]
    stds = [math.nan if r.online[n][1] is None else float(r.online[n][1]) for n in names]
    pub = rls_published_std(dof, names, vals, stds, cfg)
    return {n: [v, _f(float(s))] for n, v, s in zip(names, vals, pub)}


def _provenance(cfg: VehicleConfig | None, source: str, method: str, seed: int | None) -> dict:
    """identification.yaml ``provenance``: the data, the date, the vehicle file the values depend on
    (:func:`~...vehicle.vehicle_match.vehicle_parameters`; None without one), the method and the seed."""
    return {"source": source, "date": _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat(),
            "configuration_sha256": None if cfg is None else cfg.sha256,
            "vehicle_parameters": None if cfg is None else vehicle_parameters(cfg),
            "water_density_kg_m3": None if cfg is None else float(cfg.environment.water_density_kg_m3),
            "method": method, "seed": seed}


def build_results(identifications: Mapping[str, Any], cfg: VehicleConfig, source: str = "simulation",
                  seed: int | None = None, method: str | None = None,
                  calibration: Mapping[str, Any] | None = None) -> dict:
    """The identification.yaml document from :class:`~..fit.dof_model.DofIdentification` objects (per DOF).

    The intervals, verdicts and reasons are :func:`~.verdicts.apply_verdicts`' (applied here if not
    yet; the schema in the module docstring).

    Before the verdicts the empirical priors (``identification.prior_std_rel``) and, with ``calibration`` (the
    record's calibration steps; the identifications then come from the record scaled by
    :func:`~..fit.calibration.apply_thrust_calibration`), the thrust scales are estimated jointly with the fits
    (:func:`~..fit.calibration.joint_estimate`, in place, skipped for DOFs already assessed); each parameter that had a
    prior shows it as ``prior: [mean, std]`` beside its value, the document gains ``joint`` (the scales' posterior)
    and, with a calibration, ``calibration`` (:func:`~..fit.calibration.calibration_section`)."""
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
            entry["model_selection"] = _plain(model_selection(core))
            if core.persistence is not None:
                entry["persistence"] = _plain(core.persistence)
            if core.training:
                entry["training"] = _plain(core.training)
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
        entry["configured"] = {k: float(v) for k, v in r.truth.items()}
        if dof in priors:
            entry["prior"] = priors[dof]
        drag = drag_coefficient_entry(r, cfg)
        if drag is not None:
            entry["drag_coefficient"] = drag
        dofs[dof] = entry
    return _document(_provenance(cfg, source, method or (
        "[Hindrax-Drag] §4 self-propelled ladder; the fit core's segment-wise output error on the raw sensor "
        "samples (docs/identification.md §7); equation-error batch LS ([Hindrax-Drag] eqs. 6-8), RLS online and "
        "steady-state LS ([Hindrax-Drag] eqs. 2-8) for comparison"), seed), dofs,
        joint=joint or None, calibration=calibration_section(calibration, cfg) if calibration else None)


def _document(provenance: dict, dofs: dict, **sections: Any) -> dict:
    """The one builder of identification.yaml's top level (both :func:`build_results` and :func:`build_document`):
    schema version, ``provenance``, ``dofs`` and the further ``sections`` that are not None, as plain YAML values,
    checked by :func:`validate` (raises :class:`IdentificationFileError`)."""
    doc = {"schema_version": SCHEMA_VERSION, "provenance": provenance, "dofs": dofs,
           **{k: v for k, v in sections.items() if v is not None}}
    return validate(_plain(doc))


def write_identification(path: str | Path, document: Mapping) -> Path:
    """Validate ``document`` (:func:`validate`) and write it as YAML; returns the path. Raises
    :class:`IdentificationFileError`."""
    validate(document)
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text("# Hindrax identified hydrodynamics (hindrax_fit.assessment.results, schema "
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
    if not isinstance(dofs, Mapping) or not (dofs or doc.get("not_identified")):
        raise IdentificationFileError("dofs: missing or empty mapping")
    for dof, entry in dofs.items():
        if dof not in DOFS:
            raise IdentificationFileError(f"dofs.{dof}: unknown DOF (one of {', '.join(DOFS)})")
        if not isinstance(entry, Mapping):
            raise IdentificationFileError(f"dofs.{dof}: must be a mapping")
        if "terms" in entry:  # a model hindrax ident predict simulates
            model_spec(dof, entry)
        for name in REQUIRED_PARAMETERS(dof):
            if name == "added_mass" and doc.get("config_ready") is False:  # no vehicle file: inertia only
                continue
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


def _dof_list(dof: str, entry: Mapping, key: str) -> tuple[str, ...]:
    """``dofs.<dof>.<key>``: a list of other DOFs, each once."""
    v = entry.get(key)
    if not isinstance(v, list) or any(d not in DOFS or d == dof for d in v) or len(set(v)) != len(v):
        raise IdentificationFileError(f"dofs.{dof}.{key}: {v!r}: must be a list of other DOFs, each once "
                                      f"(of {', '.join(DOFS)})")
    return tuple(v)


def model_spec(dof: str, entry: Mapping) -> tuple[fit_core.Terms, tuple, tuple, int, list, np.ndarray]:
    """(terms, cross-term DOFs, force DOFs, runs of the per-run bias (0: none), parameter layout
    (:func:`~..fit.fit_core.parameter_layout`), values (p,) in layout order) of one DOF of a model written by
    :func:`build_document`: the explicit lists ``terms``, ``cross_dofs``, ``force_dofs``, ``bias_runs`` and
    ``parameters`` (the layout's names, checked against the one the others give) and each parameter's finite
    ``value`` (heave's one damping pair under its ``_positive`` name). A file of an older ``hindrax ident fit``
    without the lists: the lists from the parameter entries named ``cross_<dof>``, ``force_from_<dof>``,
    ``bias_run_<k>``. Raises :class:`IdentificationFileError` naming the key."""
    t = entry.get("terms")
    fields = {f.name: f.default for f in dataclasses.fields(fit_core.Terms)}
    if not isinstance(t, Mapping) or set(t) - set(fields):
        raise IdentificationFileError(f"dofs.{dof}.terms: {t!r}: must be a mapping of {', '.join(fields)}")
    kw = {k: t.get(k, d) for k, d in fields.items()}
    if kw["damping"] not in ("both", "linear", "quadratic") or any(
            not isinstance(v, bool) for k, v in kw.items() if k != "damping"):
        raise IdentificationFileError(f"dofs.{dof}.terms: {dict(t)!r}: damping one of both, linear, quadratic, the "
                                      "others true or false")
    terms = fit_core.Terms(**kw)
    if "parameters" in entry:
        cross, forces = _dof_list(dof, entry, "cross_dofs"), _dof_list(dof, entry, "force_dofs")
        runs = entry.get("bias_runs")
        if not isinstance(runs, int) or isinstance(runs, bool) or runs < 0:
            raise IdentificationFileError(f"dofs.{dof}.bias_runs: {runs!r}: must be an integer >= 0")
    else:  # older file: the lists from the parameter entries (a mapping with a value, named after a DOF)
        def named(prefix: str) -> tuple:
            return tuple(n[len(prefix):] for n, v in entry.items() if n.startswith(prefix) and isinstance(v, Mapping)
                         and "value" in v and n[len(prefix):] in DOFS)
        cross, forces = named("cross_"), named("force_from_")
        runs = sum(n.startswith("bias_run_") and isinstance(v, Mapping) for n, v in entry.items()) + 1
    layout = fit_core.parameter_layout(dof, terms, len(cross) if terms.cross else 0, cross,
                                       forces if terms.cross_force else (), runs if terms.run_bias else 0)
    names = [n for n, _k, _lo, _hi in layout]
    if "parameters" in entry and entry["parameters"] != names:
        raise IdentificationFileError(f"dofs.{dof}.parameters: {entry['parameters']!r}, but terms, cross_dofs, "
                                      f"force_dofs and bias_runs give {names!r}")
    theta = np.empty(len(names))
    for i, n in enumerate(names):
        par = entry.get(n)
        if par is None and dof == "heave":  # one pair for both directions is written per direction
            par = entry.get(f"{n}_positive")
        v = par.get("value") if isinstance(par, Mapping) else None
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
            raise IdentificationFileError(f"dofs.{dof}.{n}.value: {v!r}: a finite number is needed (the model's "
                                          "terms need it)")
        theta[i] = float(v)
    return terms, cross, forces, runs if terms.run_bias else 0, layout, theta


def model_lists(core: Any) -> dict:
    """identification.yaml's explicit description of a fit core's model (:class:`~..fit.fit_core.DofResult`), read
    back by :func:`model_spec`: ``terms``, ``cross_dofs`` (the velocities of the cross terms), ``force_dofs`` (the
    forces of ``force_from_*``), ``bias_runs`` (runs of the per-run bias, 0: none) and ``parameters`` (the layout's
    names in order)."""
    layout = core.chosen.layout
    runs = sum(k.startswith("runbias") for _n, k, _lo, _hi in layout)
    return {"terms": dataclasses.asdict(core.terms),
            "cross_dofs": [n[len("cross_"):] for n, k, _lo, _hi in layout if k.startswith("cross")],
            "force_dofs": [n[len("force_from_"):] for n, k, _lo, _hi in layout if k.startswith("xforce")],
            "bias_runs": runs + 1 if core.terms.run_bias else 0,
            "parameters": [n for n, _k, _lo, _hi in layout]}


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
    without the vehicle file only the rigid + added inertia is known), or one that fails :func:`validate`."""
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
        rot = dof in ROTATIONAL_DOFS
        mass, lin, quad = ("kg_m2", "kg_m2_s", "kg_m2") if rot else ("kg", "kg_s", "kg_m")
        out[base + f"added_mass_{mass}"] = max(0.0, val["added_mass"])
        for d in ("_positive", "_negative") if dof == "heave" else ("",):
            out[base + f"linear_damping{d}_{lin}"] = max(0.0, val[f"linear_damping{d}"])
            out[base + f"quadratic_damping{d}_{quad}"] = max(0.0, val[f"quadratic_damping{d}"])
    return out


# ------------------------------------------------------------------------------------------------ any topics
def _units(dof: str, names: Sequence[str]) -> dict:
    """Units of the core's parameters: the campaign's (:func:`.dof_model.parameter_units`), cross terms in this
    DOF's force per unit of the other DOF's velocity, the reverse gain dimensionless."""
    u = dict(parameter_units(dof))
    u.setdefault("quadratic_damping", u.get("quadratic_damping_positive", ""))
    u.setdefault("linear_damping", u.get("linear_damping_positive", ""))
    force = "N m" if dof in ROTATIONAL_DOFS else "N"
    for n in names:
        if n.startswith("bias_run_"):
            u[n] = u.get("bias", force)
        if n.startswith("force_from_"):
            other = n[len("force_from_"):]
            u[n] = f"{force}/({'N m' if other in ROTATIONAL_DOFS else 'N'})"
        if n.startswith("cross_"):
            other = n[len("cross_"):]
            u[n] = f"{force}/({'rad/s' if other in ROTATIONAL_DOFS else 'm/s'})"
    u["reverse_thrust_gain"] = "1"
    u["saturation_gain"] = "1"
    return u


def assessment(r: Any, cfg: VehicleConfig | None) -> dict:
    """The verdicts of one fitted DOF through the one verdict path (:func:`..assessment.verdicts.assess`, as ``hindrax
    ident bag``): the fit core's estimate and cluster-robust covariance, with a vehicle file after its empirical priors
    (:func:`.posterior.prior_posterior`, ``identification.prior_std_rel``), the thrust-curve covariance
    (:func:`...vehicle.uncertainty.declared_rel`: the vehicle file's, else the default), t with the core's clusters - 1
    degrees of freedom; the expected bias 0 (heave: the vehicle file's net buoyancy, unknown without one); no
    whiteness check (its threshold is the designed campaign's, docs/identification.md §7 step 6:
    here the CV nrmse judges the model and the intervals carry the residual correlation).
    ``added_mass`` with a vehicle file. Returns
    :func:`..assessment.verdicts.assess`'s dict with ``fit_values`` (the core's, before the priors) and ``priors``
    ({name: [mean, std]})."""
    c = r.core
    theta, cov = np.asarray(c.theta, dtype=float), np.asarray(c.covariance.cov, dtype=float)
    pri: dict = {}
    if cfg is not None:
        pri = theta_priors(r.dof, c.names, cfg, prior_std_rel_of(cfg))
        theta, cov = prior_posterior(c.names, theta, cov, pri)
    expected = (None if cfg is None else float(cfg.buoyancy_n - cfg.weight_n)) if r.dof == "heave" else 0.0
    ev = FitEvidence(dof=r.dof, names=list(c.names), theta=theta, cov=cov, t_dof=int(c.covariance.t_dof),
                     units=_units(r.dof, c.names), residual_rho=None, expected_bias=expected,
                     **core_evidence(c))
    a = assess(ev, declared_rel(cfg))
    if cfg is not None:
        with_added_mass(a, a["parameters"]["inertia"]["value"] - rigid_inertia(cfg, r.dof))
    a["fit_values"] = {n: float(v) for n, v in zip(c.names, c.theta)}
    a["priors"] = {n: [float(m), float(sd)] for n, (m, sd) in pri.items()}
    return a


def _param_entries(r: Any, a: dict) -> dict:
    """The parameter entries of one fitted DOF from its :func:`assessment` ``a`` (:func:`build_document`)."""
    c = r.core
    units = _units(r.dof, c.names)
    folds = np.array(r.folds) if r.folds else None
    cov = c.covariance
    sd_model = np.sqrt(np.maximum(np.diag(cov.model), 0.0))
    sd_sand = np.sqrt(np.maximum(np.diag(cov.sandwich), 0.0))
    entries: dict = {}

    def put(i, unit, pname=None):
        v = a["parameters"][pname or c.names[i]]
        e = {"value": float(v["value"]), "std": float(v["std"]), "unit": unit,
             "ci95": [float(v["ci95"][0]), float(v["ci95"][1])], "t_dof": int(v["t_dof"]),
             "std_fit": float(v["std_fit"]),
             "std_source": "cluster_robust" if sd_sand[i] >= sd_model[i] else "model",
             "std_model": float(sd_model[i]), "std_cluster_robust": float(sd_sand[i])}
        if c.names[i] in a["priors"]:
            e["prior"] = list(a["priors"][c.names[i]])
            e["fit_value"] = a["fit_values"][c.names[i]]
        if folds is not None and len(folds) >= 2:
            e["fold_spread"] = {"std": float(np.std(folds[:, i], ddof=1)), "min": float(folds[:, i].min()),
                                "max": float(folds[:, i].max()), "folds": int(len(folds))}
        e["verdict"], e["reasons"] = v["verdict"], list(v["reasons"])
        if "at_bound" in v:  # the interval means nothing there: say so next to it
            e["at_bound"] = float(v["at_bound"])
        if "advice" in v:
            e["advice"] = v["advice"]
        return e

    for i, name in enumerate(c.names):
        if r.dof == "heave" and name in ("quadratic_damping", "linear_damping"):
            for d in ("positive", "negative"):  # one coefficient for both directions
                entries[f"{name}_{d}"] = put(i, units[f"{name}_{d}"])
                entries[f"{name}_{d}"]["note"] = "one coefficient for both directions (chosen by cross-validation)"
        else:
            entries[name] = put(i, units.get(name, ""))
    # damping terms the chosen model leaves out: 0 exactly in that model
    for n in REQUIRED_PARAMETERS(r.dof):
        if "damping" in n and n not in entries:
            no_model = a["verdict"] == NO_MODEL_VERDICT
            entries[n] = {"value": 0.0, "std": 0.0, "unit": units.get(n, ""), "ci95": [0.0, 0.0],
                          "model_term": "excluded", "verdict": "suspect" if no_model else "trusted",
                          "reasons": list(a["reasons"]) if no_model else [],
                          "note": f"not in the model chosen by cross-validation ({c.terms.label})"}
    if "added_mass" in a["parameters"]:
        am = put(c.names.index("inertia"), units["added_mass"], "added_mass")
        am.pop("fold_spread", None)
        am.pop("prior", None)
        am.pop("fit_value", None)
        entries["added_mass"] = am
    return entries


def _per_run_bias(c, a: dict, bags: Sequence, unit: str) -> list:
    """[{run, bias, std, unit}] per fitted run: the mean bias plus the run's deviation (effects coding,
    :class:`.fit_core.Terms`), std from the covariance of :func:`assessment` (a linear combination)."""
    names = list(c.names)
    ib = names.index("bias")
    idx = [i for i, n in enumerate(names) if n.startswith("bias_run_")]
    R = len(idx) + 1
    theta = np.array([a["parameters"][n]["value"] for n in names])
    std = np.array([a["parameters"][n]["std"] for n in names])
    cov = np.asarray(c.covariance.cov, dtype=float)
    d = np.sqrt(np.maximum(np.diag(cov), 1e-300))
    corr = cov / np.outer(d, d)  # the fit's correlations with the reported (thrust, priors) std
    cov = corr * np.outer(std, std)
    out = []
    for k in range(R):
        g = np.zeros(len(names))
        g[ib] = 1.0
        if k < R - 1:
            g[idx[k]] = 1.0
        else:
            g[idx] = -1.0
        out.append({"run": str(Path(bags[k]).name) if k < len(bags) else f"run {k + 1}",
                    "bias": float(g @ theta), "std": float(math.sqrt(max(g @ cov @ g, 0.0))), "unit": unit})
    return out


def training_lines(training: Mapping | None) -> list[str]:
    """The training rules of a fit (:func:`~..fit.fit_core.training_rules`) in words, one line each: the initial
    state used (with each rule's CV nrmse for a measured position) and, for a fit on the moving segments, both fits'
    CV nrmse and segment counts, the verdict's marked."""
    def num(x):
        return "-" if x is None or not math.isfinite(x) else f"{x:.4f}"

    out = []
    part = (training or {}).get("initial_state")
    if part:
        cv = ", ".join(f"{k} {num(v)}" for k, v in part.get("cv_nrmse", {}).items())
        out.append(f"training initial state: {part['used']}" + (f" (CV nrmse {cv})" if cv else ""))
    part = (training or {}).get("segments")
    if part:
        out.append("training segments: " + "; ".join(
            f"{k.replace('_', ' ')}{' (the verdict uses it)' if k == part['used'] else ''}: CV nrmse "
            f"{num(part[k]['cv_nrmse'])}, {part[k]['segments']} segments"
            for k in ("moving_only", "all_segments") if part.get(k)))
    return out


#: The physical meaning of each optional term of the chosen model (identification.yaml ``terms_meaning``)
TERM_MEANING = {
    "by_direction": "damping per direction of motion (a frame that is not symmetric top to bottom)",
    "coriolis": "Coriolis and centripetal force of the other DOFs' inertias (rigid body and added mass, Fossen 2011 "
                "eq. 6.43): a turning vehicle's surge and sway push each other",
    "cross": "force per unit of another DOF's velocity (the other DOF's damping acting here: off-diagonal damping "
             "of an open frame, or a Coriolis term the diagonal inertias leave out)",
    "cross_force": "part of another DOF's commanded force appearing here (coupling through the allocation: "
                   "thrusters that do not deliver what the allocation assumes, a thrust centre off the body origin)",
    "reverse_gain": "propellers weaker in reverse than forward (the force of negative commands times a gain)",
    "saturation": "the commanded force clipped where the thrusters reach their limits (the thrust allocation's "
                  "saturation, e.g. a heave command beyond what the vertical thrusters push): the force is the "
                  "command plus saturation_gain times the allocation's shortfall (allocation/status achieved less "
                  "requested wrench; 1: the thrusters' limits as the vehicle file has them)",
    "run_bias": "a constant force of its own in each run (tether lay, trim, buoyancy drift between runs), reported "
                "per run in bias_per_run; a new run gets the mean",
}

#: Why ``hindrax ident fit`` without ``--config`` writes ``config_ready: false`` (and no ``added_mass``).
CONFIG_READY_REASON = ("no vehicle file (--config): only the rigid + added inertia is identified, not the added mass; "
                       "applying it to a vehicle file (results.to_config_overrides) needs --config")


def _plain(x):
    """numpy scalars and arrays, tuples and nested mappings as plain YAML-safe Python values."""
    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple, np.ndarray)):
        return [_plain(v) for v in x]
    if isinstance(x, np.bool_):
        return bool(x)
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return float(x)
    return x


def build_document(res: Any, cfg: VehicleConfig | None, bags: Sequence[str | Path],
                   holdout: Sequence[str | Path] = ()) -> dict:
    """identification.yaml (docs/identification.md §7): ``dofs.<dof>.<param>.{value, std, unit, ci95, t_dof,
    std_source, std_model, std_cluster_robust, fold_spread, verdict, reasons, advice}`` of the fitted DOFs (the schema
    of :mod:`..assessment.results`; ``added_mass`` only with a configuration, which gives the rigid-body inertia:
    without one ``config_ready: false`` and ``config_ready_reason``; a damping term the chosen model leaves out is 0
    with ``model_term: excluded``), per DOF ``model`` (the chosen terms), ``model_selection`` (every candidate's CV
    nrmse), ``timing`` (delay, lag), ``interval`` (clusters, t degrees of freedom), ``verdict``, ``reasons`` and
    ``advice`` (:func:`assessment`: what data would fix each suspect parameter); ``std`` and ``ci95`` with the
    thrust-curve uncertainty and, with a vehicle file, after the empirical priors (``prior``, ``fit_value``);
    ``not_identified`` with their numbers, ``validation.<dof>.{nrmse,nrmse_hold,nrmse_zero,samples}`` (the holdout
    when given, else the cross-validation; both under their own keys too) and ``preprocessing``."""
    dofs, val, other = {}, {}, {}
    assessments = {d: assessment(r, cfg) for d, r in res.dofs.items() if r.status == "fitted"}
    if cfg is not None:  # the heave bias against the vehicle file's net buoyancy judges every DOF's thrust
        thrust_curve_check(assessments, list(assessments))
    for dof, r in res.dofs.items():
        if r.status != "fitted":
            other[dof] = {"status": r.status, "reason": r.reason,
                          **{k: (round(v, 6) if isinstance(v, float) else v) for k, v in r.excitation.items()}}
            continue
        verdicts = assessments[dof]
        e = _param_entries(r, verdicts)
        c = r.core
        e["method"] = "output-error (segment-wise, prediction error; docs/identification.md §7)"
        e["model"] = c.terms.label
        e.update(model_lists(c))
        e["terms_meaning"] = {k: TERM_MEANING[k] for k, on in e["terms"].items() if on is True and k in TERM_MEANING}
        e["model_selection"] = model_selection(c)
        if c.persistence is not None:
            e["persistence"] = dict(c.persistence)
        if c.training:
            e["training"] = c.training
        e["timing"] = {"delay_s": c.timing.delay_s, "lag_s": c.timing.lag_s, "source": c.timing.source}
        if c.timing.bound_s is not None:
            e["timing"].update(searched_up_to_s=c.timing.bound_s, bound=c.timing.bound_why, at_edge=c.timing.at_edge)
            if c.timing.at_edge:
                e["timing"]["note"] = c.timing.edge_note
        e["interval"] = {"method": "cluster-robust (sandwich) covariance, contiguous blocks of segments as "
                                   "clusters, at least the model-based covariance; Student t with clusters - 1 "
                                   "degrees of freedom",
                         "clusters": c.covariance.clusters, "segments_per_cluster": c.covariance.block,
                         "cluster_score_lag1": round(c.covariance.rho, 4), "t_dof": c.covariance.t_dof,
                         "residual_lag1": round(c.covariance.residual_rho, 4)}
        e["segments"] = int(c.train.m)
        if c.terms.run_bias:
            e["bias_per_run"] = _per_run_bias(c, verdicts, bags, _units(r.dof, c.names).get("bias", ""))
        e["verdict"] = verdicts["verdict"]
        e["reasons"] = sorted({x for v in verdicts["parameters"].values() for x in v["reasons"]})
        e["advice"] = [dict(v["advice"], parameter=n) for n, v in verdicts["parameters"].items() if "advice" in v
                       and n != "added_mass"]
        if c.fold_notes:
            e["cross_validation_notes"] = list(c.fold_notes)
        e["excitation"] = {k: v for k, v in r.excitation.items() if v is not None}
        dofs[dof] = e
        main = r.validation.get("holdout") or r.validation.get("cross_validation")
        if main:
            val[dof] = {**{k: main.get(k) for k in ("nrmse", "nrmse_hold", "nrmse_zero", "samples")},
                        "data": "holdout" if "holdout" in r.validation else "cross-validation",
                        **{k: ({kk: vv for kk, vv in v.items() if kk not in ("sse", "sst")} if isinstance(v, dict)
                               else v) for k, v in r.validation.items()}}
    return _document({**_provenance(cfg, ", ".join(str(b) for b in bags), "hindrax ident fit: segment-wise output "
                                    "error (prediction error) over free-form excitation, equation-error start; model "
                                    "of [Hindrax-Drag] eq. 2 with inertia and bias", None),
                      "bags": [str(b) for b in bags], "holdout": [str(b) for b in holdout],
                      "validation_design": res.design}, dofs,
                     config_ready=cfg is not None,
                     config_ready_reason=(CONFIG_READY_REASON if cfg is None else
                                          "added_mass = inertia - the vehicle file's rigid-body inertia"),
                     not_identified=other, validation=val, preprocessing=res.preprocessing)


# ------------------------------------------------------------------------------------------------ references
def free_decay_section(record, cfg, restoring_n_m_per_rad: float | None, restoring_std: float, progress) -> dict:
    """identification.yaml ``free_decay``: per roll/pitch the inertia from the campaign's free decay
    (:func:`~..fit.calibration.decay_inertia`; :func:`~.verdicts.apply_reference_verdicts` compares it with the
    self-propelled one). The restoring stiffness: the record's inclining step, else ``restoring_n_m_per_rad``
    (``restoring_std``), else the vehicle file's m g BG; ``progress(text)`` says why a DOF has no estimate."""
    # strictly increasing gyro stamps (the identification node moves samples that arrive after their tick to the tick
    # time, executive.ordered_samples, so its log can repeat a stamp); the in-process log is unchanged by this
    gyro, last = [], -math.inf
    for t, r in sorted(record.sensors.get("gyro", []), key=lambda x: x[0]):
        if t > last:
            gyro.append((t, r))
            last = t
    record = dataclasses.replace(record, sensors={**record.sensors, "gyro": gyro})
    measured = restoring_n_m_per_rad is not None
    c0 = float(restoring_n_m_per_rad) if measured else float(cfg.weight_n) * (
        float(cfg.vehicle.centre_of_gravity_frd_m[2]) - float(cfg.vehicle.centre_of_buoyancy_frd_m[2]))
    out: dict = {}
    for dof in record.decays:
        i = {"roll": 0, "pitch": 1}[dof]
        incl = getattr(record, "inclining", {}).get(dof)
        c, c_std = (float(incl["value"]), float(incl["std"])) if incl else (c0, float(restoring_std))
        try:
            e = decay_inertia(record, dof, c, c_std, float(cfg.vehicle.inertia_kg_m2[i]))
        except (EstimationError, KeyError, ValueError) as exc:
            progress(f"{dof} free decay: no estimate ({exc})")
            continue
        e["stiffness_source"] = ("inclining campaign step (--calibrate inclining)" if incl else
                                 "--restoring-n-m-per-rad (inclining test)" if measured else
                                 "vehicle file m g BG (not measured: run hindrax ident inclining or --calibrate "
                                 "inclining)")
        out[dof] = e
    return out


def reference_sections(doc: dict, record, cfg, restoring_n_m_per_rad: float | None = None,
                       restoring_std: float = 0.0, progress=print) -> None:
    """identification.yaml ``inclining`` (restoring stiffness per DOF from the inclining step) and ``free_decay``
    (:func:`free_decay_section`, with the reference verdicts) of a campaign record that has them; in place."""
    if getattr(record, "inclining", None):
        doc["inclining"] = {k: {kk: ([float(x) for x in vv] if isinstance(vv, list) else vv)
                                for kk, vv in v.items()} for k, v in record.inclining.items()}
    if getattr(record, "decays", None):
        doc["free_decay"] = free_decay_section(record, cfg, restoring_n_m_per_rad, restoring_std, progress)
        apply_reference_verdicts(doc)  # free decay vs self-propelled inertia: suspect beyond 1.96 combined std
