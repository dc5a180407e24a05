"""Base class of the serial driver nodes (DVL-75, Ping1D): one transport, one state machine, one tap.

- configuration ``<section>.port`` (device path or pyserial URL) and ``<section>.baud_rate``
  (:func:`hindrax_common.node_support.node_common.load_node_config`: invalid -> one line, exit 1);
- a :class:`~hindrax_common.transport.serial_transport.SerialTransport` (reader thread, reconnect
  with backoff 0.05 s doubling to 1 s);
- raw traffic on ``raw/<device>`` (``RawDataPublisher.serial_tap``), one message per parsed report;
- ``/diagnostics`` state: ``disconnected`` (ERROR with the open error), ``connected`` (OK; WARN
  "connected, no data" after ``NO_DATA_TIMEOUT_S`` without a publish), ``reconnecting`` (ERROR);
  published at once on every change, and at 1 Hz;
- a :class:`CommandSequencer` that sends the start-up commands after *every* (re)connect, spaced by
  a gap, from its own thread;
- :meth:`SerialDeviceNode.check_stuck`: one :class:`~hindrax_common.node_support.node_common.StuckDetector` per
  named signal, the ERROR ``stuck`` while any is stuck; the subclass then stops publishing the stuck
  values as valid (:attr:`SerialDeviceNode.stuck`).

Received bytes are decoded and published in the transport's reader thread; timers run in the
executor. Subclasses implement :meth:`handle_bytes` and :meth:`startup_commands`, and may override
:meth:`on_link_up`, :meth:`housekeeping` and :meth:`extra_diagnostics`. Node parameter
``stuck_limit_samples`` (int >= 2, default 50): identical readings in a row that count as stuck."""
from __future__ import annotations

import contextlib
import threading
from typing import Any, Iterable, List, Optional, Sequence, Tuple

from diagnostic_msgs.msg import DiagnosticStatus
from sensor_msgs.msg import Range

from ..config import build_section
from ..config.node_parameters import declare_node_parameter
from ..config.spec import integer
from ..config.typed_sections import SensorsDvl75Section, SensorsPing1dSection
from .node_common import (DeviceDiagnostics, DiagnosticsPublisher, RawDataPublisher, StuckDetector,
                          load_node_config, time_from_ns)
from ..transport.serial_transport import SerialTransport, SerialTransportError
from .vehicle_node import VehicleNode

__all__ = ["SerialDeviceNode", "CommandSequencer", "NO_DATA_TIMEOUT_S", "range_message"]

#: Connected but nothing published for this long (ROS time): diagnostics WARN "connected, no data", s.
NO_DATA_TIMEOUT_S = 2.0
_HOUSEKEEPING_PERIOD_S = 0.25
#: node parameter ``stuck_limit_samples`` (read-only, :func:`declare_node_parameter`)
STUCK_LIMIT_SAMPLES = integer("identical readings in a row after which a sensor counts as stuck", 2)
#: Received bytes collected for raw/<device> are published at the latest when they exceed this, bytes.
RAW_FLUSH_BYTES = 4096


def range_message(stamp_ns: int, frame_id: str, field_of_view_rad: float, min_range_m: float,
                  max_range_m: float, range_m: float) -> Range:
    """An ULTRASOUND ``sensor_msgs/Range`` stamped ``stamp_ns`` (ns); variance 0 (unknown, as
    Range.msg defines: no accuracy is documented)."""
    msg = Range(radiation_type=Range.ULTRASOUND, field_of_view=float(field_of_view_rad), min_range=float(min_range_m),
                max_range=float(max_range_m), range=float(range_m), variance=0.0)
    msg.header.stamp, msg.header.frame_id = time_from_ns(stamp_ns), frame_id
    return msg


class CommandSequencer:
    """Send sequences of commands over a :class:`SerialTransport` from a background thread.

    ``submit(commands)`` replaces whatever sequence is still pending (the newest start-up sequence wins)
    and returns at once; the thread writes each command, then waits ``gap_s`` (wall time: the gap is a
    property of the device's input handling, not of ROS time). A write that fails (port gone) abandons the
    rest of the sequence; the next (re)connect submits a new one.

    Args:
        transport: the port to write to.
        gap_s: pause after each command, s (>= 0).
        name: thread name.
    Attributes:
        commands_sent, sequences_completed, write_failures: counters."""

    def __init__(self, transport: SerialTransport, gap_s: float, name: str = "CommandSequencer") -> None:
        if gap_s < 0:
            raise ValueError("gap_s must be >= 0")
        self.transport = transport
        self.gap_s = float(gap_s)
        self._cond = threading.Condition()
        self._pending: Optional[List[bytes]] = None
        self._generation = 0
        self._stop = False
        self._wake = threading.Event()
        self.commands_sent = 0
        self.sequences_completed = 0
        self.write_failures = 0
        self.last_error: Optional[str] = None
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def submit(self, commands: Sequence[bytes]) -> None:
        """Queue ``commands`` (replacing a pending sequence)."""
        with self._cond:
            self._pending = [bytes(c) for c in commands]
            self._generation += 1
            self._cond.notify_all()
        self._wake.set()  # cut short the gap of a superseded sequence

    def _run(self) -> None:
        while True:
            with self._cond:
                while self._pending is None and not self._stop:
                    self._cond.wait()
                if self._stop:
                    return
                commands, self._pending = self._pending, None
                generation = self._generation
                self._wake.clear()
            for k, command in enumerate(commands):
                with self._cond:
                    if self._stop or generation != self._generation:
                        break
                try:
                    self.transport.write(command)
                    self.commands_sent += 1
                except SerialTransportError as exc:
                    self.write_failures += 1
                    self.last_error = str(exc)
                    break
                if self.gap_s > 0 and k + 1 < len(commands):
                    self._wake.wait(self.gap_s)
            else:
                self.sequences_completed += 1

    def close(self) -> None:
        """Stop the thread (idempotent)."""
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        self._wake.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout=5.0)


class SerialDeviceNode(VehicleNode):
    """Common part of the serial driver nodes (see the module docstring).

    Args:
        node_name: ROS node name.
        device_name: short device name (``raw/<device_name>``, diagnostics ``hindrax/<device_name>``).
        config_section: typed configuration section holding ``port`` and ``baud_rate`` (e.g.
            :class:`~hindrax_common.config.typed_sections.SensorsDvl75Section`); its ``PREFIX`` names the keys declared.
        command_gap_s: pause between start-up commands, s.
        **kwargs: passed to ``rclpy.node.Node`` (context, parameter_overrides, namespace...).
    Raises ``ConfigError``: invalid vehicle configuration or ``stuck_limit_samples``."""

    def __init__(self, node_name: str, *, device_name: str,
                 config_section: type[SensorsDvl75Section] | type[SensorsPing1dSection], command_gap_s: float,
                 **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.cfg = load_node_config(self, (config_section.PREFIX,))
        self.settings = build_section(config_section, self.cfg.flat)
        self.device_name = device_name
        self.port = str(self.settings.port)
        self.baud_rate = int(self.settings.baud_rate)
        self.stuck_limit_samples = declare_node_parameter(self, "stuck_limit_samples", STUCK_LIMIT_SAMPLES, 50)
        self._closed = False
        self._ever_connected = False
        self._no_data = False
        self._last_publish_ns = 0
        self._last_link_ns = 0
        self._stuck: dict[str, StuckDetector] = {}
        self._decoder_counts: dict[str, int] = {}  # the decoder's counts already in the diagnostics
        self._stuck_now: set[str] = set()
        self.raw = RawDataPublisher(self, device_name)
        self.raw.begin_batch()  # raw/<device>: one message per parsed report (see _on_data), not per read chunk
        self.diag = DeviceDiagnostics(f"hindrax/{device_name}", self.port, self.now_s)
        self.diag.set_state("disconnected", DiagnosticStatus.ERROR, f"opening {self.port}")
        self.transport = SerialTransport(self.port, self.baud_rate, on_data=self._on_data, on_raw=self.raw.serial_tap,
                                         on_connect=self._on_connect, on_disconnect=self._on_disconnect, start=False)
        self.commands = CommandSequencer(self.transport, command_gap_s, name=f"{device_name}-commands")
        self.diagnostics = DiagnosticsPublisher(self, [self.diag], extra=self._diag_extra)
        self._housekeeping_timer = self.create_timer(_HOUSEKEEPING_PERIOD_S, self._housekeeping)

    # -- helpers for subclasses
    def count_decoder_events(self, counts: dict[str, int]) -> None:
        """Add to the diagnostics what the stream decoder's ``counts`` (kind -> running total: garbage bytes, bad
        checksums, ...) grew by since the last call."""
        for kind, total in counts.items():
            delta = total - self._decoder_counts.get(kind, 0)
            if delta:
                self.diag.count(kind, delta)
                self._decoder_counts[kind] = total

    def now_ns(self) -> int:
        """Current ROS time (sim time with ``use_sim_time``), ns."""
        return self.get_clock().now().nanoseconds

    def now_s(self) -> float:
        """Current ROS time, s."""
        return self.now_ns() * 1e-9

    def start_transport(self) -> None:
        """Start reading the port (subclasses call it at the end of their constructor)."""
        self.transport.start()

    def check_stuck(self, signal: str, value: Any) -> bool:
        """Feed one reading of ``signal``; raise/clear the ``stuck`` warning. Returns True while stuck."""
        det = self._stuck.get(signal)
        if det is None:
            det = self._stuck[signal] = StuckDetector(self.stuck_limit_samples)
        stuck = det.update(value)
        changed = (signal in self._stuck_now) != stuck
        if stuck:
            self._stuck_now.add(signal)
        else:
            self._stuck_now.discard(signal)
        if changed:
            if self._stuck_now:
                text = (f"stuck: identical {', '.join(sorted(self._stuck_now))} for "
                        f">= {self.stuck_limit_samples} samples")
                self.diag.error("stuck", text)
                self.get_logger().error(f"{self.device_name}: {text} (not published as valid)")
            else:
                self.diag.clear("stuck")
                self.get_logger().info(f"{self.device_name}: readings changing again")
            self.diag.count("stuck_events", 1 if stuck else 0)
        return stuck

    def mark_published(self, now_ns: int) -> None:
        """Count one output message for the diagnostics rate and the no-data watchdog."""
        self.diag.published()
        self._last_publish_ns = int(now_ns)
        if self._no_data:
            self._no_data = False
            self.diag.set_state("connected", DiagnosticStatus.OK, f"connected to {self.port}")

    @property
    def stuck(self) -> bool:
        """True while any signal is stuck."""
        return bool(self._stuck_now)

    # -- subclass interface
    def startup_commands(self) -> List[bytes]:
        """Command frames/lines to send after every (re)connect."""
        return []

    def handle_bytes(self, data: bytes, receive_ns: int) -> None:  # pragma: no cover - abstract
        """Decode and publish a received chunk (reader thread); ``receive_ns``: ROS time of receipt."""
        raise NotImplementedError

    def on_link_up(self) -> None:
        """Called in the reader thread after every (re)open, before the start-up commands are queued."""

    def housekeeping(self, now_ns: int) -> None:
        """Called from the executor every 0.25 s (ROS time)."""

    def extra_diagnostics(self) -> Iterable[Tuple[str, Any]]:
        """Device-specific key/values for the diagnostics status."""
        return ()

    def resend_startup(self, reason: str) -> None:
        """Queue the start-up commands again (e.g. the device rebooted or stopped streaming)."""
        self.diag.count("startup_resends")
        self.get_logger().warn(f"{self.device_name}: {reason}; sending the start-up commands again")
        self.commands.submit(self.startup_commands())

    # -- transport callbacks (reader thread)
    def _on_data(self, data: bytes) -> None:
        receive_ns = self.now_ns()
        try:
            published = self.diag.total_published
            self.handle_bytes(data, receive_ns)
            if self.diag.total_published != published or self.raw.pending_bytes > RAW_FLUSH_BYTES:
                self.raw.flush(end_batch=False)
        except Exception as exc:  # noqa: BLE001 - bad input must never stop the driver
            self.diag.count("internal_error")
            self.get_logger().error(f"{self.device_name}: error handling {len(data)} bytes: {exc!r}",
                                    throttle_duration_sec=5.0)

    def _on_connect(self) -> None:
        again = self._ever_connected
        self._ever_connected = True
        self._last_link_ns = self.now_ns()
        try:
            self.on_link_up()
        except Exception as exc:  # noqa: BLE001
            self.diag.count("internal_error")
            self.get_logger().error(f"{self.device_name}: on_link_up failed: {exc!r}")
        self.commands.submit(self.startup_commands())
        if again:
            text = f"reconnected to {self.port} (reconnects: {self.transport.status().reconnects})"
            self.get_logger().info(f"{self.device_name}: {text}")
        else:
            text = f"connected to {self.port}"
            self.get_logger().info(f"{self.device_name}: {text} at {self.baud_rate} baud")
        self._no_data = False
        self.diag.set_state("connected", DiagnosticStatus.OK, text)
        self._publish_diagnostics()

    def _on_disconnect(self, error: str) -> None:
        self._last_link_ns = self.now_ns()
        self.diag.count("disconnects")
        self.diag.set_state("reconnecting", DiagnosticStatus.ERROR, f"{self.port} lost ({error}); reconnecting")
        self.get_logger().warn(f"{self.device_name}: {self.port} lost ({error}); reconnecting")
        self._publish_diagnostics()

    def _publish_diagnostics(self) -> None:
        if self._closed:
            return
        with contextlib.suppress(Exception):  # context shutting down
            self.diagnostics.publish()

    # -- executor side
    def _housekeeping(self) -> None:
        now = self.now_ns()
        self.raw.flush(end_batch=False)  # bytes of a report that never completed: recorded all the same
        st = self.transport.status()
        if not st.connected and not self._ever_connected:
            self.diag.set_state("disconnected", DiagnosticStatus.ERROR,
                                f"cannot open {self.port}: {st.last_error or 'opening'}")
            if st.open_failures:
                self.get_logger().warn(f"{self.device_name}: cannot open {self.port} ({st.last_error}); retrying",
                                       throttle_duration_sec=10.0)
        elif st.connected:
            no_data = now - max(self._last_publish_ns, self._last_link_ns) > NO_DATA_TIMEOUT_S * 1e9
            if no_data != self._no_data:
                self._no_data = no_data
                if no_data:
                    self.diag.set_state("connected", DiagnosticStatus.WARN, f"connected to {self.port}, no data")
                else:
                    self.diag.set_state("connected", DiagnosticStatus.OK, f"connected to {self.port}")
        try:
            self.housekeeping(now)
        except Exception as exc:  # noqa: BLE001
            self.diag.count("internal_error")
            self.get_logger().error(f"{self.device_name}: housekeeping failed: {exc!r}", throttle_duration_sec=5.0)

    def _diag_extra(self) -> List[Tuple[str, Any]]:
        st = self.transport.status()
        values: List[Tuple[str, Any]] = [
            ("port", self.port), ("baud_rate", self.baud_rate), ("connected", st.connected),
            ("reconnects", st.reconnects), ("open_failures", st.open_failures), ("bytes_rx", st.bytes_rx),
            ("bytes_tx", st.bytes_tx), ("last_transport_error", st.last_error or ""),
            ("startup_commands_sent", self.commands.commands_sent),
            ("startup_sequences_completed", self.commands.sequences_completed),
        ]
        try:
            values += list(self.extra_diagnostics())
        except Exception as exc:  # noqa: BLE001
            values.append(("extra_diagnostics_error", repr(exc)))
        return values

    def close(self) -> None:
        """Stop the command thread and the transport (joins the reader thread). Idempotent; called by
        :func:`~hindrax_common.node_support.node_common.run_node` on shutdown and by :meth:`destroy_node`."""
        if self._closed:
            return
        self._closed = True
        self.commands.close()
        self.transport.close()

    def destroy_node(self) -> None:
        self.close()
        super().destroy_node()
