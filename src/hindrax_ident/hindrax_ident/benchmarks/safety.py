"""Safety benchmark: how fast every disarm path puts all thrusters at neutral, read back on the emulated chip.

One process, one SingleThreadedExecutor, wall-clock ROS time: the ESC node on a register-exact PCA9685 emulator,
the safety supervisor, and a probe (controller, operator, sensors). For each path the vehicle is armed and
commanded to 1700 us on every thruster, then the event happens; the time is taken from the event to the first
I2C transaction after which the emulator decodes every thruster channel at neutral (1500 us within one count):

* ``watchdog``: commands stop; measured from the last command the node took, so it includes
  ``esc.watchdog_timeout_s``
  (0.5 s in the shipped file); the row ``..._beyond_timeout`` subtracts it (the design bound: one output period);
* ``disarm_service``: ``esc/set_armed`` with ``arm=False`` called;
* ``supervisor_breach``: a ``pressure/depth`` message beyond ``supervisor.max_depth_m`` published;
* ``estop``: ``supervisor/estop`` called;
* ``exception``: a command with a NaN pulse width (a fault in the output path);
* ``shutdown``: :meth:`EscNode.close` (what SIGINT/SIGTERM run through ``run_node``);
* ``chip_reset``: the PCA9685 reset (brown-out) while armed: detect = until the node's read-back finds it
  (``esc.readback_interval_s``, 1 s), recover = until neutral is back on the re-initialised chip;
* ``clock_loss``: ``use_sim_time`` and ``/clock`` stops while commanding (the commands stop with it): the
  steady-clock watchdog; measured from the last command the node took (so it includes the 0.5 s timeout).

Each path is repeated (3 times with ``--quick``, 6 otherwise, to keep ``make bench`` under 6 minutes); rows give the
median and the maximum in ms.
"""
from __future__ import annotations

import time

import numpy as np

NEUTRAL_US = 1500.0
TICK_US = 1.3  # one PCA9685 count at 200 Hz is 1.24 us (docs/devices.md §5.1)


def _rig(ctx, sim_time: bool = False):
    import rclpy
    from geometry_msgs.msg import PoseWithCovarianceStamped
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rosgraph_msgs.msg import Clock
    from std_srvs.srv import Trigger

    from hindrax_drivers.pca9685.emulator import Pca9685Emulator
    from hindrax_drivers.pca9685.node import EscNode
    from hindrax_drivers.supervisor.node import SupervisorNode
    from hindrax_drivers.testing import config_parameters, wait_until
    from hindrax_drivers.transport.emulated_i2c import EmulatedI2CBus
    from hindrax_msgs.msg import ThrusterPwm
    from hindrax_msgs.srv import SetArmed

    class TimedEmulator(Pca9685Emulator):
        """Records the monotonic time of the first transaction that leaves every thruster channel at neutral."""

        watch = False
        neutral_at: float | None = None

        def i2c_write(self, data: bytes) -> None:
            super().i2c_write(data)
            if self.watch and self.neutral_at is None and self.all_neutral():
                self.neutral_at = time.monotonic()

        def all_neutral(self) -> bool:
            return all(abs(self.pulse_width_us(c) - NEUTRAL_US) < TICK_US for c in range(8))

    emu = TimedEmulator()
    # the emulated chip runs at exactly esc.oscillator_hz (calibrated by construction); sensors not simulated here,
    # so the supervisor's rate checks are off
    over = {"esc.arming_time_s": 0.0, "esc.oscillator_calibrated": True, "supervisor.min_rate.dvl_hz": 0.0,
            "supervisor.min_rate.altimeter_hz": 0.0, "supervisor.min_rate.pressure_hz": 0.0,
            "supervisor.min_rate.imu_hz": 0.0}
    params = config_parameters(over) + ([Parameter("use_sim_time", value=True)] if sim_time else [])
    esc = EscNode(bus=EmulatedI2CBus({0x40: emu}), context=ctx, parameter_overrides=params)
    sup = SupervisorNode(context=ctx, parameter_overrides=params)
    probe = rclpy.create_node("bench_safety", context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    for n in (esc, sup, probe):
        ex.add_node(n)
    r = dict(emu=emu, esc=esc, sup=sup, probe=probe, ex=ex,
             cmd=probe.create_publisher(ThrusterPwm, "thrusters/command_pulse_width", 10),
             depth=probe.create_publisher(PoseWithCovarianceStamped, "pressure/depth", 10),
             clock=probe.create_publisher(Clock, "/clock", 10),
             arm=probe.create_client(SetArmed, "esc/set_armed"), estop=probe.create_client(Trigger, "supervisor/estop"),
             reset=probe.create_client(Trigger, "supervisor/reset"), ns=1_000_000_000)

    def spin(timeout_s: float = 0.002) -> None:
        if sim_time:
            r["ns"] += 2_000_000
            c = Clock()
            c.clock.sec, c.clock.nanosec = divmod(r["ns"], 1_000_000_000)
            r["clock"].publish(c)
        ex.spin_once(timeout_sec=timeout_s)

    def call(client, request):
        fut = client.call_async(request)
        wait_until(fut.done, 10, spin, "service answer")
        return fut.result()

    def command(width: float = 1700.0) -> None:
        r["cmd"].publish(ThrusterPwm(pulse_width_us=[width] * 8, armed=True))

    def armed_at_1700() -> None:
        # the previous path's disarm (and any supervisor disarm request) has landed before the reset and re-arm
        emu.watch = False
        if esc.armed:  # the watchdog neutralises but stays armed
            call(r["arm"], SetArmed.Request(arm=False))
        settled = lambda: not esc.armed and not sup.esc_armed and (  # noqa: E731
            sup.disarm_future is None or sup.disarm_future.done())
        wait_until(settled, 10, spin, "previous disarm settled")
        t_quiet = time.monotonic() + 0.3  # > DISARM_RETRY_S: no supervisor retry still on its way
        wait_until(lambda: time.monotonic() > t_quiet and settled(), 10, spin, "previous disarm settled")
        call(r["reset"], Trigger.Request())
        emu.watch, emu.neutral_at = False, None
        wait_until(lambda: esc.neutral_confirmed_time is not None and esc.arming_remaining_s() == 0.0, 20, spin,
                   "ESC ready")
        res = call(r["arm"], SetArmed.Request(arm=True))
        if not res.success:
            raise RuntimeError(f"arming refused: {res.message}")

        def go():
            command()
            spin()
        wait_until(lambda: emu.pulse_width_us(0) > 1690.0 and sup.core.armed, 20, go, "1700 us on the wire")
        emu.watch = True

    def until_neutral(timeout_s: float = 10.0, poll=None) -> float:
        wait_until(lambda: emu.neutral_at is not None, timeout_s, poll or spin, "neutral on the chip")
        return emu.neutral_at

    wait_until(lambda: r["cmd"].get_subscription_count() > 0 and r["arm"].service_is_ready()
               and r["estop"].service_is_ready() and sup.esc_client.service_is_ready(), 20, spin, "graph ready")
    r.update(spin=spin, call=call, command=command, armed_at_1700=armed_at_1700, until_neutral=until_neutral,
             SetArmed=SetArmed, Trigger=Trigger, PoseWithCovarianceStamped=PoseWithCovarianceStamped,
             wait_until=wait_until)
    return r


def _close(r) -> None:
    r["ex"].shutdown()
    for n in (r["probe"], r["sup"], r["esc"]):
        n.destroy_node()


def run(quick: bool = False) -> list[dict]:
    from domain_coordinator import domain_id

    from hindrax_drivers.testing import ros_context

    repeats = 3 if quick else 6
    times: dict[str, list[float]] = {k: [] for k in (
        "watchdog", "watchdog_beyond_timeout", "disarm_service", "supervisor_breach", "estop", "exception",
        "shutdown", "chip_reset_detect", "chip_reset_recover", "clock_loss")}
    # a reserved ROS domain: this bench trips supervisors and calls e-stops, which must never reach another graph
    with domain_id() as did, ros_context(domain_id=did) as ctx:
        r = _rig(ctx)
        esc, emu = r["esc"], r["emu"]
        watchdog_s = esc.watchdog_s
        for _ in range(repeats):
            # watchdog: the controller stops
            r["armed_at_1700"]()
            t_neutral = r["until_neutral"]()
            dt = t_neutral - esc._steady_command  # from the last command the node took (steady clock)
            times["watchdog"].append(dt)
            times["watchdog_beyond_timeout"].append(dt - watchdog_s)
            # disarm service
            r["armed_at_1700"]()
            fut = r["arm"].call_async(r["SetArmed"].Request(arm=False))
            t0 = time.monotonic()
            times["disarm_service"].append(r["until_neutral"]() - t0)
            r["wait_until"](fut.done, 5, r["spin"], "disarm answer")
            # supervisor breach: too deep
            r["armed_at_1700"]()
            m = r["PoseWithCovarianceStamped"]()
            m.pose.pose.position.z = -(r["sup"].core.limits.max_depth_m + 0.1)
            t0 = time.monotonic()
            r["depth"].publish(m)
            times["supervisor_breach"].append(r["until_neutral"]() - t0)
            # operator e-stop
            r["armed_at_1700"]()
            fut = r["estop"].call_async(r["Trigger"].Request())
            t0 = time.monotonic()
            times["estop"].append(r["until_neutral"]() - t0)
            r["wait_until"](fut.done, 5, r["spin"], "estop answer")
            # exception in the output path
            r["armed_at_1700"]()
            t0 = time.monotonic()
            r["command"](float("nan"))
            times["exception"].append(r["until_neutral"]() - t0)
            # shutdown path
            r["armed_at_1700"]()
            t0 = time.monotonic()
            esc.close()
            times["shutdown"].append(r["until_neutral"]() - t0)
            # chip reset (brown-out) while armed and commanding
            r["armed_at_1700"]()
            emu.watch = False
            reinits = esc.chip_reinits
            t0 = time.monotonic()
            emu.reset()
            emu.watch, emu.neutral_at = True, None

            def keep_commanding():
                r["command"]()
                r["spin"]()
            r["wait_until"](lambda: esc.chip_reinits > reinits, 10, keep_commanding, "chip reset detected")
            times["chip_reset_detect"].append(esc.last_chip_reinit_monotonic - t0)
            times["chip_reset_recover"].append(r["until_neutral"](poll=keep_commanding) - t0)
        _close(r)
        # /clock loss: the steady-clock watchdog
        rs = _rig(ctx, sim_time=True)
        for _ in range(repeats):
            rs["armed_at_1700"]()  # returns right after the last /clock message
            t_neutral = rs["until_neutral"](poll=lambda: rs["ex"].spin_once(timeout_sec=0.002))
            times["clock_loss"].append(t_neutral - rs["esc"]._steady_command)
        _close(rs)

    rows = []
    notes = {"watchdog": f"from the last command; includes esc.watchdog_timeout_s = {watchdog_s:g} s",
             "watchdog_beyond_timeout": "design bound: one output period (20 ms at 50 Hz)",
             "chip_reset_detect": "read-back every esc.readback_interval_s (1 s)",
             "chip_reset_recover": "re-initialised at neutral, disarmed",
             "clock_loss": "use_sim_time, /clock stops: steady-clock watchdog (includes the 0.5 s timeout)"}
    for name, values in times.items():
        ms = np.array(values) * 1e3
        row = {"name": f"neutral_after_{name}_ms" if not name.startswith(("chip", "clock")) else f"{name}_ms",
               "value": float(np.median(ms)), "unit": "ms", "max": float(np.max(ms)), "n": int(ms.size)}
        if name in notes:
            row["note"] = notes[name]
        rows.append(row)
    return rows
