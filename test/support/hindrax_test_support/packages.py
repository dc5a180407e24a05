"""The repository's ament packages as setuptools sees them (test_import_structure.py, test_launch_files.py)."""
from __future__ import annotations

import os
import runpy
from pathlib import Path
from unittest import mock

#: the repository's root
ROOT = Path(__file__).resolve().parents[3]


def setup_kwargs(pkg: str) -> dict:
    """The keyword arguments ``src/<pkg>/setup.py`` passes to setuptools.setup (as colcon's ``setup.py install``)."""
    captured: dict = {}
    cwd = os.getcwd()
    os.chdir(ROOT / "src" / pkg)
    try:
        with mock.patch("setuptools.setup", lambda **kw: captured.update(kw)), \
                mock.patch("sys.argv", ["setup.py", "install"]):
            runpy.run_path("setup.py", run_name="__main__")
    finally:
        os.chdir(cwd)
    return captured
