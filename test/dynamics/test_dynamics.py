"""The dynamics core against conservation laws, momentum balance and its own closure rows.

Independent checks: energy and momentum (computed from the state alone, not from the
equations of motion), the rate of the chain's momenta obtained by differencing a trajectory
(eq 54 and eq 48 for k = 1), and the joint kinds (eqs 44, 51).
"""
import numpy as np
import pytest

from gyro_sim import Simulator, load_scene
from gyro_sim.dynamics import reference as dyn
from gyro_sim.dynamics.invariants import conserved

from test.dynamics.chains import random_chain


def run_invariants(scene, T, **kw):
    sim = Simulator(scene, integrator="dop853", rtol=1e-12, atol=1e-13, **kw)
    i0 = sim.invariants()
    sim.advance(T)
    return sim, i0, sim.invariants()


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("base", ["fixed", "free"])
def test_random_chain_conserves(seed, base):
    scene = load_scene(random_chain(seed, base=base, commands=False, speed_rotors=False))
    sim, i0, i1 = run_invariants(scene, 1.0)
    names = conserved(sim.model)
    assert "energy" in names
    for name in names:
        a, b = np.asarray(i0[name]), np.asarray(i1[name])
        scale = max(np.max(np.abs(a)), 1e-3)
        assert np.max(np.abs(b - a)) / scale < 1e-9, (name, a, b)


def test_speed_rotor_jacobi_integral():
    scene = load_scene(random_chain(3, base="fixed", commands=False, speed_rotors=True))
    sim, i0, i1 = run_invariants(scene, 1.0)
    assert "jacobi" in conserved(sim.model)
    assert abs(i1["jacobi"] - i0["jacobi"]) < 1e-9 * max(abs(i0["jacobi"]), 1e-3)
    # the speed rotor's motor does work: the energy itself moves (so the check above can fail)
    assert abs(i1["energy"] - i0["energy"]) > 1e-6


def _momenta(sim):
    """Total linear momentum and angular momentum about O^1 (fixed), from the state."""
    m = sim.model
    from gyro_sim.dynamics.reference import Data, cross, lam, matvec, positions, velocities

    d = Data(m)
    positions(m, d, sim.time, sim.state)
    velocities(m, d, sim.time, sim.state[m.i_vel])

    lam_w, _ = lam(m, d, sim._p, None)
    ang = matvec(d.J, d.w) + cross(d.h, d.v_o)
    lin = m.mass[:, None] * d.v_o + cross(d.w, d.h)
    L = ang.sum(0) + (0 if lam_w is None else lam_w.sum(0))
    P = lin.sum(0)
    return P, L - np.cross(d.O[0], P)


@pytest.mark.parametrize("seed", range(4))
def test_base_reaction_balances_momentum_rate(seed):
    """Eq (54): R^1 = dP/dt - sum F; and (48) at k = 1: L^1 = dK_O1/dt - sum M_O1 (fixed base).

    The rates are central differences of momenta computed from the state alone.
    """
    scene = load_scene(random_chain(seed, base="fixed", commands=True, speed_rotors=False))
    sim = Simulator(scene, integrator="dop853", rtol=1e-13, atol=1e-14)
    rng = np.random.default_rng(seed)
    sim.set_axis_moments(rng.normal(size=len(sim.axis_names)) * 0.05)
    sim.advance(0.3)
    h = 1e-4
    samples = []
    for i in range(5):  # t - 2h .. t + 2h; the reaction at the middle
        if i == 2:
            w = sim.wrenches()[0]
            body = sim.body_states()[0]
            mass = sim.model.mass.sum()
            d = dyn.Data(sim.model)  # the first moments of this state (numpy reference)
            dyn.positions(sim.model, d, sim.time, sim.state)
            r_c = d.h.sum(0) / mass - body.position
        else:
            samples.append(_momenta(sim))
        sim.advance(h)
    (Pa, Ka), (Pb, Kb), (Pc, Kc), (Pd, Kd) = samples
    g = sim.model.gravity
    # five-point central differences, error O(h^4)
    dP = (Pa - 8 * Pb + 8 * Pc - Pd) / (12 * h)
    dK = (Ka - 8 * Kb + 8 * Kc - Kd) / (12 * h)
    R1, L1 = body.rotation @ w.force, body.rotation @ w.moment
    scale = 1.0 + np.abs(dP).max()
    assert np.allclose(R1, dP - mass * g, rtol=0, atol=1e-6 * scale), (R1, dP - mass * g)
    assert np.allclose(L1, dK - np.cross(r_c, mass * g), rtol=0, atol=1e-6 * scale), (L1, dK)


@pytest.mark.parametrize("seed", range(4))
def test_joint_kinds_close_eq48(seed):
    """Spherical joints carry no moment (eq 44); hinges carry exactly the command (eq 51)."""
    scene = load_scene(random_chain(seed, base="fixed", commands=True, speed_rotors=True))
    sim = Simulator(scene, integrator="dop853", rtol=1e-10, atol=1e-12)
    rng = np.random.default_rng(100 + seed)
    cmd = rng.normal(size=len(sim.axis_names))
    sim.set_axis_moments(cmd)
    sim.advance(0.2)
    by_axis = dict(zip(sim.axis_names, cmd))
    for body, w in zip(scene.bodies, sim.wrenches()):
        assert w.frame == body.name
        scale = 1.0 + np.abs(w.force).max()
        if body.joint.type == "spherical":
            assert np.abs(w.moment).max() < 1e-10 * scale
        else:
            assert w.moment @ body.joint.axis == pytest.approx(by_axis[body.name], abs=1e-10 * scale)


def test_commands_are_validated():
    sim = Simulator(load_scene(random_chain(1, base="fixed", commands=True, speed_rotors=False)))
    n = len(sim.axis_names)
    with pytest.raises(ValueError, match="expected"):
        sim.set_axis_moments([0.0] * (n + 1))
    with pytest.raises(ValueError, match="finite"):
        sim.set_axis_moments([np.nan] * n)
    with pytest.raises(ValueError):
        sim.advance(-1.0)


def test_lagrange_chain_reports_the_papers_integrals():
    """(82) is -vertical_momentum; (85) moves with 2 x energy (eq 85 = 2 (T + V) - const)."""
    sim = Simulator(load_scene("config/double_gyro_minus.yaml"), rtol=1e-12, atol=1e-13)
    i0 = sim.invariants()
    assert i0["lagrange_82"] == pytest.approx(-i0["vertical_momentum"], rel=1e-12)
    sim2 = Simulator(load_scene("config/heavy_top.yaml"))
    assert set(sim2.invariants()) >= {"energy", "vertical_momentum", "lagrange_82", "lagrange_85"}
    hinge = Simulator(load_scene("config/hinge_chain.yaml")).invariants()
    assert "lagrange_82" not in hinge


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_outputs_follow_commands_and_state(backend):
    """Outputs asked for twice at one state agree; a new command or step changes them."""
    sim = Simulator(load_scene("config/hinge_chain.yaml"), backend=backend)
    before = [w.moment.copy() for w in sim.wrenches()]
    assert all(np.array_equal(a, w.moment) for a, w in zip(before, sim.wrenches()))
    sim.set_axis_moments([0.01] * len(sim.axis_names))
    after = [w.moment for w in sim.wrenches()]
    assert any(not np.allclose(a, b) for a, b in zip(before, after))
    js0, e0 = sim.joint_states(), sim.invariants()["energy"]
    sim.advance(0.01)
    assert sim.joint_states().position != js0.position
    assert sim.invariants()["energy"] != e0  # the commanded moments did work: not a stale cache
