"""Fixtures of the tools' tests: ``ballast_goal_on_the_graph``, one run of the graph that several tests read.

(``synthetic_runs``, which the fit's tests use too, is in the repository's conftest.py.)
"""
from __future__ import annotations

from types import SimpleNamespace

import pytest
from hindrax_test_support.vehicle_files import SHORT_HOLDS


#: session fixtures that run something long (a graph, a campaign) for several tests that only read the outcome
SHARED_RUNS = ("ballast_goal_on_the_graph",)
#: each stage of the shortened ballast goal (first prompt: +34 s of simulated time; the whole goal about a minute)
#: must come within this much SIMULATED time: the bound is the design's, the same on any machine
STAGE_SIM_S = 120.0
#: wall-clock guard of each stage, only against a hang: the in-process graph runs the simulator as fast as the
#: machine allows (real_time_factor 0), so a loaded machine takes longer for the same simulated time
STAGE_WALL_S = 500.0


@pytest.hookimpl(tryfirst=True)  # before pytest-xdist names the groups
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The readers of a fixture of :data:`SHARED_RUNS` form one xdist group named after it, so one worker runs it
    once for all of them (the root conftest.py's loadgroup scheduling)."""
    for item in items:
        for name in SHARED_RUNS:
            if name in getattr(item, "fixturenames", ()):
                item.add_marker(pytest.mark.xdist_group(name))


@pytest.fixture(scope="session")
def ballast_goal_on_the_graph(tmp_path_factory) -> SimpleNamespace:
    """One calibration-only ballast goal on the in-process graph (virtual pool, seed 4, recorder on,
    the step shortened to 3 s of settling and 9 s of averaging: :data:`SHORT_HOLDS`), the operator
    played step by step as at the pool; what the operator's calls answered and what a probe saw, for
    the tests that only read the run (``test_calibration_graph``: prompts, continue and refusals;
    ``test_calibration_topic``: the step's result on ``identification/calibration`` and in the bag).
    Each stage must come within :data:`STAGE_SIM_S` of simulated time, else the fixture fails.

    Fields: ``continue_before_goal``, ``continue_attach``, ``continue_again``, ``continue_remove``,
    ``continue_after`` ((success, message) of ``identification/continue``); ``bad_goals_accepted`` (the unknown step
    and calibration_only without a step); ``armed``, ``accepted``; ``prompts`` (every prompt in the feedback);
    ``prompt_in_status`` (the first prompt on ``identification/status``); ``awaiting_after_2_s`` (what the executive
    awaits 2 s of simulated time after the prompt); ``calibration_before_end`` (``identification/calibration`` messages
    by the removal prompt); ``result`` (the action's result); ``calibration`` (the node's record of the step);
    ``published`` (the messages a subscriber from the start got by the result); ``late`` (what a subscriber created
    after the result got); ``bag`` (the recorder's bag directory, closed)."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.action import ActionClient
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from std_srvs.srv import Trigger

    from hindrax_common.config import default_config_path
    from hindrax_common.testing import ros_context, wait_until
    from hindrax_sim.graph.bringup import build_graph
    from hindrax_sim.graph.graph_campaign import VirtualOperator
    from hindrax_onboard.identification.online import executive
    from hindrax_msgs.action import RunIdentification
    from hindrax_msgs.msg import ManeuverStatus
    from hindrax_msgs.srv import SetArmed

    run = SimpleNamespace(bag=tmp_path_factory.mktemp("ballast_goal") / "bag")
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    with ros_context() as ctx:
        graph = build_graph(default_config_path(), sim=True, context=ctx, seed=4, record=True,
                            record_dir=str(run.bag),
                            overrides={"esc.arming_time_s": 1.0, "simulation.real_time_factor": 0.0,
                                       **SHORT_HOLDS})
        probe = rclpy.create_node("operator", context=ctx)
        graph.executor.add_node(probe)
        sim = graph.nodes["simulator"].simulator
        status, feedback, published = [], [], []
        probe.create_subscription(ManeuverStatus, "identification/status", status.append, 100)
        probe.create_subscription(DiagnosticArray, "identification/calibration", published.append, latched)
        arm = probe.create_client(SetArmed, "esc/set_armed")
        cont = probe.create_client(Trigger, "identification/continue")
        action = ActionClient(probe, RunIdentification, "run_identification")
        spin = lambda: graph.spin_once(0.005)  # noqa: E731
        prompts = lambda: [x.prompt for x in feedback if x.prompt]  # noqa: E731

        def call_continue() -> tuple[bool, str]:
            f = cont.call_async(Trigger.Request())
            wait_until(f.done, 10, spin, "continue answer")
            return f.result().success, f.result().message

        def within_sim(cond, what: str) -> None:
            """``cond`` within STAGE_SIM_S of simulated time (STAGE_WALL_S of wall time guards a hang)."""
            t0 = sim.t_s
            wait_until(lambda: cond() or sim.t_s > t0 + STAGE_SIM_S, STAGE_WALL_S, spin, what)
            assert cond(), f"{what}: not within {STAGE_SIM_S:g} s of simulated time"

        try:
            wait_until(lambda: action.server_is_ready() and cont.service_is_ready(), 30, spin, "servers")
            run.continue_before_goal = call_continue()
            run.bad_goals_accepted = []
            for goal in (RunIdentification.Goal(calibrate=["tow"]), RunIdentification.Goal(calibration_only=True)):
                f = action.send_goal_async(goal)
                wait_until(f.done, 10, spin, "goal answer")
                run.bad_goals_accepted.append(f.result().accepted)
            run.armed = graph.start_and_arm(arm, 60).success
            wait_until(lambda: graph.nodes["identification"].core.armed, 30, spin, "ESC reporting armed")
            f = action.send_goal_async(RunIdentification.Goal(calibrate=["ballast"], calibration_only=True),
                                       feedback_callback=lambda m: feedback.append(m.feedback))
            wait_until(f.done, 10, spin, "goal answer")
            handle = f.result()
            run.accepted = handle.accepted
            within_sim(prompts, "first operator prompt")
            wait_until(lambda: any(s.message == prompts()[0] for s in status), 10, spin, "prompt in the status")
            run.prompt_in_status = True
            t_prompt = sim.t_s
            wait_until(lambda: sim.t_s > t_prompt + 2.0, 30, spin, "two seconds of waiting")
            run.awaiting_after_2_s = graph.nodes["identification"].core.run.executive.awaiting
            # the operator: the ballast's weight in water on the simulator, then continue
            op = VirtualOperator(sim, *executive.calibration_forces(graph.config), lambda: None)
            graph.nodes["simulator"].add_step_listener(op.on_step)
            op.on_prompt(prompts()[-1])
            run.continue_attach = call_continue()
            run.continue_again = call_continue()  # the step holds now: nothing awaited
            n = len(prompts())
            within_sim(lambda: any(p.startswith("[remove_ballast]") for p in prompts()[n:]),
                       "the step proceeds to the removal prompt")
            run.calibration_before_end = list(published)
            op.on_prompt("[remove_ballast]")
            run.continue_remove = call_continue()
            res = handle.get_result_async()
            within_sim(res.done, "result")
            run.result = res.result().result
            wait_until(lambda: published, 300, spin, "the calibration message after the result")
            run.calibration = graph.nodes["identification"].last_record.calibration
            run.continue_after = call_continue()
            run.published = list(published)
            # a late subscriber (a recorder started now) still receives it
            late: list = []
            probe.create_subscription(DiagnosticArray, "identification/calibration", late.append, latched)
            wait_until(lambda: late, 10, spin, "late subscriber")
            run.late = late
            run.prompts = prompts()
            graph.nodes["recorder"].stop_recording()
        finally:
            graph.shutdown()
            probe.destroy_node()
    return run
