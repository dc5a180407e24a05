"""Identification benchmark: wall time of the simulated campaign and the accuracy of each method.

Surge + heave, 3 levels (the acceptance tests run 2), in both modes: ``make bench`` has to stay
short; the all-DOF campaign's wall time and accuracy are ``make run``'s, in docs/results.md (section
``run``). Rows: wall time (target < 600 s for the full campaign), pool time per DOF, and per DOF the
relative error of the inertia and quadratic damping for the reported (output-error, the fit core)
estimate, the equation-error batch LS, the online RLS and the steady-state LS, with the pool time
each needed (RLS: until converged; steady-state: until the end of the last window used)."""
from __future__ import annotations

import math
import time

from hindrax_common.config import default_config_path, load_config
from hindrax_sim.campaign import Campaign
from hindrax_fit.fit.campaign_fit import identify_all_with_errors


def run(quick: bool = False) -> list[dict]:
    """Run this benchmark (``quick``: the reduced CI variant); returns its result rows."""
    cfg = load_config(default_config_path())
    dofs = ("surge", "heave")
    t0 = time.monotonic()
    rec = Campaign(cfg, dofs=dofs, levels=3).run()
    idents, _ = identify_all_with_errors(rec, cfg)
    wall = time.monotonic() - t0
    rows = [{"name": "campaign + identification wall time", "value": round(wall, 1), "unit": "s",
             "target": "< 180", "note": f"{rec.t_s[-1]:.0f} s simulated"}]
    for dof, r in idents.items():
        target = "5 %" if dof in ("surge", "sway", "heave") else "10 %"
        rows.append({"name": f"{dof} pool time", "value": round(r.pool_time_s, 1), "unit": "s"})
        quad = [n for n in r.names if n.startswith("quadratic")]
        for name in ["inertia"] + quad:
            for src in ("final", "equation_error", "online", "steady"):
                e = r.relative_error(name, src)
                if math.isnan(e):
                    continue
                label = {"final": "output-error", "equation_error": "batch LS", "online": "RLS",
                         "steady": "steady-state LS"}[src]
                rows.append({"name": f"{dof} {name} error ({label})", "value": round(100 * e, 2), "unit": "%",
                             "target": target if src == "final" else ""})
        rows.append({"name": f"{dof} pool time to RLS convergence", "value": r.rls_time_s if r.rls_time_s is None
                     else round(r.rls_time_s, 1), "unit": "s"})
        rows.append({"name": f"{dof} pool time used by steady-state LS",
                     "value": None if r.steady_time_s is None else round(r.steady_time_s, 1), "unit": "s",
                     "note": r.steady_note})
    return rows
