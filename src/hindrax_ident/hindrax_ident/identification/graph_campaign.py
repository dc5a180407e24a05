"""The identification campaign through the whole ROS graph in one process (``hindrax run``, issue "Main job").

:func:`run_graph_campaign`: build the graph (:func:`hindrax_ident.bringup.build_graph`: virtual pool, device
emulators, drivers, ESC node, thrust allocation, identification node, recorder into ``out/bag``) on one
SingleThreadedExecutor; wait for the sensors and the ESC arming time; arm through ``esc/set_armed`` (the
operator's service); send one ``run_identification`` goal and report its feedback; disarm; close the bag;
run the offline identification on the bag (:mod:`.from_bag`) and write ``identification.yaml`` and the report.
All waits are on simulated-time conditions with wall-clock deadlines.

Reproducibility: with the serial devices in lock-step (:class:`~hindrax_ident.sim.hardware.SerialLockStep`),
simulated time frozen until every driver has finished its start-up exchange and the recorder is subscribed to
every topic, and frozen again while each operator call (arm, goal, disarm) is answered, what happens at each
simulated instant no longer depends on wall-clock timing, so the same seed gives the same run.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

__all__ = ["GraphCampaignOutcome", "run_graph_campaign"]


@dataclass
class GraphCampaignOutcome:
    """What a graph campaign produced.

    success / message: the action result; estimates: the action's online (RLS) HydroEstimates;
    identifications / errors: offline results per DOF (:func:`~.estimators.identify_all_with_errors`) from the
    bag; bag_dir; record: the CampaignRecord rebuilt from the bag; disarmed: the ESC reported disarmed after
    the run; sim_time_s / wall_time_s of the whole run; final_pulse_width_us: the PCA9685 outputs after shutdown.
    """

    success: bool = False
    message: str = ""
    estimates: list = field(default_factory=list)
    identifications: dict = field(default_factory=dict)
    errors: dict = field(default_factory=dict)
    bag_dir: Path | None = None
    record: object = None
    disarmed: bool = False
    sim_time_s: float = 0.0
    wall_time_s: float = 0.0
    final_pulse_width_us: list = field(default_factory=list)


def run_graph_campaign(config_path, out: Path, dofs: Sequence[str], levels: int | None = None,
                       seed: int | None = None, real_time_factor: float = 0.0, overrides: dict | None = None,
                       progress: Callable[[str], None] | None = None, deadline_s: float = 3600.0,
                       level_fractions: Sequence[float] = (), truth=None) -> GraphCampaignOutcome:
    """Run the campaign (module docstring); outputs in ``out`` (bag/, identification.yaml, report/).

    Raises :class:`~hindrax_drivers.config.ConfigError` for an invalid configuration and ``TimeoutError`` when a
    step does not finish within its wall-clock deadline (the graph is shut down, thrusters neutral).
    """
    say = progress or (lambda _m: None)
    wall0 = time.monotonic()
    return _run(config_path, out, dofs, levels, seed, real_time_factor, overrides, say, deadline_s,
                level_fractions, wall0, truth)


def _run(config_path, out, dofs, levels, seed, real_time_factor, overrides, say, deadline_s, level_fractions,
         wall0, truth=None) -> GraphCampaignOutcome:
    import rclpy
    from rclpy.action import ActionClient

    from hindrax_drivers.action_goal import GoalSender
    from hindrax_drivers.conditions import ros_context, wait_until
    from hindrax_msgs.action import RunIdentification
    from hindrax_msgs.msg import ThrusterPwm
    from hindrax_msgs.srv import SetArmed

    from ..bringup import build_graph
    from .from_bag import BagContentError, identify_bag, write_outputs

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    bag_dir = out / "bag"
    outcome = GraphCampaignOutcome(bag_dir=bag_dir)
    ov = dict(overrides or {})
    ov["simulation.real_time_factor"] = float(real_time_factor)
    with ros_context() as ctx:
        graph = build_graph(config_path, sim=True, record=True, record_dir=str(bag_dir), context=ctx, seed=seed,
                            overrides=ov, identification=True, drive_clocks=True, truth=truth)
        cfg = graph.config
        sim = graph.nodes["simulator"].simulator
        client = rclpy.create_node("hindrax_run", context=ctx)
        graph.executor.add_node(client)
        armed_state: list = [None]
        client.create_subscription(ThrusterPwm, "thrusters/pulse_width",
                                   lambda m: armed_state.__setitem__(0, bool(m.armed)), 10)
        arm = client.create_client(SetArmed, "esc/set_armed")
        action = ActionClient(client, RunIdentification, "run_identification")
        goals = GoalSender(client, action, "run_identification")  # survives a lost goal or result response
        spin = lambda: graph.spin_once(0.01)  # noqa: E731
        try:
            say(f"graph up: {', '.join(graph.nodes)}; recording to {bag_dir}")
            # Simulated time starts only when discovery, port opening and the devices' start-up exchanges are
            # over, and stands still while the operator's calls are answered: the run then depends on the seed
            # alone, not on how long those took in wall time (graph_campaign module docstring).
            armed = graph.start_and_arm(arm, 120, action.server_is_ready)
            if not armed.success:
                outcome.message = f"arming refused: {armed.message}"
                say(outcome.message)
                return outcome
            wait_until(lambda: armed_state[0] is True, 30, spin, "ESC reporting armed")
            say("armed through esc/set_armed; sending run_identification goal "
                f"({', '.join(dofs)}, {levels or cfg.flat['identification.levels_per_dof']} levels)")
            last = [None]

            def on_feedback(fb) -> None:
                f = fb.feedback
                key = (f.dof, f.level_index, math.copysign(1.0, f.level_command) if f.level_command else 0.0)
                if key != last[0] and f.dof:
                    last[0] = key
                    unit = "N" if f.dof in ("surge", "sway", "heave") else "N m"
                    lvl = f"level {f.level_index + 1}/{f.level_count} {f.level_command:+.2f} {unit}" \
                        if f.level_command else "between levels"
                    say(f"{100 * f.progress:5.1f} %  {f.dof}: {lvl}  (t_sim {sim.t_s:.0f} s)")

            goal = RunIdentification.Goal(dofs=list(dofs), levels_per_dof=int(levels or 0),
                                          level_fractions=[float(x) for x in level_fractions])
            graph.freeze_time()
            handle = goals.send(goal, spin, 30, feedback_callback=on_feedback)
            graph.resume_time()
            if not handle.accepted:
                outcome.message = "goal rejected by the identification node"
                say(outcome.message)
                return outcome
            res = wait_until(lambda: goals.poll_result(handle), deadline_s, spin, "identification campaign").result
            outcome.success, outcome.message, outcome.estimates = bool(res.success), res.message, list(res.estimates)
            say(f"campaign finished after {sim.t_s:.0f} s simulated: {res.message}")
            graph.freeze_time()
            fut = arm.call_async(SetArmed.Request(arm=False))
            wait_until(fut.done, 30, spin, "disarm answer")
            graph.resume_time()
            wait_until(lambda: armed_state[0] is False, 30, spin, "ESC reporting disarmed")
            outcome.disarmed = True
            say("disarmed through esc/set_armed")
            # let the recorder take the ESC's disarmed, neutral outputs too (ten 50 Hz output ticks)
            t_disarmed = sim.t_s
            wait_until(lambda: sim.t_s >= t_disarmed + 0.2, 30, spin, "disarmed outputs recorded")
            graph.nodes["recorder"].stop_recording()
        finally:
            outcome.sim_time_s = sim.t_s
            graph.shutdown()
            client.destroy_node()
            outcome.final_pulse_width_us = [float(x) for x in graph.hardware.pulse_widths_us()]
    say("offline identification from the bag")
    try:
        record, idents, errors = identify_bag(bag_dir, cfg)
    except BagContentError as exc:
        record, idents, errors = None, {}, {"bag": str(exc)}
    outcome.record, outcome.identifications, outcome.errors = record, idents, errors
    outcome.wall_time_s = time.monotonic() - wall0
    if idents:
        note = (f"ROS graph campaign on the virtual pool (seed {cfg.flat['simulation.seed']}), "
                f"{outcome.sim_time_s:.0f} s simulated, wall {outcome.wall_time_s:.0f} s; "
                f"action result: {outcome.message}")
        write_outputs(out, idents, cfg, bag_dir, note, source="simulation", seed=int(cfg.flat["simulation.seed"]))
    return outcome
