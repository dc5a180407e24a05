"""The bag reader of identification: bags in, the fit core's per-DOF records out (:class:`BagRecords`).

One interface, one adapter per kind of bag:

* the campaign's topics (:func:`read_campaign`): :func:`.from_bag.record_from_bag` reads the DOF windows, the
  thrust model of the ESC widths and the vehicle's sensors into a campaign record, conditioned per DOF by
  :func:`..fit.campaign_fit.dof_records` (the record's calibration applied first, as ``hindrax run`` does);
* any topics (:func:`read_any_topics`): force and velocity found by message type (:mod:`.any_topics`), preprocessed
  onto one grid, excitation measured, one record per excited DOF of those asked for.

:func:`reads_as_campaign` chooses between them. :mod:`..assessment.pipeline` reads, fits (:mod:`..fit`) and writes."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from hindrax_common.config import DOFS, VehicleConfig

from ..fit import campaign_fit
from ..fit.calibration import apply_thrust_calibration
from .any_topics import FitInputError, FitOptions, TopicChoice, dof_records, excitation, preprocess_bag
from .from_bag import BagContentError, is_campaign_bag, record_from_bag

__all__ = ["BagRecords", "read_campaign", "read_any_topics", "reads_as_campaign", "is_campaign_bag",
           "BagContentError", "FitInputError", "FitOptions", "TopicChoice", "preprocess_bag", "dof_records"]


@dataclass
class BagRecords:
    """What the bag reader returns, whatever the kind of bag.

    kind: "campaign" | "any topics"; dofs: the DOFs asked for, in order; records: {dof: :class:`..fit.fit_core.
    DofRecord`} of the DOFs that can be fitted; statuses: {dof: (status, reason)} of the others ("not excited" |
    "failed"); notes: the ``preprocessing`` section (any topics); excitation: {dof: {force_std, velocity_std, ...}}
    (any topics); holdout_records: {dof: DofRecord} of the holdout bags (any topics; the mean bias applies there);
    campaign: the :class:`.campaign_record.CampaignRecord` (campaign; its records are built on first use);
    signals: {dof: :class:`..fit.campaign_fit.CampaignSignals`} (campaign)."""

    kind: str
    dofs: list
    statuses: dict = field(default_factory=dict)
    notes: dict = field(default_factory=dict)
    excitation: dict = field(default_factory=dict)
    holdout_records: dict = field(default_factory=dict)
    campaign: Any = None
    signals: dict = field(default_factory=dict)
    cfg: VehicleConfig | None = None
    _records: dict | None = None

    @property
    def records(self) -> dict:
        """{dof: DofRecord} (a campaign's conditioned on first use, its calibration applied)."""
        if self._records is None:
            recs, self.signals, errors = campaign_fit.dof_records(
                apply_thrust_calibration(self.campaign, cfg=self.cfg), self.cfg)
            self.statuses.update({d: ("failed", why) for d, why in errors.items()})
            self._records = recs
        return self._records


def read_campaign(bag: str | Path, cfg: VehicleConfig, grid_s: float = 0.01) -> BagRecords:
    """A bag with the campaign's topics (module docstring). Raises ``BagError`` or
    :class:`.from_bag.BagContentError`."""
    record = record_from_bag(bag, cfg, grid_s)
    return BagRecords("campaign", [d for d in DOFS if d in record.windows], campaign=record, cfg=cfg)


def read_any_topics(bags: Sequence[str | Path], choice: TopicChoice, cfg: VehicleConfig | None = None,
                    dofs: Sequence[str] | None = None, holdout: Sequence[str | Path] = (),
                    opts: FitOptions = FitOptions()) -> BagRecords:
    """Bags of any topics (module docstring), fitted jointly; ``holdout`` read the same way for validation only.

    dofs: the DOFs to identify (default all six; a DOF without excitation gets the status "not excited", roll and
    pitch without an attitude "failed"); the other excited DOFs' velocities enter as coupling candidates. Raises
    :class:`.any_topics.FitInputError` (a bad DOF, topic or frame, too little data) or ``BagError``."""
    dofs = list(dofs or DOFS)
    for d in dofs:
        if d not in DOFS:
            raise FitInputError(f"--dofs: {d!r} is not a DOF (one of {', '.join(DOFS)})")
    pres = [preprocess_bag(b, choice, cfg, opts) for b in bags]
    hold = [preprocess_bag(b, choice, cfg, opts) for b in holdout]
    ex = {d: excitation(pres, d) for d in DOFS}
    moving = [d for d in DOFS if ex[d]["excited"]]
    notes: dict[str, Any] = {"grid_s": opts.grid_s, "resampling": f"uniform grid of {opts.grid_s:g} s "
                             f"({1 / opts.grid_s:g} Hz): force held (its mean over each step), velocity samples "
                             "kept at their own times (interpolated only for the coupling terms and the "
                             "smoothed initial states)", "segment_s": opts.segment_s}
    notes["bags"] = [p.notes for p in pres]
    if hold:
        notes["holdout_bags"] = [p.notes for p in hold]
    have = sum(float(c.t[-1] - c.t[0]) for p in pres for c in p.stretches)
    if have < 2 * opts.segment_s:
        raise FitInputError(f"too little data: {have:.1f} s of continuous force and velocity; at least 2 segments "
                            f"of {opts.segment_s:g} s ({2 * opts.segment_s:g} s) are needed, more for "
                            "cross-validation")
    statuses, todo = {}, []
    for dof in dofs:
        e = ex[dof]
        if not e["excited"]:
            statuses[dof] = ("not excited", "no velocity measured" if not e["velocity_measured"] else
                             f"force std {e['force_std']:.3g} (min {e['force_std_min']:g}), velocity std "
                             f"{e['velocity_std']:.3g} (min {e['velocity_std_min']:g})")
        elif dof in ("roll", "pitch") and not any(np.isfinite(c.attitude[:, :2]).all()
                                                   for p in pres for c in p.stretches):
            statuses[dof] = ("failed", "no attitude for the restoring moment (odometry pose or DVL)")
        else:
            todo.append(dof)
    hrecs = dof_records(hold, todo, opts, moving) if hold else {}
    for hr in hrecs.values():  # a holdout bag is not one of the fitted runs: the mean bias applies
        hr.run_count, hr.runs_known = len(pres), False
    return BagRecords("any topics", dofs, statuses, notes, ex, hrecs, cfg=cfg,
                      _records=dof_records(pres, todo, opts, moving))


def reads_as_campaign(bags: Sequence[str | Path], choice: TopicChoice = TopicChoice(), cfg: VehicleConfig | None = None,
                      dofs: Sequence[str] | None = None, holdout: Sequence[str | Path] = ()) -> bool:
    """True for one bag with the campaign's topics (:func:`.from_bag.is_campaign_bag`), a vehicle file ``cfg`` and no
    topic, DOF or holdout choice: it is read as the campaign (:func:`read_campaign`). Raises ``BagError``."""
    return (cfg is not None and len(bags) == 1 and not holdout and dofs is None and choice == TopicChoice()
            and is_campaign_bag(bags[0]))
