"""``hindrax ident fit BAG [BAG ...]``: identify from any bag (piloted, closed-loop, another vehicle's) and validate.

One bag reader with two adapters feeds one fit core (:mod:`hindrax_fit.bag_input.reader`,
:mod:`hindrax_fit.assessment.pipeline`, docs/identification.md §7). A bag with the campaign's topics,
given alone with ``--config`` and no topic, DOF or holdout choice, is read as the campaign (as ``hindrax ident bag``
reads it) and written as ``hindrax ident bag`` writes it: the same values and intervals. Any other bag is read by
message type (preprocessing, K-fold and holdout validation). Writes ``identification.yaml``
(``dofs``, ``validation``, ``preprocessing``) and ``report/index.html`` (measured against predicted velocity on the
validation data) in ``--out`` (new or empty; default: a new ``<first bag>_fit_<time>`` beside it) and prints a
table. Without ``--config`` the file holds ``inertia`` (rigid + added) but no ``added_mass``: ``config_ready:
false`` with the reason, also printed (:func:`hindrax_fit.assessment.results.to_config_overrides`
refuses it). Exit 0, or 1 with one line on stderr for an unusable bag, topic, frame or too little data."""
from __future__ import annotations

import argparse
from pathlib import Path

from hindrax_onboard.commands.common import CommandError, load_vehicle
from .common import remove_if_empty

__all__ = ["add_arguments", "run", "format_table"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``hindrax ident fit``."""
    parser.add_argument("bags", nargs="+", metavar="BAG", help="bag directories (or .mcap files), fitted jointly")
    parser.add_argument("--wrench-topic", default=None,
                        help="force: geometry_msgs/WrenchStamped (base_link, FLU) or hindrax_msgs/ThrusterPwm "
                             "(needs --config); default: the one topic of such a type")
    parser.add_argument("--velocity-topic", default=None,
                        help="velocity: nav_msgs/Odometry, TwistWithCovarianceStamped, TwistStamped or "
                             "hindrax_msgs/Dvl")
    parser.add_argument("--imu-topic", default=None, help="angular rate from sensor_msgs/Imu (default: the velocity "
                        "topic's, else an IMU found with a Dvl, else the differentiated attitude)")
    parser.add_argument("--depth-topic", default=None, help="heave velocity from the derivative of a depth: "
                        "sensor_msgs/FluidPressure, Odometry or PoseStamped pose")
    parser.add_argument("--dofs", default=None, help="comma-separated DOFs (default: all six)")
    parser.add_argument("--holdout", nargs="+", default=[], metavar="BAG", help="bags used for validation only")
    parser.add_argument("--folds", type=int, default=4, help="K of the cross-validation (default 4)")
    parser.add_argument("--persistence-margin", type=float, default=None, metavar="FRACTION",
                        help="relative margin by which a DOF's model must beat holding the "
                             "velocity in cross-validation, else its verdict is 'no model beats "
                             "holding the velocity' (default 0.05; docs/identification.md §7)")
    parser.add_argument("--max-delay-s", type=float, default=1.0,
                        help="largest input delay + lag searched for a commanded wrench, s (default 1.0)")
    parser.add_argument("--config", default=None,
                        help="vehicle file (optional: without it nothing about the vehicle is assumed; needed for "
                             "ThrusterPwm forces and for added_mass = inertia - rigid-body inertia)")
    parser.add_argument("--out", default=None,
                        help="output directory, new or empty (default: a new <first bag>_fit_<time> beside it)")


def _num(x, width: int, fmt: str = ".3f") -> str:
    """``x`` right-aligned in ``width``; a missing or non-finite number is ``-`` (never ``nan`` in a table)."""
    import math

    return f"{'-':>{width}}" if x is None or not math.isfinite(float(x)) else f"{float(x):{width}{fmt}}"


def format_table(res, cfg=None) -> str:
    """Parameters (value +- std, which covariance set the fit's std, 95 % interval, fold spread), the chosen model and
    timing per DOF, and the validation, one row each. Value, std and interval are identification.yaml's: the one
    verdict path (:func:`~..identification.assessment.results.assessment`: with ``cfg`` after the priors, with the
    thrust-curve uncertainty)."""
    import numpy as np

    from hindrax_fit.assessment.results import assessment, training_lines
    from hindrax_fit.assessment.verdicts import no_model_line

    lines = [f"{'DOF':6} {'parameter':28} {'value':>10} {'std':>9} {'std from':>14} {'95 % interval':>23} "
             f"{'fold spread':>11}"]
    for dof, r in res.dofs.items():
        if r.status != "fitted":
            lines.append(f"{dof:6} {r.status}: {r.reason}")
            continue
        c = r.core
        folds = np.array(r.folds) if len(r.folds) >= 2 else None
        par = assessment(r, cfg)["parameters"]
        sm = np.sqrt(np.maximum(np.diag(c.covariance.model), 0.0))
        ss = np.sqrt(np.maximum(np.diag(c.covariance.sandwich), 0.0))
        for i, n in enumerate(c.names):
            sp = f"{np.std(folds[:, i], ddof=1):11.4g}" if folds is not None else f"{'-':>11}"
            src = "cluster_robust" if ss[i] >= sm[i] else "model"
            e = par[n]
            ci = (f"[{e['ci95'][0]:10.4g}, {e['ci95'][1]:10.4g}]" if "at_bound" not in e else
                  f"{'at bound ' + format(e['at_bound'], 'g') + ': none':>24}")
            lines.append(f"{dof:6} {n:28} {e['value']:10.4g} {e['std']:9.3g} {src:>14} {ci} {sp}")
        lines.append(f"{dof:6} model: {c.terms.label}; delay {c.timing.delay_s:.3f} s, lag {c.timing.lag_s:.3f} s "
                     f"({c.timing.source}); t with {c.covariance.t_dof} degrees of freedom "
                     f"({c.covariance.clusters} clusters)")
        if c.timing.at_edge:
            lines.append(f"{dof:6} timing: {c.timing.edge_note}")
        lines += [f"{dof:6} {line}" for line in training_lines(c.training)]
        if not c.beats_persistence:
            lines.append(no_model_line(dof, c.persistence))
    lines.append("")
    lines.append(f"validation ({res.design})")
    lines.append(f"{'DOF':6} {'data':17} {'nrmse':>7} {'nrmse_hold':>10} {'nrmse_zero':>10} {'samples':>8} "
                 f"{'noise floor':>11}")
    for dof, r in res.dofs.items():
        for key, v in r.validation.items():
            if not isinstance(v, dict) or "nrmse" not in v:
                continue
            lines.append(f"{dof:6} {key:17} {_num(v['nrmse'], 7)} {_num(v.get('nrmse_hold'), 10)} "
                         f"{_num(v.get('nrmse_zero'), 10)} {v['samples']:8d} {_num(v.get('nrmse_floor'), 11)}")
    lines.append("(-: not computable from these samples, e.g. the noise floor of a measured position)")
    return "\n".join(lines)


def _run_campaign(args: argparse.Namespace, cfg, out: Path) -> int:
    """A campaign bag: the campaign reader, the fit core with this command's folds, the outputs of ``hindrax ident bag``
    (:func:`~.ident_bag.identify_campaign_bag`) into ``out`` and this command's table of the core's results."""
    from hindrax_fit.assessment.pipeline import campaign_result, core_options
    from .ident_bag import identify_campaign_bag

    bag = Path(args.bags[0])
    opts = core_options(args.folds)
    _record, idents, path = identify_campaign_bag(bag, out, cfg, args, "ident fit", opts)
    res = campaign_result(idents, args.folds, opts)
    print(f"{bag}: the campaign's topics: read as hindrax ident bag reads them (DOF windows from "
          "identification/status, thrust model of the ESC widths, the vehicle's sensors)")
    print(format_table(res, cfg))
    print(f"output: {path} and {out / 'report' / 'index.html'}")
    return 0


def _campaign_hint(args: argparse.Namespace, cfg) -> str:
    """'; it is a campaign bag: ...' when the first bag, not read as the campaign (no --config, several bags, a
    holdout, DOFs or topics chosen), has the campaign's topics, else ''."""
    from hindrax_fit.bag_input.reader import is_campaign_bag

    try:
        if not is_campaign_bag(args.bags[0]):
            return ""
    except Exception:  # noqa: BLE001 - the hint is optional; the error itself was already said
        return ""
    why = ("give --config VEHICLE.yaml to read it as the campaign" if cfg is None else "give it alone, with --config "
           "and without --holdout, --dofs or --*-topic, to read it as the campaign (as hindrax ident bag does)")
    return f"; {args.bags[0]} is a campaign bag: {why}"


def run(args: argparse.Namespace) -> int:
    """Fit, write the outputs, print the table. Raises :class:`CommandError` on bad input (an
    output folder that cannot be used: before anything is fitted)."""
    from hindrax_bringup.recording.reader import BagError

    from hindrax_fit.bag_input.reader import FitOptions, TopicChoice, reads_as_campaign
    from .ident_bag import result_dir_for_bag

    cfg = None if args.config is None else load_vehicle(args.config)
    for b in list(args.bags) + list(args.holdout):
        if not Path(b).exists():
            raise CommandError(f"ident fit: {b}: no such file or directory")
    if args.folds < 2:
        raise CommandError(f"ident fit: --folds {args.folds}: must be >= 2")
    margin = FitOptions().persistence_margin if args.persistence_margin is None else float(args.persistence_margin)
    if not 0.0 <= margin < 1.0:
        raise CommandError(f"ident fit: --persistence-margin {margin:g}: must be in [0, 1)")
    if not 0.0 < args.max_delay_s <= 5.0:
        raise CommandError(f"ident fit: --max-delay-s {args.max_delay_s:g}: must be in (0, 5]")
    dofs = [d.strip() for d in args.dofs.split(",") if d.strip()] if args.dofs else None
    choice = TopicChoice(args.wrench_topic, args.velocity_topic, args.imu_topic, args.depth_topic)
    try:
        campaign = reads_as_campaign(args.bags, choice, cfg, dofs, args.holdout)
    except (BagError, OSError) as exc:
        raise CommandError(f"ident fit: {exc}") from exc
    out = result_dir_for_bag(Path(args.bags[0]), args.out, "fit")
    try:
        if campaign:
            return _run_campaign(args, cfg, out)
        opts = FitOptions(folds=args.folds, persistence_margin=margin, max_delay_s=args.max_delay_s)
        return _run_any(args, cfg, out, choice, dofs, opts)
    except BaseException:  # a failed or interrupted fit leaves no empty result folder
        remove_if_empty(out)
        raise


def _run_any(args: argparse.Namespace, cfg, out: Path, choice, dofs, options) -> int:
    """Bags of any topics: fit (:func:`~...identification.assessment.pipeline.fit_bags`), write into ``out``, print."""
    from hindrax_bringup.recording.reader import BagError

    from hindrax_fit.assessment.pipeline import fit_bags, write_any_outputs
    from hindrax_fit.assessment.verdicts import format_advice
    from hindrax_fit.bag_input.reader import FitInputError

    try:
        res = fit_bags(args.bags, choice, cfg, dofs, args.holdout, options)
    except (FitInputError, BagError, OSError) as exc:
        raise CommandError(f"ident fit: {exc}{_campaign_hint(args, cfg)}") from exc
    if not any(r.status == "fitted" for r in res.dofs.values()):
        print(format_table(res, cfg))
        raise CommandError("ident fit: no DOF could be identified (see the table: not excited or failed)")
    doc, path, index = write_any_outputs(out, res, cfg, args.bags, args.holdout)
    print(format_table(res, cfg))
    for dof, e in doc["dofs"].items():
        if e.get("verdict") != "trusted":
            print(f"{dof}: suspect ({'; '.join(e['reasons'])})")
            for a in e.get("advice", []):
                print(format_advice(a["parameter"], a))
    d = res.preprocessing
    print(f"preprocessing: {d['resampling']}; "
          + "; ".join(f"{Path(b['bag']).name}: {b['gaps']['dropped_s']:g} s in gaps dropped, "
                      f"{b['velocity_repeated_values_dropped']} repeated velocities dropped" for b in d["bags"]))
    if not doc["config_ready"]:
        print(f"config_ready: false: {doc['config_ready_reason']}")
    print(f"output: {path} and {index}")
    return 0
