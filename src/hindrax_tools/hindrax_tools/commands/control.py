"""``hindrax control evaluate | scenarios | model``: the identified model in closed loop (docs/control.md).

* ``hindrax control evaluate --truth FILE --model YAML [--out DIR] [--maneuvers ...] [--models ...] [--seed N]
  [--seeds N]``: closed-loop runs in the in-process virtual pool on the truth FILE
  (:mod:`hindrax_sim.control_evaluate`): a 0.3 m depth step, an altitude hold at 0.5 m over a sloped floor and a 30
  degree heading step, each with the model of YAML, the vehicle file's model and the former PD hold. Prints the table
  (RMSE, overshoot, settling time, RMS thrust) and the ratios, writes ``control.json`` and ``report/index.html`` in
  DIR (default ``<recording.output_root>/control-<UTC time>``); with ``--seeds N`` the mean over N noise seeds. A
  model file that cannot be used is reported in one line and the command exits 1.
* ``hindrax control scenarios [--scenarios NAMES] [--seed N] [--levels N] [--out DIR]``: for each
  truth of the scenario suite, an in-process identification campaign against that truth, then the
  depth step and the altitude hold with the identified model, the vehicle file's and the PD hold:
  ``control_scenarios.json`` and ``control_scenarios.md`` (the RMSE ratios per scenario).
* ``hindrax control model [--model YAML]``: the gains of each hold, their bandwidth and the source of every model
  value (identified, or the vehicle file and why).

Exit status 0, or 1 on bad input (one line on stderr)."""
from __future__ import annotations

import argparse
import datetime as _dt
import math
from pathlib import Path

from .. import results_doc
from hindrax_onboard.commands.common import CommandError, add_config_argument, choices, load_vehicle
from .common import WallProgress

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of the subcommand named by ``parser.prog``."""
    which = parser.prog.split()[-1]
    parser.set_defaults(_control=which)
    add_config_argument(parser)
    if which == "model":
        parser.add_argument("--model", default=None, metavar="YAML",
                            help="identification.yaml (default: the vehicle file's model)")
        return
    parser.add_argument("--seed", type=int, default=1, help="simulation seed (default 1)")
    if which == "evaluate":
        parser.add_argument("--seeds", type=int, default=1,
                            help="run every case with the noise seeds seed .. seed+N-1 and report the mean (default 1)")
    parser.add_argument("--out", default=None, metavar="DIR", help="output directory")
    results_doc.add_argument(parser)
    if which == "evaluate":
        parser.add_argument("--truth", required=True, metavar="FILE",
                            help="truth file of the virtual pool (overlay of the vehicle file + disturbances)")
        parser.add_argument("--model", required=True, metavar="YAML",
                            help="identification.yaml identified against that truth (hindrax ident campaign --truth)")
        parser.add_argument("--maneuvers", default="depth_step,altitude_hold,heading_step,altitude_gentle",
                            help="comma-separated manoeuvres (default all four: depth_step, altitude_hold, "
                                 "heading_step and the former gentle altitude case altitude_gentle)")
        parser.add_argument("--no-sensor-noise", action="store_true",
                            help="diagnostic: the simulated sensors without white noise, dropouts, DVL scale error "
                                 "and beam-range noise, to separate the model's error from the noise")
        parser.add_argument("--models", default="identified,vehicle_file,pd_hold",
                            help="comma-separated holds (default identified,vehicle_file,pd_hold)")
    else:
        parser.add_argument("--scenarios", default=None,
                            help="comma-separated scenario names "
                                 "(default: every truth in ros_ws/config/truth/scenarios)")
        parser.add_argument("--levels", type=int, default=3, help="levels per DOF of each identification (default 3)")
        parser.add_argument("--truth-dir", default=None, metavar="DIR",
                            help="folder of the scenario truth files (default ros_ws/config/truth/scenarios)")


def _out_dir(cfg, out: str | None, prefix: str) -> Path:
    if out:
        return Path(out)
    stamp = _dt.datetime.now(_dt.timezone.utc).strftime("%Y%m%dT%H%M%SZ")
    return Path(str(cfg.recording.output_root)) / f"{prefix}-{stamp}"


def run(args: argparse.Namespace) -> int:
    """Dispatch on the subcommand."""
    cfg = load_vehicle(args.config)
    return {"model": _model, "evaluate": _evaluate}.get(args._control, _scenarios)(args, cfg)


def _load_model(path, cfg):
    from hindrax_onboard.control.model import ModelFileError, load_model, model_from_config

    try:
        model = model_from_config(cfg) if path is None else load_model(path, cfg)
    except ModelFileError as exc:  # an error, never the vehicle file in its place
        raise CommandError(f"--model {exc}") from exc
    for note in model.notes:
        print(note, flush=True)
    return model


def _model(args, cfg) -> int:
    from hindrax_onboard.control.law import ControlSettings, Controller
    from hindrax_onboard.control.maneuvers import dof_authority
    from hindrax_bringup.allocation.core import AllocationCore
    from hindrax_common.config import DOFS

    model = _load_model(args.model, cfg)
    core = AllocationCore(cfg)
    c = Controller(model, [dof_authority(core, d) for d in DOFS], ControlSettings.from_config(cfg))
    print(f"model: {model.source}")
    print("\n".join(c.gain_report()))
    return 0


def _evaluate(args, cfg) -> int:
    from hindrax_sim import control_evaluate as ev
    from hindrax_sim.truth import TruthError, load_truth

    maneuvers = choices("--maneuvers", args.maneuvers, ev.MANEUVERS, "manoeuvre", empty_ok=False)
    models = choices("--models", args.models, ev.MODELS, "model", empty_ok=False)
    try:
        truth = load_truth(cfg, args.truth)
    except TruthError as exc:
        raise CommandError(f"--truth: {exc}") from exc
    model = _load_model(args.model, cfg)
    progress = WallProgress()
    setup = ev.EvaluationSetup(sensor_noise=not args.no_sensor_noise)
    if args.seeds < 1:
        raise CommandError(f"--seeds: {args.seeds}: a number >= 1")
    cases = ev.evaluate(cfg, truth, model, maneuvers, models, setup, seed=args.seed, progress=progress,
                        seeds=args.seeds)
    out = _out_dir(cfg, args.out, "control")
    info = {"truth": str(args.truth), "model": model.source, "model_notes": list(model.notes),
            "vehicle_file": cfg.source, "seed": args.seed, "seeds": args.seeds, "setup": ev.setup_dict(setup),
            "gains_identified": ev.make_hold("identified", cfg, setup, model).core.gain_report(),
            "gains_vehicle_file": ev.make_hold("vehicle_file", cfg, setup).core.gain_report()}
    path = ev.write_outputs(out, cases, info)
    print(ev.format_table(cases))
    ratio_lines = [f"{m}: identified rmse / vehicle file {row.get('rmse_vs_vehicle_file', math.nan):.2f}, "
                   f"/ PD hold {row.get('rmse_vs_pd_hold', math.nan):.2f} (mean over {args.seeds} seed(s))"
                   for m, row in ev.ratios(cases).items()]
    print("\n".join(ratio_lines))
    section, title = (("control-evaluate-quiet", "Closed loop without sensor noise (diagnostic)")
                      if args.no_sensor_noise else
                      ("control-evaluate", "Closed loop: identified model against the vehicle file"))
    results_doc.write_if_asked(args, section, title,
                               f"Truth `{args.truth}`, model `{model.source}`, seeds {args.seed}.."
                               f"{args.seed + args.seeds - 1}"
                               + (", sensor noise off (diagnostic)" if args.no_sensor_noise else "")
                               + f".\n\n```\n{ev.format_table(cases)}\n"
                               + "\n".join(ratio_lines) + "\n```")
    print(f"output: {path} and {path.parent / 'report' / 'index.html'}  "
          f"(wall time {progress.elapsed():.0f} s)")
    return 0


def _scenarios(args, cfg) -> int:
    from hindrax_sim import control_suite as suite

    try:
        names, truth_dir = suite.scenario_names(args.scenarios, args.truth_dir)
    except ValueError as exc:
        raise CommandError(f"--scenarios: {exc}") from exc
    out = _out_dir(cfg, args.out, "control-scenarios")
    progress = WallProgress()
    rows = suite.run_suite(cfg, names, truth_dir, out, seed=args.seed, levels=args.levels, progress=progress)
    md = suite.write_suite(out, rows, cfg)
    print(md.read_text())
    results_doc.write_if_asked(args, "control-scenarios", "Closed loop over the scenario suite", md.read_text())
    print(f"output: {out / 'control_scenarios.json'} and {md}  "
          f"(wall time {progress.elapsed():.0f} s)")
    return 0
