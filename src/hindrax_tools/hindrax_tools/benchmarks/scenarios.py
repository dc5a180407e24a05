"""Scenario-suite benchmark: a short subset of ``hindrax ident scenarios`` in ``make bench``.

quick: scenario ``thrust_0.90`` only, surge, 2 levels, seed 1; full: ``none``, ``thrust_0.90`` and ``reverse_weak``,
surge, 2 levels, seed 1 (the full table is written by the command into docs/results.md, section ``scenarios``). Rows:
wall time per campaign, and per scenario the fraction of parameters whose 95 % interval covers the truth, the fraction
marked suspect and the fraction covered-or-suspect (target 100 %: a parameter that misses the truth must be suspect),
plus the no-disturbance scenario's suspect fraction (target <= 10 %)."""
from __future__ import annotations

import time

from hindrax_tools.commands.scenarios import run_case, summarise


def run(quick: bool = False) -> list[dict]:
    """Run this benchmark (``quick``: the reduced CI variant); returns its result rows."""
    scenarios = ("thrust_0.90",) if quick else ("none", "thrust_0.90", "reverse_weak")
    dofs = ("surge",)
    levels = 2
    results, rows = [], []
    for sc in scenarios:
        t0 = time.monotonic()
        results.append(run_case(None, sc, 1, dofs, levels))
        rows.append({"name": f"{sc} campaign wall time ({'+'.join(dofs)}, {levels} levels)",
                     "value": round(time.monotonic() - t0, 1), "unit": "s"})
    for sc, s in summarise(results).items():
        n = max(s["cases"], 1)
        rows.append({"name": f"{sc}: interval covers truth", "value": round(100 * s["covered"] / n, 1), "unit": "%"})
        rows.append({"name": f"{sc}: marked suspect", "value": round(100 * s["suspect"] / n, 1), "unit": "%",
                     "target": "<= 10" if sc == "none" else ""})
        rows.append({"name": f"{sc}: covered or suspect", "value": round(100 * s["ok"] / n, 1), "unit": "%",
                     "target": "100"})
    return rows
