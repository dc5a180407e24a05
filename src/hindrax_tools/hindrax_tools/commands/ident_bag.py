"""``hindrax ident bag BAG [--out DIR] [--config FILE] [--restoring-n-m-per-rad C --restoring-std S]``: offline
identification of a recorded campaign bag.

Writes ``identification.yaml`` and ``report/index.html`` into a new folder beside the bag, ``<bag>_ident_<time>``
(``--out``: a new or empty folder; :func:`result_dir_for_bag`), and prints the summary table; the pipeline is
:mod:`hindrax_fit.assessment.pipeline` (docs/identification.md §7). Calibration steps' results in the bag
(``identification/calibration``) are applied as ``hindrax run`` applies them (docs/identification.md §6). A DOF whose
chosen model does not beat holding the velocity in the cross-validation gets that verdict, as in ``hindrax ident
fit``. Exit 0, or 1 with one line on stderr when the configuration, the bag or its content is unusable, or when no
DOF could be identified."""
from __future__ import annotations

import argparse
from pathlib import Path

from hindrax_onboard.commands.common import CommandError, add_config_argument, load_vehicle
from .common import remove_if_empty, result_dir

__all__ = ["add_arguments", "run", "identify_campaign_bag", "result_dir_for_bag"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``hindrax ident bag``."""
    parser.add_argument("bag", help="bag directory (or .mcap file) recorded during an identification campaign")
    parser.add_argument("--out", default=None,
                        help="output directory, new or empty (default: a new <bag>_ident_<time> beside the bag)")
    parser.add_argument("--restoring-n-m-per-rad", type=float, default=None,
                        help="roll/pitch restoring stiffness C for the bag's tilt_decay steps when it has no inclining "
                             "step (from `hindrax ident inclining`; default the vehicle file's m g BG)")
    parser.add_argument("--restoring-std", type=float, default=0.0, help="1-sigma of C, N m/rad")
    add_config_argument(parser)


def result_dir_for_bag(bag: Path, out: str | None, kind: str = "ident") -> Path:
    """The folder of one result from ``bag`` (:func:`.common.result_dir`): ``out``, else a new
    ``<bag name>_<kind>_<time>[_N]`` beside the bag, never the bags' shared parent itself."""
    resolved = bag.resolve()
    name = resolved.stem if resolved.is_file() else resolved.name
    return result_dir(out, resolved.parent, f"{name}_{kind}",
                      f"{bag}: cannot create a result folder beside it ({{why}}); give --out")


def identify_campaign_bag(bag: Path, out: Path, cfg, args: argparse.Namespace, command: str, opts=None):
    """Identify a campaign bag (:func:`~..identification.assessment.pipeline.identify_bag`, the fit core's ``opts``:
    default its defaults) and write identification.yaml and the report in ``out``
    (:func:`~..identification.assessment.pipeline.write_campaign_outputs`); prints the DOFs without an estimate and
    the bag's calibration (the steps' scales, then the joint ones control model uses), and the fit's progress while
    it runs (a minute or two for a whole campaign:
    :class:`~hindrax_sim.progress_line.Ticker`, the seconds on a terminal). ``args`` gives ``restoring_n_m_per_rad`` and
    ``restoring_std`` (the free decay's stiffness when the bag has no inclining step; absent: the vehicle file's).
    Returns (record, {dof: DofIdentification}, the yaml's path). Raises :class:`CommandError` (prefixed ``command``)
    for an unusable bag or when no DOF is identified."""
    import yaml

    from hindrax_bringup.recording.reader import BagError

    from hindrax_fit.assessment import pipeline
    from hindrax_fit.bag_input.reader import BagContentError
    from hindrax_sim.progress_line import ProgressLine, Ticker

    try:
        with Ticker(ProgressLine(lambda s: print(s, flush=True)), f"{command}: reading and fitting {bag}"):
            record, idents, errors = pipeline.identify_bag(bag, cfg, opts=opts)
        lacking = pipeline.truncation(bag)
    except (BagError, BagContentError, OSError, ValueError) as exc:
        raise CommandError(f"{command}: {exc}") from exc
    if lacking:
        print(f"TRUNCATED bag {bag}: " + "; ".join(lacking))
    for dof, msg in errors.items():
        print(f"{dof}: no estimate ({msg})")
    if not idents:
        raise CommandError(f"{command}: no DOF could be identified")
    out.mkdir(parents=True, exist_ok=True)
    if record.calibration:
        print("calibration from the bag (identification/calibration), the steps' measured thrust scales: " + ", ".join(
            f"{k} {v['value']:.4f} +- {v['std']:.4f}" for k, v in record.calibration.items()))
    path = pipeline.write_campaign_outputs(out, record, idents, cfg, bag, lacking,
                                           getattr(args, "restoring_n_m_per_rad", None),
                                           getattr(args, "restoring_std", 0.0))
    scales = (yaml.safe_load(Path(path).read_text()).get("joint") or {}).get("scales") or {}
    if scales:  # issue 74.8: the scale control model uses differs from the step's; both are named
        print("thrust scales estimated jointly with the fits (identification.yaml joint.scales, what control model "
              "divides by): " + ", ".join(f"{g} {e['value']:.4f} +- {e['std']:.4f} ({', '.join(e.get('dofs', []))})"
                                          for g, e in scales.items()))
    return record, idents, path


def run(args: argparse.Namespace) -> int:
    """Identify from a bag, write the outputs, print the summary. Raises :class:`CommandError` on bad input."""
    import yaml

    from hindrax_fit.assessment.verdicts import format_advice, no_model_line
    from hindrax_fit.fit.fit_core import NO_MODEL_VERDICT
    from .run import format_summary

    cfg = load_vehicle(args.config)
    bag = Path(args.bag)
    if not bag.exists():
        raise CommandError(f"ident bag: {bag}: no such file or directory")
    out = result_dir_for_bag(bag, args.out)
    try:
        _record, idents, path = identify_campaign_bag(bag, out, cfg, args, "ident bag")
    except CommandError:
        remove_if_empty(out)
        raise
    print(format_summary(idents))
    doc = yaml.safe_load(Path(path).read_text())
    for dof, e in doc.get("dofs", {}).items():  # never worse than holding the velocity (as ident fit prints it)
        if e.get("verdict") == NO_MODEL_VERDICT and e.get("persistence"):
            print(no_model_line(dof, e["persistence"]))
    for dof, e in doc.get("dofs", {}).items():  # what data would fix each suspect parameter (as ident fit prints)
        for name, p in e.items():
            if isinstance(p, dict) and p.get("advice"):
                print(format_advice(f"{dof} {name}", p["advice"]))
    print(f"output: {path} and {out / 'report' / 'index.html'}")
    return 0
