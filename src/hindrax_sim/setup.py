"""ament_python package hindrax_sim (topside; editable pip install in the dev venv). Metadata: package.xml."""
from setuptools import find_packages, setup

PACKAGE = "hindrax_sim"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
    ],
    entry_points={"console_scripts": ["simulator_node = hindrax_sim.node:main"]},
)
