"""The versions and defaults that the docs quote are those of the code and of the installed packages.

Each test reads the figure from the text and from its source of truth (package metadata, a module constant,
a default argument), so a doc that drifts from the code fails here (issue 28 item 7):

* the rclpy, Fast DDS and Python versions of docs/architecture.md §11 and of every docstring;
* frames: ``hindrax_common/base/frames.py`` is the only module that spells the FLU/FRD and ENU/NED matrices out
  (docs/architecture.md §2);
* the blocking I2C waits that docs/architecture.md §10 lists: which drivers sleep, for how long;
* the number of repeats of the failure table (docs/architecture.md §8.1) and of the safety benchmark.
"""
from __future__ import annotations

import importlib.metadata
import inspect
import re
import sys
from pathlib import Path

from hindrax_drivers.pca9685 import protocol as pca9685
from hindrax_common.transport.i2c import I2CDevice
from hindrax_tools.benchmarks import safety

ROOT = Path(__file__).resolve().parents[1]
ARCH = (ROOT / "docs" / "architecture.md").read_text()
DRIVERS = ROOT / "src" / "hindrax_drivers" / "hindrax_drivers"
COMMON = ROOT / "src" / "hindrax_common" / "hindrax_common"
BRINGUP = ROOT / "src" / "hindrax_bringup" / "hindrax_bringup"


def _major_minor(version: str) -> str:
    return ".".join(version.split(".")[:2])


def _section(text: str, heading: str) -> str:
    start = text.index(heading)
    end = text.find("\n## ", start + len(heading))
    return text[start:] if end < 0 else text[start:end]


def _sources_and_docs() -> list[Path]:
    docs = [p for p in (ROOT / "docs").glob("*.md") if p.name != "results.md"]  # results.md is generated
    code = [p for p in (ROOT / "src").rglob("*.py") if "test" not in p.relative_to(ROOT).parts]
    return docs + code


def test_every_quoted_rclpy_version_is_the_installed_one():
    installed = _major_minor(importlib.metadata.version("rclpy"))
    quotes = []
    for path in _sources_and_docs():
        for m in re.finditer(r"\brclpy (\d+\.\d+)", path.read_text()):
            quotes.append((path.relative_to(ROOT).as_posix(), m.group(1)))
    assert len(quotes) >= 3, quotes  # architecture.md §11, ros_process.py, identification/online/node.py at least
    wrong = [(path, v) for path, v in quotes if v != installed]
    assert not wrong, f"rclpy {installed} is installed; these quote another version: {wrong}"


def test_fast_dds_and_python_versions_of_section_11():
    section = _section(ARCH, "## 11. ROS 2 from pip wheels")
    fast_dds = re.search(r"Fast DDS (\d+\.\d+)", section)
    assert fast_dds and fast_dds.group(1) == _major_minor(importlib.metadata.version("ros-fastrtps"))
    python = re.search(r"Debian 12, Python (\d+\.\d+)", section)
    assert python and python.group(1) == f"{sys.version_info.major}.{sys.version_info.minor}"


_FRAME_MATRICES = (
    re.compile(r"diag\(\[1(?:\.0*)?,-1(?:\.0*)?,-1(?:\.0*)?\]\)"),  # FLU <-> FRD
    re.compile(r"\[\[0(?:\.0*)?,1(?:\.0*)?,0(?:\.0*)?\],\[1(?:\.0*)?,0(?:\.0*)?,0(?:\.0*)?\],"
               r"\[0(?:\.0*)?,0(?:\.0*)?,-1(?:\.0*)?\]\]"),  # ENU <-> NED
)


def test_frames_py_is_the_only_module_that_spells_the_frame_matrices_out():
    assert "the only place | `hindrax_common/base/frames.py`" in (ROOT / "docs" / "module_map.md").read_text()
    frames = COMMON / "base" / "frames.py"
    assert all(p.search(re.sub(r"\s", "", frames.read_text())) for p in _FRAME_MATRICES)  # the check can see them
    code = [p for p in (ROOT / "src").rglob("*.py") if "test" not in p.relative_to(ROOT).parts and p != frames]
    offenders = [p.relative_to(ROOT).as_posix() for p in code
                 if any(pat.search(re.sub(r"\s", "", p.read_text())) for pat in _FRAME_MATRICES)]
    assert not offenders, f"convert frames through hindrax_common/base/frames.py: {offenders}"


def test_the_blocking_i2c_waits_are_those_section_10_lists():
    section = _section(ARCH, "## 10. Threading and stepping model")
    defaults = inspect.signature(I2CDevice.__init__).parameters
    retries, backoff_s = defaults["retries"].default, defaults["backoff_s"].default
    # the figures the text quotes
    assert f"{pca9685.RESTART_DELAY_S * 1e6:g} us oscillator start-up" in section
    assert f"({backoff_s * 1e3:g} ms doubled per retry" in section
    worst = " + ".join(f"{backoff_s * 1e3 * 2 ** k:g}" for k in range(retries))
    assert f"{worst} ms over {retries} retries" in section
    # the drivers said never to block build their transports without backoff and sleep nowhere (with their base)
    for device in ("icm20948", "ms5837"):
        text = (DRIVERS / device / "node.py").read_text() + (COMMON / "node_support" / "i2c_node.py").read_text()
        calls = re.findall(r"I2CDevice\([^)]*\)", text)
        assert calls and all("backoff_s=0.0" in c for c in calls), (device, calls)
        assert not re.search(r"\.sleep\(|write_sequence\(", text), device
    # the output guard retries once
    assert re.search(r'I2CDevice\([^)]*"pca9685-guard", retries=1\)', (BRINGUP / "guard" / "node.py").read_text())
    assert "1 ms for the guard's one retry" in section


def test_failure_table_quotes_the_repeats_of_the_safety_benchmark():
    section = _section(ARCH, "### 8.1 Failure table")
    assert f"median / max of {safety.PROCESS_REPEATS} repeats for the" in section
    assert f"of {safety.REPEATS} repeats for\nthe rows measured in one process" in section
    assert safety.QUICK_REPEATS < min(safety.REPEATS, safety.PROCESS_REPEATS)


def _import_structure():
    """test/test_import_structure.py as a module (its LAYERS and PACKAGE_ORDER are the code's truth)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("import_structure", ROOT / "test" / "test_import_structure.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _doc_layers(section: str) -> list[tuple[str, int]]:
    """(module prefix, layer) of each row of §2's "layer  room" block, in its order."""
    block = section[section.index("layer  room"):]
    block = block[:block.index("```")]
    rows = re.findall(r"^\s*(\d+)\s+(hindrax_[\w/.]+)", block, re.M)
    return [(path.removesuffix("/").removesuffix(".py").replace("/", "."), int(n)) for n, path in rows]


def test_section_2_lists_the_rooms_in_the_layer_order_the_code_keeps():
    """docs/architecture.md §2's rooms in layers are test_import_structure.LAYERS (a package root that only holds its
    public surface shares its lowest room's layer and is not a row), every room of every package (each subpackage) is
    named in §2, and every ``hindrax_<package>/...`` path §2 names exists."""
    structure = _import_structure()
    section = _section(ARCH, "## 2. Packages and layers")
    surfaces = {p for p, lay in structure.LAYERS if any(q.startswith(p + ".") and m == lay
                                                        for q, m in structure.LAYERS)}
    assert _doc_layers(section) == [(p, lay) for p, lay in structure.LAYERS if p not in surfaces]
    assert len(_doc_layers(section)) >= 30  # the parse is not vacuous
    for pkg in structure.PACKAGE_ORDER:
        assert f"src/{pkg}/" in section, f"§2 does not list the package {pkg}"
        top = ROOT / "src" / pkg / pkg
        rooms = [p.parent for p in top.glob("*/__init__.py")] + [p.parent for p in top.glob("*/*/__init__.py")
                                                                   if p.parent.parent.name == "identification"]
        for room in rooms:
            name = room.relative_to(top.parent).as_posix() + "/"
            assert name in section, f"§2 does not name the room {name}"
    named = set(re.findall(r"`(hindrax_\w+/[\w/.]+?)[`.]?(?:`|\s|\))", section))
    missing = sorted(n for n in named if not (ROOT / "src" / n.split("/")[0] / n).exists()
                     and not (ROOT / "src" / n).exists())
    assert named and not missing, f"§2 names paths that do not exist: {missing}"
