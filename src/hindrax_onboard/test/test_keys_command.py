"""``hindrax keys``: the vehicle's operator key, mode 0600, and where its topside copy goes; never replaced
silently."""
from __future__ import annotations

import stat
import subprocess
import sys

from hindrax_bringup.gateway.operator_signing import load_key
from hindrax_common.testing import child_env


def keys(tmp_path, *args):
    return subprocess.run([sys.executable, "-m", "hindrax_onboard.cli", "keys", *args],
                          capture_output=True, text=True,
                          env=child_env(HINDRAX_KEYS_DIR=str(tmp_path / "keys")), timeout=120)


def test_keys_makes_a_0600_key_says_where_the_copy_goes_and_keeps_it(tmp_path):
    r = keys(tmp_path)
    path = tmp_path / "keys" / "hindrax.key"  # the vehicle file's vehicle.name
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines()[0] == f"hindrax: operator key written to {path} (mode 0600)"
    assert "copy it to the operator's PC" in r.stdout
    assert stat.S_IMODE(path.stat().st_mode) == 0o600 and len(load_key(path)) == 32
    first = path.read_text()
    r = keys(tmp_path)
    assert r.returncode == 1 and len(r.stderr.strip().splitlines()) == 1 and "use --force" in r.stderr, r.stderr
    assert path.read_text() == first
    assert keys(tmp_path, "--vehicle", "bravo").returncode == 0 and (tmp_path / "keys" / "bravo.key").exists()
