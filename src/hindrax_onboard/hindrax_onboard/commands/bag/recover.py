"""``hindrax bag recover BAG``: repair a bag whose recorder was killed or lost power.

Rewrites every truncated .mcap file of BAG as a complete file (summary, indexes, rosbag2 metadata
record) and rebuilds metadata.yaml from the files; complete files are left unchanged. Prints one line
per file and a total. Exit 0, or 1 with one line on stderr. Implementation:
:mod:`hindrax_bringup.recording.recover`."""
from __future__ import annotations

import argparse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the command's options and arguments to ``parser``."""
    parser.add_argument("bag", help="bag directory or .mcap file")
    parser.add_argument("--keep-original", action="store_true",
                        help="keep each damaged file beside the repaired one as <name>.truncated")


def run(args: argparse.Namespace) -> int:
    """Run the command with the parsed ``args``; returns the process exit code."""
    from hindrax_bringup.recording.recover import RecoverError, recover_bag

    from ..common import CommandError

    try:
        meta, results = recover_bag(args.bag, keep_original=args.keep_original)
    except (FileNotFoundError, RecoverError, OSError) as exc:
        raise CommandError(f"hindrax bag recover: {exc}") from exc
    if meta.message_count == 0:
        raise CommandError(f"hindrax bag recover: {args.bag}: no complete message to recover")
    for r in results:
        print(r.summary_line())
    print(f"{args.bag}: {meta.message_count} messages on {len(meta.topics)} topics in {len(meta.files)} file(s)")
    return 0
