"""Blue Robotics Ping (Ping1D protocol) altimeter driver node (serial): range to the bottom and confidence.

Run alone: ``python -m hindrax_drivers.ping1d.node --ros-args --params-file ros_ws/config/hindrax.yaml``
(or composed: construct :class:`Ping1dNode`). Configuration ``sensors.ping1d.*``: ``port`` (device path
or pyserial URL), ``baud_rate``, ``speed_of_sound_m_s``, ``ping_interval_s``, ``mode_auto``,
``field_of_view_rad``, ``min_range_m``, ``max_range_m``. Node parameter ``stuck_limit_samples`` (default 50).

Start-up (docs/devices.md §2.1, §2.3, §2.4), after every (re)connect, 20 ms apart: the auto-baud sync byte ``U``;
``set_speed_of_sound`` (1002), ``set_ping_interval`` (1004), ``set_mode_auto`` (1003; in manual mode the device keeps
its configured range and gain), ``set_ping_enable(1)`` (1006), ``continuous_start(1300)`` (1400: the device streams a
``profile`` at every ping, which carries distance and confidence); then ``general_request`` (6) for ``firmware_version``
(1200), ``general_info`` (1210) and ``speed_of_sound`` (1203) to verify that the settings took (a mismatch raises the
diagnostics warning ``settings``; a NACK raises ``nack``). ACKs are accepted but not required (whether firmware ACKs
sets is unverified, §2.3). If no distance arrives for ``max(1 s, 5 * ping_interval_s)`` while connected, the sequence is
sent again (a device reset stops streaming).

Publishes (QoS reliable, depth 10), for every ``profile`` (1300), ``distance`` (1212) or
``distance_simple`` (1211) received (a repeated ``ping_number`` is not published twice):

- ``ping/altitude`` (sensor_msgs/Range, frame ``ping_link``, ULTRASOUND, ``field_of_view``,
  ``min_range``, ``max_range`` from the configuration): the distance along the sonar axis, m; ``+inf``
  when the confidence is 0 (REP-117 "no detection"). Out of range per REP-117: a distance below
  ``min_range_m`` (the transducer's blind zone) is published as ``-inf`` and one beyond ``max_range_m`` as
  ``+inf``, never as measured (counted as ``errors.out_of_range``); variance 0 (unknown, as Range.msg defines).
- ``ping/confidence`` (std_msgs/Float32): the device's confidence, percent 0-100 (docs/devices.md §2.4).
- ``raw/ping1d`` (hindrax_msgs/RawDeviceData): every byte in both directions.
- ``/diagnostics``: state (disconnected / connected / reconnecting), rate, last message age, ``errors.garbage_bytes``,
  ``errors.truncated``, ``errors.bad_checksum``, ``errors.unknown_message``, ``errors.malformed`` (see
  :mod:`hindrax_drivers.ping1d.stream`), ``errors.nack``, the ERROR ``stuck`` (identical distance, confidence and
  profile samples for ``stuck_limit_samples`` pings: from then on, until the data change, nothing is published on
  ``ping/altitude`` and ``ping/confidence``), firmware version and verified settings.

Time stamps: receive time (ROS time, ``use_sim_time`` supported): the Ping1D messages carry no device
time (docs/devices.md §2.4)."""
from __future__ import annotations

import math
from typing import Any, Iterable, List, Optional, Tuple

from sensor_msgs.msg import Range
from std_msgs.msg import Float32

from hindrax_common.config.typed_sections import SensorsPing1dSection
from hindrax_common.node_support.node_common import DEFAULT_QOS_DEPTH, declare_frame_ids, run_node
from hindrax_common.node_support.serial_node import SerialDeviceNode, range_message
from .protocol import (SYNC_BYTE, Ack, AsciiText, ContinuousStart, Distance, DistanceSimple,
                       FirmwareVersion, GeneralInfo, Nack, Ping1dId, Profile, SetModeAuto,
                       SetPingEnable, SetPingInterval, SetSpeedOfSound, SpeedOfSound, request_frame)
from .stream import Ping1dStreamDecoder

__all__ = ["Ping1dNode", "main", "COMMAND_GAP_S", "startup_frames"]

#: Pause between start-up frames, s (no documented requirement; keeps the device's input queue short).
COMMAND_GAP_S = 0.02
_SPEED_TOLERANCE_M_S = 0.0015  # wire resolution 1 mm/s (docs/devices.md §2.4)
_INTERVAL_TOLERANCE_S = 0.0015  # wire resolution 1 ms


def startup_frames(speed_of_sound_m_s: float, ping_interval_s: float, mode_auto: bool) -> List[bytes]:
    """Byte strings the node sends after every (re)connect (see the module docstring), host id 0 -> device 0.

    Raises ``ValueError``: a value that does not fit its wire field (speed u32 mm/s, interval u16 ms)."""
    return [
        SYNC_BYTE,
        SetSpeedOfSound(float(speed_of_sound_m_s)).encode(),
        SetPingInterval(float(ping_interval_s)).encode(),
        SetModeAuto(bool(mode_auto)).encode(),
        SetPingEnable(True).encode(),
        ContinuousStart(int(Ping1dId.PROFILE)).encode(),
        request_frame(Ping1dId.FIRMWARE_VERSION),
        request_frame(Ping1dId.GENERAL_INFO),
        request_frame(Ping1dId.SPEED_OF_SOUND),
    ]


class Ping1dNode(SerialDeviceNode):
    """Ping1D serial altimeter node (see the module docstring). ``**kwargs`` go to ``rclpy.node.Node``.

    Raises ``ConfigError``: invalid configuration (one line logged; ``main`` exits with status 1)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("ping1d", device_name="ping1d", config_section=SensorsPing1dSection,
                         command_gap_s=COMMAND_GAP_S, **kwargs)
        self.frames = declare_frame_ids(self, {"frame_id": "ping_link"})
        s = self.cfg.sensors.ping1d
        self.speed_of_sound_m_s = float(s.speed_of_sound_m_s)
        self.ping_interval_s = float(s.ping_interval_s)
        self.mode_auto = bool(s.mode_auto)
        self.field_of_view_rad = float(s.field_of_view_rad)
        self.min_range_m = float(s.min_range_m)
        self.max_range_m = float(s.max_range_m)
        self.silence_timeout_s = max(1.0, 5.0 * self.ping_interval_s)
        self.decoder = Ping1dStreamDecoder()
        self._frames = startup_frames(self.speed_of_sound_m_s, self.ping_interval_s, self.mode_auto)
        self._last_startup_ns = 0
        self._last_distance_ns: Optional[int] = None
        self._last_ping_number: Optional[int] = None
        self.firmware_version = ""
        self.settings_verified: Optional[bool] = None
        self._checks: dict[str, bool] = {}
        self.acks = 0
        self.pub_range = self.create_publisher(Range, "ping/altitude", DEFAULT_QOS_DEPTH)
        self.pub_confidence = self.create_publisher(Float32, "ping/confidence", DEFAULT_QOS_DEPTH)
        self.get_logger().info(
            f"Ping1D on {self.port}: speed of sound {self.speed_of_sound_m_s} m/s, ping interval "
            f"{self.ping_interval_s} s, {'auto' if self.mode_auto else 'manual'} mode")
        self.start_transport()

    # -- start-up
    def startup_commands(self) -> List[bytes]:
        self._last_startup_ns = self.now_ns()
        return list(self._frames)

    def on_link_up(self) -> None:
        self.decoder.reset()
        self.count_decoder_events(self.decoder.counts)
        self._last_ping_number = None
        self._checks.clear()
        self.settings_verified = None

    # -- data path (reader thread)
    def handle_bytes(self, data: bytes, receive_ns: int) -> None:
        """Decode a chunk and publish what it completes."""
        decoded = self.decoder.feed(data)
        self.count_decoder_events(self.decoder.counts)
        for item in decoded:
            p = item.payload
            if isinstance(p, (Profile, Distance, DistanceSimple)):
                self._on_distance(p, receive_ns)
            elif isinstance(p, GeneralInfo):
                self._check("ping_interval_s", p.ping_interval_s, self.ping_interval_s, _INTERVAL_TOLERANCE_S)
                self._check("mode_auto", p.mode_auto, self.mode_auto, 0)
                if not self.firmware_version:
                    self.firmware_version = f"{p.firmware_version_major}.{p.firmware_version_minor}"
            elif isinstance(p, SpeedOfSound):
                self._check("speed_of_sound_m_s", p.speed_of_sound_m_s, self.speed_of_sound_m_s, _SPEED_TOLERANCE_M_S)
            elif isinstance(p, FirmwareVersion):
                self.firmware_version = f"{p.firmware_version_major}.{p.firmware_version_minor}"
            elif isinstance(p, Ack):
                self.acks += 1
            elif isinstance(p, Nack):
                self.diag.count("nack")
                text = f"device refused message {p.nacked_id}: {p.message}"
                self.diag.warn("nack", text)
                self.get_logger().warn(f"Ping1D {text}", throttle_duration_sec=5.0)
            elif isinstance(p, AsciiText):
                self.get_logger().debug(f"Ping1D text: {p.text}")

    def _check(self, name: str, reported: Any, configured: Any, tolerance: float) -> None:
        ok = (reported == configured) if tolerance == 0 else abs(float(reported) - float(configured)) <= tolerance
        self._checks[name] = ok
        if not ok:
            self.diag.count("settings_mismatch")
            self.diag.warn("settings", f"device reports {name} = {reported}, configured {configured}")
            self.get_logger().warn(f"Ping1D reports {name} = {reported}, configured {configured}")
        if len(self._checks) == 3:
            self.settings_verified = all(self._checks.values())
            if self.settings_verified:
                self.diag.clear("settings")

    def _on_distance(self, p: Any, receive_ns: int) -> None:
        number = getattr(p, "ping_number", None)
        if number is not None:
            if number == self._last_ping_number:
                return  # the same ping reported twice (stream and a reply)
            self._last_ping_number = number
        self._last_distance_ns = receive_ns
        if self.check_stuck("distance", (p.distance_m, p.confidence_pct, getattr(p, "profile_data", None))):
            return  # a stuck sonar's distance is not published (ERROR "stuck" in /diagnostics)
        lo, hi = self.min_range_m, self.max_range_m
        distance = rep117_range(float(p.distance_m), p.confidence_pct, lo, hi)
        if p.confidence_pct > 0 and math.isinf(distance):
            self.diag.count("out_of_range")
        self.pub_range.publish(range_message(receive_ns, self.frames["frame_id"],
                                             self.field_of_view_rad, lo, hi, distance))
        self.pub_confidence.publish(Float32(data=float(p.confidence_pct)))
        self.mark_published(receive_ns)

    # -- executor side
    def housekeeping(self, now_ns: int) -> None:
        """Restart streaming when no distance arrived for ``silence_timeout_s`` while connected."""
        if not self.transport.connected:
            return
        last = max(self._last_distance_ns or 0, self._last_startup_ns)
        if now_ns - last > self.silence_timeout_s * 1e9:
            self.resend_startup(f"no distance for {self.silence_timeout_s:g} s")

    def extra_diagnostics(self) -> Iterable[Tuple[str, Any]]:
        last = self.decoder.last_error
        return [
            ("firmware_version", self.firmware_version),
            ("speed_of_sound_m_s", self.speed_of_sound_m_s), ("ping_interval_s", self.ping_interval_s),
            ("mode_auto", self.mode_auto),
            ("settings_verified", "" if self.settings_verified is None else self.settings_verified),
            ("acks", self.acks),
            ("messages", ",".join(f"{k}={v}" for k, v in sorted(self.decoder.messages.items()))),
            ("last_parse_error", "" if last is None else f"{last.kind}: {last.reason}"),
        ]


def rep117_range(distance_m: float, confidence_pct: float, min_range_m: float, max_range_m: float) -> float:
    """``sensor_msgs/Range.range`` per REP-117: ``+inf`` for no detection (confidence 0) or a distance beyond
    ``max_range_m``, ``-inf`` for one closer than ``min_range_m`` (inside the blind zone), else the distance, m."""
    if confidence_pct <= 0 or not math.isfinite(distance_m) or distance_m > max_range_m:
        return math.inf
    if distance_m < min_range_m:
        return -math.inf
    return distance_m


def main(args=None) -> int:
    """Entry point: ``python -m hindrax_drivers.ping1d.node --ros-args --params-file ros_ws/config/hindrax.yaml``.
    Returns 0 on SIGINT/SIGTERM, 1 on an invalid configuration."""
    return run_node(Ping1dNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
