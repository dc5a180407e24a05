"""Hydrodynamic identification of Hindrax (docs/architecture.md §5; [Hindrax-Drag] §3-§5; [Hindrax-AM]).

Four rooms, lowest first (``test/test_import_structure.py`` keeps the order):

* :mod:`.bag_input` - what a campaign recorded and how it is read back: the calibration topic, the campaign record
  and the campaign bag reader (the ROS messages -> samples adapters are the vehicle's, :mod:`..vehicle.signals`).
* :mod:`.fit` - the offline fit: the per-DOF model, the one fit core (segment-wise output error,
  cross-validation, cluster-robust intervals), the empirical priors and their posterior, the known-force thrust
  calibration, and the two front-ends that read records into it (a campaign record, any bag).
* :mod:`.assessment` - what is said about a fit: verdicts and honest intervals, identification.yaml
  (writer, reader, configuration overrides), the reports and open-loop predictions.
* :mod:`.online` - the campaign as it runs: the executive and its steps, excitation, the online estimator, the
  identification node. It may use the rooms below, but not the identification.yaml writer
  (:mod:`.assessment.results`).

Below the package: the vehicle (:mod:`..vehicle`) and the controller's holds and manoeuvre planning
(:mod:`..control.maneuvers`); above it: the in-process campaign on the simulator (:mod:`..sim.campaign`) and the
campaign on the composed graph (:mod:`..graph_campaign`, ``hindrax run``).
"""
