"""End-to-end tests: device emulators on a pseudo-terminal, read through the real pyserial path by
:class:`SerialTransport`.

Expected values are the emulator truth within the wire quantisation of docs/devices.md (§1.3.1: mm
position deltas over dtu; §2.4: mm distances).  Every wait is on a condition with a timeout.
"""

import threading
import time

import pytest

from hindrax_drivers.dvl75.emulator import Dvl75Emulator, DvlTruth
from hindrax_drivers.dvl75.protocol import (
    DvlExtended,
    DvlLineFramer,
    DvlParseError,
    DvlPositionDelta,
    DvlText,
    parse_line,
    startup_commands,
)
from hindrax_drivers.ping1d.emulator import Ping1dEmulator, Ping1dTruth
from hindrax_drivers.ping1d.protocol import (
    Ack,
    DistanceSimple,
    Ping1dFramer,
    Profile,
    SetSpeedOfSound,
    ContinuousStart,
    decode_message,
    request_frame,
)
from hindrax_common.transport.pty_device import PtyDevice
from hindrax_common.transport.serial_transport import SerialTransport, SerialTransportError

WAIT_S = 3.0


def wait_until(predicate, timeout_s: float = WAIT_S, poll_s: float = 0.005) -> bool:
    """Polling loop with a deadline, for state that has no notification of its own."""
    deadline = time.monotonic() + timeout_s
    pause = threading.Event()
    while not predicate():
        if time.monotonic() >= deadline:
            return False
        pause.wait(poll_s)
    return True


class Collector:
    """Thread-safe sink for the transport callbacks; tests wait on its condition."""

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self.cond = threading.Condition()
        self.records = []
        self.parse_errors = 0
        self.rx_chunks = []
        self.tap = []
        self.framer = DvlLineFramer() if kind == "dvl" else Ping1dFramer()

    def on_data(self, data: bytes) -> None:
        with self.cond:
            self.rx_chunks.append(data)
            for item in self.framer.feed(data):
                try:
                    self.records.append(parse_line(item) if self.kind == "dvl" else decode_message(item))
                except (DvlParseError, ValueError):
                    self.parse_errors += 1
            self.cond.notify_all()

    def on_raw(self, direction: str, data: bytes, t_s: float) -> None:
        with self.cond:
            self.tap.append((direction, data, t_s))
            self.cond.notify_all()

    def on_connect(self) -> None:
        with self.cond:
            self.framer.reset()  # a partial line from before the disconnect is garbage

    def count(self, cls) -> int:
        return sum(isinstance(r, cls) for r in self.records)

    def of(self, cls):
        with self.cond:
            return [r for r in self.records if isinstance(r, cls)]

    def wait_for(self, predicate, timeout_s: float = WAIT_S) -> bool:
        with self.cond:
            return self.cond.wait_for(lambda: predicate(self), timeout=timeout_s)


@pytest.fixture
def dvl_setup():
    truth = {"v": DvlTruth(velocity_frd_m_s=(0.6, -0.3, 0.1), altitude_m=2.5)}
    emu = Dvl75Emulator(lambda t: truth["v"], rate_hz=20)
    dev = PtyDevice(emu)
    col = Collector("dvl")
    tr = SerialTransport(dev.path, on_data=col.on_data, on_raw=col.on_raw, on_connect=col.on_connect)
    assert tr.wait_connected(WAIT_S)
    yield truth, emu, dev, col, tr
    tr.close()
    dev.close()


def test_dvl_end_to_end_values_match_truth_and_tap_sees_bytes(dvl_setup):
    truth, emu, dev, col, tr = dvl_setup
    assert col.wait_for(lambda c: c.count(DvlExtended) >= 3)
    with col.cond:
        assert col.count(DvlPositionDelta) == 0  # $DVPDL is OFF by factory default (§0 item 1)
    sent = b""
    for cmd in startup_commands():
        assert tr.write(cmd) == len(cmd)
        sent += cmd
    assert col.wait_for(lambda c: c.count(DvlPositionDelta) >= 5)
    for rec in col.of(DvlPositionDelta):
        assert rec.delta_time_s == pytest.approx(0.05)  # 20 Hz
        v = rec.velocity_frd_m_s()
        for got, want in zip(v, truth["v"].velocity_frd_m_s):
            assert abs(got - want) <= 0.5e-3 / rec.delta_time_s + 1e-9  # 1 mm over dtu
    ext = col.of(DvlExtended)[-1]
    assert ext.locked and ext.altitude_m == pytest.approx(2.5, abs=0.005)
    assert col.wait_for(lambda c: any(isinstance(r, DvlText) and r.text == "SEND-DVPDL ON"
                                      for r in c.records))
    with col.cond:
        rx_tap = b"".join(d for direction, d, _ in col.tap if direction == "rx")
        tx_tap = b"".join(d for direction, d, _ in col.tap if direction == "tx")
        assert rx_tap == b"".join(col.rx_chunks) and len(rx_tap) > 0
        assert tx_tap == sent
        times = [t for _, _, t in col.tap]
        assert times == sorted(times)
    status = tr.status()
    assert status.bytes_tx == len(sent) and status.bytes_rx >= len(rx_tap)
    assert status.connected and status.reconnects == 0


def test_dvl_faults_are_counted_not_fatal(dvl_setup):
    truth, emu, dev, col, tr = dvl_setup
    assert col.wait_for(lambda c: c.count(DvlExtended) >= 2)
    with col.cond:
        base_discard = col.framer.discarded_bytes
    emu.faults.inject_garbage(n_bytes=40)
    assert col.wait_for(lambda c: c.framer.discarded_bytes >= base_discard + 40)
    emu.faults.corrupt_checksum(2)
    assert col.wait_for(lambda c: c.parse_errors >= 2)
    with col.cond:
        before = col.framer.discarded_bytes
    emu.faults.truncate(1)
    assert col.wait_for(lambda c: c.framer.discarded_bytes > before)
    n = col.count(DvlExtended)
    assert col.wait_for(lambda c: c.count(DvlExtended) >= n + 3)  # the stream carries on
    assert tr.connected and tr.status().callback_errors == 0


def test_dvl_device_disappears_and_transport_reconnects_at_the_next_attempt(dvl_setup):
    truth, emu, dev, col, tr = dvl_setup
    lost = threading.Event()
    tr.on_disconnect = lambda text: lost.set()
    assert col.wait_for(lambda c: c.count(DvlExtended) >= 2)
    dev.disconnect()
    assert lost.wait(WAIT_S)
    assert not tr.connected and "read failed" in (tr.status().last_error or "")
    with pytest.raises(SerialTransportError):
        tr.write(b"SEND-DVPDL ON\r\n")
    n = col.count(DvlExtended)
    failures = tr.status().open_failures
    dev.reconnect()
    # The first open attempt after the device is back succeeds (at most one attempt was already under way
    # when it came back), so the reconnect comes within one backoff period (reconnect_max_s = 1 s). Counted
    # in attempts, not in wall time: a loaded 2-core CI can delay the reader thread past any fixed deadline.
    assert tr.wait_connected(30.0)
    assert tr.status().open_failures <= failures + 1
    assert tr.status().reconnects == 1
    assert col.wait_for(lambda c: c.count(DvlExtended) >= n + 3)
    tr.write(b"SEND-DVPDL ON\r\n")  # writes work again on the new pty
    assert col.wait_for(lambda c: c.count(DvlPositionDelta) >= 1)


def test_transport_started_before_device_exists_connects_when_it_appears():
    emu = Dvl75Emulator(DvlTruth())
    dev = PtyDevice(emu)
    dev.disconnect()
    col = Collector("dvl")
    tr = SerialTransport(dev.path, on_data=col.on_data, reconnect_initial_s=0.02, reconnect_max_s=0.5)
    try:
        assert wait_until(lambda: tr.status().open_failures >= 2)  # backoff in progress
        assert not tr.connected
        failures = tr.status().open_failures
        dev.reconnect()
        assert tr.wait_connected(30.0)
        assert tr.status().open_failures <= failures + 1  # the next attempt after it appeared succeeded
        assert tr.status().reconnects == 0  # first successful open is not a reconnect
        assert col.wait_for(lambda c: c.count(DvlExtended) >= 1)
    finally:
        tr.close()
        dev.close()


def test_simulation_clock_drives_the_emulator():
    now = {"t": 100.0}
    emu = Dvl75Emulator(DvlTruth(), rate_hz=10)
    dev = PtyDevice(emu, clock=lambda: now["t"])
    col = Collector("dvl")
    tr = SerialTransport(dev.path, on_data=col.on_data)
    try:
        assert tr.wait_connected(WAIT_S)
        tr.write(b"?\r\n")  # the reply proves the loop ran with the clock frozen
        assert col.wait_for(lambda c: any(isinstance(r, DvlText) and r.text == "CONFIGURATION"
                                          for r in c.records))
        assert col.count(DvlExtended) == 0
        with dev.lock:
            now["t"] = 101.0  # one simulated second
        assert col.wait_for(lambda c: c.count(DvlExtended) >= 10)
        tr.write(b"?\r\n")
        assert col.wait_for(lambda c: sum(isinstance(r, DvlText) and r.text == "CONFIGURATION"
                                          for r in c.records) == 2)
        assert col.count(DvlExtended) == 10  # exactly rate x simulated time
    finally:
        tr.close()
        dev.close()


def test_ping1d_end_to_end_requests_settings_stream_and_faults():
    truth = {"v": Ping1dTruth(altitude_m=3.217, confidence_pct=93)}
    emu = Ping1dEmulator(lambda t: truth["v"], true_speed_of_sound_m_s=1500.0)
    dev = PtyDevice(emu)
    col = Collector("ping")
    tr = SerialTransport(dev.path, on_data=col.on_data, on_raw=col.on_raw)
    try:
        assert tr.wait_connected(WAIT_S)
        tr.write(b"U" + request_frame(1211))  # auto-baud sync byte first (§2.1)
        assert col.wait_for(lambda c: c.count(DistanceSimple) >= 1)
        d = col.of(DistanceSimple)[0]
        assert d.distance_m == pytest.approx(3.217, abs=0.0005) and d.confidence_pct == 93
        tr.write(SetSpeedOfSound(1450.0).encode())
        assert col.wait_for(lambda c: Ack(1002) in c.records)
        truth["v"] = Ping1dTruth(altitude_m=6.0, confidence_pct=80)
        tr.write(ContinuousStart(1300).encode())
        assert col.wait_for(lambda c: c.count(Profile) >= 3)
        p = col.of(Profile)[-1]
        assert p.distance_m == pytest.approx(6.0 * 1450 / 1500, abs=0.0005)  # §2.6 c scaling
        assert p.confidence_pct == 80 and len(p.profile_data) == 200
        # faults on the wire: counted by the host framer, the stream carries on
        with col.cond:
            base = (col.framer.discarded_bytes, col.framer.bad_checksums)
        emu.faults.inject_garbage(b"\x00\x13\x37garbage")
        assert col.wait_for(lambda c: c.framer.discarded_bytes >= base[0] + 10)
        emu.faults.corrupt_checksum(1)
        assert col.wait_for(lambda c: c.framer.bad_checksums >= base[1] + 1)
        emu.faults.truncate(1)
        assert col.wait_for(lambda c: c.framer.bad_checksums >= base[1] + 2)
        n = col.count(Profile)
        assert col.wait_for(lambda c: c.count(Profile) >= n + 3)
        with col.cond:
            assert any(d == "tx" for d, _, _ in col.tap) and any(d == "rx" for d, _, _ in col.tap)
    finally:
        tr.close()
        dev.close()


def test_callback_exception_does_not_kill_reader():
    emu = Dvl75Emulator(DvlTruth())
    dev = PtyDevice(emu)
    col = Collector("dvl")
    calls = {"n": 0}

    def flaky(data: bytes) -> None:
        calls["n"] += 1
        if calls["n"] == 1:
            raise RuntimeError("driver bug")
        col.on_data(data)

    tr = SerialTransport(dev.path, on_data=flaky)
    try:
        assert col.wait_for(lambda c: c.count(DvlExtended) >= 2)
        status = tr.status()
        assert status.callback_errors == 1 and "driver bug" in status.last_error
        assert tr.connected
    finally:
        tr.close()
        dev.close()


def test_close_joins_thread_and_loop_url_works():
    col = Collector("ping")
    tr = SerialTransport("loop://", on_data=col.on_data)
    assert tr.wait_connected(WAIT_S)
    tr.write(request_frame(1211))  # loop:// echoes what is written
    assert col.wait_for(lambda c: len(c.rx_chunks) > 0 and b"".join(c.rx_chunks) == request_frame(1211))
    name = f"SerialTransport({tr.port})"
    assert any(t.name == name for t in threading.enumerate())
    tr.close()
    assert not any(t.name == name for t in threading.enumerate())
    assert tr.status().closed and not tr.connected
    with pytest.raises(SerialTransportError):
        tr.write(b"x")
    tr.close()  # idempotent


def test_caller_driven_device_and_pump_hand_every_byte_to_the_callback_in_the_calling_thread():
    """``PtyDevice(start=False).service(t)``: output only when the caller serves it, at the caller's time; the
    transport's ``pump`` reads until the callback has run on every byte sent, in the calling thread
    (the lock-step a
    simulator uses; the reader thread reads no more), and times out when nothing more comes."""
    emu = Dvl75Emulator(DvlTruth(velocity_frd_m_s=(0.2, 0.0, 0.0), altitude_m=1.5), rate_hz=10)
    dev = PtyDevice(emu, clock=lambda: 0.0, start=False)
    col, threads = Collector("dvl"), []
    tr = SerialTransport(dev.path, on_data=lambda data: (threads.append(threading.current_thread()),
                                                         col.on_data(data)))
    try:
        assert tr.wait_connected(WAIT_S) and tr.status().connections == 1
        assert not dev.threaded and tr.pump(0, 0.0)
        dev.service(0.0)  # boot banner; nothing is due before the first ping
        sent = dev.service(1.0)  # ten pings: exactly 10 $DVEXT (the caller's time, not the wall clock)
        assert sent > 0 and dev.bytes_from_host == 0
        assert tr.pump(dev.bytes_to_host, WAIT_S)
        st = tr.status()
        assert st.bytes_handled == st.bytes_rx == dev.bytes_to_host
        assert col.count(DvlExtended) == 10 and set(threads) == {threading.current_thread()}
        assert not tr.pump(dev.bytes_to_host + 1, 0.05)
        with pytest.raises(RuntimeError):
            dev.start()
            dev.service(2.0)
    finally:
        tr.close()
        dev.close()


def _voluntary_switches(thread: threading.Thread) -> int:
    """The thread's voluntary context switches so far (Linux ``/proc``): one per wake-up."""
    with open(f"/proc/self/task/{thread.native_id}/status") as status:
        return next(int(line.split()[1]) for line in status
                    if line.startswith("voluntary_ctxt_switches"))


def test_while_the_caller_reads_the_reader_thread_sleeps_until_the_port_is_lost_and_reopens_it():
    """After the first ``pump`` the reader thread does not wake while the port stays open (a caller
    reading for 0.3 s with a 10 ms read timeout: no wake-up of it, where polling made 29); when a
    read fails it wakes and re-opens the port once the device is back."""
    emu = Dvl75Emulator(DvlTruth(velocity_frd_m_s=(0.2, 0.0, 0.0), altitude_m=1.5), rate_hz=10)
    dev = PtyDevice(emu, clock=lambda: 0.0, start=False)
    tr = SerialTransport(dev.path, read_timeout_s=0.01, reconnect_initial_s=0.01,
                         reconnect_max_s=0.05)
    try:
        assert tr.wait_connected(WAIT_S)
        reader = next(t for t in threading.enumerate() if t.name == f"SerialTransport({tr.port})")
        assert not tr.pump(1, 0.1)  # takes the reading over; the reader thread's read returns
        before = _voluntary_switches(reader)
        assert not tr.pump(1, 0.3)  # nothing comes: 0.3 s of reads in this thread
        assert _voluntary_switches(reader) - before <= 1
        dev.disconnect()
        assert not tr.pump(1, 0.1) and not tr.connected  # the read fails: the port is closed
        dev.reconnect()
        assert wait_until(lambda: tr.status().connections == 2)
        dev.service(1.0)
        assert tr.pump(dev.bytes_to_host, WAIT_S)
    finally:
        tr.close()
        dev.close()
