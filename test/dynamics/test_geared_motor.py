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
    scene = turntable()
    scene["bodies"][1]["joint"]["type"] = "slide"
    with pytest.raises(SceneError, match="joint.motor: not allowed on a slide"):
        load_scene(scene)


def test_gauss4s_takes_motors_and_fixed_takes_gauss4s_for_them():
    """The canonical momenta hold the motors' coupling (test/integrators/test_gauss4s_trees.py
    checks the field): gauss4s steps the turntable, and "fixed" takes it as its stiff rung."""
    from gyro_sim.integrators.fixed import IMPLICIT, implicit_for

    sim = Simulator(turntable(), integrator="gauss4s", backend="numpy")
    sim.advance(0.01)
    assert np.isfinite(sim.state).all()
    assert implicit_for(sim.model) == IMPLICIT == "gauss4s"


# --- the compiled kernel against the numpy reference ------------------------------------------
def with_motors(scene: dict, seed: int) -> dict:
    """`scene` with a geared motor of random inertia, gear and axis on every hinge but the first
    body's (its second body made a hinge when it is not one) and a spring on every hinge."""
    from test.dynamics.test_kernel import chain_scene  # noqa: F401 (the scenes' home)

    scene = copy.deepcopy(scene)
    rng = np.random.default_rng(seed)
    if all(b["joint"]["type"] != "hinge" for b in scene["bodies"][1:]):
        scene["bodies"][1]["joint"] = {"type": "hinge", "axis": [0.3, 1.0, 0.2]}
        scene["bodies"][1]["initial"] = {"angle": 0.4, "rate": -0.7}
    for b in scene["bodies"][1:]:
        if b["joint"]["type"] == "hinge":
            b["joint"]["motor"] = {"inertia": float(rng.uniform(1e-5, 1e-3)), "gear": float(rng.choice([-1, 1])
                                                                                         * rng.uniform(5, 100)),
                                   "axis": rng.normal(size=3).tolist()}
            b["joint"]["spring"] = {"stiffness": float(rng.uniform(0.1, 3.0)), "reference": float(rng.normal())}
    return scene


def motor_chain(seed: int, base: str, heavy: bool = False) -> dict:
    from test.dynamics.test_kernel import chain_scene

    scene = with_motors(chain_scene(seed, base, n=5), seed)
    if heavy:
        tip = scene["bodies"][-1]
        tip["mass"] *= 1e3
        tip["inertia_com"] = (np.asarray(tip["inertia_com"]) * 1e3).tolist()
    return scene


@needs_numba
@pytest.mark.parametrize("base", ["fixed", "free", "moving"])
@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("heavy", [False, True])
def test_kernel_equals_reference(seed, base, heavy):
    """Both eliminations (a 1e3 x heavier tip takes the square-root form) with geared motors on
    every hinge past the first body, random commands and states."""
    from test.dynamics.test_kernel import assert_rhs_equal

    model = compile_model(load_scene(motor_chain(seed, base, heavy)))
    assert model.motor is not None
    assert fast.heavy_subtrees(model.mass) == heavy  # the kernel's heavy-subtree path, or not
    rng = np.random.default_rng(seed)
    ref, comp = ChainODE(model), FastChainODE(model)
    tau = rng.normal(size=len(model.hinge_bodies))
    for ode in (ref, comp):
        ode.hold(0.1, ref.spins(0.1), tau, None)
    for _ in range(3):
        y = initial_state(model) + rng.normal(size=model.size) * 0.3
        assert_rhs_equal(model, ref.rhs(0.4, y), comp.rhs(0.4, y), rtol=1e-9 if heavy else 1e-12)


@needs_numba
@pytest.mark.parametrize("base", ["fixed", "free"])
def test_compiled_outputs_equal_the_reference(base):
    """The publication kernel's invariants (the rotors' energy and spins) and wrenches (their
    moments on the parents) against the numpy reference's."""
    scene = motor_chain(1, base)
    sims = [Simulator(scene, backend=b) for b in ("numpy", "numba")]
    for sim in sims:
        sim.set_axis_moments(np.linspace(-0.5, 0.5, len(sim.axis_names)))
        sim.advance(0.05)
    np.testing.assert_allclose(sims[1].state, sims[0].state, rtol=0, atol=1e-9)
    a, b = (sim.invariants() for sim in sims)
    for name in a:
        np.testing.assert_allclose(b[name], a[name], rtol=1e-9, atol=1e-12, err_msg=name)
    (fa, ma), (fb, mb) = (np.array([[w.force for w in sim.wrenches()], [w.moment for w in sim.wrenches()]])
                          for sim in sims)
    np.testing.assert_allclose(fb, fa, rtol=1e-9, atol=1e-9 * np.abs(fa).max())
    np.testing.assert_allclose(mb, ma, rtol=1e-9, atol=1e-9 * np.abs(ma).max())


_STABLE_WITH_MOTORS = """
import sys
import numpy as np
sys.path.insert(0, sys.argv[1])
from gyro_sim.dynamics import kernel as fast
fast.STABLE_ABA_RATIO = -1.0  # every elimination takes the square-root form (plain Python)
from gyro_sim import load_scene
from gyro_sim.dynamics.model import compile_model, initial_state
from gyro_sim.dynamics.system import ChainODE
from test.dynamics.test_geared_motor import motor_chain
worst = 0.0
for base in ("fixed", "free", "moving"):
    for seed in range(3):
        rng = np.random.default_rng(seed)
        model = compile_model(load_scene(motor_chain(seed, base)))
        chain, data, inputs = fast.records(model)
        y = initial_state(model) + rng.normal(size=model.size) * 0.2
        tau = rng.normal(size=len(model.hinge_bodies))
        ref = ChainODE(model)
        ref.hold(0.0, ref.spins(0.0), tau, None)
        fast.hold(inputs, model, 0.0, ref.spins(0.0), tau, None)
        out = np.zeros(model.size)
        fast.rhs_kernel(0.2, y, out, chain, data, inputs)
        want = ref.rhs(0.2, y)
        worst = max(worst, float(np.abs(out - want).max() / np.abs(want).max()))
print(worst)
"""


@pytest.mark.slow
def test_the_square_root_elimination_takes_the_motors(tmp_path):
    """`_aba_stable` (the parent's own factor without the locked rotor, the child's factor with
    it and one more row, W = (U + m) / D, the refinement's residual with the motors' rows),
    forced on every chain in plain Python (numba off), against the numpy reference."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    env = dict(os.environ, NUMBA_DISABLE_JIT="1", PYTHONPATH=str(root))
    run = subprocess.run([sys.executable, "-c", _STABLE_WITH_MOTORS, str(root)], env=env, cwd=tmp_path,
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    assert float(run.stdout.strip().splitlines()[-1]) <= 1e-12


@pytest.mark.parametrize("backend", ["numpy", pytest.param("numba", marks=needs_numba)])
def test_the_joints_transmit_the_commands(backend):
    """Eq (51) at the turntable's hinge (the motor's parent: its rotor is inside the subtree,
    e^1 . L^1 = L_1) and eq (51b) at the arm's (e^2 . L^2 = L_2 - J G (a . w1' + G phi_2''), the
    torque that spins the rotor stays between the parent and the motor), with the accelerations
    of the hand-written Lagrangian."""
    sim = Simulator(turntable(), backend=backend)
    tau = np.array([0.7, -0.4])
    sim.set_axis_moments(tau)
    wrench = sim.wrenches()
    q, qd = np.array([0.2, 0.3]), np.array([3.0, 0.5])
    qdd = lagrange_accelerations(q, qd, tau)
    a = A_MOTOR / np.linalg.norm(A_MOTOR)
    rotor = J_ROTOR * GEAR * (a[2] * qdd[0] + GEAR * qdd[1])  # a . w1' = a_z theta1'' (a in body 1's axes)
    assert wrench[0].moment[2] == pytest.approx(tau[0], rel=1e-12)
    assert wrench[1].moment @ E2 == pytest.approx(tau[1] - rotor, rel=1e-10)


def test_linearisation_matches_the_lagrangian():
    """`linearize` (complex steps through the reference) against central differences of the
    hand-written Lagrangian's accelerations."""
    sim = Simulator(turntable(), backend="numpy")
    A = sim.linearize().A
    x0, h = np.array([0.2, 0.3, 3.0, 0.5]), 1e-6
    columns = []
    for k in range(4):
        dx = np.zeros(4)
        dx[k] = h
        columns.append((lagrange_accelerations((x0 + dx)[:2], (x0 + dx)[2:])
                        - lagrange_accelerations((x0 - dx)[:2], (x0 - dx)[2:])) / (2 * h))
    np.testing.assert_allclose(A[2:4], np.array(columns).T, rtol=1e-6, atol=1e-7)


@pytest.mark.parametrize("integrator", ["rk4", "dop853", "radau", "gauss4", "gauss4s", "lie4", "fixed", "auto"])
def test_every_integrator_takes_motors(integrator):
    """A tenth of a second of the turntable with each: its angles and rates within 1e-6 of the
    hand-written Lagrangian's motion."""
    sim = Simulator(turntable(), integrator=integrator, step=1e-3, backend="numpy")
    sim.advance(0.1)

    def f(t, x):
        return np.concatenate((x[2:], lagrange_accelerations(x[:2], x[2:])))

    ref = solve_ivp(f, (0.0, 0.1), [0.2, 0.3, 3.0, 0.5], method="DOP853", rtol=1e-12, atol=1e-12).y[:, -1]
    model = sim.model
    np.testing.assert_allclose(np.concatenate((sim.state[model.i_phi], sim.state[model.i_vel])), ref,
                               rtol=0, atol=1e-6)


def test_the_mujoco_peer_skips_motors():
    """The accuracy report's MuJoCo peer has no exact gear: a scene with a motor is skipped, with
    the reason, not run without its motor."""
    from gyro_sim.bench import peers

    assert "geared motor of arm" in peers.mujoco_unsupported(load_scene(turntable()))


@pytest.mark.parametrize("backend", ["numpy", pytest.param("numba", marks=needs_numba)])
def test_the_commands_work_is_the_energy_gained(backend):
    """The command is the joint's moment (G x the motor's torque): its work L_k (phi_k(t) -
    phi_k(0)) is the change of the energy, the rotor's included, under gravity."""
    sim = Simulator(turntable(), integrator="dop853", rtol=1e-12, atol=1e-12, backend=backend)
    e0 = sim.invariants()["energy"]
    sim.set_axis_moments([0.3, -0.2])
    sim.advance(0.5)
    assert sim.invariants()["energy"] - e0 == pytest.approx(sim.work, rel=1e-9)
    assert abs(sim.work) > 1e-2
