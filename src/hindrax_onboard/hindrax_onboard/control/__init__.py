"""Closed-loop control from the identified model: depth, altitude, heading and velocity holds (docs/control.md).

Below identification (which flies its campaign with these holds); imports only the drivers, estimation and vehicle.

* :mod:`.model` - the control model per DOF (inertia, damping, net buoyancy, restoring) from the vehicle file or
  from ``identification.yaml`` with its verdicts, and where each value came from.
* :mod:`.law` - the control law (pure numpy): reference models, PID with reference feedforward of the model,
  gains for a bandwidth lowered by the model's uncertainty, anti-windup, saturation.
* :mod:`.legacy` - the PD/PI holds the campaign used before (kept for the comparison of ``hindrax control evaluate``).
* :mod:`.loop` - sensor samples in, wrench out: the conditioning of the campaign around a hold.
* :mod:`.maneuvers` - the holds behind the campaign's interface, the axis authority, the pool box, level ladders.
* :mod:`.node` - ``controller_node``: the law as one more ``wrench`` source on the ROS graph.

The closed-loop evaluation in the virtual pool is the simulator's (:mod:`hindrax_sim.control_evaluate`)."""
