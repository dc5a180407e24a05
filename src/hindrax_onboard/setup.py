"""ament_python package hindrax_ident (colcon on the Pi; editable pip install in the dev venv).

Python dependencies are declared once, in the repository's requirements.txt (dev venv) and
package.xml (rosdep on the Pi); they are deliberately not repeated here. Colcon also installs
``bin/hindrax``, a wrapper on PATH once ``install/setup.bash`` is sourced.
"""
import sys
from glob import glob
from pathlib import Path

from setuptools import find_packages, setup

PACKAGE = "hindrax_ident"


#: bin/hindrax only for what colcon runs: `setup.py install` (a plain build), `setup.py develop ...
#: symlink_data` (colcon build --symlink-install; symlink_data is colcon's own command, which links
#: the data files colcon read from `setup.py --dry-run` beforehand, so that run must list it too). A
#: pip install (editable or wheel) already puts the console script itself in the environment's bin/,
#: which the wrapper must not replace.
COLCON_COMMANDS = {"install", "symlink_data", "--dry-run"}
BIN = [("bin", ["bin/hindrax"])] if COLCON_COMMANDS & set(sys.argv[1:]) else []


def _files(pattern: str) -> list[str]:
    return sorted(p for p in glob(pattern) if Path(p).is_file())


setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/launch", _files("launch/*.launch.xml")),
        (f"share/{PACKAGE}/foxglove", _files("foxglove/*.json")),
    ] + BIN,
    zip_safe=True,
    maintainer="Hindrax onboard team",
    maintainer_email="dev@hindrax.invalid",
    description="Hindrax ROV hydrodynamic identification, simulator and the hindrax command",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "hindrax = hindrax_tools.cli:main",
            "identification_node = hindrax_onboard.identification.online.node:main",
            "simulator_node = hindrax_sim.node:main",
            "controller_node = hindrax_onboard.control.node:main",
            "ident_control_node = hindrax_onboard.composition:ident_control_main",
            "ident_record_node = hindrax_onboard.composition:ident_record_main",
        ],
    },
)
