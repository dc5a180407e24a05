"""``hindrax ident bag BAG [--out DIR] [--config FILE]``: offline identification of a recorded campaign bag.

Writes ``identification.yaml`` and ``report/index.html`` (default: beside the bag) and prints the summary
table; the analysis is :mod:`hindrax_ident.identification.from_bag` (batch least squares with output-error
refinement, [Hindrax-Drag] (seed 003) eqs. 6-8). Exit 0, or 1 with one line on stderr when the configuration,
the bag or its content is unusable, or when no DOF could be identified.
"""
from __future__ import annotations

import argparse
from pathlib import Path

from .common import CommandError, add_config_argument, load_vehicle

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``hindrax ident bag``."""
    parser.add_argument("bag", help="bag directory (or .mcap file) recorded during an identification campaign")
    parser.add_argument("--out", default=None, help="output directory (default: the bag's parent directory)")
    add_config_argument(parser)


def run(args: argparse.Namespace) -> int:
    """Identify from a bag, write the outputs, print the summary. Raises :class:`CommandError` on bad input."""
    from hindrax_drivers.recording.reader import BagError

    from ..identification.from_bag import BagContentError, identify_bag, write_outputs
    from .run import format_summary

    cfg = load_vehicle(args.config)
    bag = Path(args.bag)
    if not bag.exists():
        raise CommandError(f"ident bag: {bag}: no such file or directory")
    try:
        record, idents, errors = identify_bag(bag, cfg)
    except (BagError, BagContentError, OSError) as exc:
        raise CommandError(f"ident bag: {exc}") from exc
    for dof, msg in errors.items():
        print(f"{dof}: no estimate ({msg})")
    if not idents:
        raise CommandError("ident bag: no DOF could be identified")
    out = Path(args.out) if args.out else bag.resolve().parent
    out.mkdir(parents=True, exist_ok=True)
    note = (f"Offline identification of bag {bag}, {record.t_s[-1] - record.t_s[0]:.0f} s of campaign"
            + (f"; ABORTED: {record.abort_reason}" if record.aborted else ""))
    path = write_outputs(out, idents, cfg, bag, note)
    print(format_summary(idents))
    print(f"output: {path} and {out / 'report' / 'index.html'}")
    return 0
