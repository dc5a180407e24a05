"""The identification pipeline's entry points (``hindrax run``, ``hindrax ident bag``, ``hindrax
ident fit``) read and fit with the collector off (:func:`without_collector`), then as it was;
``hindrax run`` hands its identification node's calibration to :func:`identify_bag`."""
from __future__ import annotations

import dataclasses
import gc

import pytest

from hindrax_fit.assessment import pipeline
from hindrax_fit.bag_input.from_bag import BagContentError


@dataclasses.dataclass
class _Record:
    calibration: dict


@dataclasses.dataclass
class _Read:
    campaign: _Record


def test_identify_bag_reads_and_fits_without_the_collector(monkeypatch):
    seen = []

    def identify(record, cfg, _identify):
        seen.append(("fit", gc.isenabled(), record.calibration))
        return {"surge": 1}, {}

    def read(*_a):
        seen.append(("read", gc.isenabled(), None))
        return _Read(_Record({"from": "bag"}))

    monkeypatch.setattr(pipeline, "read_campaign", read)
    monkeypatch.setattr(pipeline, "identify_calibrated", identify)
    assert gc.isenabled()
    record, idents, _errors = pipeline.identify_bag("bag", None)
    assert seen == [("read", False, None), ("fit", False, {"from": "bag"})] and gc.isenabled()
    seen.clear()
    record, idents, _errors = pipeline.identify_bag("bag", None, calibration={"from": "node"})
    # the fits see the calibration handed in; the record comes back as read
    assert seen[1] == ("fit", False, {"from": "node"}) and record.calibration == {"from": "bag"}
    assert idents == {"surge": 1} and gc.isenabled()


def test_collector_back_as_it_was_after_a_bad_bag(monkeypatch):
    def read(*_a):
        raise BagContentError("no identification/status messages")

    monkeypatch.setattr(pipeline, "read_campaign", read)
    with pytest.raises(BagContentError):
        pipeline.identify_bag("bag", None)
    assert gc.isenabled()
    gc.disable()
    try:
        with pytest.raises(BagContentError):
            pipeline.identify_bag("bag", None)
        assert not gc.isenabled()  # off before: still off
    finally:
        gc.enable()


def test_fit_bags_reads_and_fits_without_the_collector(monkeypatch):
    seen = []
    monkeypatch.setattr(pipeline, "read_any_topics",
                        lambda *a: seen.append(gc.isenabled()) or "records")
    monkeypatch.setattr(pipeline, "fit_records",
                        lambda records, *a: seen.append((records, gc.isenabled())))
    pipeline.fit_bags(["bag"], None)
    assert seen == [False, ("records", False)] and gc.isenabled()
