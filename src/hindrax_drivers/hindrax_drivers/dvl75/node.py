"""Cerulean DVL-75 driver node (serial): velocity, altitude, attitude and beams in ROS conventions.

Run alone: ``python -m hindrax_drivers.dvl75.node --ros-args --params-file ros_ws/config/hindrax.yaml``
(or composed: construct :class:`Dvl75Node` in any process). Configuration ``sensors.dvl75.*``: ``port``
(device path or pyserial URL), ``baud_rate``, ``position_frd_m`` (lever arm), ``sensor_orientation_rpy_rad``,
``speed_of_sound_m_s``, ``velocity_std_m_s``. Node parameter ``stuck_limit_samples`` (default 50).

Start-up (docs/devices.md §0 item 1, §1.4): after every (re)connect the node sends, 0.1 s apart as the BlueOS driver
does [D17], :func:`hindrax_drivers.dvl75.protocol.startup_commands` (the CONFIGURATION reply is logged at debug level).
The sequence is sent again when the DVL reboots (``tu`` goes backwards) and when ``$DVEXT`` keeps arriving without
``$DVPDL`` for ``MISSING_DVPDL_TIMEOUT_S``.

Publishes (QoS reliable, depth 10):

- ``dvl/data`` (hindrax_msgs/Dvl, frame ``base_link``): one message per ``$DVPDL``, with lock, attitude, altitude and
  beams from the latest ``$DVEXT`` (at most one ping cycle older; see :mod:`hindrax_drivers.dvl75.report` for every
  field, the FRD -> FLU conversion, the lever-arm correction and the validity rule). A velocity is **never** published
  from an unlocked or zero-confidence report: ``velocity_valid`` false, NaN velocity and delta position. When no
  ``$DVPDL`` has arrived for 1 s, one message per ``$DVEXT`` is published instead (velocity never valid).
- ``dvl/twist`` (geometry_msgs/TwistWithCovarianceStamped, ``base_link``): the same velocity, only when
  valid; covariance linear block ``velocity_std_m_s**2 * I``, angular block -1 on the diagonal
  (angular velocity not measured here: 0 with unknown variance), 0 elsewhere.
- ``dvl/altitude`` (sensor_msgs/Range, frame ``dvl_link``, ULTRASOUND): one per ``$DVEXT``, the distance to the bottom
  along the sensor axis; ``+inf`` when unlocked (REP-117 "no detection"). Limits 0.3..40 m and field of view
  :data:`ALTITUDE_FIELD_OF_VIEW_RAD` (docs/devices.md §1.1 envelope); variance 0 (unknown, as Range.msg defines).
- ``raw/dvl75`` (hindrax_msgs/RawDeviceData): every byte in both directions, receive/send time stamps.
- ``/diagnostics``: state (disconnected / connected / reconnecting), rate, last message age, ``errors.garbage_bytes``,
  ``errors.truncated``, ``errors.bad_checksum``, ``errors.malformed``, ``errors.unknown_sentence`` (see
  :mod:`hindrax_drivers.dvl75.stream`), ``errors.implausible_velocity`` and the ERROR ``implausible`` (a ``$DVPDL``
  outside the plausibility gates ``sensors.dvl75.max_speed_m_s``, ``min_interval_s``, ``max_interval_s``: published with
  ``velocity_valid`` false, see :mod:`hindrax_drivers.dvl75.report`; diagnostics published at once, cleared
  ``IMPLAUSIBLE_HOLD_S`` after the last rejected report), the ERROR ``stuck`` (identical ``$DVPDL`` deltas with
  confidence > 0, or identical ``$DVEXT`` attitude/altitude/beam data, for ``stuck_limit_samples`` reports: from then
  on, until the data change, every velocity is published not valid and ``dvl/altitude`` is not published), clock-offset
  estimate, start-up state.

Time stamps (docs/architecture.md §3; every stamp is ROS time, ``use_sim_time`` supported):

- ``dvl/data`` and ``dvl/twist`` carry the DVL's own time of validity: ``$DVPDL`` field ``tu``
  (microseconds since DVL boot, docs/devices.md §1.3.1) minus ``dtu/2`` (the velocity is the mean over the
  interval ``dtu`` that ends at ``tu``), mapped to ROS time by :class:`~.device_clock.DeviceClockSync`:
  offset = minimum over the last 10 s of (receive ROS time - ``tu``), i.e. ``tu`` plus the smallest
  transport latency seen, re-estimated after a DVL reboot (``tu`` backwards) or a ROS time jump.
- ``dvl/altitude`` and messages built from ``$DVEXT`` alone use the receive time: ``$DVEXT`` carries no
  device time (its field 14 is an EKF step length, docs/devices.md §1.3.2)."""
from __future__ import annotations

import math
from typing import Any, Iterable, List, Optional, Tuple

from geometry_msgs.msg import Quaternion, TwistWithCovarianceStamped, Vector3
from sensor_msgs.msg import Range

from hindrax_msgs.msg import Dvl

from hindrax_common.config.typed_sections import SensorsDvl75Section
from hindrax_common.base.device_clock import DeviceClockSync
from hindrax_common.node_support.node_common import (DEFAULT_QOS_DEPTH, declare_frame_ids, log_at, run_node,
                                                    time_from_ns)
from hindrax_common.node_support.serial_node import SerialDeviceNode, range_message
from .protocol import DvlExtended, DvlGprmc, DvlPositionDelta, DvlText, startup_commands
from .report import DvlReport, DvlReportBuilder, altitude_range_m
from .stream import DvlStreamDecoder

__all__ = ["Dvl75Node", "main", "COMMAND_GAP_S", "ALTITUDE_MIN_RANGE_M", "ALTITUDE_MAX_RANGE_M",
           "ALTITUDE_FIELD_OF_VIEW_RAD", "MISSING_DVPDL_TIMEOUT_S"]

#: Pause between start-up commands, s (the BlueOS driver sleeps 0.1 s between them, docs/devices.md §1.4 [D17]).
COMMAND_GAP_S = 0.1
#: Altitude envelope of the DVL-75, m (docs/devices.md §1.1 "Operating envelope": 0.3-40 m).
ALTITUDE_MIN_RANGE_M = 0.3
ALTITUDE_MAX_RANGE_M = 40.0
#: Field of view reported with dvl/altitude, rad. ASSUMPTION: docs/devices.md gives no beam angle; the
#: emulator's four-beam Janus model tilts beams 22.5 deg from the axis, i.e. a 45 deg cone.
ALTITUDE_FIELD_OF_VIEW_RAD = math.radians(45.0)
#: ``$DVEXT`` flowing but no ``$DVPDL`` for this long after the last start-up sequence: send it again, s.
MISSING_DVPDL_TIMEOUT_S = 3.0
#: Without ``$DVPDL`` for this long, ``dvl/data`` is published from each ``$DVEXT`` instead, s.
DVEXT_ONLY_AFTER_S = 1.0
#: The ERROR ``implausible`` stays raised this long after the last rejected ``$DVPDL`` (ROS time), s, so that
#: a 1 Hz diagnostics reader sees a single rejected report.
IMPLAUSIBLE_HOLD_S = 2.0


class Dvl75Node(SerialDeviceNode):
    """DVL-75 serial driver node (see the module docstring). ``**kwargs`` go to ``rclpy.node.Node``.

    Raises ``ConfigError``: invalid configuration (one line logged; ``main`` exits with status 1)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("dvl75", device_name="dvl75", config_section=SensorsDvl75Section,
                         command_gap_s=COMMAND_GAP_S, **kwargs)
        self.frames = declare_frame_ids(self, {"frame_id": "dvl_link", "base_frame_id": "base_link"})
        s = self.cfg.sensors.dvl75
        self.sensor_orientation_rpy_rad = tuple(float(a) for a in s.sensor_orientation_rpy_rad)
        self.speed_of_sound_m_s = float(s.speed_of_sound_m_s)
        self.builder = DvlReportBuilder(position_frd_m=s.position_frd_m, velocity_std_m_s=float(s.velocity_std_m_s),
                                        max_speed_m_s=float(s.max_speed_m_s), min_interval_s=float(s.min_interval_s),
                                        max_interval_s=float(s.max_interval_s),
                                        max_angular_rate_rad_s=float(s.max_angular_rate_rad_s))
        self.decoder = DvlStreamDecoder()
        self.clock_sync = DeviceClockSync()
        self._last_tu_s: Optional[float] = None
        self._last_dvpdl_ns: Optional[int] = None
        self._last_dvext_ns: Optional[int] = None
        self._last_startup_ns = 0
        self._text_lines = 0
        self._last_text = ""
        self._valid_count = 0
        self._invalid_count = 0
        self._last_report: Optional[DvlReport] = None
        self._last_implausible_ns: Optional[int] = None
        self.pub_data = self.create_publisher(Dvl, "dvl/data", DEFAULT_QOS_DEPTH)
        self.pub_twist = self.create_publisher(TwistWithCovarianceStamped, "dvl/twist", DEFAULT_QOS_DEPTH)
        self.pub_altitude = self.create_publisher(Range, "dvl/altitude", DEFAULT_QOS_DEPTH)
        self.get_logger().info(
            f"DVL-75 on {self.port}: orientation {[round(math.degrees(a), 3) for a in self.sensor_orientation_rpy_rad]}"
            f" deg, speed of sound {self.speed_of_sound_m_s} m/s")
        self.start_transport()

    # -- start-up
    def startup_commands(self) -> List[bytes]:
        """The start-up command lines (docs/devices.md §1.4), sensor orientation converted to degrees."""
        self._last_startup_ns = self.now_ns()
        return startup_commands(sensor_orientation_rad=self.sensor_orientation_rpy_rad,  # type: ignore[arg-type]
                                speed_of_sound_m_s=self.speed_of_sound_m_s)

    def on_link_up(self) -> None:
        """A new connection: a partial line is garbage, and the DVL may have rebooted meanwhile."""
        self.decoder.reset()
        self.count_decoder_events(self.decoder.counts)
        self.clock_sync.reset()
        self._last_tu_s = None

    # -- data path (reader thread)
    def handle_bytes(self, data: bytes, receive_ns: int) -> None:
        """Decode a chunk and publish what it completes."""
        records = self.decoder.feed(data)
        self.count_decoder_events(self.decoder.counts)
        for record in records:
            if isinstance(record, DvlPositionDelta):
                self._on_dvpdl(record, receive_ns)
            elif isinstance(record, DvlExtended):
                self._on_dvext(record, receive_ns)
            elif isinstance(record, DvlText):
                self._text_lines += 1
                self._last_text = record.text[:120]
                level = "warn" if "error" in record.text.lower() else "debug"
                log_at(self.get_logger(), level, f"DVL text: {record.text}")
            elif isinstance(record, DvlGprmc):
                pass  # the DVL's GPS emulation; not used (switched off at start-up)

    def _on_dvpdl(self, pdl: DvlPositionDelta, receive_ns: int) -> None:
        if self._last_tu_s is not None and pdl.time_since_boot_s < self._last_tu_s:
            self.diag.count("device_reboots")
            self.resend_startup(f"DVL clock went back from {self._last_tu_s:.3f} s to {pdl.time_since_boot_s:.3f} s"
                                " (reboot)")
        self._last_tu_s = pdl.time_since_boot_s
        self._last_dvpdl_ns = receive_ns
        self.clock_sync.update(round(pdl.time_since_boot_s * 1e9), receive_ns)
        if pdl.confidence_pct > 0:
            self.check_stuck("dvpdl", (pdl.delta_roll_rad, pdl.delta_pitch_rad, pdl.delta_yaw_rad,
                                       pdl.delta_x_m, pdl.delta_y_m, pdl.delta_z_m))
        report = self.builder.from_position_delta(pdl, receive_ns)
        if report.rejection:
            self.diag.count("implausible_velocity")
            self.diag.error("implausible", f"implausible $DVPDL published not valid: {report.rejection}")
            self.get_logger().error(f"DVL: implausible $DVPDL, velocity not valid: {report.rejection}",
                                    throttle_duration_sec=5.0)
            if self._last_implausible_ns is None:
                self._publish_diagnostics()
            self._last_implausible_ns = receive_ns
        if self.stuck:
            report = self.builder.invalidated(report, "stuck")
        stamp_ns = self.clock_sync.to_ros_ns(report.device_time_ns)  # type: ignore[arg-type]
        self._publish(report, receive_ns if stamp_ns is None else stamp_ns, receive_ns)

    def _on_dvext(self, ext: DvlExtended, receive_ns: int) -> None:
        self.builder.update_extended(ext, receive_ns)
        self._last_dvext_ns = receive_ns
        self.check_stuck("dvext", (ext.orientation_wxyz, ext.roll_rad, ext.pitch_rad, ext.heading_rad,
                                   ext.altitude_m, ext.beam_range_m, ext.beam_velocity_m_s,
                                   ext.velocity_north_m_s, ext.velocity_east_m_s, ext.velocity_up_m_s))
        if self.stuck:
            return  # a stuck DVL's altitude is not published (ERROR "stuck" in /diagnostics)
        self.pub_altitude.publish(range_message(
            receive_ns, self.frames["frame_id"], ALTITUDE_FIELD_OF_VIEW_RAD, ALTITUDE_MIN_RANGE_M,
            ALTITUDE_MAX_RANGE_M, altitude_range_m(ext)))
        if self._last_dvpdl_ns is None or receive_ns - self._last_dvpdl_ns > DVEXT_ONLY_AFTER_S * 1e9:
            self._publish(self.builder.from_extended(ext), receive_ns, receive_ns)

    def _publish(self, r: DvlReport, stamp_ns: int, receive_ns: int) -> None:
        msg = Dvl()
        msg.header.stamp = time_from_ns(stamp_ns)
        msg.header.frame_id = self.frames["base_frame_id"]
        msg.velocity_m_s = Vector3(x=r.velocity_flu_m_s[0], y=r.velocity_flu_m_s[1], z=r.velocity_flu_m_s[2])
        msg.velocity_covariance = list(r.velocity_covariance)
        msg.velocity_valid = r.velocity_valid
        msg.altitude_m = r.altitude_m
        msg.bottom_lock = r.bottom_lock
        msg.confidence_percent = float(r.confidence_pct)
        msg.beam_range_m = list(r.beam_range_m)
        msg.beam_velocity_m_s = list(r.beam_velocity_m_s)
        msg.beam_lock = list(r.beam_lock)
        x, y, z, w = r.orientation_xyzw
        msg.orientation = Quaternion(x=x, y=y, z=z, w=w)
        msg.orientation_covariance = list(r.orientation_covariance)
        msg.delta_position_m = Vector3(x=r.delta_position_flu_m[0], y=r.delta_position_flu_m[1],
                                       z=r.delta_position_flu_m[2])
        msg.delta_time_s = r.delta_time_s
        self.pub_data.publish(msg)
        self._last_report = r
        if r.velocity_valid:
            self._valid_count += 1
            tw = TwistWithCovarianceStamped()
            tw.header = msg.header
            tw.twist.twist.linear = msg.velocity_m_s
            tw.twist.covariance = list(r.twist_covariance)
            self.pub_twist.publish(tw)
        else:
            self._invalid_count += 1
        self.mark_published(receive_ns)

    # -- executor side
    def housekeeping(self, now_ns: int) -> None:
        """Clear the ``implausible`` ERROR :data:`IMPLAUSIBLE_HOLD_S` after the last rejected report; resend the
        start-up commands when ``$DVEXT`` flows but ``$DVPDL`` does not."""
        if self._last_implausible_ns is not None and now_ns - self._last_implausible_ns > IMPLAUSIBLE_HOLD_S * 1e9:
            self._last_implausible_ns = None
            self.diag.clear("implausible")
        if not self.transport.connected or self._last_dvext_ns is None:
            return
        dvext_recent = now_ns - self._last_dvext_ns < 1e9
        dvpdl_missing = self._last_dvpdl_ns is None or now_ns - self._last_dvpdl_ns > MISSING_DVPDL_TIMEOUT_S * 1e9
        if dvext_recent and dvpdl_missing:
            self.diag.warn("no_dvpdl", "$DVEXT received but no $DVPDL (SEND-DVPDL ON not effective?)")
            if now_ns - self._last_startup_ns > MISSING_DVPDL_TIMEOUT_S * 1e9:
                self.resend_startup(f"no $DVPDL for {MISSING_DVPDL_TIMEOUT_S:g} s")
        else:
            self.diag.clear("no_dvpdl")

    def extra_diagnostics(self) -> Iterable[Tuple[str, Any]]:
        offset = self.clock_sync.offset_ns
        last = self.decoder.last_error
        return [
            ("sensor_orientation_rpy_deg", ",".join(f"{math.degrees(a):.3f}" for a in self.sensor_orientation_rpy_rad)),
            ("speed_of_sound_m_s", self.speed_of_sound_m_s),
            ("records", ",".join(f"{k}={v}" for k, v in sorted(self.decoder.records.items()))),
            ("velocity_valid_reports", self._valid_count), ("velocity_invalid_reports", self._invalid_count),
            ("bottom_lock", "" if self._last_report is None else self._last_report.bottom_lock),
            ("confidence_percent", "" if self._last_report is None else self._last_report.confidence_pct),
            ("device_clock_offset_s", "" if offset is None else f"{offset * 1e-9:.6f}"),
            ("device_clock_resets", self.clock_sync.resets),
            ("text_lines", self._text_lines), ("last_text", self._last_text),
            ("last_parse_error", "" if last is None else f"{last.kind}: {last.reason}"),
        ]


def main(args=None) -> int:
    """Entry point: ``python -m hindrax_drivers.dvl75.node --ros-args --params-file ros_ws/config/hindrax.yaml``.
    Returns 0 on SIGINT/SIGTERM, 1 on an invalid configuration."""
    return run_node(Dvl75Node, args)


if __name__ == "__main__":
    raise SystemExit(main())
