"""Sensor samples in, wrench out: the campaign's conditioning around a hold (docs/control.md §5).

:class:`HoldLoop` owns a :class:`~hindrax_onboard.vehicle.state.SensorState` (depth of the body origin from the MS5837
with the lever arm, attitude, gyro, DVL velocity, Ping1D range) and a
:class:`~hindrax_onboard.vehicle.state.DepthEstimator` (depth and depth rate from the pressure fused with the vertical
acceleration), exactly as the identification executive does, and hands them to a hold
(:class:`~hindrax_onboard.control.maneuvers.HoldController` or :class:`~hindrax_onboard.control.legacy.LegacyPDHold`).
The controller node (:mod:`.node`) feeds it the samples of the driver topics (:mod:`hindrax_onboard.vehicle.signals`),
the evaluation (:mod:`hindrax_sim.control_evaluate`) those of the in-process simulator. Pure, no ROS.

Memory: the controller runs for hours, so the state's sample logs (``SensorState.log``, which the
identification executive keeps whole for its campaign record) are cut here to the last
:data:`LOG_HORIZON_S` seconds after every batch: the holds read only recent samples."""
from __future__ import annotations

import bisect
import math
from typing import Any, Iterable, Sequence

import numpy as np

from hindrax_common.config import VehicleConfig

from ..vehicle.state import DepthEstimator, SensorState
from ..vehicle.uncertainty import measurement_settings

__all__ = ["HoldLoop", "LOG_HORIZON_S"]

#: the span of samples the loop keeps in its state's logs, s (the newest sample of each log is always kept)
LOG_HORIZON_S = 5.0


class HoldLoop:
    """Conditioning + hold (module docstring). cfg: the vehicle file; hold: an object with the HoldController
    interface; tick_s: the control period (s)."""

    def __init__(self, cfg: VehicleConfig, hold: Any, tick_s: float) -> None:
        self.hold = hold
        self.tick_s = float(tick_s)
        self.state = SensorState(cfg)
        hv = measurement_settings(cfg, "heave")
        self.depth = DepthEstimator(hv["std"], hv["accel_std"], hv["accel_jerk_psd"])

    def add(self, samples: Iterable[tuple[str, Any]]) -> None:
        """Condition samples ``(device, sample)`` in stamp order (the simulator's or :mod:`..vehicle.signals`' form)."""
        for dev, s in sorted(samples, key=lambda x: x[1].stamp_s):
            self.state.on_sample(dev, s)
            self.depth.on_sample(dev, s.stamp_s, self.state)
        self._trim_logs()

    def _trim_logs(self) -> None:
        """Drop log samples older than :data:`LOG_HORIZON_S` before each log's newest one (module docstring)."""
        for log in self.state.log.values():
            if len(log) > 1:
                cut = bisect.bisect_left(log, log[-1][0] - LOG_HORIZON_S, hi=len(log) - 1, key=lambda e: e[0])
                if cut:
                    del log[:cut]

    def wrench(self, t_s: float, free: Sequence[str] = ()) -> np.ndarray:
        """FRD wrench (6,) of the hold for the tick at ``t_s`` (s)."""
        depth, rate = self.depth.predict_to(t_s)
        if math.isfinite(rate):
            self.hold.depth_rate_m_s = rate
            self.hold.depth_estimate_m = depth
        return np.asarray(self.hold.wrench(self.state, free, self.tick_s, t_s=t_s), dtype=float)
