"""The compiled fixed-step loop (gyro_sim.integrators.rk4.loop, rk_kernels) against independent
references: a textbook RK4 written here on the same right-hand side, and the Python driver of
the same method (RK4._step) on the same system, bit for bit."""
import math

import numpy as np
import pytest

from gyro_sim import load_scene
from gyro_sim.dynamics import kernel as fast
from gyro_sim import jit
from gyro_sim.integrators.rk4 import loop as fast_loop
from gyro_sim.integrators import IntegrationError, make_integrator
from gyro_sim.integrators.rk4.driver import RK4
from gyro_sim.dynamics.model import compile_model, initial_state
from gyro_sim.integrators.rk4.kernels import erk_stage_state, erk_update
from gyro_sim.dynamics.system import FastChainODE

from .chains import random_chain

pytestmark = pytest.mark.skipif(not fast.available(), reason="numba is not installed")

SCENES = ("chain_4", "hinge_chain", "free_chain_rotors", "vibrating_base", "speed_rotor_top", "fast_rotor")
#: textbook vs compiled RK4 after a few steps: round-off of the sums, relative to max |y|
TEXTBOOK_RTOL = 1e-13


def textbook_rk4(f, project, t, y, h, n):
    """n classical RK4 steps (Hairer-Norsett-Wanner I, II.1), quaternions renormalised after each."""
    y = y.copy()
    for k in range(n):
        tk = t + k * h
        k1 = f(tk, y)
        k2 = f(tk + h / 2, y + h / 2 * k1)
        k3 = f(tk + h / 2, y + h / 2 * k2)
        k4 = f(tk + h, y + h * k3)
        y = y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        project(y)
    return y


def held_system(scene, seed=0):
    model = compile_model(load_scene(scene))
    system = FastChainODE(model)
    rng = np.random.default_rng(seed)
    nt, nh = len(model.torque_body), len(model.hinge_bodies)
    system.hold(0.1, rng.uniform(-50, 50, nt) if nt else None,
                rng.normal(size=nh) if nh else None, rng.normal(size=nt) * 1e-2 if nt else None)
    y = initial_state(model)
    y[model.i_vel] += rng.normal(size=model.N) * 0.3
    return system, y


@pytest.mark.parametrize("scene", SCENES)
def test_compiled_rk4_is_the_textbook_rk4(scene):
    system, y0 = held_system(scene)
    h, n = 1e-3, 7
    want = textbook_rk4(system.rhs, system.project, 0.1, y0, h, n)
    integ = make_integrator("rk4", system, step=h)
    got = integ.advance(0.1, y0, 0.1 + n * h)
    assert np.max(np.abs(got - want)) <= TEXTBOOK_RTOL * np.max(np.abs(want))
    assert integ.nsteps == n and integ.nfev == 4 * n


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("base", ("fixed", "free"))
def test_compiled_march_equals_the_python_driver_bit_for_bit(seed, base):
    """The same arithmetic (rk_kernels) between the same kernel calls, from compiled code or
    from Python: identical bits."""
    system, y0 = held_system(random_chain(seed, base=base), seed)
    compiled = RK4(system, step=1e-3)
    python = RK4(system, step=1e-3)
    python._march_system = None  # noqa: SLF001 - the Python driver on the same system
    assert np.array_equal(compiled.advance(0.1, y0, 0.125), python.advance(0.1, y0, 0.125))


def test_non_finite_state_stops_the_march_at_the_failing_step():
    system, y0 = held_system("chain_4")
    integ = make_integrator("rk4", system, step=1e-3)
    y0 = y0.copy()
    y0[system.model.i_vel.start] = 1e200  # overflows within a few steps
    with pytest.raises(IntegrationError, match="not finite after the step") as info:
        integ.advance(0.0, y0, 0.05)
    k = integ.nsteps
    assert k < 50 and info.value.t == pytest.approx(k * 1e-3, abs=1e-15)


def test_erk_arithmetic_is_the_formula():
    rng = np.random.default_rng(3)
    K, y = rng.normal(size=(4, 9)), rng.normal(size=9)
    hA = 1e-3 * RK4.A
    ys = np.empty(9)
    for s in range(1, 4):
        erk_stage_state(y, K, hA, s, ys)
        want = y + sum(hA[s, j] * K[j] for j in range(s))
        np.testing.assert_array_equal(ys, want)  # one nonzero term per stage: exact
    y1 = y.copy()
    erk_update(y1, K, 1e-3 * RK4.B)
    want = y + (((1e-3 * RK4.B[0] * K[0] + 1e-3 * RK4.B[1] * K[1]) + 1e-3 * RK4.B[2] * K[2])
                + 1e-3 * RK4.B[3] * K[3])
    np.testing.assert_array_equal(y1, want)  # in increasing j, one term at a time


def test_loop_cache_is_keyed_on_every_file_it_compiles_in(tmp_path):
    first = jit.cache_directory(fast_loop.DEPENDENCIES)
    assert first.name.startswith("fast_loop-")
    copies = []
    for p in fast_loop.DEPENDENCIES:
        c = tmp_path / p.name
        c.write_bytes(p.read_bytes())
        copies.append(c)
    assert jit.cache_directory(copies) == first
    copies[0].write_bytes(copies[0].read_bytes() + b"\n# an edit of fast.py\n")
    assert jit.cache_directory(copies) != first


def test_step_count_and_last_step_as_the_python_path():
    system, y0 = held_system("hinge_chain")
    integ = make_integrator("rk4", system, step=1e-3)
    integ.advance(0.0, y0, 0.0105)
    assert integ.nsteps == 11 and math.isclose(integ.last_step, 0.0105 / 11)
