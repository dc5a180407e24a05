"""The identification pipeline: bags read (:mod:`..bag_input.reader`), fitted (:mod:`..fit`), written
(identification.yaml by :mod:`.results`, report/index.html by :mod:`.report`).

The commands parse their arguments and call these: ``hindrax ident fit`` (:func:`fit_bags` or, for a campaign bag,
:func:`identify_bag`), ``hindrax ident bag`` (:func:`identify_bag`, :func:`write_campaign_outputs`), ``hindrax run``
(:func:`identify_bag` with the identification node's calibration, :func:`.report.write_outputs`).
Reads and fits run with the collector off (:func:`without_collector`); docs/identification.md §7."""
from __future__ import annotations

import contextlib
import gc
import multiprocessing
import os
from dataclasses import replace
from pathlib import Path
from typing import Sequence

from hindrax_common.config import VehicleConfig

from ..bag_input.any_topics import FitOptions, TopicChoice
from ..bag_input.from_bag import truncation
from ..bag_input.reader import BagRecords, read_any_topics, read_campaign
from ..fit import fit_core
from ..fit.calibration import identify_calibrated
from ..fit.campaign_fit import fit_dofs, identify_all_with_errors
from ..fit.fit_any import DofFit, FitResult, fit_records
from .report import write_fit_outputs, write_outputs
from .results import build_document, reference_sections

__all__ = ["fit_bags", "fit_read", "identify_bag", "truncation", "campaign_result", "core_options",
           "write_any_outputs", "write_campaign_outputs", "without_collector", "OverlappedFits"]


@contextlib.contextmanager
def without_collector():
    """No GC pass inside (context manager or decorator), the collector restored after: a bag's read
    and fits make ~10^6 short-lived objects, few in cycles (~1 s of ``hindrax run``'s fits)."""
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()


@without_collector()
def fit_bags(bags: Sequence[str | Path], choice: TopicChoice, cfg: VehicleConfig | None = None,
             dofs: Sequence[str] | None = None, holdout: Sequence[str | Path] = (), opts: FitOptions = FitOptions()
             ) -> FitResult:
    """Bags of any topics read (:func:`..bag_input.reader.read_any_topics`) and fitted jointly with
    ``hindrax ident fit``'s options (:func:`..fit.fit_any.fit_records`), validated by K-fold
    cross-validation and on the ``holdout`` bags. Raises ``BagError`` or
    :class:`..bag_input.any_topics.FitInputError` (bad DOF, topics, frames, too little data)."""
    return fit_read(read_any_topics(bags, choice, cfg, dofs, holdout, opts), holdout, opts)


@without_collector()
def fit_read(records: BagRecords, holdout: Sequence[str | Path] = (), opts: FitOptions = FitOptions()) -> FitResult:
    """:func:`fit_bags` of bags already read (:func:`..bag_input.reader.read_any_topics` of the
    training bags and the ``holdout`` bags, named in the design)."""
    core = fit_core.CoreOptions(segment_s=opts.segment_s, folds=opts.folds, max_delay_s=opts.max_delay_s,
                                persistence_margin=opts.persistence_margin)
    design = (f"{opts.folds}-fold cross-validation: whole bags held out, every {opts.validation_s:g} s validation "
              "segment of them scored (one bag: contiguous blocks of the segments that move each DOF, training "
              "segments overlapping a held-out one left out)")
    if holdout:
        design += f"; holdout: {', '.join(str(b) for b in holdout)}"
    return fit_records(records, core, design)


@without_collector()
def identify_bag(bag_path: str | Path, cfg: VehicleConfig, grid_s: float = 0.01,
                 opts: fit_core.CoreOptions | None = None, calibration: dict | None = None, fitted: dict | None = None):
    """(record, {dof: DofIdentification}, {dof: error}) of a campaign bag: :func:`..bag_input.reader.read_campaign`,
    then :func:`..fit.campaign_fit.identify_all_with_errors` with the fit core's options ``opts`` (None: the
    defaults). The fits see the thrust-model force times the ``calibration`` scales (None:
    ``record.calibration``; :func:`..fit.calibration.identify_calibrated`); ``record`` stays as
    read. fitted: DOFs fitted on this bag while it was written (:class:`OverlappedFits`; no
    calibration). Raises :class:`..bag_input.from_bag.BagContentError`, ``ValueError`` for a
    scale <= 0 or ``fitted`` with a calibration."""
    record = read_campaign(bag_path, cfg, grid_s).campaign
    opts = fit_core.CoreOptions() if opts is None else opts
    scaled = record if calibration is None else replace(record, calibration=calibration)
    if fitted and scaled.calibration:
        raise ValueError("identify_bag: fits made before the calibration scales are known")
    idents, errors = identify_calibrated(scaled, cfg, lambda rec, c: identify_all_with_errors(
        rec, c, opts, fitted if rec is scaled else None))
    return record, idents, errors


def _ready(record, dof: str, margin_s: float = 1.0) -> bool:
    """True when a record read from a bag still being written holds ``dof``'s whole window and
    every sensor log a sample ``margin_s`` past it (a log's samples arrive in stamp order): the
    DOF's fit is then the whole bag's (:func:`..fit.campaign_fit.fit_dofs`)."""
    w = record.windows.get(dof)
    return w is not None and record.t_s[-1] >= w[1] + margin_s and all(
        log[-1][0] >= w[1] + margin_s for log in record.sensors.values() if log)


def _receive(conn):
    """The next message, False when the other end has closed."""
    try:
        return conn.recv()
    except EOFError:
        return False


@without_collector()
def _overlap_worker(conn, bag_dir: Path, cfg: VehicleConfig) -> None:
    """:class:`OverlappedFits`' process, at nice +10 (the campaign's graph keeps its core when the
    second one is busy): each list of DOFs received is fitted on the bag as written so far (a DOF
    not yet :func:`_ready` waits for the next list; a bag not readable yet leaves them for
    :func:`identify_bag`); None: the fits made, {dof: (DofResult, CampaignSignals)}, sent back."""
    os.nice(10)
    fitted: dict = {}
    todo: list = []
    opts = fit_core.CoreOptions()
    while (msg := _receive(conn)) is not None:
        if msg is False:
            return
        todo += [d for d in msg if d not in todo]
        with contextlib.suppress(Exception):
            record = read_campaign(bag_dir, cfg).campaign
            new, _ = fit_dofs(record, cfg, opts, [d for d in todo if _ready(record, d)])
            fitted.update(new)
            todo = [d for d in todo if d not in fitted]
    conn.send(fitted)


class OverlappedFits:
    """Fits of a campaign bag's DOFs made while the campaign writes it.

    A spawned process (started with the campaign, so its imports cost no wall time; forking an rclpy process is unsafe)
    fits each DOF (:func:`..fit.campaign_fit.fit_dofs`) on the bag as written once :meth:`done` names it; :meth:`result`
    returns those fits for ``identify_bag(..., fitted=)``, which then gives what it gives alone (a ready DOF's fit on a
    prefix is the whole bag's). Without a calibration. :meth:`close` ends the process."""

    def __init__(self, bag_dir: str | Path, cfg: VehicleConfig) -> None:
        ctx = multiprocessing.get_context("spawn")
        self._conn, child = ctx.Pipe()
        self._proc = ctx.Process(target=_overlap_worker, args=(child, Path(bag_dir), cfg), daemon=True)
        self._proc.start()
        child.close()
        self.error = ""

    def done(self, dofs: Sequence[str]) -> None:
        """The campaign has finished ``dofs`` (their data on disk now or soon: re-tried later)."""
        with contextlib.suppress(OSError):  # the process is gone: result() says so
            self._conn.send(list(dofs))

    def result(self) -> dict | None:
        """The fits made, {dof: (DofResult, CampaignSignals)} (possibly empty), or None when the
        process was lost (the reason in :attr:`error`). Ends the process."""
        try:
            self._conn.send(None)
            fitted = self._conn.recv()
        except (OSError, EOFError) as exc:
            fitted, self.error = None, f"worker lost: {type(exc).__name__} {exc}".strip()
        self.close()
        return fitted

    def close(self) -> None:
        """End the process (idempotent)."""
        self._conn.close()
        if self._proc.is_alive():
            self._proc.terminate()
        self._proc.join(5)


def campaign_result(idents: dict, folds: int, opts: fit_core.CoreOptions) -> FitResult:
    """A campaign's identifications as a :class:`..fit.fit_any.FitResult` (``hindrax ident fit``'s table): the fit
    core's result and cross-validation of each DOF."""
    return FitResult({d: DofFit(d, "fitted", {}, r.signals["core"], {"cross_validation": dict(r.signals["core"].cv)})
                      for d, r in idents.items()}, {}, f"{folds}-fold cross-validation by contiguous blocks of the "
                     f"{opts.validation_s:g} s validation segments of each DOF's window")


def core_options(folds: int) -> fit_core.CoreOptions:
    """The fit core's default options with ``folds`` folds."""
    return replace(fit_core.CoreOptions(), folds=folds)


def write_any_outputs(out: Path, res: FitResult, cfg: VehicleConfig | None, bags: Sequence[str | Path],
                      holdout: Sequence[str | Path] = ()) -> tuple[dict, Path, Path]:
    """(document, identification.yaml, report/index.html) of a fit of bags of any topics, written in ``out``."""
    doc = build_document(res, cfg, bags, holdout)
    path, index = write_fit_outputs(out, res, doc, cfg)
    return doc, path, index


def write_campaign_outputs(out: Path, record, idents: dict, cfg: VehicleConfig, bag: str | Path, lacking: list,
                           restoring_n_m_per_rad: float | None = None, restoring_std: float = 0.0,
                           progress=print) -> Path:
    """identification.yaml (its path) and the report of a campaign bag's identifications, written in ``out``: the
    calibration's sections, the reference sections (:func:`.results.reference_sections`: inclining, free decay with
    ``restoring_n_m_per_rad`` when the bag has no inclining step) and, for a truncated bag (``lacking``: what
    :func:`..bag_input.from_bag.truncation` says it lacks), ``provenance.truncated``."""
    note = (f"Offline identification of bag {bag}, {record.t_s[-1] - record.t_s[0]:.0f} s of campaign"
            + (f"; ABORTED: {record.abort_reason}" if record.aborted else ""))
    if lacking:
        note += "; TRUNCATED: " + "; ".join(lacking)

    def sections(doc: dict) -> None:
        reference_sections(doc, record, cfg, restoring_n_m_per_rad, restoring_std, progress)
        if lacking:
            doc["provenance"]["truncated"] = list(lacking)

    return write_outputs(out, idents, cfg, bag, note, calibration=record.calibration, sections=sections)
