"""Test-session set-up shared by every test directory.

- One BLAS thread a process (``OPENBLAS_NUM_THREADS=1`` unless set; subprocesses inherit it): the suite runs three
  xdist workers on two cores, and OpenBLAS's extra thread only spun beside them (a fit of test_ident_timing_cv.py:
  23.7 CPU-s with two threads, 16.2 with one, no faster in wall time).
- Discovery and data stay on loopback, over the vehicle's transport: UDPv4 bound to 127.0.0.1, no shared memory
  (:mod:`hindrax_common.process.dds_transport`; docs/architecture.md §11.4).
- Each pytest-xdist worker (three, pytest.ini; and a plain run) reserves its own ROS domain ID through
  ``domain_coordinator`` (a port lock, so concurrent test runs on one machine never share a domain) and
  exports it as ROS_DOMAIN_ID before any test imports rclpy; subprocesses inherit it. Worker gwN tries
  10 N + 2 + pid % 7 first (gw0 2-8, gw1 12-18, gw2 22-28), then the next ones up; a taken domain is skipped.
- A test that leaves SIGINT or SIGTERM ignored in its worker fails (:func:`_stop_signals_not_left_ignored`): every
  child the worker starts later would inherit the ignored signal, and ``kill`` or Ctrl-C could not end it.
- Tests marked ``vehicle_launch`` (a vehicle launch, a live pool, the real-time safety processes) form one xdist
  group, :data:`VEHICLE_LAUNCH_GROUP`: they run in a row on one worker and never overlap each other.
- Scheduling over the workers (pytest.ini: ``--dist loadgroup --no-loadscope-reorder``): each test is a unit of
  its own, dealt in order to the worker that is free, so the longest tests (:data:`LONGEST_FIRST`) go first and no
  worker is left running one of them alone at the end; the tests of a module that uses a module-scoped fixture stay
  one unit (:func:`pytest_collection_modifyitems`), so the fixture is built once.
"""
from __future__ import annotations

import math
import os
import signal
import sys
from types import SimpleNamespace

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy loads OpenBLAS (module docstring)
import numpy as np  # noqa: E402
import pytest  # noqa: E402

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
from hindrax_common.process.dds_transport import loopback_transport  # noqa: E402 - after the range is set

loopback_transport()
os.environ.setdefault("MPLBACKEND", "Agg")


def _keep_bytecode() -> None:
    """Where ``PYTHONDONTWRITEBYTECODE`` is set, let this session write bytecode (``__pycache__``, git-ignored) as on a
    machine without it: the Python processes a run starts (nodes, launches, ``hindrax`` commands) then compile the
    project once, not each at its start (0.3 s of CPU a process that imports the graph). Subprocesses inherit it."""
    if os.environ.pop("PYTHONDONTWRITEBYTECODE", None):
        sys.dont_write_bytecode = False


_keep_bytecode()

_domain_ctx = None

#: The longest tests, longest first: seconds of each in a full run with three workers on 2 cores (``-n 3
#: --durations=60``, quiet machine, 536 s in all), setup included (the colcon build, test/conftest.py, falls to the
#: first pool-day test), and the test's ``file::function``; tests of 6 s and more. Tests not listed follow in
#: collection order; refresh the list from ``--durations``. An xdist group (a module with a module-scoped fixture, or
#: the readers of a shared run) runs as one unit where its listed test stands (its tests run there, in file order),
#: with the seconds of the whole group (its parts of 5 s and more). The colcon build goes to the second line's worker
#: (test_ros_install.py's module: its first test builds it), beside the vehicle_launch group's tests that need no
#: build (:func:`_group_order`); on the group's worker it was the group's longest wait (182 s of 871 s, loaded).
LONGEST_FIRST = """
348 test_pool_day.py::test_pool_day_as_the_readme_writes_it
100 test_ros_install.py::test_every_node_and_hindrax_are_installed
 64 test_run_end_to_end.py::test_hindrax_run_surge_and_heave_through_the_graph
 54 test_ident_fit.py::test_ident_fit_recovers_the_truth_and_predicts_a_held_out_bag
 32 test_calibration_topic.py::test_node_publishes_the_step_result_when_the_ballast_step_ends_and_the_recorder_stores_it
 32 test_calibration_graph.py::test_hindrax_run_calibrate_ballast_through_the_graph_plays_the_operator
 28 test_thrust_calibration.py::test_sinker_and_float_recover_heave_under_asymmetric_thrust
 25 test_identification_campaign.py::test_translation_and_yaw_runs_stay_inside_the_pool_box
 23 test_gateway.py::test_a_command_aimed_at_one_vehicle_never_moves_the_other
 21 test_pure_cores_other_pythons.py::test_pure_core_tests_pass_under_python_3_12_when_present
 20 test_second_graph.py::test_a_vehicle_graph_ends_when_another_vehicle_appears_after_its_start
 18 test_pool_day.py::test_pool_day
 18 test_ident_timing_cv.py::test_the_equation_error_delay_goes_wrong_and_the_cross_validated_one_does_not
 18 test_ident_predict.py::test_predict_csv_scored_independently_matches_the_printed_nrmse
 18 test_pool_day.py::test_armed_esc_stays_armed_while_thrust_flows
 16 test_calibration_graph.py::test_inclining_step_gives_the_restoring_stiffness_of_roll_and_pitch
 15 test_pool_rehearsal.py::test_the_rehearsal_runs_the_readme_pool_day_commands
 15 test_thrust_calibration.py::test_tilt_decay_step_gives_roll_and_pitch_inertia_under_thrust_0_90
 14 test_ident_fit.py::test_imu_in_a_rotated_frame_and_unset_header_stamps
 14 test_ident_saturation.py::test_heave_saturation_is_chosen_and_its_gain_is_the_allocations
 13 test_ident_vehicle_graph.py::test_ident_start_on_the_vehicle_graph_reports_and_ctrl_c_cancels_to_neutral
 12 test_run_signals.py::test_sigterm_during_the_campaign_closes_the_bag_and_leaves_nothing_behind
 12 test_truth.py::test_five_percent_weaker_thrust_is_covered_or_suspect
 12 test_identification_accuracy.py::test_surge_and_heave_recover_the_configured_hydrodynamics
 11 test_ident_bag_fit_same.py::test_ident_bag_and_ident_fit_give_the_same_values_and_intervals
 11 test_rls_online_settings.py::test_online_rls_starts_at_the_priors_and_converges_on_a_short_campaign
 11 test_identification_node.py::test_action_validates_refuses_disarmed_reports_and_cancels_to_neutral
 11 test_control_evaluate.py::test_known_model_holds_the_depth_step_better_than_the_vehicle_file
 10 test_verdicts.py::test_scenarios_command_writes_table_and_json
 10 test_controller_node.py::test_controller_holds_depth_and_altitude_and_yields_wrench
  9 test_ident_persistence.py::test_a_dof_that_is_mostly_noise_gets_no_model_and_no_trusted_parameter
  8 test_campaign_steps.py::test_the_sinker_is_held_by_reverse_thrust
  8 test_heave_independence.py::test_the_right_model_under_a_coloured_disturbance_is_trusted
  7 test_ident_persistence.py::test_a_delay_beyond_the_searched_range_is_reported_at_its_edge
  7 test_thrust_calibration.py::test_line_pull_measures_the_horizontal_scale_in_surge_and_sway
  7 test_sealed_internal_graph.py::test_no_internal_participant_is_reachable_from_a_non_loopback_address
  7 test_cli_ident.py::test_run_writes_identification_report_and_summary
  6 test_icm20948_node.py::test_magnetometer_retry_does_not_interrupt_accel_and_gyro
  6 test_forged_heartbeats.py::test_supervisor_killed_while_heartbeats_are_forged_stops_the_outputs
  6 test_graybox_baseline.py::test_timing_chosen_by_cross_validation_is_the_truth
  6 test_icm20948_node.py::test_lost_magnetometer_is_retried_periodically_until_it_answers_again
  6 test_ident_fit_intervals.py::test_with_config_the_file_is_config_ready
  6 test_bringup_sim.py::test_stepped_graph_gives_the_same_messages_for_the_same_seed
"""


#: The xdist group of every test marked ``vehicle_launch`` (pytest.ini): tests that start a vehicle launch, a live
#: pool or the safety processes with their real-time priorities run one after another on one worker, never beside
#: each other. Beside each other on two cores, real-time processes of one test starved another's: a fresh clone of
#: 5d4005e failed ``test_armed_esc_stays_armed_while_thrust_flows`` (esc/heartbeat gaps up to 0.604 s, 20 of 139
#: reports disarmed), and the README pool day disarmed on an IMU rate of 19.7 Hz.
VEHICLE_LAUNCH_GROUP = "vehicle_launch"


def pytest_configure(config: pytest.Config) -> None:
    global _domain_ctx
    if hasattr(config, "workerinput") or os.environ.get("PYTEST_XDIST_WORKER") is None:
        # In a worker (or a run without xdist): reserve a domain for this process.
        from domain_coordinator import domain_id

        worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
        start = int(worker[2:]) * 10 if worker.startswith("gw") and worker[2:].isdigit() else 0

        class _Selector:
            def __init__(self) -> None:
                self.value = start + (os.getpid() % 7)

            def __call__(self) -> int:
                self.value += 1
                return (self.value % 100) + 1

        _domain_ctx = domain_id(_Selector())
        os.environ["ROS_DOMAIN_ID"] = str(_domain_ctx.__enter__())


def pytest_unconfigure(config: pytest.Config) -> None:
    global _domain_ctx
    if _domain_ctx is not None:
        try:
            _domain_ctx.__exit__(None, None, None)
        except Exception:  # noqa: BLE001 - releasing the port lock must not fail the run
            pass
        _domain_ctx = None


@pytest.fixture(autouse=True)
def _stop_signals_not_left_ignored():
    """Fail a test that leaves SIGINT or SIGTERM ignored (``SIG_IGN``, which ``exec`` passes on to children) where it
    was not before, and put the handler found back. A process that got a stop signal ignores further ones until it
    exits (:mod:`hindrax_common.process.ros_process`), so a test running such a process in its worker's main thread
    must restore the handlers. Found by a fresh clone of e0567a0: a ``RosProcess`` test left both ignored, and a later
    test's bash could not end its own background loop with ``kill``."""
    sigs = (signal.SIGINT, signal.SIGTERM)
    before = {sig: signal.getsignal(sig) for sig in sigs}
    yield
    left = [sig for sig in sigs if signal.getsignal(sig) == signal.SIG_IGN != before[sig]]
    for sig in left:
        signal.signal(sig, before[sig])
    assert not left, f"the test left {', '.join(signal.Signals(s).name for s in left)} ignored in its worker"


def _longest_first_rank() -> dict[str, int]:
    return {line.split()[1]: i for i, line in enumerate(LONGEST_FIRST.strip().splitlines())}


def _uses_a_module_fixture(item: pytest.Item) -> bool:
    info = getattr(item, "_fixtureinfo", None)
    return info is not None and any(defs and defs[-1].scope in ("package", "module", "class")
                                    for defs in info.name2fixturedefs.values())


def _name_the_group(item: pytest.Item) -> None:
    """Append ``@<group>`` to the node id of an item marked ``xdist_group``, as pytest-xdist's worker does for
    loadgroup (xdist/remote.py), where its scheduler reads the group. pytest-xdist 3.8 writes ``item._nodeid``, which
    pytest 9 no longer reads (the id is ``item._id``): without this every test was a unit of its own, and a module's
    module-scoped fixture was built again on each worker that ran one of its tests."""
    from _pytest.nodes import NodeId

    names = sorted({str(m.args[0] if m.args else m.kwargs.get("name", "default"))
                    for m in item.iter_markers("xdist_group")})
    suffix = "@" + "_".join(names)
    if names and not item.nodeid.endswith(suffix):
        item._id = NodeId.parse(item.nodeid + suffix)


@pytest.hookimpl(wrapper=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]):
    """Before the other hooks: the tests of a module with a module-scoped fixture form one xdist group (the module),
    which loadgroup keeps on one worker in a row. After them (pytest's own fixture ordering, xdist's group suffix):
    the tests of :data:`LONGEST_FIRST` first, in its order; the rest keep theirs."""
    for item in items:
        if item.get_closest_marker("vehicle_launch") is not None:
            item.add_marker(pytest.mark.xdist_group(VEHICLE_LAUNCH_GROUP))
        elif _uses_a_module_fixture(item):
            item.add_marker(pytest.mark.xdist_group(item.nodeid.split("::", 1)[0]))
    result = yield
    if getattr(config.option, "loadgroup", False):  # an xdist worker of a --dist loadgroup run
        for item in items:
            _name_the_group(item)
    rank = _longest_first_rank()
    own = {it: rank.get(f"{it.path.name}::{getattr(it, 'originalname', it.name)}", len(rank)) for it in items}
    # a group stands at its best-ranked test and keeps its collection order (a module's tests may rely on it)
    group: dict[str, int] = {}
    for it in items:
        for m in it.iter_markers("xdist_group"):
            name = str(m.args[0] if m.args else m.kwargs.get("name", "default"))
            group[name] = min(group.get(name, len(rank)), own[it])
    items.sort(key=lambda it: (min([own[it], *(group[str(m.args[0] if m.args else m.kwargs.get("name", "default"))]
                                               for m in it.iter_markers("xdist_group"))]), _group_order(it)))
    return result


def _group_order(item: pytest.Item) -> int:
    """Within the :data:`VEHICLE_LAUNCH_GROUP`: 0 for a test that needs no colcon install (test/conftest.py), 1 for
    one that does; they run in that order, and meanwhile another worker builds the install (:data:`LONGEST_FIRST`).
    0 for every other test (the sort is stable: collection order stays)."""
    return int(item.get_closest_marker("vehicle_launch") is not None and "colcon_install" in item.fixturenames)


# ---------------------------------------------------------------------------------- synthetic identification runs
# ``synthetic_runs`` (the fit's and the tools' tests): the pieces the identification tests build their data from, each
# from its definition and none from the code under test: a pilot's held force steps, the exact response of a
# first-order model to a force held over each tick, and a record chunk (:class:`~hindrax_fit.fit.fit_core.Chunk`) of
# that velocity measured at half the tick rate with white noise and smoothed (Savitzky-Golay) as the readers do.
def _steps(rng: np.random.Generator, n: int, lo: float, hi: float) -> np.ndarray:
    """(n,) a force held for 20-80 ticks at a time, each level uniform in [lo, hi] (N)."""
    out = np.empty(n)
    i = 0
    while i < n:
        k = int(rng.integers(20, 80))
        out[i:i + k] = rng.uniform(lo, hi)
        i += k
    return out


def _first_order(force: np.ndarray, inertia: float, damping: float, h: float, offset: float = 0.0) -> np.ndarray:
    """(n,) velocity of ``inertia v' = force - offset - damping v`` from rest, exact for a force held over each
    tick of ``h`` s."""
    e = math.exp(-damping / inertia * h)
    v = np.zeros(force.size)
    for j in range(1, force.size):
        v[j] = v[j - 1] * e + (1.0 - e) * (force[j - 1] - offset) / damping
    return v


def _measured_chunk(rng: np.random.Generator, v: np.ndarray, force: np.ndarray, h: float, noise: float, **chunk):
    """A fit-core chunk of ``force`` whose velocity ``v`` (n,) is measured every second tick with white noise of
    ``noise`` (m/s); smoothed velocity and acceleration by an 11-tick quadratic Savitzky-Golay filter of the
    measurements interpolated onto the ticks. ``chunk``: further :class:`~.fit_core.Chunk` fields (group, t0, ...)."""
    from scipy import signal

    from hindrax_fit.fit import fit_core

    n = v.size
    meas = np.arange(0, n, 2)
    z = v[meas] + rng.normal(0.0, noise, meas.size)
    zi = np.interp(np.arange(n), meas, z)
    return fit_core.Chunk(force, signal.savgol_filter(zi, 11, 2), np.zeros(n),
                          signal.savgol_filter(zi, 11, 2, deriv=1, delta=h), meas.astype(float), z, **chunk)


@pytest.fixture(scope="session")
def synthetic_runs() -> SimpleNamespace:
    """``steps(rng, n, lo, hi)``, ``first_order(force, inertia, damping, h, offset=0)`` and
    ``measured_chunk(rng, v, force, h, noise, **chunk_fields)`` (module docstring)."""
    return SimpleNamespace(steps=_steps, first_order=_first_order, measured_chunk=_measured_chunk)
