"""``log_at``: one call site logging at several severities (the identification node's and the DVL node's log
events). rclpy raises ``ValueError: Logger severity cannot be changed between calls`` when one line logs at two
severities; that crashed the identification node's control tick in a fresh clone's suite (a campaign's "info" line,
then "thrusters not reported neutral within 2 s of the stop" at "warn")."""
from __future__ import annotations

import pytest
import rclpy.logging

from hindrax_common.node_support.node_common import log_at


def _one_line(logger, level: str, text: str) -> None:
    getattr(logger, level)(text)  # the pattern log_at replaces: every severity from this one line


def test_one_line_at_two_severities_raises_in_rclpy():
    logger = rclpy.logging.get_logger("hindrax_test_one_line")
    _one_line(logger, "info", "first")
    with pytest.raises(ValueError, match="severity cannot be changed"):
        _one_line(logger, "warn", "second")


def test_log_at_takes_every_severity_from_one_call_site_in_any_order():
    logger = rclpy.logging.get_logger("hindrax_test_log_at")
    for level in ("info", "warn", "debug", "error", "info", "warn"):
        log_at(logger, level, f"a {level} line")


def test_an_unknown_level_is_refused_by_name():
    with pytest.raises(ValueError, match="'fatal': not one of debug, info, warn, error"):
        log_at(rclpy.logging.get_logger("hindrax_test_log_at_bad"), "fatal", "x")
