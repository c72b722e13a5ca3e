"""Slide joints (docs/theory.md section 12): a body translating along an axis of its parent.

Checked against what does not share the code: the cart-pole's equations of motion written by
hand (a 2 x 2 mass matrix from its Lagrangian), the energy integral of a closed chain of
slides and hinges under gravity, the force a slide transmits along its axis (eq 51's row for
a translation), and the numpy reference against the compiled articulated-body kernel (both
its forms: the classic elimination and the square-root form of heavy subtrees) at random
states of random chains with slides. MuJoCo's cart-pole: test/dynamics/test_slide_mujoco.py.
"""
from __future__ import annotations

import copy

import numpy as np
import pytest

from gyro_sim import Simulator, load_scene
from gyro_sim.dynamics import kernel as fast
from gyro_sim.dynamics.invariants import conserved
from gyro_sim.dynamics.model import compile_model, initial_state
from gyro_sim.dynamics.system import ChainODE, FastChainODE, heavy_subtree_ratio
from gyro_sim.scene.load import SceneError

from test.dynamics.chains import random_chain
from test.dynamics.test_kernel import BASES, MOVING_BASE, assert_rhs_equal, hold_random, random_state

#: the cart-pole: cart mass M, pole mass m, pivot to the pole's centre l, the pole's own
#: moment of inertia about its centre Ic, gravity g
M, m, L, IC, G = 1.3, 0.4, 0.7, 0.02, 9.81


def cart_pole(x=0.0, xd=0.0, th=0.0, thd=0.0, axis=(1.0, 0.0, 0.0), **joint) -> dict:
    """A cart on a slide along x, a pole hinged on it about y, upright at th = 0."""
    return {"name": "cart-pole", "gravity": [0.0, 0.0, -G], "base": {"type": "fixed"},
            "bodies": [
                {"name": "cart", "joint": {"type": "slide", "axis": list(axis), **joint}, "mass": M,
                 "inertia_com": [[0.1, 0.0, 0.0], [0.0, 0.2, 0.0], [0.0, 0.0, 0.3]], "next_joint": [0.0, 0.0, 0.0],
                 "initial": {"position": x, "velocity": xd}},
                {"name": "pole", "joint": {"type": "hinge", "axis": [0.0, 1.0, 0.0]}, "mass": m,
                 "com": [0.0, 0.0, L], "inertia_com": [[IC, 0.0, 0.0], [0.0, IC, 0.0], [0.0, 0.0, IC]],
                 "initial": {"angle": th, "rate": thd}}]}


def cart_pole_accelerations(th, thd, F, tau):
    """x'', th'' from the Lagrangian T = 1/2 (M + m) x'^2 + m l cos(th) x' th' + 1/2 (m l^2 +
    Ic) th'^2, V = m g l cos(th), with the force F on the cart and the moment tau on the pole
    (th about +y: the pole's centre at (x + l sin th, 0, l cos th))."""
    mass = np.array([[M + m, m * L * np.cos(th)], [m * L * np.cos(th), m * L * L + IC]])
    rhs = np.array([F + m * L * np.sin(th) * thd ** 2, tau + m * G * L * np.sin(th)])
    return np.linalg.solve(mass, rhs)


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_cart_pole_accelerates_as_its_lagrangian_says(backend):
    rng = np.random.default_rng(7)
    worst = 0.0
    for _ in range(8):
        x, xd, th, thd, F, tau = rng.uniform(-2.0, 2.0, 6)
        model = compile_model(load_scene(cart_pole(x, xd, th, thd)))
        ode = ChainODE(model) if backend == "numpy" else FastChainODE(model)
        ode.hold(0.0, None, np.array([F, tau]), None)
        y = initial_state(model)
        assert np.array_equal(y[model.i_phi], [x, th]) and np.array_equal(y[model.i_vel], [xd, thd])
        yd = ode.rhs(0.0, y)
        assert np.array_equal(yd[model.i_phi], [xd, thd])
        want = cart_pole_accelerations(th, thd, F, tau)
        worst = max(worst, float(np.max(np.abs(yd[model.i_vel] - want)) / np.max(np.abs(want))))
    assert worst <= 1e-12


def slide_chain(seed: int, base: str) -> dict:
    """random_chain with some bodies on slides along random axes (at least one; the first body
    too on a fixed or moving base), some of the slides with an armature (kg) and a spring (N/m)."""
    scene = random_chain(seed, base="free" if base == "free" else "fixed")
    if base == "moving":
        scene["base"] = copy.deepcopy(MOVING_BASE)
    rng = np.random.default_rng(1000 + seed)
    bodies = scene["bodies"]
    first = 1 if base == "free" else 0
    slides = [k for k in range(first, len(bodies)) if rng.random() < 0.5] or [len(bodies) - 1]
    if seed % 3 == 0 and base != "free":
        slides = sorted(set(slides) | {0})
    for k in slides:
        joint = {"type": "slide", "axis": rng.normal(size=3).tolist()}
        if rng.random() < 0.5:
            joint["armature"] = float(rng.uniform(0.0, 0.5))
            joint["spring"] = {"stiffness": float(rng.uniform(0.0, 30.0)), "reference": float(rng.normal() * 0.1)}
        bodies[k]["joint"] = joint
        bodies[k]["initial"] = {"position": float(rng.normal() * 0.2), "velocity": float(rng.normal())}
    return scene


@pytest.mark.parametrize("base", BASES)
@pytest.mark.parametrize("seed", range(9))
def test_kernel_equals_reference_on_chains_with_slides(seed, base):
    model = compile_model(load_scene(slide_chain(seed, base)))
    assert len(model.slide_bodies) and heavy_subtree_ratio(model) <= fast.STABLE_ABA_RATIO
    ref, fst = ChainODE(model), FastChainODE(model)
    rng = np.random.default_rng(seed)
    for _ in range(4):
        hold_random(rng, model, ref, fst)
        t = float(rng.uniform(-1.0, 1.0))
        y = random_state(rng, model)
        assert_rhs_equal(model, ref.rhs(t, y), fst.rhs(t, y))


def test_cases_cover_slides_everywhere():
    """The chains above put slides first, after spherical joints, after hinges and before them,
    with and without armature and springs, on every base."""
    models = [compile_model(load_scene(slide_chain(s, b))) for s in range(9) for b in BASES]
    assert any(m.is_slide[0] for m in models)
    assert any(m.is_slide[k] and not m.is_hinge[k - 1] for m in models for k in range(1, m.n))
    assert any(m.is_slide[k] and m.is_hinge[k - 1] and not m.is_slide[k - 1] for m in models for k in range(1, m.n))
    assert any(m.is_slide[k] and m.is_hinge[k + 1] and not m.is_slide[k + 1] for m in models for k in range(m.n - 1))
    assert any(m.armature is not None for m in models) and any(m.spring is not None for m in models)
    assert {m.base_type for m in models if len(m.slide_bodies)} == set(BASES)


@pytest.mark.parametrize("seed", range(4))
def test_heavy_subtrees_on_slides_take_the_square_root_form_and_agree(seed):
    """A tip 1e4 times heavier than the links, the links on slides and hinges: the kernel's
    square-root elimination (slides' columns reflected on the linear components) against the
    reference's composite-inertia solve."""
    scene = slide_chain(seed, "fixed")
    scene["bodies"][-1]["mass"] = 1e4 * scene["bodies"][-1]["mass"]
    model = compile_model(load_scene(scene))
    assert heavy_subtree_ratio(model) > fast.STABLE_ABA_RATIO
    ref, fst = ChainODE(model), FastChainODE(model)
    rng = np.random.default_rng(seed)
    for _ in range(4):
        hold_random(rng, model, ref, fst)
        y = random_state(rng, model)
        assert_rhs_equal(model, ref.rhs(0.3, y), fst.rhs(0.3, y), rtol=1e-9)


def closed_chain() -> dict:
    """A hinge, a slide along a tilted axis, a spherical joint, a slide: gravity, no commands."""
    scene = cart_pole(0.1, 0.8, 0.4, -1.5, axis=(1.0, 0.3, 0.2))
    pole = scene["bodies"][1]
    pole["next_joint"] = [0.0, 0.05, 2 * L]
    scene["bodies"] += [
        {"name": "sleeve", "joint": {"type": "slide", "axis": [0.2, 0.1, 1.0]}, "mass": 0.3, "com": [0.02, 0.0, 0.05],
         "inertia_com": [[2e-3, 0, 0], [0, 3e-3, 0], [0, 0, 4e-3]], "next_joint": [0.0, 0.0, 0.1],
         "initial": {"position": -0.05, "velocity": 0.7}},
        {"name": "ball", "joint": {"type": "spherical"}, "mass": 0.5, "com": [0.0, 0.03, 0.2],
         "inertia_com": [[4e-3, 0, 0], [0, 5e-3, 0], [0, 0, 2e-3]], "next_joint": [0.0, 0.0, 0.3],
         "initial": {"euler": [0.3, 0.5, -0.2], "euler_rates": [1.0, -0.5, 2.0]}},
        {"name": "tip", "joint": {"type": "slide", "axis": [0.0, 1.0, 0.0]}, "mass": 0.2, "com": [0.0, 0.0, 0.02],
         "inertia_com": [[1e-3, 0, 0], [0, 1e-3, 0], [0, 0, 1e-3]], "initial": {"position": 0.1, "velocity": -0.3}}]
    return scene


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_a_closed_chain_of_slides_and_hinges_keeps_its_energy(backend):
    sim = Simulator(closed_chain(), integrator="dop853", rtol=1e-12, atol=1e-12, backend=backend)
    assert "energy" in conserved(sim.model)
    e0 = sim.invariants()["energy"]
    q0 = np.array(sim.joint_states().position)
    worst = 0.0
    for _ in range(10):
        sim.advance(0.1)
        worst = max(worst, abs(sim.invariants()["energy"] - e0))
    scale = abs(sim.invariants()["kinetic"]) + abs(sim.invariants()["potential"])
    moved = float(np.max(np.abs(np.array(sim.joint_states().position) - q0)))
    assert worst <= 1e-10 * scale and moved > 0.1


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_a_slide_transmits_its_commanded_force_along_its_axis(backend):
    """The row of eq (51) for a translation: e^k . R^k = F_k, the force commanded (no armature),
    at any state; and the cart's joint state is its position (m), velocity (m/s), force (N)."""
    sim = Simulator(cart_pole(0.2, -0.5, 0.6, 1.3, axis=(1.0, 0.0, 0.5)), backend=backend)
    sim.set_axis_moments([2.5, -0.4])
    cart = sim.wrenches()[0]
    e = np.array([1.0, 0.0, 0.5]) / np.linalg.norm([1.0, 0.0, 0.5])
    assert abs(float(np.dot(e, cart.force)) - 2.5) <= 1e-12
    js = sim.joint_states()
    assert js.name[0] == "cart"
    assert (js.position[0], js.velocity[0], js.effort[0]) == pytest.approx((0.2, -0.5, 2.5), abs=1e-15)
    O = sim.body_states()[1].position  # the pole's joint point rides on the cart
    assert np.allclose(O, 0.2 * e, atol=1e-15)


def test_slide_keys_are_checked():
    bad = cart_pole()
    bad["bodies"][0]["initial"] = {"angle": 0.3}
    with pytest.raises(SceneError, match=r"bodies\[0\]\.initial\.angle: hinge-joint key, not allowed on a slide"):
        load_scene(bad)
    bad = cart_pole()
    bad["bodies"][1]["initial"] = {"position": 0.3}
    with pytest.raises(SceneError, match=r"bodies\[1\]\.initial\.position: slide-joint key, not allowed on a hinge"):
        load_scene(bad)
    bad = cart_pole()
    del bad["bodies"][0]["joint"]["axis"]
    with pytest.raises(SceneError, match=r"bodies\[0\]\.joint\.axis: required for a slide"):
        load_scene(bad)
    bad = cart_pole()
    bad["base"] = {"type": "free"}
    with pytest.raises(SceneError, match=r"bodies\[0\]\.joint\.type: a free base's first joint must be spherical, "
                                         r"not a slide"):
        load_scene(bad)


def _canonical(seed, base):
    from gyro_sim.dynamics.canonical import CanonicalChain

    model = compile_model(load_scene(slide_chain(seed, base)))
    ode = ChainODE(model)
    hold_random(np.random.default_rng(seed), model, ode)  # commands, rotor torques, spins
    return model, ode, CanonicalChain(ode)


@pytest.mark.parametrize("base", BASES)
@pytest.mark.parametrize("seed", range(0, 9, 2))
def test_the_canonical_form_takes_slides(seed, base):
    """gauss4s's equations (gyro_sim.dynamics.canonical) with a slide's momentum e . P: y -> z
    -> y is the identity, d/dt state(z(t)) along the canonical field is ChainODE's y' (central
    differences, their error ~1e-9 at this step), the field is Hamiltonian (J^T f' a Hessian,
    off |q| = 1 too), and the compiled field and state are the numpy ones to round-off."""
    model, ode, can = _canonical(seed, base)
    y, t = initial_state(model), 0.3
    z = can.momenta(t, y)
    assert np.abs(can.state(t, z) - y).max() <= 1e-12 * max(1.0, np.abs(y).max())
    zd, e = can.rhs(t, z), 1e-6
    yd = (can.state(t + e, z + e * zd) - can.state(t - e, z - e * zd)) / (2 * e)
    ref = ode.rhs(t, y)
    assert np.abs(yd - ref).max() <= 1e-7 * max(1.0, np.abs(ref).max())
    z[can.i_quat] *= 1.3
    z[can.i_pq] += 0.2 * z[can.i_quat]
    nq = can.nq
    D = np.empty((2 * nq, 2 * nq))
    for j in range(2 * nq):
        dz = np.zeros(can.size)
        dz[j] = 1e-6 * max(1.0, abs(z[j]))
        D[:, j] = (can.rhs(t, z + dz)[:2 * nq] - can.rhs(t, z - dz)[:2 * nq]) / (2 * dz[j])
    hess = np.vstack([-D[nq:], D[:nq]])  # J^T D with J = [[0, I], [-I, 0]]
    assert np.abs(hess - hess.T).max() <= 1e-6 * np.abs(hess).max()
    from gyro_sim.dynamics.canonical_kernel import FastCanonicalChain

    fode = FastChainODE(model)
    hold_random(np.random.default_rng(seed), model, fode)
    fc = FastCanonicalChain(fode)
    a, b = can.rhs(t, z), fc.rhs(t, z)
    assert np.abs(a - b).max() <= 1e-12 * np.abs(a).max()
    ya, yb = can.state(t, z), fc.state(t, z)
    assert np.abs(ya - yb).max() <= 1e-12 * np.abs(ya).max()


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_gauss4s_keeps_the_energy_of_a_chain_with_slides(backend):
    """gauss4s (symplectic) on the closed chain of slides, hinges and a ball joint at 1 ms: the
    energy error stays at 8e-12 relative over 1 s, and the motion is dop853's to 7e-10."""
    sim = Simulator(closed_chain(), integrator="gauss4s", step=1e-3, backend=backend)
    ref = Simulator(closed_chain(), integrator="dop853", rtol=1e-12, atol=1e-12, backend=backend)
    e0 = sim.invariants()["energy"]
    scale = abs(sim.invariants()["kinetic"]) + abs(sim.invariants()["potential"])
    worst = 0.0
    for _ in range(10):
        sim.advance(0.1)
        ref.advance(0.1)
        worst = max(worst, abs(sim.invariants()["energy"] - e0))
    assert worst <= 1e-10 * scale
    assert np.max(np.abs(np.array(sim.joint_states().position) - ref.joint_states().position)) <= 1e-8


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_a_cart_with_exact_coulomb_friction_stops_where_its_closed_form_says(backend):
    """A cart alone on a level slide, launched at v0 against a Coulomb force c (N): it slows at
    c / M, stops at t = M v0 / c after M v0^2 / (2 c), and sticks there (no force drives it)."""
    v0, c = 1.0, 2.0
    scene = cart_pole(0.0, v0, friction={"coulomb": c})
    del scene["bodies"][1], scene["bodies"][0]["next_joint"]
    sim = Simulator(scene, integrator="dop853", rtol=1e-12, atol=1e-12, backend=backend)
    t_stop = M * v0 / c
    sim.advance(0.5 * t_stop)
    t = sim.time
    assert sim.joint_states().position[0] == pytest.approx(v0 * t - 0.5 * c / M * t * t, abs=1e-9)
    assert sim.joint_states().velocity[0] == pytest.approx(v0 - c / M * t, abs=1e-9)
    sim.advance(t_stop)
    assert sim.joint_states().position[0] == pytest.approx(M * v0 * v0 / (2.0 * c), abs=1e-9)
    assert sim.joint_states().velocity[0] == pytest.approx(0.0, abs=1e-9)
    assert sim.friction_work == pytest.approx(-0.5 * M * v0 * v0, abs=1e-8)


def test_compiled_outputs_equal_the_reference_on_slides():
    """The publication kernel (joint states, poses, wrenches about the slides' moving O^k,
    invariants) against the numpy reference's outputs, a first body on a slide included."""
    for scene in (closed_chain(), cart_pole(0.3, -0.2, 2.5, 1.0, axis=(0.3, 1.0, -0.2))):
        ref, got = sims = [Simulator(scene, backend=b) for b in ("numpy", "numba")]
        for sim in sims:
            sim.set_axis_moments(0.3 * np.arange(1, len(sim.axis_names) + 1))
        for f in ("position", "velocity", "effort"):
            assert np.allclose(getattr(got.joint_states(), f), getattr(ref.joint_states(), f), rtol=1e-12, atol=1e-12)
        for x, y in zip(ref.body_states(), got.body_states()):
            assert np.allclose(x.position, y.position, atol=1e-13)
            assert np.allclose(x.quaternion, y.quaternion, atol=1e-13)
            assert np.allclose(x.velocity, y.velocity, atol=1e-12)
        for x, y in zip(ref.wrenches(), got.wrenches()):
            assert np.allclose(x.force, y.force, atol=1e-11) and np.allclose(x.moment, y.moment, atol=1e-11)
        iref, igot = ref.invariants(), got.invariants()
        for k in ("energy", "kinetic", "potential"):
            assert igot[k] == pytest.approx(iref[k], rel=1e-12, abs=1e-12)


def test_a_recorded_run_with_slides_resimulates_bit_for_bit(tmp_path):
    """The log of a chain with slides (commanded force on the cart) carries the scene with its
    slides and re-simulates to the same numbers (gyro_sim.log)."""
    from gyro_sim.log.record import record_run
    from gyro_sim.log.resim import resimulate

    sim = Simulator(closed_chain(), integrator="fixed", step=1e-3)
    path = tmp_path / "slides.mcap"
    record_run(sim, path, duration=0.2, publish_rate=50, schedule=[(0.0, [1.5, 0.0, 0.0, 0.0]),
                                                                    (0.1, [-0.5, 0.1, 0.2, -0.1])])
    res = resimulate(path)
    assert res.compared == 11 and res.commands == 2 and res.max_deviation == 0.0, res.report()
