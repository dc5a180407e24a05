"""``hindrax ident scenarios [--scenarios NAMES] [--seeds N] [--dofs ...] [--out DIR] [--jobs N]``: the scenario suite.

For every named scenario (a truth file in ``ros_ws/config/truth/scenarios/``, :mod:`hindrax_sim.truth`) and
every seed 1..N, one in-process identification campaign (:class:`~hindrax_sim.campaign.Campaign`, the simulator
running on the scenario's truth, every estimator on the vehicle file), the offline identification and the verdicts
(:mod:`hindrax_fit.assessment.verdicts`). Each parameter is compared with the truth's value
(:func:`~hindrax_onboard.identification.model.dof_model.truth_parameters` of the truth configuration): relative
error, z = (estimate - truth) / std, whether the 95 % interval covers the truth, and the verdict with its reasons.

Writes ``<out>/scenarios.json`` (every case, the per-scenario summary, provenance) and ``<out>/scenarios.md`` (the
table) and prints the table. A scenario *meets the target* when every parameter's interval covers the truth in at
least 90 % of the seeds or the parameter is suspect in every case where it does not; the no-disturbance scenario also
needs at most 10 % of its parameters suspect. Exit 0; 1 on bad arguments.

``--excitation ladder,multisine,prbs`` runs every case once per force input
(:mod:`hindrax_onboard.identification.online.excitation`); the label becomes ``<scenario> [<excitation>]`` for the
other excitations, and a second table compares them (:func:`format_excitation_table`). ``--calibrate thrust`` (or
other reference steps) runs them before the manoeuvres of every case and identifies as ``hindrax ident campaign
--calibrate`` does (:func:`run_case`); the label gains ``[calibrate <steps>]``. Without it the cases are identified
on the curve's force.
"""
from __future__ import annotations

import argparse
import datetime as _dt
import json
import math
import os
import time
from contextlib import nullcontext
from pathlib import Path
from typing import Sequence

from .. import results_doc
from hindrax_onboard.commands.common import CommandError, add_config_argument, choices, load_vehicle
from .common import WallProgress

__all__ = ["add_arguments", "run", "scenario_names", "run_case", "summarise", "format_table", "REPORTED",
           "format_excitation_table"]

#: DOFs of the full suite: surge, sway, heave, yaw.
DEFAULT_DOFS = ("surge", "sway", "heave", "yaw")
#: Parameters compared with the truth (added_mass is inertia minus a constant, so it is left out).
REPORTED = ("inertia", "quadratic_damping", "quadratic_damping_positive", "quadratic_damping_negative",
            "linear_damping", "linear_damping_positive", "linear_damping_negative", "bias", "restoring")


def scenario_dir() -> Path:
    """``ros_ws/config/truth/scenarios/``."""
    from hindrax_sim.truth import truth_dir
    return truth_dir() / "scenarios"


def scenario_names() -> list[str]:
    """Shipped scenarios, ``none`` first then alphabetical (``all_combined`` last)."""
    names = sorted(p.stem for p in scenario_dir().glob("*.yaml"))
    first = [n for n in ("none",) if n in names]
    last = [n for n in ("all_combined",) if n in names]
    return first + [n for n in names if n not in first + last] + last


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``hindrax ident scenarios``."""
    parser.add_argument("--scenarios", default=None,
                        help="comma-separated scenario names or truth files (default: every shipped scenario)")
    parser.add_argument("--seeds", type=int, default=5, help="seeds 1..N per scenario (default 5)")
    parser.add_argument("--dofs", default=",".join(DEFAULT_DOFS), help="comma-separated DOFs (default surge,sway,"
                        "heave,yaw)")
    parser.add_argument("--levels", type=int, default=None,
                        help="levels per DOF (default identification.levels_per_dof)")
    parser.add_argument("--out", default="scenario-results", help="output directory (default scenario-results/)")
    results_doc.add_argument(parser)
    add_config_argument(parser)
    parser.add_argument("--jobs", type=int, default=1, help="campaigns run in parallel processes (default 1)")
    parser.add_argument("--cache", default=None,
                        help="directory keeping each campaign's identification (pickle, keyed by "
                             "scenario, seed, DOFs and levels): a case found there is not run "
                             "again (empty it when the vehicle file or the code changes)")
    parser.add_argument("--excitation", default=None,
                        help="comma-separated force inputs to compare: ladder, multisine, prbs, chirp (default "
                             "identification.excitation of the vehicle file)")
    parser.add_argument("--excitation-duration", type=float, default=None,
                        help="broadband run per DOF, s (default identification.excitation_duration_s)")
    parser.add_argument("--calibrate", default="",
                        help="reference steps before the manoeuvres of every case, as hindrax run --calibrate "
                             "(docs/identification.md §6.2); the label gains [calibrate <steps>]")
    parser.add_argument("--cached-only", action="store_true",
                        help="with --cache: use only the cases found there (re-assess them with the current verdicts "
                             "and tables; the others are listed as not run)")


def _truth_path(name: str) -> Path:
    p = Path(name)
    return p if p.suffix in (".yaml", ".yml") and p.is_file() else scenario_dir() / f"{name}.yaml"


def _label(scenario: str) -> str:
    """A scenario's name: a truth file's stem, or the name as given."""
    return Path(scenario).stem if str(scenario).endswith((".yaml", ".yml")) else str(scenario)


def run_case(config_path: str | None, scenario: str, seed: int, dofs: Sequence[str],
             levels: int | None = None, cache: str | None = None, excitation: str | None = None,
             excitation_duration_s: float | None = None, calibrate: Sequence[str] = ()) -> dict:
    """One campaign of ``scenario`` (name or truth file) with ``seed``: the compared parameters.

    excitation / excitation_duration_s: the force input (default the vehicle file's ``identification.excitation``);
    another than ``ladder`` is appended to the label as `` [<excitation>]`` and to the cache key. calibrate: reference
    steps run first (:data:`~hindrax_onboard.identification.online.executive.CALIBRATION_STEPS`; the virtual pool plays
    the operator): the record is identified with its thrust scales applied and estimated jointly with the fits
    (:func:`~hindrax_fit.fit.calibration.identify_calibrated`, :func:`~hindrax_onboard.identification.
    calibration.joint_estimate`, as ``hindrax ident campaign``); the label gains `` [calibrate <steps>]``.

    Returns {"scenario", "seed", "wall_s", "aborted", "errors": {dof: msg}, "cases": [row, ...],
    "dofs": {dof: {"verdict", "reasons"}}}; a row: dof, parameter, value, std, std_fit, truth, rel_error, z,
    covered, verdict, reasons, t_dof, pool_time_s. Raises :class:`~.common.CommandError` for an invalid vehicle file."""
    from hindrax_common.config import or_default

    from hindrax_sim.campaign import Campaign
    from hindrax_fit.fit.campaign_fit import identify_all_with_errors
    from hindrax_onboard.identification.model.dof_model import truth_parameters
    from hindrax_fit.assessment.verdicts import apply_verdicts
    from hindrax_onboard.identification.model.dof_model import rls_published_std
    from hindrax_sim.simulator import Simulator
    from hindrax_sim.truth import load_truth

    import pickle

    from scipy import stats

    cfg = load_vehicle(config_path)
    truth = load_truth(cfg, _truth_path(scenario))
    label = _label(scenario)
    exc = str(or_default(cfg.identification.excitation, "ladder") if excitation is None else excitation)
    dur = excitation_duration_s
    if exc != "ladder":
        label = f"{label} [{exc}]"
    cal = [str(c) for c in calibrate]
    if cal:
        label = f"{label} [calibrate {','.join(cal)}]"
    wall0 = time.monotonic()
    cached = _cache_file(cache, scenario, seed, dofs, levels, exc, dur, cal) if cache else None
    if cached is not None and cached.is_file():
        idents, errors, aborted, abort_reason, campaign_wall = pickle.loads(cached.read_bytes())
    else:
        from hindrax_fit.fit.calibration import identify_calibrated, joint_estimate
        from hindrax_onboard.identification.online.executive import calibration_forces, inclining_load

        operator = {}
        if cal:
            w_ballast, f_line = calibration_forces(cfg)
            operator = dict(calibrate=cal, ballast_weight_in_water_n=w_ballast, line_pull_n=f_line,
                            inclining_load_n_m=inclining_load(cfg))
        record = Campaign(cfg, dofs=list(dofs), levels=levels, seed=seed,
                          sim=Simulator(cfg, seed=seed, truth=truth), excitation=exc,
                          excitation_duration_s=dur, **operator).run()
        if cal:
            idents, errors = identify_calibrated(record, cfg, identify_all_with_errors)
            if idents:
                joint_estimate(idents, cfg, record.calibration)
        else:
            idents, errors = identify_all_with_errors(record, cfg)
        aborted, abort_reason, campaign_wall = bool(record.aborted), record.abort_reason, time.monotonic() - wall0
        if cached is not None:
            for r in idents.values():
                r.signals.pop("online_history", None)
            cached.parent.mkdir(parents=True, exist_ok=True)
            cached.write_bytes(pickle.dumps((idents, errors, aborted, abort_reason, campaign_wall)))
    verdicts = apply_verdicts(idents, cfg)
    rows = []
    for dof, r in idents.items():
        true = truth_parameters(truth.config, dof)
        a = verdicts[dof]["parameters"]
        # the online RLS std as the executive publishes it (NaN = not converged / not trusted)
        online = [r.online.get(n, (math.nan, math.nan)) for n in r.names]
        published = rls_published_std(dof, r.names, [v for v, _ in online],
                                      [math.nan if s_ is None else s_ for _, s_ in online], cfg)
        rls_std = {n: float(x) for n, x in zip(r.names, published)}
        for name in REPORTED:
            if name not in r.values:
                continue
            v, s, tr = float(r.values[name]), float(r.std[name]), float(true[name])
            lo, hi = r.ci95[name]
            rv, rs = r.online.get(name, (math.nan, math.nan))[0], rls_std.get(name, math.nan)
            rls = {"rls_value": float(rv), "rls_std": rs if math.isfinite(rs) else None,
                   "rls_covers": bool(math.isfinite(rs) and abs(float(rv) - tr) <= 1.96 * rs)}
            # the older interval: the fit's own std and the t quantile of (samples - parameters), no verdict
            t_before = float(stats.t.ppf(0.975, max(int(r.residual_dof), 1)))
            before = bool(abs(v - tr) <= t_before * a[name]["std_fit"])
            rows.append({**rls, "covered_before": before, "dof": dof, "parameter": name, "value": v, "std": s,
                         "std_fit": a[name]["std_fit"],
                         "truth": tr, "rel_error": (v - tr) / abs(tr) if tr != 0.0 else None,
                         "z": (v - tr) / s if s > 0 else None, "covered": bool(lo <= tr <= hi),
                         "verdict": a[name]["verdict"], "reasons": a[name]["reasons"], "t_dof": a[name]["t_dof"],
                         "pool_time_s": float(r.pool_time_s)})
    return {"scenario": label, "excitation": exc, "calibrate": cal, "seed": int(seed), "wall_s": campaign_wall,
            "aborted": aborted, "abort_reason": abort_reason, "errors": errors, "cases": rows,
            "dofs": {d: {"verdict": v["verdict"], "reasons": v["reasons"], "checks": v["checks"]}
                     for d, v in verdicts.items()}}


def _cache_file(cache: str, scenario: str, seed: int, dofs: Sequence[str], levels: int | None,
                excitation: str | None, duration_s: float | None, calibrate: Sequence[str]) -> Path:
    """The pickle of one case in ``cache``: ``<scenario>[-<excitation>[-<duration>s]]``
    ``[-calibrate-<steps>]-seed<seed>-<dofs>-levels<levels>.pickle``, the excitation left out for
    the ladder (None: the shipped default)."""
    key = _label(scenario)
    if excitation not in (None, "ladder"):
        key += f"-{excitation}{'' if duration_s is None else f'-{duration_s:g}s'}"
    if calibrate:
        key += f"-calibrate-{'_'.join(calibrate)}"
    return Path(cache) / f"{key}-seed{seed}-{'_'.join(dofs)}-levels{levels}.pickle"


def _case_star(args):
    """run_case in a worker: an exception becomes an ``error`` entry (an exception that does not pickle back
    would stop the pool)."""
    try:
        return run_case(*args)
    except Exception as exc:  # noqa: BLE001 - reported per case, the suite goes on
        return {"scenario": _label(args[1]), "seed": int(args[2]), "wall_s": 0.0, "aborted": True, "abort_reason": "",
                "error": f"{type(exc).__name__}: {exc}", "errors": {}, "cases": [], "dofs": {}}


def summarise(results: Sequence[dict]) -> dict:
    """Per scenario: per DOF and parameter the mean error, max |z|, covered / suspect / ok counts (ok = covered
    or suspect); totals; whether the scenario meets the target (module docstring)."""
    from hindrax_fit.assessment.verdicts import spread_reasons

    out: dict = {}
    by: dict = {}
    for res in results:
        for row in res["cases"]:
            by.setdefault(res["scenario"], {}).setdefault((row["dof"], row["parameter"]), []).append(row)
    for sc, params in by.items():
        table = []
        for (dof, name), rows in params.items():
            extra = spread_reasons([r["value"] for r in rows], [r["std"] for r in rows])
            if extra:  # run-to-run spread: suspect in every case of this parameter
                for r in rows:
                    r["verdict"], r["reasons"] = "suspect", list(r["reasons"]) + extra
            cov = sum(r["covered"] for r in rows)
            ok = sum(r["covered"] or r["verdict"] == "suspect" for r in rows)
            errs = [r["rel_error"] for r in rows if r["rel_error"] is not None]
            zs = [abs(r["z"]) for r in rows if r["z"] is not None]
            table.append({"dof": dof, "parameter": name, "n": len(rows), "covered": cov,
                          "suspect": sum(r["verdict"] == "suspect" for r in rows), "ok": ok,
                          "mean_rel_error": (sum(errs) / len(errs)) if errs else None,
                          "max_abs_z": max(zs) if zs else None,
                          "meets": cov >= 0.9 * len(rows) or ok == len(rows),
                          "reasons": sorted({x for r in rows for x in r["reasons"]})[:4]})
        n_cases, n_cov, n_sus, n_ok = (sum(p[k] for p in table) for k in ("n", "covered", "suspect", "ok"))
        meets = all(p["meets"] for p in table) and not (sc == "none" and n_sus > 0.1 * n_cases)
        all_rows = [r for rows in params.values() for r in rows]
        pub = [r for r in all_rows if r.get("rls_std") is not None]
        out[sc] = {"parameters": table, "cases": n_cases, "covered": n_cov, "suspect": n_sus, "ok": n_ok,
                   "covered_before": sum(r.get("covered_before", False) for r in all_rows),
                   "meets_target": bool(meets), "rls_published": len(pub),
                   "rls_published_covers": sum(r["rls_covers"] for r in pub)}
    return out


def format_excitation_table(results: Sequence[dict]) -> str:
    """Markdown comparison of the force inputs: per scenario, excitation and DOF over the seeds:
    mean pool seconds of the DOF, mean |error| of the inertia and of the quadratic damping (heave: both directions),
    how many of their 95 % intervals cover the truth, and each error scaled to 100 s of pool time
    (|error| x sqrt(pool s / 100), the 1 / sqrt(T) law of an unbiased estimate); the last column
    scales the fits' own relative 1-sigma (``std_fit``, before the thrust-model widening) the same
    way (less noisy than the error over a few seeds)."""
    by: dict = {}
    for res in results:
        for row in res["cases"]:
            if row["rel_error"] is None:
                continue
            kind = "inertia" if row["parameter"] == "inertia" else (
                "kq" if row["parameter"].startswith("quadratic_damping") else None)
            if kind is None:
                continue
            key = (res["scenario"].split(" [")[0], res.get("excitation", "ladder"), row["dof"])
            d = by.setdefault(key, {"pool": {}, "inertia": [], "kq": [], "covered": 0, "n": 0, "inertia_std": [],
                                    "kq_std": []})
            d["pool"][res["seed"]] = row.get("pool_time_s", math.nan)
            d[kind].append(abs(row["rel_error"]))
            d[kind + "_std"].append(abs(row["std_fit"] / row["truth"]))
            d["covered"] += bool(row["covered"])
            d["n"] += 1
    lines = ["| scenario | excitation | DOF | seeds | pool s | inertia mean abs error | quadratic damping mean abs "
             "error | intervals cover | inertia error at 100 s | quadratic damping error at 100 s | 1-sigma at 100 s "
             "(inertia / quadratic damping) |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    def mean(xs) -> float:
        return sum(xs) / len(xs) if xs else math.nan

    for (sc, exc, dof), d in sorted(by.items(), key=lambda kv: (kv[0][0], kv[0][2], kv[0][1])):
        pool = mean(list(d["pool"].values())) if d["pool"] else 0.0
        mi, mq, si, sq = (mean(d[key]) for key in ("inertia", "kq", "inertia_std", "kq_std"))
        k = math.sqrt(pool / 100.0) if pool > 0 else math.nan
        lines.append(f"| {sc} | {exc} | {dof} | {len(d['pool'])} | {pool:.0f} | {100 * mi:.1f} % | {100 * mq:.1f} % | "
                     f"{d['covered']}/{d['n']} | {100 * mi * k:.1f} % | {100 * mq * k:.1f} % | "
                     f"{100 * si * k:.1f} % / {100 * sq * k:.1f} % |")
    return "\n".join(lines)


def _pct(a: int, n: int) -> str:
    return f"{100.0 * a / n:.0f} %" if n else "-"


def format_table(summary: dict) -> str:
    """Markdown: one line per scenario (coverage, suspect, ok, target), then per scenario, DOF and parameter."""
    lines = ["| scenario | cases | before: interval covers truth | after: interval covers truth | suspect | "
             "covered or suspect | target met | RLS std published (covers) |",
             "|---|---|---|---|---|---|---|---|"]
    for sc, s in summary.items():
        cb = s.get("covered_before", 0)
        lines.append(f"| {sc} | {s['cases']} | {cb} ({_pct(cb, s['cases'])}) | "
                     f"{s['covered']} ({_pct(s['covered'], s['cases'])}) | "
                     f"{s['suspect']} ({_pct(s['suspect'], s['cases'])}) | {s['ok']} ({_pct(s['ok'], s['cases'])}) | "
                     f"{'yes' if s['meets_target'] else 'no'} | {s.get('rls_published', 0)} "
                     f"({s.get('rls_published_covers', 0)}) |")
    lines += ["", "| scenario | DOF | parameter | mean error | max abs z | covers | suspect | main reason |",
              "|---|---|---|---|---|---|---|---|"]
    for sc, s in summary.items():
        for p in s["parameters"]:
            err = "-" if p["mean_rel_error"] is None else f"{100 * p['mean_rel_error']:+.1f} %"
            z = "-" if p["max_abs_z"] is None else f"{p['max_abs_z']:.1f}"
            reason = (p["reasons"][0] if p["reasons"] else "").replace("|", "/")
            if len(reason) > 70:
                reason = reason[:67] + "..."
            lines.append(f"| {sc} | {p['dof']} | {p['parameter']} | {err} | {z} | {p['covered']}/{p['n']} | "
                         f"{p['suspect']}/{p['n']} | {reason} |")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    """Run the suite (module docstring)."""
    from hindrax_common.config import DOFS

    load_vehicle(args.config)  # an invalid vehicle file: one line and exit 1 here, not an error per case
    names = [s.strip() for s in (args.scenarios.split(",") if args.scenarios else scenario_names()) if s.strip()]
    missing = [n for n in names if not _truth_path(n).is_file()]
    if missing:
        raise CommandError(f"--scenarios: no truth file for {missing}; shipped: {', '.join(scenario_names())}")
    dofs = choices("--dofs", args.dofs, DOFS, "DOF", empty_ok=False)
    if args.seeds < 1 or args.jobs < 1:
        raise CommandError("--seeds and --jobs must be >= 1")
    if args.cached_only and not args.cache:
        raise CommandError("--cached-only needs --cache DIR")
    from hindrax_onboard.identification.online.excitation import EXCITATIONS
    excitations = choices("--excitation", args.excitation, EXCITATIONS, "excitation") or [None]
    if args.excitation_duration is not None and not args.excitation_duration > 0:
        raise CommandError(f"--excitation-duration must be > 0 s, got {args.excitation_duration}")
    from hindrax_onboard.identification.online.executive import CALIBRATION_STEPS
    cal = choices("--calibrate", args.calibrate, CALIBRATION_STEPS, "step")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    # seed-major: every scenario's seed 1 first, so that a suite cut short still covers every scenario
    jobs = [(args.config, n, seed, dofs, args.levels, args.cache, e, args.excitation_duration, cal)
            for seed in range(1, args.seeds + 1) for n in names for e in excitations]
    not_run = []
    if args.cached_only:
        keep = [j for j in jobs if _cache_file(args.cache, *j[1:5], *j[6:]).is_file()]
        not_run = [f"{j[1]} seed {j[2]}" for j in jobs if j not in keep]
        jobs = keep
    progress, results = WallProgress(), []
    # import everything the workers need before they fork (the tree may change during a long suite)
    from hindrax_fit.assessment import verdicts  # noqa: F401
    from hindrax_onboard.identification.model import dof_model  # noqa: F401
    from hindrax_onboard.identification.online import estimators  # noqa: F401
    from hindrax_sim import campaign, disturbances, simulator, truth  # noqa: F401
    import multiprocessing as mp
    with mp.get_context("fork").Pool(args.jobs) if args.jobs > 1 else nullcontext() as pool:
        for res in (pool.imap if pool else map)(_case_star, jobs):
            results.append(res)
            extra = f", ERROR {res['error']}" if res.get("error") else (
                f", ABORTED: {res['abort_reason']}" if res["aborted"] else "")
            progress(f"{res['scenario']} seed {res['seed']}: {res['wall_s']:.0f} s{extra}")
    summary = summarise(results)
    date = _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()
    doc = {"date": date, "commit": results_doc.commit(), "seeds": args.seeds, "dofs": dofs,
           "scenarios": names, "calibrate": cal, "levels": args.levels, "not_run": not_run,
           "wall_time_s": progress.elapsed(), "summary": summary, "runs": results}
    table = format_table(summary)
    if args.excitation:
        doc["excitation_table"] = format_excitation_table(results)
        table += "\n\n" + doc["excitation_table"]
    (out / "scenarios.json").write_text(json.dumps(doc, indent=1, default=_json_default))
    missing = f"; not run: {', '.join(not_run)}" if not_run else ""
    calib = f", calibrate {','.join(cal)}" if cal else ""
    (out / "scenarios.md").write_text(f"Scenario suite, {date}, commit {doc['commit']}, seeds 1-{args.seeds}, "
                                      f"DOFs {', '.join(dofs)}, levels {args.levels or 'default'}{calib}{missing}\n\n"
                                      f"{table}\n")
    print(table)
    results_doc.write_if_asked(args, "scenarios", "Scenario suite: identification against truths that differ",
                               f"Seeds 1-{args.seeds}, DOFs {', '.join(dofs)}, levels {args.levels or 'default'}"
                               f"{missing}; wall time {doc['wall_time_s']:.0f} s on {os.cpu_count()} cores.\n\n"
                               f"{table}")
    print(f"output: {out / 'scenarios.json'}, {out / 'scenarios.md'} (wall time {doc['wall_time_s']:.0f} s)")
    return 0


def _json_default(x):
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if hasattr(x, "tolist"):
        return x.tolist()
    return str(x)
