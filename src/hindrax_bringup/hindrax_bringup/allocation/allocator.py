"""Thrust allocation: body wrench (FRD) -> thruster forces -> ESC pulse widths, pure numpy.

Given the thrust allocation matrix ``B`` (6, n) of [Hindrax-Drag] eq. 9 (``tau = B F``, tau = [X Y Z K M N] in N and N
m, FRD, origin at the centre of gravity) and one thrust curve per thruster ([Hindrax-Drag] eq. 1),
:class:`ThrustAllocator` turns a requested wrench into forces and pulse widths:

1. **Weighted minimum-norm solution.** ``F = B_W^+ tau`` with ``B_W^+ = W^-1/2 pinv(B W^-1/2)``, ``W
   = diag(weights)``: of the least-squares forces, the one minimising ``sum w_i F_i^2``, computed
   once per configuration (constructor, :meth:`ThrustAllocator.reconfigure`). An all-zero row of B
   (an axis without authority) gets no force and an achieved 0.
2. **Saturation.** Each thruster's reverse (< 0) and forward (> 0) limits come from its curve (times
   the battery ``voltage_scale``).

   * ``mode="uniform"``: the wrench is scaled by the largest ``s`` in (0, 1] keeping every force
     within its limits: the direction is kept exactly.
   * ``mode="priority"``: the axes are split into ordered ``priority_groups`` (default ``(("heave", "yaw"),)``; the
     others form a last group). Each group's part of the wrench is allocated with the same pseudo-inverse and added with
     the largest factor in [0, 1] that keeps all forces feasible: a group is reproduced exactly when feasible on top of
     the earlier ones, else scaled along its own direction (unlike ``scipy.optimize.lsq_linear``, which could turn the
     reduced axes). The null space of B is not used.
3. **Deadband.** An ESC gives 0 N inside its deadband (docs/devices.md §5.2). If a force of step 2
   falls in that gap, ``B F`` is allocated again by :class:`.deadband.DeadbandSearch`, which chooses which thrusters run
   as well as how hard (after [JohansenFossen2013]): ``X = -2 N`` runs one symmetric pair at 1.73 N instead of four at
   0.87 N. Otherwise step 2's forces are kept (the search costs nothing).
4. **Pulse widths and achieved wrench.** Each force is inverted on its curve (:mod:`.thrust_curve`), optionally on the
   PWM generator's grid (``pulse_width_step_us``, docs/devices.md §5.1) at the nearest width not in the deadband, and
   the *actual* thrust at that width is evaluated with the forward curve. The achieved wrench ``B @ force_n`` is what
   the thrusters will apply according to the model (for anti-windup).

Non-finite wrenches raise :class:`InvalidWrenchError` (docs/architecture.md §8)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .deadband import MAX_THRUSTERS, ZERO_FORCE_N, DeadbandSearch
from hindrax_common.base.thrust_curve import ThrustCurve, check_positive, forward_thrust

__all__ = ["AXIS_NAMES", "DEFAULT_PRIORITY_GROUPS", "InvalidWrenchError", "AllocationResult",
           "DEFAULT_EFFORT_WEIGHT", "ThrustAllocator", "weighted_pseudo_inverse"]

#: Wrench axes in order ([Hindrax-Drag] section 3 notation, SNAME): tau = [X Y Z K M N].
AXIS_NAMES: tuple[str, ...] = ("surge", "sway", "heave", "roll", "pitch", "yaw")
#: Default priority: heave and yaw first (depth and heading holding during the [Hindrax-Drag] tests).
DEFAULT_PRIORITY_GROUPS: tuple[tuple[str, ...], ...] = (("heave", "yaw"),)
_MODES = ("uniform", "priority")
_ZERO_ROW_TOLERANCE = 1e-12
#: Effort weight rho of the deadband search without a pulse-width step: about (0.0139 N / 1.204 N)^2, the
#: [Hindrax-Drag] eq. 1 curve's thrust resolution at the deadband edge with the PCA9685's 1.24 us step,
#: relative to the thrust there (what :meth:`ThrustAllocator.reconfigure` derives when the step is known).
DEFAULT_EFFORT_WEIGHT = 1e-4


class InvalidWrenchError(ValueError):
    """The requested wrench is not 6 finite numbers (NaN, inf, wrong shape or type)."""


@dataclass(frozen=True)
class AllocationResult:
    """Outcome of one :meth:`ThrustAllocator.allocate` call (FRD, N and N m, us).

    ``requested_wrench`` (6,): the request as given. ``allocated_force_n`` (n,): forces after saturation and deadband
    handling, before the curves and the pulse-width grid (``B @ allocated_force_n`` is the wrench the allocator aimed
    for; with the deadband search every force is 0 or outside the deadband). ``pulse_width_us`` (n,): ESC commands.
    ``force_n`` (n,): thrust the curves give at those pulse widths (deadband, small-force rule and quantisation
    included). ``achieved_wrench`` (6,): ``B @ force_n``. ``scale``: the uniform factor s in (0, 1] (``mode="uniform"``)
    or the smallest group factor in [0, 1] (``mode="priority"``). ``axis_scale`` (6,): factor applied to each axis of
    the request. ``saturated`` (n,) bool: the thruster's forward or reverse limit bounded the allocation (its force of
    the saturation step, or its allocated force, is at the limit)."""

    requested_wrench: np.ndarray
    allocated_force_n: np.ndarray
    force_n: np.ndarray
    pulse_width_us: np.ndarray
    achieved_wrench: np.ndarray
    scale: float
    axis_scale: np.ndarray
    saturated: np.ndarray


def weighted_pseudo_inverse(matrix, weights=None, rcond: float = 1e-10) -> np.ndarray:
    """Weighted Moore-Penrose pseudo-inverse ``W^-1/2 pinv(B W^-1/2)``, shape (n, 6) for B (6, n).

    ``F = result @ tau`` minimises ``sum w_i F_i^2`` among the least-squares solutions of ``B F = tau``
    (unconstrained weighted least-squares control allocation, Fossen 2011, Handbook of Marine Craft
    Hydrodynamics and Motion Control, control-allocation chapter). ``weights`` (n,) positive, default
    ones. Raises ``ValueError`` for bad shapes, non-finite values or non-positive weights."""
    b = np.asarray(matrix, dtype=float)
    if b.ndim != 2 or b.shape[0] != 6 or b.shape[1] < 1 or not np.all(np.isfinite(b)):
        raise ValueError(f"matrix must be a finite (6, n) array with n >= 1, got shape {b.shape}")
    n = b.shape[1]
    w = np.ones(n) if weights is None else np.asarray(weights, dtype=float)
    if w.shape != (n,) or not np.all(np.isfinite(w)) or not np.all(w > 0.0):
        raise ValueError(f"weights must be {n} finite positive numbers, got {weights!r}")
    root_inv = 1.0 / np.sqrt(w)
    return root_inv[:, None] * np.linalg.pinv(b * root_inv[None, :], rcond=rcond)


class _PulseGrid:
    """The pulse widths the generator can put out, per thruster: the grid of ``step`` us (or every width when
    ``step`` is None), and on it the widths and thrusts nearest the deadband (docs/devices.md §5.1, §5.2).

    ``smallest_forward_n`` / ``smallest_reverse_n`` (n,), magnitudes in N at ``voltage_scale = 1``: the thrust
    at the first width outside the deadband that the generator can produce (1525.20 us: 1.2038 N and
    1474.36 us: 1.2087 N for the [Hindrax-Drag] eq. 1 curve at the PCA9685's 1.24 us)."""

    def __init__(self, curves: Sequence[ThrustCurve], step: float | None) -> None:
        fwd_inner = np.array([c.forward_branch_us[0] for c in curves])
        rev_inner = np.array([c.reverse_branch_us[1] for c in curves])
        self.neutral = np.array([c.pulse_width_neutral_us for c in curves])
        self.step = step
        if step is None:
            self.first_forward_us, self.last_reverse_us = fwd_inner, rev_inner
            self.min_us = np.array([c.pulse_width_min_us for c in curves])
            self.max_us = np.array([c.pulse_width_max_us for c in curves])
        else:
            self.first_forward_us = np.ceil(fwd_inner / step - 1e-9) * step
            self.last_reverse_us = np.floor(rev_inner / step + 1e-9) * step
            self.min_us = np.array([math.ceil(c.pulse_width_min_us / step - 1e-9) * step for c in curves])
            self.max_us = np.array([math.floor(c.pulse_width_max_us / step + 1e-9) * step for c in curves])
        self.curves = tuple(curves)
        self.smallest_forward_n = np.array([c.thrust_n(p) for c, p in zip(curves, self.first_forward_us)])
        self.smallest_reverse_n = -np.array([c.thrust_n(p) for c, p in zip(curves, self.last_reverse_us)])

    def effort_weight(self) -> float:
        """``min (delta / m)^2`` over thrusters and directions with m > 0: delta the thrust of one step beyond
        the smallest thrust m (N per step at the deadband edge); :data:`DEFAULT_EFFORT_WEIGHT` if every m is 0.
        Only with a step."""
        step = float(self.step)  # type: ignore[arg-type]
        ratios = []
        for c, p_f, p_r, m_f, m_r in zip(self.curves, self.first_forward_us, self.last_reverse_us,
                                         self.smallest_forward_n, self.smallest_reverse_n):
            if m_f > 0.0:
                ratios.append((c.thrust_n(p_f + step) - m_f) / m_f)
            if m_r > 0.0:
                ratios.append((-c.thrust_n(p_r - step) - m_r) / m_r)
        return float(min(ratios) ** 2) if ratios else DEFAULT_EFFORT_WEIGHT

    def quantise(self, pulse: np.ndarray) -> np.ndarray:
        """Pulse widths (n,) to the nearest grid width, never into the deadband: a width above neutral stays at
        or above the first forward grid width, one below neutral at or below the last reverse one; within
        the grid's [min, max]. Without a step the widths are returned unchanged."""
        if self.step is None:
            return pulse
        q = self.step
        p = np.round(pulse / q) * q
        above = pulse > self.neutral + 1e-9
        below = pulse < self.neutral - 1e-9
        p = np.where(above, np.maximum(p, self.first_forward_us),
                     np.where(below, np.minimum(p, self.last_reverse_us), p))
        return np.minimum(np.maximum(p, self.min_us), self.max_us)


def _axis_index(axis) -> int:
    if isinstance(axis, str):
        if axis not in AXIS_NAMES:
            raise ValueError(f"unknown axis name {axis!r}; expected one of {AXIS_NAMES}")
        return AXIS_NAMES.index(axis)
    if isinstance(axis, (int, np.integer)) and not isinstance(axis, bool) and 0 <= int(axis) < 6:
        return int(axis)
    raise ValueError(f"axis must be a name in {AXIS_NAMES} or an index 0-5, got {axis!r}")


class ThrustAllocator:
    """Wrench -> thruster forces and pulse widths with saturation handling (see module docstring).

    Parameters
    ----------
    matrix:
        Thrust allocation matrix (6, n), FRD, [Hindrax-Drag] eq. 9 (see :mod:`.matrix`).
    curves:
        One :class:`ThrustCurve` shared by all thrusters, or a sequence of n of them.
    weights:
        Optional (n,) positive weights of the minimum-norm solution (higher = used less).
    mode:
        ``"uniform"`` (default) or ``"priority"``.
    priority_groups:
        For ``"priority"``: ordered groups of axes (names from :data:`AXIS_NAMES` or indices 0-5), highest priority
        first; axes not listed form a final group. Default :data:`DEFAULT_PRIORITY_GROUPS`. Ignored in uniform mode.
    pulse_width_step_us:
        Optional quantisation step of the pulse-width generator (us), e.g. the PCA9685 tick
        ``(PRE_SCALE + 1) * 1e6 / f_osc`` (docs/devices.md §5.1: 1.24 us at PRE_SCALE 30). ``None``: no quantisation.
    deadband_search:
        ``True`` (default): forces the thrusters cannot give (inside the ESC deadband) are avoided by choosing which
        thrusters run (:mod:`.deadband`); ``False``: each force is inverted on its own (small-force rule of
        :mod:`.thrust_curve`). Ignored (always ``False``) for more than :data:`.deadband.MAX_THRUSTERS` thrusters.
    effort_weight:
        rho of the deadband search (>= 0): the thrust spent, ``rho sum w_i F_i^2``, weighed against the
        squared wrench error. ``None`` (default): ``(delta / m)^2`` with m the smallest thrust outside the
        deadband and delta the thrust of one pulse-width step there (smallest over thrusters and directions),
        so a pair of thrusters is run against each other only to remove more than about one step's worth of
        wrench error; :data:`DEFAULT_EFFORT_WEIGHT` without a step.

    Raises ``ValueError`` for invalid configuration. Read-only attributes: ``matrix`` (6, n), ``pseudo_inverse`` (n, 6),
    ``curves`` (n ThrustCurve), ``mode``, ``priority_groups`` (tuples of axis indices, final group included),
    ``zero_authority_axes`` (6,) bool, ``n_thrusters``."""

    # Set by reconfigure() (which __init__ calls); declared here for the type checker.
    _matrix: np.ndarray
    _curves_arg: ThrustCurve | Sequence[ThrustCurve]
    _weights_arg: Sequence[float] | np.ndarray | None
    _mode: str
    _priority_groups_arg: Sequence[Sequence[int]]
    _step_us: float | None
    _search_on: bool
    _effort_weight_arg: float | None

    def __init__(self, matrix, curves: ThrustCurve | Sequence[ThrustCurve], weights=None, mode: str = "uniform",
                 priority_groups=DEFAULT_PRIORITY_GROUPS, pulse_width_step_us: float | None = None,
                 deadband_search: bool = True, effort_weight: float | None = None) -> None:
        self.reconfigure(matrix=matrix, curves=curves, weights=weights, mode=mode, priority_groups=priority_groups,
                         pulse_width_step_us=pulse_width_step_us, deadband_search=deadband_search,
                         effort_weight=effort_weight)

    # ----------------------------------------------------------------- configuration
    _KEEP = object()

    def reconfigure(self, matrix=_KEEP, curves=_KEEP, weights=_KEEP, mode=_KEEP, priority_groups=_KEEP,
                    pulse_width_step_us=_KEEP, deadband_search=_KEEP, effort_weight=_KEEP) -> None:
        """Change any of the constructor's parameters (others are kept) and recompute the pseudo-inverse and the
        deadband search's tables (about 50 ms for 8 thrusters).

        A kept shared curve or default (``None``) weights follow a new number of thrusters; kept
        per-thruster lists must still match it.

        The new configuration is validated completely before anything is replaced; on ``ValueError`` the
        allocator keeps its previous configuration."""
        keep = ThrustAllocator._KEEP
        b = np.array(self._matrix if matrix is keep else matrix, dtype=float)
        if b.ndim != 2 or b.shape[0] != 6 or b.shape[1] < 1 or not np.all(np.isfinite(b)):
            raise ValueError(f"matrix must be a finite (6, n) array with n >= 1, got shape {b.shape}")
        n = b.shape[1]
        curve_arg = self._curves_arg if curves is keep else curves
        try:
            curve_list = [curve_arg] * n if isinstance(curve_arg, ThrustCurve) else list(curve_arg)
        except TypeError:
            curve_list = []
        if len(curve_list) != n or not all(isinstance(c, ThrustCurve) for c in curve_list):
            raise ValueError(f"curves must be one ThrustCurve or a sequence of {n} ThrustCurve objects")
        weights_arg = self._weights_arg if weights is keep else weights
        w = np.ones(n) if weights_arg is None else weights_arg
        pinv = weighted_pseudo_inverse(b, w)
        zero_rows = np.all(np.abs(b) <= _ZERO_ROW_TOLERANCE, axis=1)
        pinv[:, zero_rows] = 0.0  # exact zero instead of SVD round-off: no force at all for those axes
        w = np.array(w, dtype=float)
        mode_value = self._mode if mode is keep else mode
        if mode_value not in _MODES:
            raise ValueError(f"mode must be one of {_MODES}, got {mode_value!r}")
        groups_arg = self._priority_groups_arg if priority_groups is keep else priority_groups
        groups = self._parse_groups(groups_arg)
        step = self._step_us if pulse_width_step_us is keep else pulse_width_step_us
        if step is not None:
            step = check_positive(step, "pulse_width_step_us")
        search_on = self._search_on if deadband_search is keep else deadband_search
        if not isinstance(search_on, (bool, np.bool_)):
            raise ValueError(f"deadband_search must be True or False, got {search_on!r}")
        rho_arg = self._effort_weight_arg if effort_weight is keep else effort_weight
        if rho_arg is not None:
            rho_arg = check_positive(rho_arg, "effort_weight", allow_zero=True)
        grid = _PulseGrid(curve_list, step)
        rho = rho_arg if rho_arg is not None else (grid.effort_weight() if step is not None else DEFAULT_EFFORT_WEIGHT)
        search = None
        if search_on and n <= MAX_THRUSTERS:
            search = DeadbandSearch(b, w, rho, [c.max_reverse_n for c in curve_list],
                                    [c.max_forward_n for c in curve_list], grid.smallest_forward_n,
                                    grid.smallest_reverse_n)

        # All valid: commit.
        self._matrix, self._pinv = b, pinv
        for arr in (self._matrix, self._pinv):
            arr.flags.writeable = False
        self._curves = tuple(curve_list)
        self._curves_arg, self._weights_arg = curve_arg, weights_arg
        self._mode, self._priority_groups_arg, self._groups, self._step_us = mode_value, groups_arg, groups, step
        self._zero_rows = zero_rows
        self._zero_rows.flags.writeable = False
        # Thrusters grouped by equal curves, so each distinct curve is evaluated once, vectorised.
        by_curve: dict[ThrustCurve, list[int]] = {}
        for i, c in enumerate(self._curves):
            by_curve.setdefault(c, []).append(i)
        self._curve_groups = [(self._curves[idx[0]], np.array(idx)) for idx in by_curve.values()]
        self._base_lower = np.array([c.max_reverse_n for c in self._curves])
        self._base_upper = np.array([c.max_forward_n for c in self._curves])
        # forward model of all thrusters in one vectorised call: coefficients as (4, n), the rest (n,)
        params = list(zip(*(c.forward_parameters for c in self._curves)))
        self._forward_params = tuple(np.array(v, dtype=float).T if i < 2 else np.array(v, dtype=float)
                                     for i, v in enumerate(params))
        group_masks = [np.isin(np.arange(6), g).astype(float) for g in groups]
        # per priority group: its axes and the pseudo-inverse with the other axes' columns zeroed
        self._group_index = [np.array(g, dtype=np.intp) for g in groups]
        self._group_pinv = [pinv * mask[None, :] for mask in group_masks]
        self._scale_cache: tuple[float, tuple[np.ndarray, ...]] | None = None
        self._last: tuple[bytes, float, AllocationResult] | None = None  # allocate's one-entry memo
        self._search_on, self._effort_weight_arg, self._search, self._grid = bool(search_on), rho_arg, search, grid

    @staticmethod
    def _parse_groups(groups_arg) -> tuple[tuple[int, ...], ...]:
        try:
            groups = [tuple(_axis_index(a) for a in (g if not isinstance(g, (str, int)) else (g,))) for g in groups_arg]
        except TypeError as exc:
            raise ValueError(f"priority_groups must be a sequence of axis groups, got {groups_arg!r}") from exc
        seen = [a for g in groups for a in g]
        if len(seen) != len(set(seen)) or any(len(g) == 0 for g in groups):
            raise ValueError(f"priority_groups must be non-empty and may name each axis once, got {groups_arg!r}")
        rest = tuple(a for a in range(6) if a not in seen)
        if rest:
            groups.append(rest)
        return tuple(groups)

    # ----------------------------------------------------------------- read-only views
    @property
    def matrix(self) -> np.ndarray:
        """Thrust allocation matrix (6, n), FRD (read-only array)."""
        return self._matrix

    @property
    def pseudo_inverse(self) -> np.ndarray:
        """Weighted pseudo-inverse (n, 6) used for every allocation (read-only array)."""
        return self._pinv

    @property
    def curves(self) -> tuple[ThrustCurve, ...]:
        """One thrust curve per thruster."""
        return self._curves

    @property
    def mode(self) -> str:
        """``"uniform"`` or ``"priority"``."""
        return self._mode

    @property
    def priority_groups(self) -> tuple[tuple[int, ...], ...]:
        """Axis-index groups in priority order, final catch-all group included."""
        return self._groups

    @property
    def search(self) -> DeadbandSearch | None:
        """The deadband search (step 3 of the module docstring), or ``None`` when it is off."""
        return self._search

    @property
    def zero_authority_axes(self) -> np.ndarray:
        """(6,) bool: axes whose row of the matrix is zero (no thruster acts on them)."""
        return self._zero_rows

    @property
    def n_thrusters(self) -> int:
        """Number of thrusters n."""
        return self._matrix.shape[1]

    def force_limits_n(self, voltage_scale: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """``(lower, upper)`` force limits (n,) in N: each curve's max reverse (< 0) and forward (> 0)
        thrust times ``voltage_scale``. Raises ``ValueError`` for a non-finite or non-positive scale."""
        s = check_positive(voltage_scale, "voltage_scale")
        return s * self._base_lower, s * self._base_upper

    # ----------------------------------------------------------------- allocation
    @staticmethod
    def _max_multiplier(base: np.ndarray, step: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> float:
        """Largest t >= 0 with lower <= base + t * step <= upper (inf if step is zero)."""
        with np.errstate(over="ignore"):  # a subnormal step: its ratio is inf, as for a zero step
            ratio = np.divide(np.where(step > 0.0, upper, lower) - base, step, out=np.full(step.shape, math.inf),
                              where=step != 0.0)
        return max(float(ratio.min()), 0.0)

    def _at_scale(self, s: float) -> tuple[np.ndarray, ...]:
        """Per voltage scale ``s``, computed once and kept for the next call at the same scale: the limits
        ``lower, upper`` (n,), the thresholds of ``limited`` and ``saturated`` (:meth:`allocate`) and the smallest
        thrusts ``m_fwd, m_rev`` (n,) outside the deadband on the pulse-width grid."""
        cached = self._scale_cache
        if cached is not None and cached[0] == s:
            return cached[1]
        lower, upper = s * self._base_lower, s * self._base_upper
        tol = 1e-9 * np.maximum(np.abs(lower), np.abs(upper))
        values = (lower, upper, upper - 1e-9 * upper, lower - 1e-9 * lower, upper - tol, lower + tol,
                  s * self._grid.smallest_forward_n, s * self._grid.smallest_reverse_n)
        for arr in values:
            arr.flags.writeable = False
        self._scale_cache = (s, values)
        return values

    def allocate(self, wrench, voltage_scale: float = 1.0) -> AllocationResult:
        """Allocate the wrench ``[X Y Z K M N]`` (6,) (FRD, N and N m) to the thrusters.

        ``voltage_scale`` multiplies every curve's thrust (battery voltage hook, see
        :func:`.thrust_curve.voltage_thrust_scale`). Returns an :class:`AllocationResult` whose arrays are
        read-only: a request equal bit for bit to the last call's, at the same scale, returns the same result object
        without allocating again (a hold or a step commands the same wrench for many ticks in a row). Raises
        :class:`InvalidWrenchError` if the wrench is not 6 finite numbers, ``ValueError`` for a bad
        ``voltage_scale``. Source: [Hindrax-Drag] eqs. 1 and 9; module docstring for the method."""
        try:
            tau = np.array(wrench, dtype=float)
        except (TypeError, ValueError) as exc:
            raise InvalidWrenchError(f"wrench must be 6 finite numbers [X Y Z K M N], got {wrench!r}") from exc
        if tau.shape != (6,) or not np.isfinite(tau).all():
            raise InvalidWrenchError(f"wrench must be 6 finite numbers [X Y Z K M N], got {wrench!r}")
        s_v = check_positive(voltage_scale, "voltage_scale")
        key = tau.tobytes()
        last = self._last
        if last is not None and last[0] == key and last[1] == s_v:
            return last[2]  # the same request as the last call: the same (read-only) result
        lower, upper, upper_limited, lower_limited, upper_saturated, lower_saturated, m_fwd, m_rev = \
            self._at_scale(s_v)

        # Work with the request normalised by its largest component, so huge finite requests cannot
        # overflow; a multiplier t of the unit request corresponds to the scale factor t / peak.
        peak = float(np.abs(tau).max())
        n = self._matrix.shape[1]
        force = np.zeros(n)
        axis_scale = np.ones(6)
        scales = []
        if peak > 0.0:
            unit = tau / peak
            if self._mode == "uniform":
                step = self._pinv @ unit
                t = min(peak, self._max_multiplier(force, step, lower, upper))
                force = t * step
                scales.append(t / peak)
                axis_scale[:] = t / peak
            else:
                for group, group_pinv in zip(self._group_index, self._group_pinv):
                    step = group_pinv @ unit  # = pinv @ (unit * mask): the masked columns are zero
                    t = min(peak, self._max_multiplier(force, step, lower, upper))
                    force = force + t * step
                    scales.append(t / peak)
                    axis_scale[group] = t / peak
            force = np.minimum(np.maximum(force, lower), upper)  # only removes rounding at the limits
        scale = min(scales) if scales else 1.0
        force = np.where(np.abs(force) < ZERO_FORCE_N, 0.0, force)
        limited = (force >= upper_limited) | (force <= lower_limited)  # before the deadband search
        if self._search is not None:
            if ((force != 0.0) & (force < m_fwd) & (force > -m_rev)).any():  # a force inside a deadband gap
                force = self._search.solve(self._matrix @ force, s_v)
                force = np.minimum(np.maximum(force, lower), upper)  # round-off only

        if len(self._curve_groups) == 1:
            pulse = self._curves[0]._pulse_width_unchecked(force, s_v)
        else:
            pulse = np.empty(n)
            for curve, idx in self._curve_groups:
                pulse[idx] = curve._pulse_width_unchecked(force[idx], s_v)
        pulse = self._grid.quantise(pulse)
        actual = s_v * forward_thrust(pulse, *self._forward_params)

        saturated = (force >= upper_saturated) | (force <= lower_saturated) | limited
        result = AllocationResult(requested_wrench=tau, allocated_force_n=force, force_n=actual, pulse_width_us=pulse,
                                  achieved_wrench=self._matrix @ actual, scale=float(scale), axis_scale=axis_scale,
                                  saturated=saturated)
        for arr in (tau, force, actual, pulse, result.achieved_wrench, axis_scale, saturated):
            arr.flags.writeable = False  # shared with the next call of the same request
        self._last = (key, s_v, result)
        return result
