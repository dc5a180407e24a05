"""The campaign front-end of the fit core: a :class:`~..bag_input.campaign_record.CampaignRecord` read into one
:class:`~.fit_core.DofRecord` per DOF, fitted by :mod:`.fit_core`, reported as :class:`~.dof_model.DofIdentification`.

``hindrax run``, ``hindrax ident bag``, ``hindrax ident fit`` on a bag with the campaign's topics and the in-process
campaign identify with :func:`identify_all_with_errors`, with the same :class:`~.fit_core.CoreOptions` as
``hindrax ident fit``. What the campaign knows that an arbitrary bag does not (docs/identification.md §7, "The
campaign's topics"): the DOF windows (one chunk each, the thrust-model force of the widths the ESC wrote), the sensors
conditioned by RTS smoothers (:func:`_smooth_on_ticks`), the gyro bias left after the still window
(:func:`rate_bias_against_angle`), the design (``DofRecord.terms``, ``DofRecord.all_segments``) and the roll/pitch
restoring regressor s(eta) ([NTNU-Thesis] eq. 2.23) from the DVL attitude fused with the gyro
(:func:`_smoothed_roll_pitch`).

All quantities SI, body FRD; times in s of the record's clock."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hindrax_common.config import DOFS, VehicleConfig, or_default

from hindrax_onboard.estimation.filters import smooth_kinematics
from hindrax_onboard.estimation.least_squares import EstimationError, fit_linear_model
from hindrax_onboard.vehicle.fusion import smooth_with_acceleration, smooth_with_rate
from hindrax_onboard.vehicle.state import euler_rates
from hindrax_onboard.vehicle.uncertainty import measurement_settings
from . import fit_core
from hindrax_onboard.identification.model.dof_model import (DofIdentification, core_index, parameter_names,
                        parameter_units, regressor_matrix, restoring_regressor, rigid_inertia, steady_state_fit,
                        truth_parameters)

__all__ = ["CampaignSignals", "AccelerometerAid", "RateAid", "rate_bias_against_angle", "dof_record",
           "dof_records", "fit_dofs", "identification_of", "identify_all_with_errors", "identify_dof"]


@dataclass
class CampaignSignals:
    """The conditioned signals of one DOF's window (the comparisons and the report): t (n,) s; force (n,) the lagged
    thrust-model force and force_cmd (n,) the commanded one (N or N m); run_id (n,) (-1 outside runs); x, v, a (n,)
    the RTS-smoothed position (heave depth, m; zeros otherwise), velocity and acceleration; restoring (n,) s(eta) or
    None."""

    t: np.ndarray
    force: np.ndarray
    force_cmd: np.ndarray
    run_id: np.ndarray
    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    restoring: np.ndarray | None


def dof_record(record, dof: str, cfg: VehicleConfig) -> tuple[fit_core.DofRecord, CampaignSignals]:
    """The fit core's record of ``dof`` from a campaign record (module docstring) and its conditioned signals.

    Raises :class:`~hindrax_onboard.estimation.least_squares.EstimationError` when the DOF has no window of at least
    50 ticks or fewer than 20 sensor samples in it."""
    k = DOFS.index(dof)
    sl = record.dof_slice(dof)
    t = record.t_s[sl]
    if t.size < 50:
        raise EstimationError(f"{dof}: no manoeuvre data")
    force = np.asarray(record.wrench_frd[sl, k], dtype=float)
    force_cmd = np.asarray(record.wrench_cmd_frd[sl, k], dtype=float)
    ms = measurement_settings(cfg, dof)
    tm, zm = _log_matrix(record.sensors[ms["log"]], t[0] - 2.0, t[-1])
    zm = zm[:, ms["column"]]
    if np.sum(np.isfinite(zm)) < 20:
        raise EstimationError(f"{dof}: too few sensor samples")
    aid = None
    if ms["accel"] and record.sensors.get("accel"):
        ta, aa = _log_matrix(record.sensors["accel"], t[0] - 2.0, t[-1])
        aid = AccelerometerAid(ta, aa[:, k], ms["accel_std"], ms["accel_jerk_psd"])
    rr = None
    if dof in ("roll", "pitch"):
        roll_s, pitch_s, rate_bias = _smoothed_roll_pitch(record, cfg, t)
        rr = restoring_regressor(dof, roll_s, pitch_s)
        # the gyro bias left after the on-board still window, measured against the attitude: removed from the
        # measured rate too (roll and pitch angles stay small in each other's runs, so Euler rate ~ body rate)
        zm = zm - rate_bias[k - 3]
    elif dof == "yaw":
        # the same for yaw against the DVL heading (unwrapped): a rate bias b would otherwise appear as a moment
        # bias of about linear damping x b
        zm = zm - _yaw_rate_bias(record, t)
    x_s, v_s, a_s = _smooth_on_ticks(t, tm, zm, ms["measured"], ms["jerk_psd"], ms["std"], aid)
    if ms["measured"] != "position":
        x_s = np.zeros_like(v_s)
    inside = (tm >= t[0]) & (tm <= t[-1]) & np.isfinite(zm)
    chunk = fit_core.Chunk(force_cmd, v_s, x_s, a_s, (tm[inside] - t[0]) / record.tick_s, zm[inside], rr,
                           t0=float(t[0]), force_start=float(force[0]))
    rec = fit_core.DofRecord(dof, float(record.tick_s), ms["measured"], [chunk], "thrust_model",
                             float(record.time_constant_s), terms=fit_core.Terms("both", dof == "heave"),
                             all_segments=True)
    return rec, CampaignSignals(t, force, force_cmd, np.asarray(record.run_id[sl]), x_s, v_s, a_s, rr)


def dof_records(record, cfg: VehicleConfig, dofs=DOFS) -> tuple[dict, dict, dict]:
    """({dof: DofRecord}, {dof: CampaignSignals}, {dof: error message}) of every DOF of ``dofs``
    with a window in ``record`` (:func:`dof_record`)."""
    recs, sigs, errors = {}, {}, {}
    for dof in DOFS:
        if dof not in record.windows or dof not in dofs:
            continue
        try:
            recs[dof], sigs[dof] = dof_record(record, dof, cfg)
        except EstimationError as exc:
            errors[dof] = str(exc)
    return recs, sigs, errors


def identification_of(dof: str, cfg: VehicleConfig, core: fit_core.DofResult, sig, online=None) -> DofIdentification:
    """The campaign's :class:`DofIdentification` of one DOF from the fit core's result ``core`` (the reported values,
    covariance and intervals, unchanged) on the campaign reader's signals ``sig`` (:class:`CampaignSignals`), with the
    comparisons of :mod:`.dof_model` beside it (``online``: the online RLS estimator or its recorded history, or None).

    The values are in :func:`parameter_names` order: a damping term the chosen model leaves out is 0 with std 0,
    heave's one pair for both directions (chosen by cross-validation) gives both directions the same value; the
    covariance is mapped the same way (theta_full = A theta_core, cov_full = A cov A^T). ``added_mass`` = inertia -
    the rigid-body inertia, with the inertia's std."""
    names = parameter_names(dof)
    A = np.zeros((len(names), len(core.names)))
    for i, j in enumerate(core_index(names, list(core.names))):
        if j is not None:
            A[i, j] = 1.0
    theta = A @ core.theta
    cov = A @ core.covariance.cov @ A.T
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    tq = core.t_quantile
    values = {n: float(v) for n, v in zip(names, theta)}
    stds = {n: float(s) for n, s in zip(names, std)}
    values["added_mass"] = values["inertia"] - rigid_inertia(cfg, dof)
    stds["added_mass"] = stds["inertia"]
    ci = {n: (values[n] - tq * stds[n], values[n] + tq * stds[n]) for n in values}
    t, force = sig.t, sig.force
    X = regressor_matrix(dof, sig.a, sig.v, sig.restoring)
    ok = np.all(np.isfinite(X), axis=1) & np.isfinite(force)
    try:
        ee = fit_linear_model(X[ok], force[ok], names)
        equation_error = {n: (float(v), float(s)) for n, v, s in zip(names, ee.theta, ee.std)}
    except EstimationError:
        equation_error = {}
    tick = float(np.median(np.diff(t)))
    v_fit = np.full(t.size, np.nan)
    V = fit_core.predict_validation(core.train, core.chosen.layout, core.theta)
    starts = np.rint((core.train.span[:, 0] - t[0]) / tick).astype(int)
    for i, j0 in enumerate(starts):
        j1 = min(j0 + core.train.L, t.size)
        if 0 <= j0 < j1:
            v_fit[j0:j1] = V[i, :j1 - j0]
    steady, wins, note, t_end = steady_state_fit(dof, t, sig.v, force, sig.run_id, sig.restoring,
                                                 values.get("restoring", 0.0))
    res = online.result() if online is not None else {"parameters": {}, "converged_at_s": None}
    t0 = float(t[0])
    conv = res.get("converged_at_s")
    return DofIdentification(
        dof=dof, names=names, values=values, std=stds, ci95=ci, method="output-error",
        residual_dof=int(core.train.s_z.size - len(core.names)), equation_error=equation_error,
        online=res["parameters"], steady=steady, steady_note=note, truth=truth_parameters(cfg, dof),
        units=parameter_units(dof), pool_time_s=float(t[-1] - t0),
        rls_time_s=None if conv is None else float(conv - t0),
        steady_time_s=None if (steady is None or t_end is None) else float(t_end - t0),
        signals={"t": t, "velocity": sig.v, "acceleration": sig.a, "force": force, "velocity_fit": v_fit,
                 "restoring": sig.restoring, "windows": [(w.velocity_mean, float(np.mean(force[w.start:w.stop])))
                                                         for w in wins],
                 "residual_autocorrelation": core.covariance.residual_rho,
                 "input_correlation": core.covariance.input_corr, "t_dof": core.covariance.t_dof,
                 "covariance": cov, "model": core.terms.label, "core": core,
                 "online_history": online.history if online is not None else {}})


def fit_dofs(record, cfg: VehicleConfig, opts: fit_core.CoreOptions = fit_core.CoreOptions(),
             dofs=DOFS) -> tuple[dict, dict]:
    """({dof: (DofResult, CampaignSignals)}, {dof: error message}) of the DOFs of ``dofs`` run in ``record``: the
    campaign reader (:func:`dof_records`) and the fit core (:func:`~.fit_core.identify_dofs`; ``opts`` default the
    defaults of ``hindrax ident fit``), docs/identification.md §7. A DOF's result depends on the record to the end of
    its window only (each sensor log to a sample past it): a bag still being written gives it too."""
    recs, sigs, errors = dof_records(record, cfg, dofs)
    results, errs = fit_core.identify_dofs(recs, opts)
    errors.update(errs)
    return {d: (results[d], sigs[d]) for d in results}, errors


def identify_all_with_errors(record, cfg: VehicleConfig, opts: fit_core.CoreOptions = fit_core.CoreOptions(),
                             fitted: dict | None = None) -> tuple[dict, dict]:
    """({dof: DofIdentification}, {dof: error message}) for every DOF run in ``record``:
    :func:`fit_dofs` of the DOFs not in ``fitted`` (results of :func:`fit_dofs` already made, on
    the bag while it was written), then :func:`identification_of` with the record's online
    estimates."""
    fitted = dict(fitted or {})
    new, errors = fit_dofs(record, cfg, opts, [d for d in DOFS if d not in fitted])
    fitted.update(new)
    out = {dof: identification_of(dof, cfg, *fitted[dof], record.online.get(dof))
           for dof in DOFS if dof in fitted and dof in record.windows}
    return out, {d: errors[d] for d in DOFS if d in errors}


def identify_dof(record, dof: str, cfg: VehicleConfig, opts: fit_core.CoreOptions = fit_core.CoreOptions()
                 ) -> DofIdentification:
    """One DOF of :func:`identify_all_with_errors`. Raises
    :class:`~hindrax_onboard.estimation.least_squares.EstimationError` when the DOF has no usable data."""
    rec, sig = dof_record(record, dof, cfg)
    results, errors = fit_core.identify_dofs({dof: rec}, opts)
    if dof not in results:
        raise EstimationError(errors.get(dof, f"{dof}: no fit"))
    return identification_of(dof, cfg, results[dof], sig, record.online.get(dof))


# ------------------------------------------------------------------------------------------------ conditioning
@dataclass(frozen=True)
class AccelerometerAid:
    """An accelerometer record aiding the smoother (:func:`~hindrax_onboard.vehicle.fusion.smooth_with_acceleration`):
    sample times ``t_s`` (m,) s, ``acceleration`` (m,) along the DOF's axis (m/s^2), its noise ``std`` (m/s^2) and the
    aided model's white-jerk PSD ``jerk_psd`` (m^2/s^5)."""

    t_s: np.ndarray
    acceleration: np.ndarray
    std: float
    jerk_psd: float


@dataclass(frozen=True)
class RateAid:
    """A rate record aiding an angle smoother (:func:`~hindrax_onboard.vehicle.fusion.smooth_with_rate`): sample times
    ``t_s`` (m,) s, ``rate`` (m,) rad/s (Euler-angle rate of the smoothed angle) and its noise ``std`` (rad/s)."""

    t_s: np.ndarray
    rate: np.ndarray
    std: float


def _smooth_on_ticks(t_ticks, t_meas, z_meas, measured: str, jerk_psd: float, std: float,
                     aid: AccelerometerAid | RateAid | None = None):
    """RTS-smoothed (pos, vel, acc) (each (n,)) at the tick times ``t_ticks`` (n,) from measurements ``z_meas`` at
    their own times ``t_meas`` (m,): ``measured`` "position" or "velocity", noise ``std``, white-jerk PSD
    ``jerk_psd``; with an :class:`AccelerometerAid` the accelerometer-aided smoother, with a :class:`RateAid` the
    rate-aided one (``z_meas`` is then an angle), else :func:`~hindrax_onboard.estimation.filters.smooth_kinematics`.
    All records are merged on one time grid (microsecond keys)."""
    key_ticks = np.rint(np.asarray(t_ticks) * 1e6).astype(np.int64)
    key_meas = np.rint(np.asarray(t_meas) * 1e6).astype(np.int64)
    keys = np.union1d(key_ticks, key_meas)
    if aid is not None:
        key_aid = np.rint(np.asarray(aid.t_s) * 1e6).astype(np.int64)
        keys = np.union1d(keys, key_aid)
    z = np.full(keys.size, np.nan)
    z[np.searchsorted(keys, key_meas)] = z_meas
    if aid is None:
        pos, vel, acc = smooth_kinematics(keys * 1e-6, z, measured=measured, jerk_psd=jerk_psd, measurement_std=std)
    else:
        a = np.full(keys.size, np.nan)
        if isinstance(aid, AccelerometerAid):
            a[np.searchsorted(keys, key_aid)] = aid.acceleration
            pos, vel, acc = smooth_with_acceleration(keys * 1e-6, z, a, measured, std, aid.std, aid.jerk_psd)
        else:
            a[np.searchsorted(keys, key_aid)] = aid.rate
            pos, vel, acc = smooth_with_rate(keys * 1e-6, z, a, std, aid.std, jerk_psd)
    idx = np.searchsorted(keys, key_ticks)
    return pos[idx], vel[idx], acc[idx]


def rate_bias_against_angle(t_angle, angle, t_rate, rate) -> float:
    """Constant bias (rad/s) of a rate record against an angle record of the same axis: least squares of
    ``integral(rate) - angle = c + b (t - t0)`` at the angle times (the integral by the trapezoid rule at the rate
    times, interpolated). ``t_angle``, ``angle`` (m,), ``t_rate``, ``rate`` (n,); NaN samples ignored. Returns 0.0
    with fewer than 3 usable angle samples or a rate record that does not span them."""
    ta, a = np.asarray(t_angle, dtype=float), np.asarray(angle, dtype=float)
    tr, r = np.asarray(t_rate, dtype=float), np.asarray(rate, dtype=float)
    okr = np.isfinite(r) & np.isfinite(tr)
    tr, r = tr[okr], r[okr]
    if tr.size < 2:
        return 0.0
    ok = np.isfinite(a) & np.isfinite(ta) & (ta >= tr[0]) & (ta <= tr[-1])
    if ok.sum() < 3:
        return 0.0
    integral = np.concatenate([[0.0], np.cumsum(0.5 * (r[1:] + r[:-1]) * np.diff(tr))])
    y = np.interp(ta[ok], tr, integral) - a[ok]
    x = np.column_stack([np.ones(ok.sum()), ta[ok] - ta[ok][0]])
    return float(np.linalg.lstsq(x, y, rcond=None)[0][1])


def _attitude_and_euler_rates(record, t: np.ndarray):
    """(t_att (m,), rpy (m, 3), t_gyro (n,), Euler-angle rates (n, 3)) over ``t`` (n,) plus 2 s before: the attitude log
    and the gyro's body rates turned into Euler-angle rates (:func:`~...vehicle.state.euler_rates`) at the attitude
    interpolated to the gyro times. The rates are empty (0, 3) with fewer than 10 gyro or 2 attitude samples."""
    t0, t1 = t[0] - 2.0, t[-1]
    ta, rpy = _log_matrix(record.sensors["attitude"], t0, t1)
    tg, w = _log_matrix(record.sensors.get("gyro", []), t0, t1)
    if tg.size < 10 or ta.size < 2:
        return ta, rpy, np.zeros(0), np.zeros((0, 3))
    rpy_g = np.column_stack([np.interp(tg, ta, rpy[:, 0]), np.interp(tg, ta, rpy[:, 1]), np.zeros(tg.size)])
    return ta, rpy, tg, euler_rates(rpy_g, w)


def _log_matrix(log: list, t0: float, t1: float) -> tuple[np.ndarray, np.ndarray]:
    """(times (m,), values (m, k)) of a SensorState log within [t0, t1] (k = 6 when empty)."""
    if not log:
        return np.zeros(0), np.zeros((0, 6))
    t = np.array([s[0] for s in log])
    v = np.array([s[1] for s in log], dtype=float).reshape(len(log), -1)
    m = (t >= t0) & (t <= t1)
    return t[m], v[m]


def _yaw_rate_bias(record, t: np.ndarray) -> float:
    """Bias (rad/s) of the gyro's yaw Euler rate against the unwrapped DVL heading over ``t`` (n,) plus 2 s before
    (:func:`rate_bias_against_angle`); 0.0 without enough samples."""
    ta, rpy, tg, rates = _attitude_and_euler_rates(record, t)
    ok = np.isfinite(rpy[:, 2])
    if tg.size == 0 or ok.sum() < 3:
        return 0.0
    return rate_bias_against_angle(ta[ok], np.unwrap(rpy[ok, 2]), tg, rates[:, 2])


def _smoothed_roll_pitch(record, cfg: VehicleConfig, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Roll and pitch (rad) at the tick times ``t`` (n,) and the Euler-rate biases (2,) rad/s removed: the DVL-75
    attitude fused with the Euler-angle rates of the gyro (Fossen eq. 2.29, attitude interpolated to the gyro
    times; constant bias removed by :func:`rate_bias_against_angle`) by
    :func:`~hindrax_onboard.vehicle.fusion.smooth_with_rate` (the attitude alone, zero biases, when there is no gyro
    record). Angle noise from ``sensors.dvl75.attitude_noise_std_rad`` (default 0.005 rad), rate noise and white-jerk
    PSD those of the roll filter (:func:`~...vehicle.uncertainty.measurement_settings`)."""
    ta, rpy, tg, rates = _attitude_and_euler_rates(record, t)
    std_att = max(float(or_default(cfg.sensors.dvl75.attitude_noise_std_rad, 0.005)), 1e-4)
    if tg.size == 0:
        jerk = std_att ** 2 * 15.0 ** 6
        return (_smooth_on_ticks(t, ta, rpy[:, 0], "position", jerk, std_att)[0],
                _smooth_on_ticks(t, ta, rpy[:, 1], "position", jerk, std_att)[0], np.zeros(2))
    bias = np.array([rate_bias_against_angle(ta, rpy[:, i], tg, rates[:, i]) for i in (0, 1)])
    ms = measurement_settings(cfg, "roll")
    out = [_smooth_on_ticks(t, ta, rpy[:, i], "position", ms["jerk_psd"], std_att,
                            RateAid(tg, rates[:, i] - bias[i], ms["std"]))[0] for i in (0, 1)]
    return out[0], out[1], bias
