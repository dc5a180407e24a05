"""Identification report: report/index.html with PNG plots (matplotlib, Agg backend; docs/architecture.md §5).

Plots per DOF:

* ``<dof>_force_velocity.png`` - force (moment) vs velocity as [Hindrax-Drag] Figs. 8-10: the drag samples
  tau - M nu_dot - k_r s(eta) (thrust model minus the identified inertial and restoring terms) against the
  smoothed velocity, the steady-window means of [Hindrax-Drag]'s method, and the fitted curve
  k_q |v| v + k_l v + b with its 95 % band (delta method on the damping/bias covariance, Student-t).
* ``<dof>_rls.png`` - RLS convergence: every parameter's online estimate with its +-1.96 std band (where the RLS has a
  noise estimate; the title says how many parameters have one) and the reported (offline) value.

For a fit of bags of any topics (``hindrax ident fit``, :func:`write_fit_outputs`): per fitted DOF, the validation
segments laid end to end (the holdout bags when given, else the cross-validation folds), measured velocity, the
model's open-loop prediction from each segment's measured initial velocity, and the held initial value (what
``nrmse_hold`` measures); the same measured against predicted over the record time; the autocorrelation of the
validation residuals (pairs within a segment, :func:`residual_acf`) with the 95 % band of white residuals; and, with a
vehicle file, every parameter with its 95 % interval against the vehicle file's value."""
from __future__ import annotations

import html
import math
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import yaml  # noqa: E402
from scipy import stats  # noqa: E402

from hindrax_common.config import VehicleConfig  # noqa: E402

from ..fit import fit_core  # noqa: E402
from hindrax_onboard.identification.model.dof_model import model_terms, truth_parameters  # noqa: E402
from .results import build_results, training_lines, write_identification  # noqa: E402

__all__ = ["write_report", "write_outputs", "summary_rows", "write_fit_outputs", "residual_acf"]


def _assessment(r, name: str) -> tuple[str, list, float | None]:
    """(verdict, reasons, the bound it sits at or None) of one parameter from :func:`~.verdicts.apply_verdicts`
    ("-", [], None when not assessed)."""
    a = r.signals.get("assessment") if isinstance(getattr(r, "signals", None), dict) else None
    if not a or name not in a["parameters"]:
        return "-", [], None
    p = a["parameters"][name]
    return p["verdict"], list(p["reasons"]), p.get("at_bound")


def summary_rows(identifications: Mapping[str, Any]) -> list[dict]:
    """One row per DOF and parameter: value, std, ci95, configured truth, relative error, other methods, verdict,
    reasons and ``at_bound`` (the bound a parameter sits at, where its interval means nothing; else None)."""
    rows = []
    for dof, r in identifications.items():
        for name in list(r.names) + ["added_mass"]:
            tr = r.truth.get(name)
            v = r.values[name]
            err = (v - tr) / abs(tr) if tr not in (None, 0.0) else math.nan
            verdict, reasons, at_bound = _assessment(r, name)
            rows.append({"dof": dof, "parameter": name, "value": v, "std": r.std[name], "unit": r.units[name],
                         "ci95": r.ci95[name], "truth": tr, "relative_error": err,
                         "equation_error": r.equation_error.get(name, (math.nan, math.nan))[0],
                         "rls": r.online.get(name, (math.nan, math.nan))[0],
                         "steady": (r.steady or {}).get(name, (math.nan, math.nan))[0],
                         "verdict": verdict, "reasons": reasons, "at_bound": at_bound})
    return rows


def _save(fig, path: Path, dpi: int = 90) -> None:
    fig.tight_layout()
    # tight_layout leaves a placeholder engine, for which savefig draws twice
    fig.set_layout_engine(None)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)


def _force_velocity_plot(r, path: Path) -> None:
    s = r.signals
    v, a, f = s["velocity"], s["acceleration"], s["force"]
    drag = f - r.values["inertia"] * a
    if s.get("restoring") is not None:
        drag = drag - r.values.get("restoring", 0.0) * s["restoring"]
    fig, ax = plt.subplots(figsize=(6, 4.2))
    ok = np.isfinite(v) & np.isfinite(drag)
    ax.plot(v[ok][::3], drag[ok][::3], ".", ms=2, alpha=0.35, color="0.5", label="tau - M nu_dot (samples)")
    if s.get("windows"):
        wv, wf = zip(*s["windows"])
        ax.plot(wv, wf, "s", color="C3", label="steady-window means ([Hindrax-Drag])")
    vmax = float(np.nanmax(np.abs(v[ok]))) if np.any(ok) else 1.0
    grid = np.linspace(-vmax, vmax, 201)
    rest = model_terms(r.dof, grid, np.zeros_like(grid))
    names = list(r.names)[1:]
    theta = np.array([r.values[n] for n in names])
    curve = rest @ theta
    cov = np.asarray(s.get("covariance"))
    if cov.ndim == 2 and cov.shape[0] == len(r.names):
        c = cov[1:, 1:]
        sd = np.sqrt(np.clip(np.einsum("ij,jk,ik->i", rest, c, rest), 0.0, None))
        tcrit = float(stats.t.ppf(0.975, max(r.residual_dof, 1)))
        ax.fill_between(grid, curve - tcrit * sd, curve + tcrit * sd, color="C0", alpha=0.3, label="95 % band")
    ax.plot(grid, curve, "C0", label="fit k_q|v|v + k_l v + b")
    rot = r.dof in ("roll", "pitch", "yaw")
    ax.set_xlabel(f"{r.dof} velocity ({'rad/s' if rot else 'm/s'})")
    ax.set_ylabel(f"{'moment (N m)' if rot else 'force (N)'}")
    ax.set_title(f"{r.dof}: force vs velocity ({r.method})")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)
    _save(fig, path)


def _rls_plot(r, path: Path) -> bool:
    h = r.signals.get("online_history") or {}
    if not h or not h.get("t"):
        return False
    t = np.asarray(h["t"]) - h["t"][0]
    th = np.asarray(h["theta"])
    sd = np.asarray(h["std"])
    n = th.shape[1]
    fig, axes = plt.subplots(n, 1, figsize=(6, 1.6 * n), sharex=True)
    banded = 0  # parameters with a band drawn: the title says whether the promised band is there
    for i, name in enumerate(r.names):
        ax = axes[i]
        ax.plot(t, th[:, i], "C0", lw=1)
        band, known = 1.96 * sd[:, i], np.isfinite(sd[:, i])  # NaN before the RLS has a noise estimate
        if known.any():
            banded += 1
            ax.fill_between(t, th[:, i] - band, th[:, i] + band, where=known, color="C0", alpha=0.3)
            for edge in (th[:, i] - band, th[:, i] + band):  # a band narrower than the line stays visible
                ax.plot(t, np.where(known, edge, np.nan), "C0", lw=0.5, ls=":")
        ax.axhline(r.values[name], color="C2", ls="--", lw=1, label="offline")
        tr = r.truth.get(name)
        if tr is not None:
            ax.axhline(tr, color="k", ls=":", lw=1, label="configured")
        ax.set_ylabel(name.replace("_damping", "").replace("_", " "), fontsize=7)
        lo, hi = np.nanpercentile(th[len(th) // 5:, i], [2, 98]) if len(th) > 5 else (None, None)
        if lo is not None and np.isfinite(lo):
            span = max(hi - lo, 0.2 * abs(r.values[name]) + 1e-3)
            ax.set_ylim(min(lo, r.values[name]) - 0.5 * span, max(hi, r.values[name]) + 0.5 * span)
    axes[0].legend(fontsize=6)
    axes[0].set_title(f"{r.dof}: RLS convergence " + (f"(shaded: +-1.96 std, {banded} of {n} parameters)" if banded
                                                      else "(no std yet: no band)"))
    axes[-1].set_xlabel("time in the DOF's manoeuvres (s)")
    _save(fig, path, dpi=80)
    return True


def _fmt(x, digits: int = 4) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    return f"{x:.{digits}g}"


def _head(title: str) -> str:
    """The start of a report page, up to ``<body>``: its title and the reports' one style."""
    return (f"<!doctype html><html><head><meta charset='utf-8'><title>{title}</title><style>"
            "body{font-family:sans-serif;max-width:1150px;margin:auto}"
            " table{border-collapse:collapse} td,th{border:1px solid #ccc;padding:2px 6px;"
            "font-size:13px;text-align:right}</style></head><body>")


def _table(headers: Sequence[str], rows: Iterable[Iterable[Any]]) -> str:
    """An HTML table: the header row, then a row per item of ``rows`` (each cell str(), escaped)."""
    def row(tag: str, cells: Iterable[Any]) -> str:
        return "<tr>" + "".join(f"<{tag}>{html.escape(str(c))}</{tag}>" for c in cells) + "</tr>"
    return "<table>" + row("th", headers) + "".join(row("td", r) for r in rows) + "</table>"


def _advice_table(advice: Iterable[tuple[str, Mapping]]) -> str:
    """What data would fix the suspect parameters (:func:`.verdicts.data_advice`), a row per (label, advice)."""
    heads = ("parameter", "runs", "manoeuvre", "speeds", "pool time, min", "in the data, s", "why")
    return _table(heads, ((label, f"{a.get('runs', '-')} {a.get('run_kind', '')}", a["manoeuvre"],
                           "{:g}-{:g} {}".format(*a["speed_range"]), a.get("minutes", "-"),
                           a["seconds_in_data"], a["why"]) for label, a in advice))


#: The manoeuvres that use a thruster group's two rotation directions equally (docs/identification.md §6.1).
_USES_MEAN = {"horizontal": "surge, sway, yaw use this", "vertical": "roll, pitch use this",
              "common": "surge, sway, yaw, roll, pitch use this"}


def references_html(document: Mapping) -> str:
    """The "References" section: the known-force calibration (``document["calibration"]``), the
    jointly estimated thrust scales (``document["joint"]["scales"]``: posterior, prior, steps, the error the
    uncalibrated self-propelled values would have and z against the curve), the free-decay inertias
    (``document["free_decay"]``) beside the self-propelled ones with z and verdict, and per DOF the empirical priors
    ([NTNU-Thesis] App. A, ``dofs.<dof>.prior``) beside the identified values, with the ratio and
    whether the prior lies inside the identified 95 % interval. Empty string when the document has none of them."""
    rows = []
    cal = document.get("calibration") or {}
    for name, c in (cal.get("steps") or cal).items():
        if isinstance(c, Mapping) and "value" in c and "known_force_n" in c:
            rows.append((name, _fmt(c.get("value")), _fmt(c.get("std"), 2),
                         _fmt(c.get("known_force_n")), c.get("method", ""),
                         c.get("holding_force_n", "")))
    parts = []
    if rows:
        parts.append("<h3>Known-force calibration</h3>" + _table(
            ("scale", "value", "std", "known force (N)", "method", "holding force (N)"), rows)
            + (f"<p>{html.escape(str(cal['applied_to']))}</p>" if cal.get("applied_to") else ""))
    joint = document.get("joint") or {}
    srow = []
    scales = {**(joint.get("scales") or {}), **(joint.get("group_means") or {})}
    for name, j in scales.items():
        v, sd = float(j["value"]), float(j["std"])
        z = (v - 1.0) / sd if sd > 0 else math.nan
        off = 1.0 / v - 1.0 if v > 0 else math.nan
        if "prior" in j:  # a scale (else a group's mean of its two directions)
            steps = "; ".join(f"{m['step']} {_fmt(m['value'])} +- {_fmt(m['std'], 2)}"
                              for m in j.get("measurements", []))
            prior = f"{_fmt(j['prior'][0], 3)} +- {_fmt(j['prior'][1], 2)}"
            head = (name, prior, steps, ", ".join(j.get("dofs", [])))
        else:
            head = (f"{name} mean of both directions", "-", "-", _USES_MEAN.get(name, ""))
        verdict = "curve off" if abs(z) > 1.96 else "curve agrees"
        srow.append((head[0], _fmt(v), _fmt(sd, 2), *head[1:], f"{100 * off:+.1f} %", _fmt(z, 3), verdict))
    if srow:
        parts.append("<h3>Thrust scales estimated jointly (docs/identification.md §6.2)</h3><p>posterior of each scale "
                     "s (true thrust / curve thrust, per thruster group and rotation direction) from its prior and the "
                     "calibration steps; the self-propelled values without the calibration would be off by 1/s - 1; "
                     "z = (s - 1) / std (|z| > 1.96: the thrust curve disagrees with the known forces)</p>" + _table(
                         ("scale", "value", "std", "prior", "steps", "DOFs", "uncalibrated error",
                          "z", "verdict"), srow))
    frow = []
    for dof, fd in (document.get("free_decay") or {}).items():
        sp = fd.get("self_propelled") or {}
        frow.append((dof, _fmt(fd.get("total_inertia_kg_m2")),
                     _fmt(fd.get("total_inertia_kg_m2_std"), 2),
                     _fmt(fd.get("added_inertia_kg_m2")),
                     _fmt(fd.get("stiffness_n_m_per_rad")), fd.get("stiffness_source", ""),
                     _fmt(sp.get("inertia_kg_m2")), _fmt(sp.get("inertia_kg_m2_std"), 2),
                     _fmt(sp.get("z"), 3), sp.get("verdict", "-")))
    if frow:
        parts.append("<h3>Free decay: rigid + added inertia without the thrust curve ([Hindrax-AM], "
                     "[SmallROV])</h3><p>suspect: |free decay - self-propelled| beyond 1.96 combined std "
                     "(the self-propelled inertia then carries verdict suspect)</p>" + _table(
                         ("DOF", "free-decay inertia (kg m^2)", "std", "added",
                          "stiffness (N m/rad)", "stiffness from", "self-propelled", "std", "z",
                          "verdict"), frow))
    prow = []
    for dof, e in (document.get("dofs") or {}).items():
        prior = e.get("prior") if isinstance(e, Mapping) else None
        if not prior:
            continue
        for kind in ("added_mass", "linear_damping", "quadratic_damping"):
            names = [n for n in e if isinstance(e.get(n), Mapping) and "value" in e[n]
                     and (n == kind or n.startswith(kind + "_"))]
            for n in names:
                p, par = prior.get(kind), e[n]
                lo, hi = (par.get("ci95") or [math.nan, math.nan])[:2]
                ratio = p / par["value"] if (p is not None and par["value"]) else math.nan
                inside = "-" if p is None else ("inside" if lo <= p <= hi else "outside")
                prow.append((dof, n, _fmt(par["value"]), f"[{_fmt(lo)}, {_fmt(hi)}]", _fmt(p), _fmt(ratio, 3), inside))
    if prow:
        parts.append("<h3>Empirical priors from geometry ([NTNU-Thesis] App. A.1/A.2)</h3><p>rough "
                     "estimates (the thesis reports differences of tens of percent against panel codes and CFD); "
                     "a prior outside the identified interval is expected and is not a verdict; in the batch fit each "
                     f"weighs with 1-sigma {_fmt((document.get('joint') or {}).get('prior_std_rel'), 3)} x its value "
                     "(identification.prior_std_rel)</p>" + _table(
                         ("DOF", "parameter", "identified", "95 % interval", "prior",
                          "prior / identified", "prior in interval"), prow))
    if not parts:
        return ""
    return "<h2>References (independent of the thrust curve)</h2>" + "".join(parts)


def write_report(out_dir: str | Path, identifications: Mapping[str, Any], document: Mapping,
                 campaign_note: str = "") -> Path:
    """Write ``out_dir/index.html`` and the PNGs; returns the index path."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    parts = [_head("Hindrax identification"), "<h1>Hindrax hydrodynamic identification</h1>"]
    prov = document.get("provenance", {})
    # a nested value (the vehicle_parameters the fit used: 60-odd keys) folded as YAML, not a Python dict
    parts.append("<p>" + "<br>".join(
        f"<b>{html.escape(str(k))}</b>: " + (
            f"<details><summary>{len(v)} values</summary><pre>"
            f"{html.escape(yaml.safe_dump(v, sort_keys=False, default_flow_style=None))}</pre></details>"
            if isinstance(v, (dict, list)) else html.escape(str(v))) for k, v in prov.items()) + "</p>")
    if campaign_note:
        parts.append(f"<p>{html.escape(campaign_note)}</p>")
    dofs = document["dofs"]
    parts.append("<h2>Summary</h2>" + _table(
        ("DOF", "parameter", "value", "std", "unit", "95 % interval", "configured", "rel. error",
         "equation-error LS", "RLS", "steady-state LS", "verdict", "reasons"),
        ((r["dof"], r["parameter"], _fmt(r["value"]), _fmt(r["std"], 2), r["unit"],
          f"[{_fmt(r['ci95'][0])}, {_fmt(r['ci95'][1])}]" if r["at_bound"] is None
          else f"none: at its bound {r['at_bound']:g}", _fmt(r["truth"]),
          "-" if not math.isfinite(r["relative_error"]) else f"{100 * r['relative_error']:+.2f} %",
          _fmt(r["equation_error"]), _fmt(r["rls"]), _fmt(r["steady"]), r["verdict"],
          "; ".join(r["reasons"])) for r in summary_rows(identifications))))
    parts.append("<p>" + "<br>".join(html.escape(f"{dof}: {line}") for dof, e in dofs.items()
                                     for line in training_lines(e.get("training"))) + "</p>")
    for dof, r in identifications.items():
        a = r.signals.get("assessment")
        if a:
            parts.append(f"<h2>{html.escape(dof)}: {a['verdict']}</h2>" + (
                "<ul>" + "".join(f"<li>{html.escape(x)}</li>" for x in a["reasons"]) + "</ul>" if a["reasons"] else
                "<p>no DOF-wide check failed</p>") + (
                "<p>intervals: joint covariance of the fit, the calibrated thrust scale "
                f"{html.escape(str((r.signals.get('joint') or {}).get('scale_parameter')))} and the priors "
                "(docs/identification.md §6.2)" if (r.signals.get("joint") or {}).get("thrust_in_covariance") else
                "<p>intervals: fit covariance + thrust-curve uncertainty "
                f"{a['checks'].get('thrust_uncertainty_rel')} (1-sigma, [negative, positive])")
                + f", Student t with {a['parameters']['inertia'].get('t_dof', '-')} degrees of freedom (clusters of "
                "segments - 1, docs/identification.md §7)</p>")
            adv = [(n, e["advice"]) for n, e in a["parameters"].items() if e.get("advice")]
            if adv:
                parts.append(_advice_table(adv))
        parts.append(f"<h2>{html.escape(dof)}</h2><p>method {html.escape(r.method)}; pool time {r.pool_time_s:.0f} s; "
                     f"RLS converged after {_fmt(r.rls_time_s, 3)} s; steady-state: {html.escape(r.steady_note)}</p>")
        fv = out / f"{dof}_force_velocity.png"
        _force_velocity_plot(r, fv)
        parts.append(f"<img src='{fv.name}' alt='{dof} force vs velocity'>")
        rl = out / f"{dof}_rls.png"
        if _rls_plot(r, rl):
            parts.append(f"<img src='{rl.name}' alt='{dof} RLS convergence'>")
    parts.append(references_html(document))
    parts.append("</body></html>")
    index = out / "index.html"
    index.write_text("\n".join(parts))
    return index


def write_outputs(out: Path, idents: dict, cfg: VehicleConfig, bag_path: str | Path | None, note: str,
                  source: str = "bag", seed: int | None = None, calibration: dict | None = None, sections=None) -> Path:
    """identification.yaml (provenance names the bag, when there is one) and report/index.html in ``out``; returns
    the yaml path.

    calibration: the record's calibration steps (``record.calibration`` of :func:`~.pipeline.identify_bag`):
    the thrust scales are estimated jointly with the fits and identification.yaml gets the ``calibration`` and ``joint``
    sections (:func:`~.results.build_results`). sections(doc): optional, adds further sections (e.g. ``inclining`` and
    ``free_decay``) before the file and the report are written."""
    doc = build_results(idents, cfg, source=source, seed=seed, calibration=calibration or None)
    if bag_path is not None:
        doc["provenance"]["bag"] = str(bag_path)
    if sections is not None:
        sections(doc)
    path = write_identification(out / "identification.yaml", doc)
    write_report(out / "report", idents, doc, campaign_note=note)
    return path


# ------------------------------------------------------------------------------------------------ any topics
def _num(x) -> str:
    """A score with 3 decimals; ``-`` for a missing or non-finite one (never ``nan`` in a table)."""
    return "-" if x is None or not np.isfinite(float(x)) else f"{float(x):.3f}"


def _plot(r, path: Path, h: float) -> None:
    p = r.plot
    meas, pred = p["measured"], p["predicted"]
    m, L = meas.shape
    fig, ax = plt.subplots(figsize=(11, 3.2))
    for i in range(min(m, 12)):  # at most 12 segments: 2 minutes
        t = (i * L + np.arange(L)) * h
        ax.plot(t, meas[i], "k.", ms=2, label="measured (smoothed)" if i == 0 else None)
        ax.plot(t, pred[i], "C1-", lw=1.2, label="predicted (open loop from the segment start)" if i == 0 else None)
        ax.plot(t, np.full(L, meas[i, 0]), "C2:", lw=1, label="held initial value" if i == 0 else None)
        ax.axvline(t[0], color="0.85", lw=0.8)
    _save_velocity_plot(fig, ax, r.dof, "validation time, s (segments end to end)", f"{r.dof}: {p['data']} data", path)


def _save_velocity_plot(fig, ax, dof: str, xlabel: str, title: str, path: Path) -> None:
    """Label a velocity-over-time plot of ``dof`` (its unit, FRD), add the legend and title, write it to ``path``
    and close it."""
    unit = "rad/s" if dof in ("roll", "pitch", "yaw") else "m/s"
    ax.set_xlabel(xlabel)
    ax.set_ylabel(f"{dof} velocity, {unit} (FRD)")
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title(title)
    _save(fig, path)


def _residuals(r) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(time s, segment, residual measured - predicted, measured) at the validation measurements of a fitted DOF's
    plot data (its :class:`..fit.fit_core.SegmentData`), in time order within each segment."""
    sd = r.plot["segments"]
    pred = r.plot["predicted"]
    p = fit_core.at_samples(sd, pred)
    t = sd.span[sd.s_seg, 0] + (sd.s_j + sd.s_a) * sd.h
    order = np.lexsort((t, sd.s_seg))
    return t[order], sd.s_seg[order], (sd.s_z - p)[order], sd.s_z[order]


def _time_plot(r, path: Path) -> None:
    """Measured (each sample) against predicted (open loop from each segment's start) over the record time, the
    first 120 s of validation segments."""
    sd = r.plot["segments"]
    pred = r.plot["predicted"]
    t, seg, _res, z = _residuals(r)
    fig, ax = plt.subplots(figsize=(11, 3.2))
    t_first = float(sd.span[0, 0]) if sd.m else 0.0
    for i in range(sd.m):
        if sd.span[i, 0] - t_first > 120.0:
            break
        ti = sd.span[i, 0] + np.arange(sd.L) * sd.h
        keep = ti <= sd.span[i, 1] + 1e-9
        ax.plot(ti[keep], pred[i, keep], "C1-", lw=1.2, label="predicted (open loop from the segment start)"
                if i == 0 else None)
        sel = seg == i
        ax.plot(t[sel], z[sel], "k.", ms=2, label="measured" if i == 0 else None)
        ax.axvline(ti[0], color="0.85", lw=0.8)
    _save_velocity_plot(fig, ax, r.dof, "record time, s",
                        f"{r.dof}: {r.plot['data']} data over time (the first 120 s)", path)


def residual_acf(seg: np.ndarray, res: np.ndarray, max_lag: int) -> np.ndarray:
    """Autocorrelation (max_lag + 1,) of the residuals at lags of 0..max_lag measurements, pairs taken within one
    segment only (a segment restarts the prediction), normalised by the lag-0 sum."""
    res = res - np.mean(res)
    den = float(np.sum(res * res))
    out = np.zeros(max_lag + 1)
    if den <= 0:
        return out
    for k in range(max_lag + 1):
        same = seg[k:] == seg[:res.size - k]
        out[k] = float(np.sum((res[k:] * res[:res.size - k])[same])) / den
    return out


def _acf_plot(r, path: Path) -> None:
    """Residual autocorrelation of the validation predictions up to 5 s, with the white-noise 95 % band."""
    t, seg, res, _z = _residuals(r)
    dt = float(np.median(np.diff(t)[np.diff(seg) == 0])) if res.size > 2 else 0.1
    max_lag = max(1, min(int(round(5.0 / dt)), res.size // 4))
    acf = residual_acf(seg, res, max_lag)
    fig, ax = plt.subplots(figsize=(6, 3))
    ax.bar(np.arange(max_lag + 1) * dt, acf, width=0.8 * dt, color="C0")
    band = 1.96 / np.sqrt(max(res.size, 1))
    ax.axhspan(-band, band, color="0.85", label="95 % band of white residuals")
    ax.set_xlabel("lag, s")
    ax.set_ylabel("autocorrelation")
    ax.set_title(f"{r.dof}: residuals of the {r.plot['data']} predictions")
    ax.legend(loc="upper right", fontsize=8)
    _save(fig, path)


def _parameter_plot(doc: dict, cfg, path: Path) -> bool:
    """Each identified parameter with its 95 % interval against the vehicle file's value, both divided by the
    larger magnitude of the two (one axis for every unit); False without a vehicle file."""
    if cfg is None:
        return False
    rows = []
    for dof, e in doc["dofs"].items():
        ref = truth_parameters(cfg, dof)
        for name, p in e.items():
            if not isinstance(p, dict) or "value" not in p or p.get("model_term") == "excluded" or name not in ref:
                continue
            s = max(abs(ref[name]), abs(p["value"]), 1e-12)
            rows.append((f"{dof} {name}", p["value"] / s, p["ci95"][0] / s, p["ci95"][1] / s, ref[name] / s,
                         "at_bound" in p, f"{p['value']:.3g} vs {ref[name]:.3g} {p['unit']}"))
    if not rows:
        return False
    fig, ax = plt.subplots(figsize=(9, 0.35 * len(rows) + 1.2))
    for i, (label, v, lo, hi, rf, bound, text) in enumerate(rows):
        if bound:
            ax.plot([v], [i], "C3s", ms=5)  # at its bound: no interval
        else:
            ax.errorbar([v], [i], xerr=[[v - max(lo, -3.0)], [min(hi, 3.0) - v]], fmt="C0o", ms=4, capsize=3)
        ax.plot([rf], [i], "kx", ms=7)
        ax.text(3.1, i, text, va="center", fontsize=7)
    ax.set_yticks(range(len(rows)), [r[0] for r in rows], fontsize=8)
    ax.set_xlim(-3.0, 3.0)
    ax.axvline(0.0, color="0.85", lw=0.8)
    ax.set_xlabel("value / max(|identified|, |vehicle file|): identified with its 95 % interval (o), vehicle file (x)")
    _save(fig, path)
    return True


def write_fit_outputs(out: str | Path, res, doc: dict, cfg=None) -> tuple[Path, Path]:
    """Write ``out/identification.yaml`` (``doc``, :func:`.results.build_document`) and ``out/report/index.html``;
    returns both paths."""
    out = Path(out)
    rep = out / "report"
    rep.mkdir(parents=True, exist_ok=True)
    path = write_identification(out / "identification.yaml", doc)
    dofs = doc["dofs"]
    params = [(dof, name, p) for dof, e in dofs.items() for name, p in e.items()
              if isinstance(p, dict) and "value" in p]
    parts = [_head("hindrax ident fit"), "<h1>Identification from bags (hindrax ident fit)</h1>",
             f"<p>{html.escape(res.design)}</p><h2>Parameters</h2>" + _table(
                 ("DOF", "parameter", "value", "std", "std from", "unit", "95 % interval",
                  "fold spread (std)", "verdict"),
                 ((dof, name, f"{p['value']:.4g}", f"{p['std']:.3g}",
                   p.get("std_source", p.get("model_term", "-")), p["unit"],
                   "[{:.4g}, {:.4g}]".format(*p["ci95"][:2]) if "at_bound" not in p
                   else f"none: at its bound {p['at_bound']:g}",
                   _fmt(p.get("fold_spread", {}).get("std"), 3), p.get("verdict", "-"))
                  for dof, name, p in params))]

    def candidates(e: Mapping) -> str:
        return "; ".join(f"{c['terms']}: {c['cv_nrmse']:.3f}" if c.get("cv_nrmse") is not None
                         else c["terms"] for c in e.get("model_selection", []))
    parts.append("<p>std: the cluster-robust (sandwich) covariance with contiguous blocks of segments as clusters, at "
                 "least the model-based one; 95 % intervals Student t with clusters - 1 degrees of freedom "
                 "(docs/identification.md §7).</p><h2>Model and timing</h2>" + _table(
                     ("DOF", "model (chosen by cross-validation)", "candidates: CV nrmse",
                      "delay, s", "lag, s", "clusters"),
                     ((dof, e.get("model", "-"), candidates(e), f"{e['timing']['delay_s']:.3f}",
                       f"{e['timing']['lag_s']:.3f}", e["interval"]["clusters"])
                      for dof, e in dofs.items())))
    parts.append("<p>" + "<br>".join(html.escape(f"{dof}: {line}") for dof, e in dofs.items()
                                     for line in training_lines(e.get("training"))) + "</p>")
    advice = [(f"{dof} {a['parameter']}", a) for dof, e in dofs.items() for a in e.get("advice", [])]
    if advice:
        parts.append("<h2>What data would fix the suspect parameters</h2>" + _advice_table(advice))
    if not doc.get("config_ready", True):
        parts.append(f"<p><b>config_ready: false</b>: {html.escape(doc['config_ready_reason'])}</p>")
    for dof, e in doc.get("not_identified", {}).items():
        parts.append(f"<p><b>{html.escape(dof)}</b>: {html.escape(e['status'])} ({html.escape(e['reason'])})</p>")
    parts.append("<h2>Validation</h2>" + _table(
        ("DOF", "data", "nrmse", "nrmse_hold", "nrmse_zero", "samples"),
        ((dof, key, _num(v["nrmse"]), _num(v.get("nrmse_hold")), _num(v.get("nrmse_zero")), v["samples"])
         for dof, r in res.dofs.items() for key, v in r.validation.items()
         if isinstance(v, dict) and "nrmse" in v)))
    parts.append("<p>nrmse = RMS(v_pred - v_meas) / std(v_meas) over the validation samples, v_pred simulated open "
                 "loop from the recorded force and re-initialised from the measured velocity at the start of each "
                 "segment; nrmse_hold: velocity held at the segment's initial value; nrmse_zero: 0.</p>")
    for dof, r in res.dofs.items():
        if r.status == "fitted" and r.plot:
            png = rep / f"{dof}_validation.png"
            _plot(r, png, res.preprocessing["grid_s"])
            parts.append(f"<h3>{html.escape(dof)}</h3><img src='{png.name}' alt='{dof} measured vs predicted'>")
            if "segments" in r.plot:
                for suffix, fn, alt in (("time", _time_plot, "measured and predicted over time"),
                                        ("residual_acf", _acf_plot, "residual autocorrelation")):
                    png = rep / f"{dof}_{suffix}.png"
                    fn(r, png)
                    parts.append(f"<img src='{png.name}' alt='{dof} {alt}'>")
    png = rep / "parameters_vs_vehicle_file.png"
    if _parameter_plot(doc, cfg, png):
        parts.append("<h2>Parameters against the vehicle file</h2>"
                     f"<img src='{png.name}' alt='parameters with their 95 % intervals against the vehicle file'>")
    parts.append("<h2>Preprocessing</h2><pre>" + html.escape(yaml.safe_dump(doc["preprocessing"], sort_keys=False))
                 + "</pre></body></html>")
    index = rep / "index.html"
    index.write_text("\n".join(parts))
    return path, index
