"""An aborted calibration leaves a known state: each reference step aborted after it asked for its load names what
to undo (remove the ballast, release the line, ...), and the next campaign first waits, thrusters stopped, for the
operator to confirm it, on the in-process simulator (the virtual pool's operator undoes the load when asked).

The abort is the ESC output disarmed at the tick the load hangs on the vehicle (the pool's operator attached it and
continued); holds are shortened (2 s settling, 10 s averaging: three blocks and a margin)."""
from __future__ import annotations

import numpy as np
import pytest

from hindrax_common.config import default_config_path, load_config
from hindrax_sim.campaign import Campaign
from hindrax_onboard.identification.online.core import IdentificationCore
from hindrax_onboard.identification.online.executive import TickInput
from hindrax_onboard.identification.online.steps import Ballast, Dive, Float, Inclining, LinePull, TiltDecay
from hindrax_sim.simulator import Simulator

HOLD = {"settle_s": 2.0, "window_s": 10.0}

#: (step, its remove code, the words of the undo prompt)
STEPS = [
    (lambda: Ballast(8.56, **HOLD), "remove_ballast", "remove the ballast"),
    (lambda: Float(9.3, **HOLD), "remove_float", "remove the float"),
    (lambda: LinePull("surge", 4.905, 1, **HOLD), "release_line_surge", "release the line"),
    (lambda: LinePull("sway", 4.905, -1, **HOLD), "release_line_sway_negative", "release the line"),
    (lambda: Inclining("roll", 4.28, 0.15, **HOLD), "remove_inclining_mass_roll", "remove the test mass"),
    (lambda: Inclining("pitch", 4.28, 0.15, **HOLD), "remove_inclining_mass_pitch", "remove the test mass"),
]


@pytest.fixture(scope="module")
def cfg():
    return load_config(default_config_path())


def _abort_once_loaded(camp: Campaign) -> None:
    """Run ``camp`` until its operator has a load on the vehicle, then disarm the ESC output under it."""
    ex = camp.executive
    w = ex.start(camp.sim.t_s)
    while not camp.operator.active:
        w = camp.tick(w)
        assert w is not None, f"the campaign ended before its load was applied: {ex.message}"
    assert ex.step(TickInput(camp.sim.t_s, camp.tick_s, (), armed=False)) is None and ex.aborted


@pytest.mark.parametrize("make, code, words", STEPS, ids=[c for _m, c, _w in STEPS])
def test_an_aborted_calibration_asks_to_undo_its_load_and_the_next_campaign_confirms_it(cfg, make, code, words):
    sim = Simulator(cfg, seed=3)
    first = Campaign(cfg, dofs=[], sim=sim, steps=[Dive(), make()])
    _abort_once_loaded(first)
    ex = first.executive
    assert [c for c, _t in ex.undo] == [code]
    status = ex.status()
    assert status.phase == "aborted" and status.message.startswith("ESC output disarmed; undo: " + words)
    assert "the next campaign asks to confirm it first" in status.message
    # the next campaign: the operator's confirmation first, with the thrusters stopped; nothing else moves before
    second = Campaign(cfg, dofs=[], sim=sim, steps=[Dive()], confirm=ex.undo)
    nxt = second.executive
    w = nxt.start(sim.t_s)
    assert nxt.awaiting == code and words in nxt.prompt and "the last one was aborted" in nxt.prompt
    for _ in range(10):  # it waits as long as the operator takes, commanding zero thrust
        assert np.all(w == 0.0) and nxt.awaiting == code
        w = nxt.step(TickInput(sim.t_s + nxt.tick_s, nxt.tick_s, ()))
    second.operator = first.operator  # the pool's operator, who still has the load on the vehicle
    while w is not None:
        w = second.tick(w)
    assert not second.operator.active and not nxt.aborted and nxt.undo == []


def test_an_aborted_tilt_decay_asked_for_nothing(cfg):
    camp = Campaign(cfg, dofs=[], sim=Simulator(cfg, seed=3), steps=[Dive(), TiltDecay("roll")])
    ex = camp.executive
    w = ex.start(camp.sim.t_s)
    while "free decay" not in ex.message:
        w = camp.tick(w)
    ex.step(TickInput(camp.sim.t_s, camp.tick_s, (), armed=False))
    assert ex.aborted and ex.undo == [] and ex.status().message == "ESC output disarmed"


def test_the_node_core_hands_the_undo_to_the_next_goal_and_names_it_in_the_result(cfg):
    """The identification node's core: the load a stopped goal left is in its result and the next goal's
    ``confirm``."""
    made = []

    class Recorder:
        def __init__(self, *args, **kwargs):
            made.append(kwargs)
            self.started, self.undo = False, list(kwargs["confirm"]) or [("remove_ballast",
                                                                           "calibration: remove the ballast")]

    core = IdentificationCore(cfg, tick_s=0.04, publish_period_s=1.0, dvl_lock_timeout_s=3.0, sensor_timeout_s=30.0,
                              stop_timeout_s=2.0, executive=Recorder)
    core.on_pwm([1500.0] * len(cfg.thrusters.thrusters), True)
    goal = type("Goal", (), dict(dofs=["surge"], calibrate=["ballast"], calibration_only=False, level_fractions=[],
                                 levels_per_dof=0))
    core.accept("h1", goal, 0.0)
    out = core.tick(1.0, True)                                   # cancelled before its start
    end = next(e for e in core.tick(3.5, False) + out if e.kind == "end")
    ok, message = core.finish(end.data[0])
    assert not ok and message == ("cancelled; undo: remove the ballast (the next campaign asks to confirm it first)")
    core.accept("h2", goal, 4.0)
    assert made[-1]["confirm"] == [("remove_ballast", "calibration: remove the ballast")]
