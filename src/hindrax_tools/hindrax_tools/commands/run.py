"""``hindrax run [--dofs surge,heave,...] [--levels N] [--rtf X] [--seed N] [--out DIR] [--in-process]``: the main job.

Default: the campaign through the whole ROS graph in one process (:mod:`hindrax_sim.graph.graph_campaign`: virtual
pool, device emulators, drivers, ESC, allocation, identification node and recorder; armed through ``esc/set_armed``,
one ``run_identification`` goal, disarmed, then identified from the bag), in lock-step with the identification node's
control tick, so CPU load slows the run but does not change it.

``--in-process`` (also ``hindrax ident campaign``): the same campaign stepped in-process on the simulator
(:mod:`hindrax_sim.campaign`: no drivers, no ROS graph, no bag), about four times faster; for quick studies of the
method.

Output directory: a new ``<recording.output_root>/sim_<DOFs>_<time>/`` (``sim-in-process_...`` for ``--in-process``),
with a ``latest`` link beside it moved once the run has completed (:mod:`hindrax_tools.output_dirs`), or ``--out``,
which must be new or empty. It holds ``identification.yaml`` (:mod:`hindrax_fit.assessment.results`),
``report/index.html`` with its plots, and (graph) ``bag/``. At the end a table is printed: per DOF and parameter the
identified value with its std, the configured value ("truth" in simulation) and the relative error. Exit 0, or 1 when
the campaign aborted or produced no estimate."""
from __future__ import annotations

import argparse
import math
import os
from pathlib import Path

from .. import results_doc
from hindrax_onboard.commands.common import CommandError, add_config_argument, choices, load_vehicle
from .common import WallProgress, remove_if_empty, result_dir

__all__ = ["add_arguments", "run", "run_graph", "run_in_process", "format_summary"]

#: options that replace a ``calibration.*`` key of the vehicle file: (option dest, key, help)
_CALIBRATION_OPTIONS = (
    ("ballast_mass_kg", "calibration.ballast_mass_kg", "ballast mass, kg"),
    ("ballast_volume_m3", "calibration.ballast_volume_m3", "ballast displaced volume, m^3"),
    ("line_pull_n", "calibration.line_pull_force_n", "horizontal line force over the pulley, N"),
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``hindrax run`` (and ``hindrax ident campaign``)."""
    from hindrax_common.config import DOFS

    if parser.prog.endswith("campaign"):
        parser.description = ("Run the identification campaign in-process on the simulator (no ROS graph, no bag) "
                              "and write identification.yaml and report/index.html.")
    else:
        parser.description = ("Run the identification campaign on the virtual pool through the whole ROS node graph "
                              "(simulator, device emulators, drivers, ESC, allocation, identification node, recorder "
                              "-> bag/), identify from the bag and write identification.yaml and report/index.html.")
    parser.add_argument("--dofs", default=",".join(DOFS), help=f"comma-separated DOFs (default {','.join(DOFS)})")
    parser.add_argument("--levels", type=int, default=None,
                        help="levels per DOF (default identification.levels_per_dof)")
    parser.add_argument("--rtf", type=float, default=0.0, help="real-time factor, 0 = as fast as possible (default)")
    parser.add_argument("--seed", type=int, default=None, help="simulation seed (default simulation.seed)")
    parser.add_argument("--out", default=None, help="output directory, new or empty (default: "
                        "<recording.output_root>/sim_<DOFs>_<time>/)")
    results_doc.add_argument(parser)
    add_config_argument(parser)
    parser.add_argument("--truth", default=None,
                        help="truth file of the virtual pool: overlay of the vehicle file + disturbances, read by the "
                             "simulator and emulators only (default ros_ws/config/truth/default.yaml)")
    parser.add_argument("--max-level-duration", type=float, default=None,
                        help="longest run of one level, s (default identification.max_level_duration_s)")
    parser.add_argument("--calibrate", default="",
                        help="reference steps before the ladders, comma-separated: thrust (= ballast, float, "
                             "line_pull, line_pull_negative), or some of them, tilt_decay, inclining "
                             "(docs/identification.md §6); through the graph the virtual pool plays the operator")
    for dest, key, text in _CALIBRATION_OPTIONS:
        parser.add_argument("--" + dest.replace("_", "-"), type=float, default=None,
                            help=f"{text} (default {key} of the vehicle file)")
    parser.add_argument("--restoring-n-m-per-rad", type=float, default=None,
                        help="roll/pitch restoring stiffness C for tilt_decay (from `hindrax ident inclining`; default "
                             "m g BG of the vehicle file, marked not measured)")
    parser.add_argument("--restoring-std", type=float, default=0.0, help="1-sigma of C, N m/rad")
    parser.add_argument("--excitation", default=None, choices=("ladder", "multisine", "prbs", "chirp"),
                        help="force input per DOF: the constant-thrust ladder, or one broadband run (Schroeder "
                             "multisine, m-sequence PRBS, log chirp) shaped to stay in the pool box "
                             "(default identification.excitation of the vehicle file)")
    parser.add_argument("--excitation-duration", type=float, default=None,
                        help="length of the broadband run per DOF, s (default identification.excitation_duration_s)")
    if not parser.prog.endswith("campaign"):
        parser.add_argument("--in-process", action="store_true",
                            help="step the simulator in-process instead (no drivers, no ROS graph, no bag; about 4x "
                                 "faster), as `hindrax ident campaign`")


def _summary(identifications: dict) -> list[tuple[dict, str, str, str]]:
    """Per row of :func:`~hindrax_fit.assessment.report.summary_rows`: (the row,
    its relative error or ``-``, its configured value or ``-``, its verdict with the first reason: a
    parameter at a bound that one, it has no interval)."""
    from hindrax_fit.assessment.report import summary_rows

    out = []
    for r in summary_rows(identifications):
        err = "-" if not math.isfinite(r["relative_error"]) else f"{100 * r['relative_error']:+.2f}%"
        tr = "-" if r["truth"] is None else f"{r['truth']:.4g}"
        bound = [x for x in r.get("reasons", []) if "bound" in x and "no interval" in x]
        why = f" ({(bound or r['reasons'])[0]})" if r.get("reasons") else ""
        out.append((r, err, tr, f"{r.get('verdict', '-')}{why}"))
    return out


def format_summary(identifications: dict) -> str:
    """The end-of-run table: DOF, parameter, value +- std, unit, configured value, relative error,
    verdict with its first reason (:func:`_summary`). A number that is not finite prints ``-``."""
    def num(x, spec):
        ok = x is not None and math.isfinite(x)
        return format(x, spec) if ok else format("-", ">" + spec.split(".")[0])

    lines = [f"{'DOF':6s} {'parameter':28s} {'identified':>12s} {'std':>9s} {'unit':9s} "
             f"{'configured':>11s} {'rel.err':>8s}  verdict"]
    for r, err, tr, verdict in _summary(identifications):
        lines.append(f"{r['dof']:6s} {r['parameter']:28s} {num(r['value'], '12.5g')} "
                     f"{num(r['std'], '9.3g')} {r['unit']:9s} {tr:>11s} {err:>8s}  {verdict}")
    return "\n".join(lines)


def summary_markdown(identifications: dict) -> str:
    """:func:`format_summary` as a Markdown table (value, std, the simulator's configured truth, error, verdict)."""
    header = ["DOF", "parameter", "identified", "std", "unit", "configured (truth)", "rel. error", "verdict"]
    return results_doc.markdown_table(header, [
        [r["dof"], r["parameter"], f"{r['value']:.5g}", f"{r['std']:.3g}", r["unit"], tr, err, why]
        for r, err, tr, why in _summary(identifications)])


def _finish(args: argparse.Namespace, progress: WallProgress, out: Path, idents: dict, errors: dict,
            ok: bool, where: str, extra: str = "") -> int:
    """The end of a run: the DOFs without an estimate, the summary table and section ``run`` of
    ``--results-doc`` (run ``where``), the output line; ``latest`` beside ``out`` points at it when
    ``ok`` with an estimate (not for ``--out``). Returns the exit status: 0, or 1 without that."""
    for dof, msg in errors.items():
        progress(f"{dof}: no estimate ({msg})")
    if idents:
        print(format_summary(idents))
        seed, truth = "default" if args.seed is None else args.seed, getattr(args, "truth", None)
        body = (f"Campaign {where}, DOFs {args.dofs}, levels {args.levels or 'default'}, "
                f"seed {seed}, truth {truth or 'default'}; wall time {progress.elapsed():.0f} s on "
                f"{os.cpu_count()} cores.\n\n" + summary_markdown(idents))
        title = "The main job: identified against the simulator's truth"
        results_doc.write_if_asked(args, "run", title, body)
    print(f"output: {out}  ({extra}wall time {progress.elapsed():.0f} s)")
    if not (ok and idents):
        return 1
    if not args.out:
        from ..output_dirs import point_latest

        try:
            point_latest(out)
        except OSError as exc:
            print(f"{out.parent / 'latest'}: not updated ({exc.strerror or exc})")
    return 0


def _output_dir(cfg, out: str | None, kind: str, dofs: list[str]) -> Path:
    """``--out`` (new or empty), or a new folder under ``recording.output_root`` named by the
    campaign (``kind``, the DOFs) and the time (:func:`.common.result_dir`)."""
    from hindrax_common.config import DOFS

    root = cfg.recording.output_root
    label = "all" if set(dofs) == set(DOFS) else "-".join(dofs)
    return result_dir(out, Path(str(root)), f"{kind}_{label}",
                      f"recording.output_root {root}: cannot create a run folder ({{why}})")


def run(args: argparse.Namespace) -> int:
    """``hindrax run``: through the ROS graph (default) or in-process on the simulator (``--in-process``, and
    ``hindrax ident campaign``)."""
    if hasattr(args, "in_process") and not args.in_process:
        return run_graph(args)
    return run_in_process(args)


def _check_args(args) -> tuple[object, list[str]]:
    """(vehicle configuration, DOFs to identify). Raises :class:`~.common.CommandError` on a bad argument."""
    from hindrax_common.config import DOFS

    cfg = load_vehicle(args.config)
    overrides = _calibration_overrides(args)
    if overrides:  # the options replace the vehicle file's calibration.* keys, validated like the file
        from hindrax_common.config import ConfigError, load_config
        try:
            cfg = load_config(cfg.source, overrides)
        except ConfigError as exc:
            raise CommandError(f"--ballast-mass-kg/--ballast-volume-m3/--line-pull-n: {exc}") from exc
    dofs = choices("--dofs", args.dofs, DOFS, "DOF", empty_ok=False)
    if args.levels is not None and args.levels < 1:
        raise CommandError("--levels must be >= 1")
    if args.rtf < 0:
        raise CommandError("--rtf must be >= 0")
    dur = getattr(args, "excitation_duration", None)
    if dur is not None and not (5.0 <= dur <= 1800.0):
        raise CommandError(f"--excitation-duration {dur}: allowed 5-1800 s (identification.excitation_duration_s)")
    from hindrax_onboard.identification.online.executive import expand_calibration

    cal = expand_calibration(_calibration_steps(args))
    if "float" in cal and cfg.known_forces.float_net_buoyancy_n is None:
        raise CommandError("--calibrate: the float step needs calibration.float_mass_kg and "
                           "calibration.float_volume_m3 in the vehicle file")
    return cfg, dofs


def _calibration_steps(args) -> list[str]:
    from hindrax_onboard.identification.online.executive import CALIBRATION_STEPS

    return choices("--calibrate", getattr(args, "calibrate", ""), CALIBRATION_STEPS, "step")


def _calibration_overrides(args) -> dict:
    """{key: value} of the :data:`_CALIBRATION_OPTIONS` given on the command line."""
    return {key: float(getattr(args, dest)) for dest, key, _text in _CALIBRATION_OPTIONS
            if getattr(args, dest, None) is not None}


def run_graph(args: argparse.Namespace) -> int:
    """The campaign through the ROS graph (module docstring). Returns the exit status."""
    from hindrax_common.config import default_config_path

    from hindrax_common.node_support.vehicle_graph import ForeignVehicleError

    from hindrax_sim.graph.graph_campaign import run_graph_campaign
    from hindrax_fit.assessment.results import reference_sections

    cfg, dofs = _check_args(args)
    progress = WallProgress()
    out = _output_dir(cfg, args.out, "sim", dofs)
    overrides = _calibration_overrides(args)
    if args.max_level_duration is not None:
        overrides["identification.max_level_duration_s"] = float(args.max_level_duration)
    if getattr(args, "excitation", None):  # reaches the identification node through the vehicle file override
        overrides["identification.excitation"] = args.excitation
    if getattr(args, "excitation_duration", None) is not None:
        overrides["identification.excitation_duration_s"] = float(args.excitation_duration)
    try:
        outcome = run_graph_campaign(args.config or default_config_path(), out, dofs=dofs, levels=args.levels,
                                     seed=args.seed, real_time_factor=args.rtf, overrides=overrides,
                                     progress=progress, truth=getattr(args, "truth", None),
                                     calibrate=_calibration_steps(args),
                                     sections=lambda doc, rec, idents: reference_sections(
                                         doc, rec, cfg, args.restoring_n_m_per_rad, args.restoring_std,
                                         progress))
    except ForeignVehicleError as exc:
        remove_if_empty(out)  # refused before the graph started: no empty run folder left behind
        raise CommandError(f"hindrax run: {exc}") from exc
    return _finish(args, progress, out, outcome.identifications, outcome.errors, outcome.success,
                   "through the node graph", f"bag {outcome.bag_dir}; ")


def run_in_process(args: argparse.Namespace) -> int:
    """Run the campaign in-process on the simulator, identify, write the outputs, print the summary."""
    from hindrax_sim.campaign import Campaign
    from hindrax_fit.fit.campaign_fit import identify_all_with_errors
    from hindrax_fit.assessment.report import write_outputs
    from hindrax_fit.assessment.results import reference_sections

    cfg, dofs = _check_args(args)
    progress = WallProgress()
    print("campaign in-process on the simulator (no ROS graph, no bag)", flush=True)
    from hindrax_sim.simulator import Simulator
    from hindrax_sim.truth import TruthError
    try:
        sim = Simulator(cfg, seed=args.seed, truth=getattr(args, "truth", None))
    except TruthError as exc:
        raise CommandError(f"--truth: {exc}") from exc
    cal = _calibration_steps(args)
    from hindrax_onboard.identification.online.executive import calibration_forces, inclining_load
    w_ballast, f_line = calibration_forces(cfg)
    campaign = Campaign(cfg, dofs=dofs, levels=args.levels, seed=args.seed,
                        max_level_duration_s=args.max_level_duration, progress=progress, real_time_factor=args.rtf,
                        sim=sim, calibrate=cal, excitation=getattr(args, "excitation", None),
                        excitation_duration_s=getattr(args, "excitation_duration", None),
                        ballast_weight_in_water_n=w_ballast, line_pull_n=f_line,
                        inclining_load_n_m=inclining_load(cfg) if "inclining" in cal else (0.0, 0.0))
    record = campaign.run()
    progress(f"campaign finished: {record.t_s[-1] if record.t_s.size else 0:.0f} s simulated"
             + (f", ABORTED: {record.abort_reason}" if record.aborted else ""))
    from hindrax_fit.fit.calibration import identify_calibrated

    # the calibration's per-direction scales applied, the thrust shares attached for the joint estimate
    idents, errors = identify_calibrated(record, cfg, identify_all_with_errors)
    out = _output_dir(cfg, args.out, "sim-in-process", dofs)
    if idents:
        note = (f"In-process simulator campaign, {record.t_s[-1]:.0f} s simulated, wall {record.wall_time_s:.0f} s"
                + (f"; ABORTED: {record.abort_reason}" if record.aborted else ""))
        # thrust scales estimated jointly with the fits (calibration.joint_estimate), calibration section
        write_outputs(out, idents, cfg, None, note, source="simulation", seed=record.seed,
                      calibration=record.calibration, sections=lambda doc: reference_sections(
                          doc, record, cfg, args.restoring_n_m_per_rad, args.restoring_std, progress))
    return _finish(args, progress, out, idents, errors, not record.aborted, "in-process (no ROS graph)")
