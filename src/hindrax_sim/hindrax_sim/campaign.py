"""Identification campaign on the simulator stepped in-process (no ROS graph): ``hindrax ident campaign``.

The campaign logic is the :class:`~..identification.online.executive.Executive` (the same object the identification node
drives on the ROS graph, :mod:`..identification.online.node`); here its plant is a
:class:`~hindrax_sim.simulator.Simulator` stepped in this process: each control tick
(``identification.estimate_rate_hz``; the simulator steps in between) the wrench is allocated
(:class:`~hindrax_bringup.allocation.core.AllocationCore`), its pulse widths drive the simulator's thrusters, the thrust
curve of those widths ([Hindrax-Drag] eq. 1) is what the executive records, and the sensor samples the simulator
produced during the tick go to the executive. At the end or on abort every thruster is commanded neutral. The
simulator's truth (position, attitude) goes into the record for tests and plots only; the executive never sees it.

Calibration steps (``calibrate``): the virtual pool plays the operator (:class:`PoolOperator`, shared with the graph's
:class:`~..graph_campaign.VirtualOperator`): each known force a step prompts for acts on the vehicle until the executive
asks for its removal; ``continue`` is given at once."""
from __future__ import annotations

import math
import time
from typing import Callable, Sequence

import numpy as np

from hindrax_common.base import frames
from hindrax_common.config import DOFS, VehicleConfig

from hindrax_onboard.identification.model.campaign_record import CampaignRecord
from hindrax_onboard.identification.online.executive import CampaignAbort, Executive, TickInput
from hindrax_onboard.identification.online.steps import Ballast, Float, Inclining, LinePull
from .simulator import Simulator

__all__ = ["CampaignAbort", "CampaignRecord", "Campaign", "PoolOperator"]


class PoolOperator:
    """The virtual pool's operator of the calibration steps: which known force hangs on the vehicle
    (ballast NED down, float NED up, a line over a pulley at the pool edge, an inclining mass).

    ballast_weight_n / float_buoyancy_n / line_pull_n: the known forces, N
    (:func:`~..identification.online.executive.calibration_forces`,
    :func:`~..identification.online.executive.float_buoyancy`); inclining_load_n_m: (weight in water N, arm m) of the
    inclining test mass. :meth:`act` does what a step's operator code asks (``attach_ballast``, ``remove_ballast``,
    ``attach_float``, ``remove_float``, ``apply_line_pull_<surge|sway>[_negative]``, ``release_line_<...>``,
    ``attach_inclining_mass_<dof>``, ``remove_inclining_mass_<dof>``); :meth:`external_wrench_frd` is the wrench the
    applied forces exert on the vehicle at its current attitude."""

    def __init__(self, ballast_weight_n: float = 0.0, line_pull_n: float = 0.0, inclining_load_n_m=(0.0, 0.0),
                 float_buoyancy_n: float = 0.0) -> None:
        self.ballast_weight_n = float(ballast_weight_n)
        self.line_pull_n = float(line_pull_n)
        self.float_buoyancy_n = float(float_buoyancy_n)
        self.inclining_load_n_m = tuple(float(x) for x in inclining_load_n_m)
        self.ballast_on = False
        self.float_on = False
        self.line_ned: np.ndarray | None = None  # (3,) N in NED while a line pulls
        self.inclining: str | None = None  # DOF whose inclining test mass hangs on the vehicle

    @classmethod
    def for_steps(cls, steps) -> "PoolOperator":
        """The operator of a campaign's steps (:mod:`..identification.online.steps`): the known force each reference
        step prompts for (ballast, float, line pull, inclining test mass) is the one it applies."""
        kw: dict = {}
        for st in steps:
            if isinstance(st, Ballast):
                kw["ballast_weight_n"] = st.force_n
            elif isinstance(st, Float):
                kw["float_buoyancy_n"] = st.force_n
            elif isinstance(st, LinePull):
                kw["line_pull_n"] = st.force_n
            elif isinstance(st, Inclining):
                kw["inclining_load_n_m"] = (st.weight_n, st.arm_m)
        return cls(**kw)

    @property
    def active(self) -> bool:
        """Some known force is applied."""
        return self.ballast_on or self.float_on or self.line_ned is not None or self.inclining is not None

    def act(self, code: str, rotation: np.ndarray) -> bool:
        """Do what ``code`` asks with the vehicle at ``rotation`` (3, 3) body -> NED (a line is laid along the body
        axis of that moment, horizontal); False for a code this operator does not know."""
        if code in ("attach_ballast", "remove_ballast"):
            self.ballast_on = code == "attach_ballast"
        elif code in ("attach_float", "remove_float"):
            self.float_on = code == "attach_float"
        elif code.startswith("apply_line_pull_"):
            what = code[len("apply_line_pull_"):]
            axis = np.eye(3)[0 if what.startswith("surge") else 1] * (-1.0 if what.endswith("_negative") else 1.0)
            d = np.asarray(rotation) @ axis
            self.line_ned = self.line_pull_n * np.array([d[0], d[1], 0.0]) / math.hypot(d[0], d[1])
        elif code.startswith("release_line_"):
            self.line_ned = None
        elif code.startswith(("attach_inclining_mass_", "remove_inclining_mass_")):
            self.inclining = code.rsplit("_", 1)[1] if code.startswith("attach") else None
        else:
            return False
        return True

    def external_wrench_frd(self, rotation: np.ndarray) -> np.ndarray:
        """The wrench (6,) FRD about the body origin of the applied forces, vehicle at ``rotation`` body -> NED."""
        ext = np.zeros(6)
        rt = np.asarray(rotation).T  # NED -> body
        if self.inclining is not None:  # weight in water at its arm, body +y (roll) or +x (pitch)
            weight_n, arm_m = self.inclining_load_n_m
            f = rt @ np.array([0.0, 0.0, weight_n])
            r = np.zeros(3)
            r[1 if self.inclining == "roll" else 0] = arm_m
            ext += np.concatenate([f, np.cross(r, f)])
        if self.ballast_on:
            ext[:3] += rt @ np.array([0.0, 0.0, self.ballast_weight_n])
        if self.float_on:
            ext[:3] += rt @ np.array([0.0, 0.0, -self.float_buoyancy_n])
        if self.line_ned is not None:
            ext[:3] += rt @ self.line_ned
        return ext


class Campaign:
    """Runs the identification campaign (:class:`~..identification.online.executive.Executive`) on a
    :class:`~hindrax_sim.simulator.Simulator` (module docstring).

    cfg: vehicle configuration. dofs: DOFs to test, in order (default all six). levels: levels per DOF (default
    ``identification.levels_per_dof``). seed: simulator seed (default ``simulation.seed``). progress: optional callable
    receiving one-line progress messages. real_time_factor: > 0 paces the simulation against the wall clock (0: as fast
    as possible). sim: an existing simulator (else built). Other keywords go to the
    :class:`~..identification.online.executive.Executive` (``max_level_duration_s``, ``excitation``, the calibration
    steps and their known forces, ``steps``, ``confirm``). Raises ``ValueError`` for an unknown DOF."""

    def __init__(self, cfg: VehicleConfig, dofs: Sequence[str] = DOFS, levels: int | None = None,
                 seed: int | None = None, progress: Callable[[str], None] | None = None,
                 real_time_factor: float = 0.0, sim: Simulator | None = None, **executive) -> None:
        self.seed = int(cfg.simulation.seed if seed is None else seed)
        self.sim = sim if sim is not None else Simulator(cfg, seed=self.seed)
        rate = float(cfg.identification.estimate_rate_hz)
        self.steps_per_tick = max(1, int(round(1.0 / (rate * self.sim.step_s))))
        self.tick_s = self.steps_per_tick * self.sim.step_s
        self.executive = Executive(cfg, dofs, levels, tick_s=self.tick_s, progress=progress, **executive)
        #: the virtual pool's operator of the calibration steps: the known forces the steps prompt for
        self.operator = PoolOperator.for_steps(self.executive.steps)
        self._external_used = False
        self.core = self.executive.core
        self.reversed = np.array([t.reversed for t in cfg.thrusters.thrusters], dtype=bool)
        self.neutral_us = float(cfg.thrusters.pulse_width_neutral_us)
        self.rtf = float(real_time_factor)
        self._pending: list = []
        self.sim.add_sensor_listener(lambda dev, s: self._pending.append((dev, s)))
        self._truth: dict[str, list] = {"pos": [], "eul": []}
        self._wall0 = 0.0
        self._sim0 = 0.0

    def tick(self, wrench_frd: np.ndarray) -> np.ndarray | None:
        """Command ``wrench_frd`` (6,) FRD for one control tick on the simulator and hand the tick to the executive;
        returns the executive's next wrench, None once the campaign has finished."""
        ex = self.executive
        alloc = self.core.allocate(frames.wrench_frd_to_flu(np.asarray(wrench_frd, dtype=float)))
        pw = np.asarray(alloc.pulse_width_us, dtype=float)
        ex.command(np.asarray(ex.curve.thrust_n(pw), dtype=float))  # thrust model of the commanded widths
        self._truth["pos"].append(self.sim.position_ned_m)
        self._truth["eul"].append(self.sim.euler_rad)
        wire = np.where(self.reversed, 2.0 * self.neutral_us - pw, pw)
        if ex.awaiting:  # the virtual pool's operator: do what the step asks, then continue
            self.operator.act(ex.awaiting, self.sim.rotation)
            ex.operator_continue()
        # once set, the simulator holds the last external wrench: keep setting it
        self._external_used = bool(ex.calibrate or self.operator.active or self._external_used)
        ext = self.operator.external_wrench_frd(self.sim.rotation) if self._external_used else None
        self.sim.advance(self.tick_s, wire, external_wrench_frd=ext)
        pending, self._pending = self._pending, []
        w = ex.step(TickInput(t_s=self.sim.t_s, elapsed_s=self.tick_s, samples=pending))
        if w is not None and self.rtf > 0.0:
            ahead = (self.sim.t_s - self._sim0) / self.rtf - (time.monotonic() - self._wall0)
            if ahead > 0.0:
                time.sleep(ahead)  # pacing against the wall clock only (the --rtf option)
        return w

    def run(self) -> CampaignRecord:
        """Run the campaign; returns the :class:`~..bag_input.campaign_record.CampaignRecord` (aborted campaigns
        too)."""
        self._wall0 = time.monotonic()
        self._sim0 = self.sim.t_s
        w = self.executive.start(self.sim.t_s)
        while w is not None:
            w = self.tick(w)
        self._neutral()
        return self.executive.record(
            truth_position_ned_m=np.asarray(self._truth["pos"]), truth_euler_rad=np.asarray(self._truth["eul"]),
            wall_time_s=time.monotonic() - self._wall0, seed=self.seed,
            final_pulse_width_us=np.array(self.sim.thrusters.pulse_width_us, copy=True))

    def _neutral(self) -> None:
        """Command neutral pulse widths on every thruster (end of campaign or abort)."""
        self.sim.step(np.full(len(self.core.names), self.neutral_us))

