"""``hindrax ident priors | inclining | tilt-decay``: references that do not depend on the thrust curve.

* ``hindrax ident priors (--config FILE | --length-m L --width-m W --height-m H --density-kg-m3 RHO
  --frontal-area-m2 AF --side-area-m2 AS --top-area-m2 AT) [--mass-kg M --bg-m BG | --restoring-n-m-per-rad C]
  [--roll-inertia-kg-m2 I44 --pitch-inertia-kg-m2 I55]``: empirical added mass and damping from geometry
  ([NTNU-Thesis] Sec. 3.1, App. A.1/A.2; :mod:`hindrax_onboard.estimation.priors`). Prints one JSON object
  with 6-element lists ``added_mass``, ``linear_damping``, ``quadratic_damping`` (SI, surge..yaw; null where an
  input is missing), ``units``, ``inputs`` and ``notes``. Frontal area: normal to x; side: normal to y; top: normal
  to z. With ``--config`` the box, density, mass, inertias and BG come from the vehicle file, the areas from the
  options (default: the bounding rectangles, i.e. a solid prism).
* ``hindrax ident inclining FILE --test-mass-kg M [--test-volume-m3 V] [--degrees] [--vehicle-mass-kg MV]``:
  restoring stiffness from an inclining test (CSV with a header; column 1 the signed arm of the test mass in m,
  column 2 the IMU-measured tilt, rad or with ``--degrees`` deg). Prints
  :meth:`~hindrax_onboard.estimation.free_decay.IncliningResult.to_dict` (restoring_n_m_per_rad, its std, bg_m...).
* ``hindrax ident tilt-decay FILE --stiffness C [--stiffness-std S] [--rigid-inertia I] [--signal rate|angle]
  [--identification YAML --dof roll|pitch]``: roll or pitch free decay (CSV with a header; column 1
  time s, column 2 the gyro rate in rad/s or the attitude angle in rad), fitted from its largest
  excursion on with I x'' + b1 x' + b2 |x'| x' + C x = 0 (docs/identification.md §6.4:
  [Hindrax-AM] eq. 4 applied to the vehicle, [SmallROV] eq. 12); ``total_inertia_kg_m2_std``
  combines the fit's std (``_std_fit``) with C's. With ``--identification`` the self-propelled
  inertia of that DOF is compared by the campaign's rule (:func:`_compare_with_self_propelled`).

Exit status 0 on success, 1 on bad input (one-line message on stderr).
"""
from __future__ import annotations

import argparse
import json
import math

import numpy as np

from hindrax_onboard.commands.common import CommandError, load_vehicle

__all__ = ["add_arguments", "run"]

_GEOMETRY = (("length_m", "length (x), m"), ("width_m", "width (y), m"), ("height_m", "height (z), m"),
             ("density_kg_m3", "fluid density, kg/m^3"),
             ("frontal_area_m2", "projected area normal to x, m^2"),
             ("side_area_m2", "projected area normal to y, m^2"),
             ("top_area_m2", "projected area normal to z, m^2"))


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of the subcommand named by ``parser.prog`` (…priors, …inclining, …tilt-decay)."""
    which = parser.prog.split()[-1]
    parser.set_defaults(_ident_ref=which)
    if which == "priors":
        parser.add_argument("--config", default=None, help="vehicle file (box, density, mass, inertia, CG/CB)")
        for name, text in _GEOMETRY:
            parser.add_argument("--" + name.replace("_", "-"), dest=name, type=float, default=None, help=text)
        parser.add_argument("--mass-kg", type=float, default=None, help="vehicle mass (roll/pitch linear damping)")
        parser.add_argument("--bg-m", type=float, default=None, help="CB above CG, m (restoring C = m g BG)")
        parser.add_argument("--restoring-n-m-per-rad", type=float, default=None, help="restoring C, N m/rad")
        parser.add_argument("--roll-inertia-kg-m2", type=float, default=None, help="rigid I44 (default: prism)")
        parser.add_argument("--pitch-inertia-kg-m2", type=float, default=None, help="rigid I55 (default: prism)")
    elif which == "inclining":
        parser.add_argument("file", help="CSV with a header: arm of the test mass (m), tilt (rad)")
        parser.add_argument("--test-mass-kg", type=float, required=True, help="known test mass, kg")
        parser.add_argument("--test-volume-m3", type=float, default=0.0, help="its displaced volume, m^3")
        parser.add_argument("--density", type=float, default=1000.0, help="water density, kg/m^3")
        parser.add_argument("--gravity", type=float, default=9.81, help="m/s^2")
        parser.add_argument("--vehicle-mass-kg", type=float, default=None, help="for BG = C / (m g)")
        parser.add_argument("--degrees", action="store_true", help="the tilt column is in degrees")
    else:
        parser.add_argument("file", help="CSV with a header: time (s), gyro rate (rad/s) or angle (rad)")
        parser.add_argument("--stiffness", type=float, required=True,
                            help="restoring stiffness C, N m/rad (from `hindrax ident inclining`)")
        parser.add_argument("--stiffness-std", type=float, default=0.0,
                            help="1-sigma of C (the inclining result's std), propagated: std(I)/I = std(C)/C")
        parser.add_argument("--rigid-inertia", type=float, default=None, help="rigid-body inertia, kg m^2")
        parser.add_argument("--signal", choices=("rate", "angle"), default="rate", help="what column 2 holds")
        parser.add_argument("--identification", default=None, help="identification.yaml to compare with")
        parser.add_argument("--dof", choices=("roll", "pitch"), default="roll", help="DOF of the record")


def _priors(args) -> int:
    from hindrax_onboard.estimation.least_squares import EstimationError
    from hindrax_onboard.estimation.priors import Geometry, PriorInputs, empirical_priors, priors_from_config

    try:
        if args.config:
            out = priors_from_config(load_vehicle(args.config), args.frontal_area_m2, args.side_area_m2,
                                     args.top_area_m2)
        else:
            missing = ["--" + n.replace("_", "-") for n, _ in _GEOMETRY if getattr(args, n) is None]
            if missing:
                raise CommandError("priors: give --config FILE or all of the geometry; missing "
                                   + " ".join(missing))
            g = Geometry(args.length_m, args.width_m, args.height_m, args.density_kg_m3, args.frontal_area_m2,
                         args.side_area_m2, args.top_area_m2)
            out = empirical_priors(g, PriorInputs(mass_kg=args.mass_kg, bg_m=args.bg_m,
                                                  roll_inertia_kg_m2=args.roll_inertia_kg_m2,
                                                  pitch_inertia_kg_m2=args.pitch_inertia_kg_m2,
                                                  restoring_n_m_per_rad=args.restoring_n_m_per_rad))
    except EstimationError as exc:
        raise CommandError(f"priors: {exc}") from exc
    print(json.dumps(out))
    return 0


def _inclining(args) -> int:
    from hindrax_onboard.estimation.free_decay import restoring_from_inclining
    from hindrax_onboard.estimation.least_squares import EstimationError
    from .ident import read_two_columns

    try:
        arm, tilt = read_two_columns(args.file)
        if args.degrees:
            tilt = np.radians(tilt)
        res = restoring_from_inclining(arm, tilt, args.test_mass_kg, args.test_volume_m3, args.density,
                                       args.gravity, args.vehicle_mass_kg)
    except (ValueError, EstimationError) as exc:
        raise CommandError(f"inclining: {exc}") from exc
    print(json.dumps(res.to_dict()))
    return 0


def _compare_with_self_propelled(out: dict, path: str, dof: str) -> None:
    """Add ``self_propelled`` {inertia_kg_m2, inertia_kg_m2_std, z, verdict, rule[, reason]} to the
    free-decay result ``out`` (in place) by the campaign's verdict rule itself
    (:func:`~hindrax_fit.assessment.verdicts.apply_reference_verdicts` on a one-DOF
    document: suspect beyond ``REFERENCE_Z_MAX`` combined std). Raises ``ValueError`` when ``path``
    has no ``dofs.<dof>``."""
    from hindrax_fit.assessment.results import read_identification
    from hindrax_fit.assessment.verdicts import REFERENCE_Z_MAX, apply_reference_verdicts

    entry = read_identification(path)["dofs"].get(dof)
    if entry is None:
        raise ValueError(f"{path}: no dofs.{dof}")
    v, s = float(entry["inertia"]["value"]), float(entry["inertia"]["std"])
    doc = apply_reference_verdicts({"dofs": {dof: {"inertia": {"value": v, "std": s}}}, "free_decay": {dof: out}})
    sp = doc["free_decay"][dof]["self_propelled"]
    sp["rule"] = f"suspect when |free decay - self-propelled| > {REFERENCE_Z_MAX:g} combined std"
    reasons = doc["dofs"][dof]["inertia"].get("reasons")
    if reasons:
        sp["reason"] = reasons[0]


def _tilt_decay(args) -> int:
    from hindrax_onboard.estimation.free_decay import find_release_index, fit_quadratic_free_decay
    from hindrax_onboard.estimation.least_squares import EstimationError
    from .ident import read_two_columns

    try:
        t, y = read_two_columns(args.file)
        i0 = find_release_index(y, 0.999) if y.size > 16 else 0   # start at the largest excursion
        fit = fit_quadratic_free_decay(t[i0:], y[i0:], args.stiffness, rigid_inertia=args.rigid_inertia,
                                       output="velocity" if args.signal == "rate" else "displacement")
        if not (math.isfinite(args.stiffness_std) and args.stiffness_std >= 0):
            raise ValueError(f"--stiffness-std must be >= 0, got {args.stiffness_std}")
        # I = C / omega_n^2: a relative error of C is the same relative error of I (and of the added inertia)
        std_c = fit.total_inertia * args.stiffness_std / args.stiffness
        std = math.hypot(fit.total_inertia_std, std_c)
        out = {
            "dof": args.dof,
            "total_inertia_kg_m2": fit.total_inertia, "total_inertia_kg_m2_std": std,
            "total_inertia_kg_m2_std_fit": fit.total_inertia_std,
            "added_inertia_kg_m2": None if math.isnan(fit.added_inertia) else fit.added_inertia,
            "added_inertia_kg_m2_std": std,
            "linear_damping_kg_m2_s": fit.linear_damping, "linear_damping_kg_m2_s_std": fit.linear_damping_std,
            "quadratic_damping_kg_m2": fit.quadratic_damping,
            "quadratic_damping_kg_m2_std": fit.quadratic_damping_std,
            "natural_frequency_rad_s": math.sqrt(args.stiffness / fit.total_inertia),
            "stiffness_n_m_per_rad": fit.stiffness, "rms_residual": fit.rms_residual,
            "n_samples": fit.n_samples, "start_time_s": fit.t0_s,
        }
        if args.identification:
            _compare_with_self_propelled(out, args.identification, args.dof)
    except (ValueError, EstimationError) as exc:
        raise CommandError(f"tilt-decay: {exc}") from exc
    print(json.dumps(out))
    return 0


def run(args: argparse.Namespace) -> int:
    """Dispatch on the subcommand."""
    return {"priors": _priors, "inclining": _inclining}.get(args._ident_ref, _tilt_decay)(args)
