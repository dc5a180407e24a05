"""CLI start-up benchmark: wall time of ``hindrax --help`` (target 0.3 s on the development machine).

Each run is a fresh process, the ``hindrax`` console script of this interpreter's environment (or
``python -m hindrax_tools.cli`` when the script is not installed), started with :mod:`subprocess` and timed from spawn
to exit with ``time.perf_counter``. The value is the median of the runs (one unmeasured warm-up run first, so the file
cache is warm as for an engineer typing commands). For comparison the row ``hindrax_config_check`` times
``hindrax config check`` of the repository's vehicle file (numpy + yaml, no ROS). What ``--help`` may import is checked
by ``src/hindrax_tools/test/test_cli_help.py``, not here."""
from __future__ import annotations

import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

from hindrax_common.config import default_config_path

TARGET_S = 0.3


def wall_times_s(argv: list[str], runs: int, check: bool = True) -> list[float]:
    """Wall time (s) of ``runs`` fresh processes of ``argv`` after one warm-up run. Raises
    ``subprocess.CalledProcessError`` when ``check`` and the command exits non-zero."""
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    subprocess.run(argv, env=env, check=check, capture_output=True, timeout=120)
    out = []
    for _ in range(runs):
        t0 = time.perf_counter()
        subprocess.run(argv, env=env, check=check, capture_output=True, timeout=120)
        out.append(time.perf_counter() - t0)
    return out


def run(quick: bool = False) -> list[dict]:
    """Run this benchmark (``quick``: the reduced CI variant); returns its result rows."""
    runs = 3 if quick else 11
    script = Path(sys.executable).with_name("hindrax")  # else the module of the console script
    base = [str(script)] if script.is_file() else [sys.executable, "-m", "hindrax_tools.cli"]
    help_s = wall_times_s(base + ["--help"], runs)
    rows = [{"name": "hindrax_help_wall_s", "value": statistics.median(help_s), "unit": "s",
             "target": f"< {TARGET_S:g}",
             "note": f"median of {runs} fresh processes (min {min(help_s):.3f}, max {max(help_s):.3f})"}]
    check_s = wall_times_s(base + ["config", "check", str(default_config_path())], max(3, runs // 2), check=False)
    rows.append({"name": "hindrax_config_check_wall_s", "value": statistics.median(check_s), "unit": "s",
                 "note": "median; imports the configuration schema (numpy, yaml), no ROS"})
    return rows
