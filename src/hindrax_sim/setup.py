"""ament_python package hindrax_sim (topside; editable pip install in the dev venv). Dependencies: package.xml."""
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
    zip_safe=True,
    maintainer="Hindrax onboard team",
    maintainer_email="dev@hindrax.invalid",
    description="Hindrax ROV virtual pool: 6-DOF simulator, emulated hardware, the graph in one process, campaign runs",
    license="Apache-2.0",
    entry_points={"console_scripts": ["simulator_node = hindrax_sim.node:main"]},
)
