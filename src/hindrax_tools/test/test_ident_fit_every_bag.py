"""``hindrax ident fit`` on every bag committed to the repository.

Each committed bag (``src/*/test/data/*``) is run through the in-process CLI once per pair of (wrench topic,
velocity topic) of an accepted type it carries, with RuntimeWarning turned into an error and any other warning
raised in the project's own code counted as a failure (third-party deprecation notices on import are not ours):
the command either fits (exit 0) or refuses with exit 1 and exactly one ``ident fit:`` line; never a traceback.
These bags are short driver recordings (3-4 s), so today every pair ends in a one-line refusal (frames, too
little data, an empty topic): the readers and checks run on real recorded message streams.
The piloted virtual-pool bags that do fit are covered, with the same filter, by ``test_ident_fit.py``.
"""
from __future__ import annotations

import itertools
import warnings
from pathlib import Path

import pytest

from hindrax_common.config import default_config_path
from hindrax_bringup.recording.reader import BagReader
from hindrax_tools import cli
from hindrax_fit.bag_input.any_topics import ACCEPTED

pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")

ROOT = Path(__file__).resolve().parents[3]
BAGS = sorted(p.parent for p in ROOT.glob("src/*/test/data/*/metadata.yaml"))


def _pairs(bag: Path) -> list[tuple[str, str]]:
    topics = BagReader(bag).topics
    wrench = sorted(t for t, ty in topics.items() if ty in ACCEPTED["wrench"])
    velocity = sorted(t for t, ty in topics.items() if ty in ACCEPTED["velocity"])
    return list(itertools.product(wrench, velocity))


def test_the_repository_has_committed_bags_with_force_and_velocity():
    """The test below is not vacuous: bags exist and carry at least one (wrench, velocity) pair each."""
    assert len(BAGS) >= 3, BAGS
    assert all(_pairs(b) for b in BAGS), {b.name: _pairs(b) for b in BAGS}


@pytest.mark.parametrize("bag", BAGS, ids=lambda p: p.name)
def test_ident_fit_on_a_committed_bag_is_clean(bag, tmp_path, capsys):
    """Every (wrench, velocity) choice: exit 0, or exit 1 with one ``ident fit:`` line; no traceback, no warning."""
    for k, (wrench, velocity) in enumerate(_pairs(bag)):
        argv = ["ident", "fit", str(bag), "--wrench-topic", wrench, "--velocity-topic", velocity,
                "--config", str(default_config_path()), "--out", str(tmp_path / f"out{k}")]  # results never share
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            warnings.simplefilter("error", RuntimeWarning)
            rc = cli.main(argv)
        out = capsys.readouterr()
        ours = [f"{w.filename}:{w.lineno}: {w.message}" for w in caught if "/hindrax_" in w.filename]
        assert not ours, (wrench, velocity, ours)
        assert "Traceback" not in out.err + out.out, (wrench, velocity, out.err)
        assert rc in (0, 1), (wrench, velocity, rc, out.err)
        if rc == 1:
            lines = out.err.strip().splitlines()
            assert len(lines) == 1 and lines[0].startswith("ident fit: "), (wrench, velocity, out.err)
