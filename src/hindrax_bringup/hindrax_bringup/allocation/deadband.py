"""Thrust allocation outside the ESC deadband: which thrusters run, and how hard, pure numpy.

An ESC gives no thrust inside its deadband (docs/devices.md §5.2, 1500 +- 25 us), so a thruster produces 0 N or at least
the thrust at the first pulse width outside it (about 1.2 N for the [Hindrax-Drag] eq. 1 curve at the PCA9685's step).
The weighted pseudo-inverse spreads a small request over every thruster: ``[-2 0 0 0 0 0]`` asks each horizontal
thruster for 0.87 N, which none can give, while a symmetric pair at 1.74 N gives the -2 N exactly.

Problem. Find the forces F (n,) minimising

    J(F) = || B F - tau ||^2 + rho * sum_i w_i F_i^2

subject to ``F_i = 0`` or ``m_fwd_i <= F_i <= u_i`` or ``l_i <= F_i <= -m_rev_i``, where ``m_fwd`` and ``m_rev`` are the
smallest thrusts outside the deadband (on the pulse-width grid), ``l`` and ``u`` the saturation limits, ``w`` the
allocation weights and ``rho`` the effort weight (:class:`DeadbandSearch`); the residual is in the Euclidean metric of
[X Y Z K M N], N and N m. The axes are not prioritised here (the allocator's step 2 fixes ``tau``). It is the
constrained least-squares allocation with a slack ``s = B F - tau`` of [JohansenFossen2013] (Q = I) with each bound made
semi-continuous: a mixed-integer quadratic program, with a binary on/off and a sign per thruster.

Method: a search over active sets, vectorised over all of them at once (no maintained Python solver
answers a mixed-integer QP in well under a millisecond; ``scipy.optimize.milp`` takes only a linear
objective and is tens of ms here).

1. *Seeds.* Every subset S of thrusters that may run (2^n seeds), with the forces of S the least-squares solution of
   ``B_S F_S = tau`` of least W-norm (a weighted pseudo-inverse per subset, computed once per configuration); and every
   choice of one thruster pinned at +m or -m, or of two with each at +m, -m or 0 N, the others least squares (for n = 8:
   256 + 16 + 224 = 496 seeds, one matrix product per call). With rank(B) = 6 and n = 8 the exact solutions form a 2-D
   affine family on which the allowed forces are polygons bounded by the lines ``F_i = +-m_i`` and ``F_i = 0``; their
   least-effort point is the pseudo-inverse solution, the least-norm point of one such line, or a crossing of two, all
   seeded: the exact solution of least effort is always a candidate (saturation limits are reached by the repair).
2. *Repair.* A seed with forces inside a deadband gap (0 < |F_i| < m_i) or beyond a saturation limit
   has those thrusters pinned at the nearest allowed value and the others solved again, until none
   is (at most n rounds). Pinning cannot lower the residual, so a seed whose residual plus pinned
   effort already exceeds the best J is dropped (branch and bound).
3. *Choice.* The allowed force vector of least J, the first on a tie: the seed order is fixed, so
   the result is a deterministic function of the request and the configuration.

For requests without an exact solution the search is a heuristic for the exact solve of all 3^n sign
patterns (``test/test_allocation_deadband.py`` checks two fixed requests against it). Subsets are
enumerated for n <= :data:`MAX_THRUSTERS`; beyond, the allocator runs without the search. Cost:
``make bench`` (``actuation``: ``allocate_cpu_p50``, ``allocate_cpu_p99``)."""
from __future__ import annotations

import itertools

import numpy as np

__all__ = ["MAX_THRUSTERS", "ZERO_FORCE_N", "DeadbandSearch"]

#: Largest number of thrusters for which every subset is enumerated (2^12 = 4096 seeds).
MAX_THRUSTERS = 12
#: Forces smaller than this (N) are round-off of a zero force, not a request for thrust.
ZERO_FORCE_N = 1e-9
_BOUND_TOL_N = 1e-9


class DeadbandSearch:
    """Semi-continuous least-squares allocation (module docstring): ``solve(tau, voltage_scale) -> F`` (n,), N.

    Parameters
    ----------
    matrix:
        Thrust allocation matrix B (6, n), [Hindrax-Drag] eq. 9, n <= :data:`MAX_THRUSTERS`.
    weights:
        Allocation weights w (n,), positive: the effort of thruster i counts ``w_i F_i^2``.
    effort_weight:
        rho >= 0 (dimensionless: N^2 of weighted residual per N^2 of weighted thrust).
    lower, upper:
        Saturation limits (n,) in N at ``voltage_scale = 1``, ``lower < 0 < upper``.
    smallest_forward, smallest_reverse:
        Magnitudes (n,) in N, >= 0, at ``voltage_scale = 1``: the smallest thrust each thruster gives outside its
        deadband in each direction, m_fwd and m_rev (0: no gap on that side).

    Precomputes one weighted pseudo-inverse per subset of thrusters (2^n of shape (n, 6)) and the affine map of every
    seed. Raises ``ValueError`` for a bad shape, non-finite values, non-positive weights or upper limits, non-negative
    lower limits, negative smallest thrusts, a negative effort weight, or n > :data:`MAX_THRUSTERS`."""

    def __init__(self, matrix, weights, effort_weight: float, lower, upper, smallest_forward, smallest_reverse) -> None:
        b = np.array(matrix, dtype=float)
        if b.ndim != 2 or b.shape[0] != 6 or not 1 <= b.shape[1] <= MAX_THRUSTERS or not np.all(np.isfinite(b)):
            raise ValueError(f"matrix must be a finite (6, n) array with 1 <= n <= {MAX_THRUSTERS}, got {b.shape}")
        n = b.shape[1]
        vectors = {}
        for name, value, least in (("weights", weights, 0.0), ("upper", upper, 0.0),
                                   ("smallest_forward", smallest_forward, None),
                                   ("smallest_reverse", smallest_reverse, None)):
            v = np.array(value, dtype=float)
            ok = v.shape == (n,) and np.all(np.isfinite(v)) and np.all(v > least if least is not None else v >= 0.0)
            if not ok:
                kind = "positive" if least is not None else "non-negative"
                raise ValueError(f"{name} must be {n} finite {kind} numbers, got {value!r}")
            vectors[name] = v
        low = np.array(lower, dtype=float)
        if low.shape != (n,) or not np.all(np.isfinite(low)) or not np.all(low < 0.0):
            raise ValueError(f"lower must be {n} finite negative numbers, got {lower!r}")
        if not (np.isfinite(effort_weight) and effort_weight >= 0.0):
            raise ValueError(f"effort_weight must be a finite number >= 0, got {effort_weight!r}")
        w = vectors["weights"]
        self.n = n
        self.matrix, self.weights = b, w
        self.effort_weight = float(effort_weight)
        self.lower, self.upper = low, vectors["upper"]
        self.smallest_forward, self.smallest_reverse = vectors["smallest_forward"], vectors["smallest_reverse"]
        self._bit = 1 << np.arange(n)
        # Weighted pseudo-inverse of every column subset: P_S = W^-1/2 pinv(B_S W^-1/2), rows of
        # thrusters outside S zero (pinv of a zero column is a zero row). Stacked: (2^n, n, 6).
        subsets = ((np.arange(1 << n)[:, None] & self._bit[None, :]) != 0).astype(float)  # (2^n, n)
        root_inv = 1.0 / np.sqrt(w)
        scaled = (b * root_inv[None, :])[None, :, :] * subsets[:, None, :]  # (2^n, 6, n)
        self._subset_pinv = root_inv[None, :, None] * np.linalg.pinv(scaled, rcond=1e-10)
        # Seeds: free-set bit mask and pinned forces (0 N, +m_fwd or -m_rev) of the others.
        free, pins = [], []
        everyone = (1 << n) - 1
        for mask in range(1 << n):
            free.append(mask)
            pins.append(np.zeros(n))
        for i in range(n):
            for value in (self.smallest_forward[i], -self.smallest_reverse[i]):
                pin = np.zeros(n)
                pin[i] = value
                free.append(everyone & ~(1 << i))
                pins.append(pin)
        for i, j in itertools.combinations(range(n), 2):
            for vi, vj in itertools.product((self.smallest_forward[i], -self.smallest_reverse[i], 0.0),
                                            (self.smallest_forward[j], -self.smallest_reverse[j], 0.0)):
                if vi == 0.0 and vj == 0.0:
                    continue  # both at 0 N: that is the subset seed without i and j
                pin = np.zeros(n)
                pin[i], pin[j] = vi, vj
                free.append(everyone & ~(1 << i) & ~(1 << j))
                pins.append(pin)
        self._seed_free = np.array(free, dtype=np.int64)
        pinned = np.array(pins)  # (seeds, n) at voltage_scale 1
        p_seed = self._subset_pinv[self._seed_free]  # (seeds, n, 6)
        # x = P_S tau + (pinned - P_S B pinned): affine in tau, the pinned part proportional to the voltage scale;
        # the residual B x - tau likewise. Both as one (n + 6, seeds) map of [tau, scale], in
        # thruster-major order so that every per-thruster test runs along the long (seeds) axis.
        offset = pinned - np.einsum("snk,kj,sj->sn", p_seed, b, pinned)
        residual_map = np.einsum("jk,skl->sjl", b, p_seed) - np.eye(6)[None, :, :]
        affine = np.concatenate([np.concatenate([p_seed, offset[:, :, None]], axis=2),
                                 np.concatenate([residual_map, (offset @ b.T)[:, :, None]], axis=2)], axis=1)
        self._seed_affine = np.ascontiguousarray(affine.transpose(1, 0, 2).reshape((n + 6) * len(free), 7))
        self._seed_nonfree = ((self._seed_free[:, None] & self._bit[None, :]) == 0).T.copy()  # (n, seeds)
        self._bitf = self._bit.astype(float)
        col = lambda v: v.reshape(n, 1)  # noqa: E731
        self._smallest_forward_col, self._smallest_reverse_col = col(self.smallest_forward), col(self.smallest_reverse)
        self._upper_col, self._lower_col = col(self.upper), col(self.lower)
        self._rho_w = self.effort_weight * w
        self._rho_w_m2 = self._rho_w * np.minimum(self.smallest_forward, self.smallest_reverse) ** 2
        self._limits_cache: tuple[float, tuple[np.ndarray, ...]] | None = None
        for arr in (self.matrix, self.weights, self.lower, self.upper, self.smallest_forward, self.smallest_reverse,
                    self._subset_pinv, self._seed_affine, self._seed_nonfree):
            arr.flags.writeable = False

    def objective(self, forces, tau) -> np.ndarray:
        """J of force vectors ``forces`` (..., n) for the request ``tau`` (6,): the quantity :meth:`solve` minimises."""
        f = np.asarray(forces, dtype=float)
        residual = f @ self.matrix.T - np.asarray(tau, dtype=float)
        return np.sum(residual ** 2, axis=-1) + self.effort_weight * np.sum(self.weights * f ** 2, axis=-1)

    def solve(self, tau, voltage_scale: float = 1.0) -> np.ndarray:
        """Allowed forces (n,) in N of least J for the wrench ``tau`` (6,) (same frame and units as the matrix).

        ``voltage_scale`` (> 0) multiplies the limits and the smallest thrusts (battery voltage, see
        :func:`.thrust_curve.voltage_thrust_scale`). Every returned F_i is 0 or within ``[m_fwd_i, upper_i]``
        or ``[lower_i, -m_rev_i]`` (times ``voltage_scale``). Inputs are not validated (the allocator passes
        checked values)."""
        tau = np.asarray(tau, dtype=float)
        s = float(voltage_scale)
        n, seeds = self.n, self._seed_free.size
        limits = self._limits(s)
        # seed forces x (n, seeds) and residuals B x - tau (6, seeds) in one product
        y = (self._seed_affine @ np.append(tau, s)).reshape(n + 6, seeds)
        x, residual = y[:n], y[n:]
        bound = np.einsum("js,js->s", residual, residual)  # no repair of a seed lowers its residual
        bad = _violations(x, *limits)
        rows_bad = np.logical_or.reduce(bad, axis=0)
        effort = x * x
        cost = bound + self._rho_w @ effort
        cost[rows_bad] = np.inf
        best = int(np.argmin(cost))
        best_x, best_cost = x[:, best].copy(), float(cost[best])
        # A repaired seed keeps its pins and zeros and puts every bad thruster at >= m: a lower bound of its J.
        bound += self._rho_w @ (effort * self._seed_nonfree) + (s * s) * (self._rho_w_m2 @ bad)
        rows = np.flatnonzero(rows_bad & (bound < best_cost))
        if rows.size:
            best_x, best_cost = self._repair(tau, s, limits, x[:, rows], bad[:, rows], ~self._seed_nonfree[:, rows],
                                             best_x, best_cost)
        return np.where(np.abs(best_x) > ZERO_FORCE_N, best_x, 0.0)

    def _limits(self, s: float) -> tuple[np.ndarray, ...]:
        """Columns (n, 1) at voltage scale s: m_fwd, m_rev, upper, lower, and the same with the tolerance. Kept for
        the next call at the same scale (the node allocates every command at one scale)."""
        cached = self._limits_cache
        if cached is not None and cached[0] == s:
            return cached[1]
        tol = _BOUND_TOL_N
        m_fwd, m_rev = s * self._smallest_forward_col, s * self._smallest_reverse_col
        upper, lower = s * self._upper_col, s * self._lower_col
        limits = (m_fwd - tol, -m_rev + tol, upper + tol, lower - tol, m_fwd, m_rev, upper, lower)
        for arr in limits:
            arr.flags.writeable = False
        self._limits_cache = (s, limits)
        return limits

    def _repair(self, tau, s, limits, x, bad, free, best_x, best_cost):
        """Repair rounds (module docstring, step 2) on k seeds given thruster-major: x, bad, free (n, k)."""
        m_fwd, m_rev, upper, lower = limits[4:]
        tau_col = tau[:, None]
        for _ in range(self.n):  # each round pins at least one more thruster of every seed it repairs
            clamp = np.where(x > 0.0, m_fwd, -m_rev)
            if (x > upper).any() or (x < lower).any():
                clamp = np.where(x > upper, upper, np.where(x < lower, lower, clamp))
            pinned = np.where(bad, clamp, x * ~free)  # earlier pins and zeros kept
            free &= ~bad
            subset = (self._bitf @ free).astype(np.intp)
            rhs = tau_col - self.matrix @ pinned
            x = np.einsum("knj,jk->nk", self._subset_pinv[subset], rhs) + pinned
            residual = self.matrix @ x - tau_col
            bound = np.einsum("jk,jk->k", residual, residual)
            bad = _violations(x, *limits[:4])
            rows_bad = np.logical_or.reduce(bad, axis=0)
            effort = x * x
            cost = bound + self._rho_w @ effort
            cost[rows_bad] = np.inf
            i = int(np.argmin(cost))
            if cost[i] < best_cost:
                best_x, best_cost = x[:, i].copy(), float(cost[i])
            bound += self._rho_w @ (effort * ~free) + (s * s) * (self._rho_w_m2 @ bad)  # as in solve
            keep = np.flatnonzero(rows_bad & (bound < best_cost))
            if keep.size == 0:
                break
            x, bad, free = x[:, keep], bad[:, keep], free[:, keep]
        return best_x, best_cost


def _violations(x: np.ndarray, gap_high, gap_low, upper, lower, *_unused) -> np.ndarray:
    """Bool (n, k): the forces x (n, k) inside a deadband gap (0 < |x|, gap_low < x < gap_high) or beyond a
    saturation limit (x > upper or x < lower); the bounds are (n, 1) columns, tolerances included."""
    return ((x < gap_high) & (x > gap_low) & (np.abs(x) > ZERO_FORCE_N)) | (x > upper) | (x < lower)
