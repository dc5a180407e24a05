"""Closed-loop evaluation in the virtual pool: does the identified model hold depth, altitude and heading better?

``hindrax control evaluate --truth FILE --model YAML``; the manoeuvres, why they were chosen, the
fairness rules and the metrics are those of docs/control.md §6. The simulator runs in-process on a
truth that differs from the vehicle file (:mod:`hindrax_sim.truth`); the loop is the
campaign's (:class:`~..control.loop.HoldLoop`: sensor samples -> conditioning -> hold -> wrench ->
thrust allocation -> pulse widths -> thrusters) at the controller node's rate (``control.rate_hz``).
The manoeuvres (:data:`MANEUVERS`, their numbers in :class:`EvaluationSetup`): ``depth_step``,
``altitude_hold`` (over the floor profile ``floor_profile_m``,
:meth:`~hindrax_sim.pool.Pool.set_floor_profile`), ``altitude_gentle`` (a plane floor,
``gentle_floor_gradient``) and ``heading_step``; each with the holds of :data:`MODELS`:
``identified`` (the law of :mod:`..control.law` with the model of ``identification.yaml``),
``vehicle_file`` (the same law, the vehicle file's model) and ``pd_hold``
(:class:`~..control.legacy.LegacyPDHold`). Every hold is asked for the same specified response
(:class:`~..control.law.ReferenceModel` at the target bandwidth, with :func:`reference_limits`; the
altitude hold: the setpoint).

**Metrics** (SI; from the simulator's truth, never seen by the loop; over the window from the step
or the surge start): ``rmse`` (against the specified response; m, or rad for heading; altitude: the
noise-free Ping1D range), ``rmse_setpoint``, ``overshoot`` (beyond the final setpoint in the step's
direction; altitude: the largest |error|), ``settling_time_s`` (within ``settling_fraction`` of the
step, altitude ``altitude_band_m``) and ``effort_n_rms`` (RMS thrust per thruster, N)."""
from __future__ import annotations

import html
import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import matplotlib
import matplotlib.pyplot as plt
import numpy as np

from hindrax_common.base import frames
from hindrax_bringup.allocation.core import AllocationCore
from hindrax_common.config import DOFS, VehicleConfig
from hindrax_common.base.frames import wrap_angle

from hindrax_onboard.control.maneuvers import HoldController, dof_authority
from .simulator import Simulator
from .truth import Truth, with_floor_gradient, without_sensor_noise
from hindrax_onboard.control.law import ControlSettings, ReferenceModel
from hindrax_onboard.control.legacy import LegacyPDHold
from hindrax_onboard.control.loop import HoldLoop
from hindrax_onboard.control.model import ControlModel, model_from_config

__all__ = ["MANEUVERS", "ALTITUDE_MANEUVERS", "MODELS", "METRICS", "EvaluationSetup", "CaseResult", "run_case",
           "evaluate", "metrics", "summarise", "format_table", "write_outputs", "ratios", "make_hold",
           "reference_limits", "without_sensor_noise", "jsonable"]

MANEUVERS = ("depth_step", "altitude_hold", "heading_step", "altitude_gentle")
ALTITUDE_MANEUVERS = ("altitude_hold", "altitude_gentle")
MODELS = ("identified", "vehicle_file", "pd_hold")


@dataclass(frozen=True)
class EvaluationSetup:
    """The manoeuvres' numbers (module docstring). Positions NED in the pool frame (m), angles rad, speeds m/s,
    times s; ``floor_profile_m``: (x north, floor depth) breakpoints, m; ``sensor_noise`` False: the diagnostic
    without sensor noise (:func:`without_sensor_noise`)."""

    bandwidth_rad_s: float = 2.0
    velocity_gain: float = 1.5
    hold_fraction: float = 0.6
    settle_s: float = 12.0
    bias_window_s: tuple[float, float] = (2.0, 6.0)
    start_xy_m: tuple[float, float] = (5.0, 3.0)
    depth_start_m: float = 0.6
    depth_step_m: float = 0.3
    depth_after_s: float = 25.0
    heading_step_rad: float = math.radians(30.0)
    heading_after_s: float = 20.0
    altitude_m: float = 0.5
    floor_profile_m: tuple[tuple[float, float], ...] = ((3.5, 1.8), (4.4, 1.5), (10.0, 1.5 - 5.6 / 12.0))
    altitude_start_xy_m: tuple[float, float] = (2.0, 3.0)
    surge_speed_m_s: float = 0.4
    surge_s: float = 12.0
    altitude_after_s: float = 12.0
    gentle_floor_gradient: tuple[float, float] = (-0.08, 0.0)
    gentle_start_xy_m: tuple[float, float] = (2.5, 3.0)
    gentle_surge_speed_m_s: float = 0.3
    gentle_surge_s: float = 18.0
    settling_fraction: float = 0.05
    altitude_band_m: float = 0.02
    sensor_noise: bool = True


@dataclass
class CaseResult:
    """One manoeuvre with one hold: the time series (window only) and the metrics (module docstring)."""

    maneuver: str
    model: str
    t_s: np.ndarray
    value: np.ndarray
    spec: np.ndarray
    setpoint: np.ndarray
    thrust_n: np.ndarray
    metrics: dict = field(default_factory=dict)
    unit: str = "m"
    seed: int = 1


def _authority(cfg: VehicleConfig) -> np.ndarray:
    core = AllocationCore(cfg)
    return np.array([min(dof_authority(core, d)) for d in DOFS])


def reference_limits(cfg: VehicleConfig, setup: EvaluationSetup) -> dict:
    """The reference models' acceleration limits every hold and the specified response share: those the vehicle
    file's model gives (:class:`~..control.law.Controller`), so that no hold is asked for a different response."""
    return dict(HoldController(cfg, _authority(cfg), setup.bandwidth_rad_s, setup.hold_fraction,
                               model_from_config(cfg), setup.velocity_gain).core.reference_accel)


def make_hold(kind: str, cfg: VehicleConfig, setup: EvaluationSetup, model: ControlModel | None = None):
    """The hold of one :data:`MODELS` entry (``identified`` needs ``model``). Raises ``ValueError`` for an unknown
    kind."""
    if kind not in MODELS:
        raise ValueError(f"unknown model {kind!r}; one of {', '.join(MODELS)}")
    if kind == "identified" and model is None:
        raise ValueError("the identified hold needs a model")
    auth = _authority(cfg)
    if kind == "pd_hold":
        return LegacyPDHold(cfg, auth, setup.bandwidth_rad_s, setup.hold_fraction)
    law_model = model if kind == "identified" else model_from_config(cfg)
    return HoldController(cfg, auth, setup.bandwidth_rad_s, setup.hold_fraction, law_model,
                          setup.velocity_gain, reference_limits(cfg, setup))


def _true_altitude(sim: Simulator, ping_frd: np.ndarray) -> float:
    """Noise-free Ping1D range: from the altimeter along the body z axis to the floor (m)."""
    rot = sim.rotation
    return float(sim.pool.ray_distance_m(sim.position_ned_m + rot @ ping_frd, rot[:, 2]))


def run_case(cfg: VehicleConfig, truth: Truth, maneuver: str, hold, setup: EvaluationSetup = EvaluationSetup(),
             seed: int = 1, model_name: str = "") -> CaseResult:
    """Run one manoeuvre (module docstring) with ``hold`` on the simulator of ``truth``; returns the window's series
    and metrics. Raises ``ValueError`` for an unknown manoeuvre."""
    if maneuver not in MANEUVERS:
        raise ValueError(f"unknown manoeuvre {maneuver!r}; one of {', '.join(MANEUVERS)}")
    altitude = maneuver in ALTITUDE_MANEUVERS
    if maneuver == "altitude_gentle":
        truth = with_floor_gradient(truth, setup.gentle_floor_gradient)
    if not setup.sensor_noise:
        truth = without_sensor_noise(truth)
    sim = Simulator(cfg, seed=seed, truth=truth)
    dvl = sim.sensors.models.get("dvl75")
    if not setup.sensor_noise and dvl is not None:
        dvl.beam_range_noise_fraction = 0.0  # type: ignore[attr-defined]
    if maneuver == "altitude_hold" and sim.pool is not None:
        sim.pool.set_floor_profile(setup.floor_profile_m)
    start_xy, surge_speed, surge_s = ((setup.altitude_start_xy_m, setup.surge_speed_m_s, setup.surge_s)
                                      if maneuver == "altitude_hold" else
                                      (setup.gentle_start_xy_m, setup.gentle_surge_speed_m_s, setup.gentle_surge_s))
    rate = ControlSettings.from_config(cfg).rate_hz  # the key may be absent: its default
    steps = max(1, int(round(1.0 / (rate * sim.step_s))))
    tick = steps * sim.step_s
    ping = np.asarray(cfg.sensors.ping1d.position_frd_m, dtype=float)
    if altitude:
        x, y = start_xy
        z0 = sim.pool.floor_depth_m(x, y) - setup.altitude_m - ping[2]
    else:
        (x, y), z0 = setup.start_xy_m, setup.depth_start_m
    sim.reset(position_ned_m=[x, y, z0], rpy_rad=[0.0, 0.0, 0.0])
    pending: list = []
    sim.add_sensor_listener(lambda dev, s: pending.append((dev, s)))
    loop = HoldLoop(cfg, hold, tick)
    core = AllocationCore(cfg)
    reversed_ = np.array([t.reversed for t in cfg.thrusters.thrusters], dtype=bool)
    neutral = float(cfg.thrusters.pulse_width_neutral_us)
    hold.heading_setpoint_rad = 0.0
    hold.velocity_setpoint_m_s = np.zeros(2)
    if altitude and isinstance(hold, HoldController):
        hold.altitude_setpoint_m = setup.altitude_m
        hold.depth_setpoint_m = math.nan
    else:
        hold.depth_setpoint_m = z0
    t_event = setup.settle_s
    end = t_event + (surge_s + setup.altitude_after_s if altitude else
                     {"depth_step": setup.depth_after_s, "heading_step": setup.heading_after_s}[maneuver])
    limits = reference_limits(cfg, setup)
    settings = ControlSettings()
    spec_ref = ReferenceModel(setup.bandwidth_rad_s, 1.0,
                              (settings.max_yaw_rate_rad_s if maneuver == "heading_step"
                               else settings.max_depth_rate_m_s),
                              angle=maneuver == "heading_step",
                              max_accel=limits["yaw" if maneuver == "heading_step" else "heave"])
    initial = setup.altitude_m if altitude else {"depth_step": z0, "heading_step": 0.0}[maneuver]
    final = initial + (0.0 if altitude else
                       {"depth_step": setup.depth_step_m, "heading_step": setup.heading_step_rad}[maneuver])
    spec_ref.reset(initial)
    series: dict[str, list] = {k: [] for k in ("t", "v", "spec", "sp", "thrust")}
    dive_step = 0.25 * tick  # the campaign's dive: the PD depth setpoint moves at most 0.25 m/s towards its target
    t = 0.0
    n_ticks = int(round(end / tick))
    for _ in range(n_ticks):
        loop.add(pending)
        pending.clear()
        t = sim.t_s
        if setup.bias_window_s[0] <= t < setup.bias_window_s[0] + 0.5 * tick:
            loop.state.start_gyro_bias()
        if setup.bias_window_s[1] <= t < setup.bias_window_s[1] + 0.5 * tick:
            loop.state.finish_gyro_bias()
        after = t >= t_event - 1e-9
        sp = final if after else initial
        if maneuver == "depth_step":
            hold.depth_setpoint_m = sp
        elif maneuver == "heading_step":
            hold.heading_setpoint_rad = sp
        else:
            moving = after and t < t_event + surge_s
            hold.velocity_setpoint_m_s = np.array([surge_speed if moving else 0.0, 0.0])
            if not isinstance(hold, HoldController):  # today's altitude hold: the campaign's dive rule
                st = loop.state
                if math.isfinite(st.altitude_m) and math.isfinite(st.depth_m):
                    target = st.depth_m + st.altitude_m - setup.altitude_m
                    hold.depth_setpoint_m += float(np.clip(target - hold.depth_setpoint_m, -dive_step, dive_step))
        w = loop.wrench(t)
        alloc = core.allocate(frames.wrench_frd_to_flu(w))
        hold.note_allocation(frames.wrench_flu_to_frd(alloc.requested_wrench_flu),
                             frames.wrench_flu_to_frd(alloc.achieved_wrench_flu))
        pw = np.asarray(alloc.pulse_width_us, dtype=float)
        sim.advance(tick, np.where(reversed_, 2.0 * neutral - pw, pw))
        if after:
            spec_x = sp if altitude else spec_ref.step(sp, tick)[0]
            if maneuver == "depth_step":
                v = float(sim.position_ned_m[2])
            elif maneuver == "heading_step":
                v = float(sim.euler_rad[2])
            else:
                v = _true_altitude(sim, ping)
            series["t"].append(sim.t_s - t_event)
            series["v"].append(v)
            series["spec"].append(spec_x)
            series["sp"].append(sp)
            series["thrust"].append(sim.thrust_n)
    res = CaseResult(maneuver, model_name, np.asarray(series["t"]), np.asarray(series["v"]),
                     np.asarray(series["spec"]), np.asarray(series["sp"]), np.asarray(series["thrust"]),
                     unit="rad" if maneuver == "heading_step" else "m", seed=int(seed))
    res.metrics = metrics(res, setup, step=final - initial)
    return res


def metrics(res: CaseResult, setup: EvaluationSetup, step: float) -> dict:
    """RMSE against the specified response and the setpoint, overshoot, settling time and RMS thrust (module
    docstring) of one case's window."""
    angle = res.maneuver == "heading_step"
    err_spec = res.value - res.spec
    err_sp = res.value - res.setpoint
    if angle:
        err_spec = np.array([wrap_angle(e) for e in err_spec])
        err_sp = np.array([wrap_angle(e) for e in err_sp])
    if res.maneuver in ALTITUDE_MANEUVERS:
        overshoot = float(np.max(np.abs(err_sp))) if err_sp.size else math.nan
        band = setup.altitude_band_m
    else:
        direction = math.copysign(1.0, step) if step else 1.0
        overshoot = max(0.0, float(np.max(direction * err_sp))) if err_sp.size else math.nan
        band = setup.settling_fraction * abs(step)
    outside = np.flatnonzero(np.abs(err_sp) > band)
    settle = 0.0 if outside.size == 0 else float(res.t_s[min(outside[-1] + 1, res.t_s.size - 1)])
    if outside.size and outside[-1] == res.t_s.size - 1:
        settle = math.inf  # never settled inside the window
    return {"rmse": float(np.sqrt(np.mean(err_spec ** 2))), "rmse_setpoint": float(np.sqrt(np.mean(err_sp ** 2))),
            "overshoot": overshoot, "settling_time_s": settle,
            "effort_n_rms": float(np.sqrt(np.mean(res.thrust_n ** 2))) if res.thrust_n.size else math.nan}


def evaluate(cfg: VehicleConfig, truth: Truth, model: ControlModel, maneuvers: Sequence[str] = MANEUVERS,
             models: Sequence[str] = MODELS, setup: EvaluationSetup = EvaluationSetup(), seed: int = 1,
             progress: Callable[[str], None] | None = None, seeds: int = 1) -> list[CaseResult]:
    """Every manoeuvre with every hold (module docstring) for the noise seeds ``seed`` .. ``seed + seeds - 1``;
    ``model`` is the identified model."""
    out = []
    for sd in range(int(seed), int(seed) + max(1, int(seeds))):
        for m in maneuvers:
            for kind in models:
                hold = make_hold(kind, cfg, setup, model)
                r = run_case(cfg, truth, m, hold, setup, sd, kind)
                out.append(r)
                if progress:
                    k = r.metrics
                    progress(f"seed {sd} {m} / {kind}: rmse {k['rmse']:.4g} {r.unit}, overshoot {k['overshoot']:.3g} "
                             f"{r.unit}, settling {k['settling_time_s']:.2f} s, effort {k['effort_n_rms']:.2f} N rms")
    return out


METRICS = ("rmse", "rmse_setpoint", "overshoot", "settling_time_s", "effort_n_rms")


def summarise(cases: Sequence[CaseResult]) -> list[dict]:
    """One entry per (manoeuvre, hold), in run order: the mean of each metric over the seeds, its sample std
    (``<metric>_std``, 0 for one seed), ``seeds``, ``unit``."""
    groups: dict = {}
    for c in cases:
        groups.setdefault((c.maneuver, c.model), []).append(c)
    out = []
    for (m, kind), cs in groups.items():
        e = {"maneuver": m, "model": kind, "unit": cs[0].unit, "seeds": [c.seed for c in cs]}
        for k in METRICS:
            v = np.array([c.metrics[k] for c in cs], dtype=float)
            e[k] = float(np.mean(v))
            e[k + "_std"] = float(np.std(v, ddof=1)) if v.size > 1 and np.all(np.isfinite(v)) else 0.0
        out.append(e)
    return out


def ratios(summary: Sequence) -> dict:
    """Per manoeuvre: mean rmse of ``identified`` / ``vehicle_file`` and / ``pd_hold``, and the mean overshoot
    difference (identified - other, m or rad), where both exist. Takes :func:`summarise`'s entries (or cases)."""
    rows = summarise(summary) if summary and isinstance(summary[0], CaseResult) else list(summary)
    by = {(e["maneuver"], e["model"]): e for e in rows}
    out: dict = {}
    for m in MANEUVERS:
        ident = by.get((m, "identified"))
        if ident is None:
            continue
        row = {}
        for other in ("vehicle_file", "pd_hold"):
            o = by.get((m, other))
            if o is not None:
                row[f"rmse_vs_{other}"] = ident["rmse"] / o["rmse"] if o["rmse"] > 0 else math.nan
                row[f"overshoot_minus_{other}"] = ident["overshoot"] - o["overshoot"]
        out[m] = row
    return out


def format_table(cases: Sequence) -> str:
    """The cases (or :func:`summarise`'s entries) as a plain-text table, SI with cm and deg; the mean over the seeds
    with +- its std when there are several."""
    rows = summarise(cases) if cases and isinstance(cases[0], CaseResult) else list(cases)
    lines = [f"{'manoeuvre':14s} {'model':13s} {'rmse':>16s} {'rmse_sp':>10s} {'overshoot':>10s} {'settling_s':>10s} "
             f"{'effort_N':>9s}  seeds"]
    for e in rows:
        scale, unit = (180.0 / math.pi, "deg") if e["unit"] == "rad" else (100.0, "cm")
        sd = f"+-{e['rmse_std'] * scale:5.3f}" if len(e["seeds"]) > 1 else " " * 7
        lines.append(f"{e['maneuver']:14s} {e['model']:13s} {e['rmse'] * scale:6.3f} {sd} {unit:>3s} "
                     f"{e['rmse_setpoint'] * scale:6.3f} {unit:>3s} {e['overshoot'] * scale:6.3f} {unit:>3s} "
                     f"{e['settling_time_s']:10.2f} {e['effort_n_rms']:9.3f}  {len(e['seeds'])}")
    return "\n".join(lines)


def jsonable(x: Any) -> Any:
    """``x`` with every non-finite float (NaN, inf) as None, in nested dicts, lists and tuples
    (as lists): JSON has no NaN."""
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    return x


def write_outputs(out_dir: str | Path, cases: Sequence[CaseResult], info: Mapping[str, Any]) -> Path:
    """``control.json`` (``cases``, ``runs``, ``ratios``, ``info``) and ``report/index.html`` in ``out_dir``, as
    docs/control.md §6 lists them; a settling time that never came is null. Returns the control.json path."""
    out = Path(out_dir)
    (out / "report").mkdir(parents=True, exist_ok=True)
    summary = summarise(cases)
    doc = {"cases": jsonable(summary),
           "runs": [jsonable({"maneuver": c.maneuver, "model": c.model, "seed": c.seed, **c.metrics,
                              "unit": c.unit}) for c in cases],
           "ratios": jsonable(ratios(summary)), "info": jsonable(dict(info))}
    path = out / "control.json"
    path.write_text(json.dumps(doc, indent=2) + "\n")
    first = min(c.seed for c in cases) if cases else 1
    _report(out / "report", [c for c in cases if c.seed == first], info, summary)
    return path


def _report(folder: Path, cases: Sequence[CaseResult], info: Mapping[str, Any], summary: Sequence[dict]) -> None:
    matplotlib.use("Agg")
    colours = {"identified": "tab:green", "vehicle_file": "tab:orange", "pd_hold": "tab:red"}
    parts = ["<html><head><meta charset='utf-8'><title>Hindrax control evaluation</title></head><body>",
             "<h1>Closed-loop evaluation (hindrax control evaluate)</h1>",
             f"<pre>{html.escape(format_table(summary))}</pre>",
             "<pre>" + html.escape("\n".join(f"{k}: {v}" for k, v in info.items() if not isinstance(v, (dict, list))))
             + "</pre>"]
    for m in MANEUVERS:
        sel = [c for c in cases if c.maneuver == m]
        if not sel:
            continue
        fig, (ax, ax2) = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True, gridspec_kw={"height_ratios": [3, 1]})
        scale, unit = (180.0 / math.pi, "deg") if sel[0].unit == "rad" else (1.0, "m")
        ax.plot(sel[0].t_s, sel[0].setpoint * scale, "k:", lw=1, label="setpoint")
        ax.plot(sel[0].t_s, sel[0].spec * scale, "k--", lw=1, label="specified response")
        for c in sel:
            ax.plot(c.t_s, c.value * scale, color=colours.get(c.model), lw=1.2,
                    label=f"{c.model} (rmse {c.metrics['rmse'] * scale:.3g} {unit})")
            ax2.plot(c.t_s, np.sqrt(np.mean(c.thrust_n ** 2, axis=1)), color=colours.get(c.model), lw=1)
        ylabel = {"depth_step": "depth (m, down)", "altitude_hold": "altitude (m, Ping1D range, truth)",
                  "altitude_gentle": "altitude (m, Ping1D range, truth)", "heading_step": "heading (deg)"}[m]
        ax.set_ylabel(ylabel)
        if m == "depth_step":
            ax.invert_yaxis()
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
        ax2.set_ylabel("thrust rms (N)")
        ax2.set_xlabel("time from the step / surge start (s)")
        ax2.grid(alpha=0.3)
        fig.suptitle(m.replace("_", " "))
        fig.tight_layout()
        fig.savefig(folder / f"{m}.png", dpi=90)
        plt.close(fig)
        parts.append(f"<h2>{m}</h2><img src='{m}.png'>")
    parts.append("</body></html>")
    (folder / "index.html").write_text("\n".join(parts))


def setup_dict(setup: EvaluationSetup) -> dict:
    """The setup as a JSON-ready dict."""
    return jsonable(asdict(setup))

