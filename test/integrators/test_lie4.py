"""lie4's arithmetic (gyro_sim.integrators.lie4.kernels) and its compiled march (gyro_sim.integrators.lie4.loop)
against independent references: rotations.quat_exp and quat_mul, a textbook CF4 written here
with numpy on the same right-hand side, and the Python driver of the same method (Lie4._step)
on the same system, bit for bit; every shipped scene the same after 0.2 s either way.

Measured when written: the kernel quat_exp equals rotations.quat_exp bit for bit on 20000
random vectors (1e-12 to 1e3 rad; asserted to 2 ulps, numpy's sin/cos may differ elsewhere);
the kernels' lie4 and the former numpy step differ by <= 5.4e-15 relative on every shipped
scene after 0.2 s (round-off of the reordered sums). Order 4: test_integrators.py (Python
driver, rigid body) and test_orders.py (the compiled march, through Simulator)."""
import numpy as np
import pytest

from gyro_sim import load_scene
from gyro_sim.dynamics import kernel as fast
from gyro_sim.integrators.lie4 import loop as fast_lie
from gyro_sim import jit
from gyro_sim.integrators.lie4 import kernels as lk
from gyro_sim.integrators import IntegrationError, make_integrator
from gyro_sim.integrators.lie4.driver import Lie4
from gyro_sim.dynamics.model import compile_model, initial_state
from gyro_sim.dynamics.rotations import quat_conj, quat_exp, quat_mul, quat_to_matrix
from gyro_sim.simulator import Simulator
from gyro_sim.dynamics.system import ChainODE, FastChainODE
from gyro_sim.paths import shipped_scenes
from test.integrators.package_paths import in_package

from test.dynamics.chains import random_chain

needs_numba = pytest.mark.skipif(not fast.available(), reason="numba is not installed")

EPS = np.finfo(float).eps
#: textbook vs lie4 after a few steps: round-off of the sums, relative to max |y|
TEXTBOOK_RTOL = 1e-13


# ------------------------------------------------------------------ references
def textbook_cf4(f, quat_index, project, t, y, h, n):
    """n steps of CF4 (Celledoni, Marthinsen, Owren 2003), numpy: quaternion blocks y[qi]
    (nq, 4) moved by q <- exp(theta) (x) q, the rest by translation; renormalised after each."""
    qi = np.asarray(quat_index).reshape(-1, 4)
    li = np.setdiff1d(np.arange(y.size), qi.ravel())

    def field(t, Y):
        d = f(t, Y)
        return 2.0 * quat_mul(d[qi], quat_conj(Y[qi]))[:, 1:], d[li]  # omega, the rest of y'

    def act(F, Y):
        Z = Y.copy()
        Z[qi] = quat_mul(quat_exp(F[0]), Y[qi])
        Z[li] = Y[li] + F[1]
        return Z

    def comb(*terms):  # sum of c F_i over (c, F_i)
        return tuple(sum(c * Fi[part] for c, Fi in terms) for part in (0, 1))

    y = y.copy()
    for k in range(n):
        tk = t + k * h
        F1 = field(tk, y)
        Y2 = act(comb((h / 2, F1)), y)
        F2 = field(tk + h / 2, Y2)
        Y3 = act(comb((h / 2, F2)), y)
        F3 = field(tk + h / 2, Y3)
        Y4 = act(comb((h, F3), (-h / 2, F1)), Y2)
        F4 = field(tk + h, Y4)
        y = act(comb((h / 4, F1), (h / 6, F2), (h / 6, F3), (-h / 12, F4)), y)
        y = act(comb((-h / 12, F1), (h / 6, F2), (h / 6, F3), (h / 4, F4)), y)
        project(y)
    return y


class RigidBody:
    """Torque-free rigid body, y = (q world from body, omega body), principal inertia I."""

    size = 7
    quat_index = np.arange(4).reshape(1, 4)

    def __init__(self, inertia):
        self.I = np.asarray(inertia, dtype=float)

    def rhs(self, t, y):
        q, w = y[:4], y[4:]
        w_world = quat_to_matrix(q) @ w
        return np.concatenate([0.5 * quat_mul(np.concatenate([[0.0], w_world]), q),
                               np.cross(self.I * w, w) / self.I])

    def project(self, y):
        y[:4] /= np.linalg.norm(y[:4])


def held_system(scene, seed=0):
    """A FastChainODE of `scene` with random held inputs and velocities (as test_rk4_loop)."""
    model = compile_model(load_scene(scene))
    system = FastChainODE(model)
    rng = np.random.default_rng(seed)
    nt, nh = len(model.torque_body), len(model.hinge_bodies)
    system.hold(0.1, rng.uniform(-50, 50, nt) if nt else None,
                rng.normal(size=nh) if nh else None, rng.normal(size=nt) * 1e-2 if nt else None)
    y = initial_state(model)
    y[model.i_vel] += rng.normal(size=model.N) * 0.3
    return system, y


def python_driver(system, **options):
    """Lie4 stepping in Python on `system` (the compiled march off)."""
    integ = Lie4(system, **options)
    integ.use_compiled = False
    return integ


# ------------------------------------------------------------------ the kernels
def test_quat_exp_kernel_is_rotations_quat_exp():
    """One exponential for both drivers; rotations.quat_exp (numpy) is its reference: equal to
    round-off from 1e-12 rad to 1e3 rad, on both sides of the series' threshold."""
    rng = np.random.default_rng(1)
    dirs = rng.normal(size=(400, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    angles = np.concatenate([10.0 ** rng.uniform(-12, 3, 380), [0.0, 1e-8, 1e-8 * (1 - EPS),
                             1e-8 * (1 + EPS), np.pi, 2 * np.pi] + [1e-8] * 14])
    theta = dirs * angles[:, None]
    got = np.array([lk.quat_exp(*v) for v in theta])
    want = quat_exp(theta)
    np.testing.assert_allclose(got, want, rtol=0, atol=2 * EPS)
    assert np.abs(np.linalg.norm(got, axis=1) - 1).max() <= 2 * EPS


def test_field_and_action_kernels_are_the_quaternion_formulas():
    """omega = 2 vec(q' (x) conj q) (lie_field) and e (x) q (quat_left) as rotations.quat_mul."""
    rng = np.random.default_rng(2)
    nq, nl = 3, 5
    n = 4 * nq + nl
    qi = rng.permutation(n)[:4 * nq].reshape(nq, 4).astype(np.int64)
    li = np.setdiff1d(np.arange(n), qi.ravel()).astype(np.int64)
    Y, f = rng.normal(size=(4, n)), rng.normal(size=n)
    W, V = np.zeros((4, nq, 3)), np.zeros((4, nl))
    lk.lie_field(Y, f, 2, qi, li, W, V)
    np.testing.assert_allclose(W[2], 2 * quat_mul(f[qi], quat_conj(Y[2][qi]))[:, 1:], rtol=0,
                               atol=8 * EPS)
    np.testing.assert_array_equal(V[2], f[li])
    e, q = rng.normal(size=4), Y[1].copy()
    lk.quat_left(*e, q, qi[1])
    np.testing.assert_array_equal(q[qi[1]], quat_mul(e, Y[1][qi[1]]))  # the same operations
    np.testing.assert_array_equal(np.delete(q, qi[1]), np.delete(Y[1], qi[1]))


def test_python_driver_is_the_textbook_cf4_on_a_rigid_body():
    body = RigidBody([1.0, 2.0, 3.0])
    y0 = np.concatenate([quat_exp(np.array([0.3, -0.2, 0.5])), [0.4, 1.5, -0.7]])
    h, n = 0.01, 20
    want = textbook_cf4(body.rhs, body.quat_index, body.project, 0.0, y0, h, n)
    got = make_integrator("lie4", body, step=h).advance(0.0, y0, n * h)
    assert np.max(np.abs(got - want)) <= TEXTBOOK_RTOL * np.max(np.abs(want))


@needs_numba
@pytest.mark.parametrize("scene", ("heavy_top", "chain_4", "free_chain_rotors", "hinge_chain"))
def test_both_drivers_are_the_textbook_cf4(scene):
    """A top (one rigid body) and chains: the compiled march and the Python driver on the
    same FastChainODE against the textbook CF4 on its rhs."""
    system, y0 = held_system(scene)
    h, n = 1e-3, 7
    want = textbook_cf4(system.rhs, system.quat_index, system.project, 0.1, y0, h, n)
    for integ in (Lie4(system, step=h), python_driver(system, step=h)):
        got = integ.advance(0.1, y0, 0.1 + n * h)
        assert np.max(np.abs(got - want)) <= TEXTBOOK_RTOL * np.max(np.abs(want))
        assert integ.nsteps == n and integ.nfev == 4 * n


# ------------------------------------------------------------------ the two drivers
@needs_numba
@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("base", ("fixed", "free"))
def test_compiled_march_equals_the_python_driver_bit_for_bit(seed, base):
    """The same arithmetic (lie_kernels) between the same kernel calls, from compiled code or
    from Python: identical bits, with t_eval stops on the way."""
    system, y0 = held_system(random_chain(seed, base=base), seed)
    compiled, python = Lie4(system, step=1e-3), python_driver(system, step=1e-3)
    assert compiled._compiled is not None  # the march is what is tested
    te = np.array([0.1, 0.1037, 0.11])
    a, A = compiled.advance(0.1, y0, 0.125, t_eval=te)
    b, B = python.advance(0.1, y0, 0.125, t_eval=te)
    assert np.array_equal(a, b) and np.array_equal(A, B)
    assert compiled.nsteps == python.nsteps and compiled.nfev == python.nfev


@needs_numba
def test_the_march_takes_the_coefficients_of_the_class():
    """The coefficients are class data both drivers read: a subclass with the output's
    exponentials swapped (order 2) steps the same in both, and differently from Lie4."""
    class Swapped(Lie4):
        BETA1, BETA2 = Lie4.BETA2, Lie4.BETA1

    system, y0 = held_system("chain_4")
    compiled, python = Swapped(system, step=1e-3), Swapped(system, step=1e-3)
    python.use_compiled = False
    a = compiled.advance(0.1, y0, 0.11)
    assert np.array_equal(a, python.advance(0.1, y0, 0.11))
    assert not np.array_equal(a, Lie4(system, step=1e-3).advance(0.1, y0, 0.11))


@needs_numba
def test_the_numpy_reference_system_agrees_to_round_off():
    """The Python driver on ChainODE (numpy rhs) and the compiled march on FastChainODE: the
    same method, the rhs differing in round-off only."""
    model = compile_model(load_scene(random_chain(5, base="free")))
    y0 = initial_state(model)
    slow, fast_ = ChainODE(model), FastChainODE(model)
    a = Lie4(slow, step=1e-3).advance(0.0, y0, 0.025)
    b = Lie4(fast_, step=1e-3).advance(0.0, y0, 0.025)
    assert np.max(np.abs(a - b)) <= 1e-12 * np.max(np.abs(b))


#: the shipped scenes lie4 steps (speed-dependent actuator terms are refused by it: test_actuators)
SCENE_NAMES = [p.stem for p in shipped_scenes() if not compile_model(load_scene(p)).stateful]


@needs_numba
@pytest.mark.parametrize("name", SCENE_NAMES)
def test_every_shipped_scene_same_state_after_0_2_s(name):
    """Simulator(name, "lie4", 1 ms) for 0.2 s in 10 ms advances (commands held where the
    scene has axes): the compiled march and the Python driver on the same FastChainODE give
    the same state, bit for bit; quaternions unit."""
    sims = [Simulator(name, integrator="lie4", step=1e-3) for _ in range(2)]
    assert isinstance(sims[0].system, FastChainODE)
    sims[1].integrator.use_compiled = False
    for sim in sims:
        if sim.axis_names:
            sim.set_axis_moments(0.01 * np.ones(len(sim.axis_names)))
        for _ in range(20):
            sim.advance(0.01)
    a, b = sims[0].state, sims[1].state
    assert np.array_equal(a, b), np.max(np.abs(a - b))
    qi = sims[0].model.i_quat
    if len(qi):
        assert np.abs(np.linalg.norm(a[qi], axis=1) - 1).max() <= 4 * EPS


class Unprojected:
    """A FastChainODE's rhs with a `project` that only records how far |q| is from 1 (the
    Python driver's only way to see the state before the projection)."""

    def __init__(self, system):
        self.system, self.size, self.quat_index = system, system.size, system.quat_index
        self.worst = 0.0

    def rhs(self, t, y):
        return self.system.rhs(t, y)

    def project(self, y):
        self.worst = max(self.worst, np.abs(np.linalg.norm(y[self.quat_index], axis=1) - 1).max())


@needs_numba
def test_quaternions_stay_unit_without_projection():
    """CF4 moves quaternions by unit quaternions: over 0.3 s of a free chain with rotors and
    no renormalisation, |q| stays 1 to round-off."""
    system, y0 = held_system("free_chain_rotors")
    watch = Unprojected(system)
    Lie4(watch, step=1e-3).advance(0.1, y0, 0.4)
    assert 0 < watch.worst <= 1e-14


@needs_numba
def test_non_finite_state_stops_both_drivers_at_the_same_step():
    system, y0 = held_system("chain_4")
    y0 = y0.copy()
    y0[system.model.i_vel.start] = 1e200  # overflows within a few steps
    failures = []
    for integ in (Lie4(system, step=1e-3), python_driver(system, step=1e-3)):
        with pytest.raises(IntegrationError, match="not finite after the step") as info:
            integ.advance(0.0, y0, 0.05)
        failures.append((integ.nsteps, info.value.t, integ.nfev))
    k = failures[0][0]
    assert failures[0] == failures[1]
    assert k < 50 and failures[0][1] == pytest.approx(k * 1e-3, abs=1e-15)


@needs_numba
def test_march_counts_and_last_step():
    system, y0 = held_system("hinge_chain")
    integ = make_integrator("lie4", system, step=1e-3)
    before = system.nfev
    integ.advance(0.0, y0, 0.0105)
    assert integ.nsteps == 11 and integ.nfev == 44 and system.nfev - before == 44
    assert integ.last_step == pytest.approx(0.0105 / 11, rel=1e-15)


def test_march_cache_is_keyed_on_every_file_it_compiles_in():
    names = {in_package(p) for p in fast_lie.DEPENDENCIES}
    assert names == {"dynamics/kernel.py", "dynamics/actuators.py", "integrators/lie4/kernels.py",
                     "integrators/rk4/loop.py",
                     "integrators/lie4/loop.py"}
    assert jit.cache_directory(fast_lie.DEPENDENCIES).name.startswith("fast_loop-")
