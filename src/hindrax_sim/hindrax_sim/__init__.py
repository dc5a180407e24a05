"""The virtual pool: a 6-DOF Fossen model of Hindrax in a pool box, with thrusters and sensor models.

Modules (pure numpy unless noted): :mod:`.model` (equations of motion), :mod:`.thrusters` (pulse width ->
thrust -> lagged wrench), :mod:`.pool` (floor, walls, free surface, contacts), :mod:`.sensors` (what each
device measures, with noise), :mod:`.simulator` (:class:`Simulator`: everything stepped together, no ROS),
:mod:`.node` (rclpy node publishing /clock and ground truth; imported only on demand). Above control and
identification, it runs them: :mod:`.campaign` (the identification campaign stepped in-process),
:mod:`.control_evaluate` and :mod:`.control_suite` (closed-loop holds against a truth), :mod:`.live_pool`; above them
the graph in one process (:mod:`.graph`: bringup, its executor, the campaign on the graph, bag recording)."""
from .simulator import PulseWidthError, Simulator

__all__ = ["Simulator", "PulseWidthError"]
