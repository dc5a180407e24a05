"""Hydrodynamic identification of Hindrax (docs/architecture.md §5; [Hindrax-Drag] §3-§5; [Hindrax-AM]).

* :mod:`.maneuvers` - DOF authority from the allocator, level ladders, the pool box, sensor
  conditioning and the simple holding controllers (sensor samples only).
* :mod:`.campaign` - runs the [Hindrax-Drag] §4 manoeuvres on the simulator (no ROS) and records everything.
* :mod:`.estimators` - per-DOF online estimator (Kalman filter + RLS), offline batch LS on RTS-smoothed
  signals with an output-error refinement, and the seed's steady-state LS.
* :mod:`.results` - identification.yaml writer/reader and configuration overrides.
* :mod:`.report` - report/index.html with PNG plots.
"""
