"""The Pi-sized CPU rig (hindrax_tools/benchmarks/rig.py): which controller it finds, and that a real one bounds
the CPU.

The real cases need a writable cgroup cpu controller (root; the CI machine and the development machines run as root
with cgroup v1's). Each busy loop is bounded by ``timeout``.
"""
from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

from hindrax_tools.benchmarks.rig import PI4_CORE_HERE, Rig, RigError, find_cpu_controller

BUSY = [sys.executable, "-c", "while True: pass"]


def test_finds_v1_then_v2_and_names_both_when_neither(tmp_path):
    v1, v2 = tmp_path / "cpu", tmp_path / "unified"
    v2.mkdir()
    (v2 / "cgroup.controllers").write_text("memory pids\n")  # no cpu: not usable
    with pytest.raises(RigError) as err:
        find_cpu_controller(v1, (v2,))
    assert "\n" not in str(err.value) and str(v1) in str(err.value) and str(v2) in str(err.value)
    (v2 / "cgroup.controllers").write_text("cpu memory pids\n")
    assert find_cpu_controller(v1, (v2,)) == (2, v2)
    v1.mkdir()
    (v1 / "cpu.cfs_quota_us").write_text("-1\n")
    assert find_cpu_controller(v1, (v2,)) == (1, v1)


def test_bad_cores_named():
    with pytest.raises(ValueError, match=r"rig cores 0\.0: allowed above 0"):
        Rig(0.0)


def _spin(rig: Rig, seconds: float, realtime: bool = False) -> list[subprocess.Popen]:
    fifo = ["chrt", "-f", "5"] if realtime else []
    return [subprocess.Popen([*rig.prefix, *fifo, "timeout", f"{seconds:g}", *BUSY])]


def test_a_busy_loop_gets_the_rigs_share_and_a_realtime_one_counts_against_it():
    """0.2 core: a nice-0 busy loop takes about 0.2 (not the whole core it would take); with a SCHED_FIFO busy loop
    beside it, the two together still take about 0.2 plus the kernel's least quota (1 ms per 20 ms period), not 0.4
    (the quota follows the real-time process's CPU); the group is gone afterwards."""
    with Rig(0.2) as rig:
        path = rig.path
        assert path.is_dir()
        for p in _spin(rig, 3.0):
            p.wait()
        alone = rig.usage()
        both = _spin(rig, 3.0) + _spin(rig, 3.0, realtime=True)
        t0 = time.monotonic()
        for p in both:
            p.wait()
        pair = rig.usage()
    assert 0.12 < alone.cores < 0.24 and alone.throttled_periods > 10, alone
    together = (pair.cpu_s - alone.cpu_s) / (time.monotonic() - t0)
    assert 0.12 < together < 0.3, (together, pair)
    assert not Path(path).exists()


def test_busy_loops_beside_take_one_pi_core_each():
    with Rig(0.8, busy_loops=1, busy_s=10.0) as rig:
        time.sleep(3.0)  # a measurement window, not a wait for a condition
        u = rig.usage()
    assert 0.6 * PI4_CORE_HERE < u.busy_cpu_s / u.wall_s < 1.15 * PI4_CORE_HERE, u


def test_the_quota_follows_a_realtime_process_below_the_busy_loops_own():
    """Half a Pi with two busy loops (their quota 0.4, the rig's): a SCHED_FIFO process lowers the rig's quota under
    the busy loops' own (cgroup v1 refuses a parent quota below a child's: the busy loops' goes down first); the
    balancer keeps running, the busy loops get less than their 0.4 and the rig about its 0.4 in all."""
    with Rig(0.4, busy_loops=2, busy_s=10.0) as rig:
        for p in _spin(rig, 3.0, realtime=True):
            p.wait()
        u = rig.usage()
        assert rig._thread.is_alive()
    assert u.busy_cpu_s / u.wall_s < 0.33 and 0.3 < (u.cpu_s + u.busy_cpu_s) / u.wall_s < 0.5, u


def test_the_first_pi_days_factor_is_the_pi_over_here_per_row_and_one_constant_plans_both(tmp_path):
    """docs/pi_budget.md's first Pi day: ``rig --factor PI.json HERE.json`` prints each row's Pi / here; the rig and
    the stack bench plan with the one PI4_FACTOR."""
    import json

    from hindrax_tools.benchmarks import rig, stack

    pi = {"rows": [{"name": "launch_running_cpu_total", "value": 150.0}, {"name": "machine_nbody_cpu_s", "value": 80.0},
                   {"name": "other", "value": 1.0}]}
    here = {"rows": [{"name": "launch_running_cpu_total", "value": 30.0},
                     {"name": "machine_nbody_cpu_s", "value": 20.0},
                     {"name": "heartbeat_cycle_cpu_us_heartbeat", "value": 100.0}]}
    assert rig.measured_factor(pi, here) == {"launch_running_cpu_total": 5.0, "machine_nbody_cpu_s": 4.0}
    with pytest.raises(ValueError, match="launch_running_cpu_total"):
        rig.measured_factor({"rows": []}, here)
    (tmp_path / "pi.json").write_text(json.dumps(pi))
    (tmp_path / "here.json").write_text(json.dumps(here))
    out = subprocess.run([sys.executable, "-m", "hindrax_tools.benchmarks.rig", "--factor", str(tmp_path / "pi.json"),
                          str(tmp_path / "here.json")], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and "launch_running_cpu_total: 5.00x" in out.stdout, out.stderr
    assert stack.PI4_FACTOR is rig.PI4_FACTOR and rig.PI4_CORE_HERE == pytest.approx(1 / rig.PI4_FACTOR)


def test_make_rig_writes_one_section_per_rig_with_a_fractional_core_count(tmp_path):
    from argparse import Namespace

    from hindrax_tools.benchmarks.stack import write_rig_section

    doc = tmp_path / "results.md"
    doc.write_text("# Results\n")
    rows = [{"name": "rig_disarms", "value": 3, "unit": "", "target": "0", "note": "starved"}]
    for cores, loops in ((0.4, 0), (0.8, 2)):
        write_rig_section(Namespace(rig_cores=cores, rig_busy_loops=loops, window_s=None,
                                    results_doc=str(doc)), rows)
    text = doc.read_text()
    # '.' is not allowed in a section name (results_doc): the point is written as '_'
    for name, title in (("bench-rig-0_4", "0.4 cores here, 0 busy loops"),
                        ("bench-rig-0_8-busy2", "0.8 cores here, 2 busy loops")):
        begin, end = f"<!-- results:{name}:begin -->", f"<!-- results:{name}:end -->"
        assert begin in text and end in text, text
        section = text[text.index(begin):text.index(end)]
        assert title in section and "| rig_disarms | 3 |  | 0 | starved |" in section, section
