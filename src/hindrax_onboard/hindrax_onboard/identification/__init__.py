"""Hydrodynamic identification on the vehicle (docs/architecture.md §2; [Hindrax-Drag] §3-§5; [Hindrax-AM]).

Two rooms, lowest first (``test/test_import_structure.py`` keeps the order): :mod:`.model`, the per-DOF model the
topside fit shares (regressors, the priors' posterior, the campaign record, the calibration topic), and
:mod:`.online`, the campaign as it runs (executive and steps, excitation, online estimator, the node). Below: the
vehicle and the controller's holds; above: the topside fit (:mod:`hindrax_fit`) and the simulator."""
