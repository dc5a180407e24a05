"""``make bench``: run the benchmark scripts and print one table, writing JSON beside it.

Each module in :mod:`hindrax_tools.benchmarks` (listed in :data:`BENCHMARKS`) provides ``run(quick: bool) ->
list[dict]``: rows with at least ``name``, ``value``, ``unit`` and optionally ``target`` and ``note``. Benchmarks
measure; tests never time anything (README, "Tests").

Usage: ``python -m hindrax_tools.bench [--only NAME[,NAME]] [--quick] [--out DIR] [--baseline GIT_REF]``
(``--baseline``: the stack section measures that commit's launch layout too, in the same run)."""
from __future__ import annotations

import argparse
import datetime as _dt
import importlib
import json
import os
import platform
import sys
import time
from pathlib import Path

from hindrax_tools import results_doc
from hindrax_common.process.dds_transport import loopback_transport

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
loopback_transport()  # the vehicle's transport (hindrax_common.process.dds_transport)

#: benchmark name -> the modules of :mod:`hindrax_tools.benchmarks` whose rows form its
#: section, each with ``run(quick)``; a section's first module is named like it
BENCHMARKS: dict[str, tuple[str, ...]] = {name: (name,) for name in (
    "stack", "actuation", "heartbeats", "safety", "simulator", "i2c_drivers", "i2c_socket",
    "identification", "ident_fit", "scenarios", "recorder", "serial_drivers", "robustness", "cli", "repro")}
BENCHMARKS["safety"] += ("participant_churn", "sealed_authority")


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point (``argv`` without the program name); returns the exit code."""
    parser = argparse.ArgumentParser(prog="hindrax-bench", description=__doc__.splitlines()[0])
    parser.add_argument("--only", default="", help="comma-separated benchmark names")
    parser.add_argument("--quick", action="store_true", help="shorter runs (smoke check of the scripts)")
    parser.add_argument("--out", default="bench-results", help="directory for results.json")
    parser.add_argument("--baseline", default=None, metavar="GIT_REF",
                        help="the stack section also measures this commit's launch layout in the same run and reports "
                             "today's CPU over it (hindrax_tools.benchmarks.stack.baseline_launch)")
    results_doc.add_argument(parser)
    args = parser.parse_args(argv)
    names = [n for n in args.only.split(",") if n] or list(BENCHMARKS)
    unknown = [n for n in names if n not in BENCHMARKS]
    if unknown:
        print(f"unknown benchmark(s): {', '.join(unknown)}; available: {', '.join(BENCHMARKS)}", file=sys.stderr)
        return 2
    rows: list[dict] = []
    wall_s: dict[str, float] = {}
    start = time.monotonic()
    for name in names:
        print(f"== {name}", flush=True)
        t0 = time.monotonic()
        for module in BENCHMARKS[name]:
            run = importlib.import_module(f"hindrax_tools.benchmarks.{module}").run
            extra = {"baseline": args.baseline} if args.baseline and module == "stack" else {}
            for row in run(quick=args.quick, **extra):
                rows.append({"benchmark": name, **row})
        wall_s[name] = round(time.monotonic() - t0, 1)
        print(f"== {name}: {wall_s[name]:.0f} s", flush=True)
    wall_s["total"] = round(time.monotonic() - start, 1)
    table = results_doc.markdown_table(
        ["benchmark", "measure", "value", "unit", "target", "note"],
        [[r["benchmark"], r["name"],
          f"{r['value']:.4g}" if isinstance(r["value"], (int, float)) else r["value"],
          r.get("unit", ""), r.get("target", ""), r.get("note", "")] for r in rows])
    print("\n" + table)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    doc = {"date": _dt.datetime.now(_dt.timezone.utc).isoformat(), "machine": platform.platform(),
           "cpus": os.cpu_count(), "wall_s": wall_s, "rows": rows}
    (out / "results.json").write_text(json.dumps(doc, indent=2))
    print("\nwall time per section: " + ", ".join(f"{k} {v:.0f} s" for k, v in wall_s.items()))
    print(f"written {out / 'results.json'}")
    results_doc.write_if_asked(
        args, "bench" if not args.only else "bench-" + "-".join(names),
        "Benchmarks (`make bench`)" if not args.only else f"Benchmarks: {', '.join(names)}",
        f"{platform.platform()}, {os.cpu_count()} cores; wall time {wall_s['total']:.0f} s"
        f"{' (--quick)' if args.quick else ''}. Targets are the Pi budget of docs/architecture.md §10.\n\n{table}",
        supersedes_prefix=None if args.only else "bench-", supersedes_rows=("bench", names) if args.only else None)
    return 0


if __name__ == "__main__":
    sys.exit(main())
