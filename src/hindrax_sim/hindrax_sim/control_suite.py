"""The figure that matters: for each truth of the scenario suite, how much better the identified model holds depth and
altitude than the vehicle file (``hindrax control scenarios``, docs/control.md §7).

Per scenario (a truth file of ``ros_ws/config/truth/scenarios/``): an in-process identification
(:class:`~hindrax_sim.campaign.Campaign`, :data:`SUITE_DOFS`), its ``identification.yaml`` read back through
:func:`~..control.model.load_model` (so the verdict fallbacks apply), then :data:`SUITE_MANEUVERS` of
:mod:`.control_evaluate` on the same truth. Writes ``<out>/<scenario>/identification.yaml``,
``<out>/<scenario>/control.json`` and the summary ``<out>/control_scenarios.json`` / ``control_scenarios.md``."""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Callable, Sequence

from hindrax_common.config import VehicleConfig

from hindrax_fit.fit.calibration import apply_thrust_calibration
from .campaign import Campaign
from hindrax_fit.fit.campaign_fit import identify_all_with_errors
from hindrax_fit.assessment.results import build_results, write_identification
from .simulator import Simulator
from .truth import load_truth, truth_dir as shipped
from .control_evaluate import EvaluationSetup, evaluate, jsonable, ratios, setup_dict, write_outputs
from hindrax_onboard.control.model import ControlModel, load_model, model_from_config

__all__ = ["SUITE_DOFS", "SUITE_MANEUVERS", "scenario_names", "run_scenario", "run_suite", "write_suite",
           "format_suite"]

#: DOFs identified per scenario (those the depth, altitude and velocity holds use; roll and pitch keep the file's).
SUITE_DOFS = ("surge", "sway", "heave", "yaw")
SUITE_MANEUVERS = ("depth_step", "altitude_hold")


def scenario_names(names: str | None, truth_dir: str | None) -> tuple[list[str], Path]:
    """The scenarios to run (comma-separated ``names``, default every ``*.yaml`` of the folder, ``none`` first) and
    their folder (default ``ros_ws/config/truth/scenarios``). Raises ``ValueError`` naming an unknown scenario."""
    folder = Path(truth_dir) if truth_dir else shipped() / "scenarios"
    have = sorted(p.stem for p in folder.glob("*.yaml"))
    if not have:
        raise ValueError(f"no truth files in {folder}")
    if names:
        wanted = [n.strip() for n in names.split(",") if n.strip()]
        bad = [n for n in wanted if n not in have]
        if bad or not wanted:
            raise ValueError(f"{', '.join(bad) or 'empty'}: choose from {', '.join(have)}")
        return wanted, folder
    return [n for n in have if n == "none"] + [n for n in have if n != "none"], folder


def run_scenario(cfg: VehicleConfig, name: str, truth_path: Path, out: Path, seed: int = 1, levels: int = 3,
                 setup: EvaluationSetup = EvaluationSetup(), progress: Callable[[str], None] | None = None) -> dict:
    """Identify against one truth, then evaluate (module docstring). Returns the scenario's summary row."""
    say = progress or (lambda _m: None)
    truth = load_truth(cfg, truth_path)
    folder = out / name
    sim = Simulator(cfg, seed=seed, truth=truth)
    rec = Campaign(cfg, dofs=SUITE_DOFS, levels=levels, seed=seed, sim=sim).run()
    idents, errors = identify_all_with_errors(apply_thrust_calibration(rec), cfg)
    row: dict = {"scenario": name, "aborted": rec.abort_reason if rec.aborted else "", "not_identified": sorted(errors)}
    if idents:
        doc = build_results(idents, cfg, source=f"simulation, truth {truth_path.name}", seed=seed,
                            calibration=rec.calibration)
        path = write_identification(folder / "identification.yaml", doc)
        model = load_model(path, cfg)
    else:
        base = model_from_config(cfg)  # nothing identified: the vehicle file, said in the notes
        model = ControlModel(base.axes, base.source, ("nothing identified: the vehicle file's model",))
    row["model_notes"] = list(model.notes)
    row["model_sources"] = {d: dict(model.axis(d).sources) for d in ("heave", "surge")}
    say(f"{name}: identified ({'aborted: ' + rec.abort_reason if rec.aborted else 'complete'}); evaluating")
    cases = evaluate(cfg, truth, model, SUITE_MANEUVERS, setup=setup, seed=seed)
    write_outputs(folder, cases, {"truth": str(truth_path), "model": model.source, "model_notes": list(model.notes),
                                  "seed": seed, "setup": setup_dict(setup)})
    row["cases"] = {f"{c.maneuver}/{c.model}": dict(c.metrics) for c in cases}  # one seed
    row["ratios"] = ratios(cases)
    say(f"{name}: " + "; ".join(f"{m} identified/file {r.get('rmse_vs_vehicle_file', math.nan):.2f}, "
                                f"/PD {r.get('rmse_vs_pd_hold', math.nan):.2f}" for m, r in row["ratios"].items()))
    return row


def run_suite(cfg: VehicleConfig, names: Sequence[str], truth_dir: Path, out: Path, seed: int = 1, levels: int = 3,
              progress: Callable[[str], None] | None = None) -> list[dict]:
    """:func:`run_scenario` for every name (each writes its own folder)."""
    out.mkdir(parents=True, exist_ok=True)
    return [run_scenario(cfg, n, truth_dir / f"{n}.yaml", out, seed, levels, progress=progress) for n in names]


def _heave_source(sources: dict) -> str:
    """The table's "heave model" cell from the heave axis' sources (:attr:`~..control.model.AxisModel.sources`):
    identified, the vehicle file with the first reason, or the inertia identified while the force terms (damping, bias)
    fell back (:func:`~..control.model.unexplained_bias`)."""
    src = str(sources.get("inertia", "?"))
    if not src.startswith("identified"):
        return "file: " + src.split(": ", 1)[-1][:40].rstrip(")") if "suspect" in src else "file"
    forces = [str(sources.get(k, "identified")) for k in ("damping", "bias")]
    if all(f.startswith("identified") for f in forces):
        return "identified"
    why = next(f for f in forces if not f.startswith("identified"))
    return "inertia identified; damping, bias file" + (" (force error)" if "force error" in why else "")


def format_suite(rows: Sequence[dict]) -> str:
    """The markdown table: per scenario the RMSE (cm) of each hold in the depth step and the altitude hold, and the
    ratios identified / vehicle file and identified / PD hold."""
    head = ("| scenario | heave model | depth step: identified / vehicle file / PD hold (cm) | ratio to file | "
            "ratio to PD | altitude hold: identified / vehicle file / PD hold (cm) | ratio to file | ratio to PD |")
    lines = [head, "|" + "---|" * 8]
    for r in rows:
        heave = _heave_source(r.get("model_sources", {}).get("heave", {}))
        cells = [r["scenario"] + (" (aborted)" if r.get("aborted") else ""), heave]
        for m in SUITE_MANEUVERS:
            v = [r["cases"].get(f"{m}/{k}", {}).get("rmse", math.nan) * 100 for k in ("identified", "vehicle_file",
                                                                                        "pd_hold")]
            rr = r["ratios"].get(m, {})
            cells += [" / ".join(f"{x:.3f}" for x in v), f"{rr.get('rmse_vs_vehicle_file', math.nan):.2f}",
                      f"{rr.get('rmse_vs_pd_hold', math.nan):.2f}"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write_suite(out: Path, rows: Sequence[dict], cfg: VehicleConfig) -> Path:
    """``control_scenarios.json`` and ``control_scenarios.md`` in ``out``; returns the markdown path."""
    (out / "control_scenarios.json").write_text(json.dumps(
        {"vehicle_file": cfg.source, "dofs": list(SUITE_DOFS), "maneuvers": list(SUITE_MANEUVERS),
         "rows": jsonable(list(rows))}, indent=2) + "\n")
    text = ("# Identified model vs vehicle file in closed loop, per scenario truth (hindrax control scenarios)\n\n"
            "RMSE against the specified response (docs/control.md §6); ratio < 1: the identified model holds "
            "better.\n\n" + format_suite(rows) + "\n")
    md = out / "control_scenarios.md"
    md.write_text(text)
    return md
