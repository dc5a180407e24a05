"""Hydrodynamic identification of Hindrax (docs/architecture.md §5; [Hindrax-Drag] §3-§5; [Hindrax-AM]).

* :mod:`.maneuvers` - DOF authority from the allocator, level ladders, the pool box, sensor
  conditioning and the simple holding controllers (sensor samples only).
* :mod:`.campaign` - runs the [Hindrax-Drag] §4 manoeuvres on the simulator (no ROS) and records everything.
* :mod:`.estimators` - the per-DOF model, the online estimator (Kalman filter + RLS) and the comparison methods
  (equation-error batch LS, the steady-state LS of [Hindrax-Drag]).
* :mod:`.fit_core` - the one offline fit (segment-wise output error, cross-validation, cluster-robust intervals);
  :mod:`.campaign_fit` reads a campaign record into it, :mod:`.fit_any` any bag (docs/identification.md §7).
* :mod:`.results` - identification.yaml writer/reader and configuration overrides.
* :mod:`.report` - report/index.html with PNG plots.
"""
