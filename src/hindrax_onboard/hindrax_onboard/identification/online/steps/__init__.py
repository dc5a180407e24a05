"""The campaign's steps as objects, run in order by the sequencer (:class:`~..executive.Executive`):
what every step sees and does (:mod:`.context`), the step protocol, dive and per-DOF frame
(:mod:`.base`), the ladders, the broadband run and the calibration steps (their modules)."""
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
