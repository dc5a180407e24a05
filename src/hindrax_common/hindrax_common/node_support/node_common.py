"""Pieces every Hindrax driver node shares: diagnostics, raw-traffic publishing, stuck-value detection,
configuration loading and the process entry point.

Keeping them here (docs/architecture.md §2: "no copy-paste between devices") means each device node only wires its
transport to its protocol module. All time here is ROS time from the node's clock (``use_sim_time``
supported), except rate windows, which use the same clock."""
from __future__ import annotations

import collections
import struct
import sys
import threading
from typing import Any, Callable, Iterable, Sequence

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import ParameterDescriptor, ParameterType
from rclpy.qos import QoSProfile, ReliabilityPolicy

from hindrax_msgs.msg import RawDeviceData

from ..config import ConfigError, VehicleConfig
from ..config.node_parameters import declare_vehicle_parameters
from ..process import ros_process
from ..process.ros_process import RosProcess
from ..process.scheduling import apply_realtime_priority, describe as describe_scheduling
from .vehicle_graph import ForeignVehicleError, refuse_live_peer

#: QoS depth used for sensor topics (sensor-data QoS is best effort; parsed topics use reliable, depth 10)
DEFAULT_QOS_DEPTH = 10


def sensor_input_qos(depth: int) -> QoSProfile:
    """QoS of a reader of sensor samples (the supervisor's, the controller's and the identification's sensor
    inputs): keep last ``depth``, best effort, volatile. It matches the drivers' reliable writers; a best-effort
    reader sends no acknowledgements, so a writer whose readers are all best effort runs no reliability protocol
    (Fast DDS: 1.6 event-thread wake-ups per sample less, docs/architecture.md §10.1). On the vehicle's loopback a
    sample is lost only to a full socket buffer, and every reader here takes the newest sample and counts rates."""
    return QoSProfile(depth=int(depth), reliability=ReliabilityPolicy.BEST_EFFORT)


def log_at(logger: Any, level: str, text: str) -> None:
    """Log ``text`` at ``level`` ("debug", "info", "warn", "error") on an rclpy logger.

    rclpy's logger keys its context by the calling line and raises ``ValueError: Logger severity cannot be changed
    between calls`` when one line logs at two severities (``rclpy.impl.rcutils_logger.RcutilsLogger.log``), so a
    ``getattr(logger, level)(text)`` crashed the caller the first time a level differed. Each severity is called from
    a line of its own here. Raises ``ValueError`` for any other level."""
    if level == "debug":
        logger.debug(text)
    elif level == "info":
        logger.info(text)
    elif level == "warn":
        logger.warning(text)
    elif level == "error":
        logger.error(text)
    else:
        raise ValueError(f"log level {level!r}: not one of debug, info, warn, error")


def time_from_ns(ns: int) -> Time:
    """builtin_interfaces/Time from integer nanoseconds (negative values clamp to 0)."""
    ns = max(0, int(ns))
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


class DeviceDiagnostics:
    """Counters and state of one device, rendered as a ``diagnostic_msgs/DiagnosticStatus``.

    name: status name, e.g. ``"hindrax/dvl75"``; hardware_id: port or I2C address; the output rate
    is counted over a sliding window of ``window_s`` seconds. Error kinds: ``"bad_checksum"``,
    ``"garbage_bytes"``, ``"i2c_error"`` ...; states: ``"connected"``, ``"disconnected"`` ...
    Thread-safe: transports may call :meth:`count` from their own threads."""

    def __init__(self, name: str, hardware_id: str, now_s: Callable[[], float], window_s: float = 5.0):
        self.name = name
        self.hardware_id = hardware_id
        self._now_s = now_s
        self._window_s = window_s
        self._lock = threading.Lock()
        self._stamps: collections.deque[float] = collections.deque()
        self._counts: dict[str, int] = collections.Counter()
        self._warnings: dict[str, str] = {}
        self._errors: dict[str, str] = {}
        self._state = "starting"
        self._level = DiagnosticStatus.WARN
        self._message = "starting"
        self._last_publish_s: float | None = None
        self.total_published = 0

    def published(self, now_s: float | None = None) -> None:
        """Record one published output message at ``now_s`` (the clock's time, s; read from the clock when None)."""
        t = self._now_s() if now_s is None else now_s
        with self._lock:
            self._stamps.append(t)
            self._last_publish_s = t
            self.total_published += 1
            while self._stamps and self._stamps[0] < t - self._window_s:
                self._stamps.popleft()

    @property
    def last_publish_s(self) -> float | None:
        """The clock's time of the last :meth:`published` message, s (None before the first)."""
        with self._lock:
            return self._last_publish_s

    def count(self, kind: str, n: int = 1) -> None:
        """Add ``n`` to the error counter ``kind``."""
        if n:
            with self._lock:
                self._counts[kind] += n

    def counts(self) -> dict[str, int]:
        """Snapshot of the error counters."""
        with self._lock:
            return dict(self._counts)

    def set_state(self, state: str, level: int = DiagnosticStatus.OK, message: str = "") -> None:
        """Set the device state (``level``: DiagnosticStatus.OK/WARN/ERROR/STALE)."""
        with self._lock:
            self._state, self._level, self._message = state, level, message or state

    @property
    def state(self) -> str:
        return self._state

    def warn(self, key: str, message: str) -> None:
        """Raise (or update) a named warning, e.g. ``warn("stuck", "identical readings for 5 s")``."""
        with self._lock:
            self._warnings[key] = message

    def error(self, key: str, message: str) -> None:
        """Raise (or update) a named ERROR condition, e.g. ``error("stuck", "identical readings for 2 s")``."""
        with self._lock:
            self._errors[key] = message

    def clear(self, key: str) -> None:
        """Clear a named warning or ERROR condition."""
        with self._lock:
            self._warnings.pop(key, None)
            self._errors.pop(key, None)

    def rate_hz(self) -> float:
        """Published messages per second over the sliding window."""
        t = self._now_s()
        with self._lock:
            while self._stamps and self._stamps[0] < t - self._window_s:
                self._stamps.popleft()
            n = len(self._stamps)
        return n / self._window_s

    def status(self, extra: Iterable[tuple[str, Any]] = ()) -> DiagnosticStatus:
        """The DiagnosticStatus now: level = worst of the state level and any warning."""
        rate = self.rate_hz()
        t = self._now_s()
        with self._lock:
            level = self._level
            message = self._message
            if self._warnings and level < DiagnosticStatus.WARN:
                level = DiagnosticStatus.WARN
            if self._errors and level < DiagnosticStatus.ERROR:
                level = DiagnosticStatus.ERROR
            if self._warnings or self._errors:
                message = "; ".join([message] + list(self._errors.values()) + list(self._warnings.values()))
            age = (t - self._last_publish_s) if self._last_publish_s is not None else float("inf")
            values = [("state", self._state), ("rate_hz", f"{rate:.2f}"),
                      ("last_message_age_s", f"{age:.3f}"), ("messages_published", str(self.total_published))]
            values += [(f"errors.{k}", str(v)) for k, v in sorted(self._counts.items())]
        values += [(k, str(v)) for k, v in extra]
        st = DiagnosticStatus(level=bytes([level]) if isinstance(level, int) else level, name=self.name,
                              message=message, hardware_id=self.hardware_id)
        st.values = [KeyValue(key=k, value=v) for k, v in values]
        return st


class DiagnosticsPublisher:
    """Publishes the statuses of one node's devices on ``/diagnostics`` at ``rate_hz`` (ROS timer)."""

    def __init__(self, node: Any, devices: Sequence[DeviceDiagnostics],
                 extra: Callable[[], Iterable[tuple[str, Any]]] | None = None, rate_hz: float = 1.0):
        self._node = node
        self._devices = list(devices)
        self._extra = extra
        self.publisher = node.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.timer = node.create_timer(1.0 / rate_hz, self.publish)

    def publish(self) -> None:
        msg = DiagnosticArray()
        msg.header.stamp = self._node.get_clock().now().to_msg()
        extra = list(self._extra()) if self._extra else []
        msg.status = [d.status(extra if i == 0 else ()) for i, d in enumerate(self._devices)]
        self.publisher.publish(msg)


#: ``i2c_register`` of a RawDeviceData message that carries several I2C transactions (see RawDataPublisher)
RAW_BATCH_REGISTER = -2
_RAW_RECORD = struct.Struct("<BBhH")  # direction, 7-bit address, register (-1 none), data length
#: I2C transactions of read cycles are published together at most this often (ROS time), s (RawDataPublisher): raw/*
#: is read by the recorder alone, so each message is a delivery for the bag only (docs/pi_budget.md)
RAW_I2C_PERIOD_S = 0.5
#: ... or as soon as this many bytes of records are pending
RAW_I2C_MAX_BYTES = 16384


class RawDataPublisher:
    """Publishes raw device traffic as ``hindrax_msgs/RawDeviceData`` on ``raw/<device>``.

    Use :meth:`serial_tap` as a serial transport's raw tap ``(direction 'rx'|'tx', data, t)`` and
    :meth:`i2c_tap` as an I2C helper's raw tap ``(kind 'read'|'write', address, register, data, t)``.
    Stamps are the node's ROS time at publication. Safe to call from transport threads.

    Batching: between :meth:`begin_batch` and :meth:`flush` the taps are collected. Serial: one message per parsed
    report (a host->device write flushes first: one direction per message). I2C: kept until ``i2c_period_s``
    (:data:`RAW_I2C_PERIOD_S`, ROS time) has passed since the oldest, or :data:`RAW_I2C_MAX_BYTES` are pending (a
    publish costs far more than its bytes, docs/architecture.md §10.1), then one message of records
    ``<direction u8, address u8, register i16, length u16 (little-endian), data>`` with
    ``i2c_register = RAW_BATCH_REGISTER`` (-2), or a plain message for one transaction; :func:`raw_transactions` unpacks
    both, in wire order. ``flush(force=True)`` publishes what is pending; a tap outside a batch publishes it at once, so
    the order on the wire is kept."""

    def __init__(self, node: Any, device_name: str, topic: str | None = None, i2c_period_s: float = RAW_I2C_PERIOD_S):
        self._node = node
        self.device_name = device_name
        self.publisher = node.create_publisher(RawDeviceData, topic or f"raw/{device_name}", 100)
        self.i2c_period_s = float(i2c_period_s)
        self._lock = threading.Lock()
        self._batching = False
        self._serial: bytearray = bytearray()
        self._i2c: list[tuple[int, int, int, bytes]] = []
        self._i2c_bytes = 0
        self._i2c_since_ns: int | None = None
        self._closed = False

    def _publish(self, msg: Any) -> None:
        """Publish ``msg``; nothing once :meth:`close` ran or the ROS context is shut down (a transport thread's
        last records at shutdown, e.g. the ESC's neutral write: lost with the process, at most ``i2c_period_s``)."""
        if self._closed:
            return
        try:
            self.publisher.publish(msg)
        except Exception:  # noqa: BLE001 - rclpy raises its own types for a publisher whose context is gone
            if self._node.context.ok():
                raise

    def close(self) -> None:
        """Publish nothing from now on (the node is being destroyed; a transport thread may still call a tap)."""
        self._closed = True

    def _msg(self, transport: int, direction: int, data: bytes, address: int = 0, register: int = -1):
        m = RawDeviceData()
        m.header.stamp = self._node.get_clock().now().to_msg()
        m.device_name = self.device_name
        m.transport = transport
        m.direction = direction
        m.i2c_address = address
        m.i2c_register = register
        m.data = bytes(data)
        return m

    def begin_batch(self) -> None:
        """Collect the taps from now on until :meth:`flush` (see the class docstring)."""
        with self._lock:
            self._batching = True

    @property
    def pending_bytes(self) -> int:
        """Bytes collected and not yet published."""
        with self._lock:
            return len(self._serial) + self._i2c_bytes

    def _i2c_due(self) -> bool:
        if self._i2c_bytes >= RAW_I2C_MAX_BYTES or self.i2c_period_s <= 0.0 or self._i2c_since_ns is None:
            return True
        return self._node.get_clock().now().nanoseconds - self._i2c_since_ns >= self.i2c_period_s * 1e9

    def flush(self, end_batch: bool = True, force: bool = False) -> None:
        """Publish what was collected: the serial chunks; the I2C transactions when their period is over or
        ``force`` (nothing when nothing was); ``end_batch``: publish taps at once again."""
        with self._lock:
            serial, self._serial = self._serial, bytearray()
            i2c: list = []
            if self._i2c and (force or self._i2c_due()):
                i2c, self._i2c, self._i2c_bytes, self._i2c_since_ns = self._i2c, [], 0, None
            if end_batch:
                self._batching = False
        if serial:
            self._publish(self._msg(RawDeviceData.TRANSPORT_SERIAL, RawDeviceData.DIRECTION_DEVICE_TO_HOST, serial))
        if len(i2c) == 1:
            d, address, reg, data = i2c[0]
            self._publish(self._msg(RawDeviceData.TRANSPORT_I2C, d, data, address, reg))
        elif i2c:
            packed = b"".join(_RAW_RECORD.pack(d, a, r, len(data)) + data for d, a, r, data in i2c)
            self._publish(self._msg(RawDeviceData.TRANSPORT_I2C, i2c[0][0], packed, i2c[0][1], RAW_BATCH_REGISTER))

    def serial_tap(self, direction: str, data: bytes, _t: float | None = None) -> None:
        if direction == "rx":
            with self._lock:
                if self._batching:
                    self._serial += data
                    return
            self._publish(self._msg(RawDeviceData.TRANSPORT_SERIAL, RawDeviceData.DIRECTION_DEVICE_TO_HOST, data))
            return
        self.flush(end_batch=False)  # received bytes first: one direction per message, in wire order
        self._publish(self._msg(RawDeviceData.TRANSPORT_SERIAL, RawDeviceData.DIRECTION_HOST_TO_DEVICE, data))

    def flush_pending(self) -> None:
        """Publish everything still held (at shutdown, and before a recording is closed); nothing when the ROS
        context is already shut down (the records are then lost with the process, at most ``i2c_period_s``)."""
        self.flush(end_batch=False, force=True)

    def i2c_tap(self, kind: str, address: int, register: int | None, data: bytes, _t: float | None = None) -> None:
        d = RawDeviceData.DIRECTION_DEVICE_TO_HOST if kind == "read" else RawDeviceData.DIRECTION_HOST_TO_DEVICE
        reg = -1 if register is None else int(register)
        record = (d, int(address), reg, bytes(data))
        with self._lock:
            pending = self._batching or bool(self._i2c)  # decided under the lock: the wire order is kept
            if pending:  # in a batch, or after pending records (published together below)
                if self._i2c_since_ns is None:
                    self._i2c_since_ns = self._node.get_clock().now().nanoseconds
                self._i2c.append(record)
                self._i2c_bytes += len(record[3]) + _RAW_RECORD.size
                if self._batching:
                    return
        if pending:
            self.flush(end_batch=False, force=True)  # outside a batch: what was pending, with this one, at once
            return
        self._publish(self._msg(RawDeviceData.TRANSPORT_I2C, d, data, address, reg))


def raw_transactions(msg: Any) -> list[tuple[int, int, int, bytes]]:
    """The I2C transactions of one RawDeviceData message: ``[(direction, address, register, data)]`` in wire
    order (one for a plain message, several for a batch, see :class:`RawDataPublisher`; ``register`` -1 = none).

    Raises ValueError for a batch whose records do not add up to its data."""
    data = bytes(msg.data)
    if int(msg.i2c_register) != RAW_BATCH_REGISTER:
        return [(int(msg.direction), int(msg.i2c_address), int(msg.i2c_register), data)]
    out, k = [], 0
    while k < len(data):
        if k + _RAW_RECORD.size > len(data):
            raise ValueError(f"raw batch of {msg.device_name}: truncated record header at byte {k}")
        d, a, r, n = _RAW_RECORD.unpack_from(data, k)
        k += _RAW_RECORD.size
        if k + n > len(data):
            raise ValueError(f"raw batch of {msg.device_name}: record of {n} bytes at byte {k} runs past the end")
        out.append((d, a, r, data[k:k + n]))
        k += n
    return out


class StuckDetector:
    """Flags a sensor whose readings stay bit-identical for ``limit`` consecutive samples.

    ``update(value) -> bool`` returns True while stuck. Real sensors always show noise in the last bits,
    so identical raw readings mean a frozen device or bus (docs/devices.md emulator checklists)."""

    def __init__(self, limit: int = 50):
        self.limit = limit
        self._last: Any = None
        self._repeats = 0

    def update(self, value: Any) -> bool:
        if value == self._last:
            self._repeats += 1
        else:
            self._last = value
            self._repeats = 0
        return self._repeats >= self.limit


class StuckAlarm:
    """A device's ERROR ``stuck`` over a :class:`StuckDetector`: raised in ``diag`` (counted ``stuck_events``) when
    ``limit`` raw readings in a row are bit-identical (:attr:`raised` True on that update), cleared when they change."""

    def __init__(self, limit: int, diag: DeviceDiagnostics) -> None:
        self.limit, self.diag = int(limit), diag
        self.detector = StuckDetector(self.limit)
        self.stuck = self.raised = False

    def update(self, value: Any, text: str) -> bool:
        """Feed one raw reading (compared with ``==``; ``text``: what is identical, for the ERROR); True while stuck."""
        stuck = self.detector.update(value)
        self.raised = stuck and not self.stuck
        if self.raised:
            self.diag.error("stuck", f"stuck: {text} for >= {self.limit} readings")
            self.diag.count("stuck_events")
        elif self.stuck and not stuck:
            self.diag.clear("stuck")
        self.stuck = stuck
        return stuck

    def reset(self) -> None:
        """A restarted device: no readings seen, the ERROR cleared."""
        self.detector = StuckDetector(self.limit)
        self.stuck = self.raised = False
        self.diag.clear("stuck")


class OneShot:
    """One callback at a time, once, after a delay of ``node``'s ROS time, from one timer (a device's waits without
    sleeping in a callback): ``schedule(delay_s, fn)`` replaces what was pending."""

    def __init__(self, node: Any) -> None:
        self._fn: Callable[[], None] | None = None
        self._timer = node.create_timer(1.0, self._fire, autostart=False)

    def schedule(self, delay_s: float, fn: Callable[[], None]) -> None:
        """Run ``fn`` once after ``delay_s`` (s; 0: at the next executor turn)."""
        self._fn = fn
        self._timer.timer_period_ns = max(1, int(delay_s * 1e9))
        self._timer.reset()

    def cancel(self) -> None:
        """Drop what is pending."""
        self._timer.cancel()
        self._fn = None

    def _fire(self) -> None:
        self._timer.cancel()
        fn, self._fn = self._fn, None
        if fn is not None:
            fn()


def load_node_config(node: Any, keys: Sequence[str] | None = None, *, dynamic: Sequence[str] = (),
                     on_change: Callable[[VehicleConfig], None] | None = None,
                     locked: Callable[[], str] | None = None) -> VehicleConfig:
    """Declare the node's own vehicle keys (with descriptors) and return them validated.

    keys: SCHEMA prefixes the node reads (None: all sections); dynamic: prefixes it applies while running
    (the rest are read-only); on_change(cfg) applies a validated change or raises ValueError with the reason;
    locked() gives the reason a change is refused now ('' = allowed: the ESC disarmed, ``ArmedWatch.refusal``).
    See :func:`hindrax_common.config.node_parameters.declare_vehicle_parameters` (the node must be created without
    ``automatically_declare_parameters_from_overrides``). Raises :class:`ConfigError`: :func:`run_node` prints its
    one line once and exits with status 1."""
    return declare_vehicle_parameters(node, keys, dynamic=dynamic, on_change=on_change, locked=locked)


def run_node(factory: Callable[[], Any], args: Sequence[str] | None = None, executor: str | None = None,
             exit_process: bool = True) -> int:
    """Process entry point of one node (``factory`` creates it after ``rclpy.init``): :func:`run_nodes`."""
    return run_nodes([factory], args, executor, exit_process)


def run_nodes(factories: Sequence[Callable[[], Any]], args: Sequence[str] | None = None,
              executor: str | None = None, exit_process: bool = True) -> int:
    """Process entry point of nodes composed in one process (:mod:`hindrax_bringup.layout.composition`): the nodes are
    built in order after ``rclpy.init`` and spun by one executor; on exit they are closed and destroyed in the reverse
    order (the last built first). executor: ``events``, ``single`` or None for the default
    (:mod:`hindrax_common.process.ros_process`: the EventsExecutor unless ``HINDRAX_EXECUTOR=single``). Returns the exit
    status: 0 on SIGINT/SIGTERM, 1 on an invalid configuration (one line on stderr naming key, value, allowed range) or
    when another vehicle's live ESC or supervisor is on the domain of a process running one (a node class's
    ``START_CHECK``: one line ``refused: ...``, :func:`~hindrax_common.node_support.vehicle_graph.refuse_live_peer`,
    before any node is built); an exception out of any node's callback ends the whole process (every node's ``close()``
    still runs). SIGINT shuts the process down like SIGTERM, without a ``KeyboardInterrupt`` in a callback
    (:class:`~hindrax_common.process.ros_process.RosProcess`, ``interrupt=False``). Before ``rclpy.init`` the process
    takes the real-time priority its environment asks for (:mod:`hindrax_common.process.scheduling`; a bad value of
    ``HINDRAX_REALTIME_PRIORITY`` is an invalid configuration), and logs the outcome once its nodes are built. A
    shutdown that takes longer than :data:`~hindrax_common.process.ros_process.SHUTDOWN_BUDGET_S` (8 s) writes every
    thread's traceback to stderr and exits with status 1 (:class:`~hindrax_common.process.ros_process.RosProcess`).
    exit_process: in the main thread the process ends on return, without the DDS participant's teardown
    (:mod:`hindrax_common.process.ros_process`): the exit status becomes the process's; False returns it."""
    try:
        sched = apply_realtime_priority()
    except ValueError as exc:
        print(f"invalid configuration: {exc}", file=sys.stderr)
        return 1
    with RosProcess(args, errors={ConfigError: "invalid configuration", ForeignVehicleError: "refused"},
                    executor=executor, interrupt=False, shutdown_budget_s=ros_process.SHUTDOWN_BUDGET_S,
                    exit_process=exit_process) as proc:
        for kind in dict.fromkeys(k for f in factories if (k := getattr(f, "START_CHECK", None))):
            refuse_live_peer(kind, "refusing to start a second vehicle on it (one ROS_DOMAIN_ID per vehicle)")
        nodes = [proc.own(factory()) for factory in factories]
        level, text = describe_scheduling(sched)
        if level and nodes:
            log_at(nodes[0].get_logger(), level, text)
        for node in nodes:
            proc.executor.add_node(node)
        proc.spin()
    return proc.status


def declare_frame_ids(node: Any, defaults: dict[str, str]) -> dict[str, str]:
    """Declare a node's frame ids as read-only string parameters and return their values.

    ``defaults`` maps a parameter name (``frame_id``, ``base_frame_id``, ...) to its REP-103/REP-105 default
    (``imu_link``, ``base_link``, ``odom``), the frames the static TF node publishes (docs/architecture.md §3). As
    the ROS drivers do (nmea_navsat_driver, phidgets), a vehicle with other frame names sets them with
    ``-p frame_id:=...`` instead of editing code. A value that is already declared (a composed process) is reused.

    Raises ``ValueError``: an empty frame id or one starting with ``/`` (tf2 frame ids have no leading slash), naming
    the parameter and the value in one line."""
    out: dict[str, str] = {}
    for name, default in defaults.items():
        if node.has_parameter(name):
            value = node.get_parameter(name).value
        else:
            value = node.declare_parameter(name, default, ParameterDescriptor(
                type=ParameterType.PARAMETER_STRING, read_only=True,
                description=f"frame id of the published messages' headers (REP-103/105 default {default!r})")).value
        value = str(value)
        if not value or value.startswith("/"):
            raise ValueError(f"parameter {name}: {value!r} is not a tf2 frame id (non-empty, no leading '/')")
        out[name] = value
    return out
