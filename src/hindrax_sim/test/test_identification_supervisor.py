"""The identification node's aborts trip the safety supervisor, which disarms the ESC and stays tripped.

Graph on a /clock the test drives: the ESC node on an emulated PCA9685, the safety supervisor, the identification
node and a probe publishing the sensor topics (the vehicle level, still, 1.0 m above the floor). A goal runs; then
the depth reads 1.58 m: beyond ``limits.max_depth_m`` (1.5, the identification's limit) and inside
``supervisor.max_depth_m`` (1.65), so the supervisor trips only because the identification node told it so on
``supervisor/abort``. A cancelled goal must not trip it.
"""
import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PoseWithCovarianceStamped
from rclpy.action import ActionClient
from rclpy.parameter import Parameter
from sensor_msgs.msg import FluidPressure, Imu, Range
from std_msgs.msg import String

from hindrax_common.config import default_config_path, load_config
from hindrax_common.testing import ros_context, wait_until
from hindrax_onboard.identification.online.node import IdentificationNode
from hindrax_msgs.action import RunIdentification
from hindrax_test_support.safety_graph import SafetyGraph
from hindrax_msgs.msg import Dvl, ManeuverStatus, ThrusterPwm
from hindrax_msgs.srv import SetArmed

OVERRIDES = {"esc.arming_time_s": 0.0, "esc.oscillator_calibrated": True, "esc.watchdog_timeout_s": 5.0,
             "supervisor.rate_window_s": 1.0}
TICK_US = 1.24  # one PCA9685 step at 50 Hz


@pytest.mark.ros
@pytest.mark.parametrize("end", ["depth_limit", "cancel"])
def test_identification_abort_trips_the_supervisor_and_disarms_the_esc(end):
    cfg = load_config(default_config_path(), OVERRIDES)
    f = cfg.flat
    assert f["limits.max_depth_m"] < 1.58 < f["supervisor.max_depth_m"]  # the premise of the depth case
    rho_g = cfg.environment.water_density_kg_m3 * cfg.environment.gravity_m_s2
    port_z = float(f["sensors.ms5837.position_frd_m"][2])  # the pressure port below the body origin, m (level)
    with ros_context() as ctx:
        g = SafetyGraph(ctx, OVERRIDES)
        ident = g.add(IdentificationNode(config=cfg, context=ctx, parameter_overrides=[
            Parameter("use_sim_time", value=True)]))
        esc, sup, pubs = g.esc, g.sup, g.pubs
        pressure = g.probe.create_publisher(FluidPressure, "pressure/fluid_pressure", 10)
        aborts: list = []
        phases: list = []
        g.probe.create_subscription(String, "supervisor/abort", aborts.append, 10)
        g.probe.create_subscription(ManeuverStatus, "identification/status", phases.append, 100)
        action = ActionClient(g.probe, RunIdentification, "run_identification")
        depth = {"m": 0.5}
        rng = np.random.default_rng(3)

        def step(dt_s: float = 0.01) -> None:
            """Publish the sensors for this instant (IMU 100 Hz, the others 10 Hz; stamped now, with a little noise as
            real sensors have: the supervisor takes bit-identical streams as frozen), advance /clock, run callbacks."""
            stamp = g.stamp()
            if (g.ns // 1_000_000) % 100 == 0:
                m = Dvl(velocity_valid=True)
                m.header.stamp = stamp
                m.orientation.w = 1.0  # level, heading north
                m.velocity_m_s.x, m.velocity_m_s.y = (float(v) for v in rng.normal(0.0, 1e-4, 2))
                pubs["dvl"].publish(m)
                r = Range(range=1.0 + float(rng.normal(0.0, 1e-3)), min_range=0.3, max_range=50.0)
                r.header.stamp = stamp
                pubs["alt"].publish(r)
                d = PoseWithCovarianceStamped()
                d.header.stamp = stamp
                d.pose.pose.position.z = -depth["m"] + float(rng.normal(0.0, 1e-3))
                pubs["depth"].publish(d)
                p = FluidPressure(fluid_pressure=f["environment.surface_pressure_pa"] + rho_g * (depth["m"] + port_z))
                p.header.stamp = stamp
                pressure.publish(p)
            imu = Imu()
            imu.header.stamp = stamp
            imu.linear_acceleration.z = cfg.environment.gravity_m_s2 + float(rng.normal(0.0, 0.01))
            pubs["imu"].publish(imu)
            g.advance(dt_s)

        def thrust() -> None:
            pubs["cmd"].publish(ThrusterPwm(pulse_width_us=[1700.0] * 8, armed=True))
            step()

        try:
            # fluid_pressure has no reader before a goal (the identification node subscribes to it on acceptance)
            g.wait_ready(step, action.server_is_ready)
            g.arm_with_thrust(step, lambda: ident.core.armed)
            goal = action.send_goal_async(RunIdentification.Goal(dofs=["heave"]))
            wait_until(goal.done, 10, step, "goal answer")
            handle = goal.result()
            assert handle.accepted
            wait_until(lambda: ident.core.run is not None and ident.core.run.executive.started, 30, step,
                       "campaign started")
            for _ in range(20):
                step()
            assert not sup.core.tripped and not aborts
            if end == "cancel":
                handle.cancel_goal_async()
            else:
                depth["m"] = 1.58
            result = handle.get_result_async()
            wait_until(result.done, 30, step, "the action's end")
            message = result.result().result.message
            assert not result.result().result.success
            assert phases[-1].phase in (ManeuverStatus.PHASE_ABORTED, ManeuverStatus.PHASE_IDLE)
            if end == "cancel":
                for _ in range(50):
                    step()
                assert message == "cancelled" and not aborts and not sup.core.tripped
                assert esc.armed
                return
            assert message.startswith("depth 1.58 m beyond limits.max_depth_m"), message
            wait_until(lambda: aborts and sup.core.tripped, 10, step, "the supervisor tripped")
            assert [a.data for a in aborts] == [message]  # once, with the executive's reason
            assert sup.core.tripped == f"abort requested: {message}"
            wait_until(lambda: not esc.armed and np.allclose(g.wire(), 1500.0, atol=TICK_US), 10, thrust,
                       "ESC disarmed, neutral")
            wait_until(lambda: g.statuses and g.statuses[-1].level == DiagnosticStatus.ERROR, 10, step, "status")
            assert message in g.statuses[-1].message
            # tripped: a re-arm is undone until the supervisor is reset
            esc.on_set_armed(SetArmed.Request(arm=True), SetArmed.Response())
            wait_until(lambda: not esc.armed, 10, step, "disarmed again while tripped")
            assert sup.core.tripped
        finally:
            g.close()
