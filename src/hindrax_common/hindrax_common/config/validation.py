"""Validation of a flat vehicle configuration (dotted key -> value) against the sections' schema: unknown keys
(with the closest known key suggested), wrong types, out-of-range values, missing required keys, then every
section's checks across keys (:func:`hindrax_common.config.sections.cross_checks`). Each issue is one line naming
key, value and allowed range (:class:`~hindrax_common.config.spec.ConfigIssue`)."""
from __future__ import annotations

import difflib
from typing import Any, Iterable, Mapping, Sequence

from .sections import NULLABLE_KEYS, SCHEMA, SECTIONS, cross_checks, is_optional
from .spec import THRUSTER, ConfigError, ConfigIssue, check_value

__all__ = ["flatten", "validate_flat", "schema_key"]


def flatten(tree: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Flatten nested mappings into dotted keys (``{"a": {"b": 1}} -> {"a.b": 1}``); lists are leaves."""
    out: dict[str, Any] = {}
    for k, v in tree.items():
        key = f"{prefix}{k}"
        if isinstance(v, Mapping):
            out.update(flatten(v, key + "."))
        else:
            out[key] = v
    return out


def schema_key(key: str, thruster_names: Iterable[str]) -> str | None:
    """The SCHEMA entry of a concrete key (a thruster's name -> ``<thruster>``), or None if there is none."""
    if key in SCHEMA:
        return key
    parts = key.split(".")
    if len(parts) == 3 and parts[0] == "thrusters" and parts[1] in set(thruster_names):
        generic = f"thrusters.{THRUSTER}.{parts[2]}"
        if generic in SCHEMA:
            return generic
    return None


def validate_flat(flat: Mapping[str, Any], source: str = "") -> dict[str, Any]:
    """Validate a flat dotted-key mapping against :data:`SCHEMA`.

    Keys outside :data:`SECTIONS` are an error (unknown section). Returns the coerced mapping.
    Raises :class:`ConfigError` listing every issue (unknown keys, wrong types, out-of-range values,
    missing required keys, cross-key inconsistencies)."""
    issues: list[ConfigIssue] = []
    names_raw = flat.get("thrusters.names", [])
    names = [n for n in names_raw if isinstance(n, str)] if isinstance(names_raw, (list, tuple)) else []
    out: dict[str, Any] = {}
    for key, value in flat.items():
        if value is None and key in NULLABLE_KEYS:
            continue  # e.g. esc.output_enable_gpio: null (not wired)
        if key.split(".")[0] not in SECTIONS:
            sections = ", ".join(SECTIONS)
            issues.append(ConfigIssue(key, value, f"no such key (sections: {sections})"))
            continue
        skey = schema_key(key, names)
        if skey is None:
            issues.append(ConfigIssue(key, value, "no such key" + _suggest(key, names)))
            continue
        coerced, issue = check_value(key, SCHEMA[skey], value)
        if issue:
            issues.append(issue)
        else:
            out[key] = coerced
    # required keys
    for skey, spec in SCHEMA.items():
        if is_optional(skey):
            continue
        concrete = [skey.replace(THRUSTER, n) for n in names] if THRUSTER in skey else [skey]
        for key in concrete:
            if key not in flat:
                issues.append(ConfigIssue(key, "<missing>", spec.allowed()))
    if not issues:
        issues.extend(cross_checks(out))
    if issues:
        raise ConfigError(issues, source)
    return out


def _suggest(key: str, names: Sequence[str]) -> str:
    known = [k.replace(THRUSTER, names[0]) if (THRUSTER in k and names) else k for k in SCHEMA]
    close = difflib.get_close_matches(key, known, n=1, cutoff=0.8)
    return f" (did you mean {close[0]}?)" if close else ""
