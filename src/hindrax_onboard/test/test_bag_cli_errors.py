"""Every bag command on a missing, empty, truncated or non-MCAP file says so in one line
on stderr and exits 1 (``bag info``, ``bag play`` and ``ident fit`` printed a 20-29 line traceback)."""
from __future__ import annotations

from pathlib import Path

import pytest

from hindrax_onboard.cli import main as cli_main

DATA = Path(__file__).resolve().parents[2] / "hindrax_bringup" / "test" / "data" / "sensors_4s" / "sensors_4s_0.mcap"


def _make(kind: str, tmp_path: Path) -> Path:
    path = tmp_path / f"{kind}.mcap"
    if kind == "not_mcap":
        path.write_text("timestamp,depth\n0.0,1.2\n")
    elif kind == "empty":
        path.write_bytes(b"")
    elif kind == "truncated":  # the recorder lost power inside its first chunk: magic, header, no message
        path.write_bytes(DATA.read_bytes()[:3000])
    return path  # "missing": never created


@pytest.mark.parametrize("kind", ["missing", "empty", "truncated", "not_mcap"])
@pytest.mark.parametrize("command", [["bag", "info"], ["bag", "play"], ["bag", "recover"], ["ident", "fit"]])
def test_bad_bag_file_is_one_line_and_exit_1(command, kind, tmp_path, capsys):
    path = _make(kind, tmp_path)
    rc = cli_main([*command, str(path)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 1
    assert len(err) == 1 and path.name in err[0], err
    assert "Traceback" not in err[0]
