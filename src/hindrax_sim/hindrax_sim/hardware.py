"""Virtual hardware: the device emulators driven by the simulator (docs/architecture.md §6).

In simulation the real driver code reads real bytes and registers: the DVL-75 and Ping1D emulators are served
on pseudo-terminals (:class:`~hindrax_common.transport.pty_device.PtyDevice`, so the drivers' pyserial path
runs), and the MS5837, ICM-20948 (+ AK09916) and PCA9685 emulators sit on one
:class:`~hindrax_common.transport.emulated_i2c.EmulatedI2CBus` that the I2C drivers use in place of
``smbus2.SMBus``. Each emulator's truth source is a *measured* sensor sample of the vehicle at the moment the
emulated device samples (an MS5837 conversion start, an ICM-20948 data-rate tick, a DVL ping, through
:meth:`~hindrax_sim.simulator.Simulator.measure`: noise, bias and the DVL's dropouts from
:mod:`hindrax_sim.sensors`; the Ping1D uses the newest rate-grid sample); emulator clocks are the
simulated time as published on ``/clock`` (quantised to ``simulation.clock_rate_hz``).

The simulator takes the thrusters' pulse widths from the PCA9685 emulator's registers
(:meth:`VirtualHardware.pulse_widths_us`), so the whole path wrench -> allocation -> ESC node -> PCA9685
registers -> thrust -> vehicle motion runs. A sleeping or full-OFF channel gives 0 us, i.e. no pulses and no
thrust (docs/devices.md §5.2)."""
from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np

from hindrax_common.base import devices as device_table
from hindrax_common.config import VehicleConfig
from hindrax_drivers.dvl75.emulator import DvlTruth
from hindrax_drivers.ping1d.emulator import Ping1dTruth
from hindrax_common.transport.emulated_i2c import EmulatedI2CBus
from hindrax_common.transport.pty_device import PtyDevice

from .simulator import Simulator


def truth_keywords(config: VehicleConfig, device: device_table.Device) -> dict[str, float]:
    """Keywords of ``device``'s emulator factory that only the truth knows: each of its ``truth_keywords`` from
    ``simulation.sensors.<device>`` (the simulated DVL's ping rate, Hz, and bottom-lock range, m)."""
    section = getattr(config.simulation.sensors, device.name, None)
    return {k: getattr(section, k) for k in device.truth_keywords}


#: Wall time a clock tick waits without a byte for its driver to receive what it was just sent before it gives up
#: with :class:`SerialHandoffError`, s: the pty's bytes are in the kernel, late only as long as the machine is busy.
HANDOFF_TIMEOUT_S = 60.0


class SerialHandoffError(RuntimeError):
    """A driver did not receive the bytes sent at a clock tick within :data:`HANDOFF_TIMEOUT_S` of wall time, its
    connection up: the run stops rather than go on with those bytes handled at a later simulated instant."""


class SerialLockStep:
    """Serve one serial device emulator at the simulator's clock ticks and hold simulated time until its driver has
    handled every byte sent: the serial counterpart of the I2C emulators, which answer inside the driver's call.

    :meth:`tick` is a clock listener of the :class:`~hindrax_sim.node.SimulatorNode` and
    :meth:`settled` a step gate: the driver stamps every message at the tick it was sent.

    Bytes due while the driver's port is closed are dropped (a UART nobody listens to; pyserial flushes the input
    on open anyway). Counting restarts at every (re)connection of the transport; bytes sent to a connection that
    has gone are never handled, so the gate opens when the connection changes, and only then: no wall-time limit
    decides when simulated time moves on (a pty hands its bytes over through a kernel worker, which a loaded
    machine may run a second late; going on without them would publish the driver's message at a later tick).

    Args:
        pty: the emulator's pseudo-terminal, created with ``start=False``.
        transport: the driver's :class:`~hindrax_common.transport.serial_transport.SerialTransport`.
        wait_s: wall time :meth:`settled` reads for before it answers False, s.
        ready: extra start-up condition for :meth:`startup_done` (the driver's start-up commands are sent)."""

    def __init__(self, pty: PtyDevice, transport: Any, wait_s: float = 0.002,
                 ready: Callable[[], bool] = lambda: True) -> None:
        self.pty, self.transport, self.wait_s, self.ready = pty, transport, float(wait_s), ready
        self._connection: int | None = None
        self._written0 = self._handled0 = 0
        transport.pump(0, 0.0)  # from now on the driver's bytes are read in the simulator's thread

    def tick(self, _t_s: float = 0.0) -> None:
        """Send what the emulator has due now (its clock: the drivers' clock), if the driver's port is open, and
        read it until the driver has handled it (or the connection went): its messages are then published before
        any other node runs at this tick, whatever the load. Raises :class:`SerialHandoffError` when no byte came
        for :data:`HANDOFF_TIMEOUT_S` of wall time."""
        st = self.transport.status()
        if not st.connected:
            self.pty.service(deliver=False)
            return
        if st.connections != self._connection:
            self._connection = st.connections
            self._written0, self._handled0 = self.pty.bytes_to_host, st.bytes_handled
        if self.pty.service():
            due = self._handled0 + self.pty.bytes_to_host - self._written0
            if not self.transport.pump(due, HANDOFF_TIMEOUT_S) and self._same_connection():
                raise SerialHandoffError(f"{getattr(self.transport, 'port', 'serial port')}: bytes sent at a clock "
                                         f"tick not received in {HANDOFF_TIMEOUT_S:g} s of wall time")

    def _same_connection(self) -> bool:
        """The connection the bytes were counted on is still up."""
        st = self.transport.status()
        return st.connected and st.connections == self._connection

    def startup_done(self) -> bool:
        """With simulated time frozen (call repeatedly, it serves the device at the frozen instant): True when the
        driver's port is open, ``ready()`` holds (e.g. its start-up commands are sent), the emulator has taken
        every byte the driver wrote and the driver has handled every reply."""
        self.tick()
        st = self.transport.status()
        return (st.connected and self._connection == st.connections and self.ready()
                and self.pty.bytes_from_host == st.bytes_tx and self.settled())

    def settled(self, _t_s: float = 0.0) -> bool:
        """Step gate: True when the driver has handled every byte sent on this connection, or the connection is no
        longer the one they were sent on (closed, or reopened: :meth:`tick` re-bases the count)."""
        if self._connection is None or not self._same_connection():
            return True
        return self.transport.pump(self._handled0 + self.pty.bytes_to_host - self._written0, self.wait_s)


class VirtualHardware:
    """Emulators of every device of :data:`~hindrax_common.base.devices.DEVICES`, fed by ``sim`` (module docstring);
    a device's truth adapter is the method ``_<name>_truth`` (an output has none).

    Attributes: ``emulators`` (device name -> emulator), ``i2c_bus`` (EmulatedI2CBus with the I2C devices at their
    configured addresses), ``ports`` (serial device name -> pty path). Call :meth:`close` to stop the pty threads.
    ``serve_serial=False`` skips the ptys (for tests that only need the I2C side). The ptys are served by their own
    threads, or, with ``serial_threads=False``, in lock-step with a simulator node once :meth:`lock_step_serial`
    is called (what :func:`~hindrax_sim.graph.bringup.build_graph` does)."""

    def __init__(self, sim: Simulator, config: VehicleConfig, serve_serial: bool = True, seed: int = 0,
                 serial_threads: bool = True):
        self.sim = sim
        self.config = config
        # Emulators live in simulated time, quantised like the /clock the drivers see (simulation.clock_rate_hz):
        # a driver that waits a conversion time on its clock then never reads an emulator that is, on the finer
        # simulator time, a fraction of a clock period short of it (MS5837 ADC read returning 0).
        period_s = 1.0 / config.simulation.clock_rate_hz
        self._clock_fn = lambda: math.floor(sim.t_s / period_s + 1e-9) * period_s  # noqa: E731
        clock = lambda: self._clock_fn()  # noqa: E731 - indirection so use_clock() can swap it later
        self._ensure_samples()
        self.emulators: dict[str, Any] = {}
        self._ptys: dict[str, PtyDevice] = {}
        self.ports: dict[str, str] = {}
        bus: dict[int, Any] = {}
        for d in device_table.DEVICES:
            truth = getattr(self, f"_{d.name}_truth", None)
            emulator = self.emulators[d.name] = device_table.load(d.emulator)(config, truth, clock, seed,
                                                                             **truth_keywords(config, d))
            if d.transport == device_table.I2C:
                bus[device_table.settings(config, d).i2c_address] = emulator
            elif serve_serial:
                self._ptys[d.name] = PtyDevice(emulator, clock=clock, link_name=d.name, start=serial_threads)
                self.ports[d.name] = str(self._ptys[d.name].path)
        if config.sensors.icm20948.magnetometer_mode == "bypass":
            bus[0x0C] = self.emulators["icm20948"].aux_port
        self.i2c_bus = EmulatedI2CBus(bus)
        self._channels = [t.esc_channel for t in config.thrusters.thrusters]
        #: the serial lock-steps by device name ("dvl75", "ping1d") after :meth:`lock_step_serial`
        self.serial_lock_steps: dict[str, SerialLockStep] = {}

    def use_clock(self, clock_s) -> None:
        """Run the emulators on ``clock_s()`` (s), e.g. the ROS clock of the drivers' process, so a driver's
        wait measured on its own clock is exactly what the emulator sees (no lag between /clock receptions)."""
        self._clock_fn = clock_s

    def lock_step_serial(self, sim_node: Any, transports: dict[str, Any],
                         ready: dict[str, Callable[[], bool]] | None = None) -> None:
        """Serve the serial devices' ptys from ``sim_node``'s clock ticks and gate its time on their drivers
        (:class:`SerialLockStep`). ``transports``: the drivers' transports by device name (``"dvl75"`` ...); a
        device left out is not served at all. ``ready``: optional start-up conditions by device
        name (:meth:`SerialLockStep.startup_done`).

        Raises:
            RuntimeError: the ptys are already served by threads (``serial_threads=True``), or there are none."""
        if not self._ptys or any(p.threaded for p in self._ptys.values()):
            raise RuntimeError("lock_step_serial needs VirtualHardware(serve_serial=True, serial_threads=False)")
        for name, transport in transports.items():
            link = SerialLockStep(self._ptys[name], transport, ready=(ready or {}).get(name, lambda: True))
            self.serial_lock_steps[name] = link
            sim_node.add_clock_listener(link.tick)
            sim_node.add_step_gate(link.settled)

    def serve_serial(self, lock: Any = None, poll_period_s: float | None = None) -> None:
        """Serve the serial devices' ptys from their own threads (built with ``serial_threads=False``), each
        emulator call under ``lock`` when given (the lock that also guards the simulator's stepping), waiting at most
        ``poll_period_s`` when given (:class:`~hindrax_common.transport.pty_device.PtyDevice`).

        Raises:
            RuntimeError: the ptys are served already (threads or :meth:`lock_step_serial`), or there are none."""
        if not self._ptys or any(p.threaded for p in self._ptys.values()) or self.serial_lock_steps:
            raise RuntimeError("serve_serial needs VirtualHardware(serve_serial=True, serial_threads=False), once")
        for pty in self._ptys.values():
            if lock is not None:
                pty.lock = lock
            pty.poll_period_s = poll_period_s or pty.poll_period_s
            pty.start()

    def serial_startup_done(self) -> bool:
        """:meth:`SerialLockStep.startup_done` of every lock-stepped serial device (True when there is none)."""
        return all([link.startup_done() for link in self.serial_lock_steps.values()])

    def _ensure_samples(self) -> None:
        """Step the unpowered simulator until every device has produced a first sample (<= 1 s simulated)."""
        for _ in range(int(1.0 / self.sim.step_s) + 1):
            if all(self.sim.sensors.latest.get(d) is not None for d in self.sim.sensors.models):
                return
            self.sim.step(None)

    # -- truth adapters (simulator samples -> emulator truth types)
    def _dvl75_truth(self, _t: float) -> DvlTruth:
        # measured at the ping (the emulator's cycle): the driver's time of validity (middle of the $DVPDL
        # interval of the trapezoidal deltas) is then exact; a dropout is a ping without bottom lock
        v = self.sim.measure("dvl75", dropout=True)
        latest = self.sim.sensors.latest
        a = self.sim.measure("dvl75_attitude", dropout=True)
        if a is None:  # a dropout repeats the newest report (the live pool's grid is stopped: SensorSuite.stop_grid)
            a = latest.get("dvl75_attitude")
        else:
            latest["dvl75_attitude"] = a
        locked = bool(v is not None and v.locked and all(math.isfinite(x) for x in v.velocity_frd_m_s))
        altitude = v.altitude_m if v is not None and math.isfinite(v.altitude_m) else None
        roll, pitch, yaw = (a.roll_rad, a.pitch_rad, a.yaw_rad) if a is not None else (0.0, 0.0, 0.0)
        beams = tuple(v.beam_range_m) if (locked and all(math.isfinite(r) for r in v.beam_range_m)) else None
        return DvlTruth(velocity_frd_m_s=tuple(v.velocity_frd_m_s) if locked else (0.0, 0.0, 0.0),
                        altitude_m=altitude, roll_rad=roll, pitch_rad=pitch, yaw_rad=yaw, bottom_lock=locked,
                        confidence_pct=100.0 if locked else 0.0, beam_range_m=beams)

    def _ping1d_truth(self, _t: float) -> Ping1dTruth:
        s = self.sim.measure("ping1d", dropout=True)  # at the ping, as the DVL
        if s is None or not s.valid or not math.isfinite(s.distance_m):
            return Ping1dTruth(altitude_m=None, confidence_pct=0.0)
        return Ping1dTruth(altitude_m=float(s.distance_m), confidence_pct=100.0)

    # The I2C devices sample the vehicle when the emulator asks (start of an MS5837 conversion, an
    # ICM-20948 data-rate tick), as the real parts do, not the newest grid sample (<= 100 ms old).
    def _ms5837_truth(self, _t: float) -> tuple[float, float]:
        s = self.sim.measure("ms5837")
        return (float(s.pressure_pa), float(s.temperature_c))

    def _icm20948_truth(self, _t: float):
        a = self.sim.measure("icm20948_accel")
        g = self.sim.measure("icm20948_gyro")
        m = self.sim.measure("icm20948_mag")
        return (a.specific_force_m_s2, g.angular_rate_rad_s, m.magnetic_field_t, a.temperature_c)

    # -- actuation
    def pulse_widths_us(self) -> np.ndarray:
        """(n,) pulse widths the PCA9685 actually outputs on the thrusters' channels, us (0 = no pulses)."""
        return np.array(self.emulators["pca9685"].pulse_widths_us(self._channels))

    def close(self) -> None:
        """Stop the pseudo-terminal threads (idempotent)."""
        for p in self._ptys.values():
            p.close()
        self._ptys = {}
