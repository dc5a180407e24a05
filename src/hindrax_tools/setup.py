"""ament_python package hindrax_tools (topside). Metadata: package.xml. Its commands join hindrax_onboard's `hindrax`
through the hindrax.commands entry point (hindrax_onboard/cli.py)."""
from setuptools import find_packages, setup

PACKAGE = "hindrax_tools"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
    ],
    entry_points={"hindrax.commands": ["topside = hindrax_tools.cli:TOPSIDE"]},
)
