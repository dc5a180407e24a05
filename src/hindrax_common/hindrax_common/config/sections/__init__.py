"""The sections of the vehicle file, one module each, joined here in the file's order.

Each section module owns its keys: ``SCHEMA, OPTIONAL = section(name, keys, optional)``
(:func:`~hindrax_common.config.spec.section`: ``SCHEMA`` maps each dotted key under the section's name to its
:class:`~hindrax_common.config.spec.Spec`, ``OPTIONAL`` holds the prefixes of its optional keys) and, where keys
constrain each other, ``cross_checks(flat)`` (the checks across keys that name one of its keys, each one issue of one
line; they may read other sections' keys, run only when every key is individually valid, and skip what a partial
mapping lacks: a node validates its own selection of keys with them,
:func:`hindrax_common.config.node_parameters.validate_selection`). A section without it has every key checked by
its own range alone. A check belongs to the section of the key it names: ``lights.esc_channel`` against the
thrusters' channels is the lights'. The section modules import nothing of this package but :mod:`..spec` (and the
typed-section base) and nothing of a driver (``test_import_structure``)."""
from __future__ import annotations

from typing import Any, Mapping

from ..spec import ConfigIssue, Spec
from . import (calibration, control, environment, esc, hydrodynamics, identification, lights, limits, pool,
               recording, sensors, simulation, supervisor, thrusters, vehicle)

__all__ = ["MODULES", "SECTIONS", "SCHEMA", "OPTIONAL_PREFIXES", "NULLABLE_KEYS", "cross_checks", "is_optional"]

#: The section modules in the vehicle file's order.
MODULES = (vehicle, environment, hydrodynamics, thrusters, esc, lights, sensors, pool, limits,
           identification, simulation, recording, supervisor, calibration, control)

#: Sections a configuration file may contain (top level under ``ros__parameters``).
SECTIONS: tuple[str, ...] = tuple(m.__name__.rsplit(".", 1)[-1] for m in MODULES)

#: Every key of every section: dotted key (``<thruster>`` for the per-thruster segment) -> Spec.
SCHEMA: dict[str, Spec] = {k: v for m in MODULES for k, v in m.SCHEMA.items()}

#: Optional keys (prefixes): absent is fine; present must validate. Everything else in SCHEMA is required.
OPTIONAL_PREFIXES: tuple[str, ...] = tuple(p for m in MODULES for p in m.OPTIONAL)

#: keys whose YAML value may be null, meaning "absent" (their sub-keys are optional)
NULLABLE_KEYS: tuple[str, ...] = esc.NULLABLE


def is_optional(key: str) -> bool:
    """True when ``key`` may be absent from a vehicle file (:data:`OPTIONAL_PREFIXES`)."""
    return key.startswith(OPTIONAL_PREFIXES)


def cross_checks(flat: Mapping[str, Any]) -> list[ConfigIssue]:
    """Every section's checks across keys, in the file's order of sections. Only run when every key is valid."""
    return [issue for m in MODULES if hasattr(m, "cross_checks") for issue in m.cross_checks(flat)]
