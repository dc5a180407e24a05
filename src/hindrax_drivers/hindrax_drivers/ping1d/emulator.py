"""Blue Robotics Ping1D device emulator (device side of the binary protocol), I/O-free.

Layer 2 of the Ping1D altimeter driver (docs/architecture.md §2).  The host's bytes go into
:meth:`Ping1dEmulator.feed_host_bytes`; :meth:`Ping1dEmulator.poll` ``(t_s)`` returns the device's
bytes up to time ``t_s``.  Serve it on a pty with
:class:`hindrax_common.transport.pty_device.PtyDevice` so the real pyserial path runs.

Behaviour (docs/devices.md §2.1-§2.6, the §2.6 checklist):
- Frames are extracted with :class:`~hindrax_drivers.ping1d.protocol.Ping1dFramer`, so auto-baud
  ``U`` (0x55) bytes, BREAK-induced NULs and garbage are skipped, the stream resynchronises on
  ``BR`` and frames with a bad checksum are dropped.
- Both request forms are answered: ``general_request`` (id 6) and the legacy zero-payload frame
  (§2.3).  Replies use src = the device id (default 1, as in the §2.5 reply vectors) and dst = the
  requester's src.
- Set messages (1000-1006) are validated and applied to :class:`Ping1dSettings`, then ACKed
  (whether the firmware ACKs is unverified, §2.3).  Invalid values, wrong payload
  sizes and unknown ids are NACKed with a text reason.
- ``continuous_start(1300)`` streams ``profile`` at every ping; 1211 and 1212 are accepted too
  [EMULATOR extension: only 1300 is documented, §2.4].  ``continuous_stop`` ends streaming.
- Frames are accepted when dst is this device, 255 (broadcast), or src = dst = 0 (legacy), per the
  early protocol draft [P10] (unverified for current firmware).

Truth -> measurement [EMULATOR choices where marked]:
- Truth = the true acoustic range to the bottom ``altitude_m`` (+ confidence).  The device pings every
  ``ping_interval`` (effective minimum 10 ms) while enabled; each ping reports
  distance = true range x (configured c / true c) (§2.6), rounded to 1 mm.
- Auto mode: scan_start 0, scan_length = the next whole metre above 1.5 x distance, within
  1 m .. ``max_range_m`` [EMULATOR].  Manual mode uses the configured range.  No echo inside the scan
  window (or truth None) -> distance 0, confidence 0 [EMULATOR].
- Transmit duration, gain choice in auto mode and the profile samples (a Gaussian echo on 200 points,
  as brping's simulator uses [P4]) are [EMULATOR] models."""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import Callable, Dict, List, Optional, Union

import numpy as np

from hindrax_common.transport.pty_device import PeriodicSchedule, StreamFaults
from .protocol import (Ack, ContinuousStart, ContinuousStop, DeviceId, DeviceInformation, Distance, DistanceSimple,
                       FirmwareVersion, GainSetting, GeneralInfo, GeneralRequest, ModeAuto, Nack, PcbTemperature,
                       Ping1dFramer, Ping1dId, Ping1dMessage, Ping1dParseError, Ping1dPayload, PingEnable, PingInterval,
                       ProcessorTemperature, Profile, ProtocolVersion, Range, SetDeviceId, SetGainSetting, SetModeAuto,
                       SetPingEnable, SetPingInterval, SetRange, SetSpeedOfSound, SpeedOfSound, TransmitDuration,
                       Voltage5, decode_message, encode_message)

__all__ = ["from_config", "Ping1dTruth", "Ping1dSettings", "Ping1dMeasurement", "Ping1dEmulator"]

_BROADCAST_ID = 0xFF
_MIN_PING_INTERVAL_S = 0.01  # [EMULATOR]
_FIRMWARE_VERSION = (3, 29)  # (major, minor) in firmware_version / general_info
_PROFILE_POINTS = 200  # samples per profile, as brping's simulator [P4]
_MAX_RANGE_M = 100.0  # longest detectable range (Ping2, §2.1)
_MAX_BACKLOG_S = 1.0  # when polled late, pings older than this are skipped
_STREAMABLE = (Ping1dId.PROFILE, Ping1dId.DISTANCE, Ping1dId.DISTANCE_SIMPLE)


@dataclass(frozen=True)
class Ping1dTruth:
    """True target seen by the echosounder.

    Attributes:
        altitude_m: true acoustic range from the transducer to the bottom, m (None = no echo).
        confidence_pct: confidence the device reports for a valid echo, 0..100 %."""

    altitude_m: Optional[float] = 5.0
    confidence_pct: float = 100.0


@dataclass
class Ping1dSettings:
    """Device settings changed by the set messages (docs/devices.md §2.4).  Defaults: speed of sound
    1500 m/s [P10], auto mode, pinging enabled; ping interval 0.1 s, gain index 6 and the manual scan
    window 0..30 m are [EMULATOR] choices (real defaults unverified, docs/devices.md §6)."""

    device_id: int = 1
    speed_of_sound_m_s: float = 1500.0
    mode_auto: bool = True
    scan_start_m: float = 0.0
    scan_length_m: float = 30.0
    ping_interval_s: float = 0.1
    gain_setting: int = 6
    ping_enabled: bool = True


@dataclass(frozen=True)
class Ping1dMeasurement:
    """Result of the latest ping (what distance / profile replies report), SI units."""

    distance_m: float = 0.0
    confidence_pct: int = 0
    transmit_duration_s: float = 0.0
    ping_number: int = 0
    scan_start_m: float = 0.0
    scan_length_m: float = 1.0
    gain_setting: int = 0
    profile_data: bytes = b""


TruthSource = Union[Callable[[float], Union[Ping1dTruth, float, None]], Ping1dTruth]


class Ping1dEmulator:
    """I/O-free Ping1D.  See the module docstring for the behaviour.

    Args:
        truth_source: callable ``t_s -> Ping1dTruth`` (a bare float is taken as ``altitude_m``), or a
            constant :class:`Ping1dTruth`.
        settings: initial settings (default :class:`Ping1dSettings`).
        true_speed_of_sound_m_s: water's true c; reported distance scales by configured c / true c.
        protocol_version: (major, minor, patch) reported in protocol_version.
        seed: seed of the fault generator.
    Attributes:
        settings, faults (:class:`StreamFaults`), measurement (latest :class:`Ping1dMeasurement`), streaming (streamed
        id -> destination device id), received (counts of accepted host messages by id)."""

    def __init__(self, truth_source: TruthSource, *, settings: Optional[Ping1dSettings] = None,
                 true_speed_of_sound_m_s: float = 1500.0, protocol_version: tuple = (1, 0, 0), seed: int = 0) -> None:
        if isinstance(truth_source, Ping1dTruth):
            constant = truth_source
            truth_source = lambda _t: constant  # noqa: E731
        if true_speed_of_sound_m_s <= 0:
            raise ValueError("true_speed_of_sound_m_s must be positive")
        self._truth_source = truth_source
        self.settings = settings if settings is not None else Ping1dSettings()
        self.true_speed_of_sound_m_s = float(true_speed_of_sound_m_s)
        self.protocol_version = tuple(protocol_version)
        self.faults = StreamFaults(seed=seed)
        self.framer = Ping1dFramer()
        self.measurement = Ping1dMeasurement()
        self.streaming: Dict[int, int] = {}
        self.received: Dict[int, int] = {}
        self._force_zero_confidence = False
        self._lock = threading.RLock()
        self._pending: List[bytes] = []
        self._inbox: List[Ping1dMessage] = []
        self._schedule = PeriodicSchedule(self._interval_s())
        self._was_enabled = False

    # --- faults -------------------------------------------------------------------------------------
    def set_zero_confidence(self, zero: bool) -> None:
        """Fault: report confidence 0 on every ping regardless of the truth."""
        self._force_zero_confidence = bool(zero)

    # --- host interface -----------------------------------------------------------------------------
    def feed_host_bytes(self, data: bytes) -> None:
        """Receive host bytes; complete frames are queued and handled by the next :meth:`poll`, after
        the pings due by then (so a reply reports the latest ping).  Ignored while
        ``faults.disconnected``."""
        with self._lock:
            if self.faults.disconnected:
                return
            self._inbox.extend(self.framer.feed(data))

    def poll(self, t_s: float) -> bytes:
        """Bytes the device sends up to time ``t_s`` (s): messages streamed by the pings due by then,
        then the replies to the frames received since the last poll."""
        with self._lock:
            enabled = self.settings.ping_enabled
            if enabled and not self._was_enabled:
                self._schedule.restart(t_s, 0)  # first ping at boot / when re-enabled
            self._was_enabled = enabled
            if enabled:
                self._schedule.set_period(self._interval_s())
                for t_ping in self._schedule.due(t_s, _MAX_BACKLOG_S):
                    self._ping(t_ping)
            inbox, self._inbox = self._inbox, []
            for message in inbox:
                self._handle(message)
            messages, self._pending = self._pending, []
            return self.faults.transmit(messages, _corrupt_checksum)

    def next_output_s(self) -> Optional[float]:
        """When the next unprompted output is due (s): the next ping; -inf with frames or replies waiting or pinging
        just switched; None while off (:class:`~hindrax_common.transport.pty_device.ByteStreamEmulator`)."""
        with self._lock:
            if self._inbox or self._pending or self.settings.ping_enabled != self._was_enabled:
                return -math.inf
            return self._schedule.next_s() if self._was_enabled else None

    # --- measurement model --------------------------------------------------------------------------
    def _interval_s(self) -> float:
        return max(self.settings.ping_interval_s, _MIN_PING_INTERVAL_S)

    def _truth(self, t_s: float) -> Ping1dTruth:
        value = self._truth_source(t_s)
        if value is None or isinstance(value, (int, float)):
            return Ping1dTruth(altitude_m=None if value is None else float(value))
        return value

    def _ping(self, t_s: float) -> None:
        s = self.settings
        truth = self.faults.hold(self._truth(t_s))
        d_true = truth.altitude_m
        distance = None
        if d_true is not None and math.isfinite(d_true) and 0.0 < d_true <= _MAX_RANGE_M:
            distance = d_true * s.speed_of_sound_m_s / self.true_speed_of_sound_m_s
        if s.mode_auto:
            scan_start = 0.0
            want = 1.5 * distance if distance is not None else _MAX_RANGE_M
            scan_length = min(_MAX_RANGE_M, max(1.0, math.ceil(want)))
            gain = min(6, max(0, int(distance // 5))) if distance is not None else 6
        else:
            scan_start, scan_length, gain = s.scan_start_m, s.scan_length_m, s.gain_setting
        in_window = distance is not None and scan_start <= distance <= scan_start + scan_length
        confidence = int(round(min(100.0, max(0.0, truth.confidence_pct)))) if in_window else 0
        if self._force_zero_confidence:
            confidence = 0
        reported = round(distance, 3) if in_window and distance is not None else 0.0
        transmit = min(500e-6, max(5e-6, round(50e-6 + 20e-6 * reported, 6)))
        self.measurement = Ping1dMeasurement(
            distance_m=reported, confidence_pct=confidence, transmit_duration_s=transmit,
            ping_number=(self.measurement.ping_number + 1) & 0xFFFFFFFF,
            scan_start_m=round(scan_start, 3), scan_length_m=round(scan_length, 3),
            gain_setting=gain,
            profile_data=self._profile(reported if in_window else None, scan_start, scan_length))
        for mid, dst in sorted(self.streaming.items()):
            self._reply(mid, dst)

    def _profile(self, distance_m: Optional[float], scan_start_m: float, scan_length_m: float) -> bytes:
        n = _PROFILE_POINTS
        r = scan_start_m + (np.arange(n) + 0.5) * scan_length_m / n
        amplitude = 40.0 * np.exp(-r / 0.3)  # transducer ring-down [EMULATOR]
        if distance_m is not None:
            sigma = max(scan_length_m / n, 0.05)
            amplitude = amplitude + 220.0 * np.exp(-0.5 * ((r - distance_m) / sigma) ** 2)
        return np.clip(np.round(amplitude), 0, 255).astype(np.uint8).tobytes()

    # --- message handling ---------------------------------------------------------------------------
    def _send(self, payload: Ping1dPayload, dst: int) -> None:
        self._pending.append(encode_message(payload, self.settings.device_id, dst))

    def _nack(self, nacked_id: int, reason: str, dst: int) -> None:
        self._send(Nack(nacked_id & 0xFFFF, reason), dst)

    def _addressed_to_me(self, m: Ping1dMessage) -> bool:
        return (m.dst_device_id in (self.settings.device_id, _BROADCAST_ID)
                or (m.src_device_id == 0 and m.dst_device_id == 0))

    def _handle(self, m: Ping1dMessage) -> None:
        if not self._addressed_to_me(m):
            return
        self.received[m.message_id] = self.received.get(m.message_id, 0) + 1
        src = m.src_device_id
        mid = m.message_id
        if mid == Ping1dId.GENERAL_REQUEST:
            try:
                req = decode_message(m)
            except Ping1dParseError as exc:
                self._nack(mid, f"invalid payload: {exc}", src)
                return
            assert isinstance(req, GeneralRequest)
            self._reply(req.requested_id, src)
            return
        if not m.payload and mid in _GETTERS:
            self._reply(mid, src)  # legacy request (§2.3)
            return
        if mid in _SETTERS or mid in (Ping1dId.CONTINUOUS_START, Ping1dId.CONTINUOUS_STOP):
            try:
                msg = decode_message(m)
                self._apply(msg, src)
            except (Ping1dParseError, ValueError) as exc:
                self._nack(mid, str(exc)[:100], src)
                return
            self._send(Ack(mid), src)
            return
        self._nack(mid, "unknown or unsupported message id", src)

    def _apply(self, msg: Ping1dPayload, src: int) -> None:
        s = self.settings
        if isinstance(msg, SetDeviceId):
            if not 0 <= msg.device_id <= 254:
                raise ValueError("device_id must be 0..254")
            s.device_id = msg.device_id
        elif isinstance(msg, SetRange):
            if msg.scan_length_m < 1.0:
                raise ValueError("scan_length must be >= 1000 mm")
            s.scan_start_m, s.scan_length_m = msg.scan_start_m, msg.scan_length_m  # used in manual mode
        elif isinstance(msg, SetSpeedOfSound):
            s.speed_of_sound_m_s = msg.speed_of_sound_m_s
        elif isinstance(msg, SetModeAuto):
            s.mode_auto = msg.auto
        elif isinstance(msg, SetPingInterval):
            s.ping_interval_s = msg.ping_interval_s
        elif isinstance(msg, SetGainSetting):
            if not 0 <= msg.gain_setting <= 6:
                raise ValueError("gain_setting must be 0..6")
            s.gain_setting = msg.gain_setting
        elif isinstance(msg, SetPingEnable):
            s.ping_enabled = msg.enabled
        elif isinstance(msg, ContinuousStart):
            if msg.requested_id not in _STREAMABLE:
                raise ValueError(f"cannot stream id {msg.requested_id}")
            self.streaming[int(msg.requested_id)] = src
        elif isinstance(msg, ContinuousStop):
            self.streaming.pop(int(msg.requested_id), None)

    def _reply(self, requested_id: int, dst: int) -> None:
        build = _GETTERS.get(requested_id)
        if build is None:
            self._nack(requested_id, "unknown or unsupported message id", dst)
            return
        self._send(build(self), dst)


def _distance_fields(e: Ping1dEmulator) -> tuple:
    m = e.measurement
    return (m.distance_m, m.confidence_pct, m.transmit_duration_s, m.ping_number, m.scan_start_m,
            m.scan_length_m, m.gain_setting)


_GETTERS: Dict[int, Callable[[Ping1dEmulator], Ping1dPayload]] = {
    Ping1dId.DEVICE_INFORMATION: lambda e: DeviceInformation(1, 1, *_FIRMWARE_VERSION, 0, 0),
    Ping1dId.PROTOCOL_VERSION: lambda e: ProtocolVersion(*e.protocol_version, 0),
    Ping1dId.FIRMWARE_VERSION: lambda e: FirmwareVersion(1, 1, *_FIRMWARE_VERSION),
    Ping1dId.DEVICE_ID: lambda e: DeviceId(e.settings.device_id),
    Ping1dId.VOLTAGE_5: lambda e: Voltage5(5.0),
    Ping1dId.SPEED_OF_SOUND: lambda e: SpeedOfSound(e.settings.speed_of_sound_m_s),
    Ping1dId.RANGE: lambda e: Range(e.measurement.scan_start_m, e.measurement.scan_length_m)
    if e.settings.mode_auto else Range(e.settings.scan_start_m, e.settings.scan_length_m),
    Ping1dId.MODE_AUTO: lambda e: ModeAuto(e.settings.mode_auto),
    Ping1dId.PING_INTERVAL: lambda e: PingInterval(e.settings.ping_interval_s),
    Ping1dId.GAIN_SETTING: lambda e: GainSetting(e.measurement.gain_setting if e.settings.mode_auto
                                                 else e.settings.gain_setting),
    Ping1dId.TRANSMIT_DURATION: lambda e: TransmitDuration(e.measurement.transmit_duration_s),
    Ping1dId.GENERAL_INFO: lambda e: GeneralInfo(
        *_FIRMWARE_VERSION, 5.0, e.settings.ping_interval_s,
        e.measurement.gain_setting if e.settings.mode_auto else e.settings.gain_setting,
        e.settings.mode_auto),
    Ping1dId.DISTANCE_SIMPLE: lambda e: DistanceSimple(e.measurement.distance_m, e.measurement.confidence_pct),
    Ping1dId.DISTANCE: lambda e: Distance(*_distance_fields(e)),
    Ping1dId.PROCESSOR_TEMPERATURE: lambda e: ProcessorTemperature(35.0),
    Ping1dId.PCB_TEMPERATURE: lambda e: PcbTemperature(30.0),
    Ping1dId.PING_ENABLE: lambda e: PingEnable(e.settings.ping_enabled),
    Ping1dId.PROFILE: lambda e: Profile(*_distance_fields(e), e.measurement.profile_data),
}

_SETTERS = frozenset({Ping1dId.SET_DEVICE_ID, Ping1dId.SET_RANGE, Ping1dId.SET_SPEED_OF_SOUND, Ping1dId.SET_MODE_AUTO,
                      Ping1dId.SET_PING_INTERVAL, Ping1dId.SET_GAIN_SETTING, Ping1dId.SET_PING_ENABLE})


def _corrupt_checksum(frame: bytes) -> bytes:
    """The frame with its checksum's high byte inverted (always a wrong checksum)."""
    if len(frame) < 2:
        return frame
    return frame[:-1] + bytes([frame[-1] ^ 0xFF])


def from_config(config, truth: TruthSource, clock: Callable[[], float], seed: int = 0) -> Ping1dEmulator:
    """The simulator's Ping1D (configured speed of sound) on ``truth`` (devices.py factory; clock: the pty's)."""
    return Ping1dEmulator(truth, true_speed_of_sound_m_s=config.sensors.ping1d.speed_of_sound_m_s, seed=seed)
