"""The machine-speed reference of the stack benchmark (hindrax_tools.benchmarks.machine) and
its use
in the rows."""
import math

import pytest

from hindrax_tools.benchmarks import machine, stack


def nbody_energy(bodies: list[tuple[list[float], list[float], float]]) -> float:
    """Total energy (kinetic + potential) of ``bodies`` (as ``machine._bodies``) in their units: -0.169075164 at the
    start and -0.169087605 after 1000 steps, the Benchmarks Game's published output for that program (the check
    that the workload is the computation the published timings are of)."""
    e = 0.0
    for i, (r, v, m) in enumerate(bodies):
        e += 0.5 * m * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
        for r2, _, m2 in bodies[i + 1:]:
            e -= m * m2 / math.sqrt((r[0] - r2[0]) ** 2 + (r[1] - r2[1]) ** 2 + (r[2] - r2[2]) ** 2)
    return e


def test_the_workload_is_the_published_n_body_computation():
    """The Benchmarks Game publishes the n-body program's output for 1000 steps: the energy -0.169075164 before and
    -0.169087605 after. The same numbers here make the timed workload the computation the published timings are
    of, not some other loop."""
    bodies = machine._bodies()
    assert f"{nbody_energy(bodies):.9f}" == "-0.169075164"
    machine._advance(bodies, 1000)
    assert f"{nbody_energy(bodies):.9f}" == "-0.169087605"


def test_nbody_cpu_s_extrapolates_to_the_published_step_count_and_rejects_nonsense():
    """A run of 2000 steps is scaled to 5 million: a positive time 2500 x that of the run (a few seconds at most on
    any machine this runs on, not a few milliseconds); no steps or no repeats are refused."""
    t = machine.nbody_cpu_s(steps=2000, repeats=1)
    assert 0.5 < t < 600
    with pytest.raises(ValueError, match="steps=0"):
        machine.nbody_cpu_s(steps=0)
    with pytest.raises(ValueError, match="repeats=0"):
        machine.nbody_cpu_s(repeats=0)


def test_proc_cpu_s_counts_the_processes_cpu_time():
    """The CPU time of this process from /proc agrees with the interpreter's own count (both tick-rounded), and a
    gone process is an OSError."""
    import os
    import subprocess
    import sys
    import time

    before, own0 = machine.proc_cpu_s(), time.process_time()
    machine._advance(machine._bodies(), 20_000)  # some CPU
    assert machine.proc_cpu_s() - before == pytest.approx(time.process_time() - own0, abs=0.05)
    assert machine.proc_cpu_s(os.getpid()) == pytest.approx(machine.proc_cpu_s(), abs=0.05)
    child = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    with pytest.raises(OSError):
        machine.proc_cpu_s(int(child.stdout))


def _launch(total_per_process: dict[str, float]) -> dict:
    window = {"per_process": total_per_process, "rates": {"/wrench": 50.0}, "wall_s": 10.0, "pool": 0.2,
              "bench": 0.05, "loadavg": 1.0, "rss_mb": {n: 100.0 for n in total_per_process},
              "pss_mb": {n: 40.0 for n in total_per_process}}
    return {"launch_file": "pool_test.launch.xml", "phases": {"idle": {"windows": [window]},
                                                              "running": {"windows": [window]}}}


def test_totals_at_reference_speed_scale_with_this_machines_n_body_time():
    """A machine twice as slow as the reference (n-body 2 x 27 s) measures twice the CPU for the same work: its 0.6
    of a core is 30 % at the reference speed, its largest process 0.4 is 20 %. Without an n-body time, no such
    rows; the Pi projection keeps its fixed factor (rig.PI4_FACTOR, 5) either way."""
    rows = {r["name"]: r for r in stack.launch_rows(_launch({"a": 0.4, "b": 0.2}),
                                                   nbody_s=2 * machine.REFERENCE_NBODY_CPU_S)}
    assert rows["launch_running_cpu_total"]["value"] == pytest.approx(60.0)
    assert rows["launch_running_cpu_total_at_reference_speed"]["value"] == pytest.approx(30.0)
    assert rows["launch_running_cpu_max_process_at_reference_speed"]["value"] == pytest.approx(20.0)
    assert rows["launch_running_cpu_max_process_at_reference_speed"]["note"] == "a"
    assert "x5 on a Pi 4 = 300 % of one Pi core" in rows["launch_running_cpu_total"]["note"]
    plain = {r["name"] for r in stack.launch_rows(_launch({"a": 0.4}))}
    assert "launch_running_cpu_total_at_reference_speed" not in plain and "launch_running_cpu_total" in plain


def test_totals_per_pool_divide_by_the_pool_of_the_same_window():
    """Two windows: 0.6 of a core beside a pool of 0.2 (3x), then 0.9 beside 0.45 (2x): the median ratio is 2.5, at
    the reference pool (20.3 %) 50.75 %; the largest process (a: 0.4/0.2, 0.6/0.45) likewise. A window without a
    measured pool gives no such rows (no division by zero, no made-up ratio)."""
    launch = _launch({"a": 0.4, "b": 0.2})
    second = {**launch["phases"]["running"]["windows"][0], "per_process": {"a": 0.6, "b": 0.3}, "pool": 0.45}
    launch["phases"]["running"]["windows"].append(second)
    rows = {r["name"]: r for r in stack.launch_rows(launch)}
    assert stack.REFERENCE_POOL_CPU == pytest.approx(0.203)
    assert rows["launch_running_cpu_total_per_pool"]["value"] == pytest.approx(2.5)
    assert "3.00 / 2.00" in rows["launch_running_cpu_total_per_pool"]["note"]
    assert rows["launch_running_cpu_total_at_reference_pool"]["value"] == pytest.approx(2.5 * 20.3)
    assert rows["launch_running_cpu_max_process_at_reference_pool"]["value"] == pytest.approx(
        (2.0 + 0.6 / 0.45) / 2 * 20.3)
    assert rows["launch_idle_cpu_total_per_pool"]["value"] == pytest.approx(3.0)
    no_pool = _launch({"a": 0.4})
    no_pool["phases"]["running"]["windows"] = [{**no_pool["phases"]["running"]["windows"][0], "pool": 0.0}]
    names = {r["name"] for r in stack.launch_rows(no_pool)}
    assert "launch_running_cpu_total_per_pool" not in names and "launch_idle_cpu_total_per_pool" in names


def test_per_process_per_pool_and_wake_up_rows():
    """Each process in pool units of its window (a: 0.4 / 0.2 = 2.0, target 0.35; an idle identification process
    0.1 / 0.2 = 0.5 against its 0.1), and its wake-ups per second with the busiest threads by name in the note."""
    launch = _launch({"a": 0.4, "ident_record": 0.1})
    for phase in ("idle", "running"):
        w = launch["phases"][phase]["windows"][0]
        w["wakeups"] = {"a": (300.0, 100.0, {"main": 100.0, "dds.udp.7411": 200.0},
                              {"main": 0.3, "dds.udp.7411": 0.02}),
                        "ident_record": (50.0, 20.0, {"main": 20.0, "bag-writer": 30.0},
                                         {"main": 0.06, "bag-writer": 0.01, "dds.ev.0": 0.01})}
    rows = {r["name"]: r for r in stack.launch_rows(launch)}
    assert rows["launch_running_cpu_a_per_pool"]["value"] == pytest.approx(2.0)
    assert rows["launch_running_cpu_a_per_pool"]["target"] == "<= 0.35"
    assert rows["launch_idle_cpu_ident_record_per_pool"]["value"] == pytest.approx(0.5)
    assert rows["launch_idle_cpu_ident_record_per_pool"]["target"] == "<= 0.1"
    assert rows["launch_running_wakeups_a"]["value"] == 300.0
    assert "dds.udp.7411 200 (2.0), main 100 (30.0)" in rows["launch_running_wakeups_a"]["note"]
    assert rows["launch_idle_wakeups_total"]["value"] == 350.0
    # Fast DDS's threads: 0.02 + 0.01 of a core, of a total 0.4 + 0.1
    assert rows["launch_running_cpu_dds_threads"]["value"] == pytest.approx(3.0)
    assert "6 % of the total" in rows["launch_running_cpu_dds_threads"]["note"]


def test_proc_wakeups_counts_this_process_threads():
    """This process's voluntary context switches: the main thread's are part of the total, the names' counts add up
    to it, and a thread that slept 20 times while alive adds at least 20 (threads are named by the OS: Fast DDS names
    its own, a Python thread has the process's name)."""
    import os
    import threading

    slept, finish = threading.Event(), threading.Event()

    def sleeper():
        for _ in range(20):
            finish.wait(0.001)
        slept.set()
        finish.wait(30)

    before = stack._proc_wakeups(os.getpid())
    t = threading.Thread(target=sleeper)
    t.start()
    try:
        assert slept.wait(30)
        after = stack._proc_wakeups(os.getpid())
    finally:
        finish.set()
        t.join()
    total, main, named, cpu = after
    assert total >= main and named["main"] == main and sum(named.values()) == total
    assert total - before[0] >= 20
    assert set(cpu) == set(named) and cpu["main"] >= before[3]["main"] > 0.0  # this process has run Python
    rates = stack._wakeup_rates(before, after, 2.0)
    assert rates[:2] == ((total - before[0]) / 2.0, (main - before[1]) / 2.0)
    assert rates[3]["main"] == pytest.approx((cpu["main"] - before[3]["main"]) / 2.0)


def test_baseline_rows_are_todays_figures_over_the_baselines():
    """The ratio rows divide today's row by the baseline's row of the same name (running 30 / 40 = 0.75); a row the
    baseline lacks gives no ratio; the baseline's processes are listed in a note."""
    today = [{"name": "launch_running_cpu_total", "value": 30.0, "unit": "% of a core"},
             {"name": "launch_running_wakeups_total", "value": 900.0, "unit": "1/s"},
             {"name": "launch_idle_cpu_total_per_pool", "value": 1.5, "unit": "x"}]
    before = [{"name": "launch_running_cpu_total", "value": 40.0, "unit": "% of a core"},
              {"name": "launch_running_cpu_recorder", "value": 4.0, "unit": "% of a core"},
              {"name": "launch_idle_cpu_total_per_pool", "value": 2.0, "unit": "x"}]
    rows = {r["name"]: r for r in stack.baseline_rows(today, before, "abc1234")}
    assert rows["launch_running_cpu_total_vs_baseline"]["value"] == pytest.approx(0.75)
    assert rows["launch_idle_cpu_total_per_pool_vs_baseline"]["value"] == pytest.approx(0.75)
    assert "launch_running_wakeups_total_vs_baseline" not in rows
    assert rows["launch_running_cpu_baseline_processes"]["note"] == "baseline abc1234: recorder 4.0"
