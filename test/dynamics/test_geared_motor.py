"""A hinge's geared motor: a rotor on the parent turning G times the joint's rate (docs/theory.md,
"The geared motor"). Checked against a Lagrangian written out here by hand (accelerations and a
trajectory), the energy and angular momentum it keeps, the armature it reduces to where its
parent cannot turn about its axis, and the compiled kernel against the numpy reference."""
import copy

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from gyro_sim import Simulator, load_scene
from gyro_sim.dynamics import kernel as fast
from gyro_sim.dynamics import reference as dyn
from gyro_sim.dynamics.model import compile_model, initial_state
from gyro_sim.dynamics.system import ChainODE, FastChainODE
from gyro_sim.scene.load import SceneError

needs_numba = pytest.mark.skipif(not fast.available(), reason="numba is not installed")

G_WORLD = np.array([0.0, 0.0, -9.81])
#: the turntable and its arm: body 1 about the vertical, body 2 about E2 (body 1's frame) at S1,
#: the motor on body 1 with axis A_MOTOR (a bevel gear: not the hinge's axis)
M1, C1, I1C, S1 = 2.0, np.array([0.1, 0.05, 0.0]), np.diag([0.05, 0.06, 0.07]), np.array([0.5, 0.0, 0.1])
M2, C2, I2C = 1.0, np.array([0.2, 0.0, 0.1]), np.array([[0.01, 0.002, 0.0], [0.002, 0.02, 0.001], [0.0, 0.001, 0.015]])
E2 = np.array([0.0, 1.0, 0.0])
J_ROTOR, GEAR = 2e-4, 40.0
A_MOTOR = np.array([0.0, 0.6, 0.8])


def turntable(axis=A_MOTOR, gear=GEAR, inertia=J_ROTOR, gravity=True, rates=(3.0, 0.5)) -> dict:
    """The two-body chain with the geared motor of hinge 2 on body 1."""
    return {
        "name": "turntable", "gravity": G_WORLD.tolist() if gravity else [0.0, 0.0, 0.0],
        "base": {"type": "fixed"},
        "bodies": [
            {"name": "table", "joint": {"type": "hinge", "axis": [0, 0, 1]}, "mass": M1, "com": C1.tolist(),
             "inertia_com": I1C.tolist(), "next_joint": S1.tolist(), "initial": {"angle": 0.2, "rate": rates[0]}},
            {"name": "arm", "joint": {"type": "hinge", "axis": E2.tolist(),
                                      "motor": {"inertia": inertia, "gear": gear, "axis": list(axis)}},
             "mass": M2, "com": C2.tolist(), "inertia_com": I2C.tolist(), "initial": {"angle": 0.3, "rate": rates[1]}},
        ],
    }


# --- the Lagrangian, by hand -----------------------------------------------------------------
def _rot(axis, angle):
    """Rotation by `angle` about the unit `axis` (Rodrigues), complex-step safe."""
    K = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * (K @ K)


def _lagrangian_parts(q, axis=A_MOTOR, gear=GEAR, inertia=J_ROTOR, gravity=True):
    """M(q) (2, 2) of T = 1/2 q'^T M q' and V(q), from each body's velocity Jacobians: body 1
    turns about z through the origin, body 2 about R1 E2 through O2 = R1 S1; the rotor's absolute
    axial rate is a . w1 + G q2' (a = R1 A), its energy 1/2 J (a . w1 + G q2')^2."""
    z = np.array([0.0, 0.0, 1.0])
    R1 = _rot(z, q[0])
    R2 = R1 @ _rot(E2, q[1])
    O2 = R1 @ S1
    r1, r2 = R1 @ C1, O2 + R2 @ C2
    e2 = R1 @ E2
    Jw1 = np.stack([z, np.zeros(3)], axis=1)
    Jv1 = np.stack([np.cross(z, r1), np.zeros(3)], axis=1)
    Jw2 = np.stack([z, e2], axis=1)
    Jv2 = np.stack([np.cross(z, r2), np.cross(e2, r2 - O2)], axis=1)
    I1 = R1 @ I1C @ R1.T
    I2 = R2 @ I2C @ R2.T
    a = R1 @ (np.asarray(axis) / np.linalg.norm(axis))
    Jr = np.array([a @ z, gear])  # the rotor's absolute axial rate per q'
    M = M1 * Jv1.T @ Jv1 + Jw1.T @ I1 @ Jw1 + M2 * Jv2.T @ Jv2 + Jw2.T @ I2 @ Jw2 + inertia * np.outer(Jr, Jr)
    V = -(M1 * G_WORLD @ r1 + M2 * G_WORLD @ r2) if gravity else 0.0 * q[0]
    return M, V


def lagrange_accelerations(q, qd, Q=(0.0, 0.0), **kw):
    """q'' of d/dt dT/dq' - dT/dq + dV/dq = Q, the derivatives of M and V by complex steps."""
    h = 1e-30
    M, _ = _lagrangian_parts(q, **kw)
    dM, dV = [], []
    for k in range(2):
        qc = q.astype(complex)
        qc[k] += 1j * h
        Mc, Vc = _lagrangian_parts(qc, **kw)
        dM.append(Mc.imag / h)
        dV.append(np.imag(Vc) / h)
    Mdot = sum(dM[k] * qd[k] for k in range(2))
    rhs = np.asarray(Q) - Mdot @ qd + 0.5 * np.array([qd @ dM[k] @ qd for k in range(2)]) - np.array(dV)
    return np.linalg.solve(M, rhs)


def lagrange_energy(q, qd, **kw):
    M, V = _lagrangian_parts(q, **kw)
    return 0.5 * qd @ M @ qd + V


# --- the tests ------------------------------------------------------------------------------
def _state(model, q, qd):
    y = initial_state(model)
    y[model.i_phi] = q
    y[model.i_vel] = qd
    return y


@pytest.mark.parametrize("axis", [A_MOTOR, E2, [1.0, 0.0, 0.0]])
def test_accelerations_match_the_lagrangian(axis):
    model = compile_model(load_scene(turntable(axis=axis)))
    data = dyn.Data(model)
    rng = np.random.default_rng(3)
    for _ in range(5):
        q, qd, tau = rng.normal(size=2), 3.0 * rng.normal(size=2), rng.normal(size=2)
        udot = dyn.forward(model, data, 0.0, _state(model, q, qd), tau, None, None)
        expected = lagrange_accelerations(q, qd, tau, axis=axis)
        np.testing.assert_allclose(udot, expected, rtol=1e-10, atol=1e-10 * np.max(np.abs(expected)))


def test_energy_matches_the_lagrangian():
    """The invariants' energy counts the rotor: phi' J G a . w1 + 1/2 J G^2 phi'^2 beyond the
    parent's inertia, which holds its locked J a a^T."""
    sim = Simulator(turntable(), backend="numpy")
    q, qd = np.array([0.2, 0.3]), np.array([3.0, 0.5])
    assert sim.invariants()["energy"] == pytest.approx(lagrange_energy(q, qd), rel=1e-13)


@pytest.mark.parametrize("backend", ["numpy", pytest.param("numba", marks=needs_numba)])
def test_trajectory_matches_the_lagrangian(backend):
    """One second of the turntable from both, each integrated to ~1e-12: the angles and rates
    agree to 1e-10."""
    sim = Simulator(turntable(), integrator="dop853", rtol=1e-13, atol=1e-13, backend=backend)
    sim.advance(1.0)
    y = sim.state
    model = sim.model

    def f(t, x):
        return np.concatenate((x[2:], lagrange_accelerations(x[:2], x[2:])))

    ref = solve_ivp(f, (0.0, 1.0), [0.2, 0.3, 3.0, 0.5], method="DOP853", rtol=1e-13, atol=1e-13).y[:, -1]
    np.testing.assert_allclose(np.concatenate((y[model.i_phi], y[model.i_vel])), ref, rtol=0, atol=1e-10)


def free_chain(base="free") -> dict:
    """Three bodies without gravity: a spherical first joint, two hinges with geared motors
    (one coaxial, one on a bevel axis), all turning."""
    return {
        "name": "free_motors", "base": {"type": base},
        "bodies": [
            {"name": "hub", "joint": {"type": "spherical"}, "mass": 3.0, "com": [0.05, 0.0, 0.02],
             "inertia_com": [[0.1, 0.01, 0.0], [0.01, 0.12, 0.0], [0.0, 0.0, 0.09]], "next_joint": [0.3, 0.1, 0.0],
             "initial": {"quaternion": [1.0, 0.1, 0.2, 0.0], "angular_velocity": [0.4, -1.0, 2.0]}},
            {"name": "link", "joint": {"type": "hinge", "axis": [0, 0, 1],
                                       "motor": {"inertia": 3e-4, "gear": 60.0}},
             "mass": 1.0, "com": [0.2, 0.0, 0.0], "inertia_com": [[0.01, 0, 0], [0, 0.02, 0], [0, 0, 0.02]],
             "next_joint": [0.4, 0.0, 0.0], "initial": {"angle": 0.3, "rate": 1.5}},
            {"name": "tip", "joint": {"type": "hinge", "axis": [0, 1, 0],
                                      "motor": {"inertia": 1e-4, "gear": -25.0, "axis": [1.0, 0.0, 0.5]}},
             "mass": 0.5, "com": [0.1, 0.0, 0.05], "inertia_com": [[0.004, 0, 0], [0, 0.005, 0], [0, 0, 0.006]],
             "initial": {"angle": -0.2, "rate": -2.0}},
        ],
    }


@pytest.mark.parametrize("base", ["free", "fixed"])
def test_energy_and_momentum_kept(base):
    """No gravity, no commands: the energy (the rotors' included) and the angular momentum (the
    rotors' spins J G phi' a included) stay to 1e-12 over a second of fast motion."""
    sim = Simulator(free_chain(base), integrator="dop853", rtol=3e-14, atol=1e-14, backend="numpy")
    before = sim.invariants()
    sim.advance(1.0)
    after = sim.invariants()
    names = ["energy"] + (["angular_momentum", "linear_momentum"] if base == "free" else ["angular_momentum_O1"])
    for name in names:
        scale = np.linalg.norm(before[name]) if name != "linear_momentum" else 1.0
        np.testing.assert_allclose(after[name], before[name], rtol=0, atol=1e-12 * scale, err_msg=name)
    # and the motors matter: without their coupling (armature J G^2 instead) the momentum differs
    plain = copy.deepcopy(free_chain(base))
    for b in plain["bodies"][1:]:
        mo = b["joint"].pop("motor")
        b["joint"]["armature"] = mo["inertia"] * mo["gear"] ** 2
    name = names[1]  # an angular momentum
    assert np.linalg.norm(Simulator(plain, backend="numpy").invariants()[name] - before[name]) \
        > 1e-3 * np.linalg.norm(before[name])


def test_reduces_to_armature_where_the_parent_cannot_turn_about_it():
    """The parent turns about z only; a motor axis normal to z sees no parent rate (a . w1 = 0,
    a . w1' = 0): the joint moves as with armature J G^2, to round-off."""
    axis = [1.0, 0.0, 0.0]
    geared = Simulator(turntable(axis=axis), integrator="dop853", rtol=1e-12, atol=1e-12, backend="numpy")
    plain_scene = turntable(axis=axis)
    plain_scene["bodies"][1]["joint"].pop("motor")
    plain_scene["bodies"][1]["joint"]["armature"] = J_ROTOR * GEAR ** 2
    plain = Simulator(plain_scene, integrator="dop853", rtol=1e-12, atol=1e-12, backend="numpy")
    model_g, model_p = geared.model, plain.model
    rng = np.random.default_rng(5)
    for _ in range(4):
        q, qd, tau = rng.normal(size=2), 3.0 * rng.normal(size=2), rng.normal(size=2)
        a = dyn.forward(model_g, dyn.Data(model_g), 0.0, _state(model_g, q, qd), tau, None, None)
        b = dyn.forward(model_p, dyn.Data(model_p), 0.0, _state(model_p, q, qd), tau, None, None)
        np.testing.assert_allclose(a, b, rtol=1e-14, atol=1e-14 * np.max(np.abs(b)))


@pytest.mark.parametrize("base", ["fixed", "moving"])
def test_on_the_first_body_is_armature(base):
    """The base never rotates (fixed, or moving: it translates; a free base's first joint is
    spherical): a motor on the first body is exactly armature J G^2, whatever its axis."""
    scene = free_chain("fixed")
    scene["bodies"][0]["joint"] = {"type": "hinge", "axis": [0, 0, 1],
                                   "motor": {"inertia": 1e-3, "gear": 30.0, "axis": [1.0, 1.0, 0.0]}}
    scene["bodies"][0]["initial"] = {"angle": 0.1, "rate": 2.0}
    scene["base"] = {"fixed": {"type": "fixed"},
                     "moving": {"type": "moving", "motion": {"type": "sine", "amplitude": [0.1, 0.0, 0.0],
                                                             "frequency": 2.0}}}[base]
    plain = copy.deepcopy(scene)
    plain["bodies"][0]["joint"].pop("motor")
    plain["bodies"][0]["joint"]["armature"] = 1e-3 * 30.0 ** 2
    a, b = compile_model(load_scene(scene)), compile_model(load_scene(plain))
    assert np.array_equal(a.armature, b.armature) and np.array_equal(a.inertia, b.inertia)
    y = initial_state(a)
    assert np.array_equal(dyn.forward(a, dyn.Data(a), 0.3, y, None, None, None),
                          dyn.forward(b, dyn.Data(b), 0.3, y, None, None, None))


@pytest.mark.parametrize("motor, message", [
    ({"inertia": 0.0, "gear": 10}, "inertia: must be > 0"),
    ({"inertia": 1e-3, "gear": 0}, "gear: must not be zero"),
    ({"inertia": 1e-3}, "gear"),
    ({"inertia": 1e-3, "gear": 10, "axis": [0, 0, 0]}, "axis: zero vector"),
    ({"inertia": 1e-3, "gear": 10, "ratio": 2}, "ratio"),
    ({"inertia": "x", "gear": 10}, "inertia"),
])
def test_bad_motors_refused_naming_the_key(motor, message):
    scene = turntable()
    scene["bodies"][1]["joint"]["motor"] = motor
    with pytest.raises(SceneError, match="bodies\\[1\\].joint.motor") as err:
        load_scene(scene)
    assert message in str(err.value)


def test_motor_with_armature_or_on_a_spherical_joint_refused():
    scene = turntable()
    scene["bodies"][1]["joint"]["armature"] = 0.1
    with pytest.raises(SceneError, match="joint.motor: not allowed with armature"):
        load_scene(scene)
    scene = free_chain()
    scene["bodies"][0]["joint"]["motor"] = {"inertia": 1e-3, "gear": 10}
    with pytest.raises(SceneError, match="joint.motor: not allowed for a spherical joint"):
        load_scene(scene)


def test_gauss4s_refuses_motors():
    with pytest.raises(ValueError, match="gauss4s does not take geared motors"):
        Simulator(turntable(), integrator="gauss4s", backend="numpy")
