"""Reproducibility benchmark: the main job (``hindrax run``, the ROS graph in lock-step) run twice with the same
options, quiet and beside six CPU-bound processes (:func:`.participant_churn.cpu_bound_neighbours`, on 2 cores a
load of 8 and more), and the two ``identification.yaml`` compared value by value (README: the same table on any
machine). Only ``provenance.date`` and ``provenance.bag`` (the run's folder) may differ.

quick: heave and yaw, 2 levels; full: every DOF, the default levels (``make run``'s campaign). Rows: the entries
that differ (target 0; the note names the first ones), the wall time of each run and the 1-minute load beside the
busy processes."""
from __future__ import annotations

import os
import subprocess
import tempfile
import time
from pathlib import Path

import yaml

from hindrax_common.config import DOFS
from hindrax_common.testing import own_domain_env, python_executable
from . import run_alone
from .participant_churn import cpu_bound_neighbours

#: CPU-bound processes beside the second run (issue 72.4: six busy loops on 2 cores)
NEIGHBOURS = 6
#: what differs between two runs by construction: when and where they were written
RUN_KEYS = ("date", "bag")


def comparable(path: Path) -> dict:
    """``identification.yaml`` at ``path`` without :data:`RUN_KEYS` of its provenance."""
    doc = yaml.safe_load(path.read_text())
    for key in RUN_KEYS:
        doc.get("provenance", {}).pop(key, None)
    return doc


def differences(a, b, where: str = "") -> list[str]:
    """Dotted keys (list items by index) whose values differ between ``a`` and ``b`` (exact comparison)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return [d for k in sorted(set(a) | set(b), key=str)
                for d in differences(a.get(k), b.get(k), f"{where}.{k}" if where else str(k))]
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        return [d for i, (x, y) in enumerate(zip(a, b)) for d in differences(x, y, f"{where}[{i}]")]
    return [] if a == b or (a != a and b != b) else [where]  # NaN equals NaN here


def _main_job(out: Path, dofs: str, levels: list[str]) -> float:
    """One ``hindrax run`` into ``out``; returns its wall time, s. Raises RuntimeError when it fails."""
    t0 = time.monotonic()
    proc = subprocess.run([python_executable(), "-m", "hindrax_tools.cli", "run", "--dofs", dofs, *levels,
                           "--seed", "1", "--out", str(out)], env=own_domain_env(), capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"hindrax run --dofs {dofs} failed: {(proc.stdout + proc.stderr)[-2000:]}")
    return time.monotonic() - t0


def run(quick: bool = False) -> list[dict]:
    """Run this benchmark (``quick``: heave and yaw, 2 levels); returns its result rows."""
    dofs, levels = ("heave,yaw", ["--levels", "2"]) if quick else (",".join(DOFS), [])
    with tempfile.TemporaryDirectory(prefix="hindrax-bench-repro-") as tmp:
        quiet_s = _main_job(Path(tmp) / "quiet", dofs, levels)
        with cpu_bound_neighbours(NEIGHBOURS):
            busy_s = _main_job(Path(tmp) / "busy", dofs, levels)
            load = os.getloadavg()[0]
        diff = differences(comparable(Path(tmp) / "quiet" / "identification.yaml"),
                           comparable(Path(tmp) / "busy" / "identification.yaml"))
    what = f"{dofs}, {'2 levels' if levels else 'default levels'}"
    return [{"name": f"identification.yaml entries differing, quiet vs beside {NEIGHBOURS} busy loops",
             "value": len(diff), "unit": "", "target": "0",
             "note": f"{what}; " + (", ".join(diff[:5]) + (" ..." if len(diff) > 5 else "") if diff else
                                   "values, intervals and verdicts identical")},
            {"name": "main job wall time, quiet", "value": round(quiet_s, 1), "unit": "s"},
            {"name": f"main job wall time beside {NEIGHBOURS} busy loops", "value": round(busy_s, 1), "unit": "s",
             "note": f"1-minute load {load:.1f} at its end"}]


if __name__ == "__main__":
    raise SystemExit(run_alone(run))
