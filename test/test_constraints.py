"""constraints.txt pins what `make setup` installs: every requirement has a pin inside its range, and the venv
the tests run in holds exactly the pinned versions (it would not if setup_venv.sh stopped passing ``-c``)."""
from __future__ import annotations

import importlib.metadata
import runpy
from pathlib import Path

from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from packaging.version import Version

REPO = Path(__file__).resolve().parents[1]


def _lines(path: Path) -> list[str]:
    return [line.split("#", 1)[0].strip() for line in path.read_text().splitlines()
            if line.split("#", 1)[0].strip()]


def _pins() -> dict[str, Version]:
    pins = {}
    for line in _lines(REPO / "constraints.txt"):
        name, _, version = line.partition("==")
        assert version, f"constraints.txt: {line!r} is not name==version"
        pins[canonicalize_name(name)] = Version(version)
    return pins


def test_every_requirement_is_pinned_inside_its_range():
    pins = _pins()
    for file in ("requirements.txt", "requirements-colcon.txt"):
        for line in _lines(REPO / file):
            req = Requirement(line)
            name = canonicalize_name(req.name)
            assert name in pins, f"{file}: {req.name} has no pin in constraints.txt"
            assert req.specifier.contains(pins[name], prereleases=True), \
                f"{file}: {req.name} pinned at {pins[name]}, outside {req.specifier}"


def test_setup_passes_the_constraints_to_pip():
    script = (REPO / "scripts" / "setup_venv.sh").read_text()
    assert "-r requirements.txt -r requirements-colcon.txt -c constraints.txt" in script


def test_the_venv_holds_the_pinned_versions():
    pins = _pins()
    installed = {canonicalize_name(d.metadata["Name"]): Version(d.version) for d in importlib.metadata.distributions()}
    wrong = {name: (str(installed[name]), str(pin)) for name, pin in pins.items()
             if name in installed and installed[name] != pin}
    assert not wrong, f"installed != pinned (re-run make setup): {wrong}"
    # what the freeze script would write now is the same set of packages the file pins
    frozen = runpy.run_path(str(REPO / "scripts" / "freeze_constraints.py"))["pins"]()
    names = {canonicalize_name(line.split("==")[0]) for line in frozen}
    assert set(pins) <= names, sorted(set(pins) - names)
