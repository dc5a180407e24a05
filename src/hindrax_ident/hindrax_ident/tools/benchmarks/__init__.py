"""The ``make bench`` benchmarks: one module per concern, each with a ``run(quick)`` function."""
from __future__ import annotations

import argparse
import json
from typing import Callable, Sequence


def run_alone(run: Callable[[bool], list[dict]], argv: Sequence[str] | None = None) -> int:
    """Run one benchmark module alone (``python -m hindrax_ident.tools.benchmarks.<name>
    [--quick]``): print the rows of ``run(quick)`` as JSON; returns the exit status 0."""
    parser = argparse.ArgumentParser(description="one benchmark module's rows, as JSON")
    parser.add_argument("--quick", action="store_true", help="the reduced variant (bench --quick)")
    print(json.dumps(run(parser.parse_args(argv).quick), indent=2))
    return 0
