"""ament_python package hindrax_drivers (colcon on the Pi; editable pip install in the dev venv).

Python dependencies are declared once, in the repository's requirements.txt (dev venv) and package.xml
(rosdep on the Pi); they are deliberately not repeated here.
"""
from setuptools import find_packages, setup

PACKAGE = "hindrax_drivers"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
    ],
    zip_safe=True,
    maintainer="Hindrax onboard team",
    maintainer_email="dev@hindrax.invalid",
    description="Hindrax ROV device drivers, emulators, thrust allocation, configuration and recording",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
        ],
    },
)
