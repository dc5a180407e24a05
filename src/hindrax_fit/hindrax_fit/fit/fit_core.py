"""The one fit core of ``hindrax ident bag`` and ``hindrax ident fit``; the method in full: docs/identification.md §7.

The bag reader (:mod:`..bag_input.reader`) hands it one :class:`DofRecord` per DOF: continuous
chunks on a uniform tick grid with the commanded force, the smoothed states and the raw measurements
at their own times. :func:`identify_dofs` takes them through the steps of docs/identification.md §7:
timing (:func:`estimate_timing`), segments (:func:`build_segments`, :func:`training_rules`), the
output-error fit (:func:`fit_terms`), model terms by cross-validation (:func:`select_terms`,
:func:`persistence`, :func:`coupling_consistent`) and intervals (:func:`cluster_covariance`).

All quantities SI; forces N (N m for rotations), velocities m/s (rad/s); body FRD. Raises
:class:`~hindrax_onboard.estimation.least_squares.EstimationError` when a DOF has too little usable data."""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Sequence

import numpy as np
from scipy import optimize, signal as _signal, stats

from hindrax_common.config import DOFS

from hindrax_onboard.estimation.least_squares import EstimationError
from hindrax_onboard.vehicle.thrust_lag import ThrustLag
from . import timing_grid

__all__ = ["EXCITATION_MIN", "SEGMENT_S", "VALIDATION_S", "MIN_CLUSTERS", "CLUSTER_RHO_MAX",
           "Chunk", "DofRecord", "Terms", "CoreOptions", "Timing", "SegmentData", "build_segments",
           "simulate", "at_samples", "fit_terms", "FitOutcome", "cluster_covariance",
           "estimate_timing", "validation_measures", "DofResult", "select_terms", "identify_dof",
           "identify_dofs", "inertia_vector", "predict_validation", "parameter_layout",
           "excited_kind", "coriolis_products", "persistence", "PERSISTENCE_MARGIN",
           "NO_MODEL_VERDICT", "resolvable_delay", "with_edge", "NESTED", "not_below_nested",
           "input_correlation", "INPUT_CORRELATION_LAG_S", "coupling_consistent", "refit_coupling", "COUPLING_RTOL"]

#: (force std, velocity std) within a segment below which it does not move the DOF: translational (N, m/s),
#: rotational (N m, rad/s)
EXCITATION_MIN = {"translational": (0.5, 0.03), "rotational": (0.05, 0.05)}
#: Training segment length, s (each simulated open loop from its own initial state)
SEGMENT_S = 10.0
#: Horizon of the validation predictions (cross-validation and holdout), s
VALIDATION_S = 10.0
#: Fewest clusters the interval's blocks may be merged down to
MIN_CLUSTERS = 6
#: Lag-1 autocorrelation of the cluster scores above which blocks are lengthened
CLUSTER_RHO_MAX = 0.2
#: Reverse thrust gain bounds (ratio of the reverse to the forward force per unit of command)
REVERSE_GAIN_BOUNDS = (0.2, 2.0)
#: Bounds of the saturation gain (the fraction of the allocation's force shortfall that acts, :class:`Terms`): 0 the
#: force as commanded, 1 as the allocation achieved it, up to 3 (thrusters that saturate sooner than their curves say)
SATURATION_GAIN_BOUNDS = (0.0, 3.0)
#: A DOF's force shortfall (achieved - commanded) counts as saturation when its largest magnitude is above this
#: fraction of the largest commanded force (below it the column is rounding noise and its gain not identifiable)
SATURATION_MIN_REL = 0.02
#: The kinds of the parameters whose regressors are time-dependent columns (:attr:`SegmentData.cols`), by prefix
_COLUMN_PREFIXES = ("cross", "xforce", "runbias", "sat")
#: Relative margin by which a model's cross-validated nrmse must be below holding the velocity
#: (:func:`persistence`; why 0.05: docs/identification.md §7 step 7)
PERSISTENCE_MARGIN = 0.05
#: The verdict of a DOF whose best model does not beat holding the velocity (:func:`persistence`)
NO_MODEL_VERDICT = "no model beats holding the velocity"


def excited_kind(dof: str) -> str:
    """``"rotational"`` for roll, pitch, yaw, else ``"translational"``."""
    return "rotational" if dof in ("roll", "pitch", "yaw") else "translational"


# ------------------------------------------------------------------------------------------------ data model
@dataclass
class Chunk:
    """One continuous stretch of one DOF on the uniform tick grid (n ticks of ``h``; tick j at ``t0 + j h``).

    force (n,): the commanded force over [t_j, t_j + h) (N or N m), before the delay and lag of :class:`Timing`;
    v, x, a (n,): smoothed velocity, position (zeros unless the position is measured) and acceleration at the ticks
    (initial states, equation-error start, excitation); sample_pos (k,): the measurements' times in ticks from t0
    (fractional); sample_z (k,): the measurements (velocity, or position for a measured position);
    restoring (n,) or None: s(eta) (roll, pitch); coupling (n, 6) or None: the Coriolis and centripetal products
    g_k with C(nu) nu of this DOF = g_k . [M1..M6] (:func:`coriolis_products`); cross (n, c) or None: the other
    moving DOFs' velocities; group: the bag (record) it belongs to; force_start: the lagged force at tick 0 (None:
    settled at the first command); cross_force (n, f) or None: the other DOFs' commanded forces over each tick, as
    ``force`` (before the delay and lag); shortfall (n,) or None: the force the thrust allocation achieved less the
    commanded ``force`` over each tick (its ``allocation/status``: 0 while no thruster saturates), as ``force``."""

    force: np.ndarray
    v: np.ndarray
    x: np.ndarray
    a: np.ndarray
    sample_pos: np.ndarray
    sample_z: np.ndarray
    restoring: np.ndarray | None = None
    coupling: np.ndarray | None = None
    cross: np.ndarray | None = None
    group: int = 0
    t0: float = 0.0
    force_start: float | None = None
    cross_force: np.ndarray | None = None
    shortfall: np.ndarray | None = None


@dataclass
class DofRecord:
    """One DOF's data for the core. measured: ``"velocity"`` or ``"position"`` (a measured position: one free offset
    and one free initial velocity per segment); force_source: ``"thrust_model"`` (force of recorded pulse widths
    through the vehicle's thrust curves: ``lag_s`` and the latency are known) or ``"wrench"`` (a commanded wrench:
    delay and lag estimated); lag_s: the known first-order thrust lag (thrust model), s; cross_names: the DOFs of
    the ``cross`` columns; terms: the model a designed experiment was built to identify (the campaign's ladders:
    linear + quadratic damping, heave per direction), fitted as it is; None: the terms are chosen by
    cross-validation (``CoreOptions.select``); all_segments: the record is a designed experiment's window (the
    campaign's), every segment of it is fitted, moving or not (as ``CoreOptions.all_segments``): a DOF that did
    not move gets parameters with wide intervals and advice, not "no segment"; force_names: the DOFs of the chunks'
    ``cross_force`` columns; run_count: the runs (the chunks' ``group`` 0..run_count-1) of a per-run bias, 0 or 1:
    none; runs_known: False for a record whose runs are not the fitted ones (a holdout bag, ``ident predict``):
    its per-run bias columns are zero, the mean bias applies."""

    dof: str
    h: float
    measured: str
    chunks: list
    force_source: str = "wrench"
    lag_s: float = 0.0
    cross_names: tuple = ()
    terms: "Terms | None" = None
    all_segments: bool = False
    force_names: tuple = ()
    run_count: int = 0
    runs_known: bool = True

    @property
    def has_coupling(self) -> bool:
        return any(c.coupling is not None for c in self.chunks)

    @property
    def saturates(self) -> bool:
        """The allocation fell short of the commanded force somewhere (:data:`SATURATION_MIN_REL`): the saturation
        term is a candidate."""
        top = max((float(np.max(np.abs(c.force))) for c in self.chunks if c.force.size), default=0.0)
        short = max((float(np.max(np.abs(c.shortfall))) for c in self.chunks
                     if c.shortfall is not None and c.shortfall.size), default=0.0)
        return top > 0.0 and short > SATURATION_MIN_REL * top


@dataclass(frozen=True)
class Terms:
    """The model's terms (their physics: docs/identification.md §7 steps 4 and 8): damping ``"linear"``, ``"quadratic"``
    or ``"both"``; by_direction: heave's damping per sign of w; coriolis: the Coriolis and centripetal force of the
    other DOFs' inertias subtracted from the input; cross: free coefficients on the other moving DOFs' velocities;
    reverse_gain: the force of negative commands times a free gain; cross_force: the other DOFs' commanded forces times
    free coefficients, with this DOF's delay and lag; run_bias: a constant force per run (bag), effects coding around
    the mean ``bias`` (``bias_run_<k>`` for runs 1..R-1, run R the negative of their sum, a run not fitted gets the
    mean); saturation: the commanded force plus a free gain times :attr:`Chunk.shortfall`, with this DOF's delay and lag
    (1: the vehicle file's thrust limits)."""

    damping: str = "both"
    by_direction: bool = False
    coriolis: bool = False
    cross: bool = False
    reverse_gain: bool = False
    cross_force: bool = False
    run_bias: bool = False
    saturation: bool = False

    @property
    def label(self) -> str:
        parts = [{"both": "linear + quadratic", "linear": "linear", "quadratic": "quadratic"}[self.damping]
                 + " damping" + (" per direction" if self.by_direction else "")]
        added = ((self.coriolis, "Coriolis"), (self.cross, "cross-DOF coupling"),
                 (self.cross_force, "other DOFs' forces"), (self.run_bias, "per-run bias"),
                 (self.saturation, "thrust saturation"), (self.reverse_gain, "reverse thrust gain"))
        parts += [name for flag, name in added if flag]
        return " + ".join(parts)


@dataclass(frozen=True)
class CoreOptions:
    """segment_s: training segment, s; validation_s: prediction horizon of the validation, s; folds: K of the
    cross-validation; max_delay_s: largest input delay searched (commanded wrench), s; robust: soft-L1 loss (else
    plain least squares); select: choose the terms by cross-validation (else ``terms``); terms: the model when not
    selecting; min_clusters: fewest clusters for the interval; all_segments: fit every segment of the record, moving
    or not (a designed campaign's DOF window), else only the segments that move the DOF; persistence_margin: the
    relative margin by which the chosen model must beat holding the velocity (:func:`persistence`)."""

    segment_s: float = SEGMENT_S
    validation_s: float = VALIDATION_S
    folds: int = 4
    max_delay_s: float = 1.0
    robust: bool = True
    select: bool = True
    terms: Terms = Terms()
    min_clusters: int = MIN_CLUSTERS
    all_segments: bool = False
    persistence_margin: float = PERSISTENCE_MARGIN


@dataclass(frozen=True)
class Timing:
    """delay_s: the force acts this late; lag_s: then through a first-order lag of this time constant; source:
    ``"known"`` (thrust model) or ``"estimated"``; curve: [(delay, normalised residual)] of the search; bound_s:
    the largest delay + lag searched (:func:`resolvable_delay`; None for a known timing) and bound_why what set it;
    at_edge: the estimate within one grid step of that bound."""

    delay_s: float = 0.0
    lag_s: float = 0.0
    source: str = "known"
    curve: tuple = ()
    bound_s: float | None = None
    bound_why: str = ""
    at_edge: bool = False

    @property
    def edge_note(self) -> str:
        """One line when delay + lag sit at the upper end of the searched range (the true value may be larger:
        the data cannot resolve it), else ``""``."""
        if not self.at_edge or self.bound_s is None:
            return ""
        return (f"delay + lag {self.delay_s + self.lag_s:.3f} s at the edge of its range 0-{self.bound_s:.3f} s "
                f"({self.bound_why}): the data cannot tell a longer one")


def parameter_layout(dof: str, terms: Terms, n_cross: int = 0, cross_names: Sequence[str] = (),
                     force_names: Sequence[str] = (), n_runs: int = 0) -> list[tuple]:
    """[(name, kind, lower, upper)] of the model's parameters in vector order: inertia; quadratic then linear damping
    (heave per direction: ``_positive`` (w > 0, down) and ``_negative``); bias; restoring (roll, pitch); cross
    terms ``cross_<dof>``; other DOFs' force coefficients ``force_from_<dof>``; per-run biases ``bias_run_<k>``;
    ``saturation_gain`` (:data:`SATURATION_GAIN_BOUNDS`); ``reverse_thrust_gain``. Bounds keep
    them physical (docs/identification.md §7 step 3)."""
    out = [("inertia", "inertia", 1e-6, np.inf)]
    split = dof == "heave" and terms.by_direction
    for kind, name in (("kq", "quadratic_damping"), ("kl", "linear_damping")):
        if (kind == "kq" and terms.damping == "linear") or (kind == "kl" and terms.damping == "quadratic"):
            continue
        if split:
            out += [(f"{name}_positive", kind + "+", 0.0, np.inf), (f"{name}_negative", kind + "-", 0.0, np.inf)]
        else:
            out.append((name, kind, 0.0, np.inf))
    out.append(("bias", "bias", -np.inf, np.inf))
    if dof in ("roll", "pitch"):
        out.append(("restoring", "restoring", 0.0, np.inf))
    if terms.cross:
        names = list(cross_names) or [str(i) for i in range(n_cross)]
        out += [(f"cross_{names[i]}", f"cross{i}", -np.inf, np.inf) for i in range(n_cross)]
    if terms.cross_force:
        out += [(f"force_from_{d}", f"xforce{i}", -np.inf, np.inf) for i, d in enumerate(force_names)]
    if terms.run_bias and n_runs >= 2:
        out += [(f"bias_run_{k + 1}", f"runbias{k}", -np.inf, np.inf) for k in range(n_runs - 1)]
    if terms.saturation:
        out.append(("saturation_gain", "sat", *SATURATION_GAIN_BOUNDS))
    if terms.reverse_gain:
        out.append(("reverse_thrust_gain", "reverse", *REVERSE_GAIN_BOUNDS))
    return out


# ------------------------------------------------------------------------------------------------ segments
@dataclass
class SegmentData:
    """Equal segments of ``L`` ticks ready to simulate (:func:`build_segments`).

    u (3, m, L): the input force at the start, middle and end of each tick (delay, lag, less the Coriolis force
    when chosen, the positive part only with a reverse gain); cols (3, m, L, c): the time-dependent regressors
    multiplying parameters (restoring -s(eta), cross -v_j, the negative force part) at the same instants, c may be 0;
    v0, x0 (m,): initial states; s_seg, s_j, s_a, s_z (k,): each measurement's segment, tick and fraction, value;
    group (m,), start (m,) chunk tick of the first tick, chunk (m,) index, span (m, 2) record time range (s);
    excited (m,); v_s, a_s (m, L) the smoothed velocity and acceleration (validation of a measured position,
    equation-error start, advice); force (m, L) the input force at the ticks (advice)."""

    h: float
    L: int
    u: np.ndarray
    cols: np.ndarray
    v0: np.ndarray
    x0: np.ndarray
    s_seg: np.ndarray
    s_j: np.ndarray
    s_a: np.ndarray
    s_z: np.ndarray
    group: np.ndarray
    span: np.ndarray
    excited: np.ndarray
    v_s: np.ndarray
    a_s: np.ndarray
    force: np.ndarray
    measured: str = "velocity"

    @property
    def m(self) -> int:
        return int(self.v0.shape[0])

    def subset(self, idx) -> "SegmentData":
        """The segments ``idx`` (indices or mask) with their measurements."""
        idx = np.flatnonzero(idx) if np.asarray(idx).dtype == bool else np.asarray(idx, dtype=int)
        new = np.full(self.m, -1)
        new[idx] = np.arange(idx.size)
        keep = new[self.s_seg] >= 0
        return SegmentData(self.h, self.L, self.u[:, idx], self.cols[:, idx], self.v0[idx], self.x0[idx],
                           new[self.s_seg[keep]], self.s_j[keep], self.s_a[keep], self.s_z[keep], self.group[idx],
                           self.span[idx], self.excited[idx], self.v_s[idx], self.a_s[idx], self.force[idx],
                           self.measured)


def _shift(x: np.ndarray, ticks: float) -> np.ndarray:
    """x (n, ...) held over ticks, delayed by ``ticks`` (fractional: the step mean of the shifted held signal); the
    first value is held before the start."""
    if ticks <= 0:
        return x.copy()
    k = int(math.floor(ticks))
    f = ticks - k
    pad = np.concatenate([np.repeat(x[:1], k + 1, axis=0), x], axis=0)
    n = x.shape[0]
    a = pad[1:n + 1]  # x[j - k]
    b = pad[0:n]  # x[j - k - 1]
    return (1.0 - f) * a + f * b


def coriolis_products(velocity: np.ndarray) -> np.ndarray:
    """The products g (..., 6, 6) with the Coriolis and centripetal force of a diagonal inertia M = diag(M1..M6)
    (body origin at the CG; Fossen 2011 eqs. 6.43 and 6.45) C(nu) nu = g @ [M1..M6] for nu (..., 6) = [u v w p q r]
    FRD: surge q w M3 - r v M2, sway r u M1 - p w M3, heave p v M2 - q u M1, roll v w (M3 - M2) + q r (M6 - M5),
    pitch u w (M1 - M3) + p r (M4 - M6), yaw u v (M2 - M1) + p q (M5 - M4). NaN velocities count as 0."""
    u, v, w, p, q, r = np.moveaxis(np.nan_to_num(np.asarray(velocity, dtype=float)), -1, 0)
    z = np.zeros_like(u)
    rows = [[z, -r * v, q * w, z, z, z],
            [r * u, z, -p * w, z, z, z],
            [-q * u, p * v, z, z, z, z],
            [z, -v * w, v * w, z, -q * r, q * r],
            [u * w, z, -u * w, p * r, z, -p * r],
            [-u * v, u * v, z, -p * q, p * q, z]]
    return np.stack([np.stack(row, axis=-1) for row in rows], axis=-2)


def build_segments(rec: DofRecord, terms: Terms, timing: Timing, seconds: float,
                   coupling_inertia: np.ndarray | None = None, excited_only: bool = True,
                   min_fraction: float = 0.5, anchor_s: float | None = None) -> SegmentData:
    """Cut ``rec``'s chunks into segments of ``seconds`` with the force delayed, lagged and less the Coriolis force
    (``coupling_inertia`` (6,) of the other DOFs, NaN = unknown, this DOF's own entry unused) as ``terms`` and
    ``timing`` say. A last part of at least ``min_fraction`` of a segment is kept (padded, no measurement in the
    padding); without ``excited_only`` a whole chunk shorter than that is one segment too (a designed window shorter
    than a segment is still fitted). ``excited_only``: only the segments that move the DOF (:data:`EXCITATION_MIN`).
    ``anchor_s``: segment boundaries every ``seconds`` from this record time instead of from each chunk's start (a
    chunk starting between two boundaries begins with the part up to the next one; ``hindrax ident predict
    --segment-s``).
    Raises
    :class:`EstimationError` when no segment remains."""
    h = rec.h
    L = max(10, int(round(seconds / h)))
    fmin, vmin = EXCITATION_MIN[excited_kind(rec.dof)]
    k_dof = DOFS.index(rec.dof)
    U, C, V0, X0, G, SP, EX, VS, AS, FF = [], [], [], [], [], [], [], [], [], []
    s_seg, s_j, s_a, s_z = [], [], [], []
    lag = ThrustLag(timing.lag_s)

    def tick_points(x):  # x at the start, middle and end of each tick (held after the last one)
        x1 = np.concatenate([x[1:], x[-1:]])
        return x, 0.5 * (x + x1), x1

    for ci, ch in enumerate(rec.chunks):
        n = ch.force.size
        f = _shift(ch.force, timing.delay_s / h)
        fs, fm, fe = lag.over_ticks(f, h, ch.force_start if timing.delay_s <= 0 else None)
        inputs = [fs, fm, fe]
        extra = []  # time-dependent regressors (start, middle, end) of the parameters after the restoring
        if rec.dof in ("roll", "pitch"):
            r = ch.restoring if ch.restoring is not None else np.zeros(n)
            extra.append(tuple(-x for x in tick_points(r)))
        if terms.cross:
            for i in range(len(rec.cross_names)):
                c = ch.cross[:, i] if ch.cross is not None else np.zeros(n)
                extra.append(tuple(-x for x in tick_points(c)))
        if terms.cross_force:  # the other DOFs' forces through this DOF's delay and lag
            for i in range(len(rec.force_names)):
                g = ch.cross_force[:, i] if ch.cross_force is not None else np.zeros(n)
                extra.append(lag.over_ticks(_shift(g, timing.delay_s / h), h, None))
        if terms.run_bias and rec.run_count >= 2:  # effects coding; the force is less the run's bias
            code = np.zeros(rec.run_count - 1)  # run k < R - 1: -1 in column k; the last: +1 in all
            if rec.runs_known and 0 <= ch.group < code.size:
                code[ch.group] = -1.0
            elif rec.runs_known and ch.group == code.size:
                code[:] = 1.0
            extra += [(np.full(n, c),) * 3 for c in code]
        if terms.saturation:  # the allocation's shortfall through this DOF's delay and lag, as the force
            g = ch.shortfall if ch.shortfall is not None else np.zeros(n)
            extra.append(lag.over_ticks(_shift(g, timing.delay_s / h), h, None))
        if terms.reverse_gain:
            extra.append(tuple(np.minimum(x, 0.0) for x in inputs))
            inputs = [np.maximum(x, 0.0) for x in inputs]
        if terms.coriolis and ch.coupling is not None and coupling_inertia is not None:
            mi = np.where(np.isfinite(coupling_inertia), coupling_inertia, 0.0).copy()
            mi[k_dof] = 0.0
            inputs = [u - c for u, c in zip(inputs, tick_points(ch.coupling @ mi))]
        pos = ch.sample_pos
        order = np.argsort(pos)
        pos, zs = pos[order], ch.sample_z[order]
        if anchor_s is None:
            cuts = list(range(0, n, L))
        else:  # boundaries on the record's grid anchor_s + k L h
            first = int(math.ceil(round((anchor_s - ch.t0) / h, 6))) % L
            cuts = ([0] if first > 0 else []) + list(range(first, n, L))
        for ci_, s0 in enumerate(cuts):
            mlen = min(L, n - s0, (cuts[ci_ + 1] - s0) if ci_ + 1 < len(cuts) else n - s0)
            if mlen < 10 or (mlen < min_fraction * L and (excited_only or s0 > 0)):
                continue
            sl = slice(s0, s0 + mlen)
            vseg = ch.v[sl]
            if not (np.isfinite(ch.v[s0]) and np.isfinite(ch.x[s0])):
                continue
            exc = (math.sqrt(float(np.nanmean(vseg ** 2))) >= vmin) or (float(np.std(ch.force[sl])) >= fmin)
            if excited_only and not exc:
                continue
            lo, hi = np.searchsorted(pos, [s0 + 1e-9, s0 + mlen - 1 + 1e-9], side="left")
            q = pos[lo:hi] - s0
            q = q[q <= mlen - 1]
            if q.size < 3:
                continue
            j = np.minimum(np.floor(q).astype(int), L - 2)
            seg_i = len(V0)
            s_seg.append(np.full(q.size, seg_i))
            s_j.append(j)
            s_a.append(q - j)
            s_z.append(zs[lo:lo + q.size])

            def pad(a):
                a = a[sl]
                return np.concatenate([a, np.repeat(a[-1:], L - mlen, axis=0)]) if mlen < L else a

            U.append(np.stack([pad(x) for x in inputs]))
            C.append(np.stack([np.stack([pad(e[s]) for e in extra], axis=-1) if extra else np.zeros((L, 0))
                               for s in range(3)]))
            V0.append(float(ch.v[s0]))
            X0.append(float(ch.x[s0]))
            G.append(ch.group)
            SP.append((ch.t0 + s0 * h, ch.t0 + (s0 + mlen - 1) * h))
            EX.append(exc)
            VS.append(pad(ch.v))
            AS.append(pad(ch.a))
            FF.append(pad(fs))
    if not V0:
        raise EstimationError(f"{rec.dof}: no segment of {seconds:g} s with the DOF moving and at least 3 "
                              "measurements")
    return SegmentData(h, L, np.stack(U, axis=1), np.stack(C, axis=1),
                       np.array(V0), np.array(X0), np.concatenate(s_seg), np.concatenate(s_j), np.concatenate(s_a),
                       np.concatenate(s_z), np.array(G, dtype=int), np.array(SP, dtype=float), np.array(EX),
                       np.array(VS), np.array(AS), np.array(FF), rec.measured)


# ------------------------------------------------------------------------------------------------ simulation
def _kinds(layout: list) -> list[str]:
    return [k for _n, k, _lo, _hi in layout]


def _column_params(layout: list) -> list[int]:
    """Indices of the parameters multiplying the time-dependent columns :attr:`SegmentData.cols`."""
    return [i for i, k in enumerate(_kinds(layout)) if k in ("restoring", "reverse") or k.startswith(_COLUMN_PREFIXES)]


def simulate(sd: SegmentData, layout: list, P: np.ndarray, v0: np.ndarray | None = None,
             position: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
    """Velocities (B, m, L) (and positions with ``position``) of every segment for B parameter sets
    ``P`` (B, p) at once, from the segments' initial states (``v0`` (B, m) replaces the initial
    velocities). Classical RK4 for the velocity, Runge-Kutta-Nystrom for the position, inputs at the
    start, middle and end of each tick. The states are kept within 1000 x (the largest
    measurement + 1): a diverging trial stays finite (floating-point warnings are off here)."""
    P = np.atleast_2d(np.asarray(P, dtype=float))
    B = P.shape[0]
    kinds = _kinds(layout)
    h = sd.h
    M = P[:, 0][:, None]
    inv_m = 1.0 / M

    def col(kind):
        return P[:, kinds.index(kind)][:, None] if kind in kinds else None

    kq, kl, kqp, kqn, klp, kln = (col(k) for k in ("kq", "kl", "kq+", "kq-", "kl+", "kl-"))
    b = col("bias")
    split = kqp is not None or klp is not None
    # time-dependent regressors x their parameters, added to the input once for all ticks
    tk = _column_params(layout)
    U = np.broadcast_to(sd.u[:, None], (3, B) + sd.u.shape[1:])
    if tk:
        U = U + np.einsum("smlc,bc->sbml", sd.cols, P[:, tk])
    U = U - b[None, :, :, None]
    bound = 1e3 * (float(np.max(np.abs(sd.s_z))) + 1.0) if sd.s_z.size else 1e6
    v = np.broadcast_to(sd.v0, (B, sd.m)).copy() if v0 is None else np.array(v0, dtype=float)
    x = np.broadcast_to(sd.x0, (B, sd.m)).copy()
    L = sd.L
    V = np.empty((L, B, sd.m))  # tick first (rows contiguous), returned as (B, m, L) views
    X = np.empty((L, B, sd.m)) if position else None
    V[0] = v
    if position:
        X[0] = x

    if split:
        kqp_, kqn_ = (kqp if kqp is not None else 0.0), (kqn if kqn is not None else 0.0)
        klp_, kln_ = (klp if klp is not None else 0.0), (kln if kln is not None else 0.0)

        def damp(vv, out):
            pos = vv > 0
            return np.abs(vv) * vv * np.where(pos, kqp_, kqn_) + vv * np.where(pos, klp_, kln_)
    else:
        def damp(vv, out):  # (kq |v| + kl) v, in place, without a term the layout lacks
            if kq is None:
                return np.multiply(kl, vv, out=out)
            np.abs(vv, out=out)
            out *= kq
            if kl is not None:
                out += kl
            out *= vv
            return out

    def stage(u, vv, out):  # (u - damp(vv)) / M, in place
        d = damp(vv, out)
        np.subtract(u, d, out=out)
        out *= inv_m
        return out

    Ut = np.ascontiguousarray(np.moveaxis(U, -1, 1))  # (3, L, B, m): one tick's inputs contiguous
    k1, k2, k3, k4, w = (np.empty((B, sd.m)) for _ in range(5))
    with np.errstate(all="ignore"):
        for i in range(L - 1):
            timing_grid.rk4_step(stage, Ut[0, i], Ut[1, i], Ut[2, i], v, h, (k1, k2, k3, k4), w)
            if position:  # Runge-Kutta-Nystrom (the stages k1..k3 of the velocity)
                x = x + h * v + (h * h / 6.0) * (k1 + k2 + k3)
                np.minimum(np.maximum(x, -bound, out=x), bound, out=x)
                X[i + 1] = x
            v = v + w
            np.minimum(np.maximum(v, -bound, out=v), bound, out=v)  # a NaN (inf - inf) cannot arise
            V[i + 1] = v
    return np.moveaxis(V, 0, -1), None if X is None else np.moveaxis(X, 0, -1)


def at_samples(sd: SegmentData, Y: np.ndarray) -> np.ndarray:
    """Y (..., m, L) linearly interpolated at the measurement times: (..., k)."""
    j1 = np.minimum(sd.s_j + 1, sd.L - 1)
    return Y[..., sd.s_seg, sd.s_j] * (1.0 - sd.s_a) + Y[..., sd.s_seg, j1] * sd.s_a


def _residuals(sd: SegmentData, layout: list, P: np.ndarray, v0: np.ndarray | None) -> np.ndarray:
    """(B, k) residuals model - measurement; a measured position less its mean per segment (free offset)."""
    pos = sd.measured == "position"
    V, X = simulate(sd, layout, P, v0, position=pos)
    if not pos:
        return at_samples(sd, V) - sd.s_z
    r = at_samples(sd, X) - sd.s_z
    cnt = np.bincount(sd.s_seg, minlength=sd.m).astype(float)
    out = np.empty_like(r)
    for bi in range(r.shape[0]):
        mean = np.bincount(sd.s_seg, weights=r[bi], minlength=sd.m) / np.maximum(cnt, 1.0)
        out[bi] = r[bi] - mean[sd.s_seg]
    return out


# ------------------------------------------------------------------------------------------------ the fit
@dataclass
class FitOutcome:
    """theta (p,) of ``layout``; v0 (m,) the fitted initial velocities (measured position) or None; the residuals
    (k,) and the robust weights (k,) at the optimum; J (k, p + m_free) the Jacobian; f_scale."""

    layout: list
    theta: np.ndarray
    v0: np.ndarray | None
    residuals: np.ndarray
    weights: np.ndarray
    jac: np.ndarray
    f_scale: float


def _equation_error_start(sd: SegmentData, layout: list, a: np.ndarray) -> np.ndarray:
    """Bounded equation-error least squares of the model on the smoothed velocity ``sd.v_s`` and acceleration ``a``
    (m, L) at the ticks, within the bounds of ``layout`` (scipy ``lsq_linear``): the physical start of the fit."""
    kinds = _kinds(layout)
    v = sd.v_s
    pos, q = v > 0, np.abs(v) * v
    terms = {"kq": q, "kl": v, "kq+": np.where(pos, q, 0.0), "kq-": np.where(pos, 0.0, q),
             "kl+": np.where(pos, v, 0.0), "kl-": np.where(pos, 0.0, v), "bias": np.ones_like(v)}
    rows = [a] + [terms[k] for k in kinds[1:] if k in terms]
    for c in range(len(_column_params(layout))):
        rows.append(-sd.cols[0][..., c])
    A = np.stack(rows, axis=-1)
    y = sd.u[0]
    ok = np.all(np.isfinite(A), axis=-1) & np.isfinite(y)
    A, y = A[ok], y[ok]
    scale = np.maximum(np.sqrt(np.mean(A ** 2, axis=0)), 1e-12)
    lo, hi = np.array([(lb, ub) for _n, _k, lb, ub in layout], dtype=float).T * scale
    lo[0] = max(lo[0], 1e-9)
    res = optimize.lsq_linear(A / scale, y, bounds=(lo, hi), lsmr_tol="auto", method="bvls")
    return res.x / scale


def _mad_sigma(r: np.ndarray) -> float:
    r = r[np.isfinite(r)]
    if r.size == 0:
        return 1.0
    s = 1.4826 * float(np.median(np.abs(r - np.median(r))))
    return s if s > 0 else max(float(np.std(r)), 1e-9)


def fit_terms(sd: SegmentData, dof: str, layout: list, theta0: np.ndarray, robust: bool = True,
              f_scale: float | None = None, max_nfev: int | None = None, free_v0: bool | None = None) -> FitOutcome:
    """Output-error fit of ``layout`` on ``sd`` from ``theta0`` (docs/identification.md §7 step 3):
    ``scipy.optimize.least_squares`` within the bounds of ``layout``, soft-L1 loss with scale
    ``f_scale`` (default 3 x the MAD sigma of the residuals at ``theta0``); a diverging trial step
    costs a large finite value; the Jacobian in one vectorised simulation. ``free_v0``: fit each
    segment's initial velocity too (default: for a measured position), else start each from its
    smoothed measurement."""
    lower, upper = np.array([(lb, ub) for _n, _k, lb, ub in layout], dtype=float).T
    th0 = np.clip(np.asarray(theta0, dtype=float), lower, upper)
    th0[0] = max(th0[0], 1e-3 * max(abs(float(theta0[0])), 1.0), 1e-6)
    # start strictly inside the bounds (trust-region reflective needs it)
    span = np.where(np.isfinite(upper - lower), upper - lower, np.maximum(np.abs(th0), 1.0))
    th0 = np.minimum(np.maximum(th0, lower + 1e-6 * span), upper - 1e-6 * span)
    p = th0.size
    free_v0 = sd.measured == "position" if free_v0 is None else free_v0
    m = sd.m
    x0 = np.concatenate([th0, sd.v0]) if free_v0 else th0
    lo_all = np.concatenate([lower, np.full(m, -np.inf)]) if free_v0 else lower
    hi_all = np.concatenate([upper, np.full(m, np.inf)]) if free_v0 else upper

    def split(x):
        return x[:p], (x[p:][None, :] if free_v0 else None)

    last: dict = {}
    # without time-dependent regressors a row's residuals do not depend on its batch: fun simulates
    # x's forward steps too (least_squares next asks the Jacobian at the point it last evaluated)
    with_steps = not _column_params(layout)

    def batch(x):
        """Residuals at x (row 0) and its forward steps (rows 1..) in one simulation, kept."""
        if last.get("x") is not None and np.array_equal(last["x"], x):
            return last
        th, v0 = split(x)
        d = 1e-6 * np.maximum(np.abs(th), 1e-3 * np.maximum(np.abs(th0), 1e-6))
        # forward steps that stay inside the bounds
        d = np.where(th + d > upper, -d, d)
        P = np.vstack([th, th + np.diag(d)])
        V0, dv = None, 0.0
        if free_v0:
            dv = 1e-6 * max(1.0, float(np.max(np.abs(v0))))
            V0 = np.vstack([np.repeat(v0, p + 1, axis=0), v0 + dv])
            P = np.vstack([P, th])
        last.update(x=np.array(x, copy=True), R=_residuals(sd, layout, P, V0), d=d, dv=dv)
        return last

    def fun(x):
        if with_steps:
            return batch(x)["R"][0].copy()  # least_squares scales what it gets in place
        if not np.array_equal(last.get("x1"), x):  # least_squares starts where r0 below was
            th, v0 = split(x)
            last.update(x1=np.array(x, copy=True), r1=_residuals(sd, layout, th[None, :], v0)[0])
        return last["r1"].copy()

    def jac(x):
        b = batch(x)
        R, d, dv = b["R"], b["d"], b["dv"]
        J = (R[1:p + 1] - R[0]) / d[:, None]
        if not free_v0:
            return J.T
        # each segment's residuals depend on its own initial velocity only (the offset projection too)
        Jv = np.zeros((R.shape[1], m))
        Jv[np.arange(R.shape[1]), sd.s_seg] = (R[p + 1] - R[0]) / dv
        return np.hstack([J.T, Jv])

    r0 = fun(x0)
    if f_scale is None:
        f_scale = 3.0 * _mad_sigma(r0)
    sol = optimize.least_squares(fun, x0, jac=jac, bounds=(lo_all, hi_all), method="trf",
                                 x_scale="jac", loss="soft_l1" if robust else "linear",
                                 f_scale=f_scale, max_nfev=max_nfev)
    r = sol.fun
    w = (1.0 + (r / f_scale) ** 2) ** -0.5 if robust else np.ones_like(r)
    th, v0 = split(sol.x)
    return FitOutcome(layout, th.copy(), None if v0 is None else v0[0].copy(), r, w, sol.jac, float(f_scale))


# ------------------------------------------------------------------------------------------------ covariance
@dataclass
class Covariance:
    """cov (p, p) reported (at least the model-based one, parameter by parameter); model, sandwich (p, p); clusters
    G, block (segments per cluster), rho (lag-1 autocorrelation of the cluster scores at that block), t_dof = G - 1,
    residual_rho (lag-1 autocorrelation of consecutive residual samples); input_corr: the residuals' correlation with
    the input (:func:`input_correlation`; a measured position only, else None)."""

    cov: np.ndarray
    model: np.ndarray
    sandwich: np.ndarray
    clusters: int
    block: int
    rho: float
    t_dof: int
    residual_rho: float
    input_corr: dict | None = None


def _blocks(group: np.ndarray, b: int) -> np.ndarray:
    """Cluster id of each segment: consecutive runs of ``b`` segments within a group."""
    out = np.empty(group.size, dtype=int)
    cid, count, prev = -1, 0, None
    for i, g in enumerate(group):
        if g != prev or count == b:
            cid += 1
            count = 0
            prev = g
        out[i] = cid
        count += 1
    return out


def cluster_covariance(fit: FitOutcome, sd: SegmentData, min_clusters: int = MIN_CLUSTERS) -> Covariance:
    """Cluster-robust covariance of the output-error fit from its simulation-error Jacobian ([Ljung1999] §9.2-9.3),
    blocks of segments as clusters (docs/identification.md §7 step 5): blocks lengthened while their scores correlate
    above :data:`CLUSTER_RHO_MAX`, at least ``min_clusters``; G / (G - 1), Student t with G - 1 degrees of freedom
    ([Liang-Zeger1986]; [Bester-Conley-Hansen2011]; [Cameron-Miller2015] §VI); never below the model-based covariance
    widened for the residuals' lag-1 autocorrelation."""
    p = fit.theta.size
    J, r, w = fit.jac, fit.residuals, fit.weights
    Jw = J * w[:, None]
    bread = J.T @ Jw
    binv = np.linalg.pinv(bread)
    n = r.size
    dof_res = max(n - J.shape[1], 1)
    sigma2 = float(np.sum(w * r * r)) / dof_res
    same = sd.s_seg[1:] == sd.s_seg[:-1]
    den = float(r @ r)
    rho_r = float(np.sum((r[1:] * r[:-1])[same]) / den) if den > 0 else 0.0
    rho_r = max(0.0, min(0.95, rho_r))
    model = sigma2 * binv * (1.0 + rho_r) / (1.0 - rho_r)
    seg_scores = np.zeros((sd.m, J.shape[1]))
    np.add.at(seg_scores, sd.s_seg, Jw * r[:, None])
    infl = seg_scores @ binv.T  # each segment's influence on the estimate
    # lengthen the blocks while their influences are correlated (and enough clusters remain)
    b = 1
    while True:
        cid = _blocks(sd.group, b)
        G = int(cid.max()) + 1
        blk = np.zeros((G, J.shape[1]))
        np.add.at(blk, cid, infl)
        grp = np.array([sd.group[np.flatnonzero(cid == c)[0]] for c in range(G)])
        ok = grp[1:] == grp[:-1]
        x = blk[:, :p]
        rho = 0.0
        if ok.sum() >= 3:
            num = np.sum(x[1:][ok] * x[:-1][ok], axis=0)
            den2 = np.sum(x * x, axis=0)
            rr = np.where(den2 > 0, num / np.where(den2 > 0, den2, 1.0), 0.0)
            rho = float(np.max(rr))
        nxt = int(_blocks(sd.group, 2 * b).max()) + 1
        if rho > CLUSTER_RHO_MAX and nxt >= min_clusters and nxt < G:
            b *= 2
            continue
        break
    scores = np.zeros((G, J.shape[1]))
    np.add.at(scores, cid[sd.s_seg], Jw * r[:, None])
    corr = G / (G - 1) if G > 1 else 1.0
    sand = corr * binv @ (scores.T @ scores) @ binv
    model_p, sand_p = model[:p, :p], sand[:p, :p]
    if G < 3:  # two clusters tell nothing about the spread between them: the model-based covariance alone
        return Covariance(model_p.copy(), model_p, sand_p, G, b, rho, max(G - 1, 1), rho_r)
    var = np.diag(model_p)
    ratio = np.where(var > 0, np.diag(sand_p) / np.where(var > 0, var, 1.0), 1.0)
    d = np.sqrt(np.maximum(1.0, ratio))
    cov = model_p * np.outer(d, d)
    return Covariance(cov, model_p, sand_p, G, b, rho, max(G - 1, 1), rho_r)



#: Longest lag of the input in :func:`input_correlation`, s (a few damping time constants M / (dD/dv) of the heave)
INPUT_CORRELATION_LAG_S = 2.0


def input_correlation(residuals: np.ndarray, sd: SegmentData, max_lag_s: float = INPUT_CORRELATION_LAG_S) -> dict:
    """The independence test of output-error residuals ([Ljung1999] §16.6): the normalised cross-correlation
    r(tau) = sum e(t) g(t - tau) / sqrt(sum e^2 sum g^2) of the residuals e (k,) at the measurements of ``sd`` with
    the model's input g (the force at the tick, :attr:`SegmentData.u`, after delay and lag) and with its magnitude |g|
    (a per-direction error), both less their mean in each segment, pairs within a segment only, at lags tau from 0 to
    ``max_lag_s`` (every measurement interval). A model whose dynamics are right leaves residuals independent of past
    inputs whatever the colour of the disturbances it does not model; a wrong inertia, damping law, lag or
    direction asymmetry leaves a part of the input's response in them. z(tau): r(tau) over its standard deviation
    under independence, from the Newey-West (Bartlett) variance of the products e(t) g(t - tau) within each segment,
    bandwidth ``max_lag_s`` (both signals are coloured: the white-noise bound 1 / sqrt(k) would be far too narrow).
    Returns the lag and input of the largest z: {"z", "r": |r| there, "lag_s", "input": "force" | "force magnitude"}."""
    h = sd.h
    pos = sd.s_j + sd.s_a
    same = sd.s_seg[1:] == sd.s_seg[:-1]
    step = float(np.median(np.diff(pos)[same])) if np.any(same) else 1.0
    lags = np.arange(0, int(round(max_lag_s / h)) + 1, max(1, int(round(step))))
    band = max(1, int(math.ceil(max_lag_s / (step * h))))
    e_all = np.asarray(residuals, dtype=float)
    best = {"z": 0.0, "r": 0.0, "lag_s": 0.0, "input": "force"}
    for name, g in (("force", sd.u[0]), ("force magnitude", np.abs(sd.u[0]))):
        for tau in lags:
            ok = sd.s_j >= tau
            x_all = g[sd.s_seg, np.maximum(sd.s_j - tau, 0)]
            num = var = see = sgg = 0.0
            for s in np.unique(sd.s_seg[ok]):
                m = ok & (sd.s_seg == s)
                if m.sum() < 3:
                    continue
                e, x = e_all[m] - e_all[m].mean(), x_all[m] - x_all[m].mean()
                w = e * x
                num, see, sgg = num + w.sum(), see + e @ e, sgg + x @ x
                var += w @ w + sum(2.0 * (1.0 - k / (band + 1)) * (w[k:] @ w[:-k]) for k in range(1, min(band, w.size)))
            z = abs(num) / math.sqrt(var) if var > 0 else 0.0
            if z > best["z"]:
                best = {"z": z, "r": abs(num) / math.sqrt(see * sgg) if see > 0 and sgg > 0 else 0.0,
                        "lag_s": float(tau * h), "input": name}
    return best


# ------------------------------------------------------------------------------------------------ timing
#: Fraction of a training segment a delay may take (each segment starts from its measured state: a delay of a
#: tenth of it already leaves a tenth of every segment driven by force from before its start)
DELAY_SEGMENT_FRACTION = 0.1
#: Fraction of the velocity's power below the excitation bandwidth (:func:`resolvable_delay`)
BANDWIDTH_POWER = 0.9


def resolvable_delay(rec: DofRecord, max_delay_s: float, segment_s: float = SEGMENT_S) -> tuple[float, str]:
    """The largest input delay + lag (s) the record can resolve, and what set it (docs/identification.md §7 step 7): the
    smallest of ``max_delay_s`` (the option), :data:`DELAY_SEGMENT_FRACTION` of the training segment and a quarter
    period of the excitation bandwidth, below which :data:`BANDWIDTH_POWER` of the detrended velocity's power lies
    (Welch periodogram of each chunk, pooled): there a delay trades against the dynamics' own phase lag (at most
    90 degrees). Never below two grid steps (the sample rate's resolution)."""
    h = rec.h
    limits = [(float(max_delay_s), f"option max_delay_s {max_delay_s:g} s"),
              (DELAY_SEGMENT_FRACTION * segment_s,
               f"{DELAY_SEGMENT_FRACTION:g} x the {segment_s:g} s segment (record length)")]
    freqs = np.linspace(0.0, 0.5 / h, 401)
    power = np.zeros_like(freqs)
    for ch in rec.chunks:
        v = np.asarray(ch.v, dtype=float)
        if v.size < 32 or not np.all(np.isfinite(v)):
            continue
        f, p = _signal.welch(_signal.detrend(v), fs=1.0 / h, nperseg=min(v.size, int(round(40.0 / h))))
        power += np.interp(freqs, f, p) * v.size  # a density, weighted by the chunk's length
    if float(np.sum(power)) > 0:
        cum = np.cumsum(power) / float(np.sum(power))
        fb = float(freqs[min(int(np.searchsorted(cum, BANDWIDTH_POWER)), freqs.size - 1)])
        if fb > 0:
            limits.append((0.25 / fb, f"a quarter period of the {fb:.2g} Hz excitation bandwidth "
                                      f"({100 * BANDWIDTH_POWER:.0f} % of the velocity's power)"))
    bound, why = min(limits, key=lambda x: x[0])
    if bound < 2 * h:
        return 2 * h, f"two grid steps of {h:g} s (the sample rate's resolution; {why}: {bound:.3g} s)"
    return bound, why


def with_edge(timing: Timing, h: float) -> Timing:
    """``timing`` with ``at_edge`` set: an estimated delay + lag within one grid step ``h`` of its bound."""
    if timing.bound_s is None or timing.source == "known":
        return timing
    return replace(timing, at_edge=bool(timing.delay_s + timing.lag_s >= timing.bound_s - h))


#: Coarse grid of the timing search (:func:`estimate_timing`): delay step, s, and the first-order thrust lags, s
DELAY_STEP_S = 0.1
LAGS_S = (0.0, 0.05, 0.15, 0.4)
#: Fine grid around the coarse optimum: delay offsets, s
FINE_DELAYS_S = (-0.05, -0.025, 0.0, 0.025, 0.05)
#: Grid points fitted at once (bounds the memory of the batched simulation)
GRID_BATCH = 6


def _timing_scores(rec: DofRecord, points: list, sd: SegmentData, sv: SegmentData, folds: "Folds",
                   opts: CoreOptions, starts: np.ndarray | None = None,
                   iterations: int = timing_grid.ITERATIONS) -> tuple[np.ndarray, np.ndarray]:
    """Cross-validated simulation-error mse of the 1-DOF model (:mod:`.timing_grid`) at each (delay, lag) of
    ``points``: per point the inputs rebuilt with that timing, per fold a fit on its training segments and the
    prediction of its held-out ones (:func:`make_folds`; without folds, the training error on all segments), from
    ``starts`` (K, p) (default: each point's equation-error start) in ``iterations`` steps. Returns (mse (n,), the
    fold fits (n, K, p))."""
    terms = Terms("both")
    layout = parameter_layout(rec.dof, terms)
    if folds.held:
        train = np.zeros((len(folds.train), sd.m), dtype=bool)
        held = np.zeros((len(folds.held), sv.m), dtype=bool)
        # scored where the force moves: a held-out run the DOF only drifts in (a bias) has no timing to tell and its
        # error, which the fitted damping and bias alone set, swamped the curve of the runs that have (delay 0)
        driven = np.std(sv.force, axis=1) >= EXCITATION_MIN[excited_kind(rec.dof)][0]
        for k, (t, hh) in enumerate(zip(folds.train, folds.held)):
            train[k, t] = True
            held[k, hh[driven[hh]] if driven[hh].any() else hh] = True
    else:
        train = held = np.ones((1, sd.m), dtype=bool)
        sv = sd
    out, fits = np.empty(len(points)), []
    for a in range(0, len(points), GRID_BATCH):
        batch = points[a:a + GRID_BATCH]
        tms = [Timing(d, lag, "estimated") for d, lag in batch]
        sds = [build_segments(rec, terms, tm, opts.segment_s, excited_only=_excited_only(rec, opts)) for tm in tms]
        svs = sds if sv is sd else [build_segments(rec, terms, tm, opts.validation_s, excited_only=False) for tm in tms]
        U, Uv = np.stack([x.u for x in sds], axis=1), np.stack([x.u for x in svs], axis=1)
        start = (np.stack([_equation_error_start(x, layout, x.a_s) for x in sds]) if starts is None
                 else np.broadcast_to(starts, (len(batch),) + starts.shape))
        smp, nc = (sd.s_seg, sd.s_j, sd.s_a, sd.s_z), start.shape[-1] - 4
        th = timing_grid.fit_batch(U, sd.v0, smp, train, start, sd.h, sd.cols[..., :nc], iterations)
        sse, n = timing_grid.held_out_sse(Uv, sv.v0, (sv.s_seg, sv.s_j, sv.s_a, sv.s_z), held, th, sv.h,
                                          sv.cols[..., :nc])
        out[a:a + len(batch)] = np.sum(sse, axis=1) / max(float(np.sum(n)), 1.0)
        fits += list(th)
    return out, np.array(fits)


def estimate_timing(rec: DofRecord, opts: CoreOptions) -> Timing:
    """The input delay and first-order thrust lag of a commanded wrench with the smallest cross-validated simulation
    error of the 1-DOF model (docs/identification.md §7 step 1; :func:`_timing_scores`): a coarse grid (delay every
    :data:`DELAY_STEP_S`, lags :data:`LAGS_S`, delay + lag within :func:`resolvable_delay`), then :data:`FINE_DELAYS_S`
    around its best delay with the best lag and the lags halfway to its neighbours. ``curve``: [(delay, lag, cv mse)] of
    every point. A thrust-model force keeps its known timing (``rec.lag_s``, no delay). Raises :class:`EstimationError`
    when no segment moves the DOF."""
    if rec.force_source != "wrench":
        return Timing(0.0, rec.lag_s, "known")
    bound, why = resolvable_delay(rec, opts.max_delay_s, opts.segment_s)
    zero, both = Timing(), Terms("both")
    sd = build_segments(rec, both, zero, opts.segment_s, excited_only=_excited_only(rec, opts))
    sv = build_segments(rec, both, zero, opts.validation_s, excited_only=False)
    fo = make_folds(sd, sv, opts.folds)
    step = max(rec.h, DELAY_STEP_S)
    coarse = [(round(float(d), 6), lag) for lag in LAGS_S for d in np.arange(0.0, bound + 1e-9, step)
              if d + lag <= bound + 1e-9]
    # every point and fold starts from the fold's fit at no delay, the fine points from the best coarse point's: a
    # warm start converges in fewer steps than the equation-error one (biased by the noise of the differentiated
    # velocity), in timing_grid.WARM_ITERATIONS
    s0, ref = _timing_scores(rec, [(0.0, 0.0)], sd, sv, fo, opts)
    sc, th = _timing_scores(rec, coarse[1:], sd, sv, fo, opts, ref[0], timing_grid.WARM_ITERATIONS)
    scores = dict(zip(coarse, np.concatenate([s0, sc])))
    d0, lag0 = min(scores, key=scores.get)
    best = dict(zip(coarse, np.concatenate([ref, th])))[(d0, lag0)]
    i = LAGS_S.index(lag0)
    lags = {lag0, 0.5 * (lag0 + LAGS_S[i - 1]) if i > 0 else lag0,
            0.5 * (lag0 + LAGS_S[i + 1]) if i + 1 < len(LAGS_S) else lag0}
    fine = [(round(d0 + x, 6), lag) for lag in sorted(lags) for x in FINE_DELAYS_S
            if d0 + x >= 0.0 and d0 + x + lag <= bound + 1e-9 and (round(d0 + x, 6), lag) not in scores]
    if fine:
        scores.update(zip(fine, _timing_scores(rec, fine, sd, sv, fo, opts, best, timing_grid.WARM_ITERATIONS)[0]))
    d, lag = min(scores, key=scores.get)
    curve = tuple((round(a, 4), round(b, 4), float(c)) for (a, b), c in sorted(scores.items()))
    return with_edge(Timing(d, lag, "estimated (output-error cross-validation)", curve, bound, why), rec.h)


# ------------------------------------------------------------------------------------------------ validation
def validation_measures(sd: SegmentData, V: np.ndarray) -> dict:
    """nrmse, nrmse_hold, nrmse_zero, nrmse_floor and samples of predictions ``V`` (m, L) on ``sd``:
    RMS(prediction - measured) / std(measured) over the measurements after each segment's start;
    ``hold``: the initial velocity held; ``zero``: 0. A measured position is validated on the
    smoothed velocity at the ticks. ``nrmse_floor``: the white measurement noise over
    std(measured), the nrmse a perfect model would still have, sigma^2 = mean(d2^2) / 6 with d2 the
    second differences of consecutive measurements in a segment (white noise of variance sigma^2
    gives var(d2) = 6 sigma^2; a smooth velocity adds little at the sensor's rate), NaN for a
    measured position or fewer than 3 measurements in every segment."""
    if sd.measured == "position":
        z = sd.v_s[:, 1:].ravel()
        pred = V[:, 1:].ravel()
        hold = np.repeat(sd.v0, sd.L - 1)
    else:
        z = sd.s_z
        pred = at_samples(sd, V)
        hold = sd.v0[sd.s_seg]
    ok = np.isfinite(z) & np.isfinite(pred)
    z, pred, hold = z[ok], pred[ok], hold[ok]
    if z.size < 2:
        return {"nrmse": math.nan, "nrmse_hold": math.nan, "nrmse_zero": math.nan, "nrmse_floor": math.nan,
                "samples": int(z.size)}
    sd_z = float(np.std(z)) or 1.0

    def rms(e):
        return float(np.sqrt(np.mean(e ** 2)))

    floor = math.nan
    if sd.measured != "position":
        seg = sd.s_seg[ok]
        order = np.lexsort((sd.s_j[ok] + sd.s_a[ok], seg))
        zs, gs = z[order], seg[order]
        d2 = zs[2:] - 2.0 * zs[1:-1] + zs[:-2]
        same = (gs[2:] == gs[:-2])
        if np.any(same):
            floor = math.sqrt(float(np.mean(d2[same] ** 2)) / 6.0) / sd_z
    return {"nrmse": rms(pred - z) / sd_z, "nrmse_hold": rms(hold - z) / sd_z, "nrmse_zero": rms(z) / sd_z,
            "nrmse_floor": floor, "samples": int(z.size), "sse": float(np.sum((pred - z) ** 2)),
            "sst": float(np.sum((z - z.mean()) ** 2))}


def predict_validation(sd: SegmentData, layout: list, theta: np.ndarray) -> np.ndarray:
    """Open-loop velocity predictions (m, L) of the validation segments ``sd`` from their smoothed initial
    velocities (no free initial velocity even for a measured position)."""
    V, _ = simulate(sd, layout, theta[None, :])
    return V[0]


# ------------------------------------------------------------------------------------------------ selection
@dataclass(eq=False)  # compared by identity: two fits of the same terms are two candidates
class Candidate:
    """One model's fit on all training segments and its cross-validation: terms, layout, full-data fit, fold
    estimates (K, p) (NaN rows: the fold could not be fitted), per-fold held-out sse, n and sst, the pooled CV
    measures, and per-fold notes."""

    terms: Terms
    layout: list
    fit: FitOutcome
    train: SegmentData
    val: SegmentData
    fold_theta: np.ndarray
    fold_sse: np.ndarray
    fold_n: np.ndarray
    cv: dict
    fold_notes: list
    free_v0: bool = False

    @property
    def n_params(self) -> int:
        return len(self.layout)

    @property
    def mse(self) -> float:
        n = float(np.sum(self.fold_n))
        return float(np.sum(self.fold_sse)) / n if n > 0 else math.inf


@dataclass
class Folds:
    """K folds: held-out validation segments (index arrays into the validation SegmentData) and the training
    segments to use without each fold (index arrays into the training SegmentData); notes."""

    held: list
    train: list
    notes: list


def make_folds(sd_train: SegmentData, sd_val: SegmentData, k: int) -> Folds:
    """The folds of the cross-validation, built as the held-out runs are (docs/identification.md §7 step 4).

    Validation segments of two runs or more (``group``): whole runs held out, every segment of them moving or not
    (the held-out runs of ``hindrax ident fit --holdout`` and ``ident predict`` are new runs, scored on all their
    segments), the runs dealt to ``k`` groups in turn, the most force variance first (one run per fold when there
    are at most ``k``); each fold trains on the other runs. One run: contiguous blocks of the excited validation
    segments (time order), a training segment overlapping a held-out validation segment's time span left out of that
    fold's training; fewer excited validation segments than ``k``: that many folds (at least 2)."""
    runs = np.unique(sd_val.group)
    if runs.size >= 2:
        # dealt in turn, the runs that drive the DOF most first: runs driving it in a row (a campaign) held out in one
        # fold left it to train on none of them (its CV at holding's level, the delay curve noise: delay 0)
        drive = [-float(np.sum(np.var(sd_val.force[sd_val.group == g], axis=1))) for g in runs]
        order, k = runs[np.argsort(drive, kind="stable")], min(k, runs.size)
        held_runs = sorted((np.sort(order[i::k]) for i in range(k)), key=lambda a: int(a[0]))
        held = [np.flatnonzero(np.isin(sd_val.group, a)) for a in held_runs]
        return Folds(held, [np.flatnonzero(~np.isin(sd_train.group, a)) for a in held_runs], [])
    exc = np.flatnonzero(sd_val.excited)
    if exc.size < 2:
        return Folds([], [], [f"{exc.size} validation segment(s) move the DOF: no cross-validation possible"])
    k = max(2, min(k, exc.size))
    held = [a for a in np.array_split(exc, k) if a.size]
    train = []
    for hidx in held:
        spans = sd_val.span[hidx]
        grp = sd_val.group[hidx]
        keep = np.ones(sd_train.m, dtype=bool)
        for (a, b), g in zip(spans, grp):
            keep &= ~((sd_train.group == g) & (sd_train.span[:, 1] >= a) & (sd_train.span[:, 0] <= b))
        train.append(np.flatnonzero(keep))
    return Folds(held, train, [])


def _cv(sd_train: SegmentData, sd_val: SegmentData, folds: Folds, dof: str, layout: list, full: FitOutcome,
        robust: bool, free_v0: bool | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list]:
    """Fold refits (warm start from the full fit) and their held-out sse, counts and sst."""
    K = len(folds.held)
    p = len(layout)
    th = np.full((K, p), np.nan)
    sse, nn, sst = np.zeros(K), np.zeros(K), np.zeros(K)
    notes = []
    fmin, vmin = EXCITATION_MIN[excited_kind(dof)]
    for i, (hidx, tidx) in enumerate(zip(folds.held, folds.train)):
        tr = sd_train.subset(tidx)
        if tr.m < 2 or not tr.excited.any():
            notes.append(f"fold {i + 1}: its training part has no segment moving {dof}")
            continue
        start = full.theta.copy()
        # a regressor absent from this fold's training (a held-out run): 0, not the full fit's value
        for c, j in enumerate(_column_params(layout)):
            if c < tr.cols.shape[-1] and not np.any(tr.cols[0][..., c]):
                start[j] = 0.0
        try:
            f = fit_terms(tr, dof, layout, start, robust, full.f_scale, max_nfev=25, free_v0=free_v0)
        except (EstimationError, ValueError, np.linalg.LinAlgError) as exc:
            notes.append(f"fold {i + 1}: fit failed ({exc})")
            continue
        th[i] = f.theta
        va = sd_val.subset(hidx)
        if np.unique(sd_val.group).size >= 2:  # a held-out run is a new run: the mean bias, as ident predict's
            va.cols[..., [c for c, j in enumerate(_column_params(layout)) if layout[j][1].startswith("runbias")]] = 0.0
        m = validation_measures(va, predict_validation(va, layout, f.theta))
        if m["samples"] < 2:
            notes.append(f"fold {i + 1}: no measurement held out")
            continue
        sse[i], nn[i], sst[i] = m["sse"], m["samples"], m["sst"]
        zstd = math.sqrt(m["sst"] / m["samples"])
        if zstd < vmin:
            notes.append(f"fold {i + 1}: held-out {dof} velocity std {zstd:.3g} below {vmin:g} (not excited)")
    return th, sse, nn, sst, notes


def _cv_summary(sd_val: SegmentData, folds: Folds, sse, nn, sst) -> dict:
    n = float(np.sum(nn))
    if n < 2:
        return {"nrmse": math.nan, "samples": 0, "folds": 0}
    idx = np.concatenate([h for h, c in zip(folds.held, nn) if c > 0])
    va = sd_val.subset(idx)
    # nrmse over the pooled held-out measurements (hold and zero from the same samples)
    pooled = validation_measures(va, np.broadcast_to(va.v0[:, None], (va.m, va.L)))
    sd_z = math.sqrt(pooled["sst"] / pooled["samples"]) if pooled["samples"] else 1.0
    return {"nrmse": math.sqrt(float(np.sum(sse)) / n) / sd_z, "nrmse_hold": pooled["nrmse_hold"],
            "nrmse_zero": pooled["nrmse_zero"], "nrmse_floor": pooled["nrmse_floor"], "samples": int(n),
            "folds": int(np.sum(nn > 0)),
            "fold_nrmse": [float(math.sqrt(s / c) / math.sqrt(t / c)) if c > 0 and t > 0 else None
                           for s, c, t in zip(sse, nn, sst)]}


def _excited_only(rec: DofRecord, opts: CoreOptions) -> bool:
    """Fit only the segments that move the DOF (not ``opts.all_segments`` nor ``rec.all_segments``)."""
    return not (opts.all_segments or rec.all_segments)


def _candidate(rec: DofRecord, terms: Terms, timing: Timing, opts: CoreOptions, inertia: np.ndarray | None,
               folds_cache: dict, theta0: np.ndarray | None = None, free_v0: bool | None = None,
               excited_only: bool | None = None) -> Candidate:
    """``terms`` fitted on the training segments (only the moving ones unless ``excited_only`` is False or the record
    says otherwise, :func:`_excited_only`; each segment's initial velocity fitted when ``free_v0``, default for a
    measured position) and cross-validated on the validation segments."""
    free_v0 = rec.measured == "position" if free_v0 is None else free_v0
    sd = build_segments(rec, terms, timing, opts.segment_s, inertia,
                        excited_only=_excited_only(rec, opts) if excited_only is None else excited_only)
    sv = build_segments(rec, terms, timing, opts.validation_s, inertia, excited_only=False)
    layout = parameter_layout(rec.dof, terms, len(rec.cross_names), rec.cross_names, rec.force_names, rec.run_count)
    start = _equation_error_start(sd, layout, sd.a_s)
    if theta0 is not None and theta0.size == start.size:
        start = theta0
    fit = fit_terms(sd, rec.dof, layout, start, opts.robust, free_v0=free_v0)
    key = (sd.m, sv.m)
    if key not in folds_cache:
        folds_cache[key] = make_folds(sd, sv, opts.folds)
    folds = folds_cache[key]
    # without folds: no fold estimates, no score, and the reason in the notes (make_folds)
    th, sse, nn, sst, notes = _cv(sd, sv, folds, rec.dof, layout, fit, opts.robust, free_v0)
    cv = _cv_summary(sv, folds, sse, nn, sst)
    return Candidate(terms, layout, fit, sd, sv, th, sse, nn, cv, list(folds.notes) + notes, free_v0)


def persistence(cv: dict, margin: float = PERSISTENCE_MARGIN) -> dict:
    """The model's cross-validated nrmse against the two trivial predictors scored on the SAME held-out samples
    (:func:`_cv_summary`): holding the segment's initial velocity (persistence) and 0. ``beats``: nrmse <=
    (1 - ``margin``) nrmse_hold (NaN scores: False). Returns {nrmse, nrmse_hold, nrmse_zero, margin, beats}."""
    n, hold, zero = (float(cv.get(k, math.nan)) if cv.get(k) is not None else math.nan
                     for k in ("nrmse", "nrmse_hold", "nrmse_zero"))
    beats = bool(math.isfinite(n) and math.isfinite(hold) and n <= (1.0 - margin) * hold)
    return {"nrmse": n, "nrmse_hold": hold, "nrmse_zero": zero, "margin": float(margin), "beats": beats}


def _best_cv(cands: list[Candidate]) -> Candidate:
    """The candidate with the smallest cross-validated error (ties within 0.1 %: the one with fewer parameters)."""
    ok = [c for c in cands if math.isfinite(c.mse)]
    if not ok:
        return min(cands, key=lambda c: c.n_params)
    best = min(c.mse for c in ok)
    return min((c for c in ok if c.mse <= best * 1.001), key=lambda c: (c.n_params, c.mse))


def _improves(base: Candidate, c: Candidate) -> bool:
    """True when ``c``'s CV error is below ``base``'s by more than one standard error of the fold differences."""
    if not (math.isfinite(c.mse) and math.isfinite(base.mse)):
        return False
    K = base.fold_n.size
    if K < 2 or c.fold_n.size != K:
        return c.mse < base.mse
    d = base.fold_sse / np.maximum(base.fold_n, 1) - c.fold_sse / np.maximum(c.fold_n, 1)
    se = float(np.std(d, ddof=1) / math.sqrt(K))
    return float(np.mean(d)) > se


#: The 1-DOF model (linear + quadratic damping, bias; no coupling, one law for both directions): always a
#: candidate of :func:`select_terms`, with the timing chosen for it (:func:`estimate_timing`)
NESTED = Terms("both")


def not_below_nested(chosen: Candidate, tried: list[Candidate]) -> Candidate:
    """``chosen`` when its cross-validated error is below the nested 1-DOF model's (:data:`NESTED`, among ``tried``)
    by more than one standard error of the fold differences (:func:`_improves`), else the nested model: selection
    moves away from the model every richer one contains only when cross-validation says so (the one-standard-error
    rule, [Hastie-ESL2009] §7.10)."""
    nested = [c for c in tried if c.terms == NESTED and math.isfinite(c.mse)]
    best = min(nested, key=lambda c: c.mse, default=None)
    if best is None or best is chosen:
        return chosen
    return chosen if _improves(best, chosen) else best


def select_terms(rec: DofRecord, timing: Timing, opts: CoreOptions, inertia: np.ndarray | None,
                 stage: int = 0, base: Candidate | None = None) -> tuple[Candidate, list[Candidate]]:
    """Stage 1 (``stage`` 1): damping by the smallest CV error; stage 2: the additions on ``base``,
    each kept by the one-standard-error rule ([Hastie-ESL2009] §7.10); 0: both
    (docs/identification.md §7 step 4). Returns (chosen, every candidate evaluated)."""
    folds_cache: dict = {}
    tried: list[Candidate] = []

    def run(terms, theta0=None):
        try:
            c = _candidate(rec, terms, timing, opts, inertia, folds_cache, theta0)
        except (EstimationError, ValueError, np.linalg.LinAlgError):
            return None
        tried.append(c)
        return c

    other = None if inertia is None else np.delete(inertia, DOFS.index(rec.dof))
    cor = bool(rec.has_coupling and other is not None and np.isfinite(other).any())
    if stage in (0, 1):
        splits = (False, True) if rec.dof == "heave" else (False,)
        for by_dir in splits:
            for damping in ("quadratic", "linear", "both"):
                run(Terms(damping, by_dir, coriolis=cor))
        if cor:  # the nested 1-DOF model, as it is fitted alone
            run(NESTED)
        if not tried:
            raise EstimationError(f"{rec.dof}: no model could be fitted")
        base = _best_cv(tried)
        if stage == 1:
            return base, tried
    assert base is not None
    chosen = base
    # (term, value, when it is a candidate); the Coriolis force is physics (the other DOFs'
    # inertias): tried without it, not added
    candidates = (("coriolis", False, base.terms.coriolis), ("cross", True, bool(rec.cross_names)),
                  ("cross_force", True, bool(rec.force_names)),
                  ("run_bias", True, rec.run_count >= 2 and rec.runs_known),
                  ("saturation", True, rec.saturates),
                  ("reverse_gain", True, rec.force_source == "wrench"))
    changes = [(name, value) for name, value, when in candidates if when]
    keep = []
    for name, value in changes:
        c = run(replace(base.terms, **{name: value}))
        if c is not None and _improves(base, c):
            keep.append((name, value))
    if len(keep) == 1:
        chosen = next(t for t in tried if t.terms == replace(base.terms, **dict(keep)))
    elif keep:
        c = run(replace(base.terms, **dict(keep)))
        singles = [t for t in tried if t.terms in [replace(base.terms, **{n: v}) for n, v in keep]]
        best_single = min(singles, key=lambda t: t.mse)
        chosen = c if c is not None and _improves(best_single, c) else best_single
    chosen = not_below_nested(chosen, tried)
    if not persistence(chosen.cv, opts.persistence_margin)["beats"]:
        # the one-standard-error rule kept a simpler model that holding the velocity beats: the best one that does
        better = [t for t in tried if persistence(t.cv, opts.persistence_margin)["beats"]]
        if better:
            chosen = min(better, key=lambda t: t.mse)
    return chosen, tried


# ------------------------------------------------------------------------------------------------ one DOF
@dataclass
class DofResult:
    """The core's result for one DOF: names, units-free theta (p,), the reported covariance and its parts
    (:class:`Covariance`), std (p,), ci95 (p, 2), the chosen terms and every candidate's CV score, the timing, the
    cross-validation of the chosen model (pooled measures, fold estimates, notes), the training and validation
    segments, and the chosen candidate."""

    dof: str
    names: list
    theta: np.ndarray
    covariance: Covariance
    std: np.ndarray
    ci95: np.ndarray
    terms: Terms
    timing: Timing
    candidates: list
    cv: dict
    fold_theta: np.ndarray
    fold_notes: list
    train: SegmentData
    chosen: Candidate
    measured: str
    persistence: dict | None = None
    training: dict | None = None

    @property
    def beats_persistence(self) -> bool:
        """The chosen model beats holding the velocity in cross-validation (:func:`persistence`); True without a
        cross-validation (nothing to compare)."""
        return self.persistence is None or bool(self.persistence["beats"]) or not math.isfinite(
            self.persistence["nrmse_hold"])

    @property
    def t_quantile(self) -> float:
        return float(stats.t.ppf(0.975, self.covariance.t_dof))


#: How a training segment starts (:func:`training_rules`), per ``Candidate.free_v0``
INITIAL_STATES = {False: "smoothed measurement", True: "fitted per segment"}


def training_rules(rec: DofRecord, chosen: Candidate, timing: Timing, opts: CoreOptions,
                   inertia: np.ndarray | None) -> dict:
    """Fit what is scored (docs/identification.md §7 step 2): the chosen terms refitted under the
    other training rules, each cross-validated on the same validation segments (which start from the
    smoothed measurement): for a measured position, the initial state (each training segment's
    initial velocity fitted, the verdict's, or the smoothed measurement); for a record fitted on its
    moving segments only (:func:`_excited_only`), the fit on every segment beside it.

    Returns {initial_state: {used, cv_nrmse: {rule: nrmse}}, segments: {used, moving_only,
    all_segments: {cv_nrmse, segments, parameters}}}."""
    def refit(**kw):
        try:
            return _candidate(rec, chosen.terms, timing, opts, inertia, {}, chosen.fit.theta, **kw)
        except (EstimationError, ValueError, np.linalg.LinAlgError):
            return None

    out: dict = {"initial_state": {"used": INITIAL_STATES[chosen.free_v0]}}
    if rec.measured == "position":
        both = [c for c in (chosen, refit(free_v0=not chosen.free_v0)) if c is not None]
        out["initial_state"]["cv_nrmse"] = {INITIAL_STATES[c.free_v0]: c.cv.get("nrmse") for c in both}
    if _excited_only(rec, opts):
        def row(c):
            return None if c is None else {"cv_nrmse": c.cv.get("nrmse"), "segments": int(c.train.m), "parameters": {
                n: float(v) for (n, _k, _lo, _hi), v in zip(c.layout, c.fit.theta)}}

        out["segments"] = {"used": "moving_only", "moving_only": row(chosen),
                           "all_segments": row(refit(free_v0=chosen.free_v0, excited_only=False))}
    return out


def finish(rec: DofRecord, chosen: Candidate, tried: list, timing: Timing, opts: CoreOptions,
           inertia: np.ndarray | None) -> DofResult:
    """The result: :func:`training_rules` (``inertia`` (6,) as the chosen model's) and the intervals
    (:func:`cluster_covariance`) of the chosen candidate."""
    training = training_rules(rec, chosen, timing, opts, inertia)
    cov = cluster_covariance(chosen.fit, chosen.train, opts.min_clusters)
    if rec.measured == "position":
        cov = replace(cov, input_corr=input_correlation(chosen.fit.residuals, chosen.train))
    std = np.sqrt(np.maximum(np.diag(cov.cov), 0.0))
    tq = float(stats.t.ppf(0.975, cov.t_dof))
    th = chosen.fit.theta
    names = [n for n, _k, _lo, _hi in chosen.layout]
    return DofResult(rec.dof, names, th, cov, std, np.column_stack([th - tq * std, th + tq * std]), chosen.terms,
                     timing, tried, chosen.cv, chosen.fold_theta, chosen.fold_notes, chosen.train, chosen,
                     rec.measured, persistence(chosen.cv, opts.persistence_margin) if chosen.cv.get("samples")
                     else None, training)


def identify_dof(rec: DofRecord, opts: CoreOptions = CoreOptions(), inertia: np.ndarray | None = None) -> DofResult:
    """Timing, terms by cross-validation (or ``opts.terms``), fit and intervals of one DOF (module docstring).
    ``inertia`` (6,): the other DOFs' inertias for the Coriolis candidate (NaN: unknown). Raises
    :class:`EstimationError`."""
    timing = estimate_timing(rec, opts)
    if opts.select and rec.terms is None:
        chosen, tried = select_terms(rec, timing, opts, inertia)
    else:
        c = _candidate(rec, rec.terms or opts.terms, timing, opts, inertia, {})
        chosen, tried = c, [c]
    return finish(rec, chosen, tried, timing, opts, inertia)


def inertia_vector(results: dict) -> np.ndarray:
    """[M1..M6] of the fitted DOFs (NaN where not fitted): the inertias of the Coriolis terms.
    ``results``: {dof: DofResult, Candidate or FitOutcome}."""
    out = np.full(6, np.nan)
    for d, r in results.items():
        out[DOFS.index(d)] = float(getattr(r, "fit", r).theta[0])
    return out


def identify_dofs(records: dict, opts: CoreOptions = CoreOptions()) -> tuple[dict, dict]:
    """:func:`identify_dof` for several DOFs at once, so that the Coriolis force of each uses the others' inertias (from
    a first fit of every DOF; :func:`coupling_consistent`). Returns ({dof: DofResult}, {dof: error message})."""
    timings, errors, first = {}, {}, {}
    for dof, rec in records.items():  # timing, and a first fit of every DOF for the inertias of the Coriolis force
        try:
            tm = timings[dof] = estimate_timing(rec, opts)
            terms = Terms("both", rec.dof == "heave")
            sd = build_segments(rec, terms, tm, opts.segment_s, excited_only=_excited_only(rec, opts))
            layout = parameter_layout(rec.dof, terms)
            start = _equation_error_start(sd, layout, sd.a_s)
            first[dof] = fit_terms(sd, dof, layout, start, opts.robust, max_nfev=40)
        except (EstimationError, ValueError, np.linalg.LinAlgError) as exc:
            errors[dof] = str(exc)
    inertia0 = inertia_vector(first)
    # once more with the Coriolis force of those inertias (a surge fit without it reads the centripetal force of a
    # turning run as inertia or damping, and the yaw Munk moment (M2 - M1) u v depends on both)
    inertia1 = inertia0.copy()
    for dof, f in first.items():
        rec = records[dof]
        if not rec.has_coupling:
            continue
        try:
            terms = Terms("both", rec.dof == "heave", coriolis=True)
            sd = build_segments(rec, terms, timings[dof], opts.segment_s, inertia0,
                                excited_only=_excited_only(rec, opts))
            layout = parameter_layout(rec.dof, terms)
            f1 = fit_terms(sd, dof, layout, f.theta, opts.robust, max_nfev=40)
            inertia1[DOFS.index(dof)] = float(f1.theta[0])
        except (EstimationError, ValueError, np.linalg.LinAlgError):
            pass
    chosen, allc = {}, {}
    for dof in first:  # stage 1 (damping), then stage 2 (the additions) on its choice
        rec, tm = records[dof], timings[dof]
        try:
            if opts.select and rec.terms is None:
                base, tried = select_terms(rec, tm, opts, inertia1, stage=1)
                c, more = select_terms(rec, tm, opts, inertia1, stage=2, base=base)
                allc[dof] = tried + [t for t in more if t not in tried]
                chosen[dof] = not_below_nested(c, allc[dof])
            else:
                c = _candidate(rec, rec.terms or opts.terms, tm, opts, inertia1, {})
                chosen[dof], allc[dof] = c, [c]
        except (EstimationError, ValueError, np.linalg.LinAlgError) as exc:
            errors[dof] = str(exc)
    used = coupling_consistent(records, timings, chosen, allc, {d: inertia1 for d in chosen}, opts)
    results = {}
    for dof, c in chosen.items():
        try:
            results[dof] = finish(records[dof], c, allc[dof], timings[dof], opts, used[dof])
        except (EstimationError, ValueError, np.linalg.LinAlgError) as exc:
            errors[dof] = str(exc)
    return results, errors


#: Largest relative difference between an inertia a DOF's Coriolis force was fitted with and the
#: one the result states for that DOF (:func:`coupling_consistent`); passes of refits at most
COUPLING_RTOL = 0.01
COUPLING_PASSES = 3


def _inertia_moved(used: np.ndarray, stated: np.ndarray, dof: str) -> bool:
    """The other DOFs' inertias ``used`` (6,) differ from ``stated`` (6,) by > COUPLING_RTOL."""
    k = DOFS.index(dof)
    a, b = np.delete(np.nan_to_num(used), k), np.delete(np.nan_to_num(stated), k)
    return bool(np.any(np.abs(a - b) > COUPLING_RTOL * np.maximum(np.abs(b), 1e-9)))


def refit_coupling(rec: DofRecord, chosen: Candidate, tried: list, timing: Timing,
                   opts: CoreOptions, inertia: np.ndarray) -> tuple[Candidate, list]:
    """``chosen`` (with the Coriolis force) fitted and cross-validated again with the other DOFs' inertias ``inertia``
    (6,), replacing it among ``tried``; then :func:`not_below_nested` against the nested 1-DOF model (no Coriolis
    force). A refit that fails: the nested model (or ``chosen`` without one). Returns (the model, the candidates)."""
    rest = [t for t in tried if t is not chosen]
    try:
        c = _candidate(rec, chosen.terms, timing, opts, inertia, {}, chosen.fit.theta)
    except (EstimationError, ValueError, np.linalg.LinAlgError):
        nested = [t for t in rest if t.terms == NESTED and math.isfinite(t.mse)]
        return (min(nested, key=lambda t: t.mse), rest) if nested else (chosen, tried)
    return not_below_nested(c, rest + [c]), rest + [c]


def coupling_consistent(records: dict, timings: dict, chosen: dict, tried: dict, used: dict, opts: CoreOptions) -> dict:
    """Score every chosen model with the inertias it is predicted with (docs/identification.md
    §7 step 4): selection fits a DOF's Coriolis force with preliminary inertias of the other DOFs
    (``used``: {dof: (6,)}); until they agree with the stated ones (:data:`COUPLING_RTOL`, at most
    :data:`COUPLING_PASSES` passes) each such model is refitted with those (:func:`refit_coupling`).
    Updates ``chosen`` and ``tried`` in place; returns the inertias each model was fitted with."""
    used = dict(used)
    for _ in range(COUPLING_PASSES):
        stated = inertia_vector(chosen)
        stale = [d for d, c in chosen.items() if c.terms.coriolis and _inertia_moved(used[d], stated, d)]
        if not stale:
            break
        for d in stale:
            chosen[d], tried[d] = refit_coupling(records[d], chosen[d], tried[d], timings[d], opts, stated)
            used[d] = stated
    return used
