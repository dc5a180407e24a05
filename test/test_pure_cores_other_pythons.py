"""The pure cores' tests under the Python the Raspberry Pi runs (3.12: Ubuntu 24.04 and the ros:jazzy image), while
the development venv is 3.11 (the ROS 2 wheels exist for cp311 only).

The cores (ESC, IMU start-up, device protocols, PCA9685 chip access, thrust curve, allocation) need no ROS: their
test files (:data:`PURE_CORE_TESTS`) run in a throwaway venv of the other interpreter that holds only
:data:`CORE_PACKAGES` at the versions of constraints.txt, with no conftest, and must all pass there.

Which interpreter: every ``python3.12`` on PATH or in pyenv's usual place (``$PYENV_ROOT`` or ``~/.pyenv``,
``versions/3.12*/bin``), the first that runs. On a machine without one the same files run the same way under this
venv's own base interpreter: that still checks that the cores need nothing but those packages (no rclpy, no
messages; what a 3.12 run needs first), and the test prints which Python it used, so a run without 3.12 never reads
as a 3.12 result. The packages come from the machine's package index (network, or a local index/wheelhouse that
pip is configured for); without one the test fails naming pip's error: it cannot say anything about 3.12 then.
"""
from __future__ import annotations

import glob
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: the driver level's package directories (what the pure cores and their tests import)
DRIVERS = os.pathsep.join(str(ROOT / "src" / p) for p in ("hindrax_common", "hindrax_drivers", "hindrax_bringup"))
TARGET = (3, 12)

#: the test files of the pure cores; each imports the core, numpy and the packages below, never rclpy or messages
PURE_CORE_TESTS = [f"src/hindrax_drivers/test/{name}.py" for name in (
    "test_esc_core", "test_esc_chip", "test_pca9685", "test_icm20948_core", "test_icm20948_protocol",
    "test_ms5837_protocol", "test_ms5837_core", "test_ping1d_protocol")] + [
    "src/hindrax_common/test/test_thrust_curve.py", "src/hindrax_bringup/test/test_allocation.py"]
#: what those files import besides the standard library (ament_index_python: the configuration finds the shipped
#: vehicle file with it; a pure-Python wheel; smbus2: an I2C burst over 32 bytes is an i2c_rdwr of smbus2.i2c_msg);
#: versions from constraints.txt
CORE_PACKAGES = ["numpy", "PyYAML", "ros-ament-index-python", "smbus2", "pytest", "hypothesis"]
#: left to the 3.11 suite: 21 s alone at load 13 on 2 cores (3^8 sign patterns), numpy arithmetic the other
#: allocation tests run too; the rest of the run takes about 45 s there
NOT_HERE = ["test_fault10_quantisation_never_rounds_into_the_deadband"]


def _version(python: str) -> tuple[tuple[int, int], str] | None:
    """(major, minor) and the real executable of ``python``, or None when it does not run (a pyenv shim of a
    version that is not selected exits non-zero)."""
    try:
        res = subprocess.run([python, "-c", "import sys; print(sys.version_info[0], sys.version_info[1], "
                              "sys.executable)"], capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired):
        return None
    if res.returncode != 0 or not res.stdout.strip():
        return None
    major, minor, exe = res.stdout.split(maxsplit=2)
    return (int(major), int(minor)), exe.strip()


def find_interpreters(version: tuple[int, int] = TARGET) -> list[str]:
    """The real executables of every ``python<major>.<minor>`` on PATH and in pyenv's versions folder that run and
    report ``version``, without duplicates, PATH first."""
    name = f"python{version[0]}.{version[1]}"
    pyenv = Path(os.environ.get("PYENV_ROOT", Path.home() / ".pyenv"))
    candidates = [shutil.which(name)] + sorted(glob.glob(str(pyenv / "versions" / f"{version[0]}.{version[1]}*"
                                                             / "bin" / name)))
    found: list[str] = []
    for c in candidates:
        if c is None:
            continue
        v = _version(c)
        if v is not None and v[0] == version and os.path.realpath(v[1]) not in map(os.path.realpath, found):
            found.append(v[1])
    return found


def _core_venv(python: str, where: Path) -> Path:
    """A venv of ``python`` in ``where`` with only :data:`CORE_PACKAGES` (constraints.txt versions; wheels from pip's
    cache when it holds them, not byte-compiled at install: the run compiles what it imports). pip runs from this venv
    against the new one (``pip --python``): the interpreter needs no ensurepip of its own. Returns its python. Raises
    AssertionError with pip's last lines when the install fails."""
    venv = where / "venv"
    subprocess.run([python, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=120)
    vpy = venv / "bin" / "python"
    res = subprocess.run([sys.executable, "-m", "pip", "--python", str(vpy), "install", "--quiet", "--no-compile",
                          "--disable-pip-version-check", "--only-binary", ":all:", "-c", str(ROOT / "constraints.txt"),
                          *CORE_PACKAGES], capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, (f"cannot install the cores' packages for {python} (no package index reachable?): "
                                 + "\n".join((res.stdout + res.stderr).splitlines()[-5:]))
    return vpy


@pytest.mark.timeout(1800)  # 77-98 s at load 13-16; 554 s at load 20 (pip downloads and 335 tests on 2 starved cores)
def test_pure_core_tests_pass_under_python_3_12_when_present(tmp_path):
    found = find_interpreters()
    python = found[0] if found else getattr(sys, "_base_executable", sys.executable)
    vpy = _core_venv(python, tmp_path)
    ran = subprocess.run([str(vpy), "-c", "import sys, importlib.util as u; print(sys.version_info[:2], "
                          "u.find_spec('rclpy') is None, u.find_spec('hindrax_msgs') is None)"],
                         capture_output=True, text=True, timeout=60, env={"PYTHONPATH": DRIVERS})
    want = TARGET if found else sys.version_info[:2]
    assert ran.stdout.strip() == f"{want} True True", ran.stdout + ran.stderr  # that Python, and no ROS in reach
    (tmp_path / "pytest.ini").write_text("[pytest]\n")  # not the repository's: no xdist, no conftest, no ROS domain
    env = {"PATH": os.environ.get("PATH", "/usr/bin:/bin"), "HOME": str(tmp_path), "PYTHONPATH": DRIVERS,
           "MPLBACKEND": "Agg", "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    res = subprocess.run([str(vpy), "-m", "pytest", "-q", "-c", str(tmp_path / "pytest.ini"), "--rootdir",
                          str(ROOT), "--noconftest", "-p", "no:cacheprovider", "--import-mode=importlib",
                          "-k", " and ".join(f"not {t}" for t in NOT_HERE), *[str(ROOT / f) for f in PURE_CORE_TESTS]],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=1200)
    summary = res.stdout.strip().splitlines()[-1] if res.stdout.strip() else res.stderr
    print(f"pure cores under {python} ({'.'.join(map(str, want))}"
          + ("" if found else f"; no Python {TARGET[0]}.{TARGET[1]} on this machine, so NOT checked under it")
          + f"): {summary}")
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-2000:]
    passed = re.search(r"(\d+) passed", summary)
    assert passed and int(passed.group(1)) > 0 and not re.search(r"skipped|error|xfail", summary), summary
