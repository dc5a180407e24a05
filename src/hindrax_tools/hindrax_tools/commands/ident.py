"""``hindrax ident free-decay | thruster-fit | campaign``: offline identification tools.

* ``hindrax ident free-decay FILE --stiffness K --mass M --volume V [--density RHO] [--model linear|quadratic]``:
  [Hindrax-AM] analysis of a free-decay record (CSV with a header row; column 1 time in s, column 2
  acceleration in m/s^2). Prints one JSON object
  (:meth:`hindrax_onboard.estimation.free_decay.FreeDecayResult.to_dict`): omega_d_rad_s, zeta,
  added_mass_kg (eq. 5), added_mass_simplified_kg (eq. 7), damping_n_s_per_m (eq. 6), c_m (eq. 8),
  kc (eq. 9)... ``--model quadratic`` adds the output-error fit of the nonlinear ODE (linear +
  quadratic damping, [SmallROV] eq. 12;
  :func:`hindrax_onboard.estimation.free_decay.quadratic_free_decay_keys`).
* ``hindrax ident thruster-fit FILE [--write CONFIG]``: [Hindrax-Drag] eq. 1 cubic per rotation direction from
  bollard-pull data (CSV with a header; column 1 pulse width in us, column 2 thrust in N). Prints
  ``{"negative": {c4..c1, c4_std..c1_std, thrust_relative_std, ...}, "positive": {...},
  "thrust_fit_uncertainty_rel": [negative, positive]}``; ``--write`` stores the curves and the fit's
  relative thrust std in a vehicle file (:func:`write_thruster_curves`), which the identification
  intervals then use instead of the declared ``thrust_uncertainty_rel``.
* ``hindrax ident campaign``: the identification campaign on the simulator, same as ``hindrax run``
  (:mod:`hindrax_tools.commands.run`).

Exit status 0 on success, 1 on bad input (one-line message on stderr).
"""
from __future__ import annotations

import argparse
import csv
import json
import sys

import numpy as np

from hindrax_common.config import ConfigError

from .common import CommandError, update_vehicle_file

__all__ = ["add_arguments", "run", "read_two_columns"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of the subcommand named by ``parser.prog`` (…free-decay, …thruster-fit, …campaign)."""
    which = parser.prog.split()[-1]
    parser.set_defaults(_ident=which)
    if which == "free-decay":
        parser.add_argument("file", help="CSV with a header: time (s), acceleration (m/s^2)")
        parser.add_argument("--stiffness", type=float, required=True, help="equivalent spring stiffness k_eq, N/m")
        parser.add_argument("--mass", type=float, required=True, help="body mass m_b, kg")
        parser.add_argument("--volume", type=float, required=True, help="displaced volume V, m^3")
        parser.add_argument("--density", type=float, default=1000.0, help="water density, kg/m^3 (default 1000)")
        parser.add_argument("--model", choices=("linear", "quadratic"), default="linear",
                            help="linear: log decrement and period only (default); quadratic: also fit the "
                                 "nonlinear ODE with linear + quadratic damping to the whole record "
                                 "([SmallROV] eq. 12), adding linear_damping_n_s_per_m, "
                                 "quadratic_damping_n_s2_per_m2 and their _std")
    elif which == "thruster-fit":
        parser.add_argument("file", help="CSV with a header: pulse width (us), thrust (N)")
        parser.add_argument("--write", metavar="CONFIG", default=None,
                            help="update thrusters.curve_negative/curve_positive and thrust_fit_uncertainty_rel "
                                 "(the fit's relative thrust std per direction, used by the identification "
                                 "intervals) in this configuration file")
        parser.add_argument("--neutral", type=float, default=1500.0, help="neutral pulse width, us")
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


def run(args: argparse.Namespace) -> int:
    """Dispatch on the subcommand."""
    from . import run as run_cmd

    which = getattr(args, "_ident", "")
    return {"free-decay": _free_decay, "thruster-fit": _thruster_fit}.get(which, run_cmd.run)(args)
