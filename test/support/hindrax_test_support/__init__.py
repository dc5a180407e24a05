"""Helpers only tests use, kept out of ``src`` so that no package ships them (issue 75, point 6).

On the import path of every test through pytest.ini's ``pythonpath`` (``test/support``). What tests and the ``make
bench`` benchmarks share stays in :mod:`hindrax_common.testing`, which the benchmarks import.

- :mod:`.replay_devices`: the driver nodes on a bag's recorded raw device data (docs/architecture.md §7);
  :mod:`.record_bag` records the bag of the virtual pool they replay (``sim_drivers_3s``).
- :mod:`.helpers`: small helpers of a few tests (real-time priority, a burst's QoS, unbatching raw data).
- :mod:`.decay`: an independent RK4 reference of free decays (the identification tests' records).
- :mod:`.packages`: the keyword arguments each package's setup.py gives setuptools.
- :mod:`.safety_graph`: the ESC node and the supervisor on a /clock the test drives (the supervisor's graph test,
  the identification-abort test).
"""
