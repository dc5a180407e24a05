"""ament_python package hindrax_bringup (colcon on the Pi; editable pip install in the dev venv).
Dependencies and metadata: package.xml (rosdep on the Pi) and requirements.txt (dev venv), not here.

Installed (colcon): every node and composed process as a console script in ``lib/hindrax_bringup``
(``ros2 run hindrax_bringup <node>``; setup.cfg puts scripts there) and the launch files in
``share/hindrax_bringup/launch``."""
from glob import glob
from pathlib import Path

from setuptools import find_packages, setup

PACKAGE = "hindrax_bringup"
HERE = Path(__file__).resolve().parent

#: console script -> module with main(); the names `ros2 run hindrax_bringup <name>` and launch files use.
NODES = {
    "allocation_node": "hindrax_bringup.allocation.node",
    "recorder_node": "hindrax_bringup.recording.recorder_node",
    "player_node": "hindrax_bringup.recording.player_node",
    "supervisor_node": "hindrax_bringup.supervisor.node",
    "output_guard_node": "hindrax_bringup.guard.node",
    "gateway_node": "hindrax_bringup.gateway.node",
}
# A node whose module is not in this checkout is not installed (no entry point to a missing module).
NODES = {name: mod for name, mod in NODES.items() if (HERE / (mod.replace(".", "/") + ".py")).is_file()}
#: composed processes (hindrax_bringup.layout.composition: several nodes, one process):
#: console script -> module:function
GROUPS = {
    "sensors_node": "hindrax_bringup.layout.composition:sensors_main",
    "actuation_node": "hindrax_bringup.layout.composition:actuation_main",
    # not a node: the systemd units' ExecStopPost= (docker/hindrax*.service), no ROS
    "outputs_off": "hindrax_bringup.guard.outputs_off:main",
}


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
    ],
    entry_points={
        "console_scripts": [f"{name} = {mod}:main" for name, mod in NODES.items()]
        + [f"{name} = {target}" for name, target in GROUPS.items()],
    },
)
