"""The tools room: what engineers run beside the vehicle, not what it runs.

The ``hindrax`` command line (:mod:`.cli`, one module per subcommand in :mod:`.commands`) and the
``make bench`` benchmarks (:mod:`.bench`, :mod:`.benchmarks`). The top layer: nothing outside this
room imports it (test/test_import_structure.py).
"""
