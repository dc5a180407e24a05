"""The validated vehicle configuration, :class:`VehicleConfig`: typed sections built on first use
from the flat dotted keys, derived views (rigid-body and added-mass matrices, hydrodynamics per DOF,
calibration forces) and the ROS-parameter conversion.

Typed access (``cfg.esc.output_latency_s``, ``cfg.supervisor.min_rate.imu_hz``): a misspelt name is an AttributeError
that mypy and the import of a module's tests catch, not a KeyError on the vehicle. The classes live in
:mod:`.typed_sections` (its docstring: fields, absent keys), generated from the schema by
``scripts/gen_config_sections.py`` (a test checks the file is current): written by hand next to a 250-key schema they
would drift, and generated at import time they would hide from mypy. Section objects are built once per configuration
(it is immutable). ``cfg.thrusters`` is the hand-written :class:`~.sections.thrusters.ThrustersConfig` (per-thruster
keys); ``cfg.dof_hydrodynamics(dof)`` and ``cfg.known_forces`` are derived views over ``cfg.hydrodynamics`` and
``cfg.calibration``. ``cfg.flat`` (dotted key -> value) stays for the ROS-parameter conversion, overrides and
validation; modules outside the configuration do not index it by a literal key."""
from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from typing import Any, Generic, Mapping, TypeVar

import numpy as np

from .sections import is_optional
from .sections.calibration import CalibrationConfig
from .sections.hydrodynamics import DofHydrodynamics, added_mass_matrix_from_flat
from .sections.thrusters import ThrustersConfig, thrusters_config
from .spec import DOFS, ROTATIONAL_DOFS
from .typed_sections import (ABSENT, CalibrationSection, ControlSection, EnvironmentSection,
                             EscSection, HydrodynamicsSection, IdentificationSection, LightsSection,
                             LimitsSection, PoolSection, RecordingSection, Section, SensorsSection,
                             SimulationSection, SupervisorSection, VehicleSection)
from .validation import validate_flat

__all__ = ["VehicleConfig", "build_section", "or_default"]

_S = TypeVar("_S", bound=Section)
_V = TypeVar("_V")


def or_default(value: _V | None, default: _V) -> _V:
    """``value``, or ``default`` when it is None (an absent optional key of a typed section)."""
    return default if value is None else value


def build_section(cls: type[_S], flat: Mapping[str, Any], prefix: str | None = None) -> _S:
    """The typed section ``cls`` (a generated :class:`~.typed_sections.Section`) at dotted path
    ``prefix`` (default ``cls.PREFIX``) from validated flat keys.

    Lists become tuples; an absent optional key is None; an absent required key (a node's selection of keys) is
    held as ABSENT and raises KeyError naming the key when read."""
    prefix = cls.PREFIX if prefix is None else prefix
    kw: dict[str, Any] = {}
    for f in dataclasses.fields(cls):  # type: ignore[arg-type]  # the generated sections are dataclasses
        if isinstance(f.type, type) and issubclass(f.type, Section):
            kw[f.name] = build_section(f.type, flat, f"{prefix}.{f.name}")
            continue
        key = f"{prefix}.{f.name}"
        if key in flat:
            v = flat[key]
            kw[f.name] = tuple(v) if isinstance(v, (list, tuple, np.ndarray)) else v
        else:
            kw[f.name] = None if is_optional(key) else ABSENT
    return cls.build(kw, prefix)


class _TypedSection(Generic[_S]):
    """A :class:`VehicleConfig` attribute: its typed section ``cls`` (``cfg.esc``), built from the
    flat keys on first use and kept (the configuration is immutable). ``doc``: what it holds."""

    def __init__(self, cls: type[_S], doc: str = "") -> None:
        self.cls = cls
        self.__doc__ = f"``{cls.PREFIX}.*``" + (f": {doc}" if doc else ".")

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    def __get__(self, cfg: Any, owner: type | None = None) -> _S:
        if cfg is None:
            return self  # type: ignore[return-value]  # the class attribute (documentation)
        section = build_section(self.cls, cfg.flat)
        cfg.__dict__[self.name] = section  # a plain attribute from now on, as a cached_property
        return section


@dataclass(frozen=True)
class VehicleConfig:
    """The validated vehicle configuration.

    Typed sections (built once, on first use), each under its section's name: ``vehicle``, ``environment``,
    ``hydrodynamics``, ``thrusters`` (:class:`ThrustersConfig`), ``esc``, ``lights``, ``sensors``, ``pool``, ``limits``,
    ``supervisor``, ``identification``, ``calibration``, ``control``, ``simulation``, ``recording`` (module docstring).
    Derived views: rigid-body and added-mass matrices, ``dof_hydrodynamics(dof)``, ``known_forces``. ``flat`` holds
    every validated key (dotted names, SI values) for the ROS-parameter conversion and overrides."""

    flat: Mapping[str, Any]
    source: str = ""
    sha256: str = ""

    # -- generic access by dotted key (tools that list or convert keys; modules read the typed sections) --
    def get(self, key: str) -> Any:
        """Value of a dotted key (KeyError if absent)."""
        return self.flat[key]

    # -- typed sections --
    vehicle = _TypedSection(VehicleSection, "rigid-body data.")
    environment = _TypedSection(EnvironmentSection, "water and gravity.")
    hydrodynamics = _TypedSection(HydrodynamicsSection, "per DOF: :meth:`dof_hydrodynamics`; the "
                                  "matrix: :attr:`added_mass_matrix`.")
    esc = _TypedSection(EscSection, "the PCA9685 ESC output.")
    lights = _TypedSection(LightsSection)
    sensors = _TypedSection(SensorsSection, "``dvl75``, ``ping1d``, ``ms5837``, ``icm20948``.")
    pool = _TypedSection(PoolSection, "the pool box and start pose.")
    limits = _TypedSection(LimitsSection, "the identification's own abort limits.")
    supervisor = _TypedSection(SupervisorSection, "the safety supervisor.")
    identification = _TypedSection(IdentificationSection)
    calibration = _TypedSection(CalibrationSection, "masses and volumes (:attr:`known_forces`: the derived forces).")
    control = _TypedSection(ControlSection, "the holds' settings (all optional: None when absent).")
    simulation = _TypedSection(SimulationSection, "the virtual pool's integration, sensor models.")
    recording = _TypedSection(RecordingSection, "the MCAP recorder.")

    # -- derived views --
    @property
    def weight_n(self) -> float:
        """W = m g, N."""
        return self.vehicle.mass_kg * self.environment.gravity_m_s2

    @property
    def buoyancy_n(self) -> float:
        """B = rho g V, N."""
        return self.environment.water_density_kg_m3 * self.environment.gravity_m_s2 * self.vehicle.displaced_volume_m3

    @property
    def inertia_matrix_kg_m2(self) -> np.ndarray:
        """3x3 inertia tensor about the CG, kg m^2 (products of inertia with the usual minus sign)."""
        ixx, iyy, izz = self.vehicle.inertia_kg_m2
        ixy, ixz, iyz = self.vehicle.products_of_inertia_kg_m2
        return np.array([[ixx, -ixy, -ixz], [-ixy, iyy, -iyz], [-ixz, -iyz, izz]])

    @property
    def added_mass_matrix(self) -> np.ndarray:
        """6x6 positive-definite added-mass matrix M_A, FRD, SNAME order (kg, kg m, kg m^2)."""
        return added_mass_matrix_from_flat(self.flat)

    @functools.cached_property
    def known_forces(self) -> CalibrationConfig:
        """The known forces of the reference steps derived from ``calibration.*`` (:class:`CalibrationConfig`)."""
        c = self.calibration
        rho, g = self.environment.water_density_kg_m3, self.environment.gravity_m_s2
        float_b = None
        if c.float_mass_kg is not None and c.float_volume_m3 is not None:
            float_b = (rho * c.float_volume_m3 - c.float_mass_kg) * g
        return CalibrationConfig(
            ballast_weight_in_water_n=(c.ballast_mass_kg - c.ballast_volume_m3 * rho) * g,
            line_pull_force_n=float(c.line_pull_force_n),
            inclining_weight_in_water_n=(c.inclining_mass_kg - c.inclining_volume_m3 * rho) * g,
            inclining_arm_m=float(c.inclining_arm_m),
            float_net_buoyancy_n=float_b,
            net_buoyancy_std_n=float(or_default(c.net_buoyancy_std_n, 0.05)))

    def dof_hydrodynamics(self, dof: str) -> DofHydrodynamics:
        """Hydrodynamic coefficients of one DOF, the same fields for every DOF (see :class:`DofHydrodynamics`)."""
        if dof not in DOFS:
            raise KeyError(f"unknown DOF {dof!r}; one of {', '.join(DOFS)}")
        hs = self.hydrodynamics
        if dof == "heave":
            v = hs.heave
            return DofHydrodynamics(dof, v.added_mass_kg, v.linear_damping_positive_kg_s,
                                    v.linear_damping_negative_kg_s, v.quadratic_damping_positive_kg_m,
                                    v.quadratic_damping_negative_kg_m)
        if dof in ROTATIONAL_DOFS:
            r = {"roll": hs.roll, "pitch": hs.pitch, "yaw": hs.yaw}[dof]
            return DofHydrodynamics(dof, r.added_mass_kg_m2, r.linear_damping_kg_m2_s, r.linear_damping_kg_m2_s,
                                    r.quadratic_damping_kg_m2, r.quadratic_damping_kg_m2)
        t = {"surge": hs.surge, "sway": hs.sway}[dof]
        return DofHydrodynamics(dof, t.added_mass_kg, t.linear_damping_kg_s, t.linear_damping_kg_s,
                                t.quadratic_damping_kg_m, t.quadratic_damping_kg_m)

    @functools.cached_property
    def thrusters(self) -> ThrustersConfig:
        """Typed thruster set (:func:`~.sections.thrusters.thrusters_config`); built once per configuration (the
        configuration is immutable; the control and identification loops read it at every tick)."""
        return thrusters_config(self.flat)

    def summary(self) -> str:
        """A short multi-line human summary of the vehicle (used by ``hindrax config check``)."""
        t, v = self.thrusters, self.vehicle
        lines = [
            f"vehicle {v.name}: mass {v.mass_kg:g} kg, volume {v.displaced_volume_m3:g} m^3, net buoyancy "
            f"{(self.buoyancy_n - self.weight_n):.3f} N (rho {self.environment.water_density_kg_m3:g} kg/m^3)",
            f"thrusters: {len(t.thrusters)} ({', '.join(t.names)}), pulse width "
            f"{t.pulse_width_min_us:g}-{t.pulse_width_max_us:g} us, neutral {t.pulse_width_neutral_us:g} us",
            "added mass (surge sway heave kg; roll pitch yaw kg m^2): "
            + " ".join(f"{v:g}" for v in np.diag(self.added_mass_matrix)),
            f"pool {self.pool.length_m:g} x {self.pool.width_m:g} x {self.pool.depth_m:g} m",
            f"sha256 {self.sha256[:12]}" if self.sha256 else "",
        ]
        return "\n".join(x for x in lines if x)

    def to_ros_parameters(self) -> dict[str, Any]:
        """Flat dotted ROS parameter names -> values (lists as lists), for ``--params-file`` or declare."""
        return {k: (list(v) if isinstance(v, (list, tuple, np.ndarray)) else v) for k, v in self.flat.items()}

    def with_overrides(self, overrides: Mapping[str, Any]) -> "VehicleConfig":
        """A new validated configuration with some dotted keys replaced (raises ConfigError)."""
        flat = dict(self.flat)
        flat.update(overrides)
        return VehicleConfig(validate_flat(flat, source=self.source), self.source, self.sha256)
