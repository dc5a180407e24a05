"""Peer process for test_interfaces.py: serves hindrax_msgs from a separate process.

Publishes hindrax_msgs/Dvl on /peer/dvl at 20 Hz, serves hindrax_msgs/srv/SetArmed on /peer/set_armed and the
hindrax_msgs/action/RunIdentification action on /peer/run_identification (two feedbacks, then a result with
one HydroEstimate per requested DOF). Exits on SIGTERM/SIGINT.
"""
import math
import sys
import time

import rclpy
from rclpy.action import ActionServer
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node

from hindrax_msgs.action import RunIdentification
from hindrax_msgs.msg import Dvl, HydroEstimate
from hindrax_msgs.srv import SetArmed

FEEDBACK_TOPIC = "/peer/run_identification/_action/feedback"


class Peer(Node):
    def __init__(self) -> None:
        super().__init__("interface_peer")
        self.pub = self.create_publisher(Dvl, "/peer/dvl", 10)
        self.count = 0
        self.create_timer(0.05, self.tick)
        self.armed = False
        self.create_service(SetArmed, "/peer/set_armed", self.set_armed)
        self.action = ActionServer(self, RunIdentification, "/peer/run_identification", self.execute)

    def tick(self) -> None:
        m = Dvl()
        m.header.stamp = self.get_clock().now().to_msg()
        m.header.frame_id = "base_link"
        m.velocity_m_s.x = 0.25
        m.velocity_m_s.y = -0.125
        m.velocity_m_s.z = float(self.count)
        m.velocity_valid = True
        m.altitude_m = 0.9
        m.bottom_lock = True
        m.confidence_percent = 87.5
        m.beam_range_m = [1.0, 1.1, 1.2, 1.3]
        m.beam_lock = [True, True, False, True]
        m.beam_velocity_m_s = [0.1, 0.2, math.nan, 0.4]
        m.orientation.w = 1.0
        m.delta_time_s = 0.1
        self.pub.publish(m)
        self.count += 1

    def set_armed(self, request, response):
        self.armed = request.arm
        response.success = True
        response.armed = self.armed
        response.message = "peer armed" if self.armed else "peer disarmed"
        return response

    def execute(self, goal_handle):
        dofs = list(goal_handle.request.dofs)
        # Feedback is a plain topic: sent before discovery has matched the client's feedback subscription (slow
        # on a loaded machine) it is lost. Wait (bounded) until the client's subscription is seen.
        deadline = time.monotonic() + 10.0
        while self.count_subscribers(FEEDBACK_TOPIC) == 0 and time.monotonic() < deadline:
            time.sleep(0.01)
        for i, dof in enumerate(dofs):
            fb = RunIdentification.Feedback()
            fb.dof = dof
            fb.level_index = 0
            fb.level_count = goal_handle.request.levels_per_dof
            fb.level_command = 10.0 * (i + 1)
            fb.progress = (i + 1) / len(dofs)
            goal_handle.publish_feedback(fb)
        goal_handle.succeed()
        result = RunIdentification.Result()
        result.success = True
        result.message = "ok"
        for dof in dofs:
            e = HydroEstimate()
            e.dof = dof
            e.method = "rls"
            e.parameter_names = ["inertia", "quadratic_damping"]
            e.parameter_units = ["kg", "kg/m"]
            e.values = [27.3, 66.5]
            e.std = [0.5, 1.5]
            e.covariance = [0.25, 0.0, 0.0, 2.25]
            e.sample_count = 1234
            e.excitation = 0.75
            e.converged = True
            result.estimates.append(e)
        return result


def main() -> int:
    rclpy.init()
    node = Peer()
    ex = SingleThreadedExecutor()
    ex.add_node(node)
    try:
        ex.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        ex.shutdown()
        node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
