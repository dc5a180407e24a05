"""The identification campaign through the whole ROS graph in one process (``hindrax run``).

:func:`run_graph_campaign`: build the graph (:func:`hindrax_sim.graph.bringup.build_graph`: virtual pool, device
emulators, drivers, ESC node, thrust allocation, identification node, recorder into ``out/bag``) on one
SingleThreadedExecutor; wait for the sensors and the ESC arming time; arm through ``esc/set_armed`` (the
operator's service); send one ``run_identification`` goal and report its feedback; disarm; close the bag;
identify the bag (:func:`.identification.assessment.pipeline.identify_bag`), write the report and
``identification.yaml``. All waits are on simulated-time conditions with wall-clock deadlines.

Calibration steps (``calibrate``, :data:`~.identification.online.executive.CALIBRATION_STEPS`):
sent in the goal; :class:`VirtualOperator` plays the operator on the ROS interfaces: for each
feedback ``prompt`` (``[attach_ballast] ...``, ``[apply_line_pull_surge] ...``) it applies or
removes the known force in the simulator as the in-process campaign does
(:class:`~.sim.campaign.PoolOperator`) and calls ``identification/continue``. The thrust scales the
node measured are applied to the bag's record and estimated jointly with the fits
(:func:`~.identification.assessment.results.build_results`), as ``hindrax ident campaign
--calibrate`` does.

Reproducibility: with the serial devices in lock-step (:class:`~hindrax_sim.hardware.SerialLockStep`),
simulated time frozen until every driver has finished its start-up exchange and the recorder is subscribed to
every topic, and frozen again while each operator call (arm, goal, disarm) is answered, what happens at each
simulated instant no longer depends on wall-clock timing, so the same seed gives the same run.

Isolation: without ``ROS_DOMAIN_ID`` in the environment the graph runs on a ROS domain that no other process on
the machine holds (:func:`run_domain`), and says which; another graph on the same domain (a second ``hindrax
run``, a launch on the system clock) would feed its messages into the identification and the bag."""
from __future__ import annotations

import contextlib
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import rclpy
from diagnostic_msgs.msg import DiagnosticStatus
from domain_coordinator import domain_id
from rclpy.action import ActionClient
from std_srvs.srv import Trigger

from hindrax_common.node_support.action_goal import GoalSender
from hindrax_common.process.conditions import ros_context, wait_until
from hindrax_common.node_support.esc_state import ESC_STATE_TOPIC, esc_state_qos, read_esc_state
from hindrax_common.node_support.vehicle_graph import ForeignVehicleWatch, own_view, refuse_before_start
from hindrax_msgs.action import RunIdentification
from hindrax_msgs.srv import SetArmed

from .bringup import build_graph
from ..campaign import PoolOperator
from hindrax_onboard.identification.online.executive import calibration_forces, float_buoyancy, inclining_load
from hindrax_fit.bag_input.reader import BagContentError
from hindrax_fit.assessment.pipeline import OverlappedFits, identify_bag
from hindrax_fit.assessment.report import write_outputs
from ..progress_line import ProgressLine, Ticker

__all__ = ["GraphCampaignOutcome", "VirtualOperator", "parse_prompt", "run_graph_campaign"]


def parse_prompt(prompt: str) -> str:
    """The step code of an operator prompt ``"[<code>] <instruction>"`` (e.g. ``attach_ballast``), "" for none."""
    p = (prompt or "").strip()
    if not p.startswith("[") or "]" not in p:
        return ""
    return p[1:p.index("]")].strip()


class VirtualOperator:
    """The virtual pool's operator for the calibration steps on the ROS graph (module docstring);
    what each step code does is :class:`~.sim.campaign.PoolOperator`'s, as in-process.

    simulator: the :class:`~hindrax_sim.simulator.Simulator`; ballast_weight_n, line_pull_n, inclining_load_n_m (weight
    in water N, arm m), float_buoyancy_n: the known forces (:mod:`~.identification.online.executive`:
    ``calibration_forces``, ``inclining_load``, ``float_buoyancy``); request_continue: sends one
    ``identification/continue`` request and returns its future (or None); say: progress lines; freeze / resume: hold
    simulated time (:meth:`~hindrax_sim.graph.bringup.Graph.freeze_time`) from acting on a prompt until the continue
    answer, so the step goes on at the simulated instant the operator acted. Feed it every feedback prompt
    (:meth:`on_prompt`), call :meth:`on_step` after every integration step and :meth:`poll` from the wait loop: a
    request with no answer within ``resend_after_s`` of wall time is sent again (after a continue every step holds at
    least :data:`~.identification.online.steps.CALIBRATION_SETTLE_S` before its next prompt, so a repeat finds nothing
    awaited and is answered False)."""

    def __init__(self, simulator, ballast_weight_n: float, line_pull_n: float,
                 request_continue: Callable[[], object], say: Callable[[str], None] = lambda _m: None,
                 resend_after_s: float = 5.0, freeze: Callable[[], None] = lambda: None,
                 resume: Callable[[], None] = lambda: None, inclining_load_n_m=(0.0, 0.0),
                 float_buoyancy_n: float = 0.0) -> None:
        self.sim = simulator
        #: which known forces hang on the vehicle (:class:`~.sim.campaign.PoolOperator`)
        self.pool = PoolOperator(ballast_weight_n, line_pull_n, inclining_load_n_m, float_buoyancy_n)
        self._request = request_continue
        self._say = say
        self.resend_after_s = float(resend_after_s)
        self.handled = ""             # step code last acted on ("" once its prompt went away)
        self.answers: list[tuple[bool, str]] = []
        self._pending = None
        self._sent_at = -math.inf
        self._external_set = False
        self._freeze, self._resume = freeze, resume

    def on_prompt(self, prompt: str) -> None:
        """Act on one feedback prompt: apply or remove the force the step code asks for, then request continue."""
        code = parse_prompt(prompt)
        if not code:
            self.handled = ""
            return
        if code == self.handled:
            return
        self.handled = code
        self._freeze()
        if not self.pool.act(code, self.sim.rotation):
            self._say(f"virtual operator: unknown request {code!r}; continuing")
        self._say(f"virtual operator: {code} done (t_sim {self.sim.t_s:.1f} s), calling identification/continue")
        self._send()

    def _send(self) -> None:
        self._pending = self._request()
        self._sent_at = time.monotonic()

    def poll(self) -> None:
        """Collect the continue answer; send again when none came within ``resend_after_s`` and a prompt waits."""
        fut = self._pending
        if fut is None:
            return
        if fut.done():
            res = fut.result()
            self.answers.append((bool(res.success), str(res.message)))
            if not res.success:
                self._say(f"virtual operator: continue refused: {res.message}")
            self._pending = None
            self._resume()
        elif self.handled and time.monotonic() - self._sent_at > self.resend_after_s:
            self._send()

    def external_wrench_frd(self):
        """The wrench (6,) FRD the applied forces exert now (zeros when none)."""
        return self.pool.external_wrench_frd(self.sim.rotation)

    def on_step(self, _sim=None) -> None:
        """Step listener: hold the current external wrench for the next integration step."""
        if self.pool.active:
            self.sim.set_external_wrench(self.external_wrench_frd())
            self._external_set = True
        elif self._external_set:
            self.sim.set_external_wrench([0.0] * 6)
            self._external_set = False


@dataclass
class GraphCampaignOutcome:
    """What a graph campaign produced.

    success / message: the action result; identifications / errors: offline results per DOF
    (:func:`~.identification.fit.campaign_fit.identify_all_with_errors`) from the bag; bag_dir;
    sim_time_s / wall_time_s of the whole run."""

    success: bool = False
    message: str = ""
    identifications: dict = field(default_factory=dict)
    errors: dict = field(default_factory=dict)
    bag_dir: Path | None = None
    sim_time_s: float = 0.0
    wall_time_s: float = 0.0


#: rate of the simulator's ground truth (sim/odometry, sim/wrench) in the campaign's bag, Hz: for plots and checks
#: only (the offline identification reads the drivers' topics), a tenth of the 100 Hz clock's messages
TRUTH_RATE_HZ = 10.0
#: what a campaign refuses beside another vehicle's ESC or supervisor
_BESIDE = ("refusing to run a campaign beside another vehicle graph (set ROS_DOMAIN_ID to a free domain, or unset it "
           "to get one reserved)")


@contextlib.contextmanager
def run_domain(say: Callable[[str], None]):
    """The ROS domain ID for a graph run: ``ROS_DOMAIN_ID`` when the environment sets it (the user's choice, e.g.
    to watch the run with a topside tool), else one reserved for the run's duration by ``domain_coordinator``
    (a free one of 1-100, held by a port lock as the tests' domains are). Yields the ID; ``say`` gets one line."""
    if os.environ.get("ROS_DOMAIN_ID", "").strip():
        yield int(os.environ["ROS_DOMAIN_ID"])
        return
    with domain_id() as did:
        say(f"ROS domain {did} (reserved for this run; set ROS_DOMAIN_ID to choose one)")
        yield did


def run_graph_campaign(config_path, out: Path, dofs: Sequence[str], levels: int | None = None,
                       seed: int | None = None, real_time_factor: float = 0.0,
                       overrides: dict | None = None, progress: Callable[[str], None] | None = None,
                       deadline_s: float = 3600.0, truth=None, calibrate: Sequence[str] = (),
                       sections: Callable | None = None) -> GraphCampaignOutcome:
    """Run the campaign (module docstring); outputs in ``out`` (bag/, identification.yaml, report/).

    calibrate: calibration steps before the ladders (goal field; :class:`VirtualOperator` answers the prompts); with
    ``dofs`` empty only the calibration steps run (goal ``calibration_only``). sections(doc, record, identifications):
    optional, adds sections to identification.yaml from the identification node's own record (e.g. ``free_decay`` and
    ``inclining`` of the tilt_decay and inclining steps, which need its sensor log).

    Raises :class:`~hindrax_common.config.ConfigError` for an invalid configuration,
    ``TimeoutError`` when a step does not finish within its wall-clock deadline (the graph is shut
    down, thrusters neutral) and :class:`~hindrax_common.node_support.vehicle_graph.ForeignVehicleError` when
    another ESC or supervisor is on the domain."""
    say = progress or (lambda _m: None)
    wall0 = time.monotonic()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    bag_dir = out / "bag"
    outcome = GraphCampaignOutcome(bag_dir=bag_dir)
    ov = dict(overrides or {})
    ov["simulation.real_time_factor"] = float(real_time_factor)
    with run_domain(say) as did, ros_context(domain_id=did) as ctx:
        # a second graph on a domain with another ESC or supervisor would mix the two safety graphs: refused before
        # any node of this run exists (its heartbeat publishers alone would disarm the other vehicle)
        refuse_before_start(ctx, _BESIDE)
        graph = build_graph(config_path, sim=True, record=True, record_dir=str(bag_dir), context=ctx, seed=seed,
                            overrides=ov, identification=True, drive_clocks=True, truth=truth,
                            truth_rate_hz=TRUTH_RATE_HZ, parameter_services=False)
        cfg = graph.config
        sim = graph.nodes["simulator"].simulator
        client = rclpy.create_node("hindrax_run", context=ctx)
        graph.executor.add_node(client)
        armed_state: list = [None]
        # the ESC's latched armed flag (a malformed state reads as not armed)
        client.create_subscription(DiagnosticStatus, ESC_STATE_TOPIC, lambda m: armed_state.__setitem__(
            0, bool((read_esc_state(m) or (0, False))[1])), esc_state_qos())
        arm = client.create_client(SetArmed, "esc/set_armed")
        action = ActionClient(client, RunIdentification, "run_identification")
        goals = GoalSender(client, action, "run_identification")  # survives a lost goal or result response
        operator = None
        if calibrate:
            cont = client.create_client(Trigger, "identification/continue")
            operator = VirtualOperator(sim, *calibration_forces(cfg), lambda: cont.call_async(Trigger.Request()),
                                       say, freeze=graph.freeze_time, resume=graph.resume_time,
                                       inclining_load_n_m=inclining_load(cfg), float_buoyancy_n=float_buoyancy(cfg))
            graph.nodes["simulator"].add_step_listener(operator.on_step)

        # the offline fits of each DOF overlap the campaign's next ones (pipeline.OverlappedFits):
        # a DOF is named 1 s simulated and a recorder flush interval (wall) after it ended
        overlap = OverlappedFits(bag_dir, cfg) if dofs and not calibrate else None
        ended: list = []  # (dof, sim time, wall time) of the DOFs finished and not yet named
        flush_s = float(cfg.recording.flush_interval_s)

        def spin() -> None:
            graph.spin_once(0.01)
            if operator is not None:
                operator.poll()
            if ended and sim.t_s >= ended[-1][1] + 1.0 and \
                    time.monotonic() >= ended[-1][2] + flush_s + 0.5:
                overlap.done([d for d, _, _ in ended])
                ended.clear()

        calibration: dict = {}
        keep = False  # the overlapped fits are wanted: the campaign ended normally
        try:
            say(f"graph up: {', '.join(graph.nodes)}; recording to {bag_dir}")
            # another vehicle that appears meanwhile: refused before arming, and while the run lasts
            watch = ForeignVehicleWatch(client, "refused", _BESIDE,
                                        own=lambda: own_view([*graph.nodes.values(), client]), window_s=0.0)
            # the watch first: it looks at every poll, not only once the action server is up
            armed = graph.start_and_arm(arm, 120, lambda: watch.settled() and action.server_is_ready())
            if not armed.success:
                outcome.message = f"arming refused: {armed.message}"
                say(outcome.message)
                return outcome
            watch.check_every()  # one discovered later ends the run the same way, through spin()
            wait_until(lambda: armed_state[0] is True, 30, spin, "ESC reporting armed")
            say("armed through esc/set_armed; sending run_identification goal "
                f"({', '.join(dofs)}, {levels or cfg.identification.levels_per_dof} levels)")
            last = [None]
            last_said = [-float("inf")]

            def on_feedback(fb) -> None:
                f = fb.feedback
                if operator is not None:
                    operator.on_prompt(f.prompt)
                if overlap is not None and last[0] is not None and f.dof and f.dof != last[0][0]:
                    ended.append((last[0][0], sim.t_s, time.monotonic()))
                key = (f.dof, f.level_index, math.copysign(1.0, f.level_command) if f.level_command else 0.0)
                # a new DOF or level always prints; a sign change within one (a ladder's reverse run, or the
                # many of a broadband excitation's force) at most every 5 s of simulated time
                new_level = last[0] is None or key[:2] != last[0][:2]
                if f.dof and (new_level or (key != last[0] and sim.t_s - last_said[0] >= 5.0)):
                    last[0], last_said[0] = key, sim.t_s
                    unit = "N" if f.dof in ("surge", "sway", "heave") else "N m"
                    lvl = f"level {f.level_index + 1}/{f.level_count} {f.level_command:+.2f} {unit}" \
                        if f.level_command else "between levels"
                    say(f"{100 * f.progress:5.1f} %  {f.dof}: {lvl}  (t_sim {sim.t_s:.0f} s)")

            goal = RunIdentification.Goal(dofs=list(dofs), levels_per_dof=int(levels or 0),
                                          calibrate=list(calibrate), calibration_only=bool(calibrate and not dofs))
            graph.freeze_time()
            handle = goals.send(goal, spin, 30, feedback_callback=on_feedback)
            graph.resume_time()
            if not handle.accepted:
                outcome.message = "goal rejected by the identification node"
                say(outcome.message)
                return outcome
            res = wait_until(lambda: goals.poll_result(handle), deadline_s, spin, "identification campaign").result
            outcome.success, outcome.message = bool(res.success), res.message
            say(f"campaign finished after {sim.t_s:.0f} s simulated: {res.message}")
            graph.freeze_time()
            fut = arm.call_async(SetArmed.Request(arm=False))
            wait_until(fut.done, 30, spin, "disarm answer")
            graph.resume_time()
            wait_until(lambda: armed_state[0] is False, 30, spin, "ESC reporting disarmed")
            say("disarmed through esc/set_armed")
            # let the recorder take the ESC's disarmed, neutral outputs too (ten 50 Hz output ticks)
            t_disarmed = sim.t_s
            wait_until(lambda: sim.t_s >= t_disarmed + 0.2, 30, spin, "disarmed outputs recorded")
            graph.nodes["recorder"].stop_recording()
            # a last look: a vehicle that appeared late (its forged heartbeat may have had the output guard disarm
            # the ESC, ending the campaign, before the next periodic check) is named as what ended the run
            watch.check()
            node_record = graph.nodes["identification"].last_record
            calibration = dict(node_record.calibration) if node_record is not None else {}
            keep = True
        finally:
            if overlap is not None and not keep:
                overlap.close()
            outcome.sim_time_s = sim.t_s
            graph.shutdown()
            client.destroy_node()
    if not dofs:
        outcome.wall_time_s = time.monotonic() - wall0
        return outcome
    # a line at least every QUIET_S (progress_line) while the fits and the report run: minutes on a busy machine
    with Ticker(ProgressLine(say, tty=False), "offline identification from the bag") as ticker:
        fitted = overlap.result() if overlap is not None else None
        if overlap is not None:
            ticker.line(f"fitted while the campaign ran: {', '.join(fitted) or 'none'}" if fitted is not None
                        else f"overlapped fits lost ({overlap.error}): identifying serially")
        try:  # with the identification node's calibration results
            _record, idents, errors = identify_bag(bag_dir, cfg, calibration=calibration,
                                                  fitted=None if calibration else fitted)
        except BagContentError as exc:
            idents, errors = {}, {"bag": str(exc)}
        outcome.identifications, outcome.errors = idents, errors
        outcome.wall_time_s = time.monotonic() - wall0
        if idents:
            ticker.set("offline identification: writing identification.yaml and the report")
            note = (f"ROS graph campaign on the virtual pool (seed {cfg.simulation.seed}), {outcome.sim_time_s:.0f} s "
                    f"simulated, wall {outcome.wall_time_s:.0f} s; action result: {outcome.message}")
            # with a calibration: thrust scales estimated jointly with the fits, calibration section (build_results)
            add = sections if sections is not None and node_record is not None else None
            write_outputs(out, idents, cfg, bag_dir, note, source="simulation", seed=int(cfg.simulation.seed),
                          calibration=calibration, sections=add and (lambda doc: add(doc, node_record, idents)))
    return outcome
