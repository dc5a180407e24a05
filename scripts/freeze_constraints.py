"""Print the pins of constraints.txt: every distribution of the running venv that pip installed from an index.

Run inside the venv after `make setup` with changed ranges: `.venv/bin/python scripts/freeze_constraints.py`
(the header comment of constraints.txt is kept by hand). Left out: what pip did not install (the message packages
that rosidl's CMake install writes, the egg-info records that the ros-jazzy-* wheels carry inside them), editable
or local installs (a ``direct_url.json``), and pip itself (setup_venv.sh upgrades it first).
"""
from __future__ import annotations

import importlib.metadata


def pins() -> list[str]:
    """Return ``name==version`` lines, sorted by lower-case name, of the pip-installed index distributions."""
    found: dict[str, str] = {}
    for dist in importlib.metadata.distributions():
        installer = (dist.read_text("INSTALLER") or "").strip()
        if installer != "pip" or dist.read_text("direct_url.json"):
            continue
        name = dist.metadata["Name"].lower()
        if name != "pip":
            found[name] = dist.version
    return [f"{name}=={found[name]}" for name in sorted(found)]


if __name__ == "__main__":
    print("\n".join(pins()))
