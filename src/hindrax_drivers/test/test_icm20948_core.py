"""ICM-20948 start-up core (hindrax_drivers.icm20948.core) against the register-exact emulator, without ROS.

The expected values are the datasheet's and the settings', written out here: DEVICE_RESET then 10 ms, wake then
20 ms (docs/devices.md §4.3); +-4 g -> ACCEL_FS_SEL 1, +-500 dps -> GYRO_FS_SEL 1, 50 Hz -> divider
round(1125 / 50) - 1 = 21, DLPFCFG 4 (docs/devices.md §4.4); the slowest AK09916 continuous mode not below
1125 / 22 = 51.1 Hz is mode 4, 100 Hz, CNTL2 = 0x08 (docs/devices.md §4.5); WHO_AM_I 0xEA, AK09916 WIA 0x48 0x09.
"""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from hindrax_drivers.icm20948 import protocol as p
from hindrax_drivers.icm20948.core import (MAG_ATTEMPTS, BankedRegisters, DataReadyGate, FrozenBlockWatch, GyroBias,
                                           ImuSettings, MagnetometerWatch, MagNackFilter, PollFailures,
                                           StartupSequence, chip_reset_problems, diagnostic_values,
                                           imu_config_from_settings, mag_mode_for_rate, read_poll)
from hindrax_drivers.icm20948.emulator import Icm20948Emulator
from hindrax_common.transport.emulated_i2c import EmulatedI2CBus, ManualClock
from hindrax_common.transport.i2c import I2CDevice

ADDRESS = 0x69
CONFIG = imu_config_from_settings(4.0, 500.0, 4, 50.0)
EXPECTED_CONFIG = p.ImuConfig(accel_fs_sel=1, gyro_fs_sel=1, accel_dlpfcfg=4, gyro_dlpfcfg=4, accel_smplrt_div=21,
                              gyro_smplrt_div=21)
EXPECTED_MAG_MODE = 0x08  # AK09916 CNTL2 continuous mode 4 (100 Hz)


def truth(t):
    return np.array([0.1, -0.2, 9.8]), np.array([0.01, 0.02, -0.03]), np.array([20e-6, -5e-6, 40e-6]), 25.0


class OtherChip(Icm20948Emulator):
    """An MPU-9250 answering at the address (WHO_AM_I 0x71)."""

    def _read_register(self, register):
        if self._bank == 0 and register == p.WHO_AM_I.address:
            return 0x71
        return super()._read_register(register)


class Rig:
    def __init__(self, mode="i2c_master", chip=Icm20948Emulator, present=True, aux=True, aux_on_bus=True):
        self.clock = ManualClock(100.0)
        self.emu = chip(truth, clock=self.clock, address=ADDRESS)
        self.emu.aux_connected = aux
        self.bus = EmulatedI2CBus()
        if present:
            self.bus.add_device(ADDRESS, self.emu)
            if mode == "bypass" and aux_on_bus:
                self.bus.add_device(p.AK09916_ADDRESS, self.emu.aux_port)
        self.mode = mode
        self.regs = BankedRegisters(I2CDevice(self.bus, ADDRESS, "icm20948", backoff_s=0.0))
        self.mag = I2CDevice(self.bus, p.AK09916_ADDRESS, "ak09916", backoff_s=0.0)
        self.events: list[tuple[bool, str]] = []

    def sequence(self, **kwargs):
        return StartupSequence(self.regs, self.mag, CONFIG, self.mode, mag_mode_for_rate(CONFIG.accel_odr_hz),
                               lambda ok, why: self.events.append((ok, why)), **kwargs)

    def run(self, **kwargs):
        """Advance a sequence to its end, letting the emulator's time pass by each requested wait."""
        seq = self.sequence(**kwargs)
        waits = []
        for _ in range(200):
            result = seq.advance()
            if result.failure is not None or result.done:
                return seq, result, waits
            waits.append(result.wait_s)
            self.clock.advance(result.wait_s)
        raise AssertionError("the start-up never ended")


def test_settings_give_the_datasheet_register_fields():
    assert CONFIG == EXPECTED_CONFIG
    assert mag_mode_for_rate(CONFIG.accel_odr_hz) == EXPECTED_MAG_MODE
    assert mag_mode_for_rate(10.0) == 0x02 and mag_mode_for_rate(20.0) == 0x04 and mag_mode_for_rate(50.0) == 0x06


#: name, Rig arguments, failure text (None: the start-up completes), magnetometer available, reason text
CASES = [
    ("i2c_master", {}, None, True, ""),
    ("i2c_master, AK09916 silent", {"aux": False}, None, False, f"after {MAG_ATTEMPTS} attempts"),
    ("bypass", {"mode": "bypass"}, None, True, ""),
    ("bypass, AK09916 absent", {"mode": "bypass", "aux_on_bus": False}, None, False, "no answer at 0x0c"),
    ("another chip", {"chip": OtherChip}, "WHO_AM_I = 0x71, expected 0xea: not an ICM-20948 at 0x69", None, ""),
    ("no chip", {"present": False}, "start-up I2C failure", None, ""),
]


@pytest.mark.parametrize("name,kwargs,failure,mag,reason", CASES, ids=[c[0] for c in CASES])
def test_startup_table(name, kwargs, failure, mag, reason):
    rig = Rig(**kwargs)
    seq, result, waits = rig.run()
    if failure is not None:
        assert result.failure is not None and failure in result.failure
        assert result.i2c_failure == ("I2C" in failure)
        assert rig.emu.sleeping  # never woken: nothing was configured
        return
    assert result.done and result.failure is None
    assert waits[:2] == [0.010, 0.020]  # DEVICE_RESET, wake
    assert seq.who_am_i == 0xEA
    assert not rig.emu.sleeping and rig.emu.config == EXPECTED_CONFIG
    assert seq.mag_available is mag
    assert rig.events[-1][0] is mag and reason in rig.events[-1][1]
    if kwargs.get("mode") == "bypass":
        assert rig.emu.bypass_active and not rig.emu.master_enabled
        if mag:
            assert rig.emu.magnetometer.mode == EXPECTED_MAG_MODE
    else:
        assert rig.emu.master_enabled
        assert seq.mag_attempt == (1 if mag else MAG_ATTEMPTS)


def test_magnetometer_only_brings_a_returned_ak09916_back_without_resetting_the_chip():
    rig = Rig(aux=False)
    seq, result, _ = rig.run()
    assert result.done and not seq.mag_available
    rig.emu.aux_connected = True
    # a bank-0 register the start-up never writes and a DEVICE_RESET would clear: proof that no reset ran
    rig.regs.write(p.INT_ENABLE_1, 0x01)
    retry = rig.sequence(magnetometer_only=True)
    steps = 0
    while not retry.finished:
        rig.clock.advance(retry.step().wait_s)
        steps += 1
    assert retry.mag_available and rig.events[-1] == (True, "")
    assert steps >= 3 and retry.who_am_i is None  # no identity check: the chip is not started again
    assert rig.emu.register_value(p.INT_ENABLE_1) == 0x01 and rig.emu.config == EXPECTED_CONFIG


def test_a_failed_step_of_the_magnetometer_retry_gives_it_up_without_a_start_up_failure():
    rig = Rig(aux=False)
    rig.run()
    retry = rig.sequence(magnetometer_only=True)
    rig.bus.remove_device(ADDRESS)  # the whole bus goes quiet mid-retry
    result = retry.step()
    assert result.done and retry.finished and result.failure is None
    assert rig.events[-1][0] is False and "re-initialisation failed" in rig.events[-1][1]
    assert rig.regs.bank is None  # the failed transfer left the bank unknown


class RecordingDevice:
    address = ADDRESS

    def __init__(self):
        self.writes: list[tuple[int, int]] = []

    def write_byte_data(self, register, value):
        self.writes.append((register, value))

    def read_block(self, register, length):
        return bytes(length)


def test_banked_registers_select_a_bank_only_when_it_changes_or_is_unknown():
    dev = RecordingDevice()
    regs = BankedRegisters(dev)
    regs.read(p.WHO_AM_I)            # bank 0: selected
    regs.read(p.WHO_AM_I)            # still bank 0: no selection
    regs.write(p.GYRO_CONFIG_1, 1)   # bank 2
    regs.invalidate()
    regs.write(p.GYRO_CONFIG_1, 1)   # unknown: selected again
    regs.write(p.PWR_MGMT_1, p.PWR_MGMT_1_DEVICE_RESET)  # bank 0, and the reset makes the bank unknown
    regs.read(p.WHO_AM_I)
    bank_writes = [v for r, v in dev.writes if r == 0x7F]
    assert bank_writes == [0x00, 0x20, 0x20, 0x00, 0x00]  # REG_BANK_SEL bits 5:4 (docs/devices.md §4.1)
    with pytest.raises(ValueError, match="CNTL2 is not an ICM-20948 register"):
        regs.write(p.AK_CNTL2, 1)  # an AK09916 register has no user bank


def on_the_bus(writes, bank=None):
    """The (register, value) pairs the driver's :class:`BankedRegisters` puts on the bus for ``writes``, as the
    start-up's write steps run them, with ``bank`` known selected before (None: unknown)."""
    dev = RecordingDevice()
    regs = BankedRegisters(dev)
    if bank is not None:
        regs.select_bank(bank)
        dev.writes.clear()
    for w in writes:
        regs.write(w.register, w.value)
    return dev.writes


# ---------------------------------------------------------------------------------------------- sequences (§4.3, §4.6)
def test_reset_wake_sequence_reselects_bank_after_reset():
    assert on_the_bus(p.reset_wake_sequence()) == [(0x7F, 0x00), (0x06, 0x80), (0x7F, 0x00), (0x06, 0x01),
                                                    (0x07, 0x00)]
    assert p.reset_wake_sequence()[0].delay_after_s >= 0.010


def test_configure_sequence_in_bank_2():
    cfg = p.ImuConfig(accel_fs_sel=2, gyro_fs_sel=3, accel_dlpfcfg=4, gyro_dlpfcfg=2, accel_smplrt_div=0x2AB,
                      gyro_smplrt_div=7)
    assert on_the_bus(p.configure_sequence(cfg), bank=0) == [
        (0x7F, 0x20), (0x00, 7), (0x01, (2 << 3) | (3 << 1) | 1), (0x10, 0x02), (0x11, 0xAB),
        (0x14, (4 << 3) | (2 << 1) | 1)]
    assert on_the_bus(p.configure_sequence(cfg), bank=2)[0] == (0x00, 7)


def test_mag_sequences():
    cfg = p.ImuConfig()
    flat = on_the_bus(p.mag_master_sequence(cfg))
    # §4.6(b): BYPASS_EN = 0; I2C_MST_CTRL = 0x17; USER_CTRL = 0x20; SLV0 writes; SLV0 read 0x8C/0x10/0x89.
    assert flat[:6] == [(0x7F, 0x00), (0x0F, 0x00), (0x7F, 0x30), (0x01, 0x17), (0x7F, 0x00), (0x03, 0x20)]
    assert flat[-4:] == [(0x05, 0x00), (0x03, 0x8C), (0x04, 0x10), (0x05, 0x89)]
    assert [(0x03, 0x0C), (0x04, 0x32), (0x06, 0x01), (0x05, 0x81)] == flat[8:12]
    assert [(0x03, 0x0C), (0x04, 0x31), (0x06, 0x08), (0x05, 0x81)] == flat[13:17]
    assert on_the_bus(p.mag_bypass_sequence()) == [(0x7F, 0x00), (0x03, 0x00), (0x0F, 0x02)]
    assert [(w.register, w.value) for w in p.ak09916_direct_init_writes(0x08)] == [(0x32, 0x01), (0x31, 0x08)]
    with pytest.raises(p.Icm20948Error):
        p.mag_master_sequence(cfg, mode=0x03)


# ---------------------------------------------------------------------------------------------- per-poll decisions
A, B = bytes(range(1, 15)), bytes(range(2, 16))  # two different non-zero 14-byte sensor blocks
ZERO = bytes(14)


@pytest.mark.parametrize("blocks,expected", [
    ([A, B, A, B], [None, None, None, None]),          # a live sensor
    ([A, A, A, A], [None, None, None, "frozen"]),      # the third repeat with frozen_check_samples 3
    ([A, A, B, B, B, B], [None, None, None, None, None, "frozen"]),
    ([A, ZERO, ZERO], [None, "zero", "zero"]),         # the reset value of every data register
    ([A, A, A, A, A], [None, None, None, "frozen", None]),  # once per run of repeats
])
def test_frozen_block_watch(blocks, expected):
    watch = FrozenBlockWatch(3)
    assert [watch.update(b) for b in blocks] == expected


@pytest.mark.parametrize("state,master,problems", [
    (bytes([0x20, 0, 0x40, 0x01]), True, []),                                        # I2C master on, awake
    (bytes([0x00, 0, 0x40, 0x41]), True, ["PWR_MGMT_1 = 0x41 (asleep)", "USER_CTRL = 0x00 (I2C master off)"]),
    (bytes([0x00, 0, 0x40, 0x41]), False, ["PWR_MGMT_1 = 0x41 (asleep)"]),           # bypass: master off is right
    (bytes([0x00, 0, 0x40, 0x01]), True, ["USER_CTRL = 0x00 (I2C master off)"]),
])
def test_chip_reset_problems_from_the_read_back(state, master, problems):
    """PWR_MGMT_1 0x41 = the reset value (SLEEP, CLKSEL 1); USER_CTRL bit 5 = I2C_MST_EN (docs/devices.md §4.3)."""
    assert chip_reset_problems(state, master) == problems


@pytest.mark.parametrize("flags,publish,raised_at,cleared_at", [
    ([True, None, True], [True, True, True], [], []),
    ([False, False, True], [False, False, True], [], []),                     # below the 3 polls: no ERROR
    ([False, False, False, False, True], [False] * 4 + [True], [2], [4]),    # ERROR at the 3rd, cleared by a sample
    ([False, False, False, None], [False] * 3 + [True], [2], [3]),           # an unknown flag publishes and clears
])
def test_data_ready_gate(flags, publish, raised_at, cleared_at):
    gate = DataReadyGate(3)
    verdicts = [gate.update(f) for f in flags]
    assert [v.publish for v in verdicts] == publish
    assert [i for i, v in enumerate(verdicts) if v.raise_error] == raised_at
    assert [i for i, v in enumerate(verdicts) if v.clear_error] == cleared_at


def test_mag_nack_filter_drops_the_block_held_since_the_nack_until_it_changes():
    old, new = bytes([1] * 9), bytes([2] * 9)
    f = MagNackFilter()
    assert f.update(old, nack=False) == old
    assert f.update(old, nack=True) is None        # NACK: the block is the sample of before
    assert f.update(old, nack=False) is None       # the same block re-read between two master cycles
    assert f.update(new, nack=False) == new        # the AK09916 answered again
    assert f.update(new, nack=False) == new


# ---------------------------------------------------------------------------------------- node decisions
class FakeReinit:
    """A magnetometer-only re-initialisation of ``steps`` steps of 0.01 s each."""

    def __init__(self, steps=2):
        self.left = steps

    @property
    def finished(self):
        return self.left == 0

    def step(self):
        self.left -= 1
        return type("R", (), {"wait_s": 0.01})()


# (time s, magnetometer available, data_ready sample) -> event; timeout 0.5 s, retry every 2 s, reinit 2 steps
MAG_EVENTS = [
    ("fresh samples keep it watched", [(0.0, True, True), (0.4, True, True), (0.8, True, True)], ["", "", ""]),
    ("lost after 0.5 s without a fresh sample", [(0.0, True, True), (0.4, True, False), (0.6, True, False)],
     ["", "", "lost"]),
    ("the re-initialisation steps once per due poll, then recovers", [(0.0, True, True), (0.6, True, False),
     (0.6, False, False), (0.61, False, False), (0.62, True, False)], ["", "lost", "", "", "recovered"]),
    ("still missing: retried after the interval", [(0.0, True, True), (0.6, True, False), (0.6, False, False),
     (0.61, False, False), (0.62, False, False), (2.0, False, False), (2.62, False, False)],
     ["", "lost", "", "", "", "", "retry"]),
]


@pytest.mark.parametrize("name,polls,events", MAG_EVENTS, ids=[row[0] for row in MAG_EVENTS])
def test_magnetometer_watch_table(name, polls, events):
    made = []
    watch = MagnetometerWatch(1, 0.5, 2.0, lambda: made.append(FakeReinit()) or made[-1])
    watch.started(0.0, True)
    got = []
    for t_s, available, fresh in polls:
        if fresh:
            watch.sample(t_s, True, False)
        got.append(watch.after_sample(t_s, available))
    assert got == events
    assert len(made) == events.count("lost") + events.count("retry")
    assert ("lost" not in events) or "0.6" in watch.text or "recovered" in events


@pytest.mark.parametrize("samples,every,published", [
    ([(True, False)] * 6, 3, [True, False, False, True, False, False]),  # every 3rd valid sample
    ([(False, False), (True, True), (True, False)], 1, [False, False, True]),  # no DRDY; overflow: not published
])
def test_magnetometer_decimation(samples, every, published):
    watch = MagnetometerWatch(every, 0.5, 2.0, FakeReinit)
    assert [watch.sample(0.1 * i, ready, overflow) for i, (ready, overflow) in enumerate(samples)] == published


def test_poll_failures_restart_after_the_interval():
    failures = PollFailures(1.0)
    assert [failures.failed(t) for t in (5.0, 5.5, 6.0)] == ["warn", "warn", "restart"]
    failures.ok()
    assert failures.failed(6.1) == "warn"


def test_settings_rates_covariances_and_warnings():
    section = SimpleNamespace(sample_rate_hz=100.0, accel_full_scale_g=4.0, gyro_full_scale_dps=500.0,
                              dlpf_config=4, mounting_rpy_rad=[0.0, 0.0, np.pi / 2])
    st = ImuSettings.from_section(section)
    assert st.odr_hz == pytest.approx(1125 / 11) and not st.warnings  # 102.27 Hz is within 5 % of 100 Hz
    assert st.temperature_every == 102 and st.mag_every == 5  # 1 Hz; 100 Hz AK09916 mode / 20 Hz
    assert np.allclose(st.rotation @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])  # yaw 90 deg: x -> y
    assert np.allclose(np.diag(st.accel_cov), st.accel_var)  # isotropic noise stays diagonal under rotation
    slow = ImuSettings.from_section(SimpleNamespace(**{**vars(section), "sample_rate_hz": 700.0, "dlpf_config": 0}))
    assert len(slow.warnings) == 2 and "not reachable" in slow.warnings[0] and "1125 Hz" in slow.warnings[1]
    assert "FS 4 g, 500 dps, DLPFCFG 4" in st.describe()


def test_gyro_bias_applied_only_when_still():
    bias = GyroBias(True, 0.1, gyro_var=1e-6, accel_var=1e-4)
    assert bias.start() and bias.status == "estimating"
    results = [bias.add(0.01 * k, np.array([0.0, 0.0, 0.01]), np.array([0.0, 0.0, 9.81])) for k in range(12)]
    result = next(r for r in results if r is not None)  # once, when 0.1 s has passed
    assert results.count(None) == 11 and result.still and np.allclose(bias.bias_rad_s, [0.0, 0.0, 0.01])
    assert not bias.start()  # done once per process
    assert bias.status == result.message
    off = GyroBias(False, 0.1, 1e-6, 1e-4)
    assert not off.start() and off.status is None and off.add(0.0, np.zeros(3), np.zeros(3)) is None


def test_data_ready_text_and_diagnostic_values():
    gate = DataReadyGate(5)
    verdicts = [gate.update(False) for _ in range(5)]
    assert [v.raise_error for v in verdicts] == [False] * 4 + [True]
    assert "not set for 5 consecutive polls" in verdicts[-1].text
    values = dict(diagnostic_values(CONFIG, 0xEA, 50.0, "bypass", True, 7, 2, np.array([0.0, 0.001, -0.002]), None))
    assert values["who_am_i"] == "0xea" and values["output_data_rate_hz"] == "51.136"
    assert values["gyro_bias_rad_s"] == "0.000000 0.001000 -0.002000" and "gyro_bias_status" not in values


@pytest.mark.parametrize("mode,available,require,counters,has_mag,reads", [
    ("i2c_master", True, True, (), True, [(0x17, 45)]),  # status registers, data, EXT_SLV_SENS_DATA: one burst
    ("i2c_master", True, False, (), True, [(0x17, 45)]),
    ("bypass", True, False, (), True, [(0x2D, 14), (0x10, 9)]),
    ("bypass", True, True, (), True, [(0x1A, 33), (0x10, 9)]),
    ("i2c_master", False, False, (), False, [(0x2D, 14)]),  # no magnetometer: the 14-byte burst only
])
def test_read_poll_reads_what_the_mode_needs(mode, available, require, counters, has_mag, reads):
    rig = Rig(mode=mode)
    seq, result, _ = rig.run()
    assert result.done
    rig.regs.select_bank(0)
    rig.clock.advance(0.05)
    taps = []
    for dev in (rig.regs.device, rig.mag):
        dev.raw_tap = lambda direction, address, register, data, *_: taps.append((direction, register, len(data)))
    r = read_poll(rig.regs, rig.mag, mode, available, require, MagNackFilter())
    assert r.error is None and len(r.block) == p.SENSOR_BLOCK_LENGTH and r.counters == counters
    assert (r.ready is not None) == require and (r.mag_block is not None) == has_mag
    assert [(reg, n) for d, reg, n in taps if d == "read"] == reads  # one bus transaction per poll (bypass: two)
