"""Virtual pool, vehicle model and integration: checked against physics, not against the code.

Expected values come from the configured coefficients through closed-form physics (steady speed of
k_q|v|v + k_l v + b = F, Newton's F = (m + m_a) a, first-order lag, Archimedes) or from independent
formulations (Fossen eq. 2.23 written out in Euler angles, Newton-Euler eqs. 2.4-2.5, energy conservation).

Where a test needs a single DOF to move alone, the configuration is made *neutrally buoyant with the CB at
the CG* (mass = rho V, net buoyancy 0, r_b = 0): then g(eta) = 0 identically, and a pure force (moment)
at the CG along (about) a principal axis of a vehicle with diagonal M_A excites no other DOF (C_RB nu and
C_A nu vanish for motion along a single axis), so the motion is exactly 1-DOF. Heave instead keeps the real
buoyancy, which appears as the bias b = B - W of [Hindrax-Drag] eq. 2 ([Hindrax-Drag] §5).
"""
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hindrax_common.base import frames
from hindrax_common.config import DOFS, default_config_path, load_config
from hindrax_sim import model as mdl
from hindrax_sim.simulator import PulseWidthError, Simulator
from hindrax_sim.thrusters import Thrusters


@pytest.fixture(scope="module")
def cfg():
    return load_config(default_config_path())


@pytest.fixture(scope="module")
def neutral_cfg(cfg):
    rho, vol = cfg.environment.water_density_kg_m3, cfg.vehicle.displaced_volume_m3
    return cfg.with_overrides({"vehicle.mass_kg": rho * vol, "vehicle.net_buoyancy_n": 0.0,
                               "vehicle.centre_of_buoyancy_frd_m": [0.0, 0.0, 0.0]})


@pytest.fixture(scope="module")
def coupled_cfg(cfg):
    """CG offset, products of inertia and symmetric added-mass couplings (all allowed by the schema)."""
    coupling = np.zeros((6, 6))
    for (i, j), val in {(0, 4): 0.8, (1, 3): -0.6, (1, 5): 0.5, (2, 4): 0.4, (3, 5): 0.05}.items():
        coupling[i, j] = coupling[j, i] = val
    return cfg.with_overrides({"vehicle.centre_of_gravity_frd_m": [0.01, -0.02, 0.03],
                               "vehicle.products_of_inertia_kg_m2": [0.01, 0.02, -0.015],
                               "hydrodynamics.added_mass_coupling": coupling.reshape(-1).tolist()})


def steady_speed(kq, kl, net_force):
    """Positive root s of kq s^2 + kl s = net_force (net_force > 0)."""
    return (-kl + math.sqrt(kl * kl + 4.0 * kq * net_force)) / (2.0 * kq)


def random_state(rng, position=(5.0, 3.0, 0.9)):
    q = Rotation.from_euler("ZYX", rng.uniform([-3, -0.6, -0.6], [3, 0.6, 0.6])).as_quat()
    nu = rng.uniform(-1, 1, 6) * np.array([0.5, 0.5, 0.5, 0.8, 0.8, 0.8])
    return np.concatenate([position, q, nu])


# ----------------------------------------------------------------------------------- equations, matrix form
def coriolis_rigid_body(mass_kg: float, r_g_m, inertia_o_kg_m2, nu) -> np.ndarray:
    """C_RB(nu) (6x6), coordinate-free form (docs/identification.md, Fossen 2011).

    C_RB = [0, -m S(v) - m S(S(w) r_g); -m S(v) - m S(S(w) r_g), m S(S(v) r_g) - S(I_o w)],
    v = nu[:3] (m/s), w = nu[3:] (rad/s), r_g (3,) in m, inertia_o_kg_m2 (3, 3) about CO.
    """
    nu = np.asarray(nu, dtype=float)
    v, w = nu[:3], nu[3:]
    r_g = np.asarray(r_g_m, dtype=float)
    i_o = np.asarray(inertia_o_kg_m2, dtype=float)
    off = -mass_kg * mdl.skew(v) - mass_kg * mdl.skew(mdl.skew(w) @ r_g)
    lower = mass_kg * mdl.skew(mdl.skew(v) @ r_g) - mdl.skew(i_o @ w)
    return np.block([[np.zeros((3, 3)), off], [off, lower]])


def coriolis_added_mass(added_mass, nu) -> np.ndarray:
    """C_A(nu) (6x6) from the positive added-mass matrix M_A (6x6): [0, -S(a1); -S(a1), -S(a2)],
    a = M_A nu.

    Fossen 2011; equals docs/identification.md §1.A, [NTNU-Thesis] eq. 2.83 for a diagonal
    M_A = -diag(X_udot ... N_rdot).
    """
    a = np.asarray(added_mass, dtype=float) @ np.asarray(nu, dtype=float)
    s1, s2 = mdl.skew(a[:3]), mdl.skew(a[3:])
    return np.block([[np.zeros((3, 3)), -s1], [-s1, -s2]])


def generalized_forces(model, state, tau) -> dict[str, np.ndarray]:
    """Each term of the equations of motion at ``state`` (13,) and ``tau`` (6,) in matrix form, (6,)
    each: C_RB nu, C_A nu, D(nu) nu, g(eta) with the free-surface buoyancy, and nu_dot =
    (M_RB + M_A)^-1 (tau - the others): the reference the model's scalar fast path is checked
    against."""
    s = np.asarray(state, dtype=float)
    nu = s[7:13]
    r = mdl.rotation_matrix_from_quaternion(s[3:7])
    out = {
        "coriolis_rigid_body":
            coriolis_rigid_body(model.mass_kg, model.r_g_m, model.inertia_o_kg_m2, nu) @ nu,
        "coriolis_added_mass": coriolis_added_mass(model.added_mass_matrix, nu) @ nu,
        "damping": mdl.damping_vector(nu, model.damping_linear_positive,
                                      model.damping_linear_negative,
                                      model.damping_quadratic_positive,
                                      model.damping_quadratic_negative),
        "restoring": mdl.restoring_vector(r, model.weight_n,
                                          model.buoyancy_n * model.buoyancy_fraction(s),
                                          model.r_g_m, model.r_b_m),
    }
    out["nu_dot"] = model.mass_matrix_inverse @ (np.asarray(tau, dtype=float) - sum(out.values()))
    return out


def test_fast_path_equals_matrix_form(coupled_cfg):
    """The scalar fast path equals M^-1 (tau - C_RB nu - C_A nu - D nu - g) and the kinematics eta_dot = J nu."""
    model = mdl.VehicleModel(coupled_cfg)
    rng = np.random.default_rng(3)
    for _ in range(20):
        s = random_state(rng)
        tau = rng.normal(0, 10, 6)
        d = model.derivative(s, tau)
        terms = generalized_forces(model, s, tau)
        assert np.allclose(d[7:], terms["nu_dot"], rtol=1e-10, atol=1e-12)
        r = Rotation.from_quat(s[3:7])
        assert np.allclose(d[:3], r.apply(s[7:10]), atol=1e-12)
        # quaternion rate: body angular velocity recovered from q_dot = 1/2 q (x) [0, w]
        q = s[3:7]
        qd = d[3:7]
        x, y, z, w = q
        # 2 q* (x) q_dot, vector part = body angular velocity
        omega = 2.0 * np.array([w * qd[0] - x * qd[3] - y * qd[2] + z * qd[1],
                                w * qd[1] - y * qd[3] - z * qd[0] + x * qd[2],
                                w * qd[2] - z * qd[3] - x * qd[1] + y * qd[0]])
        assert np.allclose(omega, s[10:13], atol=1e-12)


def test_coriolis_rigid_body_is_newton_euler(coupled_cfg):
    """C_RB(nu) nu (coordinate-free form) reproduces the Newton-Euler terms of [T] eqs. 2.4-2.5."""
    m = coupled_cfg.vehicle.mass_kg
    r_g = coupled_cfg.vehicle.centre_of_gravity_frd_m
    i_o = mdl.rigid_body_mass_matrix(m, r_g, coupled_cfg.inertia_matrix_kg_m2)[3:, 3:]
    rng = np.random.default_rng(5)
    for _ in range(20):
        nu = rng.normal(0, 1, 6)
        v, w = nu[:3], nu[3:]
        expected = np.concatenate([m * (np.cross(w, v) + np.cross(w, np.cross(w, r_g))),
                                   m * np.cross(r_g, np.cross(w, v)) + np.cross(w, i_o @ w)])
        c = coriolis_rigid_body(m, r_g, i_o, nu)
        assert np.allclose(c @ nu, expected, atol=1e-12)
        assert np.allclose(c, -c.T)  # skew-symmetric: does no work
        ca = coriolis_added_mass(coupled_cfg.added_mass_matrix, nu)
        assert np.allclose(ca, -ca.T)


def test_parallel_axis_inertia(coupled_cfg):
    """I_o = I_cg + m (|r|^2 I - r r^T): the inertia about CO grows by the parallel-axis term."""
    m, r = coupled_cfg.vehicle.mass_kg, np.asarray(coupled_cfg.vehicle.centre_of_gravity_frd_m)
    mrb = mdl.rigid_body_mass_matrix(m, r, coupled_cfg.inertia_matrix_kg_m2)
    expected = coupled_cfg.inertia_matrix_kg_m2 + m * (r @ r * np.eye(3) - np.outer(r, r))
    assert np.allclose(mrb[3:, 3:], expected)
    assert np.allclose(mrb[:3, :3], m * np.eye(3))
    assert np.allclose(mrb, mrb.T)


def restoring_vector_euler(roll_rad: float, pitch_rad: float, weight_n: float,
                           buoyancy_n: float, r_g_m, r_b_m) -> np.ndarray:
    """g(eta) (6,) written out in Euler angles, Fossen eq. 2.23 as printed in docs/identification.md
    §1.A: the independent formulation :func:`restoring_vector` is checked against (rad, N, r_g and
    r_b in m, FRD)."""
    xg, yg, zg = r_g_m
    xb, yb, zb = r_b_m
    w, b = weight_n, buoyancy_n
    sph, cph = math.sin(roll_rad), math.cos(roll_rad)
    sth, cth = math.sin(pitch_rad), math.cos(pitch_rad)
    return np.array([
        (w - b) * sth,
        -(w - b) * cth * sph,
        -(w - b) * cth * cph,
        -(yg * w - yb * b) * cth * cph + (zg * w - zb * b) * cth * sph,
        (zg * w - zb * b) * sth + (xg * w - xb * b) * cth * cph,
        -(xg * w - xb * b) * cth * sph - (yg * w - yb * b) * sth,
    ])


@pytest.mark.parametrize("roll,pitch", [(0.0, 0.0), (0.3, 0.0), (0.0, -0.4), (0.5, 0.7), (-1.2, 0.2)])
def test_restoring_matches_fossen_eq_2_23(cfg, roll, pitch):
    r_g, r_b = np.array([0.01, -0.02, 0.03]), np.array([0.005, 0.01, -0.03])
    rot = Rotation.from_euler("ZYX", [0.7, pitch, roll]).as_matrix()
    got = mdl.restoring_vector(rot, cfg.weight_n, cfg.buoyancy_n, r_g, r_b)
    expected = restoring_vector_euler(roll, pitch, cfg.weight_n, cfg.buoyancy_n, r_g, r_b)
    assert np.allclose(got, expected, atol=1e-12)


def test_restoring_physics(cfg):
    """Level: net buoyancy B - W pushes up (g_z = W - B on the left side); rolled: the CB above the CG rights."""
    w, b = cfg.weight_n, cfg.buoyancy_n
    r_b = cfg.vehicle.centre_of_buoyancy_frd_m
    g = mdl.restoring_vector(np.eye(3), w, b, np.zeros(3), r_b)
    assert g[2] == pytest.approx(-(w - b)) and b - w == pytest.approx(0.785, abs=0.001)  # [Hindrax-Drag] §5
    rot = Rotation.from_euler("x", 0.2).as_matrix()
    g = mdl.restoring_vector(rot, w, b, np.zeros(3), r_b)
    # righting moment K = -g_4 = -B * BG * sin(phi) (BG = 0.03 m: CB above CG)
    assert -g[3] == pytest.approx(-b * 0.03 * math.sin(0.2), rel=1e-9)


def test_euler_output_matches_frames_module(cfg):
    rng = np.random.default_rng(11)
    for _ in range(10):
        q = Rotation.from_euler("ZYX", rng.uniform([-3, -1.2, -3], [3, 1.2, 3])).as_quat()
        ours = mdl.euler_from_rotation_matrix(mdl.rotation_matrix_from_quaternion(q))
        assert np.allclose(ours, frames.euler_ned_from_quaternion(q), atol=1e-9)


def test_energy_conserved_without_damping_and_restoring(neutral_cfg):
    """No damping, no restoring, no thrust: the kinetic energy 1/2 nu^T M nu of a tumbling vehicle is constant."""
    zero = {f"hydrodynamics.{d}.{k}": 0.0 for d in DOFS for k in
            (["linear_damping_positive_kg_s", "linear_damping_negative_kg_s", "quadratic_damping_positive_kg_m",
              "quadratic_damping_negative_kg_m"] if d == "heave" else
             ["linear_damping_kg_s", "quadratic_damping_kg_m"] if d in ("surge", "sway") else
             ["linear_damping_kg_m2_s", "quadratic_damping_kg_m2"])}
    c = neutral_cfg.with_overrides({**zero, "vehicle.products_of_inertia_kg_m2": [0.01, 0.02, -0.015]})
    sim = Simulator(c, pool=False, sensors=False)
    nu0 = [0.3, -0.2, 0.1, 0.6, -0.9, 1.1]
    sim.reset(position_ned_m=[0, 0, 0], rpy_rad=[0.1, 0.2, 0.3], nu=nu0)
    m = sim.model.mass_matrix

    def energy():
        return 0.5 * sim.nu @ m @ sim.nu

    e0 = energy()
    sim.advance(10.0)
    assert not np.allclose(sim.nu, nu0, atol=0.05)  # the Coriolis terms really exchanged momentum
    assert energy() == pytest.approx(e0, rel=1e-6)


# --------------------------------------------------------------------------------- steady speeds ([Hindrax-Drag] eq. 2)
@pytest.mark.parametrize("dof,load", [("surge", 10.0), ("surge", -6.0), ("sway", 8.0), ("roll", 0.5),
                                      ("pitch", -0.4), ("yaw", 0.6)])
def test_steady_speed_pure_load(neutral_cfg, dof, load):
    """A constant pure force/moment at the CG gives the positive root of k_q|v|v + k_l v = F (b = 0)."""
    i = DOFS.index(dof)
    h = neutral_cfg.dof_hydrodynamics(dof)
    sign = 1.0 if load > 0 else -1.0
    kq = h.quadratic_damping_positive if sign > 0 else h.quadratic_damping_negative
    kl = h.linear_damping_positive if sign > 0 else h.linear_damping_negative
    expected = sign * steady_speed(kq, kl, abs(load))
    sim = Simulator(neutral_cfg, pool=False, sensors=False)
    sim.reset(position_ned_m=[0, 0, 10], rpy_rad=[0, 0, 0])
    wrench = np.zeros(6)
    wrench[i] = load
    sim.advance(20.0, external_wrench_frd=wrench)
    assert sim.nu[i] == pytest.approx(expected, rel=0.01)
    others = np.delete(sim.nu, i)
    assert np.allclose(others, 0.0, atol=1e-9)  # a pure 1-DOF motion


@pytest.mark.parametrize("force", [20.0, 5.0, -12.0, -3.0])
def test_steady_heave_with_net_buoyancy(cfg, force):
    """Heave keeps the real buoyancy: k_q|w|w + k_l w + b = Z with b = B - W (0.785 N, [Hindrax-Drag] §5), the
    positive-heave (down, w > 0) coefficients for w > 0 and the negative-heave ones for w < 0."""
    h = cfg.dof_hydrodynamics("heave")
    b = cfg.buoyancy_n - cfg.weight_n
    net = force - b
    if net > 0:
        expected = steady_speed(h.quadratic_damping_positive, h.linear_damping_positive, net)
    else:
        expected = -steady_speed(h.quadratic_damping_negative, h.linear_damping_negative, -net)
    sim = Simulator(cfg, pool=False, sensors=False)
    sim.reset(position_ned_m=[0, 0, 50], rpy_rad=[0, 0, 0])
    sim.advance(25.0, external_wrench_frd=[0, 0, force, 0, 0, 0])
    assert sim.nu[2] == pytest.approx(expected, rel=0.01)
    assert abs(sim.euler_rad[1]) < 1e-9 and abs(sim.nu[0]) < 1e-9


# ----------------------------------------------------------------------------------- initial acceleration
@pytest.mark.parametrize("dof", DOFS)
def test_initial_acceleration_is_force_over_total_mass(neutral_cfg, dof):
    """Right after a load step from rest: dv/dt = F / (m + m_a) (or K / (I + I_a))."""
    i = DOFS.index(dof)
    load = 10.0 if i < 3 else 0.5
    inertia = neutral_cfg.vehicle.mass_kg if i < 3 else neutral_cfg.vehicle.inertia_kg_m2[i - 3]
    total = inertia + neutral_cfg.dof_hydrodynamics(dof).added_mass
    sim = Simulator(neutral_cfg, pool=False, sensors=False)
    sim.reset(position_ned_m=[0, 0, 10], rpy_rad=[0, 0, 0])
    wrench = np.zeros(6)
    wrench[i] = load
    sim.advance(0.01, external_wrench_frd=wrench)
    assert sim.nu[i] / sim.t_s == pytest.approx(load / total, rel=0.02)


def test_thruster_step_acceleration_and_lag(neutral_cfg):
    """T1+T2 at equal pulse widths: surge force 2 F(P) cos 55 deg ([Hindrax-Drag] eq. 1 and §4), accelerating
    m + m_a; with the first-order lag the thrust reaches 1 - 1/e of its command after one time constant."""
    p_us = 1750.0
    c4, c3, c2, c1 = neutral_cfg.thrusters.curve_positive
    f_one = c4 * p_us ** 3 + c3 * p_us ** 2 + c2 * p_us + c1
    x_force = 2.0 * f_one * math.cos(math.radians(55.0))
    total = neutral_cfg.vehicle.mass_kg + neutral_cfg.dof_hydrodynamics("surge").added_mass
    pw = [p_us, p_us, 1500, 1500, 1500, 1500, 1500, 1500]

    instant = neutral_cfg.with_overrides({"thrusters.time_constant_s": 0.0})
    sim = Simulator(instant, pool=False, sensors=False)
    sim.reset(position_ned_m=[0, 0, 10], rpy_rad=[0, 0, 0])
    sim.advance(0.01, pw)
    assert sim.nu[0] / sim.t_s == pytest.approx(x_force / total, rel=0.02)

    tc = neutral_cfg.thrusters.time_constant_s
    sim = Simulator(neutral_cfg, pool=False, sensors=False)
    sim.reset(position_ned_m=[0, 0, 10], rpy_rad=[0, 0, 0])
    sim.advance(tc, pw)
    assert sim.thrust_n[0] == pytest.approx(f_one * (1.0 - math.exp(-1.0)), rel=1e-6)
    assert sim.wrench_frd[0] == pytest.approx(x_force * (1.0 - math.exp(-1.0)), rel=1e-6)


def test_surge_and_sway_pairs_make_no_yaw(cfg):
    """[Hindrax-Drag] §4.1: T1+T2 push surge, T1+T3 push sway; with the symmetric layout neither makes a yaw moment."""
    thr = Thrusters(cfg)
    thr.command([1700, 1700, 1500, 1500, 1500, 1500, 1500, 1500])
    thr.advance(10.0)  # many time constants: the thrust equals its command
    w = thr.wrench_co()  # about the CG: the body origin is at the CG
    f = thr.commanded_force_n[0]
    assert f > 5.0
    assert w[0] == pytest.approx(2 * f * math.cos(math.radians(55)), rel=1e-6)  # config rounds to 6 digits
    assert abs(w[1]) < 1e-9 and abs(w[5]) < 1e-9
    thr.command([1700, 1500, 1700, 1500, 1500, 1500, 1500, 1500])
    thr.advance(10.0)
    w = thr.wrench_co()
    assert w[1] == pytest.approx(2 * f * math.sin(math.radians(55)), rel=1e-6)
    assert abs(w[0]) < 1e-9 and abs(w[5]) < 1e-9


def test_reversed_thruster_and_no_signal(cfg):
    """A reversed thruster's wire width is mirrored about neutral; width 0 (no pulses) stops the ESC."""
    rev = cfg.with_overrides({"thrusters.t1.reversed": True})
    normal, mirrored = Thrusters(cfg), Thrusters(rev)
    f_normal = normal.thrust_from_pulse_width([1700] + [1500] * 7)
    f_rev = mirrored.thrust_from_pulse_width([1300] + [1500] * 7)
    assert f_rev[0] == pytest.approx(f_normal[0]) and f_normal[0] > 5.0
    assert np.all(normal.thrust_from_pulse_width([0.0] * 8) == 0.0)


# ----------------------------------------------------------------------------------- kinematics & integration
def test_heading_east_surge_moves_east(neutral_cfg):
    sim = Simulator(neutral_cfg, pool=False, sensors=False)
    sim.reset(position_ned_m=[0, 0, 10], rpy_rad=[0, 0, math.pi / 2])
    sim.advance(5.0, external_wrench_frd=[10, 0, 0, 0, 0, 0])
    north, east, down = sim.position_ned_m
    assert east > 1.0 and abs(north) < 1e-9 and down == pytest.approx(10.0, abs=1e-9)


def test_step_halving_changes_10s_trajectory_by_less_than_1um(cfg):
    """RK4 at step_s and step_s / 2 over 10 s of mixed thrust (all DOFs moving, no contact): the final
    position differs by < 1e-6 m and the attitude by < 1e-6 rad (stated tolerance)."""
    pw = [1650, 1580, 1500, 1440, 1530, 1526, 1520, 1500]
    finals = []
    for dt in (cfg.simulation.step_s, cfg.simulation.step_s / 2):
        sim = Simulator(cfg, step_s=dt, sensors=False)
        sim.reset(position_ned_m=[4.0, 3.0, 0.8])
        faces = set()
        for _ in range(int(round(10.0 / dt))):
            sim.step(pw)
            faces |= set(sim.contact.faces)
        assert not faces  # precondition: free motion
        finals.append(sim)
    a, b = finals
    assert np.linalg.norm(a.position_ned_m - [4.0, 3.0, 0.8]) > 1.0  # it really moved
    assert np.max(np.abs(a.position_ned_m - b.position_ned_m)) < 1e-6
    assert np.max(np.abs(a.euler_rad - b.euler_rad)) < 1e-6
    assert abs(a.euler_rad[2]) > 0.5  # and turned


def test_deterministic_with_seed(cfg):
    def run(seed):
        sim = Simulator(cfg, seed=seed)
        sim.reset(position_ned_m=[4.0, 3.0, 0.8])
        out = []
        for _ in range(400):
            out.extend(sim.step([1600, 1600, 1500, 1500, 1500, 1500, 1500, 1500]))
        return out

    a, b, c = run(7), run(7), run(8)
    assert len(a) > 100 and a == b
    assert a != c
    gyro = [[s.stamp_s for n, s in run_ if n == "icm20948_gyro"] for run_ in (a, c)]
    assert gyro[0] == gyro[1] and len(gyro[0]) == 201  # same sampling grid (100 Hz over 2 s), other noise


def test_bad_pulse_widths_rejected_and_state_unchanged(cfg):
    sim = Simulator(cfg, sensors=False)
    sim.step([1600] * 8)
    before = sim.state
    for bad in ([1600] * 7, [1600] * 7 + [float("nan")], "x"):
        with pytest.raises(PulseWidthError):
            sim.step(bad)
    assert np.array_equal(sim.state, before)
    with pytest.raises(ValueError):
        sim.step(None, external_wrench_frd=[1, 2, 3])
