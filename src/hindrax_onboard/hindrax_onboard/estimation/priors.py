"""Empirical priors from geometry: added mass, linear and quadratic damping ([NTNU-Thesis] Sec. 3.1, App. A).

This is a transcription of the thesis's two MATLAB scripts, the ones that produced its Chapter 4 "Empirical"
columns: App. A.1 ("Empirical Added Mass estimator for ROV") and App. A.2 ("Empirical Damping estimator for
ROV"), in SI units (the scripts work in mm and carry the 10^-n factors; the formulas are the same). The thesis
derives them in Sec. 3.1.3 (added mass) and 3.1.4 (damping); where the scripts and the text differ, the scripts
are followed, because they produced the printed tables:

* Tables are interpolated with MATLAB's ``spline`` (not-a-knot cubic spline through the points, sorted by
  abscissa, extrapolated with the end polynomials), what ``scipy.interpolate.CubicSpline`` with its default
  ``bc_type="not-a-knot"`` gives (:func:`not_a_knot_spline`, written out: the identification node builds these
  priors at start, and importing ``scipy.interpolate`` would cost its process 45 MB of proportional set size,
  29 MB of it private, for four tables of 4-9 points; a test checks it against scipy). A lookup outside a table's
  abscissa range is an extrapolation; it is reported in ``notes``.
* Added mass 3D table (DNV-RP-H103 rectangular prism, thesis Table 3.2): the script's values
  ``[1 .68; 2 .36; 3 .24; 4 .19; 5 .15; 6 .14; 7 .11]`` (Table 3.2 prints 0.13 at 6 and a point at 10).
* Surge added mass: the 3D value A_3D = C_a(L/a) L a^2 rho Cp_yz^2 Cp_xz Cp_xy with a = (H + W)/2 (eq. 3.3)
  and the strip value A_2D = rho C_a2D(W/L) pi (W/2)^2 Cp_yz^2 Cp_xz Cp_xy H; the script sets
  lambda = sqrt(A_3D / A_2D) and A11 = lambda A_2D (i.e. the geometric mean of the two; the text's
  lambda = A_3D / A_2D would give A11 = A_3D). Sway, heave and the rotations are strip values scaled by that
  lambda (eq. 3.4 for the rotations, 2D coefficients "CA2DR" of the script).
* Quadratic damping (eq. 3.7, 3.10): lambda = C_D3D(L/a) / C_D2D(L/W) (eq. 3.8) with the Blevins (2003)
  tables 10-19/10-20 points of the script; translations 1/2 rho C_D A Cp lambda; rotations by four quadrants,
  F = rho/6 C_D (D/2) l Cp lambda per quadrant, moment arm 3/4 of the half width, cubed half width
  (the script's ``Mh = Fh*(3/4)*((H/2))^3``).
* Linear damping (eq. 3.18 and the text after it): roll and pitch 2 zeta sqrt(C (I + A)) with zeta = 0.025
  and the restoring coefficient C; surge, sway and heave 0.16 times the quadratic term (Eng et al. 2009,
  the script's ``lambda0``); yaw the quadratic yaw term times the pitch ratio BL55 / BQ55.
* Rigid inertia when not given: the prism formulas of Sec. 3.1.1 (I4 = m/12 (W^2 + H^2), ...); restoring
  C = m g BG (Sec. 3.1.2, weight = buoyancy), BG the vertical distance from the CG up to the CB.

Coordinates: L along x (length), W along y (width), H along z (height); projected areas: frontal normal to x
(the thesis's "front", plane YZ), side normal to y ("side", XZ), top normal to z ("top", XY); Cp = projected
area / bounding rectangle (Table 3.1).

Units of the results (SI, diagonal, positive): added mass kg (1-3), kg m^2 (4-6); linear damping kg/s (1-3),
kg m^2/s (4-6); quadratic damping kg/m (1-3), kg m^2 (4-6)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional, Sequence

import numpy as np

from .least_squares import EstimationError

__all__ = ["Geometry", "PriorInputs", "not_a_knot_spline", "added_mass_priors", "quadratic_damping_priors",
           "linear_damping_priors", "empirical_priors", "priors_from_config", "ADDED_MASS_3D", "ADDED_MASS_2D",
           "DRAG_2D", "DRAG_3D", "ZETA_ROLL_PITCH", "LINEAR_TO_QUADRATIC_TRANSLATION", "UNITS"]

#: [NTNU-Thesis] App. A.1 ``EMP3D``: (B/A, C_a) of the DNV rectangular prism (two sides equal).
ADDED_MASS_3D = ((1.0, 0.68), (2.0, 0.36), (3.0, 0.24), (4.0, 0.19), (5.0, 0.15), (6.0, 0.14), (7.0, 0.11))
#: [NTNU-Thesis] App. A.1 ``EMP2D``: (b/a, C_a translation, C_a rotation) of 2D rectangular sections (DNV).
ADDED_MASS_2D = ((10.0, 1.14, 0.125), (5.0, 1.21, 0.15), (2.0, 1.36, 0.15), (1.0, 1.51, 0.234),
                 (0.5, 1.70, 0.15), (0.2, 1.98, 0.15), (0.1, 2.23, 0.147))
#: [NTNU-Thesis] App. A.2 ``Data2D``: (L/D, C_D) 2D rectangular section (Blevins 2003 table 10-20).
DRAG_2D = ((0.5, 2.5), (1.5, 1.8), (2.5, 1.4), (6.0, 0.89))
#: [NTNU-Thesis] App. A.2 ``Data3D``: (L/D, C_D) 3D block (Blevins 2003 table 10-19).
DRAG_3D = ((0.0, 1.25), (0.5, 1.25), (1.0, 1.15), (1.5, 0.97), (2.0, 0.87), (2.5, 0.9), (3.0, 0.93),
           (4.0, 0.95), (5.0, 0.95))
#: [NTNU-Thesis] eq. 3.18 and App. A.2: damping ratio assumed in roll and pitch.
ZETA_ROLL_PITCH = 0.025
#: [NTNU-Thesis] Sec. 3.1.4 and App. A.2 ``lambda0``: linear / quadratic damping in translation (Eng et al. 2009).
LINEAR_TO_QUADRATIC_TRANSLATION = 0.16

UNITS = {
    "added_mass": ["kg", "kg", "kg", "kg m^2", "kg m^2", "kg m^2"],
    "linear_damping": ["kg/s", "kg/s", "kg/s", "kg m^2/s", "kg m^2/s", "kg m^2/s"],
    "quadratic_damping": ["kg/m", "kg/m", "kg/m", "kg m^2", "kg m^2", "kg m^2"],
}


def not_a_knot_spline(x: Sequence[float] | np.ndarray, y: Sequence[float] | np.ndarray):
    """The not-a-knot cubic spline through the points (x, y) (MATLAB ``spline``; ``scipy.interpolate.CubicSpline``
    with ``bc_type="not-a-knot"``): a function of a scalar returning a float, extrapolating with the end cubics.

    x (n,) strictly increasing, y (n,), n >= 2 (2 points: the line, 3: the parabola through them, as scipy does).
    Second derivatives M at the knots from the continuity of the first derivative at the interior knots and of the
    third derivative at the second and the second-to-last knot (de Boor, "A Practical Guide to Splines", Ch. IV).
    Raises EstimationError for fewer than 2 points or an x not strictly increasing."""
    xa, ya = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    n = xa.size
    if n < 2 or ya.shape != xa.shape or np.any(np.diff(xa) <= 0):
        raise EstimationError("a spline needs 2 or more points with strictly increasing x")
    if n == 3:  # not-a-knot through 3 points: one cubic piece with zero cubic term, the parabola
        c = np.polyfit(xa, ya, 2)
        return lambda v: float(np.polyval(c, float(v)))
    h = np.diff(xa)
    m: np.ndarray = np.zeros(n)
    if n > 3:
        a, b = np.zeros((n, n)), np.zeros(n)
        slope = np.diff(ya) / h
        for i in range(1, n - 1):
            a[i, i - 1:i + 2] = h[i - 1], 2.0 * (h[i - 1] + h[i]), h[i]
            b[i] = 6.0 * (slope[i] - slope[i - 1])
        a[0, :3] = h[1], -(h[0] + h[1]), h[0]
        a[-1, -3:] = h[-1], -(h[-2] + h[-1]), h[-2]
        m = np.linalg.solve(a, b)

    def value(v: float) -> float:
        v = float(v)
        i = int(np.clip(np.searchsorted(xa, v) - 1, 0, n - 2))
        hi, left, right = h[i], xa[i + 1] - v, v - xa[i]
        return float(m[i] * left ** 3 / (6.0 * hi) + m[i + 1] * right ** 3 / (6.0 * hi)
                     + (ya[i] / hi - m[i] * hi / 6.0) * left + (ya[i + 1] / hi - m[i + 1] * hi / 6.0) * right)
    return value


class _Table:
    """MATLAB ``spline``/``ppval`` of column ``column`` of a table given as rows against its first
    column; records out-of-range lookups in ``notes``."""

    def __init__(self, name: str, rows: Sequence[Sequence[float]], notes: list, column: int = 1):
        xa = np.array([r[0] for r in rows], float)
        ya = np.array([r[column] for r in rows], float)
        order = np.argsort(xa)
        self.name, self.x, self.notes = name, xa[order], notes
        self.spline = not_a_knot_spline(xa[order], ya[order])

    def __call__(self, value: float, what: str) -> float:
        if not (self.x[0] <= value <= self.x[-1]):
            self.notes.append(f"{what}: {self.name} extrapolated at {value:.4g} (table {self.x[0]:g}..{self.x[-1]:g})")
        return float(self.spline(value))


@dataclass(frozen=True)
class Geometry:
    """Bounding box, fluid density and projected areas ([NTNU-Thesis] Tables 1.1-1.5, App. A inputs).

    length_m (x), width_m (y), height_m (z): > 0, m. fluid_density_kg_m3: > 0. frontal_area_m2 (normal to x),
    side_area_m2 (normal to y), top_area_m2 (normal to z): projected areas, > 0, m^2; each at most its
    bounding rectangle is not enforced (the thesis's own inputs exceed it for some vehicles).
    Raises :class:`EstimationError` on a non-positive or non-finite value."""

    length_m: float
    width_m: float
    height_m: float
    fluid_density_kg_m3: float
    frontal_area_m2: float
    side_area_m2: float
    top_area_m2: float

    def __post_init__(self):
        for k, v in self.__dict__.items():
            if not (isinstance(v, (int, float)) and np.isfinite(v) and v > 0):
                raise EstimationError(f"{k} must be a finite number > 0, got {v!r}")

    @property
    def cp(self) -> tuple[float, float, float]:
        """(Cp_xy, Cp_yz, Cp_xz): top / (L W), frontal / (H W), side / (L H) ([NTNU-Thesis] Sec. 3.1.3)."""
        L, W, H = self.length_m, self.width_m, self.height_m
        return self.top_area_m2 / (L * W), self.frontal_area_m2 / (H * W), self.side_area_m2 / (L * H)


def added_mass_priors(g: Geometry, notes: Optional[list] = None) -> np.ndarray:
    """(6,) diagonal added mass, kg and kg m^2 ([NTNU-Thesis] App. A.1, Sec. 3.1.3 eqs. 3.2-3.4)."""
    notes = [] if notes is None else notes
    ca3d = _Table("added-mass 3D table", ADDED_MASS_3D, notes)
    ca2dt = _Table("added-mass 2D table (translation)", ADDED_MASS_2D, notes)
    ca2dr = _Table("added-mass 2D table (rotation)", ADDED_MASS_2D, notes, column=2)
    L, W, H, rho = g.length_m, g.width_m, g.height_m, g.fluid_density_kg_m3
    cxy, cyz, cxz = g.cp
    A = np.zeros(6)
    a = 0.5 * (H + W)                                        # averaged height/width (H3D = W3D)
    a11_3d = ca3d(L / a, "surge 3D") * L * a * a * rho * cyz**2 * cxz * cxy
    a2d = rho * ca2dt(W / L, "surge 2D") * np.pi * (0.5 * W) ** 2 * cyz**2 * cxz * cxy
    a11_strip = H * a2d
    lam = np.sqrt(a11_3d / a11_strip)
    A[0] = a11_strip * lam
    ca = ca2dt(L / W, "sway/heave 2D")
    ar = np.pi * (0.5 * L) ** 2
    A[1] = rho * ca * ar * cxz**2 * cxy * cyz * H * lam
    A[2] = rho * ca * ar * cxy**2 * cxz * cyz * W * lam
    cp3 = cyz * cxy * cxz
    # strip length, section sides (b / a, radius the larger side); rotations (eq. 3.4)
    for i, (length, b, a, what) in enumerate(((L, H, W, "roll 2D"), (W, L, H, "pitch 2D"),
                                              (H, W, L, "yaw 2D")), start=3):
        A[i] = length * rho * ca2dr(b / a, what) * np.pi * (0.5 * max(b, a)) ** 4 * cp3 * lam
    return A


def quadratic_damping_priors(g: Geometry, notes: Optional[list] = None) -> np.ndarray:
    """(6,) diagonal quadratic damping, kg/m and kg m^2 ([NTNU-Thesis] App. A.2, eqs. 3.6-3.10)."""
    notes = [] if notes is None else notes
    d2 = _Table("drag 2D table", DRAG_2D, notes)
    d3 = _Table("drag 3D table", DRAG_3D, notes)
    L, W, H, rho = g.length_m, g.width_m, g.height_m, g.fluid_density_kg_m3
    cxy, cyz, czx = g.cp
    a = 0.5 * (H + W)
    lam = d3(L / a, "surge 3D drag") / d2(L / W, "surge 2D drag")      # eq. 3.8
    BQ = np.zeros(6)
    BQ[0] = 0.5 * rho * d2(L / a, "surge drag") * H * W * cyz * lam      # eq. 3.7
    BQ[1] = 0.5 * rho * d2(W / H, "sway drag") * L * H * czx * lam
    BQ[2] = 0.5 * rho * d2(H / W, "heave drag") * L * W * cxy * lam

    def quadrants(dh, lh, cph, dv, lv, cpv, what):
        """2 horizontal + 2 vertical quadrants (eq. 3.10): half sizes dh, dv, lengths lh, lv."""
        fh = rho / 6.0 * d2(2.0 * dv / dh, what + " (h)") * dh * lh * cph * lam
        mh = fh * 0.75 * dh**3
        fv = rho / 6.0 * d2(2.0 * dh / dv, what + " (v)") * dv * lv * cpv * lam
        mv = fv * 0.75 * dv**3
        return 2.0 * mv + 2.0 * mh

    # roll: LD = W/(H/2) for the horizontal quadrants (half height), H/(W/2) for the vertical ones
    BQ[3] = quadrants(0.5 * H, L, czx, 0.5 * W, L, cxy, "roll drag")
    BQ[4] = quadrants(0.5 * H, W, cyz, 0.5 * L, W, cxy, "pitch drag")
    BQ[5] = quadrants(0.5 * W, H, cyz, 0.5 * L, H, czx, "yaw drag")
    return BQ


def linear_damping_priors(quadratic: Sequence[float] | np.ndarray, restoring_n_m_per_rad: Optional[float],
                          roll_inertia_kg_m2: Optional[float], pitch_inertia_kg_m2: Optional[float],
                          roll_added_kg_m2: float, pitch_added_kg_m2: float) -> list:
    """(6,) linear damping, kg/s and kg m^2/s ([NTNU-Thesis] eq. 3.18, App. A.2 "Linear Viscous Damping").

    Roll and pitch 2 zeta (I + A) sqrt(C / (I + A)) (:data:`ZETA_ROLL_PITCH`); surge, sway, heave
    :data:`LINEAR_TO_QUADRATIC_TRANSLATION` times the quadratic term;
    yaw BQ66 BL55 / BQ55. Without a restoring coefficient or rigid inertias, roll, pitch and yaw are None."""
    bq = [float(x) for x in quadratic]
    ratio, zeta = LINEAR_TO_QUADRATIC_TRANSLATION, ZETA_ROLL_PITCH
    bl: list = [ratio * bq[0], ratio * bq[1], ratio * bq[2], None, None, None]
    if restoring_n_m_per_rad and roll_inertia_kg_m2 and pitch_inertia_kg_m2:
        c = float(restoring_n_m_per_rad)
        i44, i55 = roll_inertia_kg_m2 + roll_added_kg_m2, pitch_inertia_kg_m2 + pitch_added_kg_m2
        bl[3] = 2.0 * zeta * i44 * np.sqrt(c / i44)
        bl[4] = 2.0 * zeta * i55 * np.sqrt(c / i55)
        bl[5] = bq[5] * bl[4] / bq[4]
    return bl


@dataclass(frozen=True)
class PriorInputs:
    """Optional rigid-body inputs of the linear roll/pitch damping ([NTNU-Thesis] App. A.2 ``I44 I55 A44 A55 C``).

    mass_kg: with ``bg_m``, gives C = m g BG and, when the inertias are None, the prism inertias of Sec. 3.1.1.
    bg_m: vertical distance from the CG up to the CB, m (> 0 for a stable vehicle).
    roll_inertia_kg_m2 / pitch_inertia_kg_m2: rigid I44 / I55 (default: prism formulas from mass_kg).
    roll_added_kg_m2 / pitch_added_kg_m2: A44 / A55 (default: the App. A.1 estimates).
    restoring_n_m_per_rad: C (default: m g BG). gravity_m_s2: g (default 9.81)."""

    mass_kg: Optional[float] = None
    bg_m: Optional[float] = None
    roll_inertia_kg_m2: Optional[float] = None
    pitch_inertia_kg_m2: Optional[float] = None
    roll_added_kg_m2: Optional[float] = None
    pitch_added_kg_m2: Optional[float] = None
    restoring_n_m_per_rad: Optional[float] = None
    gravity_m_s2: float = 9.81


def empirical_priors(g: Geometry, rigid: PriorInputs = PriorInputs()) -> dict[str, Any]:
    """The three 6-element prior vectors with their inputs, as one JSON-friendly dict.

    Returns ``{"added_mass": [6], "linear_damping": [6] (None where it cannot be computed), "quadratic_damping": [6],
    "units": UNITS, "inputs": {...}, "notes": [...]}``. Raises :class:`EstimationError` on invalid inputs."""
    notes: list = []
    A = added_mass_priors(g, notes)
    BQ = quadratic_damping_priors(g, notes)
    m = rigid.mass_kg
    i44, i55 = rigid.roll_inertia_kg_m2, rigid.pitch_inertia_kg_m2
    if m is not None:
        L, W, H = g.length_m, g.width_m, g.height_m
        if i44 is None:
            i44 = m / 12.0 * (W * W + H * H)          # [NTNU-Thesis] Sec. 3.1.1
            notes.append("roll inertia: solid prism m/12 (W^2 + H^2) (Sec. 3.1.1)")
        if i55 is None:
            i55 = m / 12.0 * (L * L + H * H)
            notes.append("pitch inertia: solid prism m/12 (L^2 + H^2) (Sec. 3.1.1)")
    c = rigid.restoring_n_m_per_rad
    if c is None and m is not None and rigid.bg_m is not None:
        c = m * rigid.gravity_m_s2 * rigid.bg_m         # [NTNU-Thesis] Sec. 3.1.2 (W = B)
    a44 = A[3] if rigid.roll_added_kg_m2 is None else rigid.roll_added_kg_m2
    a55 = A[4] if rigid.pitch_added_kg_m2 is None else rigid.pitch_added_kg_m2
    if c is not None and not c > 0:
        raise EstimationError(f"restoring coefficient must be > 0 (CB above CG), got {c}")
    BL = linear_damping_priors(BQ, c, i44, i55, a44, a55)
    if BL[3] is None:
        notes.append("roll, pitch, yaw linear damping need the restoring coefficient and rigid inertias "
                     "(--mass-kg with --bg-m, or --restoring-n-m-per-rad with the inertias)")
    return {
        "added_mass": [float(x) for x in A],
        "linear_damping": [None if x is None else float(x) for x in BL],
        "quadratic_damping": [float(x) for x in BQ],
        "units": UNITS,
        "inputs": {"length_m": g.length_m, "width_m": g.width_m, "height_m": g.height_m,
                   "fluid_density_kg_m3": g.fluid_density_kg_m3, "frontal_area_m2": g.frontal_area_m2,
                   "side_area_m2": g.side_area_m2, "top_area_m2": g.top_area_m2,
                   "roll_inertia_kg_m2": i44, "pitch_inertia_kg_m2": i55,
                   "roll_added_kg_m2": float(a44), "pitch_added_kg_m2": float(a55),
                   "restoring_n_m_per_rad": c},
        "notes": notes,
    }


def priors_from_config(cfg, frontal_area_m2: Optional[float] = None, side_area_m2: Optional[float] = None,
                       top_area_m2: Optional[float] = None) -> dict[str, Any]:
    """:func:`empirical_priors` from a :class:`~hindrax_common.config.VehicleConfig`.

    Uses vehicle.length_m/width_m/height_m, environment.water_density_kg_m3, vehicle.mass_kg,
    vehicle.inertia_kg_m2 (roll, pitch), environment.gravity_m_s2 and BG = z_CG - z_CB from
    vehicle.centre_of_gravity_frd_m / centre_of_buoyancy_frd_m (FRD, z down). The vehicle file has no
    projected areas: a missing area is the full bounding rectangle (solid prism, Cp = 1), noted in ``notes``."""
    v = cfg.vehicle
    L, W, H = float(v.length_m), float(v.width_m), float(v.height_m)
    rect = {"frontal": W * H, "side": L * H, "top": L * W}
    given = {"frontal": frontal_area_m2, "side": side_area_m2, "top": top_area_m2}
    areas = {k: (rect[k] if v is None else float(v)) for k, v in given.items()}
    g = Geometry(L, W, H, float(cfg.environment.water_density_kg_m3), areas["frontal"], areas["side"], areas["top"])
    inertia = list(v.inertia_kg_m2)
    zg = float(v.centre_of_gravity_frd_m[2])
    zb = float(v.centre_of_buoyancy_frd_m[2])
    out = empirical_priors(g, PriorInputs(mass_kg=float(v.mass_kg), bg_m=zg - zb, roll_inertia_kg_m2=float(inertia[0]),
                                          pitch_inertia_kg_m2=float(inertia[1]),
                                          gravity_m_s2=float(cfg.environment.gravity_m_s2)))
    missing = [k for k, v in given.items() if v is None]
    if missing:
        out["notes"].insert(0, f"projected area(s) {', '.join(missing)} not given: bounding rectangle "
                               "(solid prism, Cp = 1), an upper bound for an open frame")
    out["source"] = getattr(cfg, "source", "")
    return out
