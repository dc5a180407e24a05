"""The campaign's steps as objects, run in order by the sequencer (:class:`~..executive.Executive`).

* :mod:`.context`: :class:`StepContext`, what every step sees and does (sensors, holds, pool box, tick log,
  results, operator hand-shake, the shared motion primitives);
* :mod:`.base`: the :class:`Step` protocol, the :class:`Confirm` of what an aborted campaign left, the
  :class:`Dive`, the per-DOF frame :class:`DofStep`;
* :mod:`.ladders`: :class:`TranslationLadder`, :class:`RotationLadder` ([Hindrax-Drag] §4);
* :mod:`.broadband`: :class:`BroadbandRun` (one broadband run instead of a ladder);
* :mod:`.calibration_steps`: :class:`Ballast`, :class:`Float`, :class:`LinePull` (thrust scales from known
  forces), :class:`Inclining`, :class:`TiltDecay` (docs/identification.md §6).
"""
from .base import Confirm, Dive, DofStep, Step, undo_line
from .broadband import BroadbandRun
from .calibration_steps import (CALIBRATION_SETTLE_S, CALIBRATION_WINDOW_S, Ballast, Float, Inclining,
                                KnownForceStep, LinePull, TiltDecay)
from .context import CALIBRATION_BLOCK_S, CampaignAbort, StepContext, Wrenches
from .ladders import RotationLadder, TranslationLadder

__all__ = ["Step", "Confirm", "undo_line",
           "Dive", "DofStep", "TranslationLadder", "RotationLadder", "BroadbandRun", "KnownForceStep",
           "Ballast", "Float", "LinePull", "Inclining", "TiltDecay", "StepContext", "CampaignAbort", "Wrenches",
           "CALIBRATION_SETTLE_S", "CALIBRATION_WINDOW_S", "CALIBRATION_BLOCK_S"]
