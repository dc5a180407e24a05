"""The vehicle's physics and timing, below control, identification and the simulator (docs/architecture.md §2).

The rigid body, the thrust lag, the thrust curve and the angle wrap exist once in the repository
(``test/test_import_structure.py`` checks both the layering and the single definitions):

- :mod:`.rigid_body`: the skew matrix and the rigid-body mass matrix M_RB about the body origin;
- :mod:`.thrust_lag`: :class:`~.thrust_lag.ThrustLag`, the first-order lag between commanded and delivered thrust;
- :mod:`.state`: the sensor state (conditioned samples, dead reckoning) and the depth estimate that the holds, the
  controller and the identification read; :mod:`.fusion`: the accelerometer-aided Kalman filter and smoothers;
- :mod:`.signals`: ROS messages -> sensor samples; :mod:`.uncertainty`: the measurement noise and thrust uncertainty
  the vehicle file declares; :mod:`.vehicle_match`: the vehicle-file values an identification depends on;
- the thrust curve: :class:`hindrax_common.base.thrust_curve.ThrustCurve`, built from the vehicle file by
  :func:`hindrax_bringup.allocation.from_config.thrust_curve_from_config` (the allocation's, used as it is);
- the angle wrap: :func:`hindrax_common.base.frames.wrap_angle` (in the drivers because the DVL-75 emulator needs it).

Nothing here imports the simulator, identification or control."""
