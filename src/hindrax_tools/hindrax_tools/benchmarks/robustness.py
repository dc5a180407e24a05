"""Robustness benchmark: fuzzed parsers and injected faults, measured.

Fuzzing (:mod:`hypothesis`, derandomised so every run draws the same inputs): per parser at least :data:`FUZZ_INPUTS`
inputs. Each hypothesis example draws one *template* (arbitrary bytes, a frame with a *valid* checksum around arbitrary
fields or payloads so that the field decoders are reached and not only the checksum test, or a valid frame with byte
flips) and a random generator seeded by hypothesis (``st.randoms(use_true_random=True)``), from which
:data:`BATCH` - 1 mutants of the template are made (byte flips, insertions, deletions, truncations, splices; half of
them with the checksum recomputed). Hypothesis alone costs ~0.3 ms per example here: a hundred thousand plain examples
per parser would take most of a minute each. A **crash** is any exception other than the parser's documented error
class, or a result that breaks the parser's contract (a non-finite value accepted as valid, a DVL velocity accepted
outside the vehicle file's plausibility gates):

- DVL-75 sentences: :class:`~hindrax_drivers.dvl75.stream.DvlStreamDecoder` (never raises), every
  ``$DVPDL`` it returns through :class:`~hindrax_drivers.dvl75.report.DvlReportBuilder` with the gates of
  the vehicle file (a valid report must have a finite speed within ``sensors.dvl75.max_speed_m_s``).
- Ping1D frames: :class:`~hindrax_drivers.ping1d.stream.Ping1dStreamDecoder` (never raises).
- MS5837 PROM/ADC conversion: PROM words -> :meth:`Calibration.from_words` (CRC-4 checked, and
  unchecked so that arbitrary coefficients reach the arithmetic) -> :func:`prom_sanity_issue` ->
  :func:`parse_adc` -> :func:`compensate` (``Ms5837Error`` allowed; results must be finite).
- ICM-20948 register decoding: bank-2 registers -> :meth:`ImuConfig.from_registers`, 14-byte sensor block
  -> :func:`parse_sensor_block`, 9-byte AK09916 block -> :func:`parse_ak09916_block`
  (``Icm20948Error`` allowed; results must be finite).

Injected faults (wall-clock times, emulators on their real transports: DVL on a pty through pyserial,
I2C devices on the emulated bus, each node in its own rclpy context, polled every 2 ms):

- serial unplug/replug (DVL-75): detect = unplug -> diagnostics state ``reconnecting``; recover = replug
  -> first ``dvl/data`` with a valid velocity.
- DVL bottom-lock loss: detect = lock lost -> first report published not valid; recover = lock back ->
  first valid report. Both bounded by the ping period (20 Hz here).
- I2C errno 121 burst (ICM-20948, 0.3 s): detect = burst start -> first failed poll counted; recover =
  burst end -> next ``imu/data_raw``.
- I2C outage with sensor power loss (MS5837, 0.5 s; the part needs a new reset command): detect =
  outage start -> ERROR state; recover = bus back -> first pressure published (after reset and PROM).
- stuck sensor (ICM-20948 registers frozen): detect = freeze -> ERROR ``stuck`` (nothing published from
  then on); recover = unfreeze -> next ``imu/data_raw``.
- chip reset (ICM-20948 power glitch): detect = glitch -> reset detected; recover = glitch -> first
  ``imu/data_raw`` after the re-initialisation.
- magnetometer NACK (AK09916 behind the ICM's I2C master): detect = NACK onset -> ERROR ``magnetometer``;
  recover = the AK09916 answers again (right after the failed re-initialisation) -> first ``imu/mag`` (the
  node retries every ``sensors.icm20948.mag_retry_interval_s``)."""
from __future__ import annotations

import math
import time
from typing import Any, Callable

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from hindrax_drivers.dvl75.emulator import Dvl75Emulator, DvlTruth
from hindrax_drivers.dvl75.node import Dvl75Node
from hindrax_drivers.dvl75.protocol import DvlParseError, DvlPositionDelta, format_dvpdl, format_sentence, nmea_checksum
from hindrax_drivers.dvl75.report import DvlReportBuilder
from hindrax_drivers.dvl75.stream import DvlStreamDecoder
from hindrax_drivers.icm20948 import protocol as icm_protocol
from hindrax_drivers.icm20948.emulator import Icm20948Emulator
from hindrax_drivers.icm20948.node import Icm20948Node
from hindrax_drivers.icm20948.protocol import Icm20948Error
from hindrax_drivers.ms5837 import protocol as ms5837_protocol
from hindrax_drivers.ms5837.emulator import Ms5837Emulator
from hindrax_drivers.ms5837.node import Ms5837Node
from hindrax_drivers.ms5837.protocol import Ms5837Error
from hindrax_drivers.ping1d.protocol import Distance, encode_frame, encode_message
from hindrax_drivers.ping1d.stream import Ping1dStreamDecoder
from hindrax_common.testing import config_parameters, ros_context, wait_until
from hindrax_common.transport.emulated_i2c import EmulatedI2CBus
from hindrax_common.transport.pty_device import PtyDevice
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from hindrax_common.config import default_config_path, load_config

from . import run_alone, spin_for, spinning

#: Fuzzed inputs per parser (full run); ``quick``: a tenth.
FUZZ_INPUTS = 100_000
#: Inputs drawn per hypothesis example.
BATCH = 100


# ---------------------------------------------------------------------------------------------- fuzzing
def _fuzz(name: str, template: Any, mutate: Callable[[Any, Any], Any], check: Callable[[Any], None],
          allowed: tuple, n_inputs: int) -> dict:
    """Feed ``n_inputs`` inputs (hypothesis templates and their mutants) to ``check``; count crashes."""
    stats = {"inputs": 0, "accepted": 0, "crashes": 0, "first": ""}

    @settings(max_examples=max(1, n_inputs // BATCH), database=None, deadline=None, phases=[Phase.generate],
              derandomize=True, suppress_health_check=list(HealthCheck))
    @given(template, st.randoms(use_true_random=True))
    def run(base, rnd):
        batch = [base] + [mutate(base, rnd) for _ in range(BATCH - 1)]
        for item in batch:
            stats["inputs"] += 1
            try:
                stats["accepted"] += bool(check(item))
            except allowed:
                pass
            except Exception as exc:  # noqa: BLE001 - the measurement
                stats["crashes"] += 1
                if not stats["first"]:
                    stats["first"] = f"{type(exc).__name__}: {exc} for {item!r}"[:300]

    t0 = time.monotonic()
    while stats["inputs"] < n_inputs:  # hypothesis may stop early on a small search space: draw again
        run()
    return {"name": name, **stats, "seconds": time.monotonic() - t0}


def _mutate_bytes(data: bytes, rnd, fix: Callable[[bytes], bytes]) -> bytes:
    """One random mutant of ``data``: flips, insertion, deletion, truncation or splice; half re-checksummed."""
    out = bytearray(data)
    op = rnd.randrange(5)
    if op == 0 or not out:
        for _ in range(rnd.randint(1, 4)):
            if out:
                out[rnd.randrange(len(out))] = rnd.randrange(256)
            else:
                out.append(rnd.randrange(256))
    elif op == 1:
        pos = rnd.randrange(len(out) + 1)
        out[pos:pos] = bytes(rnd.randrange(256) for _ in range(rnd.randint(1, 8)))
    elif op == 2:
        a = rnd.randrange(len(out))
        del out[a:a + rnd.randint(1, 16)]
    elif op == 3:
        del out[rnd.randrange(len(out)):]
    else:
        a, b = sorted((rnd.randrange(len(out)), rnd.randrange(len(out))))
        pos = rnd.randrange(len(out) + 1)
        out[pos:pos] = out[a:b + 1]
    out = bytes(out)
    return fix(out) if rnd.random() < 0.5 else out


def _dvl_fix(line: bytes) -> bytes:
    """Recompute the XOR checksum of a ``$...*hh`` line (so the mutant reaches the field parser)."""
    body = line.rstrip(b"\r\n")
    star = body.rfind(b"*")
    if not body.startswith(b"$") or star < 1:
        return line
    return body[:star + 1] + b"%02X" % nmea_checksum(body[1:star]) + b"\r\n"


def _ping_fix(frame: bytes) -> bytes:
    """Recompute the Ping1D checksum (u16 sum of the bytes before it) of a frame starting with ``BR``."""
    if len(frame) < 10 or not frame.startswith(b"BR"):
        return frame
    return frame[:-2] + (sum(frame[:-2]) & 0xFFFF).to_bytes(2, "little")


def _flips(st, frame: bytes):
    """Strategy: ``frame`` with 1-4 bytes replaced at drawn positions."""
    n = len(frame)

    def apply(edits):
        out = bytearray(frame)
        for pos, value in edits:
            out[pos % n] = value
        return bytes(out)

    return st.lists(st.tuples(st.integers(0, n - 1), st.integers(0, 255)), min_size=1, max_size=4).map(apply)


def _dvl_strategy():
    numbers = st.one_of(st.integers(-10**12, 10**12).map(str),
                        st.floats(allow_nan=False, allow_infinity=False, width=32).map(lambda v: f"{v:.6g}"),
                        st.floats(allow_nan=False, allow_infinity=False).map(repr),  # up to 1.8e308
                        st.sampled_from(["", "1e999", "-1e999", "nan", "inf", "0", "-0", "999.999", "1e300", "F",
                                         "T", "X", "0x10", "+", "-", ".", "1..2", "100", "101", "-1"]),
                        st.text(alphabet="0123456789.-+eE,TFX ", max_size=12))
    sentence_ids = st.sampled_from(["DVPDL", "DVEXT", "GPRMC", "DVTXT", "DVNVM", "DVKFA"])

    def body(sid_fields):
        sid, fields = sid_fields
        return format_sentence(",".join([sid, *fields]))

    field_counts = st.sampled_from([9, 35, 12, 8, 10, 34, 36, 0, 1])
    valid_checksum = st.tuples(sentence_ids, field_counts).flatmap(
        lambda t: st.tuples(st.just(t[0]), st.lists(numbers, min_size=t[1], max_size=t[1]))).map(body)
    numeric = st.one_of(st.integers(-10**12, 10**12).map(str), st.floats(allow_nan=False).map(repr),
                        st.sampled_from(["1e999", "-1e999", "999.999", "1e300", "-1e300", "0", "-0", "1e-300"]))
    dvpdl = st.tuples(st.integers(0, 10**10), st.sampled_from([0, 1, 999, 25000, 50000, 100000, 10**6, 10**7]),
                      st.lists(numeric, min_size=6, max_size=6), st.integers(0, 100)).map(
        lambda t: format_sentence(",".join(["DVPDL", str(t[0]), str(t[1]), *t[2], str(t[3])])))
    good = format_dvpdl(DvlPositionDelta(12.345678, 0.1, 0.001, -0.002, 0.003, 0.0123, -0.0045, 0.0007, 87))
    real_dvext = (b"$DVEXT,F,X,3330,-1.8,2.4,259.5,-1175,0.000,0.00,-0.000,0.000,0.000000000,0.000000000,0.100,"
                  b"0.091711,0.019853,0.017436,-0.995435,25,25,25,25,F,F,F,F,0.0000,0.0000,0.0000,0.0000,-1.000,"
                  b"-1.000,-1.000,-1.000,*54\r\n")
    return st.one_of(st.binary(max_size=300), valid_checksum, dvpdl, dvpdl, _flips(st, good), _flips(st, real_dvext))


def _dvl_check_factory():
    s = load_config(default_config_path()).sensors.dvl75
    builder = DvlReportBuilder(max_speed_m_s=s.max_speed_m_s, min_interval_s=s.min_interval_s,
                               max_interval_s=s.max_interval_s)

    def check(data: bytes) -> bool:
        records = DvlStreamDecoder().feed(data)
        for record in records:
            if isinstance(record, DvlPositionDelta):
                rep = builder.from_position_delta(record, 0)
                if rep.velocity_valid:
                    speed = math.sqrt(sum(v * v for v in rep.velocity_flu_m_s))
                    if not (math.isfinite(speed) and speed <= s.max_speed_m_s * 1.01 + 0.05):
                        # (the gate is on the transducer's speed; the lever-arm term adds |omega x r|)
                        raise AssertionError(f"valid velocity {rep.velocity_flu_m_s} outside the gates")
        return bool(records)

    return check


def _ping_strategy():
    ids = st.sampled_from([1, 2, 3, 4, 5, 6, 1200, 1201, 1202, 1203, 1204, 1205, 1206, 1207, 1208, 1210, 1211,
                           1212, 1213, 1300, 1400, 1401, 2000, 65535])
    valid_checksum = st.tuples(ids, st.binary(max_size=260)).map(lambda t: encode_frame(t[0], t[1]))
    good = encode_message(Distance(distance_m=2.345, confidence_pct=93, transmit_duration_s=0.0001,
                                   ping_number=17, scan_start_m=0.1, scan_length_m=10.0, gain_setting=3))
    return st.one_of(st.binary(max_size=300), valid_checksum, _flips(st, good))


def _ping_check(data: bytes) -> bool:
    return bool(Ping1dStreamDecoder().feed(data))


def _ms5837_strategy():
    datasheet = ms5837_protocol.prom_with_crc(ms5837_protocol.EXAMPLE_WORD0_30BA,
                                              ms5837_protocol.EXAMPLE_COEFFICIENTS_30BA)

    def edited(edits):
        out = list(datasheet)
        for index, value in edits:
            out[index] = value
        return out

    words = st.one_of(st.lists(st.integers(0, 0xFFFF), min_size=8, max_size=8),
                      st.lists(st.tuples(st.integers(0, 7), st.integers(0, 0xFFFF)), max_size=3).map(edited))
    adc = st.one_of(st.integers(0, 0xFFFFFF), st.sampled_from([0, 1, 0xFFFFFF, 0x800000, 4958179, 6815414]))
    return st.tuples(words, adc, adc, st.sampled_from(["30BA", "02BA"]))


def _ms5837_mutate(item, rnd):
    words, d1, d2, variant = item
    words = list(words)
    which = rnd.randrange(4)
    if which == 0:
        words[rnd.randrange(8)] ^= 1 << rnd.randrange(16)
    elif which == 1:
        words[rnd.randrange(8)] = rnd.choice((0, 0xFFFF, rnd.randrange(0x10000)))
    elif which == 2:
        d1 = rnd.choice((0, 1, 0xFFFFFF, rnd.randrange(1 << 24), d1 ^ (1 << rnd.randrange(24))))
    else:
        d2 = rnd.choice((0, 1, 0xFFFFFF, rnd.randrange(1 << 24), d2 ^ (1 << rnd.randrange(24))))
    return words, d1, d2, variant


def _ms5837_check(item) -> bool:
    """True when the PROM passes CRC-4 and the sanity check and both ADC reads are usable."""
    words, d1, d2, variant = item
    parsed = [ms5837_protocol.parse_prom_word(ms5837_protocol.encode_prom_word(w)) for w in words]
    try:
        ms5837_protocol.Calibration.from_words(parsed, check_crc=True)
        crc_ok = True
    except ms5837_protocol.Ms5837Error:
        crc_ok = False
    # arbitrary coefficients reach the arithmetic too
    cal = ms5837_protocol.Calibration.from_words(parsed, check_crc=False)
    sane = not ms5837_protocol.prom_sanity_issue(cal)
    a = ms5837_protocol.parse_adc(ms5837_protocol.encode_adc(d1))
    b = ms5837_protocol.parse_adc(ms5837_protocol.encode_adc(d2))
    reading = ms5837_protocol.compensate(a, b, cal, ms5837_protocol.parse_variant(variant), apply_second_order=True)
    if not (math.isfinite(reading.pressure_pa) and math.isfinite(reading.temperature_c)):
        raise AssertionError(f"non-finite reading {reading}")
    return crc_ok and sane


def _icm_strategy():
    return st.tuples(st.binary(min_size=14, max_size=14), st.binary(min_size=9, max_size=9),
                     st.lists(st.integers(0, 255), min_size=5, max_size=5))


def _icm_mutate(item, rnd):
    block, mag_block, regs = bytearray(item[0]), bytearray(item[1]), list(item[2])
    for _ in range(rnd.randint(1, 3)):
        which = rnd.randrange(3)
        if which == 0:
            block[rnd.randrange(14)] = rnd.choice((0x00, 0x7F, 0x80, 0xFF, rnd.randrange(256)))
        elif which == 1:
            mag_block[rnd.randrange(9)] = rnd.choice((0x00, 0x7F, 0x80, 0xFF, rnd.randrange(256)))
        else:
            regs[rnd.randrange(5)] = rnd.randrange(256)
    return bytes(block), bytes(mag_block), regs


def _icm_check(item) -> bool:
    block, mag_block, regs = item
    config = icm_protocol.ImuConfig.from_registers(*regs)
    sample = icm_protocol.parse_sensor_block(block, config)
    mag = icm_protocol.parse_ak09916_block(mag_block)
    values = np.concatenate([sample.accel_m_s2, sample.gyro_rad_s, [sample.temperature_c], mag.magnetic_field_t])
    if not np.all(np.isfinite(values)):
        raise AssertionError(f"non-finite decoded values {values}")
    return True


def fuzz_parsers(n_inputs: int = FUZZ_INPUTS) -> list[dict]:
    """One result per parser: inputs, crashes, first crash (text), seconds."""
    return [
        _fuzz("DVL-75 sentences", _dvl_strategy(), lambda b, r: _mutate_bytes(b, r, _dvl_fix), _dvl_check_factory(),
              (DvlParseError,), n_inputs),
        _fuzz("Ping1D frames", _ping_strategy(), lambda b, r: _mutate_bytes(b, r, _ping_fix), _ping_check, (),
              n_inputs),
        _fuzz("MS5837 PROM/ADC conversion", _ms5837_strategy(), _ms5837_mutate, _ms5837_check, (Ms5837Error,),
              n_inputs),
        _fuzz("ICM-20948 register decoding", _icm_strategy(), _icm_mutate, _icm_check, (Icm20948Error,), n_inputs),
    ]


# ---------------------------------------------------------------------------------------------- faults
def _until(predicate: Callable[[], Any], spin: Callable[[], None], timeout_s: float, what: str) -> float:
    """Spin until ``predicate()``; return the wall time it took, s (raises on timeout)."""
    t0 = time.monotonic()
    wait_until(predicate, timeout_s, spin, what)
    return time.monotonic() - t0


def _dvl_faults() -> list[dict]:
    def truth(t):
        return DvlTruth(velocity_frd_m_s=(0.3 + 0.1 * math.sin(2 * t), 0.05 * math.cos(3 * t), 0.0),
                        altitude_m=3.0 + 0.2 * math.sin(t))

    emu = Dvl75Emulator(truth, rate_hz=20.0)
    dev = PtyDevice(emu)
    out = []
    try:
        with ros_context() as ctx:
            node = Dvl75Node(context=ctx, parameter_overrides=config_parameters({"sensors.dvl75.port": dev.path}))
            with spinning(ctx, node, timeout_s=0.002) as (_ex, spin):
                _until(lambda: node._valid_count >= 5 and node.commands.sequences_completed >= 1, spin, 20, "data")
                dev.disconnect()
                detect = _until(lambda: node.diag.state == "reconnecting", spin, 10, "unplug detected")
                valid = node._valid_count
                dev.reconnect()
                recover = _until(lambda: node._valid_count > valid, spin, 10, "valid data after replug")
                out.append(_fault_row("serial unplug/replug (DVL-75 over a pty)", detect, recover,
                                      "detect: unplug -> state reconnecting; recover: replug -> valid dvl/data"))
                _until(lambda: node._valid_count >= valid + 5, spin, 10, "steady")
                invalid = node._invalid_count
                with dev.lock:
                    emu.set_unlocked(True)
                detect = _until(lambda: node._invalid_count > invalid, spin, 10, "lock loss published invalid")
                valid = node._valid_count
                with dev.lock:
                    emu.set_unlocked(False)
                recover = _until(lambda: node._valid_count > valid, spin, 10, "valid after lock")
                out.append(_fault_row("DVL bottom-lock loss", detect, recover,
                                      "detect: lock lost -> first report not valid; recover: lock -> first valid "
                                      "(20 Hz pings)"))
    finally:
        dev.close()
    return out


def _fault_row(name: str, detect_s: float, recover_s: float, note: str) -> dict:
    return {"name": name, "detect_s": detect_s, "recover_s": recover_s, "note": note}


def _icm_faults() -> list[dict]:
    def truth(t):
        s = math.sin(7.0 * t)
        return (0.5 + 0.5 * s, -1.2 + 0.5 * s, 9.6 + 0.5 * s), (0.1 * s, -0.2, 0.05), \
            (21e-6 + 5e-6 * s, -5e-6, 41e-6), 27.0 + 0.5 * s

    emu = Icm20948Emulator(truth, address=0x69)
    bus = EmulatedI2CBus({0x69: emu}, seed=1)
    out = []
    with ros_context() as ctx:
        node = Icm20948Node(bus=bus, context=ctx, parameter_overrides=config_parameters(
            {"sensors.icm20948.estimate_gyro_bias": False}))
        with spinning(ctx, node, timeout_s=0.002) as (_ex, spin):
            _until(lambda: node.diag.total_published >= 50, spin, 20, "IMU data")
            failures, published = node.diag.counts().get("i2c_failure", 0), node.diag.total_published
            bus.disconnected = True
            detect = _until(lambda: node.diag.counts().get("i2c_failure", 0) > failures, spin, 5, "I2C failure")
            spin_for(0.3 - detect, spin)  # the rest of the burst
            published = node.diag.total_published
            bus.disconnected = False
            recover = _until(lambda: node.diag.total_published > published, spin, 5, "data after the burst")
            out.append(_fault_row("I2C errno 121 burst 0.3 s (ICM-20948)", detect, recover,
                                  "detect: burst -> failed poll counted; recover: bus back -> next imu/data_raw"))

            emu.stuck = True
            detect = _until(lambda: node.is_stuck, spin, 10, "stuck detected")
            published = node.diag.total_published
            emu.stuck = False
            recover = _until(lambda: node.diag.total_published > published, spin, 5, "published again")
            out.append(_fault_row("stuck sensor (ICM-20948 registers frozen)", detect, recover,
                                  "detect: freeze -> ERROR stuck (2 s of identical samples); recover: unfreeze "
                                  "-> next imu/data_raw"))

            resets, published = node.diag.counts().get("chip_resets", 0), node.diag.total_published
            t0 = time.monotonic()
            emu.power_glitch()
            detect = _until(lambda: node.diag.counts().get("chip_resets", 0) > resets, spin, 5, "reset detected")
            between = node.diag.total_published - published
            _until(lambda: node.running and node.diag.total_published > published + between, spin, 5,
                   "data after reset")
            out.append(_fault_row("chip reset (ICM-20948 power glitch)", detect, time.monotonic() - t0,
                                  f"recover: glitch -> first imu/data_raw after re-initialisation; {between} "
                                  "sample(s) published between the glitch and its detection"))

            lost = node.diag.counts().get("mag_lost", 0)
            emu.aux_connected = False
            detect = _until(lambda: node.diag.counts().get("mag_lost", 0) > lost, spin, 5, "magnetometer lost")
            _until(lambda: node.running and not node.mag_available, spin, 5, "running without magnetometer")
            mags = node.mag_samples
            emu.aux_connected = True
            retry_s = node.mag.retry_interval_s
            recover = _until(lambda: node.mag_samples > mags, spin, 3 * retry_s + 5, "imu/mag again")
            out.append(_fault_row("magnetometer NACK (AK09916 via I2C master)", detect, recover,
                                  "detect: NACK onset -> ERROR magnetometer (mag_stale_timeout_s 0.5 s; no "
                                  "frozen imu/mag published meanwhile); IMU continues without imu/mag; recover: "
                                  "AK09916 answers again (just after the failed re-initialisation) -> first "
                                  f"imu/mag (retried every mag_retry_interval_s {retry_s:g} s)"))
    return out


def _ms5837_faults() -> list[dict]:
    emu = Ms5837Emulator(lambda t: (110000.0 + 500.0 * math.sin(t), 18.0), variant="30BA")
    bus = EmulatedI2CBus({0x76: emu}, seed=2)
    with ros_context() as ctx:
        node = Ms5837Node(bus=bus, context=ctx, parameter_overrides=config_parameters({"sensors.ms5837.rate_hz": 25.0}))
        with spinning(ctx, node, timeout_s=0.002) as (_ex, spin):
            _until(lambda: node.diag.total_published >= 5, spin, 20, "pressure data")
            bus.disconnected = True
            emu.power_cycle()
            t0 = time.monotonic()
            detect = _until(lambda: node.diag.status().level == DiagnosticStatus.ERROR, spin, 10, "outage ERROR")
            spin_for(t0 + 0.5 - time.monotonic(), spin)  # the rest of the outage
            published = node.diag.total_published
            bus.disconnected = False
            recover = _until(lambda: node.diag.total_published > published, spin, 10, "pressure after the outage")
    return [_fault_row("I2C outage 0.5 s with sensor power loss (MS5837, 25 Hz)", detect, recover,
                       "detect: outage -> ERROR (3 failed cycles); recover: bus back -> reset, PROM, first "
                       f"pressure (resets sent: {emu.resets})")]


# ---------------------------------------------------------------------------------------------- bench rows
def run(quick: bool = False) -> list[dict]:
    """Benchmark rows (see the module docstring). ``quick``: 10k fuzzed inputs per parser."""
    rows: list[dict] = []
    for r in fuzz_parsers(FUZZ_INPUTS // 10 if quick else FUZZ_INPUTS):
        rows.append({"name": f"fuzz {r['name']}: crashes", "value": r["crashes"], "unit": "crashes",
                     "target": "0", "note": f"{r['inputs']} inputs ({r['accepted']} decoded) in {r['seconds']:.1f} s"
                                            + (f"; first: {r['first']}" if r["first"] else "")})
    for f in _dvl_faults() + _icm_faults() + _ms5837_faults():
        rows.append({"name": f"{f['name']}: time to detect", "value": f["detect_s"] * 1e3, "unit": "ms",
                     "note": f["note"]})
        rows.append({"name": f"{f['name']}: time to recover", "value": f["recover_s"] * 1e3, "unit": "ms"})
    return rows


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(run_alone(run))
