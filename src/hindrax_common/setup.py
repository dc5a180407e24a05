"""ament_python package hindrax_common (colcon on the Pi; editable pip install in the dev venv).
Dependencies and metadata: package.xml (rosdep on the Pi) and requirements.txt (dev venv), not here.

Installed (colcon): no executable; the vehicle file in ``share/hindrax_common/config/hindrax.yaml``
(``config`` is a symlink to the repository's ``ros_ws/config``, the one vehicle file) with the Fast DDS
profiles, the virtual pool's truth files beside it in ``share/hindrax_common/config/truth``
(``truth/scenarios``: the scenario suite; read by the simulator of ``hindrax run``, ``hindrax bringup
--sim`` and ``simulator_node``, never by a vehicle node)."""
from glob import glob
from pathlib import Path

from setuptools import find_packages, setup

PACKAGE = "hindrax_common"


def _files(pattern: str) -> list[str]:
    return sorted(p for p in glob(pattern) if Path(p).is_file())


setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", _files("config/*.yaml") + _files("config/*.xml")),
        (f"share/{PACKAGE}/config/truth", _files("config/truth/*.yaml")),
        (f"share/{PACKAGE}/config/truth/scenarios", _files("config/truth/scenarios/*.yaml")),
    ],
    entry_points={"console_scripts": []},
)
