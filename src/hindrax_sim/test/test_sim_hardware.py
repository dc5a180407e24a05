"""Virtual hardware: emulators fed by the simulator, through the real transports."""
import threading

import numpy as np
import pytest

from hindrax_common.config import default_config_path, load_config
from hindrax_drivers.dvl75 import protocol as dvl
from hindrax_drivers.pca9685 import protocol as pca
from hindrax_drivers.dvl75.emulator import Dvl75Emulator, DvlTruth
from hindrax_common.transport.i2c import I2CDevice
from hindrax_common.transport.pty_device import PtyDevice
from hindrax_common.transport.serial_transport import SerialTransport
from hindrax_sim.hardware import SerialHandoffError, SerialLockStep, VirtualHardware
from hindrax_sim.simulator import Simulator


@pytest.fixture
def hw():
    sim = Simulator(load_config(default_config_path()), seed=3)
    cfg = sim.config  # the truth (vehicle file + default truth): what the emulators read
    vh = VirtualHardware(sim, cfg)
    yield sim, vh, cfg
    vh.close()


def test_pca9685_registers_drive_the_simulated_thrusters(hw):
    sim, vh, cfg = hw
    assert np.all(vh.pulse_widths_us() == 0.0)  # power-up: full OFF, no pulses, no thrust
    dev = I2CDevice(vh.i2c_bus, cfg.esc.i2c_address, "pca9685")
    prescale = pca.esc_prescale(cfg.esc.pwm_frequency_hz, cfg.esc.oscillator_hz)
    dev.write_sequence(pca.startup_sequence(prescale))
    widths = [1700.0, 1700.0, 1500.0, 1500.0, 1500.0, 1500.0, 1500.0, 1500.0]  # T1+T2: pure surge
    for ch, w in enumerate(widths):
        dev.write_block(pca.led_register(ch), pca.channel_bytes_for_pulse(w, prescale, cfg.esc.oscillator_hz))
    wire = vh.pulse_widths_us()
    assert np.allclose(wire, widths, atol=1.3)
    sim.reset(position_ned_m=[5.0, 3.0, 0.9])
    sim.advance(1.0, wire)
    assert sim.nu[0] > 0.05  # surging forward
    assert abs(sim.nu[5]) < 0.02  # T1+T2 with the symmetric layout: no yaw


def test_dvl_emulator_on_a_pty_reports_the_simulated_velocity(hw, dvl_reports):
    sim, vh, cfg = hw
    sim.reset(position_ned_m=[5.0, 3.0, 0.9], nu=[0.3, 0.0, 0.0, 0.0, 0.0, 0.0])
    records = dvl_reports(sim, vh, lambda rs: any(isinstance(r, dvl.DvlPositionDelta) for r in rs), "$DVPDL report",
                          b"SEND-DVPDL ON\n")
    deltas = [r for r in records if isinstance(r, dvl.DvlPositionDelta)]
    v = deltas[-1].velocity_frd_m_s()
    assert v is not None and abs(v[0] - sim.nu[0]) < 0.1  # 5 % scale noise + 0.01 m/s, plus decay


def test_i2c_emulators_measure_the_vehicle_when_sampled_not_the_last_grid_sample(hw):
    """The MS5837 and ICM-20948 emulators sample the vehicle at that moment: while sinking at 0.3 m/s the pressure
    they are given follows the current depth, not the 10 Hz sensor-model sample (up to 100 ms, 3 cm, old)."""
    sim, vh, cfg = hw
    sim.reset(position_ned_m=[5.0, 3.0, 0.5], nu=[0.0, 0.0, 0.3, 0.0, 0.0, 0.0])
    rho_g = cfg.environment.water_density_kg_m3 * cfg.environment.gravity_m_s2
    port_z = cfg.sensors.ms5837.position_frd_m[2]
    errors, stale = [], []
    for _ in range(12):
        sim.advance(0.035)  # off the 10 Hz grid of the pressure model
        # what a conversion samples
        pressure_pa = float(np.mean([vh.emulators["ms5837"].truth(0.0)[0] for _ in range(20)]))
        port_depth = (pressure_pa - cfg.environment.surface_pressure_pa) / rho_g
        errors.append(port_depth - port_z - sim.position_ned_m[2])
        stale.append(sim.t_s - sim.sensors.latest["ms5837"].stamp_s)
    assert max(stale) > 0.05  # the grid sample was old at several of these reads
    noise_m = cfg.simulation.sensors.ms5837.noise_std_pa / rho_g / np.sqrt(20)
    assert np.max(np.abs(errors)) < 0.002 + 4 * noise_m  # the depth now (a 50 ms old sample is 15 mm off)
    spec_gyro = vh.emulators["icm20948"].truth(0.0)[1]
    assert np.allclose(spec_gyro, sim.measure("icm20948_gyro").angular_rate_rad_s, atol=0.05)


def test_serial_lock_step_has_a_slow_driver_handle_every_byte_before_the_tick_ends():
    """A driver hop of 0.7 s (a starved machine): when ``tick`` returns, the driver has handled every
    byte sent at that tick, in the simulator's thread, so what it publishes is there before the other
    nodes run at the tick and before simulated time moves on (the recorded data does not depend on the
    load)."""
    t = [0.0]
    pty = PtyDevice(Dvl75Emulator(DvlTruth(velocity_frd_m_s=(0.2, 0.0, 0.0), altitude_m=1.5),
                                  rate_hz=10),
                    clock=lambda: t[0], start=False)
    threads, never = [], threading.Event()

    def slow_driver(_data: bytes) -> None:
        threads.append(threading.current_thread())
        if len(threads) == 1:
            # the first message's handling outlasts the hand-off timeout
            never.wait(0.7)

    transport = SerialTransport(pty.path, on_data=slow_driver)
    try:
        assert transport.wait_connected(5.0)
        link = SerialLockStep(pty, transport)
        for t[0] in (0.0, 0.1, 0.2):
            link.tick()
            assert transport.status().bytes_handled == pty.bytes_to_host
            assert link.settled()
        assert pty.bytes_to_host > 0 and set(threads) == {threading.current_thread()}
    finally:
        transport.close()
        pty.close()


def _fake_link(pump):
    """A :class:`SerialLockStep` over stand-ins: a pty whose emulator sends 40 bytes at every tick, a transport
    connected once whose ``pump(n, timeout_s)`` is ``pump``; returns (link, transport status)."""
    from types import SimpleNamespace

    st = SimpleNamespace(connected=True, connections=1, bytes_rx=0, bytes_handled=0)
    pty = SimpleNamespace(bytes_to_host=0, bytes_from_host=0)

    def service(deliver: bool = True) -> bool:
        pty.bytes_to_host += 40
        return True

    pty.service = service
    transport = SimpleNamespace(status=lambda: st, connected=True, pump=pump, port="/dev/pts/fake")
    return SerialLockStep(pty, transport), st


def test_a_serial_tick_waits_for_bytes_the_kernel_hands_over_late():
    """Issue 72.4: a pty's bytes reach the driver through a kernel worker, on a loaded machine 2 s late (here
    ``pump`` gets them only when it may wait that long without a byte): the tick still returns with every byte
    handled, so the driver's message goes out at this tick, not at the next one. Before, it gave up after 0.5 s
    and the message went out a tick later (the run then depended on the load); a connection that stays silent for
    HANDOFF_TIMEOUT_S ends the run with the reason, one that went meanwhile does not."""
    handled = []
    link, st = _fake_link(lambda n, timeout_s: timeout_s >= 2.0 and not handled.append(n))
    link.tick()
    assert handled == [40]
    link, st = _fake_link(lambda _n, _t: False)
    with pytest.raises(SerialHandoffError, match="fake: bytes sent at a clock tick not received"):
        link.tick()

    def lost(_n, _t) -> bool:
        st.connections += 1  # the port reopened while waiting: its bytes went with the old connection
        return False

    link, st = _fake_link(lost)
    link.tick()
    assert link.settled()


def test_a_serial_gate_holds_time_in_a_process_the_machine_did_not_schedule(monkeypatch):
    """The gate opens only when the driver has handled every byte sent at the tick or its connection changed: a
    process a loaded machine leaves unscheduled between two checks (here the steady clock jumps 5 s per reading),
    or a kernel that hands the bytes over seconds late, still holds simulated time, however often it asks. Re-based
    after a second of its own waits (500 checks), it let time run on with the DVL's message unhandled, so the
    message's tick (and the run) depended on the load."""
    import itertools
    import time

    clock = itertools.count(0.0, 5.0)
    monkeypatch.setattr(time, "monotonic", lambda: float(next(clock)))
    arrived = [True]
    link, st = _fake_link(lambda _n, _t: arrived[0])
    link.tick()
    arrived[0] = False
    link.pty.service()  # 40 more bytes sent, still in the kernel's pty buffer (not received, not handled)
    assert not any(link.settled() for _ in range(1000))  # 1000 checks, 5000 s of wall time: the gate still holds
    arrived[0] = True
    assert link.settled()
    arrived[0] = False
    link.pty.service()
    st.connections += 1  # reopened: those bytes went with the old connection
    assert link.settled()


def test_a_dvl_attitude_dropout_repeats_the_newest_report_with_the_grid_stopped(hw, monkeypatch):
    sim, vh, _ = hw
    sim.reset(position_ned_m=[5.0, 3.0, 0.9], rpy_rad=[0.0, 0.0, 1.0])
    sim.sensors.stop_grid()  # as the live pool: every device samples on demand only
    sim.advance(0.05, None)
    heard = vh._dvl75_truth(0.0)
    assert heard.yaw_rad == pytest.approx(1.0, abs=0.1)
    measure = sim.measure
    monkeypatch.setattr(sim, "measure", lambda d, dropout=False: None if d == "dvl75_attitude" else measure(d, dropout))
    assert vh._dvl75_truth(0.0).yaw_rad == heard.yaw_rad  # the newest report, not the startup grid's or 0
