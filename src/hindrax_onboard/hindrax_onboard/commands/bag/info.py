"""``hindrax bag info BAG``: topics, types, message counts, rates, duration and size of a bag.

BAG is a bag directory (metadata.yaml + .mcap files) or one .mcap file. Exit 0, or 1 with one line
on stderr when BAG is not a readable bag. Implementation: :mod:`hindrax_bringup.recording.info`."""
from __future__ import annotations

import argparse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the command's options and arguments to ``parser``."""
    parser.add_argument("bag", help="bag directory or .mcap file")


def run(args: argparse.Namespace) -> int:
    """Run the command with the parsed ``args``; returns the process exit code."""
    from hindrax_bringup.recording.info import bag_info, format_bag_info
    from hindrax_bringup.recording.reader import BagError

    from ..common import CommandError

    try:
        info = bag_info(args.bag)
    except (FileNotFoundError, BagError, OSError) as exc:
        raise CommandError(f"hindrax bag info: {exc}") from exc
    print(format_bag_info(info))
    return 0
