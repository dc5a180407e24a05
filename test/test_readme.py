"""The README is a tour (issue 28): short, readable lines, measurements in docs/results.md, every command it names
exists in ``hindrax --help``."""
from __future__ import annotations

import re
import subprocess
from pathlib import Path

from hindrax_common.testing import child_env, python_executable

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")


def prose_lines(text: str) -> list[tuple[int, str]]:
    """(line number, line) outside fenced code blocks."""
    out, fenced = [], False
    for n, line in enumerate(text.splitlines(), 1):
        if line.startswith("```"):
            fenced = not fenced
            continue
        if not fenced:
            out.append((n, line))
    return out


def test_the_readme_is_short_and_its_lines_readable():
    assert len(README.splitlines()) < 400
    long = [f"README.md:{n}: {len(line)} characters" for n, line in prose_lines(README) if len(line) > 200]
    assert not long, "\n".join(long)


def test_the_readme_holds_no_measurement_history():
    """Measured figures live in docs/results.md (written by the commands); no 'measured at commit X' notes here."""
    assert not re.search(r"\bat commit [0-9a-f]{7}", README)
    assert "docs/results.md" in README


def test_every_hindrax_command_in_the_readme_exists():
    """Each ``hindrax <command>`` the README names is a subcommand of the installed CLI."""
    names = set(re.findall(r"`hindrax ([a-z][a-z0-9-]+)", README))
    assert len(names) >= 10
    helptext = subprocess.run([python_executable(), "-m", "hindrax_tools.cli", "--help"],
                              env=child_env(),
                              capture_output=True, text=True, timeout=60).stdout
    missing = sorted(n for n in names if not re.search(rf"\b{re.escape(n)}\b", helptext))
    assert not missing, f"README names hindrax commands the CLI does not have: {missing}"
