"""Outputs of ``hindrax ident fit``: identification.yaml and report/index.html (measured vs predicted velocity).

The plots use matplotlib's Agg backend as :mod:`.report`: per fitted DOF, the validation segments laid end to end
(the holdout bags when given, else the cross-validation folds), measured velocity, the model's open-loop prediction
from each segment's measured initial velocity, and the held initial value (what ``nrmse_hold`` measures); the same
measured against predicted over the record time; the autocorrelation of the validation residuals (pairs within a
segment, :func:`residual_acf`) with the 95 % band of white residuals; and, with a vehicle file, every parameter with
its 95 % interval against the vehicle file's value.
"""
from __future__ import annotations

import html
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import yaml  # noqa: E402

from ..fit.dof_model import truth_parameters  # noqa: E402

__all__ = ["write_fit_outputs", "residual_acf"]


def _num(x) -> str:
    """A score with 3 decimals; ``-`` for a missing or non-finite one (never ``nan`` in a table)."""
    return "-" if x is None or not np.isfinite(float(x)) else f"{float(x):.3f}"


def _plot(r, path: Path, h: float) -> None:
    p = r.plot
    meas, pred, valid = p["measured"], p["predicted"], p["valid"]
    m, L = meas.shape
    fig, ax = plt.subplots(figsize=(11, 3.2))
    for i in range(min(m, 12)):  # at most 12 segments: 2 minutes
        t = (i * L + np.arange(L)) * h
        ok = valid[i]
        ax.plot(t[ok], meas[i, ok], "k.", ms=2, label="measured (smoothed)" if i == 0 else None)
        ax.plot(t[ok], pred[i, ok], "C1-", lw=1.2,
                label="predicted (open loop from the segment start)" if i == 0 else None)
        ax.plot(t[ok], np.full(ok.sum(), meas[i, 0]), "C2:", lw=1, label="held initial value" if i == 0 else None)
        ax.axvline(t[0], color="0.85", lw=0.8)
    _save_velocity_plot(fig, ax, r.dof, "validation time, s (segments end to end)", f"{r.dof}: {p['data']} data",
                        path)


def _save_velocity_plot(fig, ax, dof: str, xlabel: str, title: str, path: Path) -> None:
    """Label a velocity-over-time plot of ``dof`` (its unit, FRD), add the legend and title, write it to ``path``
    and close it."""
    unit = "rad/s" if dof in ("roll", "pitch", "yaw") else "m/s"
    ax.set_xlabel(xlabel)
    ax.set_ylabel(f"{dof} velocity, {unit} (FRD)")
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _residuals(r) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(time s, segment, residual measured - predicted, measured) at the validation measurements of a fitted DOF's
    plot data (its :class:`..fit.fit_core.SegmentData`), in time order within each segment."""
    sd = r.plot["segments"]
    pred = r.plot["predicted"]
    j1 = np.minimum(sd.s_j + 1, sd.L - 1)
    p = pred[sd.s_seg, sd.s_j] * (1.0 - sd.s_a) + pred[sd.s_seg, j1] * sd.s_a
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
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


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
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return True


def write_fit_outputs(out: str | Path, res, doc: dict, cfg=None) -> tuple[Path, Path]:
    """Write ``out/identification.yaml`` (``doc``, :func:`..fit.fit_any.build_document`) and ``out/report/index.html``;
    returns both paths."""
    out = Path(out)
    rep = out / "report"
    rep.mkdir(parents=True, exist_ok=True)
    path = out / "identification.yaml"
    path.write_text("# Hindrax identified hydrodynamics (hindrax ident fit; hindrax_ident.identification.fit.fit_any)\n"
                    + yaml.safe_dump(doc, sort_keys=False, default_flow_style=None))
    parts = ["<!doctype html><html><head><meta charset='utf-8'><title>hindrax ident fit</title><style>body{"
             "font-family:sans-serif;max-width:1150px;margin:auto} table{border-collapse:collapse} td,th{border:1px "
             "solid #ccc;padding:2px 6px;font-size:13px;text-align:right}</style></head><body>",
             "<h1>Identification from bags (hindrax ident fit)</h1>",
             f"<p>{html.escape(res.design)}</p><h2>Parameters</h2><table><tr><th>DOF</th><th>parameter</th>"
             "<th>value</th><th>std</th><th>std from</th><th>unit</th><th>95 % interval</th><th>fold spread (std)</th>"
             "<th>verdict</th></tr>"]
    for dof, e in doc["dofs"].items():
        for name, p in e.items():
            if isinstance(p, dict) and "value" in p:
                sp = p.get("fold_spread", {}).get("std")
                parts.append("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in (
                    dof, name, f"{p['value']:.4g}", f"{p['std']:.3g}", p.get("std_source", p.get("model_term", "-")),
                    p["unit"], f"[{p['ci95'][0]:.4g}, {p['ci95'][1]:.4g}]" if "at_bound" not in p else
                    f"none: at its bound {p['at_bound']:g}", "-" if sp is None else f"{sp:.3g}",
                    p.get("verdict", "-"))) + "</tr>")
    parts.append("</table><p>std: the cluster-robust (sandwich) covariance with contiguous blocks of segments as "
                 "clusters, at least the model-based one; 95 % intervals Student t with clusters - 1 degrees of "
                 "freedom (docs/identification.md §7).</p><h2>Model and timing</h2><table><tr><th>DOF</th>"
                 "<th>model (chosen by cross-validation)</th><th>candidates: CV nrmse</th><th>delay, s</th>"
                 "<th>lag, s</th><th>clusters</th></tr>")
    for dof, e in doc["dofs"].items():
        cands = "; ".join(f"{c['terms']}: {c['cv_nrmse']:.3f}" if c.get("cv_nrmse") is not None else c["terms"]
                          for c in e.get("model_selection", []))
        parts.append("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in (
            dof, e.get("model", "-"), cands, f"{e['timing']['delay_s']:.3f}", f"{e['timing']['lag_s']:.3f}",
            e["interval"]["clusters"])) + "</tr>")
    parts.append("</table>")
    advice = [(dof, a) for dof, e in doc["dofs"].items() for a in e.get("advice", [])]
    if advice:
        parts.append("<h2>What data would fix the suspect parameters</h2><table><tr><th>parameter</th>"
                     "<th>runs</th><th>manoeuvre</th><th>speeds</th><th>pool time, min</th><th>in the data, s</th>"
                     "<th>why</th></tr>")
        for dof, a in advice:
            parts.append("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in (
                f"{dof} {a['parameter']}", f"{a.get('runs', '-')} {a.get('run_kind', '')}", a["manoeuvre"],
                f"{a['speed_range'][0]:g}-{a['speed_range'][1]:g} {a['speed_range'][2]}",
                a.get("minutes", "-"), a["seconds_in_data"], a["why"])) + "</tr>")
        parts.append("</table>")
    if not doc.get("config_ready", True):
        parts.append(f"<p><b>config_ready: false</b>: {html.escape(doc['config_ready_reason'])}</p>")
    for dof, e in doc.get("not_identified", {}).items():
        parts.append(f"<p><b>{html.escape(dof)}</b>: {html.escape(e['status'])} ({html.escape(e['reason'])})</p>")
    parts.append("<h2>Validation</h2><table><tr><th>DOF</th><th>data</th><th>nrmse</th><th>nrmse_hold</th>"
                 "<th>nrmse_zero</th><th>samples</th></tr>")
    for dof, r in res.dofs.items():
        for key, v in r.validation.items():
            if not isinstance(v, dict) or "nrmse" not in v:
                continue
            parts.append("<tr>" + "".join(f"<td>{c}</td>" for c in (
                dof, key, _num(v["nrmse"]), _num(v.get("nrmse_hold")), _num(v.get("nrmse_zero")), v["samples"]))
                + "</tr>")
    parts.append("</table><p>nrmse = RMS(v_pred - v_meas) / std(v_meas) over the validation samples, v_pred "
                 "simulated open loop from the recorded force and re-initialised from the measured velocity at the "
                 "start of each segment; nrmse_hold: velocity held at the segment's initial value; nrmse_zero: 0.</p>")
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
