"""``hindrax ident free-decay | thruster-fit | priors | inclining | tilt-decay | campaign``: offline identification
tools (the references of priors, inclining and tilt-decay do not depend on the thrust curve).

* ``hindrax ident free-decay FILE --stiffness K --mass M --volume V [--density RHO] [--model linear|quadratic]``:
  [Hindrax-AM] analysis of a free-decay record (CSV with a header row; column 1 time in s, column 2 acceleration in
  m/s^2). Prints one JSON object (:meth:`hindrax_onboard.estimation.free_decay.FreeDecayResult.to_dict`): omega_d_rad_s,
  zeta, added_mass_kg (eq. 5), added_mass_simplified_kg (eq. 7), damping_n_s_per_m (eq. 6), c_m (eq. 8), kc (eq. 9)...
  ``--model quadratic`` adds the output-error fit of the nonlinear ODE (linear + quadratic damping, [SmallROV] eq. 12;
  :func:`hindrax_onboard.estimation.free_decay.quadratic_free_decay_keys`).
* ``hindrax ident thruster-fit FILE [--write CONFIG]``: [Hindrax-Drag] eq. 1 cubic per rotation direction from
  bollard-pull data (CSV with a header; column 1 pulse width in us, column 2 thrust in N). Prints
  ``{"negative": {c4..c1, c4_std..c1_std, thrust_relative_std, ...}, "positive": {...},
  "thrust_fit_uncertainty_rel": [negative, positive]}``; ``--write`` stores the curves and the fit's relative thrust
  std in a vehicle file (:func:`~hindrax_onboard.commands.common.update_vehicle_file`), which the identification
  intervals then use instead of the declared ``thrust_uncertainty_rel``.
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
* ``hindrax ident campaign``: the identification campaign on the simulator, same as ``hindrax run``
  (:mod:`hindrax_tools.commands.run`).

Exit status 0 on success, 1 on bad input (one-line message on stderr)."""
from __future__ import annotations

import argparse
import csv
import json
import math
import sys

import numpy as np

from hindrax_common.config import ConfigError

from hindrax_onboard.commands.common import CommandError, load_vehicle, update_vehicle_file

__all__ = ["add_arguments", "run", "read_two_columns"]

_GEOMETRY = (("length_m", "length (x), m"), ("width_m", "width (y), m"), ("height_m", "height (z), m"),
             ("density_kg_m3", "fluid density, kg/m^3"), ("frontal_area_m2", "projected area normal to x, m^2"),
             ("side_area_m2", "projected area normal to y, m^2"), ("top_area_m2", "projected area normal to z, m^2"))


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of the subcommand named by ``parser.prog`` (…free-decay, …thruster-fit, …priors, …inclining,
    …tilt-decay, …campaign)."""
    which = parser.prog.split()[-1]
    parser.set_defaults(_ident=which)
    if which == "free-decay":
        parser.add_argument("file", help="CSV with a header: time (s), acceleration (m/s^2)")
        parser.add_argument("--stiffness", type=float, required=True, help="equivalent spring stiffness k_eq, N/m")
        parser.add_argument("--mass", type=float, required=True, help="body mass m_b, kg")
        parser.add_argument("--volume", type=float, required=True, help="displaced volume V, m^3")
        parser.add_argument("--density", type=float, default=1000.0, help="water density, kg/m^3 (default 1000)")
        parser.add_argument("--model", choices=("linear", "quadratic"), default="linear",
                            help="linear: log decrement and period only (default); quadratic: also fit the nonlinear "
                                 "ODE with linear + quadratic damping to the whole record ([SmallROV] eq. 12), adding "
                                 "linear_damping_n_s_per_m, quadratic_damping_n_s2_per_m2 and their _std")
    elif which == "thruster-fit":
        parser.add_argument("file", help="CSV with a header: pulse width (us), thrust (N)")
        parser.add_argument("--write", metavar="CONFIG", default=None,
                            help="update thrusters.curve_negative/curve_positive and thrust_fit_uncertainty_rel "
                                 "(the fit's relative thrust std per direction, used by the identification "
                                 "intervals) in this configuration file")
        parser.add_argument("--neutral", type=float, default=1500.0, help="neutral pulse width, us")
    elif which == "priors":
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
    elif which == "tilt-decay":
        parser.add_argument("file", help="CSV with a header: time (s), gyro rate (rad/s) or angle (rad)")
        parser.add_argument("--stiffness", type=float, required=True,
                            help="restoring stiffness C, N m/rad (from `hindrax ident inclining`)")
        parser.add_argument("--stiffness-std", type=float, default=0.0,
                            help="1-sigma of C (the inclining result's std), propagated: std(I)/I = std(C)/C")
        parser.add_argument("--rigid-inertia", type=float, default=None, help="rigid-body inertia, kg m^2")
        parser.add_argument("--signal", choices=("rate", "angle"), default="rate", help="what column 2 holds")
        parser.add_argument("--identification", default=None, help="identification.yaml to compare with")
        parser.add_argument("--dof", choices=("roll", "pitch"), default="roll", help="DOF of the record")
    else:
        from . import run as run_cmd
        run_cmd.add_arguments(parser)


def read_two_columns(path: str) -> tuple[np.ndarray, np.ndarray]:
    """First two numeric columns of a CSV with one header row. Raises ``ValueError`` (one-line message)."""
    try:
        with open(path, newline="") as fh:
            rows = list(csv.reader(fh))
    except OSError as exc:
        raise ValueError(f"{path}: cannot read ({exc.strerror})") from exc
    if len(rows) < 2:
        raise ValueError(f"{path}: need a header row and data rows")
    a, b = [], []
    for n, row in enumerate(rows[1:], start=2):
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) < 2:
            raise ValueError(f"{path}:{n}: need two columns, got {row!r}")
        try:
            a.append(float(row[0]))
            b.append(float(row[1]))
        except ValueError:
            raise ValueError(f"{path}:{n}: not numbers: {row[:2]!r}") from None
    x, y = np.asarray(a), np.asarray(b)
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise ValueError(f"{path}: NaN or infinite values")
    return x, y


def _free_decay(args) -> int:
    from hindrax_onboard.estimation.free_decay import analyse_free_decay, quadratic_free_decay_keys
    from hindrax_onboard.estimation.least_squares import EstimationError
    try:
        t, a = read_two_columns(args.file)
        res = analyse_free_decay(t, a, args.stiffness, args.mass, args.volume, fluid_density_kg_m3=args.density)
        out = res.to_dict()
        if getattr(args, "model", "linear") == "quadratic":
            out.update(quadratic_free_decay_keys(res, t, a))
    except (ValueError, EstimationError) as exc:
        raise CommandError(f"free-decay: {exc}") from exc
    print(json.dumps(out))
    return 0


def _thruster_fit(args) -> int:
    from hindrax_onboard.estimation.least_squares import EstimationError
    from hindrax_onboard.estimation.thruster_fit import fit_thruster_curve
    try:
        pw, thrust = read_two_columns(args.file)
        fit = fit_thruster_curve(pw, thrust, neutral_us=args.neutral)
    except (ValueError, EstimationError) as exc:
        raise CommandError(f"thruster-fit: {exc}") from exc
    out = fit.to_dict()
    rel = fit.relative_std()
    print(json.dumps({"negative": out["negative"], "positive": out["positive"],
                      "thrust_fit_uncertainty_rel": list(rel)}))
    if args.write:
        try:
            # comments kept; thrust_fit_uncertainty_rel added after curve_positive when absent
            update_vehicle_file(args.write, {
                "thrusters.curve_negative": [float(c) for c in fit.negative.coefficients],
                "thrusters.curve_positive": [float(c) for c in fit.positive.coefficients],
                "thrusters.thrust_fit_uncertainty_rel": [float(s) for s in rel]},
                new_keys={"thrusters.thrust_fit_uncertainty_rel": (
                    "curve_positive", "1-sigma relative thrust std [negative, positive] of the "
                                      "bollard-pull fit (hindrax ident thruster-fit)")})
        except ConfigError as exc:
            raise CommandError(f"thruster-fit: {args.write} would be invalid, left unchanged: "
                               f"{'; '.join(exc.lines())}") from exc
        except (OSError, ValueError) as exc:
            raise CommandError(f"thruster-fit: {exc}") from exc
        print(f"updated {args.write}", file=sys.stderr)
    return 0


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
                raise CommandError("priors: give --config FILE or all of the geometry; missing " + " ".join(missing))
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
    """Add ``self_propelled`` {inertia_kg_m2, inertia_kg_m2_std, z, verdict, rule[, reason]} to the free-decay result
    ``out`` (in place) by the campaign's verdict rule itself
    (:func:`~hindrax_fit.assessment.verdicts.apply_reference_verdicts` on a one-DOF document: suspect beyond
    ``REFERENCE_Z_MAX`` combined std). Raises ``ValueError`` when ``path`` has no ``dofs.<dof>``."""
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
    from . import run as run_cmd

    commands = {"free-decay": _free_decay, "thruster-fit": _thruster_fit, "priors": _priors, "inclining": _inclining,
                "tilt-decay": _tilt_decay}
    return commands.get(getattr(args, "_ident", ""), run_cmd.run)(args)
