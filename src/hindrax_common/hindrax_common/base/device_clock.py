"""Map a device's own clock onto ROS time (offset estimation by the minimum-latency filter).

A device that timestamps its reports (the DVL-75 ``$DVPDL`` field ``tu``, microseconds since the DVL
booted, docs/devices.md §1.3.1) gives better timing than the host's receive time: the receive time adds the
serial transmission time, the OS and reader-thread latency, and their jitter. The two clocks differ by an
unknown offset. Every report received at ROS time ``r_k`` with device time ``d_k`` satisfies

    r_k = d_k + offset + latency_k,   latency_k >= 0,

so ``min_k (r_k - d_k)`` over a window is an upper bound of ``offset`` that is tight to the smallest
latency seen (the classic one-way minimum-delay estimator used for sensor clock alignment). A sliding
window (default 10 s of device time) lets the estimate follow the drift between the two crystals
(50 ppm is 0.5 ms in 10 s). The estimate is re-initialised when

- the device clock goes backwards (device reboot or counter wrap), or
- ``resync_samples`` consecutive samples arrive more than ``jump_s`` *later* than the current offset
  predicts (ROS time jumped forward, e.g. a simulator restarted with ``use_sim_time``). A jump
  backwards needs no rule: the minimum follows it at the next sample.

Everything is integer nanoseconds (a float64 of ROS time in seconds only resolves about 0.2 us).
Pure code: no ROS, no clock reads."""
from __future__ import annotations

import collections
from typing import Deque, Optional, Tuple

__all__ = ["DeviceClockSync"]


class DeviceClockSync:
    """Estimate ``offset_ns`` with ``ros_ns = device_ns + offset_ns`` from (device, receive) pairs.

    Args:
        window_s: device-time span of the sliding minimum, s (> 0).
        jump_s: a sample this much later than predicted counts towards a re-sync, s (> 0).
        resync_samples: consecutive late samples that trigger a re-sync (>= 1).
    Attributes:
        resets: number of re-initialisations (device clock backwards, ROS time jump).
        samples: samples accepted since construction.
    Raises ``ValueError``: non-positive window or jump, resync_samples < 1."""

    def __init__(self, window_s: float = 10.0, jump_s: float = 1.0, resync_samples: int = 3) -> None:
        if window_s <= 0 or jump_s <= 0 or resync_samples < 1:
            raise ValueError("need window_s > 0, jump_s > 0 and resync_samples >= 1")
        self.window_ns = int(window_s * 1e9)
        self.jump_ns = int(jump_s * 1e9)
        self.resync_samples = int(resync_samples)
        # (device_ns, receive_ns - device_ns), deltas increasing from left to right (monotonic deque).
        self._window: Deque[Tuple[int, int]] = collections.deque()
        self._last_device_ns: Optional[int] = None
        self._late = 0
        self.resets = 0
        self.samples = 0

    def reset(self) -> None:
        """Forget every sample (e.g. after a reconnect: the device may have rebooted)."""
        self._window.clear()
        self._last_device_ns = None
        self._late = 0

    @property
    def offset_ns(self) -> Optional[int]:
        """Current estimate of ``ros - device`` in ns (None before the first sample)."""
        return self._window[0][1] if self._window else None

    def update(self, device_ns: int, receive_ns: int) -> int:
        """Add one report: device time ``device_ns`` received at ROS time ``receive_ns`` (both ns).

        Returns the offset estimate after the update (ns)."""
        device_ns, receive_ns = int(device_ns), int(receive_ns)
        delta = receive_ns - device_ns
        if self._last_device_ns is not None and device_ns < self._last_device_ns:
            self.resets += 1  # device rebooted (or its counter wrapped)
            self.reset()
        elif self._window and delta > self._window[0][1] + self.jump_ns:
            self._late += 1
            if self._late >= self.resync_samples:
                self.resets += 1  # ROS time jumped forward
                self.reset()
        else:
            self._late = 0
        self._last_device_ns = device_ns
        while self._window and self._window[-1][1] >= delta:
            self._window.pop()
        self._window.append((device_ns, delta))
        while self._window and self._window[0][0] < device_ns - self.window_ns:
            self._window.popleft()
        self.samples += 1
        return self._window[0][1]

    def to_ros_ns(self, device_ns: int) -> Optional[int]:
        """ROS time (ns) of device time ``device_ns``; None before the first sample."""
        offset = self.offset_ns
        return None if offset is None else int(device_ns) + offset
