"""Fixtures of the system tests: the colcon install of the workspace, built once and shared.

``colcon_install`` builds a copy of the repository's workspace with ``make ros-install`` (colcon against the venv's
ROS wheels, as the vehicle builds it against /opt/ros/jazzy; about 60 s on a shared two-core machine with the
compiles of hindrax_msgs taken from ``make setup``'s ccache, twice that without) and returns the install space with
the environment of a shell that sourced it. The build goes to
``build/colcon-test/<hash of its inputs>/`` under a file lock: the pytest-xdist workers (and later runs with the
same sources) use the same build instead of repeating it; any change to the inputs (src/ without tests,
ros_ws/config, the Makefile, the requirements, the venv) makes a new one.
"""
from __future__ import annotations

import fcntl
import hashlib
import os
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
VENV = Path(sys.prefix)
CACHE = REPO / "build" / "colcon-test"
_IGNORE = ("__pycache__", "*.egg-info", "*.pyc", "test")


@dataclass(frozen=True)
class ColconInstall:
    """A colcon install: ``root`` (the copied repository), ``prefix`` (``<root>/ros_ws/install``) and ``env`` (the
    environment after ``source .venv/bin/activate && source <prefix>/setup.bash``, discovery on loopback, this
    worker's ROS domain)."""

    root: Path
    prefix: Path
    env: dict

    def share(self, package: str) -> Path:
        return self.prefix / "share" / package

    def executable(self, package: str, name: str) -> Path:
        return self.prefix / "lib" / package / name


def _inputs_hash(extra: str) -> str:
    h = hashlib.sha256(f"{VENV}\n{extra}\n".encode())
    files = [REPO / "Makefile", REPO / "requirements.txt", REPO / "requirements-colcon.txt", REPO / "constraints.txt"]
    for top in (REPO / "src", REPO / "ros_ws" / "config"):
        for dirpath, dirnames, filenames in os.walk(top, followlinks=False):
            dirnames[:] = sorted(d for d in dirnames
                                 if d not in ("__pycache__", "test") and not d.endswith(".egg-info"))
            files += [Path(dirpath) / f for f in sorted(filenames) if not f.endswith(".pyc")]
    for f in files:
        h.update(str(f.relative_to(REPO)).encode())
        h.update(os.readlink(f).encode() if f.is_symlink() else f.read_bytes())
    return h.hexdigest()[:16]


def copy_workspace(root: Path) -> None:
    """The repository's src/ (tests left out) and ros_ws/config, with ros_ws/src -> ../src, and the Makefile."""
    shutil.copytree(REPO / "src", root / "src", symlinks=True, ignore=shutil.ignore_patterns(*_IGNORE))
    shutil.copytree(REPO / "ros_ws" / "config", root / "ros_ws" / "config")
    (root / "ros_ws" / "src").symlink_to("../src")
    shutil.copy2(REPO / "Makefile", root / "Makefile")


def build_env() -> dict:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("AMENT_", "COLCON_", "PYTHONPATH"))}
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    return env


def sourced_env(prefix: Path) -> dict:
    """The environment of a shell that activated the venv and sourced ``prefix/setup.bash``."""
    out = subprocess.run(["bash", "-c", f"source {VENV}/bin/activate && source {prefix}/setup.bash && env -0"],
                         env=build_env(), capture_output=True, timeout=60, check=True).stdout
    env = dict(kv.split("=", 1) for kv in out.decode().split("\0") if "=" in kv)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env["ROS_DOMAIN_ID"] = os.environ.get("ROS_DOMAIN_ID", "0")
    env["PYTHONUNBUFFERED"] = "1"
    return env


def ccache_settings() -> dict[str, str]:
    """What scripts/ccache_env.sh exports (the settings scripts/setup_venv.sh compiled with), run
    by bash in the repository as setup sources it."""
    r = subprocess.run(["bash", "-c", ". scripts/ccache_env.sh && env -0"], cwd=REPO,
                       env={"PATH": os.defpath}, capture_output=True, text=True, check=True,
                       timeout=30)
    exported = dict(v.split("=", 1) for v in r.stdout.split("\0") if "=" in v)
    return {k: v for k, v in exported.items() if k.startswith("CCACHE_") or k == "PYTHONHASHSEED"}


def make_ros_install(root: Path, colcon_args: str = "") -> subprocess.CompletedProcess:
    """``make ros-install`` in ``root`` (``-o setup``: the venv is set up already), optionally
    with COLCON_ARGS.

    hindrax_msgs' C and C++ compiles go through the venv's ccache with ``make setup``'s cache
    and settings (scripts/ccache_env.sh, :func:`ccache_settings`): a compile of the same
    source, headers and flags takes the object setup's compile made, any other compiles
    (measured: 173 of 175 taken, the colcon build's CPU 79 -> 40 s). rosidl's generators, CMake,
    colcon and the install run as on the vehicle, with the Makefile's command a user runs."""
    env = build_env()
    ccache = VENV / "bin" / "ccache"
    if ccache.exists():
        env.update(CMAKE_C_COMPILER_LAUNCHER=str(ccache), CMAKE_CXX_COMPILER_LAUNCHER=str(ccache),
                   **ccache_settings())
    cmd = ["make", "-o", "setup", "ros-install", f"VENV={VENV}"] + ([f"COLCON_ARGS={colcon_args}"] if colcon_args
                                                                      else [])
    return subprocess.run(cmd, cwd=root, env=env, capture_output=True, text=True, timeout=1200)


@pytest.fixture(scope="session")
def colcon_tools():
    """The helpers behind ``colcon_install`` (copy_workspace, make_ros_install, sourced_env), for a test that builds
    its own variant (e.g. ``--symlink-install``)."""
    import types

    return types.SimpleNamespace(copy_workspace=copy_workspace, make_ros_install=make_ros_install,
                                 sourced_env=sourced_env)


@pytest.fixture(scope="session")
def colcon_install() -> ColconInstall:
    """The shared colcon install of the workspace (module docstring)."""
    CACHE.mkdir(parents=True, exist_ok=True)
    (CACHE / "COLCON_IGNORE").write_text("copies of the workspace built by the tests (test/conftest.py)\n")
    key = _inputs_hash("ros-install")
    root = CACHE / key
    with open(CACHE / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # another worker may be building the same inputs: wait for it
        try:
            if not (root / "done").exists():
                shutil.rmtree(root, ignore_errors=True)
                root.mkdir()
                copy_workspace(root)
                r = make_ros_install(root)
                assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
                print("colcon:", r.stdout.strip().splitlines()[-1] if r.stdout.strip() else "")
                (root / "done").write_text(r.stdout)
                for old in CACHE.iterdir():  # keep this build only
                    if old.is_dir() and old != root:
                        shutil.rmtree(old, ignore_errors=True)
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)
    prefix = root / "ros_ws" / "install"
    return ColconInstall(root, prefix, sourced_env(prefix))


@pytest.fixture(scope="session")
def pool_day_model() -> dict:
    """The README pool day's identification, for the session's later tests: test_pool_day.py's README walk stores the
    ``identification.yaml`` of its ``ident bag`` under ``"model"`` (Path), once its heave is checked against the pool's
    truth. The rehearsal (test_pool_rehearsal.py) launches the block's second day with it instead of running a heave
    campaign and its fit again (they run in a row on one worker: the vehicle_launch group, conftest.py; the second
    campaign and fit took about 100 of the group's 690 s, loaded); run alone, it makes its own."""
    return {}
