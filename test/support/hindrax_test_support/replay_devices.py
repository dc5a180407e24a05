"""Mock hardware from a bag: the device emulators take their truth from recorded raw device data.

docs/architecture.md §6-7: "the same emulators can be driven from a recorded bag (raw device data replayed through the
drivers)". A bag recorded by the stack holds every byte and register transaction of every driver
(``hindrax_msgs/RawDeviceData`` on ``raw/<device>``, see :class:`~.node_common.RawDataPublisher`).
This module serves them again to *fresh, unmodified* driver nodes through the same transports the simulator
uses, so the real parsing code runs on the recorded stream:

- :class:`SerialReplayDevice` (a :class:`~hindrax_common.transport.pty_device.ByteStreamEmulator`, served on a pty by
  :class:`~hindrax_common.transport.pty_device.PtyDevice`): emits the recorded device->host chunks in order, each at the
  step of the replay clock that reaches its recorded receive time (``paced=True``) or all at once (``paced=False``).
  Host->device bytes are ignored (the recorded replies are in the device->host stream already).
- :class:`I2CReplayDevice` (one per I2C address on an :class:`~hindrax_common.transport.emulated_i2c.EmulatedI2CBus`):
  answers each read transaction with the next recorded read data *of that register* (the register pointer is the first
  byte of the preceding write, as on the wire), and accepts writes, comparing each with the next recorded write of the
  address (:attr:`I2CReplayDevice.write_mismatches`). When a register's recorded reads are used up, reads NACK
  (``OSError`` errno 121, as an absent device): the driver counts an I2C failure and publishes nothing, so a replay
  never invents data.
- :class:`ReplayHardware`: all of it for one bag (``dvl75`` and ``ping1d`` on ptys served by the
  caller, every recorded I2C device on one bus).
- :class:`DriverReplay`: the driver nodes (DVL-75, Ping1D, MS5837, ICM-20948, ESC) on that hardware with
  ``use_sim_time``, a ``/clock`` publisher stepping through the recorded ``/clock`` values (or, without them, a 100 Hz
  grid over the recorded span), and a probe collecting every parsed message; it runs until every recorded device->host
  byte and every recorded I2C read has been consumed. The serial devices run in lock-step with that clock, as in the
  simulator that records such bags: at each step, every driver's clock already there, the chunks due are written and
  each driver reads and handles them in the harness's thread (``SerialTransport.pump``) before time moves on, so every
  chunk is received at its recorded time whatever the load (a rule on receive times, such as the DVL node's "no
  ``$DVPDL`` for 1 s", sees the recorded gaps).

What "the same" means after a replay: :func:`compare_parsed` (checked by ``test/test_bag_replay_drivers.py``)."""
from __future__ import annotations

import collections
import copy
import errno
import math
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile
from rclpy.serialization import deserialize_message
from rosgraph_msgs.msg import Clock

from hindrax_msgs.msg import RawDeviceData

from hindrax_common.base import devices as device_table
from hindrax_common.config import load_config
from hindrax_common.node_support.node_common import raw_transactions, time_from_ns
from hindrax_drivers.pca9685.emulator import Pca9685Emulator
from hindrax_common.transport.emulated_i2c import EmulatedI2CBus
from hindrax_common.transport.pty_device import PtyDevice
from hindrax_bringup.recording.msgtypes import message_class
from hindrax_bringup.recording.reader import BagReader

__all__ = ["SerialReplayDevice", "I2CReplayDevice", "ReplayHardware", "DriverReplay", "PARSED_TOPICS", "I2C_STAMPED",
           "iter_raw_device_data", "serial_chunks", "i2c_transactions", "compare_parsed", "strip_stamp"]

#: Parsed topics of the driver nodes (absolute names, :data:`~hindrax_common.base.devices.DEVICES`), with the device
#: whose raw data they are parsed from.
PARSED_TOPICS: dict[str, str] = {t: d.name for d in device_table.DEVICES for t in d.topics}
#: Topics of the I2C drivers, stamped with the ROS time of a read their own timers make: not
#: lock-stepped with the replay (compare_parsed).
I2C_STAMPED = frozenset(t for d in device_table.DEVICES if d.transport == device_table.I2C for t in d.topics)

_NACK = errno.EREMOTEIO  # 121, what i2c-dev returns for an unanswered address


def iter_raw_device_data(bag_path: str | Path, device_name: str) -> Iterator[tuple[int, Any]]:
    """``(t_ns, hindrax_msgs.msg.RawDeviceData)`` of one device, in the order they were recorded.

    Every topic of type ``hindrax_msgs/msg/RawDeviceData`` is read (merged in log-time order) and messages whose
    ``device_name`` equals ``device_name`` are yielded. ``t_ns`` is the message's ``header.stamp`` (the
    time the driver received or sent the bytes, ROS time) in ns, or the bag log time when the stamp is
    zero. Both directions (DIRECTION_DEVICE_TO_HOST / HOST_TO_DEVICE) are yielded; filter on
    ``msg.direction``. Raises FileNotFoundError/BagError for a bad path."""
    reader = BagReader(bag_path)
    topics = [t for t, c in reader.channels.items() if c.type == "hindrax_msgs/msg/RawDeviceData"]
    for m in reader.messages(topics) if topics else ():
        msg = deserialize_message(m.data, RawDeviceData)
        if msg.device_name == device_name:
            stamp_ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            yield (stamp_ns if stamp_ns > 0 else m.log_time_ns), msg


def serial_chunks(items: Iterable[tuple[int, Any]]) -> tuple[list[tuple[int, bytes]], list[tuple[int, bytes]]]:
    """Split ``iter_raw_device_data`` output of a serial device into (device->host, host->device) lists of
    ``(t_ns, bytes)`` in recorded order. I2C messages are ignored."""
    rx: list[tuple[int, bytes]] = []
    tx: list[tuple[int, bytes]] = []
    for t, m in items:
        if m.transport != RawDeviceData.TRANSPORT_SERIAL:
            continue
        (rx if m.direction == RawDeviceData.DIRECTION_DEVICE_TO_HOST else tx).append((int(t), bytes(m.data)))
    return rx, tx


@dataclass
class I2CTransactions:
    """Recorded I2C traffic of one address: ``reads[register]`` = data of each read in order (register -1:
    a read without register, e.g. SMBus receive byte); ``writes`` = the bytes of each write transaction
    (register byte first) in order."""

    reads: dict[int, list[bytes]] = field(default_factory=dict)
    writes: list[bytes] = field(default_factory=list)


def i2c_transactions(items: Iterable[tuple[int, Any]]) -> dict[int, I2CTransactions]:
    """Group ``iter_raw_device_data`` output of an I2C device by 7-bit address (see :class:`I2CTransactions`).

    The driver tap records a write as (register, payload) and ``write_byte(value)`` as (value, b"")
    (:class:`~hindrax_common.transport.i2c.I2CDevice`), so the wire bytes are ``[register] + payload``."""
    out: dict[int, I2CTransactions] = {}
    for _t, m in items:
        if m.transport != RawDeviceData.TRANSPORT_I2C:
            continue
        for direction, address, reg, data in raw_transactions(m):  # one, or a read cycle's batch
            tr = out.setdefault(address, I2CTransactions())
            if direction == RawDeviceData.DIRECTION_DEVICE_TO_HOST:
                tr.reads.setdefault(reg, []).append(data)
            else:
                tr.writes.append((bytes([reg]) if reg >= 0 else b"") + data)
    return out


class SerialReplayDevice:
    """Byte-stream emulator that plays back recorded device->host chunks (see the module docstring).

    Args:
        chunks: ``(t_ns, data)`` device->host chunks in recorded order (ROS time of receipt, ns).
        paced: emit a chunk only once ``poll(t_s)`` reaches its time; False: emit everything at the first poll.
    Attributes:
        total_bytes: device->host bytes recorded in all."""

    def __init__(self, chunks: Iterable[tuple[int, bytes]], paced: bool = True) -> None:
        self._chunks = collections.deque((int(t), bytes(d)) for t, d in chunks)
        self.paced = bool(paced)
        self.total_bytes = sum(len(d) for _, d in self._chunks)

    def feed_host_bytes(self, data: bytes) -> None:
        """Host->device bytes: never answered (the answers are recorded)."""

    def poll(self, t_s: float) -> bytes:
        """The recorded chunks due by ``t_s`` (s of ROS time; 1 us tolerance for the float conversion)."""
        limit_ns = math.inf if not self.paced else int(round(t_s * 1e9)) + 1000
        out = bytearray()
        while self._chunks and self._chunks[0][0] <= limit_ns:
            out += self._chunks.popleft()[1]
        return bytes(out)

    @property
    def done(self) -> bool:
        """True when every recorded chunk has been emitted."""
        return not self._chunks


class I2CReplayDevice:
    """I2C device emulator answering from recorded transactions (see the module docstring).

    A one-byte write immediately followed by a read is the register pointer of that read (what
    ``read_i2c_block_data`` / ``read_byte_data`` put on the wire); any other write is a write transaction
    and is compared with the next recorded write. Thread-safe.

    Args:
        transactions: the recorded traffic of this address (:func:`i2c_transactions`).
    Attributes:
        write_mismatches: list of (index, recorded, replayed); writes past the recording: ignored."""

    def __init__(self, transactions: I2CTransactions) -> None:
        self._lock = threading.RLock()
        self._reads = {reg: collections.deque(v) for reg, v in transactions.reads.items()}
        self._writes = list(transactions.writes)
        self._write_index = 0
        self._pending: bytes | None = None
        self.write_mismatches: list[tuple[int, bytes, bytes]] = []

    def _commit_write(self, data: bytes) -> None:
        if self._write_index >= len(self._writes):
            return
        expected = self._writes[self._write_index]
        self._write_index += 1
        if expected != data:
            self.write_mismatches.append((self._write_index - 1, expected, bytes(data)))

    def i2c_write(self, data: bytes) -> None:
        """One write transaction (see the class docstring)."""
        with self._lock:
            self.flush()  # a pending one-byte write had no read after it (RLock: re-entered)
            if len(data) == 1:
                self._pending = bytes(data)  # pointer of a following read, or a command byte
            elif data:
                self._commit_write(bytes(data))

    def i2c_read(self, n: int) -> bytes:
        """One read transaction: the next recorded read of the current register. Raises OSError(121) when
        none is left or its length is not ``n``."""
        with self._lock:
            register = self._pending[0] if self._pending is not None else -1
            self._pending = None
            queue = self._reads.get(register)
            if not queue or len(queue[0]) != n:
                raise OSError(_NACK, f"replay: no recorded {n}-byte read of register {register} left")
            return queue.popleft()

    def flush(self) -> None:
        """Account a trailing one-byte write (a command byte with no read after it)."""
        with self._lock:
            if self._pending is not None:
                self._commit_write(self._pending)
                self._pending = None

    @property
    def reads_left(self) -> int:
        """Recorded reads not served yet."""
        with self._lock:
            return sum(len(q) for q in self._reads.values())

    @property
    def writes_left(self) -> int:
        """Recorded writes not compared yet."""
        with self._lock:
            return len(self._writes) - self._write_index


class ReplayHardware:
    """Replay devices of every device in a bag, on ptys and one emulated I2C bus.

    Args:
        bag_path: the bag (directory or .mcap).
        devices: device names to serve (default: those of :data:`~hindrax_common.base.devices.DEVICES` with raw data
            in the bag).
        paced: see :class:`SerialReplayDevice`.
    Attributes:
        serial (name -> SerialReplayDevice), ptys (name -> PtyDevice without a thread: served by :class:`DriverReplay`),
        ports (name -> pty path), i2c (address -> I2CReplayDevice), i2c_device_of (address -> device name), i2c_bus.
    Raises:
        FileNotFoundError / BagError: bad bag path."""

    def __init__(self, bag_path: str | Path, devices: Iterable[str] | None = None, paced: bool = True) -> None:
        self.serial: dict[str, SerialReplayDevice] = {}
        self.ptys: dict[str, Any] = {}
        self.ports: dict[str, str] = {}
        self.i2c: dict[int, I2CReplayDevice] = {}
        self.outputs: dict[int, Any] = {}  # PCA9685: emulated, not replayed (see below)
        self.i2c_device_of: dict[int, str] = {}
        table = {d.name: d for d in device_table.DEVICES}
        for name in tuple(devices) if devices is not None else table:
            items = list(iter_raw_device_data(bag_path, name))
            if table[name].transport == device_table.SERIAL:
                rx, tx = serial_chunks(items)
                if not rx and not tx:
                    continue
                dev = SerialReplayDevice(rx, paced=paced)
                self.serial[name] = dev
                self.ptys[name] = PtyDevice(dev, link_name=name, start=False)
                self.ports[name] = str(self.ptys[name].path)
            elif table[name].output:
                # an output device: its reads only echo the driver's writes, and the ESC node's read-back runs on the
                # steady clock (docs/architecture.md §8), so their number depends on wall time, not on the bag: the
                # register-exact emulator answers them (its outputs are not compared)
                for address in i2c_transactions(items):
                    self.outputs[address] = Pca9685Emulator()
                    self.i2c_device_of[address] = name
            else:
                for address, tr in i2c_transactions(items).items():
                    self.i2c[address] = I2CReplayDevice(tr)
                    self.i2c_device_of[address] = name
        self.i2c_bus = EmulatedI2CBus({**self.i2c, **self.outputs})

    def serial_done(self, name: str, bytes_read: int) -> bool:
        """True when every recorded chunk of ``name`` is emitted and the driver has read ``bytes_read`` >= all."""
        dev = self.serial[name]
        return dev.done and bytes_read >= dev.total_bytes

    def i2c_reads_left(self) -> dict[str, int]:
        """{device name: recorded I2C reads not served yet} of the devices with any left ({}: all served)."""
        return {self.i2c_device_of[a]: d.reads_left for a, d in self.i2c.items() if d.reads_left}

    def i2c_done(self) -> bool:
        """True when every recorded I2C read has been served (:meth:`i2c_reads_left` is empty)."""
        return not self.i2c_reads_left()

    def close(self) -> None:
        """Stop the pty threads (idempotent)."""
        for p in self.ptys.values():
            p.close()
        self.ptys = {}
        for d in self.i2c.values():
            d.flush()


def strip_stamp(msg: Any) -> Any:
    """A copy of ``msg`` with ``header.stamp`` zeroed (messages without a header are returned unchanged)."""
    if not hasattr(msg, "header"):
        return msg
    out = copy.deepcopy(msg)
    out.header.stamp.sec = 0
    out.header.stamp.nanosec = 0
    return out


def _equal(a: Any, b: Any) -> bool:
    """Field-wise equality of two rclpy messages where NaN equals NaN (an invalid DVL velocity is NaN)."""
    if hasattr(a, "get_fields_and_field_types"):
        return type(a) is type(b) and all(_equal(getattr(a, f), getattr(b, f)) for f in a.get_fields_and_field_types())
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    if isinstance(a, (list, tuple)) or hasattr(a, "__len__") and not isinstance(a, (str, bytes)):
        try:
            return len(a) == len(b) and all(_equal(x, y) for x, y in zip(a, b))
        except TypeError:
            return a == b
    return a == b


def compare_parsed(recorded: dict[str, list[Any]], replayed: dict[str, list[Any]]) -> list[str]:
    """Differences between recorded and replayed parsed messages, one line each ([] = the same).

    Rule: for every topic of :data:`PARSED_TOPICS` present in ``recorded``, the same number of messages, and message k
    of the replay equals message k of the recording field by field (NaN == NaN, exact float equality otherwise: the same
    bytes go through the same code), ``header.stamp`` included on the serial devices' topics: their bytes are served in
    lock-step with the replay clock (module docstring), so each chunk is received at its recorded time and the DVL's
    device-time stamps (``tu - dtu/2`` plus the offset estimate min(receive time - tu)) are the recorded ones too.
    Excluded on :data:`I2C_STAMPED` topics."""
    problems: list[str] = []
    for topic in sorted(set(recorded) & set(PARSED_TOPICS)):
        a, b = recorded[topic], replayed.get(topic, [])
        if len(a) != len(b):
            problems.append(f"{topic}: {len(a)} recorded, {len(b)} replayed")
        for k, (x, y) in enumerate(zip(a, b)):
            strip = strip_stamp if topic in I2C_STAMPED else (lambda m: m)
            if not _equal(strip(x), strip(y)):
                problems.append(f"{topic}[{k}]: recorded {x} != replayed {y}")
                break
    return problems


class DriverReplay:
    """Fresh driver nodes fed by :class:`ReplayHardware` (see the module docstring).

    Args:
        bag_path: the bag.
        config_path: vehicle configuration (ports and buses are replaced by the replay ones).
        context: rclpy context (initialised).
        overrides: configuration overrides (dotted keys), e.g. the same ones used for the recording.
        clock_period_s: step of the replay clock where the bag has no ``/clock``, s.
    Attributes:
        hardware, nodes (name -> node), probe, received (topic -> list of messages), published (topic ->
        count, every publisher of the driver nodes), timeline_ns (the /clock values replayed)."""

    def __init__(self, bag_path: str | Path, config_path: str | Path, context: Any, overrides: dict | None = None,
                 clock_period_s: float = 0.01) -> None:
        self.bag_path = Path(bag_path)
        reader = BagReader(self.bag_path)
        self.timeline_ns = self._timeline(reader, clock_period_s)
        self.hardware = ReplayHardware(self.bag_path)
        hw = self.hardware
        ov = dict(overrides or {})
        present = [d for d in device_table.DEVICES if d.name in set(hw.serial) | set(hw.i2c_device_of.values())]
        ov.update({f"{d.section}.port": hw.ports[d.name] for d in present if d.name in hw.ports})
        cfg = load_config(config_path, ov)
        params = [Parameter(k, value=v) for k, v in cfg.to_ros_parameters().items()]
        params.append(Parameter("use_sim_time", value=True))
        kw = dict(parameter_overrides=params, context=context)
        # the ESC's chip jobs in the executor thread: the replayed bus answers in the recorded order of its transactions
        extra = {"esc": {"chip_thread": False}}
        self.nodes: dict[str, Any] = {d.node: device_table.build_node(d, hw.i2c_bus, **extra.get(d.node, {}), **kw)
                                      for d in present}
        self.published: collections.Counter[str] = collections.Counter()
        for node in self.nodes.values():
            for pub in node.publishers:
                self._count(pub)
        self.probe = rclpy.create_node("replay_probe", context=context)
        self._clock_pub = self.probe.create_publisher(Clock, "/clock", QoSProfile(depth=1))
        self.received: dict[str, list[Any]] = {t: [] for t in PARSED_TOPICS}
        self.received["/thrusters/pulse_width"] = []
        for topic in self.received:
            cls = message_class(reader.topics.get(topic) or self._type_of(topic))
            self.probe.create_subscription(cls, topic, self.received[topic].append, 1000)
        self.executor = SingleThreadedExecutor(context=context)
        for node in list(self.nodes.values()) + [self.probe]:
            self.executor.add_node(node)

    @staticmethod
    def _type_of(topic: str) -> str:
        types = {t: k for d in device_table.DEVICES for t, k in d.topics.items()}
        return {**types, "/thrusters/pulse_width": "hindrax_msgs/msg/ThrusterPwm"}[topic]

    def _count(self, pub: Any) -> None:
        topic = pub.topic_name
        original = pub.publish

        def publish(msg: Any) -> None:
            original(msg)
            self.published[topic] += 1

        pub.publish = publish

    @staticmethod
    def _timeline(reader: BagReader, period_s: float) -> list[int]:
        """The recorded /clock values (ns, increasing); without /clock a grid over the raw data's span."""
        if "/clock" in reader.topics:
            ts = sorted({deserialize_message(m.data, Clock).clock.sec * 1_000_000_000
                         + deserialize_message(m.data, Clock).clock.nanosec for m in reader.messages(["/clock"])})
            if ts:
                return ts
        if reader.start_ns is None:
            return []
        step = int(period_s * 1e9)
        return list(range(int(reader.start_ns) - step, int(reader.end_ns) + step, step))

    # -- running
    def _set_clock(self, t_ns: int, wait_s: float) -> None:
        """Publish /clock t_ns, spin until every node's clock shows it, then serve the serial
        devices at t_ns: their drivers read and handle the chunks due in this thread."""
        self._clock_pub.publish(Clock(clock=time_from_ns(t_ns)))
        nodes = list(self.nodes.values())
        _spin_until(self.executor, lambda: all(n.get_clock().now().nanoseconds >= t_ns for n in nodes), wait_s,
                    f"all replay nodes at /clock {t_ns} ns")
        for name, pty in self.hardware.ptys.items():
            transport = self.nodes[name].transport
            if pty.service(t_ns * 1e-9) and not transport.pump(pty.bytes_to_host, wait_s):
                raise TimeoutError(f"replay: timed out waiting for {name} to handle {t_ns} ns")
        self.executor.spin_once(timeout_sec=0.0)  # timers that became due

    def consumed(self) -> bool:
        """True when every recorded device->host byte was read and handled (parsed, published) by its driver and
        every I2C read served."""
        hw = self.hardware
        serial = all(hw.serial_done(n, self.nodes[n].transport.status().bytes_handled)
                     for n in hw.serial if n in self.nodes)
        return serial and hw.i2c_done()

    def run(self, timeout_s: float = 60.0, extra_s: float = 5.0) -> None:
        """Wait for the serial drivers to connect, step the clock through the timeline (at each step the
        serial drivers read every byte due), continue ``extra_s`` of ROS time at the last step's period until
        everything recorded is consumed, then wait until the probe has every published parsed message.

        Raises TimeoutError (naming what was not reached) after ``timeout_s`` of wall time per wait."""
        serial_nodes = [self.nodes[n] for n in self.hardware.serial if n in self.nodes]
        _spin_until(self.executor, lambda: all(n.transport.connected for n in serial_nodes), timeout_s,
                    "serial drivers connected to the replay ptys")
        for node in serial_nodes:
            node.transport.pump(0, 0.0)  # from now on the drivers read in this thread (_set_clock)
        timeline = list(self.timeline_ns)
        if not timeline:
            return
        step = (timeline[-1] - timeline[0]) // max(1, len(timeline) - 1) or 10_000_000
        for t in timeline:
            self._set_clock(t, timeout_s)
        t = timeline[-1]
        end = t + int(extra_s * 1e9)
        while not self.consumed() and t < end:
            t += step
            self._set_clock(t, timeout_s)
        _spin_until(self.executor, self._probe_has_all, timeout_s, "probe received every published message")

    def _probe_has_all(self) -> bool:
        return all(len(msgs) >= self.published.get(topic, 0) for topic, msgs in self.received.items())

    def close(self) -> None:
        """Close the drivers, stop the ptys, destroy the nodes."""
        for node in self.nodes.values():
            close = getattr(node, "close", None)
            if callable(close):
                close()
        self.hardware.close()
        self.executor.shutdown()
        for node in list(self.nodes.values()) + [self.probe]:
            node.destroy_node()


def _spin_until(executor: Any, predicate: Callable[[], bool], timeout_s: float, what: str) -> None:
    """Spin ``executor`` (0.005 s per call) until ``predicate()``; TimeoutError naming ``what`` after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            raise TimeoutError(f"replay: timed out waiting for {what}")
        executor.spin_once(timeout_sec=0.005)


def recorded_parsed(bag_path: str | Path) -> dict[str, list[Any]]:
    """The parsed messages of :data:`PARSED_TOPICS` (and ``/thrusters/pulse_width``) in a bag, decoded into
    rclpy classes, in log-time order per topic."""
    reader = BagReader(bag_path)
    wanted = [t for t in list(PARSED_TOPICS) + ["/thrusters/pulse_width"] if t in reader.topics]
    out: dict[str, list[Any]] = {t: [] for t in wanted}
    # a bag recorded before a message changed (ThrusterPwm gained output_state) decodes from its stored
    # definition, the new field at its default (OUTPUT_UNKNOWN: those bags did not record the state on the wire)
    for m, msg in reader.installed_messages(wanted):
        out[m.topic].append(msg)
    return out
