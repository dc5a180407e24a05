"""The virtual pool's truth: what the water, the thrusters and the sensors really do, apart from the vehicle file.

A *truth file* (``ros_ws/config/truth/*.yaml``, docs/virtual_pool.md §2) overlays the vehicle
configuration for the simulator and the device emulators only (:attr:`Truth.config`): any key of the
vehicle schema, nested as in ``hindrax.yaml`` without the ``/**: ros__parameters:`` wrapper, plus
``simulation.sensors.<device>.*`` (the simulated sensors' noise, bias, rate, dropouts:
:mod:`.sensors`) and ``disturbances.*`` (:class:`Disturbances`, every one off by default). The
shipped ``default.yaml`` (default sensor noise, no disturbance) fills the keys the vehicle
configuration lacks; a truth file given with ``--truth`` then overrides any key.

Disturbances (``disturbances:`` section; the physical source of each; all default off):

``thrust.scale`` (all thrusters), ``thrust.per_thruster`` (n factors), ``thrust.positive`` / ``thrust.negative``
    (per rotation direction): a different propeller, fouling, a worn motor, the asymmetry of a propeller in
    reverse (Blue Robotics T200 data: reverse about 78 % of forward at the same |dPWM|, docs/devices.md §5.3).
``battery``: ``voltage_start_v`` falling linearly to ``voltage_end_v`` over ``duration_s``; thrust scales as
    (V / ``nominal_voltage_v``)^``exponent``, exponent 1.2 from the T200 full-throttle thrust at 10-20 V
    (docs/devices.md §5.3: 12 V -> 16 V gives x1.41). The open-loop ESC has no speed regulation.
``inflow.loss_per_m_s``: thrust loss with the advance ratio J = V_a / (n D): K_T(J) falls roughly linearly
    (open-water propeller curves; [NTNU-Thesis] §1.1 and [SmallROV]: thrust depends on the vehicle's speed),
    modelled at the fixed rotation rate of a held pulse width as F = F_0 (1 - k V_a), V_a = the water speed into
    the propeller along its thrust (clipped to 0.0 .. 1.5).
``esc.output_latency_s`` / ``thrusters.time_constant_s`` / ``thrusters.deadband_us`` (vehicle keys in the
    truth file): the real ESC delay, spin-up lag and deadband where they differ from the vehicle file's.
``hydrodynamics.added_mass_coupling`` (vehicle key in the truth file, non-symmetric allowed) and
    ``hydrodynamics.damping_coupling_linear`` (36 values, row-major, diagonal ignored): off-diagonal added mass
    and linear damping of an open frame (Fossen 2011 §6; [NTNU-Thesis] §2.3: the frame is not symmetric).
``hydrodynamics.drag_centre_offset_frd_m``: the translational drag acts at this point instead of the origin
    (the centre of pressure of a frame with floats on top is above the CG), so surge/sway drag gives a moment.
``current``: ``velocity_ned_m_s`` plus ``amplitude_ned_m_s`` sin(2 pi t / ``period_s``): pool circulation from
    the filter pumps; damping acts on the velocity relative to the water (Fossen 2011 §10.3). Added-mass
    effects of the slowly varying current are neglected.
``tether``: a neutrally buoyant tether from ``anchor_ned_m`` (pool edge) to ``attachment_frd_m``: lumped drag
    ``drag_n_s2_m3`` x deployed length x |v| v of the attachment point through the water, plus a constant
    ``tension_n`` towards the anchor (the handler's pull) ([NTNU-Thesis] eq. 3.19 subtracts a known tether force).
``floor``: heave added mass grows near the floor (image method: about (reference/h)^3):
    ``heave_added_mass_fraction`` x M_A33 x (``reference_altitude_m`` / h)^3 at altitude h of the hull bottom,
    applied as -dM w_dot with the previous step's heave acceleration; ``dvl_noise_gain``: the DVL noise
    multiplied by 1 + gain (reference / h)^2 (beam footprint and side lobes near the floor); ``gradient``: a sloped
    floor, the depth change per metre (north, east) about the pool centre (a pool's shallow end, a beach; the DVL and
    Ping1D altitudes and the floor contact follow it, :mod:`.pool`).
``dvl``: ``scale_factor`` (speed-of-sound or transducer error), ``misalignment_rpy_rad`` (mounting),
    ``latency_s`` (reports the velocity that was), ``multipath_distance_m`` / ``multipath_dropout_probability``
    (side-lobe returns from walls: a report is lost with probability p (1 - d / distance) within that distance).
``imu``: ``gyro_bias_walk_rad_s_sqrt_s``, ``accel_bias_walk_m_s2_sqrt_s``: bias random walk (MEMS bias
    instability; ICM-20948 datasheet §3.1 lists the initial tolerance, the walk is an ASSUMPTION).
``pressure``: ``drift_pa_per_s`` (temperature drift of the MS5837 after power-up) and ``random_walk_pa_sqrt_s``."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any, Mapping

import yaml
from ament_index_python.packages import get_package_share_directory

from hindrax_common.config import ConfigError, VehicleConfig, default_config_path, flatten, validate_flat

__all__ = ["Disturbances", "Truth", "TruthError", "default_truth_path", "truth_dir", "load_truth",
           "truth_from_mapping", "with_floor_gradient", "DISTURBANCE_SCHEMA"]


class TruthError(ValueError):
    """A truth file that cannot be used (one line per issue: key, value, allowed range)."""


def truth_dir() -> Path:
    """The truth files: ``truth/`` beside the vehicle file in use (the repository's ``ros_ws/config/truth``, or
    ``share/hindrax_common/config/truth`` of a colcon install); when the vehicle file is elsewhere
    (``HINDRAX_CONFIG`` naming a mounted file), the installed ``share/hindrax_common/config/truth``. Raises
    :class:`TruthError` naming the places searched when neither exists."""
    beside = default_config_path().parent / "truth"
    if beside.is_dir():
        return beside
    searched = [beside]
    try:
        installed = Path(get_package_share_directory("hindrax_common")) / "config" / "truth"
        if installed.is_dir():
            return installed
        searched.append(installed)
    except Exception:  # noqa: BLE001 - no ament index entry: report what was searched
        pass
    raise TruthError(f"no truth files: searched {', '.join(str(p) for p in searched)}")


def default_truth_path() -> Path:
    """The shipped default truth (today's sensor noise, no disturbance)."""
    return truth_dir() / "default.yaml"


#: disturbances.<key> -> (default, lo, hi, length or None for a scalar). Lengths "n" = number of thrusters.
DISTURBANCE_SCHEMA: dict[str, tuple[Any, float, float, Any]] = {
    "thrust.scale": (1.0, 0.0, 3.0, None),
    "thrust.per_thruster": ((), 0.0, 3.0, "n"),
    "thrust.positive": (1.0, 0.0, 3.0, None),
    "thrust.negative": (1.0, 0.0, 3.0, None),
    "battery.voltage_start_v": (0.0, 0.0, 60.0, None),
    "battery.voltage_end_v": (0.0, 0.0, 60.0, None),
    "battery.nominal_voltage_v": (14.8, 1.0, 60.0, None),
    "battery.duration_s": (600.0, 1.0, 1e6, None),
    "battery.exponent": (1.2, 0.0, 3.0, None),
    "inflow.loss_per_m_s": (0.0, 0.0, 5.0, None),
    "hydrodynamics.damping_coupling_linear": ((0.0,) * 36, -100.0, 100.0, 36),
    "hydrodynamics.drag_centre_offset_frd_m": ((0.0, 0.0, 0.0), -1.0, 1.0, 3),
    "current.velocity_ned_m_s": ((0.0, 0.0, 0.0), -2.0, 2.0, 3),
    "current.amplitude_ned_m_s": ((0.0, 0.0, 0.0), -2.0, 2.0, 3),
    "current.period_s": (60.0, 0.1, 1e5, None),
    "tether.anchor_ned_m": ((0.0, 3.0, 0.0), -100.0, 100.0, 3),
    "tether.attachment_frd_m": ((-0.25, 0.0, -0.1), -2.0, 2.0, 3),
    "tether.drag_n_s2_m3": (0.0, 0.0, 100.0, None),
    "tether.tension_n": (0.0, 0.0, 100.0, None),
    "floor.heave_added_mass_fraction": (0.0, 0.0, 5.0, None),
    "floor.reference_altitude_m": (0.5, 0.01, 10.0, None),
    "floor.dvl_noise_gain": (0.0, 0.0, 100.0, None),
    "floor.gradient": ((0.0, 0.0), -0.5, 0.5, 2),
    "dvl.scale_factor": (1.0, 0.5, 1.5, None),
    "dvl.misalignment_rpy_rad": ((0.0, 0.0, 0.0), -0.5, 0.5, 3),
    "dvl.latency_s": (0.0, 0.0, 2.0, None),
    "dvl.multipath_distance_m": (0.0, 0.0, 10.0, None),
    "dvl.multipath_dropout_probability": (0.0, 0.0, 1.0, None),
    "imu.gyro_bias_walk_rad_s_sqrt_s": (0.0, 0.0, 1.0, None),
    "imu.accel_bias_walk_m_s2_sqrt_s": (0.0, 0.0, 10.0, None),
    "pressure.drift_pa_per_s": (0.0, -100.0, 100.0, None),
    "pressure.random_walk_pa_sqrt_s": (0.0, 0.0, 1000.0, None),
}


@dataclass(frozen=True)
class Disturbances:
    """Validated ``disturbances.*`` values (module docstring); ``values`` maps every schema key to its value.

    Groups (built once; the default where the file does not set a key): ``thrust``, ``battery``, ``inflow``,
    ``hydrodynamics``, ``current``, ``tether``, ``floor``, ``dvl``, ``imu``, ``pressure``."""

    values: Mapping[str, Any] = field(default_factory=dict)

    def __getattr__(self, group: str) -> SimpleNamespace:
        """``disturbances.<group>.*`` as attributes, built on first use and kept (called only for
        a name that is not an attribute yet). Raises ``AttributeError`` for an unknown group."""
        prefix = f"{group}."
        keys = [k for k in DISTURBANCE_SCHEMA if k.startswith(prefix)]
        if not keys:
            raise AttributeError(f"{type(self).__name__} has no disturbance group {group!r}")
        value = SimpleNamespace(**{k[len(prefix):]: self.get(k) for k in keys})
        self.__dict__[group] = value  # a plain attribute from now on, as a cached_property
        return value

    def get(self, key: str) -> Any:
        """Value of ``disturbances.<key>`` (the default when the file does not set it)."""
        return self.values.get(key, DISTURBANCE_SCHEMA[key][0])

    def is_set(self, *prefixes: str) -> bool:
        """True when any key starting with one of ``prefixes`` differs from its default."""
        return any(k.startswith(prefixes) and self._differs(k) for k in self.values)

    def _differs(self, key: str) -> bool:
        v, d = self.values[key], DISTURBANCE_SCHEMA[key][0]
        if key == "thrust.per_thruster":
            return any(float(x) != 1.0 for x in v)
        if isinstance(d, tuple):
            return tuple(float(x) for x in v) != d
        return float(v) != float(d)

    @property
    def active(self) -> list[str]:
        """The keys that differ from their defaults (empty: a pool that does what the vehicle file says)."""
        return sorted(k for k in self.values if self._differs(k))


def _validate_disturbances(flat: Mapping[str, Any], n_thrusters: int, source: str) -> Disturbances:
    issues: list[str] = []
    out: dict[str, Any] = {}
    for key, value in flat.items():
        if key not in DISTURBANCE_SCHEMA:
            issues.append(f"disturbances.{key}: {value!r}: no such key (known: "
                          f"{', '.join(sorted({k.split('.')[0] for k in DISTURBANCE_SCHEMA}))}.*)")
            continue
        _, lo, hi, length = DISTURBANCE_SCHEMA[key]
        want = 1 if length is None else n_thrusters if length == "n" else length
        xs = [value] if length is None else value
        if not (isinstance(xs, (list, tuple)) and len(xs) == want and all(
                isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(float(x))
                and lo <= float(x) <= hi for x in xs)):
            what = "a number" if length is None else f"{want} numbers"
            issues.append(f"disturbances.{key}: {value!r}: {what} in [{lo:g}, {hi:g}]")
        else:
            out[key] = float(value) if length is None else tuple(float(x) for x in value)
    a, b = "battery.voltage_start_v", "battery.voltage_end_v"
    if (a in out) != (b in out):
        missing = a if a not in out else b
        issues.append(f"disturbances.{missing}: <missing>: set both battery voltages")
    if issues:
        raise TruthError(f"{source}: " + "; ".join(issues))
    return Disturbances(out)


@dataclass(frozen=True)
class Truth:
    """The simulator's world: ``config`` (vehicle file + truth overlay, validated with the vehicle schema),
    ``disturbances``, ``vehicle`` (the vehicle file as the nodes see it), ``overlay`` (flat keys the truth file
    set), ``source`` (path or description)."""

    config: VehicleConfig
    disturbances: Disturbances
    vehicle: VehicleConfig
    overlay: Mapping[str, Any]
    source: str

def truth_from_mapping(vehicle: VehicleConfig, doc: Any, source: str = "truth", fill_only: bool = False) -> Truth:
    """A :class:`Truth` from a parsed truth document (nested mapping, module docstring).

    fill_only: only keys the vehicle configuration lacks are taken from ``doc`` (how the default truth is
    applied when no truth file is given, so a configuration that already sets ``simulation.sensors.*``, e.g. a
    test's, keeps its values). Raises :class:`TruthError` (one line per issue)."""
    if doc is None:
        doc = {}
    if isinstance(doc, Mapping) and len(doc) == 1 and isinstance(next(iter(doc.values())), Mapping) \
            and "ros__parameters" in next(iter(doc.values())):
        raise TruthError(f"{source}: a truth file is a plain overlay (sections at the top level), not a ROS "
                         "params file: remove the '/**: ros__parameters:' wrapper")
    if not isinstance(doc, Mapping):
        raise TruthError(f"{source}: <file>: {type(doc).__name__}: a mapping of configuration sections")
    body = dict(doc)
    dist_doc = body.pop("disturbances", None) or {}
    if not isinstance(dist_doc, Mapping):
        raise TruthError(f"{source}: disturbances: {dist_doc!r}: a mapping")
    overlay = flatten(body) if body else {}
    flat = dict(vehicle.flat)
    if fill_only:
        overlay = {k: v for k, v in overlay.items() if k not in flat}
    flat.update(overlay)
    try:
        cfg = VehicleConfig(validate_flat(flat, source=source), source, vehicle.sha256)
    except ConfigError as exc:
        raise TruthError(f"{source}: " + "; ".join(exc.lines())) from exc
    dist = _validate_disturbances(flatten(dict(dist_doc)), len(cfg.thrusters.names), source)
    return Truth(cfg, dist, vehicle, overlay, source)


def load_truth(vehicle: VehicleConfig, path: str | Path | None = None) -> Truth:
    """The truth over ``vehicle``: the shipped default fills the keys ``vehicle`` lacks (the simulated sensors),
    then the truth file at ``path`` (if any) overrides any key and sets the disturbances. A truth file therefore
    only states what differs from the vehicle file and the default noise.

    Raises :class:`TruthError` for an unreadable file, bad YAML or invalid keys (one line per issue)."""
    default = truth_from_mapping(vehicle, _read(default_truth_path()), str(default_truth_path()), fill_only=True)
    if path is None:
        return default
    p = Path(path)
    t = truth_from_mapping(default.config, _read(p), str(p))
    return Truth(t.config, t.disturbances, vehicle, {**default.overlay, **t.overlay}, str(p))


def _read(p: Path) -> Any:
    try:
        return yaml.safe_load(Path(p).read_text())
    except OSError as exc:
        raise TruthError(f"{p}: cannot read ({exc.strerror})") from exc
    except yaml.YAMLError as exc:
        raise TruthError(f"{p}: not valid YAML ({str(exc).splitlines()[0]})") from exc


def with_floor_gradient(truth: Truth, gradient_ne) -> Truth:
    """The same truth with the floor sloped by ``gradient_ne`` (north, east depth change per metre; the
    ``floor.gradient`` disturbance, module docstring). Raises :class:`TruthError` for a value out of range."""
    values = dict(truth.disturbances.values)
    values["floor.gradient"] = tuple(float(x) for x in gradient_ne)
    dist = _validate_disturbances(values, len(truth.config.thrusters.names), truth.source)
    return Truth(truth.config, dist, truth.vehicle, truth.overlay, truth.source)


def without_sensor_noise(truth: Truth) -> Truth:
    """The same truth with the simulated sensors' white noise, dropouts and DVL scale error set to zero
    (``simulation.sensors.*.noise_std_*``, ``dropout_probability``, ``dvl75.scale_error_fraction``); biases, rates
    and the truth's disturbances are kept. With :func:`hindrax_sim.control_evaluate.run_case` also turning off
    the DVL beam-range noise, this is the diagnostic that separates the model's error from the sensor noise
    (docs/control.md §6; ``hindrax control evaluate --no-sensor-noise``). Raises :class:`TruthError` if the
    configuration does not validate (it always should)."""
    quiet = {k: 0.0 for k in truth.config.flat
             if k.startswith("simulation.sensors.") and (".noise_std_" in k or k.endswith(".dropout_probability")
                                                          or k.endswith(".scale_error_fraction"))}
    try:
        config = truth.config.with_overrides(quiet)
    except ConfigError as exc:
        raise TruthError(f"{truth.source}: {exc}") from exc
    return Truth(config, truth.disturbances, truth.vehicle, truth.overlay, f"{truth.source} (sensor noise off)")
