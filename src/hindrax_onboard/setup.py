"""ament_python package hindrax_onboard (the vehicle; colcon on the Pi, pip -e in the venv). Metadata: package.xml.
Colcon also installs bin/hindrax (on PATH)."""
import sys
from glob import glob

from setuptools import find_packages, setup

PACKAGE = "hindrax_onboard"

#: bin/hindrax only for what colcon runs: `setup.py install` (a plain build), `setup.py develop ... symlink_data`
#: (--symlink-install; colcon links the data files it read from `setup.py --dry-run`, so that run lists it too). A pip
#: install already puts the console script itself in the environment's bin/, which the wrapper must not replace.
COLCON_COMMANDS = {"install", "symlink_data", "--dry-run"}
BIN = [("bin", ["bin/hindrax"])] if COLCON_COMMANDS & set(sys.argv[1:]) else []

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/launch", sorted(glob("launch/*.launch.xml"))),
        (f"share/{PACKAGE}/foxglove", sorted(glob("foxglove/*.json"))),
    ] + BIN,
    entry_points={
        "console_scripts": [
            "identification_node = hindrax_onboard.identification.online.node:main",
            "controller_node = hindrax_onboard.control.node:main",
            "ident_control_node = hindrax_onboard.composition:ident_control_main",
            "ident_record_node = hindrax_onboard.composition:ident_record_main",
            "hindrax = hindrax_onboard.cli:main",
        ],
    },
)
