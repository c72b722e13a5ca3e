"""A hinge's armature (MuJoCo's reflected rotor inertia) and joint spring (docs/theory.md,
"Armature and joint springs"): the compiled kernel and the canonical form against the numpy
reference, closed forms of a spring pendulum and of the moment the joint transmits, the energy
kept, the linearisation's frequency, and scenes without them unchanged bit for bit."""
import copy
import math

import numpy as np
import pytest

from gyro_sim import Simulator, load_scene
from gyro_sim.dynamics import kernel as fast
from gyro_sim.dynamics.canonical import CanonicalChain
from gyro_sim.dynamics.model import compile_model, initial_state
from gyro_sim.dynamics.system import ChainODE, FastChainODE

from test.dynamics.test_kernel import assert_rhs_equal, chain_scene

needs_numba = pytest.mark.skipif(not fast.available(), reason="numba is not installed")

#: the pendulum: a rod of moment I about its hinge, armature a, spring k relaxed at REF
I_HINGE, ARMATURE, STIFFNESS, REF, AMPLITUDE = 0.02, 0.005, 0.8, 0.3, 0.4


def with_joint_terms(scene: dict, seed: int) -> dict:
    """`scene` with a random armature and spring on every hinge (its last body made a hinge
    when it has none)."""
    scene = copy.deepcopy(scene)
    rng = np.random.default_rng(seed)
    if all(b["joint"]["type"] != "hinge" for b in scene["bodies"]):
        scene["bodies"][-1]["joint"] = {"type": "hinge", "axis": [0.3, 1.0, 0.2]}
        scene["bodies"][-1]["initial"] = {"angle": 0.4, "rate": -0.7}
    for b in scene["bodies"]:
        if b["joint"]["type"] == "hinge":
            b["joint"]["armature"] = float(rng.uniform(1e-3, 0.05))
            b["joint"]["spring"] = {"stiffness": float(rng.uniform(0.1, 3.0)), "reference": float(rng.normal())}
    return scene


def pendulum(armature=ARMATURE, stiffness=STIFFNESS, gravity=None) -> dict:
    """One body on a hinge about z, its centre of mass on the axis, in zero gravity."""
    joint = {"type": "hinge", "axis": [0.0, 0.0, 1.0]}
    if armature is not None:
        joint["armature"] = armature
    if stiffness is not None:
        joint["spring"] = {"stiffness": stiffness, "reference": REF}
    scene = {"name": "spring pendulum", "base": {"type": "fixed", "position": [0, 0, 0]},
             "bodies": [{"name": "rod", "joint": joint, "mass": 1.0, "com": [0.0, 0.0, 0.0],
                         "inertia_com": [[0.03, 0, 0], [0, 0.03, 0], [0, 0, I_HINGE]],
                         "initial": {"angle": REF + AMPLITUDE, "rate": 0.0}}]}
    if gravity is not None:
        scene["gravity"] = gravity
    return scene


@needs_numba
@pytest.mark.parametrize("base", ["fixed", "free", "moving"])
@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("heavy", [False, True])
def test_kernel_equals_reference(seed, base, heavy):
    """Both eliminations (a 1e3 x heavier tip takes the square-root form) with armatures and
    springs on every hinge, random commands and states."""
    scene = with_joint_terms(chain_scene(seed, base, n=5), seed)
    if heavy:
        tip = scene["bodies"][-1]
        tip["mass"] *= 1e3
        tip["inertia_com"] = (np.asarray(tip["inertia_com"]) * 1e3).tolist()
    model = compile_model(load_scene(scene))
    assert model.armature is not None and model.spring is not None
    assert fast.heavy_subtrees(model.mass) == heavy  # the kernel's heavy-subtree path, or not
    rng = np.random.default_rng(seed)
    ref, comp = ChainODE(model), FastChainODE(model)
    tau = rng.normal(size=len(model.hinge_bodies))
    for ode in (ref, comp):
        ode.hold(0.1, ref.spins(0.1), tau, None)
    for _ in range(3):
        y = initial_state(model) + rng.normal(size=model.size) * 0.3
        assert_rhs_equal(model, ref.rhs(0.4, y), comp.rhs(0.4, y), rtol=1e-9 if heavy else 1e-12)


def test_zero_armature_and_stiffness_change_no_bit():
    """armature: 0 and a spring of stiffness 0 compile to the model without them."""
    plain = chain_scene(3, "free", n=4)
    zero = copy.deepcopy(plain)
    for b in zero["bodies"]:
        if b["joint"]["type"] == "hinge":
            b["joint"]["armature"] = 0.0
            b["joint"]["spring"] = {"stiffness": 0.0, "reference": 1.0}
    a, b = compile_model(load_scene(plain)), compile_model(load_scene(zero))
    assert b.armature is None and b.spring is None
    y = initial_state(a) + np.random.default_rng(0).normal(size=a.size) * 0.3
    systems = [ChainODE] + ([FastChainODE] if fast.available() else [])
    for system in systems:
        np.testing.assert_array_equal(system(a).rhs(0.2, y), system(b).rhs(0.2, y))


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_spring_pendulum_oscillates_at_the_closed_form_frequency(backend):
    """phi = REF + AMPLITUDE cos(omega t), omega = sqrt(k / (I + a)), to 1e-9 over a few periods;
    the energy 1/2 (I + a) phi'^2 + 1/2 k (phi - REF)^2 kept to 1e-10 by a tight dop853."""
    if backend == "numba" and not fast.available():
        pytest.skip("numba is not installed")
    sim = Simulator(pendulum(), integrator="dop853", rtol=1e-13, atol=1e-15, backend=backend)
    omega = math.sqrt(STIFFNESS / (I_HINGE + ARMATURE))
    e0 = 0.5 * STIFFNESS * AMPLITUDE ** 2
    assert sim.invariants()["energy"] == pytest.approx(e0, rel=1e-15)
    for _ in range(8):
        sim.advance(0.37)
        t = sim.time
        phi, rate = sim.joint_states().position[0], sim.joint_states().velocity[0]
        assert abs(phi - (REF + AMPLITUDE * math.cos(omega * t))) <= 1e-9
        assert abs(rate + AMPLITUDE * omega * math.sin(omega * t)) <= 1e-9 * omega
        inv = sim.invariants()
        assert abs(inv["energy"] - e0) <= 1e-10 * e0
        assert inv["kinetic"] == pytest.approx(0.5 * (I_HINGE + ARMATURE) * rate ** 2, rel=1e-12, abs=1e-15)


def test_the_joint_transmits_the_command_less_the_armatures_torque():
    """A commanded moment L on a hinge with armature a, no spring or gravity: phi'' = L / (I + a);
    the moment the joint passes to the body (eq 48, its wrench) is I phi'' = L I / (I + a): the
    armature's share a phi'' stays with the motor."""
    L = 0.3
    sim = Simulator(pendulum(stiffness=None), backend="numpy")
    sim.set_axis_moments([L])
    ydot = sim.held_rhs()(sim.time, sim.state)
    m = sim.model
    assert ydot[m.i_vel][0] == pytest.approx(L / (I_HINGE + ARMATURE), rel=1e-14)
    moment = sim.wrenches()[0].moment
    assert moment[2] == pytest.approx(L * I_HINGE / (I_HINGE + ARMATURE), rel=1e-13)


def test_linearised_spring_pendulum_has_the_closed_form_eigenvalues():
    scene = pendulum()
    scene["bodies"][0]["initial"] = {"angle": REF, "rate": 0.0}
    lin = Simulator(scene, backend="numpy").linearize()
    assert lin.is_equilibrium
    omega = math.sqrt(STIFFNESS / (I_HINGE + ARMATURE))
    got = sorted(lin.eigenvalues(), key=lambda z: z.imag)
    np.testing.assert_allclose(got, [-1j * omega, 1j * omega], rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("seed", range(3))
def test_canonical_form_with_armature_and_springs(seed):
    """The canonical momenta gain a phi' at each hinge: y -> z -> y is the identity, and the
    canonical field's rates are the package's (the compiled field's too, to round-off)."""
    scene = with_joint_terms(chain_scene(seed, "fixed" if seed != 1 else "free", n=4), seed)
    model = compile_model(load_scene(scene))
    ode = ChainODE(model)
    can = CanonicalChain(ode)
    rng = np.random.default_rng(seed)
    tau = rng.normal(size=len(model.hinge_bodies)) if len(model.hinge_bodies) else None
    ode.hold(0.0, ode.spins(0.0), tau, None)
    y = initial_state(model)
    z = can.momenta(0.2, y)
    np.testing.assert_allclose(can.state(0.2, z), y, rtol=1e-12, atol=1e-12)
    zdot = can.rhs(0.2, z)
    ydot = ode.rhs(0.2, y)
    np.testing.assert_allclose(zdot[can.i_phi], ydot[model.i_phi], rtol=1e-12, atol=1e-12)
    # p_phi' by finite differences of p_phi along the motion
    h = 1e-6
    zp, zm = can.momenta(0.2 + h, y + h * ydot), can.momenta(0.2 - h, y - h * ydot)
    np.testing.assert_allclose(zdot[can.i_pphi], (zp - zm)[can.i_pphi] / (2 * h), rtol=1e-6, atol=1e-6)
    if fast.available():
        from gyro_sim.dynamics.canonical_kernel import FastCanonicalChain

        fcan = FastCanonicalChain(FastChainODE(model))
        fcan.ode.hold(0.0, ode.spins(0.0), tau, None)
        np.testing.assert_allclose(fcan.rhs(0.2, z), zdot, rtol=1e-11, atol=1e-11)


def test_gauss4s_keeps_the_energy_of_a_spring_chain():
    """gauss4s (symplectic, canonical form) on a hinge chain with armatures and springs under
    gravity: the energy error stays bounded at the step's order, no drift."""
    scene = with_joint_terms(chain_scene(0, "fixed", n=3, speed_rotors=False, commands=False), 5)
    sim = Simulator(scene, integrator="gauss4s", step=1e-3,
                    backend="numba" if fast.available() else "numpy")
    e0 = sim.invariants()["energy"]
    worst = 0.0
    for _ in range(10):
        sim.advance(0.1)
        worst = max(worst, abs(sim.invariants()["energy"] - e0))
    assert worst <= 1e-8 * max(1.0, abs(e0))


_STABLE_WITH_ARMATURE = """
import sys
import numpy as np
sys.path.insert(0, sys.argv[1])
from gyro_sim.dynamics import kernel as fast
fast.STABLE_ABA_RATIO = -1.0  # every elimination takes the square-root form (plain Python)
from gyro_sim import load_scene
from gyro_sim.dynamics.model import compile_model, initial_state
from gyro_sim.dynamics.system import ChainODE
from test.dynamics.test_joint_terms import with_joint_terms
from test.dynamics.test_kernel import chain_scene
worst = 0.0
for base in ("fixed", "free", "moving"):
    for seed in range(2):
        rng = np.random.default_rng(seed)
        model = compile_model(load_scene(with_joint_terms(chain_scene(seed, base, n=5), seed)))
        chain, data, inputs = fast.records(model)
        y = initial_state(model) + rng.normal(size=model.size) * 0.2
        tau = rng.normal(size=len(model.hinge_bodies)) if len(model.hinge_bodies) else None
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
def test_the_square_root_elimination_takes_the_armature(tmp_path):
    """`_aba_stable` (its factor passed on gains the row sqrt(a D0 / D) U / D0, W scales by
    D0 / D, the refinement's residual counts a phi''), forced on every chain in plain Python
    (numba off, the switch-over ratio below zero), against the numpy reference."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    env = dict(os.environ, NUMBA_DISABLE_JIT="1", PYTHONPATH=str(root))
    run = subprocess.run([sys.executable, "-c", _STABLE_WITH_ARMATURE, str(root)], env=env, cwd=tmp_path,
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    assert float(run.stdout.strip().splitlines()[-1]) <= 1e-12
