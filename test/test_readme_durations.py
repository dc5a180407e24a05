"""The README's times of the long commands are the ones docs/results.md holds, which each command writes itself
(section "durations", hindrax_tools/results_doc.py): a README that says "about 1.5 minutes" beside a measured 6 fails.
"""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from hindrax_tools.results_doc import duration_rows

ROOT = Path(__file__).resolve().parents[1]

#: the README's phrase of each command's time (its minutes in group 1) and the command's row in docs/results.md
QUOTES = {
    "make setup (new .venv)": r"`make setup` \(one progress line, about (\d+) minutes the first time",
    "make ros-install": r"`make ros-install` \(the colcon workspace as the vehicle builds it, with a progress line; "
                        r"about (\d+) minutes",
}


@pytest.mark.parametrize("command", sorted(QUOTES))
def test_the_readme_quotes_the_measured_minutes(command):
    readme = " ".join((ROOT / "README.md").read_text().split())
    rows = duration_rows((ROOT / "docs" / "results.md").read_text())
    assert command in rows, f"docs/results.md has no duration of {command!r}: run it (it records itself)"
    quoted = re.search(QUOTES[command], readme)
    assert quoted, f"the README does not quote the time of {command!r} as {QUOTES[command]!r}"
    assert int(quoted.group(1)) == round(float(rows[command][2])), (command, rows[command])
