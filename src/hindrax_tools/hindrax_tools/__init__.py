"""The tools: what engineers run beside the vehicle, not what it runs (the top package, nothing imports it): the
``hindrax`` command line (:mod:`.cli`, one module per subcommand in :mod:`.commands`) and the ``make bench``
benchmarks (:mod:`.bench`, :mod:`.benchmarks`); progress lines and the results document."""
