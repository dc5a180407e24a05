"""The ``make bench`` benchmarks: one module per concern, each with a ``run(quick)`` function."""
