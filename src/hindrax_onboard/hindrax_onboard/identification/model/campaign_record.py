"""The campaign record: everything an identification campaign produced, per control tick.

The executive (:class:`~..online.executive.Executive`) fills one while it runs; the bag reader
(:func:`~.from_bag.record_from_bag`) rebuilds one from a recorded campaign; the campaign reader of the fit
(:mod:`hindrax_fit.fit.campaign_fit`) reads either into the fit core's per-DOF records."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["CampaignRecord"]


@dataclass
class CampaignRecord:
    """Everything a campaign produced (arrays per control tick, shape (n,) or (n, k)).

    t_s: tick times (s). wrench_frd: thrust-model wrench at the tick (lagged), (n, 6) N / N m.
    wrench_cmd_frd: wrench of the commanded thrust held over the tick (n, 6). active: index of the DOF
    under test (-1 none). level: the test level commanded in a run (NaN outside runs). run_id: run counter
    (-1 outside runs). truth_position_ned_m / truth_euler_rad (n, 3): simulator truth, for tests and plots
    only (never used by control or estimation; NaN on the ROS graph). sensors: the conditioned sensor log of
    :class:`~hindrax_onboard.vehicle.state.SensorState`. windows: DOF -> (t_start, t_end). online: DOF ->
    OnlineDofEstimator. levels / authority: DOF -> ladder (N or N m) / (positive, negative) authority. aborted,
    abort_reason, wall_time_s, tick_s, time_constant_s, seed, final_pulse_width_us."""

    t_s: np.ndarray
    wrench_frd: np.ndarray
    wrench_cmd_frd: np.ndarray
    active: np.ndarray
    level: np.ndarray
    run_id: np.ndarray
    truth_position_ned_m: np.ndarray
    truth_euler_rad: np.ndarray
    sensors: dict
    windows: dict
    online: dict
    levels: dict
    authority: dict
    aborted: bool
    abort_reason: str
    wall_time_s: float
    tick_s: float
    time_constant_s: float
    seed: int
    final_pulse_width_us: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: known-force calibration results (:mod:`..online.steps.calibration_steps`): {key: {value, std, known_force_n,
    #: direction, group, holding_force_n, holding_force_std_n, forward_force_n, reverse_force_n, method}}, key
    #: vertical (ballast), vertical_negative (float), surge / sway (line pull +x / +y), surge_negative /
    #: sway_negative (-x / -y); empty without a calibration step
    calibration: dict = field(default_factory=dict)
    #: roll/pitch free decays (:class:`..online.steps.TiltDecay`): DOF -> (t_release, t_end), s
    decays: dict = field(default_factory=dict)
    #: inclining steps (:class:`..online.steps.Inclining`): DOF -> {value (C, N m/rad), std, known_moment_n_m,
    #: tilt_rad [without, with the mass], tilt_std_rad, method}; empty without the step
    inclining: dict = field(default_factory=dict)
    #: commanded thrust of every thruster held over each tick, (n, m) N (thrust model, along each thruster's
    #: direction; positive = forward rotation): the per-direction thrust scales are applied to it
    #: (:func:`~hindrax_fit.fit.calibration.apply_thrust_calibration`); (0, 0) when not recorded
    thrust_cmd_n: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))

    def dof_slice(self, dof: str) -> slice:
        """Tick index range of one DOF's manoeuvres (empty slice when it was not run)."""
        if dof not in self.windows:
            return slice(0, 0)
        t0, t1 = self.windows[dof]
        i0 = int(np.searchsorted(self.t_s, t0, side="left"))
        i1 = int(np.searchsorted(self.t_s, t1, side="right"))
        return slice(i0, i1)
