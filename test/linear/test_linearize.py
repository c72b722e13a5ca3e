"""Linearisation (gyro_sim.linear): the complex step against central differences of the same
dynamics, and the eigenvalues against closed forms derived in docs/theory.md section 9."""
import math

import numpy as np
import pytest

from gyro_sim import Simulator
from gyro_sim.scene.load import load_scene

G = 9.81


def _sim(scene, **kw):
    return Simulator(load_scene(scene), backend="numpy", **kw)


def _close_sets(got, want, rtol=1e-9, atol=1e-9):
    """Every eigenvalue of `want` matched by one of `got` (greedy, nearest), to rtol relative or
    atol absolute (zero eigenvalues)."""
    got = list(got)
    scale = max(1.0, max(abs(w) for w in want))
    for w in sorted(want, key=abs, reverse=True):
        i = int(np.argmin([abs(g - w) for g in got]))
        assert abs(got[i] - w) <= max(rtol * abs(w), atol * (1.0 if w == 0 else scale)), (w, got[i], got)
        got.pop(i)


# --- exact derivatives ---------------------------------------------------------------------
@pytest.mark.parametrize("scene", ["hinge_chain", "imu_pendulum", "free_chain_rotors", "double_gyro_plus",
                                   "vibrating_base"])
@pytest.mark.parametrize("chart", ["world", "body"])
def test_complex_step_agrees_with_central_differences(scene, chart):
    sim = _sim(scene)
    sim.advance(0.05)
    if sim.axis_names:
        sim.set_axis_moments(0.001 * np.arange(1, len(sim.axis_names) + 1))
    exact = sim.linearize(chart=chart, rotor_angles=True)
    fd = sim.linearize(chart=chart, rotor_angles=True, method="fd")
    for name in "ABCD":
        a, b = getattr(exact, name), getattr(fd, name)
        if a.size:
            assert np.max(np.abs(a - b)) <= 1e-6 * max(1.0, np.max(np.abs(a))), name
    np.testing.assert_array_equal(exact.f0, fd.f0)


def test_f0_is_the_simulators_own_derivative_and_every_row_is_named():
    sim = _sim("hinge_chain")
    sim.set_axis_moments([0.01, 0.02, -0.01])
    sim.advance(0.1)
    lin = sim.linearize(rotor_angles=True)
    m = sim.model
    ydot = sim.system.rhs(sim.time, sim.state)
    N = m.N
    np.testing.assert_allclose(lin.f0[N:2 * N], ydot[m.i_vel], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(lin.f0[m.col_hinge], ydot[m.i_phi], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(lin.f0[2 * N + 1:], ydot[m.i_kappa], rtol=1e-12, atol=1e-12)
    assert len(lin.state_names) == len(set(lin.state_names)) == lin.A.shape[0] == lin.A.shape[1]
    assert lin.input_names == ("wheel2", "arm3", "arm4") and lin.B.shape == (lin.A.shape[0], 3)
    assert lin.state_names[:3] == ("arm1_rx", "arm1_ry", "arm1_rz") and "wheel2_spin" in lin.state_names
    assert len(lin.output_names) == lin.C.shape[0]
    assert not lin.is_equilibrium and lin.verdict() == "not an equilibrium"
    # the rotation vector's rate at the point is the body's angular velocity (world components)
    w = sim.body_states()[0].angular_velocity
    np.testing.assert_allclose(lin.f0[:3], w, rtol=1e-12, atol=1e-12)


# --- closed forms (docs/theory.md section 9) --------------------------------------------------
def _hinge_pair(m1, c1, I1c, l1, m2, c2, I2c):
    """Two bodies on parallel hinges about x, hanging at rest (com below O^k along -z)."""
    def body(name, m, c, Ic, nxt):
        b = {"name": name, "joint": {"type": "hinge", "axis": [1.0, 0.0, 0.0]}, "mass": m, "com": [0.0, 0.0, -c],
             "inertia_com": np.diag(Ic).tolist(), "initial": {"angle": 0.0, "rate": 0.0}}
        if nxt:
            b["next_joint"] = [0.0, 0.0, -nxt]
        return b
    return {"name": "pair", "gravity": [0.0, 0.0, -G], "base": {"type": "fixed", "position": [0, 0, 0]},
            "bodies": [body("upper", m1, c1, I1c, l1), body("lower", m2, c2, I2c, None)]}


def test_hanging_hinge_pair_frequencies_are_the_roots_of_det_K_minus_w2_M():
    m1, c1, I1c, l1 = 0.7, 0.12, [3e-3, 2e-3, 1e-3], 0.3
    m2, c2, I2c = 0.4, 0.1, [1.5e-3, 1e-3, 8e-4]
    lin = _sim(_hinge_pair(m1, c1, I1c, l1, m2, c2, I2c)).linearize()
    assert lin.is_equilibrium and lin.verdict() == "marginal"
    I1, I2 = I1c[0] + m1 * c1 ** 2, I2c[0] + m2 * c2 ** 2  # about the hinges
    M = np.array([[I1 + m2 * l1 ** 2, m2 * l1 * c2], [m2 * l1 * c2, I2]])  # absolute angles
    K = np.diag([(m1 * c1 + m2 * l1) * G, m2 * c2 * G])
    w2 = np.linalg.eigvals(np.linalg.solve(M, K)).real
    want = [s * 1j * math.sqrt(x) for x in w2 for s in (1, -1)]
    _close_sets(lin.eigenvalues(), want)


def test_equal_point_masses_tend_to_two_plus_minus_root_two_g_over_l():
    l, m, tiny = 0.5, 1.0, 1e-9
    lin = _sim(_hinge_pair(m, l, [tiny] * 3, l, m, l, [tiny] * 3)).linearize()
    w2 = sorted(-(lin.eigenvalues() ** 2).real)[::2]
    np.testing.assert_allclose(w2, [(2 - math.sqrt(2)) * G / l, (2 + math.sqrt(2)) * G / l], rtol=1e-7)


def _top(A_c, B_c, m, l, rotor_A, rotor_B, rotor_m, rotor_h, p, upright=True):
    """A carrier at rest on a spherical joint, its axis up (theta = pi) or down, with a torque
    rotor on its axis spinning at p."""
    return {"name": "top", "gravity": [0.0, 0.0, -G], "base": {"type": "fixed", "position": [0, 0, 0]},
            "bodies": [{"name": "top", "joint": {"type": "spherical"}, "mass": m, "com": [0.0, 0.0, l],
                        "inertia_com": np.diag([B_c, B_c, A_c]).tolist(),
                        "rotors": [{"name": "rotor", "axis": [0, 0, 1], "position": [0, 0, rotor_h], "mass": rotor_m,
                                    "axial_inertia": rotor_A, "transverse_inertia": rotor_B, "mode": "torque",
                                    "spin": p}],
                        "initial": {"euler": [0.0, math.pi if upright else 0.0, 0.0], "euler_rates": [0, 0, 0]}}]}


@pytest.mark.parametrize("p", [400.0, 60.0])
def test_upright_top_as_carrier_at_rest_with_a_rotor(p):
    A_c, B_c, m, l = 2e-4, 1.5e-4, 0.3, 0.04
    rA, rB, rm, rh = 1.2e-4, 6.5e-5, 0.2, 0.05
    lin = _sim(_top(A_c, B_c, m, l, rA, rB, rm, rh, p)).linearize()
    assert lin.is_equilibrium
    mgl = (m * l + rm * rh) * G
    A_t = B_c + m * l ** 2 + rB + rm * rh ** 2  # transverse, about the pivot, rotor axial excluded
    h = rA * p
    disc = h * h - 4 * A_t * mgl
    if disc > 0:
        want = [s * 1j * (h + r * math.sqrt(disc)) / (2 * A_t) for r in (1, -1) for s in (1, -1)]
        assert lin.verdict() == "marginal"
    else:
        re, im = math.sqrt(-disc) / (2 * A_t), h / (2 * A_t)
        want = [a * re + 1j * b * im for a in (1, -1) for b in (1, -1)]
        assert lin.verdict() == "unstable"
        assert abs(lin.eigenvalues()[0].real - re) <= 1e-9 * re
    _close_sets(lin.eigenvalues(), want + [0.0, 0.0, 0.0])


def test_free_gyrostat_at_rest_with_a_spinning_rotor():
    I1, I2, I3, rA, p = 0.02, 0.03, 0.045, 1e-3, 300.0
    scene = {"name": "gyrostat", "base": {"type": "free", "position": [0, 0, 0]},
             "bodies": [{"name": "body", "joint": {"type": "spherical"}, "mass": 2.0, "com": [0, 0, 0],
                         "inertia_com": np.diag([I1, I2, I3]).tolist(),
                         "rotors": [{"name": "rotor", "axis": [0, 1, 0], "position": [0, 0, 0], "mass": 0.0,
                                     "axial_inertia": rA, "transverse_inertia": 0.6 * rA, "mode": "torque",
                                     "spin": p}],
                         "initial": {"quaternion": [1, 0, 0, 0], "angular_velocity": [0, 0, 0]}}]}
    lin = _sim(scene).linearize()
    assert lin.is_equilibrium
    J1, J3 = I1 + 0.6 * rA, I3 + 0.6 * rA  # the rotor's transverse moment is the carrier's
    w = rA * p / math.sqrt(J1 * J3)
    _close_sets(lin.eigenvalues(), [1j * w, -1j * w] + [0.0] * 11)


def test_reaction_wheel_pendulum_upright_without_friction():
    s = load_scene("imu_pendulum").source
    import copy
    s = copy.deepcopy(s)
    rotor = s["bodies"][0]["rotors"][0]
    for k in ("friction", "max_speed", "max_torque"):
        rotor.pop(k, None)
    s["bodies"][0]["initial"] = {"angle": math.pi, "rate": 0.0}
    lin = _sim(s).linearize()
    assert lin.is_equilibrium and lin.verdict() == "unstable"
    b = s["bodies"][0]
    mbar = b["mass"] * 0.15 + rotor["mass"] * 0.2
    J = b["inertia"]["transverse"] + rotor["mass"] * 0.2 ** 2  # the wheel's axial moment is in lambda
    r = math.sqrt(mbar * G / J)
    _close_sets(lin.eigenvalues(), [r, -r, 0.0])
    assert lin.controllability_rank() == 3
    # the wheel torque u: J theta'' = ... - u, I_w p' = u (docs/theory.md section 9)
    iw = lin.input_names.index("wheel")
    np.testing.assert_allclose(lin.B[:, iw], [0.0, -1.0 / J, 1.0 / rotor["axial_inertia"]], rtol=1e-12, atol=1e-12)
    # the hinge's own motor turns the pendulum alone: J theta'' = tau
    np.testing.assert_allclose(lin.B[:, lin.input_names.index("pendulum")], [0.0, 1.0 / J, 0.0], rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("h_rotor", [0.0, 0.004, -0.02])
def test_intermediate_axis_spin_in_the_co_rotating_chart(h_rotor):
    I1, I2, I3, W = 0.02, 0.03, 0.045, 5.0
    rA = 1e-3
    scene = {"name": "spin", "base": {"type": "fixed", "position": [0, 0, 0]},
             "bodies": [{"name": "body", "joint": {"type": "spherical"}, "mass": 1.0, "com": [0, 0, 0],
                         "inertia_com": np.diag([I1, I2, I3]).tolist(),
                         "rotors": [{"name": "rotor", "axis": [0, 1, 0], "position": [0, 0, 0], "mass": 0.0,
                                     "axial_inertia": rA, "transverse_inertia": 0.5 * rA, "mode": "torque",
                                     "spin": h_rotor / rA}],
                         "initial": {"quaternion": [0.9, 0.1, -0.3, 0.2], "angular_velocity": [0, W, 0]}}]}
    sim = _sim(scene)
    world = sim.linearize()
    assert not world.is_equilibrium  # the attitude turns: no verdict in the world chart
    lin = sim.linearize(chart="body")
    assert lin.is_equilibrium
    J1, J2, J3 = I1 + 0.5 * rA, I2, I3 + 0.5 * rA  # the rotor's transverse moments are the carrier's
    lam2 = -((J2 - J1) * W + h_rotor) * ((J2 - J3) * W + h_rotor) / (J1 * J3)
    lam = math.sqrt(lam2) if lam2 > 0 else 1j * math.sqrt(-lam2)
    _close_sets(lin.eigenvalues(), [lam, -lam, 1j * W, -1j * W, 0.0, 0.0, 0.0])
    assert lin.verdict() == ("unstable" if lam2 > 0 else "marginal")


# --- discrete models -------------------------------------------------------------------------
def test_discrete_rk4_is_the_derivative_of_one_rk4_step_at_an_equilibrium():
    s = _hinge_pair(0.7, 0.12, [3e-3, 2e-3, 1e-3], 0.3, 0.4, 0.1, [1.5e-3, 1e-3, 8e-4])
    h = 0.01
    sim = _sim(s, integrator="rk4", step=h)
    lin = sim.linearize()
    d = lin.discrete(h, "rk4")
    # central differences of the simulator's own rk4 step, in the hinge coordinates
    y0 = sim.state.copy()
    m = sim.model
    idx = list(np.arange(m.size)[m.i_phi]) + list(np.arange(m.size)[m.i_vel])
    eps = 1e-6
    Ad = np.empty((4, 4))
    for j, i in enumerate(idx):
        out = []
        for sgn in (1, -1):
            y = y0.copy()
            y[i] += sgn * eps
            sim.reset()
            sim._y = y  # the state the step starts from
            sim.advance(h)
            out.append(sim.state[idx])
        Ad[:, j] = (out[0] - out[1]) / (2 * eps)
    np.testing.assert_allclose(d.Ad, Ad, rtol=0, atol=1e-8)
    zoh = lin.discrete(h)
    np.testing.assert_allclose(np.sort(np.abs(np.linalg.eigvals(zoh.Ad))), 1.0, atol=1e-12)  # undamped


def test_bad_arguments_are_refused_in_one_line():
    from gyro_sim.linear.linearize import LinearizationError

    sim = _sim("imu_pendulum")
    with pytest.raises(LinearizationError, match="chart"):
        sim.linearize(chart="spinning")
    with pytest.raises(LinearizationError, match="method"):
        sim.linearize(method="forward")
    with pytest.raises(LinearizationError, match="adaptive"):
        sim.linearize().discrete(0.01, "dop853")
    with pytest.raises(LinearizationError, match="^y: expected 6 finite numbers"):
        sim.linearize(np.zeros(3))
    y = sim.state
    y[0] = np.nan
    with pytest.raises(LinearizationError, match="^y: "):
        sim.linearize(y)
    with pytest.raises(LinearizationError, match="^spins: "):
        sim.linearize(sim.state, spins=np.zeros(2))
    with pytest.raises(LinearizationError, match="step"):
        sim.linearize().discrete(-1.0)


def test_a_saturated_command_is_said_and_its_column_is_zero():
    sim = _sim("imu_pendulum")
    sim.set_axis_moments([0.0, 0.05])  # beyond the wheel's max_torque 0.02
    lin = sim.linearize()
    assert any("saturated" in n and n.startswith("wheel") for n in lin.notes)
    assert np.all(lin.B[:, 1] == 0.0)
    sim.set_axis_moments([0.0, 0.01])
    assert np.any(sim.linearize().B[:, 1] != 0.0)


def test_imu_outputs_at_the_point_are_what_the_simulator_reads():
    import copy

    s = copy.deepcopy(load_scene("imu_pendulum").source)
    for key in ("gyro_noise_density", "gyro_bias_instability", "accel_noise_density", "accel_bias_instability"):
        s["imus"][0][key] = 0.0
    sim = Simulator(load_scene(s))  # the compiled outputs: another path to the accelerations
    sim.set_axis_moments([0.01, 0.005])
    sim.advance(0.05)
    lin = sim.linearize()
    reading = sim.imus()[0]
    names = list(lin.output_names)
    gyro = lin.z0[[names.index(f"tip_imu.gyro_{a}") for a in "xyz"]]
    accel = lin.z0[[names.index(f"tip_imu.accel_{a}") for a in "xyz"]]
    np.testing.assert_allclose(gyro, reading.angular_velocity, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(accel, reading.linear_acceleration, rtol=1e-12, atol=1e-12)
    # a wheel torque reaches the accelerometer at once (D), the gyro only through the state (C)
    iw = lin.input_names.index("wheel")
    assert np.any(lin.D[[names.index(f"tip_imu.accel_{a}") for a in "yz"], iw] != 0.0)
    assert np.all(lin.D[[names.index(f"tip_imu.gyro_{a}") for a in "xyz"], iw] == 0.0)


def test_on_the_speed_limits_ramp_the_torque_is_scaled_and_said():
    import copy

    s = copy.deepcopy(load_scene("imu_pendulum").source)
    rotor = s["bodies"][0]["rotors"][0]
    rotor["spin"] = 599.7  # relative speed 599.7 of max_speed 600: halfway down the ramp (600 - 0.6 .. 600)
    rotor.pop("friction")
    sim = _sim(s)
    sim.set_axis_moments([0.0, 0.01])  # driving the wheel faster: the ramp applies
    lin = sim.linearize()
    assert any(n.startswith("wheel: speed 599.7 inside the speed limit's ramp") for n in lin.notes), lin.notes
    i, j = lin.state_names.index("wheel_spin"), lin.input_names.index("wheel")
    A_w = rotor["axial_inertia"]
    assert lin.B[i, j] == pytest.approx(0.5 / A_w, rel=1e-9)  # p' = ramp L / A_w, ramp = (600 - 599.7) / 0.6
    sim.set_axis_moments([0.0, -0.01])  # braking: no cut, the full torque
    assert sim.linearize().B[i, j] == pytest.approx(1.0 / A_w, rel=1e-12)


def test_chart_maps_at_large_angles_match_the_rotations_module():
    """The charts' helpers away from their series (a linearisation uses them near zero)."""
    from gyro_sim.dynamics.rotations import axis_angle_matrix, quat_exp
    from gyro_sim.linear.linearize import _exp_half, _jl_inv, _jr_inv, _rotate

    rng = np.random.default_rng(3)
    theta = rng.normal(size=(4, 3))
    theta[0] *= 1e-5  # one in the series' range
    np.testing.assert_allclose(_exp_half(theta), quat_exp(theta), rtol=1e-14, atol=1e-15)
    v = rng.normal(size=(4, 3))
    for t, vv, got in zip(theta, v, _rotate(theta, v)):
        angle = np.linalg.norm(t)
        np.testing.assert_allclose(got, axis_angle_matrix(t / angle, angle) @ vv, rtol=1e-13, atol=1e-15)
    # J_l^-1 and J_r^-1 invert the exponential's differentials: exp(theta + J^-1 w eps) ~ exp(w eps) exp(theta)
    eps = 1e-6
    from gyro_sim.dynamics.rotations import quat_mul

    for t, w in zip(theta[1:], v[1:]):
        q = quat_exp(t)
        left = (quat_exp(t + eps * _jl_inv(t, w)) - quat_exp(t - eps * _jl_inv(t, w))) / (2 * eps)
        want = (quat_mul(quat_exp(eps * w), q) - quat_mul(quat_exp(-eps * w), q)) / (2 * eps)
        np.testing.assert_allclose(left, want, atol=1e-8)
        right = (quat_exp(t + eps * _jr_inv(t, w)) - quat_exp(t - eps * _jr_inv(t, w))) / (2 * eps)
        want = (quat_mul(q, quat_exp(eps * w)) - quat_mul(q, quat_exp(-eps * w))) / (2 * eps)
        np.testing.assert_allclose(right, want, atol=1e-8)


@pytest.mark.parametrize("theta0, kappa", [(0.5, 4.0), (1.0, -6.0), (2.2, 5.0), (0.3, 1.5)])
def test_regular_precession_of_a_carrier_with_a_rotor_in_the_precessing_frame(theta0, kappa):
    """A top whose carrier precesses at kappa about the vertical, tilted theta0 from it, its
    rotor carrying the spin (docs/theory.md section 9): an equilibrium in the frame turning at
    kappa, with the nutation's eigenvalues from the reduced potential V_eff(theta)."""
    A_c, B_c, m, l = 2e-4, 1.5e-4, 0.3, 0.04
    rA, rB, rm, rh = 1.2e-4, 6.5e-5, 0.2, 0.05
    B = B_c + m * l ** 2 + rB + rm * rh ** 2  # transverse, about the pivot
    mgl = (m * l + rm * rh) * G
    c0, s0 = math.cos(theta0), math.sin(theta0)
    P_phi = (mgl + B * kappa ** 2 * c0) / kappa  # the axial momentum a steady precession needs
    p = (P_phi - A_c * kappa * c0) / rA  # the carrier turns at kappa about the vertical: w3 = kappa cos theta0
    P_psi = B * kappa * s0 ** 2 + P_phi * c0

    def V(th):  # the reduced potential (Routh), theta from the upward vertical
        return (P_psi - P_phi * np.cos(th)) ** 2 / (2 * B * np.sin(th) ** 2) + mgl * np.cos(th)

    f, f1, f2 = B * kappa * s0 ** 2, P_phi * s0, P_phi * c0  # P_psi - P_phi cos and its derivatives at theta0
    V2 = (f1 ** 2 + f * f2) / (B * s0 ** 2) - 4 * f * f1 * c0 / (B * s0 ** 3) + f ** 2 * (s0 ** 2 + 3 * c0 ** 2) / (
        B * s0 ** 4) - mgl * c0
    e = 1e-4  # the formula checked against its definition (V'(theta0) = 0, V'' by differences)
    assert abs((V(theta0 + e) - V(theta0 - e)) / (2 * e)) < 1e-6 * abs(V2)
    assert abs((V(theta0 + e) - 2 * V(theta0) + V(theta0 - e)) / e ** 2 - V2) < 1e-5 * abs(V2)
    k = V2 / B
    scene = {"name": "precession", "gravity": [0.0, 0.0, -G], "base": {"type": "fixed", "position": [0, 0, 0]},
             "bodies": [{"name": "top", "joint": {"type": "spherical"}, "mass": m, "com": [0.0, 0.0, l],
                         "inertia_com": np.diag([B_c, B_c, A_c]).tolist(),
                         "rotors": [{"name": "rotor", "axis": [0, 0, 1], "position": [0, 0, rh], "mass": rm,
                                     "axial_inertia": rA, "transverse_inertia": rB, "mode": "torque", "spin": p}],
                         "initial": {"quaternion": [math.cos(theta0 / 2), math.sin(theta0 / 2), 0.0, 0.0],
                                     "angular_velocity": [0.0, kappa * s0, kappa * c0]}}]}
    sim = _sim(scene)
    assert not sim.linearize().is_equilibrium  # the world chart sees the axis turn
    lin = sim.linearize(chart="frame", frame_rate=[0.0, 0.0, kappa])
    assert lin.is_equilibrium, lin.equilibrium_residual
    assert k > 0  # V_eff is convex at a steady precession of this top: a nutation, no growth
    lam = 1j * math.sqrt(k)
    ev = lin.eigenvalues()
    big = ev[np.abs(ev) > 1e-6 * abs(lam)]
    assert len(big) == 2 and len(ev) == 7, ev
    _close_sets(big, [lam, -lam])
    assert lin.verdict() == "marginal"
    fd = sim.linearize(chart="frame", frame_rate=[0.0, 0.0, kappa], method="fd")
    assert np.max(np.abs(fd.A - lin.A)) <= 1e-6 * np.max(np.abs(lin.A))


@pytest.mark.parametrize("scene", ["free_chain_rotors", "imu_pendulum", "rw_pendulum", "vibrating_base"])
def test_a_stack_of_states_evaluates_as_each_state_alone(scene):
    """The reference's stages on a stack of (complex) states, as the linearisation passes its
    directions, give each state's own evaluation."""
    from gyro_sim.dynamics import reference as dyn

    sim = _sim(scene)
    sim.advance(0.05)
    m = sim.model
    rng = np.random.default_rng(3)
    k = 5
    ys = (np.array(sim.state, float) + 1e-3 * rng.standard_normal((k, m.size))
          + 1j * 1e-3 * rng.standard_normal((k, m.size)))
    nh, nt = len(m.hinge_bodies), len(m.torque_body)
    taus = rng.standard_normal((k, nh)) if nh else None
    ps = rng.standard_normal((k, nt)) + 0j if nt else None
    Ls = rng.standard_normal((k, nt)) if nt else None
    if m.stateful:
        ys[:, m.i_spin] = ps
    stack = dyn.Data(m)
    rhs, parts = dyn.closure(m, stack, 0.1, ys, taus, ps, Ls)
    Mu = dyn.mass_times(m, stack, parts[0], parts[1], rhs.real)
    for i in range(k):
        one = dyn.Data(m)
        r, p1 = dyn.closure(m, one, 0.1, ys[i], None if taus is None else taus[i], None if ps is None else ps[i],
                            None if Ls is None else Ls[i])
        np.testing.assert_allclose(rhs[i], r, rtol=1e-13, atol=1e-13 * np.max(np.abs(r)))
        M = dyn.mass_matrix(m, one, p1[0], p1[1])
        np.testing.assert_allclose(Mu[i], M @ rhs[i].real, rtol=1e-12,
                                   atol=1e-12 * np.max(np.abs(M)) * np.max(np.abs(rhs)))


def test_the_stacks_size_does_not_change_the_model(monkeypatch):
    """All directions in one pass, or one direction per pass: the same A, B, C, D to round-off."""
    import importlib

    lin_mod = importlib.import_module("gyro_sim.linear.linearize")  # the module, not its function
    sim = _sim("free_chain_rotors")
    sim.advance(0.05)
    sim.set_axis_moments(0.001 * np.arange(1, len(sim.axis_names) + 1))
    big = sim.linearize(rotor_angles=True)
    monkeypatch.setattr(lin_mod, "BATCH_ELEMENTS", 1)
    one = sim.linearize(rotor_angles=True)
    for name in "ABCD":
        a, b = getattr(big, name), getattr(one, name)
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-13 * max(1.0, np.max(np.abs(a))), err_msg=name)
