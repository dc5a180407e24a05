"""Build the thrust model (curves, thrust allocation matrix, allocator) from the vehicle configuration.

The allocation node, the ``hindrax allocate`` command, the simulator and the identification regression all
call these functions, so every one of them uses the same curves and matrix."""
from __future__ import annotations

import numpy as np

from hindrax_common.config import VehicleConfig
from hindrax_drivers.pca9685 import protocol as pca
from .allocator import ThrustAllocator
from .matrix import thrust_allocation_matrix
from hindrax_common.base.thrust_curve import ThrustCurve


def thrust_curve_from_config(cfg: VehicleConfig) -> ThrustCurve:
    """The shared two-branch cubic thrust curve ([Hindrax-Drag] eq. 1) with the configured PWM range and deadband."""
    t = cfg.thrusters
    return ThrustCurve(negative=t.curve_negative, positive=t.curve_positive,
                       pulse_width_min_us=t.pulse_width_min_us, pulse_width_neutral_us=t.pulse_width_neutral_us,
                       pulse_width_max_us=t.pulse_width_max_us, deadband_us=t.deadband_us)


def allocation_matrix_from_config(cfg: VehicleConfig) -> np.ndarray:
    """Thrust allocation matrix B (6, n), body FRD about the CG ([Hindrax-Drag] eq. 9): column i = [d_i; r_i x d_i]."""
    t = cfg.thrusters
    return thrust_allocation_matrix(t.positions_frd_m - cfg.vehicle.centre_of_gravity_frd_m, t.directions_frd)


def pca9685_pulse_step_us(cfg: VehicleConfig) -> float:
    """Pulse-width resolution of the PCA9685 at the configured frequency and oscillator, us per count.

    PRE_SCALE = round(f_osc / (4096 f)) - 1; one count = (PRE_SCALE + 1) / f_osc (docs/devices.md §5.1)."""
    f_osc = cfg.esc.oscillator_hz
    return pca.count_duration_us(pca.prescale_for_frequency(cfg.esc.pwm_frequency_hz, f_osc), f_osc)


def allocator_from_config(cfg: VehicleConfig) -> ThrustAllocator:
    """The ThrustAllocator of the configuration: weighted pseudo-inverse with the per-thruster allocation
    weights, the configured saturation mode and priority DOFs, and the PCA9685 pulse step."""
    t = cfg.thrusters
    weights = np.array([th.allocation_weight for th in t.thrusters])
    return ThrustAllocator(allocation_matrix_from_config(cfg), thrust_curve_from_config(cfg), weights=weights,
                           mode=t.allocation_mode, priority_groups=(tuple(t.priority_dofs),),
                           pulse_width_step_us=pca9685_pulse_step_us(cfg))
