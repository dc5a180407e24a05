"""Vehicle configuration: schema, validation, typed objects and ROS-parameter conversion.

One YAML file per vehicle (``ros_ws/config/hindrax.yaml``) in the ros-args params-file layout::

    /**:
      ros__parameters:
        vehicle:
          mass_kg: 15.22
        ...

Nested keys become dotted ROS parameter names (``vehicle.mass_kg``). Every key of the file is declared in
:data:`SCHEMA` with its type, unit (in the key name), allowed range and a one-line meaning; the loader rejects
unknown keys, wrong types and out-of-range values, reporting each as one line naming the key, the value and the
allowed range (docs/architecture.md §4). Geometry is in the marine body frame FRD with the origin at the centre of
gravity (docs/architecture.md §3); hydrodynamic coefficients are stored as positive numbers (Fossen/SNAME).
Thruster-specific keys use the thruster names of ``thrusters.names`` as a path segment (``thrusters.t3.esc_channel``);
the schema writes that segment as ``<thruster>``.

Where each thing is:

* :mod:`.spec`: :class:`Spec` (one key), :class:`ConfigIssue` / :class:`ConfigError` (the one-line errors), the
  check of one value; why our own validator is said there.
* :mod:`.sections`: one module per section of the file (``sections/esc.py``, ``sections/supervisor.py``, ...), each
  owning its keys' schema, its optional keys and its checks across keys; ``sections/__init__`` joins them.
* :mod:`.validation`: a flat mapping checked against every section; :mod:`.loader`: files and node parameters;
  :mod:`.vehicle_config`: :class:`VehicleConfig` and its typed sections (:mod:`.typed_sections`, generated).
* :mod:`.node_parameters`: the keys each node declares as described ROS parameters, validated like the file, and
  the read-only node parameters outside the file (rclpy; not imported here, so offline tools load no rclpy).

The names below are the package's API (``from hindrax_common.config import load_config``)."""
from __future__ import annotations

from .loader import config_from_parameters, default_config_path, load_config, ros_parameters_from_yaml
from .sections import NULLABLE_KEYS, OPTIONAL_PREFIXES, SCHEMA, SECTIONS, is_optional
from .sections.calibration import CalibrationConfig
from .sections.esc import output_enable_gpio
from .sections.hydrodynamics import DofHydrodynamics, added_mass_matrix_from_flat
from .sections.thrusters import ThrusterConfig, ThrustersConfig
from .spec import DOFS, ROTATIONAL_DOFS, TRANSLATIONAL_DOFS, ConfigError, ConfigIssue, Spec, check_value
from .validation import flatten, validate_flat
from .vehicle_config import VehicleConfig, build_section, or_default

__all__ = ["load_config", "VehicleConfig", "ConfigError", "ConfigIssue", "Spec", "SCHEMA", "SECTIONS",
           "OPTIONAL_PREFIXES", "NULLABLE_KEYS", "DOFS", "TRANSLATIONAL_DOFS", "ROTATIONAL_DOFS",
           "config_from_parameters", "default_config_path", "ros_parameters_from_yaml", "flatten", "validate_flat",
           "check_value", "is_optional", "output_enable_gpio", "added_mass_matrix_from_flat", "build_section",
           "or_default", "CalibrationConfig", "DofHydrodynamics", "ThrusterConfig", "ThrustersConfig"]
