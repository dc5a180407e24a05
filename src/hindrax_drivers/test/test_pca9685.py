"""PCA9685 protocol and emulator tests, with ESC conventions. Expected values are from
docs/devices.md §5.1 (register map, prescale formula and the resolution table) and §5.2."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hindrax_drivers.pca9685 import protocol as pca
from hindrax_drivers.pca9685.emulator import Pca9685Emulator, WriteLogEntry
from hindrax_common.transport.emulated_i2c import EmulatedI2CBus, ManualClock
from hindrax_common.transport.i2c import I2CDevice

ADDR = 0x40


# ----------------------------------------------------------------------------- protocol (§5.1)
def test_register_map():
    assert (pca.DEFAULT_ADDRESS, pca.MODE1, pca.MODE2, pca.PRE_SCALE) == (0x40, 0x00, 0x01, 0xFE)
    assert [pca.led_register(n) for n in (0, 1, 15)] == [0x06, 0x0A, 0x42]
    assert pca.led_register(15) + 3 == 0x45
    assert (pca.ALL_LED_ON_L, pca.ALL_LED_OFF_H) == (0xFA, 0xFD)
    assert (pca.MODE1_RESTART, pca.MODE1_EXTCLK, pca.MODE1_AI, pca.MODE1_SLEEP, pca.MODE1_ALLCALL) == \
        (0x80, 0x40, 0x20, 0x10, 0x01)
    assert (pca.MODE2_INVRT, pca.MODE2_OCH, pca.MODE2_OUTDRV) == (0x10, 0x08, 0x04)
    for bad in (-1, 16, 1.0, True):
        with pytest.raises(pca.Pca9685Error):
            pca.led_register(bad)


def test_prescale_examples():
    # docs/devices.md §5.1 resolution table and datasheet range (25 MHz).
    assert pca.prescale_for_frequency(50) == 121 == 0x79
    assert pca.prescale_for_frequency(200) == 30 == 0x1E
    assert pca.prescale_for_frequency(400) == 14 == 0x0E
    assert pca.prescale_for_frequency(1526) == 3
    assert pca.prescale_for_frequency(23.84) == 255
    assert pca.frequency_for_prescale(255) == pytest.approx(23.84, abs=0.005)   # "min ~24 Hz"
    assert pca.frequency_for_prescale(3) == pytest.approx(1525.9, abs=0.05)     # "max ~1526 Hz"
    assert pca.frequency_for_prescale(121) == pytest.approx(50.03, abs=0.005)
    assert pca.frequency_for_prescale(30) == pytest.approx(196.9, abs=0.05)
    assert pca.frequency_for_prescale(14) == pytest.approx(406.9, abs=0.05)
    assert pca.period_s(121) == pytest.approx(19.99e-3, abs=0.005e-3)
    assert pca.count_duration_us(121) == pytest.approx(4.88, abs=0.005)
    for bad in (2000, 20, 0, -5, float("nan")):   # 2000 Hz needs prescale 2
        with pytest.raises(pca.Pca9685Error):
            pca.prescale_for_frequency(bad)


def test_prescale_rounds_half_up():
    # osc / (4096 f) = 249856 / (4096 * 2) = 30.5 exactly: round half up gives 31 - 1 = 30
    # (Python's banker's rounding would give 29).
    assert pca.prescale_for_frequency(2.0, oscillator_hz=4096 * 61) == 30


@pytest.mark.parametrize("prescale, counts", [
    (121, (225.4, 307.4, 389.3)), (30, (887.1, 1209.7, 1532.3)), (14, (1833.3, 2500.0, 3166.7))])
def test_pulse_counts_table(prescale, counts):
    for pulse_us, expected in zip((1100, 1500, 1900), counts):
        assert pca.pulse_width_to_counts(pulse_us, prescale) == round(expected)
        back = pca.counts_to_pulse_width_us(pca.pulse_width_to_counts(pulse_us, prescale), prescale)
        assert abs(back - pulse_us) <= pca.count_duration_us(prescale) / 2
    steps = pca.pulse_width_to_counts(1900, prescale) - pca.pulse_width_to_counts(1100, prescale)
    assert steps == pytest.approx(counts[2] - counts[0], abs=1)   # ~164 / ~645 / ~1333 steps


def test_pulse_width_errors():
    with pytest.raises(pca.Pca9685Error):
        pca.pulse_width_to_counts(25_000, 121)          # longer than the period
    with pytest.raises(pca.Pca9685Error):
        pca.pulse_width_to_counts(-1, 121)
    with pytest.raises(pca.Pca9685Error):
        pca.pulse_width_to_counts(1500, 2)              # prescale below 3


def test_channel_registers_encoding():
    assert pca.ChannelRegisters.full_off_setting().to_bytes() == bytes([0, 0, 0, 0x10])
    assert pca.ChannelRegisters.full_on_setting().to_bytes() == bytes([0, 0x10, 0, 0])
    assert pca.ChannelRegisters(0, 307).to_bytes() == bytes([0x00, 0x00, 0x33, 0x01])
    assert pca.ChannelRegisters(0xABC, 0x123).to_bytes() == bytes([0xBC, 0x0A, 0x23, 0x01])
    decoded = pca.ChannelRegisters.from_bytes(bytes([0xBC, 0xEA, 0x23, 0xF1]))   # reserved bits ignored
    assert decoded == pca.ChannelRegisters(0xABC, 0x123, full_on=False, full_off=True)
    with pytest.raises(pca.Pca9685Error):
        pca.ChannelRegisters.from_bytes(b"\x00\x00\x00")
    with pytest.raises(pca.Pca9685Error):
        pca.ChannelRegisters(4096, 0)


def test_high_time_semantics():
    assert pca.high_time_counts(pca.ChannelRegisters(0, 307)) == 307
    assert pca.high_time_counts(pca.ChannelRegisters(4000, 100)) == 196          # wraps
    assert pca.high_time_counts(pca.ChannelRegisters(5, 5)) == 0                 # ON == OFF
    assert pca.high_time_counts(pca.ChannelRegisters(full_on=True)) == 4096
    assert pca.high_time_counts(pca.ChannelRegisters(full_on=True, full_off=True)) == 0   # OFF wins
    assert pca.channel_bytes_for_pulse(0.0, 121) == bytes([0, 0, 0, 0x10])
    assert pca.channel_bytes_for_pulse(1500, 121, on_count=4000) == \
        pca.ChannelRegisters(4000, (4000 + 307) % 4096).to_bytes()


def test_sequences_as_data():
    seq = pca.set_frequency_sequence(121, mode1=pca.MODE1_AI)
    assert [(w.register, w.value) for w in seq] == [(0x00, 0x30), (0xFE, 121), (0x00, 0x20), (0x00, 0xA0)]
    assert seq[2].delay_after_s >= 500e-6
    start = pca.startup_sequence(30)
    assert (start[0].register, start[0].value) == (0x01, 0x04)
    assert [(w.register, w.value) for w in start[1:]] == [(0x00, 0x31), (0xFE, 30), (0x00, 0x21), (0x00, 0xA1)]
    with pytest.raises(pca.Pca9685Error):
        pca.set_frequency_sequence(256)


def test_esc_conventions():
    assert (pca.ESC_MIN_US, pca.ESC_NEUTRAL_US, pca.ESC_MAX_US) == (1100, 1500, 1900)
    assert pca.esc_prescale(50) == 121
    assert pca.esc_prescale(200) == 30
    assert pca.esc_prescale(381.5) == 15
    with pytest.raises(pca.Pca9685Error, match="406.9"):
        pca.esc_prescale(400)          # prescale 14 -> 406.9 Hz > 400 Hz (§5.1 note)
    with pytest.raises(pca.Pca9685Error):
        pca.esc_prescale(30)


# ----------------------------------------------------------------------------- emulator
def make(oscillator_hz=25e6):
    clock = ManualClock(1.0)
    emu = Pca9685Emulator(oscillator_hz=oscillator_hz, clock=clock)
    bus = EmulatedI2CBus({ADDR: emu})
    dev = I2CDevice(bus, ADDR, "pca9685", sleep=clock.sleep, clock=clock)
    return clock, emu, bus, dev


def test_power_on_state():
    clock, emu, bus, dev = make()
    assert dev.read_byte_data(0x00) == 0x11 and dev.read_byte_data(0x01) == 0x04
    assert dev.read_byte_data(0xFE) == 0x1E
    assert dev.read_byte_data(0x05) == 0xE0
    for channel in range(16):
        base = pca.led_register(channel)
        # AI = 0 at power-up, so read register by register.
        assert [dev.read_byte_data(base + k) for k in range(4)] == [0, 0, 0, 0x10]
        assert emu.pulse_width_us(channel) == 0.0


def test_prescale_only_writable_while_sleeping():
    clock, emu, bus, dev = make()
    dev.write_byte_data(0xFE, 121)                      # asleep at power-up: accepted
    assert dev.read_byte_data(0xFE) == 121
    dev.write_byte_data(0x00, 0x01)                     # wake
    dev.write_byte_data(0xFE, 30)                       # ignored
    assert dev.read_byte_data(0xFE) == 121
    dev.write_byte_data(0x00, 0x11)
    dev.write_byte_data(0xFE, 1)                        # forced to the minimum 3
    assert dev.read_byte_data(0xFE) == 3


def test_auto_increment_rules():
    clock, emu, bus, dev = make()
    dev.write_block(0x06, bytes([1, 2, 3, 4]))          # AI = 0: every byte to LED0_ON_L
    assert dev.read_byte_data(0x06) == 4
    assert dev.read_byte_data(0x07) == 0 and dev.read_byte_data(0x09) == 0x10
    dev.write_byte_data(0x00, 0x31)                     # AI = 1 (still asleep)
    dev.write_block(0x06, bytes([1, 2, 3, 4]))
    assert dev.read_block(0x06, 4) == bytes([1, 2, 3, 4])
    dev.write_block(0x45, bytes([0x10, 0x21]))          # wraps 0x45 -> 0x00 (MODE1)
    assert dev.read_byte_data(0x45) == 0x10 and dev.read_byte_data(0x00) == 0x21
    assert dev.read_block(0xFE, 2) == bytes([0x1E, 0x21])   # PRE_SCALE -> MODE1
    assert dev.read_block(0xFA, 4) == bytes(4)          # ALL_LED reads as zero
    dev.write_byte_data(0x41, 0xFF)                     # LED14_OFF_H: reserved bits 7:5 read 0
    assert dev.read_byte_data(0x41) == 0x1F


def start(dev, prescale, mode1=pca.MODE1_AI):
    dev.write_sequence(pca.startup_sequence(prescale, mode1=mode1))


@pytest.mark.parametrize("prescale", [121, 30, 15])
@pytest.mark.parametrize("oscillator_hz", [25e6, 24.06e6, 26.5e6])
def test_pulse_widths_decoded_at_the_wire_within_one_count(prescale, oscillator_hz):
    clock, emu, bus, dev = make(oscillator_hz)
    start(dev, prescale)
    assert emu.prescale == prescale and not emu.sleeping
    assert clock.sleeps and clock.sleeps[0] >= 500e-6
    tick_us = pca.count_duration_us(prescale, oscillator_hz)
    commands = [1100 + 50 * n for n in range(16)] + [1500.0]
    for channel, pulse_us in enumerate(commands[:16]):
        dev.write_block(pca.led_register(channel), pca.channel_bytes_for_pulse(pulse_us, prescale, oscillator_hz))
    for channel, pulse_us in enumerate(commands[:16]):
        assert abs(emu.pulse_width_us(channel) - pulse_us) <= tick_us
    assert emu.period_s() == pytest.approx(1.0 / pca.frequency_for_prescale(prescale, oscillator_hz))


def test_uncalibrated_oscillator_shifts_the_pulse():
    # Driver assumes 25 MHz, the part runs at 24 MHz: every count lasts 25/24 longer, so 1500 us
    # comes out ~4 % long (§0.8, §5.1: calibrate the oscillator).
    clock, emu, bus, dev = make(24e6)
    start(dev, 121)
    dev.write_block(pca.led_register(0), pca.channel_bytes_for_pulse(1500, 121, 25e6))
    assert emu.pulse_width_us(0) == pytest.approx(307 * 122 / 24e6 * 1e6)
    assert abs(emu.pulse_width_us(0) - 1500 * 25 / 24) <= pca.count_duration_us(121, 24e6)


def test_full_on_full_off_and_invert():
    clock, emu, bus, dev = make()
    start(dev, 121)
    period_us = 4096 * 122 / 25e6 * 1e6
    dev.write_block(pca.led_register(3), pca.ChannelRegisters.full_on_setting().to_bytes())
    assert emu.pulse_width_us(3) == pytest.approx(period_us)
    dev.write_block(pca.led_register(3), pca.ChannelRegisters(0, 0, full_on=True, full_off=True).to_bytes())
    assert emu.pulse_width_us(3) == 0.0
    dev.write_block(pca.led_register(3), pca.ChannelRegisters(100, 407).to_bytes())
    dev.write_byte_data(0x01, 0x04 | pca.MODE2_INVRT)
    assert emu.pulse_width_us(3) == pytest.approx(period_us - 307 * 122 / 25e6 * 1e6)


def test_pulse_widths_follow_every_change_the_channels_depend_on():
    """pulse_widths_us (asked at every simulator step, computed again only on a change) equals pulse_width_us per
    channel after a channel write, MODE2.INVRT, sleep and /OE."""
    class Line:
        high = False

        def is_high(self):
            return self.high

    clock, emu, bus, dev = make()
    emu.output_enable_line = line = Line()
    start(dev, 121)
    channels = [0, 3, 7]

    def same():
        return emu.pulse_widths_us(channels) == [emu.pulse_width_us(c) for c in channels]

    dev.write_block(pca.led_register(3), pca.channel_bytes_for_pulse(1500, 121))
    assert same() and emu.pulse_widths_us(channels)[1] > 0.0
    dev.write_block(pca.led_register(3), pca.channel_bytes_for_pulse(1200, 121))
    assert same() and abs(emu.pulse_widths_us(channels)[1] - 1200) <= pca.count_duration_us(121)
    dev.write_byte_data(0x01, 0x04 | pca.MODE2_INVRT)
    assert same()
    line.high = True
    assert same() and emu.pulse_widths_us(channels) == [0.0, 0.0, 0.0]
    line.high = False
    dev.write_byte_data(0x01, 0x04)  # not inverted: asleep is no pulse
    dev.write_byte_data(0x00, pca.MODE1_SLEEP | pca.MODE1_AI)
    assert same() and emu.pulse_widths_us(channels) == [0.0, 0.0, 0.0]


def test_all_led_writes_every_channel():
    clock, emu, bus, dev = make()
    start(dev, 121)
    dev.write_block(pca.ALL_LED_ON_L, pca.channel_bytes_for_pulse(1500, 121))
    for channel in range(16):
        assert abs(emu.pulse_width_us(channel) - 1500) <= pca.count_duration_us(121)
        assert dev.read_block(pca.led_register(channel), 4) == bytes([0, 0, 0x33, 0x01])
    dev.write_byte_data(pca.ALL_LED_OFF_H, 0x10)        # ALL full OFF
    assert all(emu.pulse_width_us(c) == 0.0 for c in range(16))


def test_sleep_and_restart():
    clock, emu, bus, dev = make()
    start(dev, 121)
    dev.write_block(pca.led_register(0), pca.channel_bytes_for_pulse(1500, 121))
    assert dev.read_byte_data(0x00) & pca.MODE1_RESTART == 0
    dev.write_byte_data(0x00, 0x30)                     # SLEEP with an active channel
    assert emu.pulse_width_us(0) == 0.0
    assert dev.read_byte_data(0x00) & pca.MODE1_RESTART
    dev.write_byte_data(0x00, 0x20)                     # wake: channels stay stopped ...
    clock.sleep(pca.RESTART_DELAY_S)
    assert emu.pulse_width_us(0) == 0.0
    dev.write_byte_data(0x00, 0x20)                     # writing RESTART = 0 does nothing
    assert emu.pulse_width_us(0) == 0.0
    dev.write_byte_data(0x00, 0xA0)                     # ... until RESTART is written with 1
    assert abs(emu.pulse_width_us(0) - 1500) <= pca.count_duration_us(121)
    assert dev.read_byte_data(0x00) == 0x20
    # A PWM register write also clears RESTART.
    dev.write_byte_data(0x00, 0x30)
    dev.write_byte_data(0x00, 0x20)
    dev.write_block(pca.led_register(1), pca.channel_bytes_for_pulse(1200, 121))
    assert dev.read_byte_data(0x00) & pca.MODE1_RESTART == 0
    assert abs(emu.pulse_width_us(1) - 1200) <= pca.count_duration_us(121)


def test_extclk_latches_only_while_sleeping():
    clock = ManualClock()
    emu = Pca9685Emulator(clock=clock, external_clock_hz=50e6)
    bus = EmulatedI2CBus({ADDR: emu})
    bus.write_byte_data(ADDR, 0x00, 0x01)               # awake
    bus.write_byte_data(ADDR, 0x00, 0x41)               # EXTCLK while awake: ignored
    assert bus.read_byte_data(ADDR, 0x00) & pca.MODE1_EXTCLK == 0
    bus.write_byte_data(ADDR, 0x00, 0x11)
    bus.write_byte_data(ADDR, 0x00, 0x51)               # EXTCLK while asleep: latched
    bus.write_byte_data(ADDR, 0x00, 0x11)               # writing 0 does not clear it
    assert bus.read_byte_data(ADDR, 0x00) & pca.MODE1_EXTCLK
    assert emu.effective_oscillator_hz == 50e6
    bus.write_byte(0x00, pca.SWRST_DATA)                # software reset clears it
    assert bus.read_byte_data(ADDR, 0x00) == 0x11 and emu.effective_oscillator_hz == 25e6


def test_software_reset_via_general_call():
    clock, emu, bus, dev = make()
    start(dev, 121)
    dev.write_block(pca.led_register(0), pca.channel_bytes_for_pulse(1500, 121))
    reset = I2CDevice(bus, pca.GENERAL_CALL_ADDRESS, "general-call", sleep=clock.sleep)
    reset.write_byte(pca.SWRST_DATA)
    assert dev.read_byte_data(0x00) == 0x11 and dev.read_byte_data(0xFE) == 0x1E
    assert emu.pulse_width_us(0) == 0.0


def test_write_log_timestamps():
    clock, emu, bus, dev = make()
    clock.advance(2.0)
    dev.write_block(pca.led_register(2), bytes([1, 2, 3, 4]))
    clock.advance(0.25)
    dev.write_byte_data(0x01, 0x04)
    assert list(emu.write_log)[-5:] == [
        WriteLogEntry(3.0, 0x0E, 1), WriteLogEntry(3.0, 0x0E, 2), WriteLogEntry(3.0, 0x0E, 3),
        WriteLogEntry(3.0, 0x0E, 4), WriteLogEntry(3.25, 0x01, 0x04)]


@settings(max_examples=100, deadline=None)
@given(st.floats(0.0, 2400.0), st.sampled_from([30, 60, 121]), st.floats(23e6, 27e6))
def test_pulse_round_trip_within_one_count(pulse_us, prescale, oscillator_hz):
    clock, emu, bus, dev = make(oscillator_hz)
    dev.write_byte_data(0xFE, prescale)
    dev.write_byte_data(0x00, pca.MODE1_AI)
    dev.write_block(pca.led_register(7), pca.channel_bytes_for_pulse(pulse_us, prescale, oscillator_hz))
    assert abs(emu.pulse_width_us(7) - pulse_us) <= pca.count_duration_us(prescale, oscillator_hz) / 2 + 1e-9


def test_channel_block_matches_per_channel_bytes_and_decodes_the_counts():
    """The ESC node's block conversion gives exactly the per-channel bytes and the widths of their counts."""
    widths = [1100.0, 1474.4, 1500.0, 1525.6, 1900.0, 0.0, 1700.04, 3.0]
    block, decoded = pca.channel_block_for_pulses(widths, 30, 25e6)
    assert block == b"".join(pca.channel_bytes_for_pulse(w, 30, 25e6) for w in widths)
    # counts by hand: round(w / 1.24 us), e.g. 1500 / 1.24 = 1209.68 -> 1210 counts = 1500.40 us; 0 us is full OFF
    assert decoded[2] == pytest.approx(1210 * 1.24) and decoded[5] == 0.0 and block[20:24] == bytes([0, 0, 0, 0x10])
    with pytest.raises(pca.Pca9685Error):
        pca.channel_block_for_pulses([1500.0, float("nan")], 30, 25e6)
    with pytest.raises(pca.Pca9685Error):
        pca.channel_block_for_pulses([5100.0], 30, 25e6)
