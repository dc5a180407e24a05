"""Vehicle configuration as the ROS 2 parameters of one node: declared per node, described, validated.

Each node declares only the vehicle keys it reads (``keys``: prefixes of :data:`hindrax_common.config.SCHEMA`
keys, e.g. ``("sensors.dvl75",)`` or ``("thrusters.names", "thrusters.<thruster>.position_frd_m")``); the other
keys of a params file or of ``parameter_overrides`` are not declared, but validated with the whole vehicle (below).
Each declared parameter gets a ``rcl_interfaces/ParameterDescriptor`` built from the schema: description
(meaning and unit), ``additional_constraints`` (the allowed range as the loader prints it), a
floating-point or integer range where the schema has both bounds, a static type, and ``read_only`` unless
the node can apply a change while running (``dynamic``). A change to a dynamic key is refused while the node's
``locked`` says why (the ESC armed: :class:`hindrax_common.node_support.esc_state.ArmedWatch`), else validated like the
file (type, range, cross-key checks) and then handed to the node's ``on_change``; a rejected change returns
``SetParametersResult(successful=False, reason=<one line naming key, value and allowed range>)``. A change
to a read-only key is refused by rclpy with the reason ``Trying to set a read-only parameter: <name>.``

Where the values come from, per key: an override (``--ros-args --params-file hindrax.yaml``, ``-p``,
``parameter_overrides``) if there is one, else the node's ``config_file`` parameter's file, else the
vehicle file found by :func:`hindrax_common.config.default_config_path` (the repository's
``ros_ws/config/hindrax.yaml`` in a checkout, ``share/hindrax_common/config/hindrax.yaml`` when installed).
So ``ros2 run hindrax_drivers dvl75_node --ros-args -p sensors.dvl75.port:=/dev/ttyUSB0`` works without a
params file. A file named by ``config_file`` is validated whole by :func:`hindrax_common.config.load_config`;
the node's own keys are validated again after the overrides are applied. Every override in the vehicle's sections,
declared by the node or not, is validated with the rest of the vehicle as ``hindrax config check`` validates a file
(:func:`check_whole_vehicle`): a node refuses what ``config check`` refuses, in the same one line.

Node parameters (:func:`declare_node_parameter`): a value that belongs to how a process runs a node, not to the
vehicle (a single-process graph widens the safety heartbeats' timeout, a simulator that holds time on purpose the
clock-stall checks), is a parameter of that node outside the vehicle file's sections. It is declared with a
:class:`~hindrax_common.config.Spec` (type, range, meaning), read-only, defaulting to the vehicle key it
refines, validated like a vehicle key (one line naming key, value and allowed range) and set by a parameter override
(``parameter_overrides``, ``-p``), so ``ros2 param get`` shows the value the node uses.

Only public rclpy API is used (declare_parameter, get_parameter, set_parameters, set_descriptor,
add_on_set_parameters_callback)."""
from __future__ import annotations

import array
import functools
import hashlib
import sys
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.parameter import Parameter

from .. import config as _c
from . import SCHEMA, SECTIONS, ConfigError, ConfigIssue, Spec, VehicleConfig
from .sections import cross_checks

__all__ = ["select_schema_keys", "concrete_keys", "validate_selection",
           "declare_vehicle_parameters", "CONFIG_FILE_PARAMETER", "vehicle_overrides",
           "check_whole_vehicle", "declare_node_parameter", "params_files"]

#: Name of the parameter naming a vehicle file to take defaults from ("" = the shipped file).
CONFIG_FILE_PARAMETER = "config_file"
_T = "<thruster>"


def _matches(key: str, prefixes: Iterable[str]) -> bool:
    return any(key == p or key.startswith(p.rstrip(".") + ".") for p in prefixes)


def select_schema_keys(prefixes: Sequence[str] | None = None) -> list[str]:
    """SCHEMA keys (generic, ``<thruster>`` unexpanded) under any of ``prefixes`` (None: every section).

    ``thrusters.names`` is added whenever a per-thruster key is selected (it names the thrusters).
    Raises ValueError for a prefix that selects nothing (a typo in a node's key list)."""
    if prefixes is None:
        prefixes = SECTIONS
    prefixes = tuple(prefixes)
    for p in prefixes:
        if not any(_matches(k, [p]) for k in SCHEMA):
            raise ValueError(f"no vehicle configuration key under {p!r}")
    keys = [k for k in SCHEMA if _matches(k, prefixes)]
    if any(_T in k for k in keys) and "thrusters.names" not in keys:
        keys.insert(0, "thrusters.names")
    return keys


def concrete_keys(generic: Sequence[str], thruster_names: Sequence[str]) -> list[str]:
    """Expand ``<thruster>`` in generic SCHEMA keys with the configured thruster names (order kept)."""
    out: list[str] = []
    for k in generic:
        out.extend([k.replace(_T, n) for n in thruster_names] if _T in k else [k])
    return out


def _generic(key: str) -> str:
    parts = key.split(".")
    if key not in SCHEMA and len(parts) == 3 and parts[0] == "thrusters":
        return f"thrusters.{_T}.{parts[2]}"
    return key


def validate_selection(flat: Mapping[str, Any], generic: Sequence[str], source: str = "") -> dict[str, Any]:
    """Validate the values of a node's selected keys like the file loader does.

    flat: concrete key -> value (None or absent = not given). generic: the node's SCHEMA keys.
    Returns the coerced values (absent optional keys left out). Raises :class:`ConfigError` listing every
    issue: wrong type, out of range, missing required key, cross-key inconsistency among the selected keys."""
    names_raw = flat.get("thrusters.names")
    names = [n for n in names_raw if isinstance(n, str)] if isinstance(names_raw, (list, tuple)) else []
    issues: list[ConfigIssue] = []
    out: dict[str, Any] = {}
    for key in concrete_keys(generic, names):
        spec = SCHEMA[_generic(key)]
        value = flat.get(key)
        if value is None:
            if not _c.is_optional(key):
                issues.append(ConfigIssue(key, "<missing>", spec.allowed()))
            continue
        coerced, issue = _c.check_value(key, spec, value)
        if issue:
            issues.append(issue)
        else:
            out[key] = coerced
    if not issues:
        # cross-key checks among the selected keys only (a check on keys the node does not read is the file
        # loader's, which `hindrax config check` and every node reading those keys run)
        issues.extend(i for i in cross_checks(out) if i.key in out)
    if issues:
        raise ConfigError(issues, source)
    return out


def _descriptor(name: str, spec: Spec, read_only: bool) -> ParameterDescriptor:
    """``rcl_interfaces/ParameterDescriptor`` of a parameter from its Spec: description, additional_constraints "allowed
    <range>", ranges for scalar numbers with both bounds; the type is left to the caller."""
    d = ParameterDescriptor(name=name, description=spec.doc, additional_constraints=f"allowed {spec.allowed()}",
                            read_only=read_only)
    if spec.kind == "float" and spec.lo is not None and spec.hi is not None:
        d.floating_point_range = [FloatingPointRange(from_value=float(spec.lo), to_value=float(spec.hi), step=0.0)]
    elif spec.kind == "int" and spec.lo is not None and spec.hi is not None and spec.choices is None:
        d.integer_range = [IntegerRange(from_value=int(spec.lo), to_value=int(spec.hi), step=1)]
    return d


@functools.lru_cache(maxsize=8)
def _load_cached(path: str, mtime_ns: int, size: int) -> VehicleConfig:
    return _c.load_config(path)


def _load(path: str | Path) -> VehicleConfig:
    p = Path(path)
    try:
        st = p.stat()
    except OSError:
        return _c.load_config(p)  # raises the loader's one-line "a readable file" error
    return _load_cached(str(p), st.st_mtime_ns, st.st_size)


def _plain(value: Any) -> Any:
    return list(value) if isinstance(value, (array.array, tuple)) else value


def vehicle_overrides(node: Any) -> dict[str, Any]:
    """The overrides (``--params-file``, ``-p``, ``parameter_overrides``) a node was started with that fall in the
    vehicle file's sections, declared by the node or not: dotted key -> plain value.

    rclpy keeps them in ``Node._parameter_overrides`` and has no public accessor for the undeclared ones (``/**``
    keys of another node's section are among them); read defensively (an empty mapping if that changes). A null
    nullable key (:data:`hindrax_common.config.NULLABLE_KEYS`) is left out, as the file loader does."""
    overrides = getattr(node, "_parameter_overrides", None) or {}
    out = {name: _plain(p.value) for name, p in overrides.items() if name.split(".")[0] in SECTIONS}
    # a YAML null (``esc.output_enable_gpio: null``, not wired) reaches rclpy as the string "null" from a params file
    return {k: v for k, v in out.items() if not (k in _c.NULLABLE_KEYS and v in (None, "null", "~", ""))}


def check_whole_vehicle(overrides: Mapping[str, Any], defaults: Mapping[str, Any], source: str) -> None:
    """Validate the vehicle a node is started with as a whole, as ``hindrax config check`` does the file: the
    ``defaults`` (a validated vehicle file, flat) with every vehicle-section override applied, including keys the
    node does not read. A misspelt key (``supervisor.max_dpth_m``, ``vehicle.mas_kg``: unknown key), a value out of
    range (``limits.max_roll_rad: 46``) or a failed cross-key check anywhere in the file stops the node, instead of
    the key being ignored as ROS 2 ignores an undeclared override. Nothing to do without overrides that change the
    defaults (validated when loaded), nor without defaults (no vehicle file found).

    Raises :class:`ConfigError` naming key, value and allowed range (``str()`` is the first issue, one line)."""
    changed = {k: v for k, v in overrides.items() if k not in defaults or defaults[k] != v}
    if not changed or not defaults:
        return  # no vehicle file to complete a partial set: the node's own keys are still validated
    merged = dict(defaults)
    merged.update(overrides)
    issues = _whole_vehicle_issues(tuple(sorted((k, _frozen(v)) for k, v in merged.items())))
    if issues:
        raise ConfigError(list(issues), source)


def _frozen(value: Any) -> Any:
    return tuple(value) if isinstance(value, list) else value


@functools.lru_cache(maxsize=8)
def _whole_vehicle_issues(items: tuple) -> tuple[ConfigIssue, ...]:
    """The issues :func:`hindrax_common.config.validate_flat` finds in a whole vehicle (flat items), computed once
    per distinct vehicle: a composed process starts several nodes with the same parameters."""
    try:
        _c.validate_flat({k: (list(v) if isinstance(v, tuple) else v) for k, v in items})
    except ConfigError as exc:
        return tuple(exc.issues)
    return ()


def declare_node_parameter(node: Any, name: str, spec: Spec, default: Any) -> Any:
    """Declare ``name``, a read-only parameter of ``node`` outside the vehicle file (module docstring), and return
    its validated value: the override the node was started with, else ``default`` (the vehicle key it refines).

    spec: type, range and one-line meaning (its ``doc`` becomes the description, its range the
    ``additional_constraints`` and the descriptor's range). Raises :class:`ConfigError` naming the parameter, the
    value and the allowed range (one line) for a value of the wrong type or out of range."""
    desc = ParameterDescriptor(name=name, description=spec.doc, additional_constraints=f"allowed {spec.allowed()}",
                               dynamic_typing=True)
    value = _plain(node.declare_parameter(name, default, desc).value)
    coerced, issue = _c.check_value(name, spec, value)
    source = f"parameters of {node.get_name()}"
    if issue is not None:
        node.undeclare_parameter(name)
        raise ConfigError([issue], source)
    if type(coerced) is not type(value):
        node.set_parameters([Parameter(name, value=coerced)])
    d = _descriptor(name, spec, read_only=True)
    d.type = Parameter(name, value=coerced).type_.value
    node.set_descriptor(name, d)
    return coerced


def params_files(argv: Sequence[str]) -> list[str]:
    """The ``--params-file FILE`` paths of the ROS arguments in ``argv`` (after a ``--ros-args``), in order."""
    ros = list(argv)[list(argv).index("--ros-args") + 1:] if "--ros-args" in argv else []
    return [ros[i + 1] for i, word in enumerate(ros[:-1]) if word == "--params-file"]


def declare_vehicle_parameters(node: Any, keys: Sequence[str] | None = None, *, dynamic: Sequence[str] = (),
                               on_change: Callable[[VehicleConfig], None] | None = None,
                               locked: Callable[[], str] | None = None) -> VehicleConfig:
    """Declare the node's vehicle keys as described ROS parameters and return them validated.

    node: an rclpy Node created *without* ``automatically_declare_parameters_from_overrides``.
    keys: SCHEMA key prefixes the node reads (None: every section, for nodes that use the whole vehicle, such as the
    simulator). dynamic: prefixes (within ``keys``) the node applies while running; they stay writable, everything
    else is read-only. on_change(cfg): called with the validated configuration after a change to dynamic keys; raise
    ValueError (or ConfigError) with the reason to refuse it. locked(): '' while a change may be applied, else the
    reason it is refused (``ArmedWatch.refusal``: safety-relevant keys are read-only while armed); required with
    dynamic keys. Returns a :class:`VehicleConfig` holding the node's keys only (``flat``). Raises
    :class:`ConfigError` (one line per issue) on a missing, mistyped or out-of-range value."""
    generic = select_schema_keys(keys)
    dynamic = tuple(dynamic)
    if dynamic and (on_change is None or locked is None):
        raise ValueError("dynamic keys need an on_change callback that applies them and a locked() check")
    if node.has_parameter(CONFIG_FILE_PARAMETER):
        config_file = node.get_parameter(CONFIG_FILE_PARAMETER).value or ""
    else:
        config_file = node.declare_parameter(
            CONFIG_FILE_PARAMETER, "", ParameterDescriptor(
                description="vehicle file giving the values of vehicle keys that no override sets "
                            "(empty: the shipped hindrax.yaml)", read_only=True)).value or ""

    defaults: dict[str, Any] = {}
    file_cfg: VehicleConfig | None = None
    default_error: ConfigError | None = None
    if config_file:
        file_cfg = _load(config_file)  # explicit file: its errors stop the node
    else:
        try:
            file_cfg = _load(_c.default_config_path())
        except FileNotFoundError:
            file_cfg = None
        except ConfigError as exc:  # reported only if the overrides do not supply the node's keys
            default_error = exc
    if file_cfg is not None:
        defaults = file_cfg.to_ros_parameters()

    source = config_file or (file_cfg.source if file_cfg else "")
    # the file the values came from: the process's --params-file (a launch's or the command line's) over the defaults
    given = ", ".join(params_files(sys.argv)) if not config_file else ""
    src = f"parameters of {node.get_name()}" + (f" (from {given})" if given else
                                                 f" (defaults from {source})" if source else "")
    check_whole_vehicle(vehicle_overrides(node), defaults, src)
    values: dict[str, Any] = {}

    def declare(key: str) -> Any:
        spec = SCHEMA[_generic(key)]  # the range is described from the start: an absent optional key keeps this
        desc = ParameterDescriptor(description=spec.doc, additional_constraints=f"allowed {spec.allowed()}",
                                   dynamic_typing=True)
        try:
            p = node.declare_parameter(key, defaults.get(key), desc)
        except (InvalidParameterValueException, InvalidParameterTypeException) as exc:  # pragma: no cover
            raise ConfigError([ConfigIssue(key, str(exc), spec.allowed())], source) from exc
        v = _plain(p.value)
        values[key] = v
        return v

    # thrusters.names first: it names the per-thruster keys.
    names = declare("thrusters.names") if "thrusters.names" in generic else []
    names = [n for n in names if isinstance(n, str)] if isinstance(names, list) else []
    declared = concrete_keys(generic, names)
    for key in declared:
        if key not in values:
            declare(key)
    overridden = any(values[k] is not None and values[k] != defaults.get(k) for k in declared)
    if default_error is not None and not overridden:
        raise default_error
    valid = validate_selection(values, generic, source=src)

    # Canonical types (an integer written for a float key becomes a float), then the final descriptors:
    # static type, range, read-only unless the node applies changes to the key.
    fix = [Parameter(k, value=v) for k, v in valid.items() if type(values[k]) is not type(v) or values[k] != v]
    if fix:
        node.set_parameters(fix)
    for key in declared:
        writable = _matches(_generic(key), dynamic) or _matches(key, dynamic)
        d = _descriptor(key, SCHEMA[_generic(key)], read_only=not writable)
        if key in valid:
            d.type = Parameter(key, value=valid[key]).type_.value
        else:  # an optional key with no value: declared without one, and as read-only as the others (issue 71.5)
            d.dynamic_typing = True
        node.set_descriptor(key, d)

    digest = (file_cfg.sha256 if (file_cfg is not None and not overridden)
              else hashlib.sha256(repr(sorted(valid.items())).encode()).hexdigest())
    state = {"cfg": VehicleConfig(valid, src, digest)}
    declared_set = set(declared)

    def on_set(params) -> SetParametersResult:
        changed = {p.name: _plain(p.value) for p in params if p.name in declared_set}
        if not changed:
            return SetParametersResult(successful=True)
        reason = locked() if locked is not None else ""
        if reason:
            return SetParametersResult(successful=False, reason=f"{', '.join(sorted(changed))}: {reason}; unchanged")
        candidate = dict(state["cfg"].flat)
        candidate.update(changed)
        try:
            new = VehicleConfig(validate_selection(candidate, generic, source="parameter update"),
                                "parameter update", state["cfg"].sha256)
            if on_change is not None:
                on_change(new)
        except ConfigError as exc:
            return SetParametersResult(successful=False, reason=exc.lines()[0])
        except ValueError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        state["cfg"] = new
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(on_set)
    return state["cfg"]

