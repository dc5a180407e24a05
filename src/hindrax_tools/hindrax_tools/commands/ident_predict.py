"""``hindrax ident predict BAG [BAG ...] --model identification.yaml --out DIR [--segment-s S]``: the identified
model's open-loop predictions on bags, as CSV anyone can score.

Per bag and DOF of the model, ``DIR/<bag>_<dof>.csv`` with ``t_s,segment,measured,predicted`` (SI, body FRD, the
frame and time origin in the first ``#`` line; :mod:`hindrax_fit.assessment.predict`). With
``--segment-s S`` the prediction restarts from the measured velocity every S seconds from the first instant with both
force and velocity; without it, the tool's own rule (its holdout validation's 10 s segments). Prints per bag and DOF the
segments, samples and nrmse, nrmse_hold, nrmse_zero of those rows (the definition in the predict module). Exit 0,
or 1 with one line on stderr for an unusable model file, bag, topic or frame."""
from __future__ import annotations

import argparse
from pathlib import Path

from hindrax_onboard.commands.common import CommandError, load_vehicle
from .ident_fit import _num

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``hindrax ident predict``."""
    parser.add_argument("bags", nargs="+", metavar="BAG", help="bag directories (or .mcap files)")
    parser.add_argument("--model", required=True, help="identification.yaml written by hindrax ident fit")
    parser.add_argument("--out", required=True, help="output directory of the CSV files")
    parser.add_argument("--segment-s", type=float, default=None, metavar="S",
                        help="re-initialise from the measured velocity every S s from the first instant with force "
                             "and velocity (default: the tool's rule, 10 s segments of each continuous stretch)")
    for signal in ("wrench", "velocity", "imu", "depth"):
        parser.add_argument(f"--{signal}-topic", default=None, help="as hindrax ident fit")
    parser.add_argument("--config", default=None, help="vehicle file (needed for a ThrusterPwm force)")


def run(args: argparse.Namespace) -> int:
    """Predict, write the CSV files, print the scores. Raises :class:`CommandError` on bad input."""
    import yaml

    from hindrax_bringup.recording.reader import BagError

    from hindrax_fit.bag_input.reader import FitInputError, TopicChoice
    from hindrax_fit.assessment.predict import ModelError, dofs_of, load_model, predict_bag, rule_text, write_csv

    if args.segment_s is not None and not 0.5 <= args.segment_s <= 3600.0:
        raise CommandError(f"ident predict: --segment-s {args.segment_s:g}: must be in [0.5, 3600] s")
    try:
        doc = yaml.safe_load(Path(args.model).read_text())
        models, inertia = load_model(doc)
    except (OSError, yaml.YAMLError, ModelError, KeyError, TypeError, ValueError) as exc:
        raise CommandError(f"ident predict: {args.model}: {exc}") from exc
    cfg = None if args.config is None else load_vehicle(args.config)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    choice = TopicChoice(args.wrench_topic, args.velocity_topic, args.imu_topic, args.depth_topic)
    rule = rule_text(args.segment_s)
    print(f"segments: {rule}; nrmse = RMS(predicted - measured) / std(measured) over the rows with a segment")
    print(f"{'bag':24} {'DOF':6} {'segments':>8} {'samples':>8} {'nrmse':>7} {'nrmse_hold':>10} {'nrmse_zero':>10}  "
          "csv")
    for b in args.bags:
        if not Path(b).exists():
            raise CommandError(f"ident predict: {b}: no such file or directory")
        try:
            preds = predict_bag(b, models, inertia, choice, cfg, args.segment_s)
        except (FitInputError, BagError, OSError) as exc:
            raise CommandError(f"ident predict: {exc}") from exc
        name = Path(b).name.removesuffix(".mcap")
        for dof in dofs_of(preds):
            p = preds[dof]
            path = write_csv(out / f"{name}_{dof}.csv", p, str(b), rule)
            s = p.scores
            print(f"{name[:24]:24} {dof:6} {s['segments']:8d} {s['samples']:8d} {_num(s['nrmse'], 7)} "
                  f"{_num(s['nrmse_hold'], 7):>10} {_num(s['nrmse_zero'], 7):>10}  {path}")
            if models[dof].verdict not in ("", "trusted", "suspect"):
                print(f"{'':24} {dof:6} verdict of the model file: {models[dof].verdict}")
    return 0
