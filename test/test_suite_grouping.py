"""The suite's real-time tests never run beside each other (conftest.py, ``VEHICLE_LAUNCH_GROUP``).

A test module that starts the safety processes' emulated layout (``running_layout``), a live pool (``LivePool``), a
launch through the process runner or the pool rehearsal carries the ``vehicle_launch`` marker, and collection puts
every such test in the one xdist group, not in a group of its module: with three workers on two cores, two of them
side by side starved each other's real-time processes (a fresh clone of 5d4005e: esc/heartbeat gaps up to 0.604 s,
``test_armed_esc_stays_armed_while_thrust_flows`` failed).
"""
from __future__ import annotations

import configparser
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: what in a test module's source starts real-time vehicle processes, the live pool, or a vehicle graph whose devices
#: run on the wall clock (test_ident_vehicle_graph.py: starved beside a launch, its campaign stopped)
STARTS_REAL_TIME = re.compile(r"running_layout\(|LivePool\(|ProcessRunner\(|\"rehearse\"|use_clock\(time\.monotonic\)")
#: modules whose process runner starts no real-time process: its own unit tests (plain Python children), the
#: gateway's tests (the gateway alone, no priority), the launch-file checks (command lines only, nothing started)
#: and the rehearsal's refusals (a bad argument or a busy domain: refused before it starts anything)
NOT_THE_VEHICLE = {"test_process_runner.py", "test_gateway.py", "test_launch_files.py", "test_cli_input_errors.py",
                   "test_second_graph.py"}


def _test_modules() -> list[Path]:
    ini = configparser.ConfigParser()
    ini.read(ROOT / "pytest.ini")
    paths = ini["pytest"]["testpaths"].split()
    return sorted(p for d in paths for p in (ROOT / d).rglob("test_*.py"))


def test_every_module_that_starts_real_time_processes_is_marked():
    starting = [p for p in _test_modules() if p.name not in NOT_THE_VEHICLE and STARTS_REAL_TIME.search(p.read_text())]
    assert len(starting) >= 8, starting  # the pool day, the rehearsal, the live pool and the safety-layout tests
    unmarked = [str(p.relative_to(ROOT)) for p in starting if "pytest.mark.vehicle_launch" not in p.read_text()]
    assert not unmarked, f"start real-time vehicle processes without the vehicle_launch marker: {unmarked}"


def test_marked_tests_share_one_xdist_group_and_no_module_group(tmp_path):
    """Collect under xdist's loadgroup in a worker's own way (``--collect-only`` in-process with ``-p xdist``) and read
    the group suffix that the scheduler keys on."""
    script = tmp_path / "collect.py"
    script.write_text(
        "import sys, pytest\n"
        "class P:\n"
        "    items = []\n"
        "    def pytest_collection_finish(self, session):\n"
        "        P.items = [(i.nodeid, [m.args[0] for m in i.iter_markers('xdist_group')]) for i in session.items]\n"
        "rc = pytest.main(['-n0', '--collect-only', '-q', '-m', 'vehicle_launch', '-p', 'no:cacheprovider'], "
        "plugins=[P()])\n"
        "for nodeid, groups in P.items:\n"
        "    print('ITEM', nodeid, ','.join(groups))\n"
        "sys.exit(rc)\n")
    res = subprocess.run([sys.executable, str(script)], cwd=ROOT, capture_output=True, text=True, timeout=300)
    items = [line.split(" ", 2)[1:] for line in res.stdout.splitlines() if line.startswith("ITEM ")]
    assert res.returncode == 0 and len(items) >= 15, res.stdout[-2000:] + res.stderr[-2000:]
    assert {groups for _, groups in items} == {"vehicle_launch"}, items
    assert any("test_pool_day.py::test_pool_day_as_the_readme_writes_it" in nodeid for nodeid, _ in items)
