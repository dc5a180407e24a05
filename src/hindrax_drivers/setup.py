"""ament_python package hindrax_drivers (colcon on the Pi; editable pip install in the dev venv).

Python dependencies are declared once, in the repository's requirements.txt (dev venv) and
package.xml (rosdep on the Pi); they are deliberately not repeated here.

Installed (colcon): every node as a console script in ``lib/hindrax_drivers`` (``ros2 run
hindrax_drivers <node>``; setup.cfg puts scripts there), the vehicle file in
``share/hindrax_drivers/config/hindrax.yaml`` (``config`` is a symlink to the repository's
``ros_ws/config``, the one vehicle file), the virtual pool's truth files beside it in
``share/hindrax_drivers/config/truth`` (``truth/scenarios``: the scenario suite; read by the
simulator of ``hindrax run``, ``hindrax bringup --sim`` and ``simulator_node``, never by a vehicle
node) and the launch files in ``share/hindrax_drivers/launch``.
"""
from glob import glob
from pathlib import Path

from setuptools import find_packages, setup

PACKAGE = "hindrax_drivers"
HERE = Path(__file__).resolve().parent

#: console script -> module with main(); the names `ros2 run hindrax_drivers <name>` and launch
#: files use.
NODES = {
    "dvl75_node": "hindrax_drivers.dvl75.node",
    "ping1d_node": "hindrax_drivers.ping1d.node",
    "ms5837_node": "hindrax_drivers.ms5837.node",
    "icm20948_node": "hindrax_drivers.icm20948.node",
    "esc_node": "hindrax_drivers.pca9685.node",
    "allocation_node": "hindrax_drivers.allocation.node",
    "recorder_node": "hindrax_drivers.recording.recorder_node",
    "player_node": "hindrax_drivers.recording.player_node",
    "static_tf_node": "hindrax_drivers.tf.node",
    "supervisor_node": "hindrax_drivers.supervisor.node",
    "output_guard_node": "hindrax_drivers.guard.node",
    "gateway_node": "hindrax_drivers.gateway.node",
}
# A node whose module is not in this checkout is not installed (no entry point to a missing module).
NODES = {name: mod for name, mod in NODES.items()
         if (HERE / (mod.replace(".", "/") + ".py")).is_file()}
#: composed processes (hindrax_drivers.layout.composition: several nodes, one process):
#: console script -> module:function
GROUPS = {
    "sensors_node": "hindrax_drivers.layout.composition:sensors_main",
    "actuation_node": "hindrax_drivers.layout.composition:actuation_main",
    # not a node: the systemd units' ExecStopPost= (docker/hindrax*.service), no ROS
    "outputs_off": "hindrax_drivers.guard.outputs_off:main",
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
        (f"share/{PACKAGE}/config", _files("config/*.yaml") + _files("config/*.xml")),
        (f"share/{PACKAGE}/config/truth", _files("config/truth/*.yaml")),
        (f"share/{PACKAGE}/config/truth/scenarios", _files("config/truth/scenarios/*.yaml")),
        (f"share/{PACKAGE}/launch", _files("launch/*.launch.xml")),
    ],
    zip_safe=True,
    maintainer="Hindrax onboard team",
    maintainer_email="dev@hindrax.invalid",
    description="Hindrax ROV drivers, emulators, thrust allocation, configuration and recording",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [f"{name} = {mod}:main" for name, mod in NODES.items()]
        + [f"{name} = {target}" for name, target in GROUPS.items()],
    },
)
