"""MS5837 node through the command-exact emulator on the emulated I2C bus.

Expected values come from the emulator's truth (pressure, temperature) and hydrostatics with the
configured water density and gravity (docs/devices.md §3.6), within the device quantisation: one output LSB
of P (30BA: 0.1 mbar = 10 Pa, 02BA: 0.01 mbar = 1 Pa) and of TEMP (0.01 degC) (docs/devices.md §3.4, §3.8).
"""
import math
import time

import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PoseWithCovarianceStamped
from rclpy.parameter import Parameter
from sensor_msgs.msg import FluidPressure, Temperature
from std_srvs.srv import Trigger

from hindrax_drivers.ms5837.emulator import Ms5837Emulator
from hindrax_drivers.ms5837.node import Ms5837Node
from hindrax_common.testing import config_parameters, wait_until
from hindrax_common.transport.emulated_i2c import EmulatedI2CBus
from hindrax_msgs.msg import RawDeviceData

pytestmark = pytest.mark.ros

RHO_KG_M3 = 1000.0  # environment.water_density_kg_m3 in ros_ws/config/hindrax.yaml
G_M_S2 = 9.81  # environment.gravity_m_s2
SURFACE_PA = 101325.0  # environment.surface_pressure_pa
LSB_PA = {"30BA": 10.0, "02BA": 1.0}  # docs/devices.md §3.4: P in 0.1 mbar (30BA) / 0.01 mbar (02BA)
TEMP_LSB_C = 0.01


class Rig:
    """Emulator on the bus, node and probe subscriptions (the ``rig`` fixture, conftest.py, adds the executor)."""

    def __init__(self, ctx, truth, emu_variant="30BA", overrides=None, bus_fault_rate=0.0, clock=None,
                 sim_time=False, **emu_kwargs):
        kwargs = {"clock": clock} if clock is not None else {}
        self.emu = Ms5837Emulator(truth, variant=emu_variant, **kwargs, **emu_kwargs)
        self.bus = EmulatedI2CBus({0x76: self.emu}, fault_rate=bus_fault_rate, seed=7)
        params = config_parameters({"sensors.ms5837.rate_hz": 25.0, **(overrides or {})})
        if sim_time:
            params.append(Parameter("use_sim_time", value=True))
        self.start(ctx, Ms5837Node(bus=self.bus, context=ctx, parameter_overrides=params), "hindrax/ms5837")
        self.pressure = self.collect(FluidPressure, "pressure/fluid_pressure", 50)
        self.temperature = self.collect(Temperature, "pressure/temperature", 50)
        self.depth = self.collect(PoseWithCovarianceStamped, "pressure/depth", 50)
        self.raw = self.collect(RawDeviceData, "raw/ms5837", 500)
        self.zero = self.probe.create_client(Trigger, "pressure/zero_depth")
        self._esc = None  # the ESC's latched esc/output_state, made by esc_state()

    def esc_state(self, armed, output_state):
        """Publish the ESC's latched output state as the ESC node does (DiagnosticStatus, esc_state.py) and wait
        for the node to take it."""
        from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

        from hindrax_common.node_support.esc_state import ESC_STATE_TOPIC, esc_state_qos
        if self._esc is None:
            self._esc = self.probe.create_publisher(DiagnosticStatus, ESC_STATE_TOPIC, esc_state_qos())
        msg = DiagnosticStatus(values=[KeyValue(key="output_state", value=str(output_state)),
                                       KeyValue(key="armed", value="true" if armed else "false")])
        self.node.armed.seen = False
        self._esc.publish(msg)
        self.wait(lambda: self.node.armed.seen, 10, "ESC state delivered")

    def wait_messages(self, n, timeout=10.0):
        start = len(self.pressure)
        self.wait(lambda: len(self.pressure) >= start + n and len(self.depth) >= start + n
                  and len(self.temperature) >= start + n, timeout, f"{n} pressure messages")
        return self.pressure[start:], self.temperature[start:], self.depth[start:]


def expected_depth_m(pressure_pa, surface_pa=SURFACE_PA):
    return (pressure_pa - surface_pa) / (RHO_KG_M3 * G_M_S2)


@pytest.mark.parametrize("emu_variant,configured", [("30BA", "30BA"), ("30BA", "auto"), ("02BA", "auto"),
                                                    ("02BA", "02BA")])
def test_published_values_equal_truth_within_quantisation(rig, emu_variant, configured, monkeypatch):
    sleeps = []
    monkeypatch.setattr(time, "sleep", sleeps.append)  # the node must never block the executor
    # 30BA at 1.9 m of water and 4 degC, 02BA at 104 kPa and 8 degC: both in the second-order
    # low-temperature branch (docs/devices.md §3.5), where first order alone is off by 420 Pa / 87 Pa.
    truth_pa, truth_c = (120000.0, 4.0) if emu_variant == "30BA" else (104000.0, 8.0)
    r = rig(lambda t: (truth_pa, truth_c), emu_variant,
            {"sensors.ms5837.variant": configured, "sensors.ms5837.oversampling": 4096})
    pressures, temperatures, depths = r.wait_messages(5)
    lsb = LSB_PA[emu_variant]
    for fp, tm, dp in zip(pressures, temperatures, depths):
        assert fp.fluid_pressure == pytest.approx(truth_pa, abs=lsb)
        assert tm.temperature == pytest.approx(truth_c, abs=TEMP_LSB_C)
        assert -dp.pose.pose.position.z == pytest.approx(expected_depth_m(truth_pa), abs=lsb / (RHO_KG_M3 * G_M_S2))
        assert fp.header.frame_id == "pressure_link" and dp.header.frame_id == "odom"
        assert fp.header.stamp == tm.header.stamp == dp.header.stamp
        # variance: resolution^2 (25 Pa 30BA / 1 Pa 02BA, docs/devices.md §3.4) + LSB^2/12
        resolution = 25.0 if emu_variant == "30BA" else 1.0
        assert fp.variance == pytest.approx(resolution ** 2 + lsb ** 2 / 12)
        assert dp.pose.covariance[14] == pytest.approx(fp.variance / (RHO_KG_M3 * G_M_S2) ** 2)
        assert dp.pose.covariance[0] > 1e3  # x, y, orientation unknown
    assert r.node.variant.value == emu_variant
    assert r.emu.zero_reads == 0  # every ADC read came after the conversion time
    assert sleeps == []
    # The wire: D1 (0x48, OSR 4096), ADC read, D2 (0x58), ADC read, in that order (docs/devices.md §3.1).
    from hindrax_common.node_support.node_common import raw_transactions  # a cycle's transactions come in one message

    write, read = RawDeviceData.DIRECTION_HOST_TO_DEVICE, RawDeviceData.DIRECTION_DEVICE_TO_HOST

    def wire():
        return [(d, reg) for m in r.raw for d, _address, reg, _data in raw_transactions(m)]

    r.wait(lambda: wire().count((write, 0x58)) >= 2, 5, "two cycles' raw records (published every RAW_I2C_PERIOD_S)")
    seq = wire()
    j = seq.index((read, 0xA0))
    assert [(read, 0xA0 + 2 * k) for k in range(8)] == seq[j:j + 8]  # the 8 PROM words (after the reset)
    i = seq.index((write, 0x48))
    assert seq[i:i + 4] == [(write, 0x48), (read, 0x00), (write, 0x58), (read, 0x00)]


def test_bad_prom_crc_reports_error_and_retries(rig):
    r = rig(lambda t: (110000.0, 20.0), "30BA")
    r.emu.corrupt_prom_crc = True  # before the PROM read, which runs in a timer 10 ms after the reset
    r.wait(lambda: any(s.level == DiagnosticStatus.ERROR and "CRC" in s.message
                       for s in r.diag), 10, "CRC error in diagnostics")
    attempts = r.node.startup_attempts
    n = len(r.pressure)
    r.wait(lambda: r.node.startup_attempts >= attempts + 1, 5, "start-up retried")
    assert len(r.pressure) == n  # nothing published while the PROM is bad
    r.emu.corrupt_prom_crc = False
    r.wait(lambda: len(r.pressure) > n, 5, "pressure after the PROM reads correctly")
    assert r.pressure[-1].fluid_pressure == pytest.approx(110000.0, abs=10.0)


def test_i2c_errors_on_a_fifth_of_transactions_do_not_stop_the_data(rig):
    truth_pa, truth_c = 130000.0, 12.0
    r = rig(lambda t: (truth_pa, truth_c), "30BA")
    r.wait_messages(1)
    r.bus.set_fault_rate(0.2)  # errno 121 on 20 % of SMBus calls
    pressures, temperatures, _ = r.wait_messages(25, timeout=20.0)
    assert all(fp.fluid_pressure == pytest.approx(truth_pa, abs=10.0) for fp in pressures)
    assert all(tm.temperature == pytest.approx(truth_c, abs=TEMP_LSB_C) for tm in temperatures)
    assert r.bus.injected_faults > 0 and r.node.device.stats.retries > 0
    status = r.node.diag.status(r.node._diag_extra())
    values = {kv.key: kv.value for kv in status.values}
    assert int(values["i2c_errors"]) == r.node.device.stats.errors > 0


def test_stuck_sensor_is_an_error_and_is_not_published(rig):
    # a live signal: 2 kPa sine on the pressure, so consecutive raw readings differ
    r = rig(lambda t: (110000.0 + 2000.0 * math.sin(3.0 * t), 20.0 + math.sin(t)), "30BA",
            {"sensors.ms5837.rate_hz": 50.0, "sensors.ms5837.oversampling": 1024})
    r.wait_messages(20)
    assert not r.node.is_stuck
    r.emu.stuck = True
    r.wait(lambda: r.node.is_stuck, 10, "stuck detected")
    detected_ns = r.node.get_clock().now().nanoseconds  # at or after the detection
    status = r.node.diag.status()
    assert status.level == DiagnosticStatus.ERROR and "stuck" in status.message
    r.wait(lambda: any(s.level == DiagnosticStatus.ERROR and "stuck" in s.message
                       for s in r.diag), 5, "stuck ERROR published")
    cycles = r.node.cycles
    r.wait(lambda: r.node.cycles >= cycles + 10, 10, "ten more stuck cycles")
    stamps = [m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec for m in r.pressure]
    assert max(stamps) < detected_ns  # nothing published while stuck
    r.emu.stuck = False
    r.wait(lambda: not r.node.is_stuck, 5, "stuck cleared")
    r.wait_messages(3)
    assert "stuck" not in r.node.diag.status().message


# ------------------------------------------------------------------------------ plausibility gates (fault 9)
DATASHEET_30BA = (34982, 36352, 20328, 22354, 26646, 26146)  # TE MS5837-30BA datasheet example C1..C6
DATASHEET_02BA = (46372, 43981, 29059, 27842, 31553, 28165)  # TE MS5837-02BA datasheet example C1..C6
OPEN_GATES = {"sensors.ms5837.min_pressure_pa": 0.0, "sensors.ms5837.max_pressure_pa": 3.1e6}


def test_saturated_adc_is_rejected_not_published_as_82_bar(rig):
    r = rig(lambda t: (110000.0, 20.0), "30BA", {"sensors.ms5837.variant": "30BA", **OPEN_GATES})
    r.wait_messages(2)
    r.emu.raw_override = (0xFFFFFF, 6815414)  # D1 saturated (bus held high / broken bridge), D2 the example's
    r.wait(lambda: r.node.diag.counts().get("adc_saturated", 0) >= 3, 10, "saturated reads counted")
    n = len(r.pressure)
    r.wait(lambda: r.node.diag.counts().get("adc_saturated", 0) >= 6, 10, "more saturated reads")
    assert len(r.pressure) <= n + 1 and all(m.fluid_pressure < 2e5 for m in r.pressure)  # never 82.8 bar
    r.emu.raw_override = None
    r.wait(lambda: len(r.pressure) > n + 1 and r.pressure[-1].fluid_pressure == pytest.approx(110000.0, abs=10.0),
           10, "valid readings again")


def test_pressure_outside_the_configured_range_is_not_published_and_raises_error(rig):
    truth = {"pa": 110000.0}
    # +-60 Pa of motion: a constant truth would also trip the stuck detector (2 s of identical D1/D2), whose
    # ERROR can outlast the implausible-pressure hold under load and hide the clearing this test waits for.
    r = rig(lambda t: (truth["pa"] + 60.0 * math.sin(9.0 * t), 20.0), "30BA")  # gates: 50 kPa .. 400 kPa
    r.wait_messages(2)
    truth["pa"] = 600000.0
    r.wait(lambda: r.node.diag.counts().get("implausible_pressure", 0) >= 3, 10, "implausible readings counted")
    r.wait(lambda: any(s.level == DiagnosticStatus.ERROR and "implausible" in s.message
                       for s in r.diag), 5, "ERROR published")
    assert all(m.fluid_pressure <= 400000.0 for m in r.pressure)
    truth["pa"] = 110000.0
    r.wait_messages(3)
    r.wait(lambda: r.node.diag.status().level == DiagnosticStatus.OK, 10, "ERROR cleared after the hold time")


def test_all_zero_prom_passes_crc4_but_is_rejected(rig):
    r = rig(lambda t: (110000.0, 20.0), "30BA", {"sensors.ms5837.variant": "30BA"})
    r.emu.blank_prom = True  # before the PROM read (a timer 10 ms after the reset command)
    r.wait(lambda: any(s.level == DiagnosticStatus.ERROR and "PROM" in s.message
                       for s in r.diag), 10, "PROM error")
    attempts = r.node.startup_attempts
    r.wait(lambda: r.node.startup_attempts >= attempts + 1, 5, "start-up retried")
    assert r.pressure == [] and r.node.calibration is None
    r.emu.blank_prom = False
    r.wait_messages(2)
    assert r.pressure[-1].fluid_pressure == pytest.approx(110000.0, abs=10.0)


def test_prom_blank_word_rule_is_configurable(rig):
    """sensors.ms5837.prom_reject_blank_words = false: the all-zero PROM (valid CRC-4) is accepted as it stands;
    the pressure it gives (0 Pa: every coefficient 0) is then caught by the range gate instead."""
    r = rig(lambda t: (110000.0, 20.0), "30BA",
            {"sensors.ms5837.variant": "30BA", "sensors.ms5837.prom_reject_blank_words": False})
    r.emu.blank_prom = True  # before the PROM read (a timer 10 ms after the reset command)
    r.wait(lambda: r.node.calibration is not None, 10, "PROM accepted")
    assert tuple(r.node.calibration.words) == (0,) * 8
    r.wait(lambda: r.node.diag.counts().get("implausible_pressure", 0) >= 2, 10, "0 Pa rejected by the range gate")
    assert r.node.diag.counts().get("prom_error", 0) == 0 and r.node.startup_attempts == 1
    assert r.pressure == []


def test_reset_and_prom_read_are_sent_again_after_an_i2c_outage(rig):
    """The part loses power during an I2C outage; without a new reset command its conversions read 0
    (datasheet "Reset sequence": the PROM is loaded by the reset). The node re-runs its start-up."""
    r = rig(lambda t: (110000.0, 20.0), "30BA")
    r.wait_messages(2)
    resets = r.emu.resets
    r.bus.disconnected = True
    r.emu.power_cycle()
    r.wait(lambda: r.node.diag.status().level == DiagnosticStatus.ERROR, 10, "outage reported")
    r.bus.disconnected = False
    r.wait(lambda: r.emu.resets > resets, 10, "reset command sent again")
    r.wait_messages(3)
    assert r.pressure[-1].fluid_pressure == pytest.approx(110000.0, abs=10.0)


# ------------------------------------------------------------------------------ independent oracle (test 14)
def datasheet_30ba(coefficients, d1, d2):
    """Pressure (Pa) and temperature (degC) by the TE MS5837-30BA datasheet flow charts ("Pressure and
    temperature calculation", "Second order temperature compensation"), written out here independently of
    hindrax_drivers.ms5837.protocol, with floor division (docs/devices.md §3.4, §3.5, §3.7)."""
    c1, c2, c3, c4, c5, c6 = coefficients
    dt = d2 - c5 * 256
    temp = 2000 + dt * c6 // 2 ** 23
    off = c2 * 2 ** 16 + c4 * dt // 2 ** 7
    sens = c1 * 2 ** 15 + c3 * dt // 2 ** 8
    if temp < 2000:
        ti, offi, sensi = 3 * dt * dt // 2 ** 33, 3 * (temp - 2000) ** 2 // 2, 5 * (temp - 2000) ** 2 // 8
        if temp < -1500:
            offi, sensi = offi + 7 * (temp + 1500) ** 2, sensi + 4 * (temp + 1500) ** 2
    else:
        ti, offi, sensi = 2 * dt * dt // 2 ** 37, (temp - 2000) ** 2 // 16, 0
    p = (d1 * (sens - sensi) // 2 ** 21 - (off - offi)) // 2 ** 13
    return p * 10.0, (temp - ti) / 100.0, temp


def test_datasheet_oracle_reproduces_the_datasheet_example():
    # the oracle itself is pinned to the datasheet's printed result: P = 39998 (3999.8 mbar), TEMP = 1981
    assert datasheet_30ba(DATASHEET_30BA, 4958179, 6815414)[:2] == (399980.0, 19.81)


@pytest.mark.parametrize("variant,coefficients,d1,d2,pressure_pa,temperature_c", [
    ("30BA", DATASHEET_30BA, 4958179, 6815414, 399980.0, 19.81),  # datasheet: P = 3999.8 mbar, 19.81 degC
    ("02BA", DATASHEET_02BA, 6465444, 8077636, 110002.0, 20.00),  # datasheet: P = 1100.02 mbar, 20.00 degC
])
def test_node_publishes_the_datasheet_example_from_raw_adc_counts(rig, variant, coefficients, d1, d2, pressure_pa,
                                                                  temperature_c):
    r = rig(lambda t: (110000.0, 20.0), variant, {"sensors.ms5837.variant": variant, **OPEN_GATES},
            coefficients=coefficients)
    r.emu.raw_override = (d1, d2)
    r.wait(lambda: len(r.pressure) >= 2 and r.pressure[-1].fluid_pressure == pressure_pa, 10, "datasheet reading")
    assert r.temperature[-1].temperature == pytest.approx(temperature_c, abs=1e-9)


@pytest.mark.parametrize("target_c", [-10.0, -14.99, -15.01, -20.0])
def test_second_order_low_temperature_branches_around_minus_15_degc(rig, target_c):
    """30BA below 20 degC (low branch) and below -15 degC (very-low branch, TEMP < -1500): raw counts fed
    straight into the node, result compared with the datasheet formulas of :func:`datasheet_30ba`."""
    c6, c5 = DATASHEET_30BA[5], DATASHEET_30BA[4]
    d2 = c5 * 256 + round((target_c * 100 - 2000) * 2 ** 23 / c6)  # first-order TEMP ~ target (inverted)
    d1 = 4958179
    expected_pa, expected_c, temp = datasheet_30ba(DATASHEET_30BA, d1, d2)
    assert (temp < -1500) == (target_c < -15.0)  # each side of the branch boundary
    r = rig(lambda t: (110000.0, 20.0), "30BA", {"sensors.ms5837.variant": "30BA", **OPEN_GATES})
    r.emu.raw_override = (d1, d2)
    r.wait(lambda: len(r.pressure) >= 2 and r.temperature[-1].temperature == pytest.approx(expected_c, abs=1e-9),
           10, "low-temperature reading")
    assert r.pressure[-1].fluid_pressure == expected_pa


def test_zero_depth_service_sets_surface_pressure(rig):
    truth_pa = 102500.0  # at the surface on a high-pressure day
    r = rig(lambda t: (truth_pa, 18.0), "30BA")
    _, _, depths = r.wait_messages(3)
    assert -depths[-1].pose.pose.position.z == pytest.approx(expected_depth_m(truth_pa), abs=10.0 / 9810.0)
    r.wait(lambda: r.zero.service_is_ready(), 5, "zero_depth service")
    r.esc_state(False, 1)  # the ESC reports disarmed at neutral
    fut = r.zero.call_async(Trigger.Request())
    r.wait(fut.done, 5, "zero_depth answer")
    assert fut.result().success
    assert r.node.surface_pressure_pa == pytest.approx(truth_pa, abs=10.0)
    assert r.node.get_parameter("environment.surface_pressure_pa").value == r.node.surface_pressure_pa
    _, _, depths = r.wait_messages(3)
    assert all(abs(d.pose.pose.position.z) <= 10.0 / 9810.0 for d in depths)


def test_zero_depth_is_refused_at_depth_and_while_armed(rig):
    """A zero taken at 1.5 m (14715 Pa above the 101325 Pa reference, hand arithmetic 1.5 * 1000 * 9.81) would move
    every depth 1.5 m: refused beyond sensors.ms5837.zero_depth_margin_pa (5000 Pa). At the surface, refused before
    the ESC has reported its state, while it reports armed, and while its state is unknown after armed (it may still
    be thrusting); accepted once it reports disarmed at neutral (esc/output_state, latched)."""
    truth = {"pa": SURFACE_PA + 1.5 * RHO_KG_M3 * G_M_S2}
    r = rig(lambda t: (truth["pa"], 18.0), "30BA")
    r.wait_messages(3)
    r.wait(lambda: r.zero.service_is_ready(), 5, "zero_depth service")

    def zero():
        fut = r.zero.call_async(Trigger.Request())
        r.wait(fut.done, 5, "zero_depth answer")
        return fut.result()

    res = zero()
    assert not res.success and "no ESC output state" in res.message, res.message
    r.esc_state(False, 1)
    res = zero()
    assert not res.success and "+14715" in res.message and "zero_depth_margin_pa 5000" in res.message, res.message
    assert r.node.surface_pressure_pa == SURFACE_PA
    truth["pa"] = SURFACE_PA + 400.0  # at the surface, 4 cm of weather off the reference
    r.wait(lambda: r.pressure and abs(r.pressure[-1].fluid_pressure - truth["pa"]) <= 10.0, 10, "new pressure")
    r.wait_messages(int(25 * 1.2))  # a whole zero_depth window (1 s at 25 Hz) of surface readings
    for armed, state in ((True, 1), (False, 0)):  # armed; then unknown (the ESC says armed=false) after armed
        r.esc_state(armed, state)
        res = zero()
        assert not res.success and "armed" in res.message and r.node.surface_pressure_pa == SURFACE_PA, res.message
    r.esc_state(False, 1)
    assert "esc_state_malformed" not in r.node.diag.counts()
    res = zero()
    assert res.success, res.message
    assert r.node.surface_pressure_pa == pytest.approx(SURFACE_PA + 400.0, abs=10.0)
    r._esc.publish(DiagnosticStatus())  # malformed: counted, read as unknown (disarmed stays disarmed)
    r.wait(lambda: r.node.diag.counts().get("esc_state_malformed") == 1, 10, "malformed state counted")
    assert not r.node.armed.armed


def test_surface_pressure_parameter_is_read_only_while_armed(rig):
    """``ros2 param set environment.surface_pressure_pa`` goes through zero_depth's checks: while armed a
    101325 -> 118983 Pa change (1.8 m of water, 17658 Pa = 1.8 * 1000 * 9.81) would publish 3.00 m as 1.20 m and
    blind the depth limit. Refused before the ESC reported, while armed and while unknown after armed, with the reason;
    disarmed, refused too (issue 71.7: it carried into the next arm) beyond zero_depth_margin_pa (5000 Pa) of the
    mean reading; a change within it is applied."""
    r = rig(lambda t: (SURFACE_PA, 18.0), "30BA")
    change = [Parameter("environment.surface_pressure_pa", value=118983.0)]
    res = r.node.set_parameters(change)[0]
    assert not res.successful and "no ESC output state" in res.reason, res.reason
    for armed, state in ((True, 2), (False, 0)):  # armed; then unknown after armed
        r.esc_state(armed, state)
        res = r.node.set_parameters(change)[0]
        assert not res.successful and "environment.surface_pressure_pa" in res.reason and "armed" in res.reason
        assert r.node.surface_pressure_pa == SURFACE_PA
        assert r.node.get_parameter("environment.surface_pressure_pa").value == SURFACE_PA
    r.esc_state(False, 1)
    r.wait_messages(int(25 * 1.2))  # a whole zero_depth window of surface readings
    res = r.node.set_parameters(change)[0]
    assert not res.successful and "Pa (+1.80 m of water) from the mean reading 1013" in res.reason \
        and "zero_depth_margin_pa 5000" in res.reason, res.reason
    assert r.node.surface_pressure_pa == SURFACE_PA
    assert r.node.get_parameter("environment.surface_pressure_pa").value == SURFACE_PA
    assert r.node.set_parameters([Parameter("environment.surface_pressure_pa", value=101725.0)])[0].successful
    assert r.node.surface_pressure_pa == 101725.0


def test_a_surface_pressure_set_at_depth_is_refused(rig):
    """Issue 71.7: disarmed at a true 3.00 m (29430 Pa = 3 * 1000 * 9.81 above 101325), a surface pressure of
    116040 Pa (1.50 m of water above it) would publish 1.50 m and carry into the next arm: refused as zero_depth is."""
    r = rig(lambda t: (SURFACE_PA + 29430.0, 18.0), "30BA")
    r.esc_state(False, 1)
    r.wait_messages(int(25 * 1.2))
    res = r.node.set_parameters([Parameter("environment.surface_pressure_pa", value=116040.0)])[0]
    assert not res.successful and "not at the surface" in res.reason, res.reason
    _, _, depths = r.wait_messages(3)
    assert -depths[-1].pose.pose.position.z == pytest.approx(3.0, abs=0.01)


def test_zero_depth_before_any_reading_is_refused(rig):
    r = rig(lambda t: (101000.0, 18.0), "30BA")
    r.bus.disconnected = True  # no reading can arrive
    r.wait(lambda: r.zero.service_is_ready(), 5, "zero_depth service")
    fut = r.zero.call_async(Trigger.Request())
    r.wait(fut.done, 5, "zero_depth answer")
    assert not fut.result().success and "no pressure reading" in fut.result().message
    assert r.node.surface_pressure_pa == SURFACE_PA
    assert r.node.diag.status().level == DiagnosticStatus.ERROR  # bus down reported, node alive


def _node_clock(holder, sim):
    """A clock for the emulator: the ROS time of ``holder["node"]`` (the /clock it has received), s; before the
    node exists, ``sim["t"]``."""
    def now_s():
        node = holder.get("node")
        return node.get_clock().now().nanoseconds * 1e-9 if node is not None else sim["t"]
    return now_s


def test_use_sim_time_stamps_and_timers_follow_the_clock(rig):
    sim, holder = {"t": 1000.0}, {}
    # the emulator reads the node's own ROS clock: with a separate simulator variable, /clock messages delivered
    # late under load made the node's clock lag by a varying amount, and a wait that began at a large lag and
    # ended at a small one read early in the emulator's time (seen once in a loaded fresh clone)
    r = rig(lambda t: (115000.0, 14.0), "30BA", clock=_node_clock(holder, sim), sim_time=True)
    holder["node"] = r.node
    tick = r.clock_ticker(sim)
    wait_until(lambda: len(r.pressure) >= 1, 20, tick, "pressure under sim time")
    # counted from the first reading on: a cycle started before the node's first /clock (its time still 0) may read
    # early once, a start-up race of the test's clock, not a wait measured in wall time
    zero_reads = r.emu.zero_reads
    wait_until(lambda: len(r.pressure) >= 4, 20, tick, "pressure under sim time")
    stamp_s = r.pressure[-1].header.stamp.sec + r.pressure[-1].header.stamp.nanosec * 1e-9
    assert 1000.0 < stamp_s <= sim["t"] + 1e-6
    assert r.pressure[-1].fluid_pressure == pytest.approx(115000.0, abs=10.0)
    assert r.emu.zero_reads == zero_reads  # conversion waits were measured in simulated time


def test_stamp_is_the_time_of_validity_of_the_pressure(rig):
    """The stamp is the D1 command time plus half the conversion time (4.5 ms at OSR 4096), not the read time:
    with a pressure ramp of 1e5 Pa/s sampled by the emulator when D1 is commanded, the published pressure
    dates the sample to stamp - 4.5 ms within the 10 Pa output step (0.1 ms of ramp). The emulator reads the
    node's own ROS clock (the /clock the node has received), so how late /clock messages arrive under load
    changes nothing (a separate simulator variable did: a 2.5 ms tolerance a loaded CI could miss)."""
    sim = {"t": 1000.0}
    ramp_pa_s = 1.0e5
    holder = {}
    r = rig(lambda t: (101000.0 + ramp_pa_s * (t - 1000.0), 14.0), "30BA", clock=_node_clock(holder, sim),
            sim_time=True,
            overrides={"sensors.ms5837.min_pressure_pa": 0.0, "sensors.ms5837.max_pressure_pa": 3.1e6,
                       # the synthetic ramp is 10 m/s of depth: beyond the vehicle's physics the gate holds to
                       "sensors.ms5837.max_depth_rate_m_s": 20.0, "sensors.ms5837.max_depth_m": 300.0})
    holder["node"] = r.node
    tick = r.clock_ticker(sim)
    wait_until(lambda: len(r.pressure) >= 4, 20, tick, "pressure under sim time")
    for m in r.pressure[1:]:
        stamp_s = m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
        sampled_s = 1000.0 + (m.fluid_pressure - 101000.0) / ramp_pa_s
        assert stamp_s - sampled_s == pytest.approx(0.5 * 0.009, abs=0.0002)


def test_runs_as_a_process_and_reports_a_missing_bus(runs_without_its_bus):
    """``python -m hindrax_drivers.ms5837.node --ros-args --params-file hindrax.yaml`` on a machine without the
    configured /dev/i2c-N: the node stays up, reports the bus in /diagnostics, and exits 0 on SIGINT."""
    runs_without_its_bus("ms5837")
