"""ament_python package hindrax_tools: the ``hindrax`` command and the benchmarks (topside; editable pip install in
the dev venv). Dependencies: package.xml. Colcon also installs ``bin/hindrax``, a wrapper on PATH once
``install/setup.bash`` is sourced.
"""
import sys

from setuptools import find_packages, setup

PACKAGE = "hindrax_tools"

#: bin/hindrax only for what colcon runs: `setup.py install` (a plain build), `setup.py develop ...
#: symlink_data` (colcon build --symlink-install; symlink_data is colcon's own command, which links
#: the data files colcon read from `setup.py --dry-run` beforehand, so that run must list it too). A
#: pip install (editable or wheel) already puts the console script itself in the environment's bin/,
#: which the wrapper must not replace.
COLCON_COMMANDS = {"install", "symlink_data", "--dry-run"}
BIN = [("bin", ["bin/hindrax"])] if COLCON_COMMANDS & set(sys.argv[1:]) else []

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
    ] + BIN,
    zip_safe=True,
    maintainer="Hindrax onboard team",
    maintainer_email="dev@hindrax.invalid",
    description="Hindrax ROV tools: the hindrax command line and the make bench benchmarks",
    license="Apache-2.0",
    entry_points={"console_scripts": ["hindrax = hindrax_tools.cli:main"]},
)
