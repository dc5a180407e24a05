"""Tests of hindrax_onboard.estimation.free_decay against [Hindrax-AM] (Tables 3-6) and physics.

Table checks: every printed number is compared with the value computed from the printed
inputs of its own equation: m_ad eq. 7 and eq. 5 from (omega_d, zeta, k_eq, m_b = 0.39 kg);
c (eq. 6) from (zeta, k_eq, m_b + printed m_ad eq. 5); error % (eq. 11) from the two printed
added masses; KC (eq. 9) from A and D = V^(1/3) of the 0.00056 m^3 model. The tolerance is the
printed rounding: the computed value is evaluated over the box of inputs within half a unit of
their last printed digit, widened by half a unit of the printed output's last digit. Cells where
the paper disagrees with its own inputs beyond that are listed in HINDRAX_AM_DISAGREEMENTS with the
value the equations give (hand arithmetic in the comment); the test asserts both that our code
gives that value and that the printed value lies outside the rounding interval, so the
discrepancy stays documented instead of being absorbed by a loose tolerance.
"""

import itertools
import math

import numpy as np
import pytest

from hindrax_onboard.estimation.free_decay import (
    FreeDecayResult,
    added_mass_error_percent,
    added_mass_exact,
    added_mass_simplified,
    analyse_free_decay,
    damping_coefficient,
    damping_ratio_from_log_decrement,
    displacement_from_acceleration,
    find_release_index,
    inertia_coefficient,
    keulegan_carpenter,
    log_decrement,
    natural_frequency,
)
from hindrax_onboard.estimation.least_squares import EstimationError

MODEL_MASS_KG = 0.39          # [Hindrax-AM] section 2
MODEL_VOLUME_M3 = 0.00056     # [Hindrax-AM] section 2
MODEL_LENGTH_M = MODEL_VOLUME_M3 ** (1 / 3)   # 0.0824 m, [Hindrax-AM] section 4
PROTOTYPE_VOLUME_M3 = 0.0153  # [Hindrax-AM] section 2
RHO = 1000.0                  # [Hindrax-AM] eq. 12 text

# (table, direction, A mm, k_eq, omega_d, zeta, c, m_ad eq7, m_ad eq5, error %, KC) as printed
HINDRAX_AM_ROWS = [
    ("3", "surge", "4", 1127.7, "36.7824", "0.0713", "4.35", "0.4435", "0.4401", "0.77", "0.3"),
    ("3", "sway", "5", 1127.7, "31.7580", "0.1155", "8.14", "0.7281", "0.7132", "2.09", "0.38"),
    ("4", "heave", "6", 1127.7, "30.3976", "0.0604", "4.47", "0.8304", "0.8260", "0.53", "0.46"),
    ("4", "heave", "20", 1127.7, "30.1326", "0.1154", "8.56", "0.8454", "0.8289", "1.99", "1.52"),
    ("4", "heave", "25", 1127.7, "29.966", "0.172", "12.75", "0.8658", "0.8287", "4.48", "1.9"),
    ("5", "heave", "20", 659.9, "23.1477", "0.1328", "7.57", "0.8416", "0.8198", "2.66", "1.52"),
    ("5", "heave", "25", 659.9, "23.0504", "0.1656", "9.48", "0.8520", "0.8179", "4.17", "1.9"),
    ("5", "heave", "30", 659.9, "23.0629", "0.1518", "8.69", "0.8506", "0.8220", "3.48", "2.28"),
    ("5", "heave", "35", 659.9, "22.9846", "0.1702", "9.77", "0.8591", "0.8229", "4.4", "2.66"),
    ("5", "heave", "40", 659.9, "23.0505", "0.1613", "9.23", "0.852", "0.8197", "3.94", "3.05"),
    ("5", "heave", "45", 659.9, "22.8966", "0.1992", "11.48", "0.8687", "0.8187", "6.1", "3.43"),
]
COLUMNS = ("damping", "m7", "m5", "error", "kc")

# Printed cells that disagree with their own inputs beyond rounding.
# key: (table, direction, A mm, column) -> value given by the paper's equations.
HINDRAX_AM_DISAGREEMENTS = {
    # Table 3 surge: eq. 5 = 1127.7 (1 - 0.0713^2) / 36.7824^2 - 0.39 = 0.82928 - 0.39 = 0.4393,
    # printed 0.4401 (the printed eq. 7 value 0.4435 matches; eq. 11 on the printed masses gives
    # the printed 0.77 %, eq. 11 on the computed masses would give 0.96 %).
    ("3", "surge", "4", "m5"): 0.4393,
    # Table 3 surge: eq. 6 = 2 * 0.0713 * sqrt(1127.7 * (0.39 + 0.4401)) = 4.363, printed 4.35.
    ("3", "surge", "4", "damping"): 4.363,
    # Table 4 heave 20 mm: 1127.7 / 30.1326^2 - 0.39 = 0.8520 (printed 0.8454) and eq. 5 gives
    # 0.8355 (printed 0.8289). Both printed masses are 0.0066 kg lower, as if omega_d were
    # 30.213 rad/s instead of the printed 30.1326; c and the error % of the row are consistent
    # with the printed masses.
    ("4", "heave", "20", "m7"): 0.8520,
    ("4", "heave", "20", "m5"): 0.8355,
    # Table 5 (k_eq = 659.9 N/m), damping column: the printed c equals eq. 6 evaluated with the
    # eq. 7 total mass k/omega_d^2 (i.e. c = 2 zeta k / omega_d), not with m_b + m_ad(eq. 5) as
    # the text prescribes (and as Tables 3-4 do). Eq. 6 with the printed eq. 5 mass, e.g. 20 mm:
    # 2 * 0.1328 * sqrt(659.9 * (0.39 + 0.8198)) = 7.505 (printed 7.57 = 2 * 0.1328 * 659.9 /
    # 23.1477).
    ("5", "heave", "20", "damping"): 7.505,
    ("5", "heave", "25", "damping"): 9.351,
    ("5", "heave", "30", "damping"): 8.586,
    ("5", "heave", "35", "damping"): 9.630,
    ("5", "heave", "40", "damping"): 9.115,
    ("5", "heave", "45", "damping"): 11.252,
    # Table 5 45 mm: 659.9 (1 - 0.1992^2) / 22.8966^2 - 0.39 = 0.81879, printed 0.8187
    # (truncated; the input rounding moves it by at most 3e-5).
    ("5", "heave", "45", "m5"): 0.81879,
    # KC column: 2 pi 0.030 / 0.08243 = 2.287 and 2 pi 0.035 / 0.08243 = 2.668 are printed
    # truncated as 2.28 and 2.66 (other rows, e.g. 0.457 -> 0.46, are rounded).
    ("5", "heave", "30", "kc"): 2.287,
    ("5", "heave", "35", "kc"): 2.668,
}


def _half_ulp(printed: str) -> float:
    decimals = len(printed.split(".")[1]) if "." in printed else 0
    return 0.5 * 10.0 ** (-decimals)


def _box(*printed):
    """Corners of the rounding box of printed numbers (strings)."""
    return itertools.product(*[(float(p) - _half_ulp(p), float(p) + _half_ulp(p))
                               for p in printed])


def _cell(column, row, exact=False):
    """Computed cell: exact=True -> at the printed inputs; else (min, max) over their box."""
    table, direction, a_mm, k, wd_s, z_s, c_s, m7_s, m5_s, err_s, kc_s = row
    if column in ("m7", "m5"):
        def f(wd, z):
            if column == "m7":
                return added_mass_simplified(k, wd, MODEL_MASS_KG)
            return added_mass_exact(k, wd, z, MODEL_MASS_KG)
        args = (wd_s, z_s)
    elif column == "damping":
        def f(z, m5):
            return damping_coefficient(z, k, MODEL_MASS_KG + m5)
        args = (z_s, m5_s)
    elif column == "error":
        def f(m7, m5):
            return added_mass_error_percent(m7, m5)
        args = (m7_s, m5_s)
    else:  # kc: A is an imposed value (Table 2), D = V^(1/3)
        def f():
            return keulegan_carpenter(float(a_mm) / 1000.0, MODEL_LENGTH_M)
        args = ()
    if exact:
        return f(*[float(a) for a in args])
    vals = [f(*corner) for corner in _box(*args)]
    return min(vals), max(vals)


CASES = [(row, col) for row in HINDRAX_AM_ROWS for col in COLUMNS]


@pytest.mark.parametrize("row,column", CASES,
                         ids=[f"T{r[0]}-{r[1]}-{r[2]}mm-{c}" for r, c in CASES])
def test_hindrax_am_table_cells(row, column):
    printed = dict(zip(COLUMNS, row[6:]))[column]
    lo, hi = _cell(column, row)
    tol = _half_ulp(printed)
    key = (row[0], row[1], row[2], column)
    computed = _cell(column, row, exact=True)
    if key in HINDRAX_AM_DISAGREEMENTS:
        expected = HINDRAX_AM_DISAGREEMENTS[key]
        assert computed == pytest.approx(expected, abs=1e-3 * max(1.0, abs(expected)))
        # the printed cell really is outside its rounding interval (documented disagreement)
        assert not (lo - tol <= float(printed) <= hi + tol)
    else:
        assert lo - tol <= float(printed) <= hi + tol, (computed, printed)


def test_hindrax_am_table6_from_printed_added_masses():
    """[Hindrax-AM] Table 6 from the seventh column of Tables 3-5 (eqs. 8 and 12)."""
    surge = inertia_coefficient(0.4401, MODEL_VOLUME_M3, RHO)
    sway = inertia_coefficient(0.7132, MODEL_VOLUME_M3, RHO)
    heave_m = np.array([float(r[8]) for r in HINDRAX_AM_ROWS if r[1] == "heave"])
    assert heave_m.size == 9
    # section 5: "The mean was 0.8227, and the standard deviation was +-0.0042 ... 0.51 %"
    assert heave_m.mean() == pytest.approx(0.8227, abs=5e-5)
    assert heave_m.std(ddof=1) == pytest.approx(0.0042, abs=5e-5)
    assert 100 * heave_m.std(ddof=1) / heave_m.mean() == pytest.approx(0.51, abs=0.005)
    heave = inertia_coefficient(heave_m.mean(), MODEL_VOLUME_M3, RHO)
    heave_std = heave_m.std(ddof=1) / (RHO * MODEL_VOLUME_M3)
    assert surge == pytest.approx(0.79, abs=0.005)
    assert sway == pytest.approx(1.27, abs=0.005)
    assert heave == pytest.approx(1.4692, abs=5e-5)
    assert heave_std == pytest.approx(0.0075, abs=5e-5)
    def prototype_added_mass(c_m, volume_m3, rho):  # eq. 12
        return c_m * rho * volume_m3

    # eq. 12; heave agrees with the unrounded C_M
    assert prototype_added_mass(heave, PROTOTYPE_VOLUME_M3, RHO) == pytest.approx(22.48, abs=0.005)
    # Disagreement: with the unrounded C_M, surge 0.7859 * 15.3 = 12.02 kg and sway
    # 1.2736 * 15.3 = 19.49 kg; the printed 12.08 and 19.43 follow from C_M rounded to
    # 0.79 and 1.27 (0.79 * 15.3 = 12.087, printed truncated; 1.27 * 15.3 = 19.431).
    assert prototype_added_mass(surge, PROTOTYPE_VOLUME_M3, RHO) == pytest.approx(12.02, abs=0.005)
    assert prototype_added_mass(sway, PROTOTYPE_VOLUME_M3, RHO) == pytest.approx(19.49, abs=0.005)
    assert prototype_added_mass(0.79, PROTOTYPE_VOLUME_M3, RHO) == pytest.approx(12.08, abs=0.01)
    assert prototype_added_mass(1.27, PROTOTYPE_VOLUME_M3, RHO) == pytest.approx(19.43, abs=0.005)


def test_hindrax_am_reynolds_range_of_heave_rows():
    """Section 4: 0.14e5 <= Re <= 0.67e5 with Re = U_m V^(1/3) / nu, nu = 1.01e-6 m^2/s.

    U_m of a linear oscillator released from rest at A: v = -A (wn^2/wd) e^(-s t) sin(wd t),
    maximal at tan(wd t) = wd / s, where |v| = A wn exp(-s t*) (independent physics). The paper's
    U_m is measured, so we only require agreement within 5 %: the heave rows span
    0.136e5 (6 mm) to 0.65e5 (45 mm). (The surge and sway rows would give about 0.11e5, below
    the printed lower bound.)
    """
    from hindrax_onboard.estimation.drag_coefficient import reynolds_number

    res = []
    for row in HINDRAX_AM_ROWS:
        if row[1] != "heave":
            continue
        a_m, wd, z = float(row[2]) / 1000, float(row[4]), float(row[5])
        wn = wd / math.sqrt(1 - z * z)
        s = z * wn
        t_star = math.atan2(wd, s) / wd
        res.append(reynolds_number(a_m * wn * math.exp(-s * t_star), MODEL_LENGTH_M))
    assert min(res) == pytest.approx(0.14e5, rel=0.05)
    assert max(res) == pytest.approx(0.67e5, rel=0.05)


def test_closed_form_relations():
    # eq. 3 both ways
    for z in (0.0, 0.06, 0.2, 0.5):
        assert damping_ratio_from_log_decrement(2 * math.pi * z / math.sqrt(1 - z * z)) == \
            pytest.approx(z, abs=1e-12)
    # eq. 2 and eq. 4: omega_n^2 (m_b + m_ad,eq5) = k_eq
    wd, z, k, mb = 25.0, 0.15, 700.0, 0.4
    wn = natural_frequency(wd, z)
    assert wn == pytest.approx(wd / math.sqrt(1 - z * z))
    assert wn**2 * (mb + added_mass_exact(k, wd, z, mb)) == pytest.approx(k, rel=1e-12)
    # eq. 7 with the measured frequency; eq. 11 sign: simplified > exact
    m7 = added_mass_simplified(k, wd, mb)
    assert m7 == pytest.approx(k / wd**2 - mb)
    assert added_mass_error_percent(m7, added_mass_exact(k, wd, z, mb)) > 0
    # eq. 6 equals 2 zeta m omega_n
    m = mb + added_mass_exact(k, wd, z, mb)
    assert damping_coefficient(z, k, m) == pytest.approx(2 * z * m * wn, rel=1e-12)
    assert keulegan_carpenter(0.02, 0.0824) == pytest.approx(2 * math.pi * 0.02 / 0.0824)
    assert log_decrement([1.0, 0.5, 0.25]) == pytest.approx(math.log(2.0))


@pytest.mark.parametrize("bad", [
    lambda: log_decrement([1.0]),
    lambda: log_decrement([1.0, -0.5]),
    lambda: damping_ratio_from_log_decrement(-0.1),
    lambda: natural_frequency(10.0, 1.0),
    lambda: added_mass_exact(-1.0, 10.0, 0.1, 0.39),
    lambda: added_mass_error_percent(1.0, 0.0),
    lambda: keulegan_carpenter(0.01, 0.0),
    lambda: find_release_index(np.zeros(10)),
])
def test_closed_form_errors(bad):
    with pytest.raises(EstimationError):
        bad()


# --------------------------------------------------------------------------------------
# Synthetic free-decay records
# --------------------------------------------------------------------------------------
FS_HZ = 330.0   # [Hindrax-AM] section 4
DURATION_S = 10.0


def damped_record(k, mb, mad, zeta, amplitude_m, noise_m_s2=0.025, bias_m_s2=0.15,
                  hold_s=0.5, seed=0):
    """Analytic linear oscillator released from rest at amplitude_m after hold_s seconds.

    x = A e^(-s t)(cos wd t + (s/wd) sin wd t), v = -A (wn^2/wd) e^(-s t) sin wd t,
    a = -2 s v - wn^2 x. Noise ~ ICM-20948 (230 ug/sqrt(Hz) over ~110 Hz: ~0.025 m/s^2 rms).
    """
    rng = np.random.default_rng(seed)
    wn = math.sqrt(k / (mb + mad))
    s = zeta * wn
    wd = wn * math.sqrt(1 - zeta**2)
    t = np.arange(0.0, DURATION_S, 1.0 / FS_HZ)
    tt = np.clip(t - hold_s, 0.0, None)
    e = np.exp(-s * tt)
    x = amplitude_m * e * (np.cos(wd * tt) + s / wd * np.sin(wd * tt))
    v = -amplitude_m * (wn**2 / wd) * e * np.sin(wd * tt)
    a = -2 * s * v - wn**2 * x
    a[t < hold_s] = 0.0
    x[t < hold_s] = amplitude_m
    return t, a + bias_m_s2 + rng.normal(0.0, noise_m_s2, t.size), x, v, wd


@pytest.mark.parametrize("k,mad,zeta,amp,sign", [
    (659.9, 0.82, 0.15, 0.030, 1.0),     # Table 5 like
    (1127.7, 0.83, 0.06, 0.006, -1.0),   # Table 4 first row like, released downwards
    (1127.7, 0.44, 0.07, 0.004, 1.0),    # Table 3 surge like
    (659.9, 0.82, 0.20, 0.045, 1.0),     # heaviest damping in Table 5
])
def test_synthetic_free_decay_recovers_parameters(k, mad, zeta, amp, sign):
    for seed in range(3):
        t, a, x, v, wd = damped_record(k, MODEL_MASS_KG, mad, zeta, sign * amp, seed=seed)
        r = analyse_free_decay(t, a, k, MODEL_MASS_KG, MODEL_VOLUME_M3)
        assert isinstance(r, FreeDecayResult)
        assert r.omega_d_rad_s == pytest.approx(wd, rel=0.005)
        assert r.zeta == pytest.approx(zeta, rel=0.10)
        assert r.added_mass_kg == pytest.approx(mad, rel=0.03)
        assert r.first_peak_displacement_m == pytest.approx(amp, rel=0.03)
        assert r.kc == pytest.approx(2 * math.pi * amp / MODEL_LENGTH_M, rel=0.03)
        # release found within two samples of the true 0.5 s
        assert abs(r.t_s[0] - 0.5) <= 2.0 / FS_HZ
        assert r.n_periods >= 2
        # the acceleration-fit cross-check agrees as well
        assert r.omega_d_fit_rad_s == pytest.approx(wd, rel=0.005)
        assert r.zeta_fit == pytest.approx(zeta, rel=0.10)
        # Re from the peak speed of the oscillator (see test_hindrax_am_reynolds_range...)
        assert r.max_velocity_m_s == pytest.approx(np.max(np.abs(v)), rel=0.03)
        # simplified mass over-estimates (eq. 11 error positive and grows with zeta)
        assert r.added_mass_simplified_kg > r.added_mass_kg
        assert r.added_mass_error_percent == pytest.approx(
            100 * (k / wd**2 - k * (1 - zeta**2) / wd**2) / mad, rel=0.15)


def test_free_decay_result_to_dict_and_envelope():
    t, a, x, v, wd = damped_record(659.9, MODEL_MASS_KG, 0.82, 0.15, 0.03)
    r = analyse_free_decay(t, a, 659.9, MODEL_MASS_KG, MODEL_VOLUME_M3)
    d = r.to_dict()
    for key in ("omega_d_rad_s", "zeta", "log_decrement", "omega_n_rad_s", "added_mass_kg",
                "added_mass_simplified_kg", "added_mass_error_percent", "damping_n_s_per_m",
                "c_m", "kc", "reynolds", "first_peak_displacement_m", "peaks"):
        assert key in d
    assert d["c_m"] == pytest.approx(d["added_mass_kg"] / (RHO * MODEL_VOLUME_M3))
    assert isinstance(d["peaks"], list) and len(d["peaks"]) == r.n_periods + 1
    assert "t_s" not in d
    # envelope passes through the peak amplitudes (exponential decay of a linear oscillator)
    env_at_peaks = r.envelope_m[r.peaks]
    np.testing.assert_allclose(env_at_peaks, r.peak_amplitudes_m, rtol=0.05)
    # the displacement follows the true one (after the release)
    x_true = x[r.release_index:]
    assert np.max(np.abs(r.displacement_m[:330] - x_true[:330])) < 0.05 * 0.03


def test_displacement_from_acceleration_noise_free():
    """Bias removal and double integration reproduce an analytic decay.

    Without noise the only errors are the trapezoid discretisation (O(dt^2) per step, about
    1e-4 m/s of velocity offset at 330 Hz for a 18 m/s^2 release) integrated over 10 s, and
    the high-pass leakage near the release: we require < 1 % of the peak velocity and
    < 2.5 % of A for the displacement, with and without the high-pass.
    """
    t, a, x, v, wd = damped_record(1127.7, MODEL_MASS_KG, 0.83, 0.1, 0.02, noise_m_s2=0.0,
                                   bias_m_s2=0.3, hold_s=0.0)
    for hp in (None, 0.1 * wd / (2 * math.pi)):
        disp, vel = displacement_from_acceleration(t, a, highpass_hz=hp)
        assert np.max(np.abs(vel - v)) < 0.01 * np.max(np.abs(v))
        # reference about the record mean, like the function (equilibrium up to the small mean)
        assert np.max(np.abs(disp - (x - x.mean()))) < 0.025 * 0.02
    # without bias removal the 0.3 m/s^2 bias integrates to 0.3 * 10^2 / 2 = 15 m of drift
    disp, _ = displacement_from_acceleration(t, a, remove_bias=False)
    assert np.ptp(disp) > 5.0


def test_noise_only_record_is_rejected():
    rng = np.random.default_rng(5)
    t = np.arange(0, 10, 1 / FS_HZ)
    with pytest.raises(EstimationError):
        analyse_free_decay(t, rng.normal(0, 0.03, t.size), 1127.7, 0.39, 0.00056)


@pytest.mark.parametrize("t,a", [
    (np.arange(5.0), np.ones(4)),
    (np.array([0.0, 1.0, 1.0, 2.0] * 5), np.ones(20)),
    (np.arange(20.0), np.r_[np.ones(19), np.nan]),
])
def test_analyse_free_decay_bad_input(t, a):
    with pytest.raises(EstimationError):
        analyse_free_decay(t, a, 1127.7, 0.39, 0.00056)
    with pytest.raises(ValueError):   # EstimationError is a ValueError
        analyse_free_decay(t, a, 1127.7, 0.39, 0.00056)
