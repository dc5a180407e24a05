"""Reading a vehicle file: the ros-args params-file layout, its validation as a whole (:func:`load_config`), a
node's parameters as a configuration (:func:`config_from_parameters`) and where the default vehicle file is
(:func:`default_config_path`)."""
from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import Any, Mapping

import yaml
from ament_index_python.packages import get_package_prefix, get_package_share_directory

from .sections import SECTIONS
from .spec import ConfigError, ConfigIssue
from .validation import flatten, validate_flat
from .vehicle_config import VehicleConfig

__all__ = ["ros_parameters_from_yaml", "load_config", "config_from_parameters", "default_config_path"]


def ros_parameters_from_yaml(doc: Any, source: str = "") -> dict[str, Any]:
    """Extract the ``ros__parameters`` mapping of a params-file document (first node key) as a nested dict.

    Accepts ``{"/**": {"ros__parameters": {...}}}`` or any single node name. Raises ConfigError otherwise."""
    if not isinstance(doc, Mapping) or not doc:
        raise ConfigError([ConfigIssue("<file>", type(doc).__name__,
                                       "a mapping {'/**': {'ros__parameters': {...}}}")], source)
    if len(doc) != 1:
        raise ConfigError([ConfigIssue("<file>", list(doc), "exactly one node key, e.g. '/**'")], source)
    (node_key, body), = doc.items()
    if not isinstance(body, Mapping) or "ros__parameters" not in body or set(body) != {"ros__parameters"}:
        raise ConfigError([ConfigIssue(str(node_key), list(body) if isinstance(body, Mapping) else body,
                                       "a mapping with the single key 'ros__parameters'")], source)
    params = body["ros__parameters"]
    if not isinstance(params, Mapping):
        raise ConfigError([ConfigIssue(f"{node_key}.ros__parameters", params, "a mapping")], source)
    return dict(params)


def load_config(path: str | Path, overrides: Mapping[str, Any] | None = None) -> VehicleConfig:
    """Load and validate a vehicle configuration file (ros-args params-file layout).

    path: YAML file. overrides: dotted keys replacing file values before validation.
    Returns a :class:`VehicleConfig`. Raises :class:`ConfigError` (with every issue) on an unreadable
    file, bad YAML, unknown/missing keys, wrong types or out-of-range values."""
    path = Path(path)
    src = str(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise ConfigError([ConfigIssue("<file>", src, f"a readable file ({exc.strerror})")], src) from exc
    except UnicodeDecodeError as exc:  # a binary file
        raise ConfigError([ConfigIssue("<file>", src, f"a UTF-8 text file (byte {exc.start}: {exc.reason})")],
                          src) from exc
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ConfigError([ConfigIssue("<file>", src, f"valid YAML ({str(exc).splitlines()[0]})")], src) from exc
    except RecursionError as exc:  # nesting deeper than the parser's recursion limit
        raise ConfigError([ConfigIssue("<file>", src, "YAML nested less deeply (the parser ran out of recursion)")],
                          src) from exc
    flat = flatten(ros_parameters_from_yaml(doc, src))
    if overrides:
        flat.update(overrides)
    valid = validate_flat(flat, source=src)
    return VehicleConfig(valid, src, hashlib.sha256(text.encode()).hexdigest())


def config_from_parameters(params: Mapping[str, Any], source: str = "ros parameters") -> VehicleConfig:
    """Validate the vehicle keys among a node's parameters (dotted names -> values).

    Parameters outside the configuration sections (``use_sim_time``, node-specific ones) are ignored;
    inside the sections, unknown keys are errors. Raises :class:`ConfigError`."""
    flat = {k: v for k, v in params.items() if k.split(".")[0] in SECTIONS}
    digest = hashlib.sha256(repr(sorted(flat.items())).encode()).hexdigest()
    return VehicleConfig(validate_flat(flat, source=source), source, digest)


def default_config_path() -> Path:
    """Path of the vehicle file used when none is given (``--config``, ``config_file``, ``--params-file``).

    Order: in an installed workspace (this module imported from a colcon install space, e.g. ``ros_ws/install`` or
    ``/ws/install``), ``share/hindrax_common/config/hindrax.yaml`` of that install; otherwise (repository checkout,
    editable dev venv) the repository's ``ros_ws/config/hindrax.yaml``, found by walking up from this file, then the
    installed share directory. The canonical file is the repository's ``ros_ws/config/hindrax.yaml``; the package
    installs it through the symlink ``src/hindrax_common/config -> ../../ros_ws/config``. The environment variable
    ``HINDRAX_CONFIG``, when set, names the file instead (the Docker image sets it to the mounted vehicle file). Raises
    FileNotFoundError naming the places searched."""
    env = os.environ.get("HINDRAX_CONFIG")
    if env:
        if Path(env).is_file():
            return Path(env)
        raise FileNotFoundError(f"HINDRAX_CONFIG={env}: no such file")
    here = Path(__file__).resolve()
    source_tree = [p / "ros_ws" / "config" / "hindrax.yaml" for p in here.parents]
    installed: list[Path] = []
    in_install_space = False
    try:  # colcon install (the vehicle) or the ament index of the dev venv
        installed.append(Path(get_package_share_directory("hindrax_common")) / "config" / "hindrax.yaml")
        in_install_space = Path(get_package_prefix("hindrax_common")).resolve() in here.parents
    except Exception:  # noqa: BLE001 - no ament index entry (plain checkout) is fine
        pass
    candidates = installed + source_tree if in_install_space else source_tree + installed
    for c in candidates:
        if c.is_file():
            return c
    raise FileNotFoundError("hindrax.yaml not found; searched: " + ", ".join(str(c) for c in candidates[:4]))
