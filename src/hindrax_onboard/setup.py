"""ament_python package hindrax_onboard: what runs on the vehicle above the drivers (colcon on the Pi; editable pip
install in the dev venv). Python dependencies are declared once, in the repository's requirements.txt (dev venv) and
package.xml (rosdep on the Pi); they are deliberately not repeated here.
"""
from glob import glob
from pathlib import Path

from setuptools import find_packages, setup

PACKAGE = "hindrax_onboard"


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
    ],
    zip_safe=True,
    maintainer="Hindrax onboard team",
    maintainer_email="dev@hindrax.invalid",
    description="Hindrax ROV onboard: estimation, vehicle state, control, online identification",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "identification_node = hindrax_onboard.identification.online.node:main",
            "controller_node = hindrax_onboard.control.node:main",
            "ident_control_node = hindrax_onboard.composition:ident_control_main",
            "ident_record_node = hindrax_onboard.composition:ident_record_main",
        ],
    },
)
