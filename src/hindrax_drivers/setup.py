"""ament_python package hindrax_drivers (colcon on the Pi; editable pip install in the dev venv).
Dependencies and metadata: package.xml (rosdep on the Pi) and requirements.txt (dev venv), not here.

Installed (colcon): every device node and the static TF as a console script in ``lib/hindrax_drivers``
(``ros2 run hindrax_drivers <node>``; setup.cfg puts scripts there)."""
from pathlib import Path

from setuptools import find_packages, setup

PACKAGE = "hindrax_drivers"
HERE = Path(__file__).resolve().parent

#: console script -> module with main(); the names `ros2 run hindrax_drivers <name>` and launch files use.
NODES = {
    "dvl75_node": "hindrax_drivers.dvl75.node",
    "ping1d_node": "hindrax_drivers.ping1d.node",
    "ms5837_node": "hindrax_drivers.ms5837.node",
    "icm20948_node": "hindrax_drivers.icm20948.node",
    "esc_node": "hindrax_drivers.pca9685.node",
    "static_tf_node": "hindrax_drivers.tf.node",
}
# A node whose module is not in this checkout is not installed (no entry point to a missing module).
NODES = {name: mod for name, mod in NODES.items() if (HERE / (mod.replace(".", "/") + ".py")).is_file()}

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
    ],
    entry_points={
        "console_scripts": [f"{name} = {mod}:main" for name, mod in NODES.items()],
    },
)
