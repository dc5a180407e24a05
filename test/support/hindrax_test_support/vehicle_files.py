"""Vehicle files a test writes: the shipped (or installed) ``hindrax.yaml`` with a few keys
changed, the way a user edits theirs and passes it with ``--config`` or ``config:=``; one writer
for every test that needs one."""
from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

import yaml

from hindrax_common.config import default_config_path, load_config, ros_parameters_from_yaml

#: the ballast step's holds shortened for tests (the vehicle file's keys; defaults: 15 s of
#: settling, 30 s averaged), s
SHORT_HOLDS = {"calibration.hold_settle_s": 3.0, "calibration.hold_window_s": 9.0}


def vehicle_file(path: Path, overrides: Mapping[str, Any], source: Path | None = None) -> Path:
    """Write ``source`` (default: the shipped vehicle file) to ``path`` with ``overrides`` (dotted
    keys as in the file, ``{"calibration.hold_settle_s": 6.0}``) set, sections made where the file
    leaves a key at its default; returns ``path``. The values are not checked (a test of a refusal
    writes a bad one). Raises KeyError for a key the loader does not know (a misspelt key would
    otherwise be a test of the defaults)."""
    source = Path(source or default_config_path())
    config = load_config(source)
    params = ros_parameters_from_yaml(yaml.safe_load(source.read_text()))
    for key, value in overrides.items():
        if not _known(config, key):
            raise KeyError(f"no vehicle-file key {key}")
        *sections, leaf = key.split(".")
        node = params
        for part in sections:
            node = node.setdefault(part, {})
        node[leaf] = value
    path.write_text(yaml.safe_dump({"/**": {"ros__parameters": params}}))
    return path


def _known(config: Any, key: str) -> bool:
    """Whether the loader knows ``key``: set in the file, or a field of its section left at its
    default."""
    if key in config.flat:
        return True
    node = config
    for part in key.split("."):
        if not hasattr(node, part):
            return False
        node = getattr(node, part)
    return True
