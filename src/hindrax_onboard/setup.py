"""ament_python package hindrax_onboard (the vehicle; colcon on the Pi, pip -e in the venv). Metadata: package.xml."""
from glob import glob

from setuptools import find_packages, setup

PACKAGE = "hindrax_onboard"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/launch", sorted(glob("launch/*.launch.xml"))),
        (f"share/{PACKAGE}/foxglove", sorted(glob("foxglove/*.json"))),
    ],
    entry_points={
        "console_scripts": [
            "identification_node = hindrax_onboard.identification.online.node:main",
            "controller_node = hindrax_onboard.control.node:main",
            "ident_control_node = hindrax_onboard.composition:ident_control_main",
            "ident_record_node = hindrax_onboard.composition:ident_record_main",
        ],
    },
)
