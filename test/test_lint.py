"""Lint and type checks as tests, so that `make test` (and CI's .ci/run) runs them (docs/architecture.md §12).

* ruff with the repository's rules (pyproject.toml ``[tool.ruff]``: pyflakes F, pycodestyle E/W at 120 columns,
  docstrings D with the pep257 convention, imports at the top) passes on every Python file of the repository;
* mypy (pyproject.toml ``[tool.mypy]``) passes on the pure cores: the device protocols, the configuration, the
  thrust allocation and the estimation package;
* each tool is really configured to catch what it claims: a planted unused import, function-local import,
  over-long line, missing docstring and type error are reported (a configuration that silently selects nothing
  would pass the first two tests).
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _run(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", *args], cwd=cwd, capture_output=True, text=True, timeout=300)


def test_ruff_passes_on_the_repository():
    res = _run("ruff", "check", "--no-cache", "--output-format", "concise", ".")
    assert res.returncode == 0, res.stdout + res.stderr


def test_mypy_passes_on_the_pure_cores():
    res = _run("mypy", "--config-file", str(ROOT / "pyproject.toml"))
    assert res.returncode == 0, res.stdout + res.stderr
    assert "Success" in res.stdout


def test_ruff_configuration_reports_unused_and_local_imports_long_lines_and_missing_docstrings(tmp_path):
    bad = tmp_path / "hindrax_bad.py"
    bad.write_text('"""A module."""\nimport os\n\n\ndef public():\n    import json\n\n    return json.dumps("'
                   + "x" * 120 + '")\n')
    res = _run("ruff", "check", "--no-cache", "--output-format", "concise", "--config", str(ROOT / "pyproject.toml"),
               str(bad))
    assert res.returncode == 1
    for code in ("F401", "E501", "D103", "PLC0415"):
        assert code in res.stdout, (code, res.stdout)


def test_mypy_configuration_reports_a_type_error(tmp_path):
    bad = tmp_path / "hindrax_bad.py"
    bad.write_text("x: int = 'not an int'\n")
    res = _run("mypy", "--config-file", str(ROOT / "pyproject.toml"), "--cache-dir", str(tmp_path / "cache"), str(bad))
    assert res.returncode == 1
    assert "Incompatible types in assignment" in res.stdout
