"""gauss4s and the chain's canonical equations (gyro_sim.dynamics.canonical).

Checked against things independent of the canonical code: the package's own equations
(ChainODE, through the chain rule of the conversion), the symmetry a Hamiltonian vector field
must have, the symplecticity of the step map (and that the same check fails for rk4), exact
momentum conservation where gauss4 on the package's state has an h^4 error, order 4 against a
tight dop853.
"""
import numpy as np
import pytest

from gyro_sim import load_scene
from gyro_sim.dynamics.canonical import CanonicalChain
from gyro_sim.integrators import RK4, Gauss4, IntegrationError, make_integrator
from gyro_sim.dynamics.model import compile_model, initial_state
from gyro_sim.simulator import Simulator
from gyro_sim.dynamics import kernel as fast
from gyro_sim.integrators.gauss4 import kernels as gk
from gyro_sim.dynamics.system import ChainODE, FastChainODE, make_system

from test.dynamics.chains import random_chain
from test.dynamics.test_kernel import chain_scene, hold_random

CASES = [(seed, base) for seed in range(8) for base in ("fixed", "free", "moving")]


def _canonical(seed, base):
    model = compile_model(load_scene(chain_scene(seed, base)))
    ode = ChainODE(model)
    hold_random(np.random.default_rng(seed), model, ode)  # commands, rotor torques, spins
    return model, ode, CanonicalChain(ode)


@pytest.mark.parametrize("seed,base", CASES)
def test_conversion_round_trip(seed, base):
    model, ode, can = _canonical(seed, base)
    y = initial_state(model)
    z = can.momenta(0.3, y)
    assert np.abs(can.state(0.3, z) - y).max() <= 1e-12 * max(1.0, np.abs(y).max())


@pytest.mark.parametrize("seed,base", CASES)
def test_vector_field_is_the_package_equations(seed, base):
    """d/dt state(t, z(t)) along z' = f(t, z) is ChainODE's y' (a second formulation: the
    canonical field uses no acceleration; ChainODE solves the closure rows of eq 48)."""
    model, ode, can = _canonical(seed, base)
    y, t = initial_state(model), 0.3
    z = can.momenta(t, y)
    zd = can.rhs(t, z)
    e = 1e-5
    yd = (can.state(t + e, z + e * zd) - can.state(t - e, z - e * zd)) / (2 * e)
    ref = ode.rhs(t, y)
    assert np.abs(yd - ref).max() <= 1e-7 * max(1.0, np.abs(ref).max())


@pytest.mark.parametrize("seed,base", CASES[:9])
def test_vector_field_is_hamiltonian(seed, base):
    """f = J grad H: J^T f' is a Hessian, symmetric -- also off |q| = 1 and q . p = 0, where
    the Gauss stages are (the method is symplectic only if the field is Hamiltonian there)."""
    model, ode, can = _canonical(seed, base)
    hess = field_hessian(model, can)
    assert np.abs(hess - hess.T).max() <= 1e-6 * np.abs(hess).max()


def field_hessian(model, can):
    """J^T f' (J = [[0, I], [-I, 0]]) of the canonical field `can` of `model` by central
    differences over the coordinates and momenta at t = 0.3, at the initial state moved off
    |q| = 1 and q . p = 0: the Hessian of H there when f = J grad H."""
    t = 0.3
    z = can.momenta(t, initial_state(model))
    z[can.i_quat] *= 1.3
    z[can.i_pq] += 0.2 * z[can.i_quat]
    nq = can.nq
    D = np.empty((2 * nq, 2 * nq))
    for j in range(2 * nq):
        dz = np.zeros(can.size)
        dz[j] = 1e-6 * max(1.0, abs(z[j]))
        D[:, j] = (can.rhs(t, z + dz)[:2 * nq] - can.rhs(t, z - dz)[:2 * nq]) / (2 * dz[j])
    return np.vstack([-D[nq:], D[:nq]])


needs_numba = pytest.mark.skipif(not fast.available(), reason="numba is not installed")


@needs_numba
@pytest.mark.parametrize("seed,base", CASES)
def test_compiled_field_and_state_match_numpy(seed, base):
    """fast_canonical's kernels against canonical.py's numpy form, off |q| = 1 and q . p = 0
    too (the O(n) elimination against the dense solve of M)."""
    from gyro_sim.dynamics.canonical_kernel import FastCanonicalChain

    model, ode, can = _canonical(seed, base)
    fode = FastChainODE(model)
    hold_random(np.random.default_rng(seed), model, fode)
    field, state = compiled_against_numpy(model, can, FastCanonicalChain(fode))
    assert field <= 1e-13 and state <= 1e-13


def compiled_against_numpy(model, can, fc) -> tuple[float, float]:
    """The largest differences of the compiled canonical field `fc` and its state map from the
    numpy form `can` of `model` at t = 0.3, off |q| = 1 and q . p = 0, relative to the largest
    entry: (field, state)."""
    z = can.momenta(0.3, initial_state(model))
    z[can.i_quat] *= 1.1
    z[can.i_pq] += 0.05 * z[can.i_quat]
    a, b = can.rhs(0.3, z), fc.rhs(0.3, z)
    ya, yb = can.state(0.3, z), fc.state(0.3, z)
    return np.abs(a - b).max() / np.abs(a).max(), np.abs(ya - yb).max() / np.abs(ya).max()


@needs_numba
def test_compiled_march_is_the_python_driver():
    """gauss4s on the compiled system: the compiled march and the Python driver (the same
    kernels between evaluations) give the same steps, bit for bit."""
    model = compile_model(load_scene(random_chain(5, n=3, commands=False)))
    y0 = initial_state(model)
    out = []
    for compiled in (True, False):
        integ = make_integrator("gauss4s", make_system(model, "numba"), step=1e-3)
        integ.inner.use_compiled = compiled
        out.append((integ.advance(0.0, y0, 0.05), integ.counts.copy()))
    assert np.array_equal(out[0][0], out[1][0])
    assert np.array_equal(out[0][1], out[1][1])


def _step_map_defect(integ, can, t, z, h):
    """|Phi^T J Phi - J| / |Phi|^2 of one step's map Phi (central differences)."""
    nq = can.nq
    Phi = np.empty((2 * nq, 2 * nq))
    for j in range(2 * nq):
        cols = []
        for sgn in (1.0, -1.0):
            zz = z.copy()
            zz[j] += sgn * 1e-6
            integ.reset()
            integ.march(t, zz, t + h)
            cols.append(zz[:2 * nq])
        Phi[:, j] = (cols[0] - cols[1]) / 2e-6
    J = np.block([[np.zeros((nq, nq)), np.eye(nq)], [-np.eye(nq), np.zeros((nq, nq))]])
    return np.abs(Phi.T @ J @ Phi - J).max() / np.abs(Phi).max() ** 2


def test_step_map_is_symplectic():
    """One gauss4s step is a symplectic map of the canonical variables; one rk4 step of the
    same field, at the same (large) step, is not: the check can fail."""
    model = compile_model(load_scene(random_chain(4, n=2, commands=False)))
    ode = ChainODE(model)
    can = CanonicalChain(ode)
    z = can.momenta(0.0, initial_state(model))
    h = 0.05
    gauss = _step_map_defect(Gauss4(can, step=h), can, 0.0, z, h)
    rk4 = _step_map_defect(RK4(can, step=h), can, 0.0, z, h)
    assert gauss <= 1e-7, gauss
    assert rk4 >= 1e3 * gauss and rk4 >= 1e-6, (rk4, gauss)


def _free_floating():
    """A free-floating chain without gravity: spherical, hinge and spherical joints, torque
    and speed rotors (whose commands stay zero)."""
    sc = random_chain(2, base="free", commands=False, n=3, gravity=False)
    sc["bodies"][1]["joint"] = {"type": "hinge", "axis": [0.3, -0.2, 1.0]}
    sc["bodies"][1]["initial"] = {"angle": 0.4, "rate": 10.0}
    for k in (0, 2):
        sc["bodies"][k]["initial"]["euler_rates"] = [5.0 * r for r in sc["bodies"][k]["initial"]["euler_rates"]]
    sc["base"]["velocity"] = [0.0, 0.0, 0.0]
    return load_scene(sc)


def test_free_floating_chain_keeps_its_momenta_to_round_off():
    """1e4 steps of 1 ms: the linear and angular momentum of a free-floating chain stay at
    their initial values to round-off with gauss4s (bilinear in (q, p): kept exactly by a
    Gauss method); gauss4 on the package's state keeps them only to its h^4 truncation."""
    drift = {}
    for name in ("gauss4s", "gauss4"):
        sim = Simulator(_free_floating(), integrator=name, step=1e-3)
        can = CanonicalChain(ChainODE(sim.model))

        def L_origin():
            # about the fixed origin (about the centre of mass, as `invariants` reports it, the
            # centre's own position error would enter)
            z = can.momenta(sim.time, sim.state)
            return can.angular_momentum(z), z[can.i_pr]

        L0, P0 = L_origin()
        worst = 0.0
        for _ in range(10):
            sim.advance(1.0)
            L, P = L_origin()
            # L = sum pi + r0 x P: measured against the size of its terms (the base's r0 is
            # a sum of 1e4 rounded increments, and r0 x P enters L)
            r0 = sim.state[sim.model.i_r0]
            scale = np.abs(L0).max() + np.linalg.norm(r0) * np.linalg.norm(P0)
            worst = max(worst, np.abs(L - L0).max() / scale, np.abs(P - P0).max() / np.abs(P0).max())
        drift[name] = worst
    # round-off: a random walk of ~1e-16 a step, 2.5e-14 at its largest over these 1e4 steps
    # (and 7e-14 over 3e4: it wanders, it does not grow linearly)
    assert drift["gauss4s"] <= 5e-14, drift
    assert drift["gauss4"] >= 30 * drift["gauss4s"], drift


@pytest.mark.slow
def test_order_four_on_a_chain():
    """Global error at t = 0.2 s against dop853 at rtol 1e-13, for h = 20, 10, 5 ms: the ratio
    of successive errors tends to 2^4."""
    model = compile_model(load_scene(random_chain(7, n=3, commands=False)))
    ref_sys = make_system(model, "numpy")
    y0 = initial_state(model)
    ref = make_integrator("dop853", ref_sys, rtol=1e-13, atol=1e-13).advance(0.0, y0, 0.2)
    errs = []
    for h in (0.02, 0.01, 0.005):
        integ = make_integrator("gauss4s", make_system(model, "numpy"), step=h)
        y = integ.advance(0.0, y0, 0.2)
        errs.append(np.abs(y - ref).max())
    ratios = [errs[i] / errs[i + 1] for i in range(2)]
    assert 12 < ratios[-1] < 20, (errs, ratios)


def test_newton_failure_is_reported():
    """A step whose Newton iteration meets a non-finite field (a NaN hinge command held in the
    system) raises IntegrationError named gauss4s with the reason, never a silent result."""
    model, ode, can = _canonical(0, "fixed")
    assert len(model.hinge_bodies)
    integ = make_integrator("gauss4s", ode, step=1e-3)
    ode.hold(0.0, ode.p0, np.full(len(model.hinge_bodies), np.nan), None)
    with pytest.raises(IntegrationError, match="gauss4s: .*(finite|Newton)"):
        integ.advance(0.0, initial_state(model), 0.01)


def test_only_chains():
    class Plain:
        size, quat_index = 2, np.zeros((0, 4), dtype=int)

    with pytest.raises(ValueError, match="chain"):
        make_integrator("gauss4s", Plain())


@needs_numba
@pytest.mark.slow
def test_energy_stays_bounded_on_the_fast_double_gyroscope():
    """The double gyroscope spun at 1e3 rad/s (1 rad a 1 ms step), 2e4 steps: gauss4s's energy
    error stays at round-off level and does not grow (its largest over the second 10 s is no
    more than twice that over the first); gauss4 on the package's state grows as t^2, to ~4e-8
    at 20 s (docs/integrators.md): the check can fail."""
    from gyro_sim.bench.spin_sweep import double_gyro

    scene = load_scene(double_gyro(1e3))
    worst = {}
    for name in ("gauss4s", "gauss4"):
        sim = Simulator(scene, integrator=name, step=1e-3)
        inv0 = sim.invariants()
        scale = abs(inv0["kinetic"]) + abs(inv0["potential"])
        errs = []
        for _ in range(20):
            sim.advance(1.0)
            errs.append(abs(sim.invariants()["energy"] - inv0["energy"]) / scale)
        worst[name] = (max(errs[:10]), max(errs[10:]))
    first, second = worst["gauss4s"]
    assert second <= 1e-10 and second <= 2.0 * max(first, 1e-13), worst
    assert worst["gauss4"][1] >= 100.0 * second and worst["gauss4"][1] >= 3.0 * worst["gauss4"][0], worst


@needs_numba
@pytest.mark.slow
@pytest.mark.parametrize("kappa, drifts", [(None, False), (1e-5, True)])
def test_round_off_does_not_drift_the_vertical_momentum(kappa, drifts):
    """The heavy top spun at 1e3 rad/s (1 rad a 1 ms step), 1e5 steps: the vertical angular
    momentum K, bilinear in gauss4s's variables and so kept exactly by the method, wanders at
    round-off (~3e-14) instead of drifting. With the Newton stop of gauss4 (1e-5 tolerance
    units), what the simplified iteration leaves has a sign, and K drifts linearly, ~2.5e-13
    over the same steps (measured; on the double gyroscope at 1e3 rad/s the rounded
    coefficients h a_ij made it 16x more again): the check can fail. Hairer, McLachlan, Razakarivony, BIT 48 (2008)."""
    from gyro_sim.bench.spin_sweep import heavy_top

    sim = Simulator(load_scene(heavy_top(1e3)), integrator="gauss4s", step=1e-3)
    if kappa is not None:
        sim.integrator.inner._params[gk.PAR_DENSE_KAPPA] = kappa
    K0 = sim.invariants()["vertical_momentum"]
    drift = []
    for _ in range(10):
        sim.advance(10.0)
        drift.append((sim.invariants()["vertical_momentum"] - K0) / abs(K0))
    worst = max(abs(d) for d in drift)
    if drifts:
        assert worst > 1e-13 and abs(drift[-1]) > 4 * abs(drift[1]), drift
    else:
        assert worst < 1e-13, drift
