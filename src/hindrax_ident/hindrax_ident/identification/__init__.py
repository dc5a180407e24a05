"""Hydrodynamic identification of Hindrax (docs/architecture.md §5; [Hindrax-Drag] §3-§5; [Hindrax-AM]).

Four rooms, lowest first (``test/test_import_structure.py`` keeps the order):

* :mod:`.bag_input` - what a campaign recorded and how it is read back: the ROS messages -> samples adapters
  shared by the live node and the bag reader, the calibration topic, the campaign record and the campaign bag
  reader.
* :mod:`.fit` - the offline fit: the per-DOF model, the one fit core (segment-wise output error,
  cross-validation, cluster-robust intervals), the empirical priors and their posterior, the known-force thrust
  calibration, and the two front-ends that read records into it (a campaign record, any bag).
* :mod:`.assessment` - what is said about a fit: verdicts and honest intervals, identification.yaml
  (writer, reader, configuration overrides), the vehicle it belongs to, the reports and open-loop predictions.
* :mod:`.online` - the campaign as it runs: the executive and its steps, excitation, manoeuvres and holds, the
  online estimator, the identification node, the in-process campaign on the simulator. It may use the rooms
  below, but not the identification.yaml writer (:mod:`.assessment.results`).

:mod:`.graph_campaign` (``hindrax run``) spans the rooms: the campaign on the composed graph, then the offline
fit of its bag and the outputs.
"""
