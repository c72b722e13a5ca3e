"""The numba backend (gyro_sim.dynamics.kernel, FastChainODE) against the numpy reference (ChainODE).

Same equations, a different algorithm (articulated-body recursion about each joint point
instead of a composite-inertia matrix about the origin): the results must agree to
round-off at any state an integrator may ask for, and whole trajectories must agree to the
integration tolerance.
"""
import copy

import numpy as np
import pytest

from gyro_sim import jit, load_scene
from gyro_sim.bench.scenes import spherical_chain
from gyro_sim.dynamics import reference as dyn
from gyro_sim.dynamics import kernel as fast
from gyro_sim.integrators import make_integrator
from gyro_sim.dynamics.model import compile_model, initial_state
from gyro_sim.dynamics.system import (
    BACKENDS, ChainODE, FastChainODE, heavy_subtree_ratio, make_system,
)

from .chains import random_chain

pytestmark = pytest.mark.skipif(not fast.available(), reason="numba is not installed")

SEEDS = range(12)
BASES = ("fixed", "free", "moving")
#: round-off agreement of one evaluation, relative to the largest entry of each block
RHS_RTOL = 1e-12
#: states per case
STATES = 4
MOVING_BASE = {"type": "moving", "position": [0.0, 0.0, 0.0],
               "motion": {"type": "sine", "amplitude": [0.0, 0.0, 0.01], "frequency": 20.0}}


def chain_scene(seed: int, base: str, **kw) -> dict:
    """random_chain with base "fixed", "free" or "moving" (a vertical sine at 20 Hz)."""
    scene = random_chain(seed, base="free" if base == "free" else "fixed", **kw)
    if base == "moving":
        scene["base"] = copy.deepcopy(MOVING_BASE)
    return scene


def systems(scene: dict):
    model = compile_model(load_scene(scene))
    return model, ChainODE(model), FastChainODE(model)


def hold_random(rng, model, *systems_) -> None:
    """The same random commands and rotor spins held from a random t0 on every system."""
    nt, nh = len(model.torque_body), len(model.hinge_bodies)
    t0 = float(rng.uniform(-1.0, 1.0))
    p0 = rng.uniform(-50.0, 50.0, nt) if nt else None
    hinge_tau = rng.normal(size=nh) if nh else None
    L_rotor = rng.normal(size=nt) * 1e-2 if nt else None
    for s in systems_:
        s.hold(t0, p0, hinge_tau, L_rotor)


def random_state(rng, model) -> np.ndarray:
    """The initial state disturbed, quaternions off unit length as in integrator stages."""
    y = initial_state(model) + rng.normal(size=model.size) * 0.3
    if len(model.sph_bodies):
        y[model.i_quat] *= rng.uniform(0.9, 1.1, size=(len(model.sph_bodies), 1))
    return y


def blocks(model):
    """Index blocks of y compared separately: positions/quaternions, velocities, rotor angles."""
    i_vel = np.arange(model.size)[model.i_vel]
    i_kap = np.arange(model.size)[model.i_kappa]
    rest = np.setdiff1d(np.arange(model.size), np.concatenate([i_vel, i_kap]))
    return {"positions": rest, "velocities": i_vel, "rotor angles": i_kap}


def assert_rhs_equal(model, ref: np.ndarray, got: np.ndarray, rtol: float = RHS_RTOL) -> None:
    assert got.shape == ref.shape == (model.size,)
    assert np.all(np.isfinite(got))
    for name, idx in blocks(model).items():
        if idx.size:
            scale = max(np.abs(ref[idx]).max(), 1e-300)
            err = np.abs(got[idx] - ref[idx]).max() / scale
            assert err <= rtol, f"{name}: relative difference {err:.2e}"


# --- one evaluation --------------------------------------------------------------------------
@pytest.mark.parametrize("base", BASES)
@pytest.mark.parametrize("seed", SEEDS)
def test_rhs_equals_reference(seed, base):
    model, ref, fst = systems(chain_scene(seed, base))
    rng = np.random.default_rng(1000 + seed)
    for i in range(STATES):
        if i:  # first state: the inputs of a fresh system (no hold yet)
            hold_random(rng, model, ref, fst)
        t = float(rng.uniform(-1.0, 1.0)) if i else 0.0
        y = random_state(rng, model) if i else initial_state(model)
        assert_rhs_equal(model, ref.rhs(t, y), fst.rhs(t, y))


@pytest.mark.parametrize("base", BASES)
def test_rhs_equals_reference_without_rotors_or_gravity(base):
    model, ref, fst = systems(chain_scene(7, base, speed_rotors=False, gravity=False))
    rng = np.random.default_rng(7)
    hold_random(rng, model, ref, fst)
    y = random_state(rng, model)
    assert_rhs_equal(model, ref.rhs(0.3, y), fst.rhs(0.3, y))


def test_cases_cover_the_features():
    """The seeds above include hinge-first chains, torque and speed rotors, commands."""
    models = [compile_model(load_scene(chain_scene(s, b))) for s in SEEDS for b in BASES]
    assert any(m.is_hinge[0] for m in models)
    assert any(m.is_hinge[1:].any() for m in models if m.free)
    assert any(len(m.torque_body) and m.lam_speed is not None for m in models)
    assert any(len(m.axis_names) for m in models)
    assert {m.base_type for m in models} == set(BASES)


@pytest.mark.parametrize("n", [1, 2, 10, 30])
def test_long_spherical_chain(n):
    """A long bent chain: the articulated inertias stay symmetric and the recursion accurate
    (without exact symmetry their round-off grows x2.5 per link: O(1) errors at n = 30)."""
    model, ref, fst = systems(spherical_chain(n, rotors=True))
    y = initial_state(model)
    assert_rhs_equal(model, ref.rhs(0.0, y), fst.rhs(0.0, y), rtol=1e-10)


# --- the kernel's scalar twins of formulas whose home is numpy -----------------------------
def test_twins_equal_their_numpy_homes():
    """_quat_to_matrix, _quat_rate, _rotor_angle_rate against rotations.quat_to_matrix,
    rotations.quat_rates, dynamics.torque_rotor_rates, on non-unit quaternions as integrator
    stages pass them."""
    from gyro_sim.dynamics.rotations import quat_rates, quat_to_matrix

    rng = np.random.default_rng(7)
    q = rng.normal(size=(50, 4))
    w = rng.normal(size=(50, 3)) * 10.0
    for qk, wk, ref_R, ref_qd in zip(q, w, quat_to_matrix(q), quat_rates(q, w)):
        R = np.array(fast._quat_to_matrix(*qk)).reshape(3, 3)
        np.testing.assert_allclose(R, ref_R, rtol=0, atol=4 * np.finfo(float).eps)
        qd = np.array(fast._quat_rate(*qk, *wk))
        np.testing.assert_allclose(qd, ref_qd, rtol=1e-15, atol=1e-14)
    model = compile_model(load_scene(chain_scene(0, "fixed")))
    assert len(model.torque_body)
    data = dyn.Data(model)
    y = random_state(rng, model)
    dyn.positions(model, data, 0.0, y)
    dyn.velocities(model, data, 0.0, y[model.i_vel])
    p = rng.uniform(-50.0, 50.0, len(model.torque_body))
    ref = dyn.torque_rotor_rates(model, data, p)
    for i, k in enumerate(model.torque_body):
        e = data.R[k] @ model.torque_axis[i]
        assert fast._rotor_angle_rate(p[i], *data.w[k], *e) == pytest.approx(ref[i], rel=1e-14, abs=1e-12)


# --- the rest of the ChainODE interface ------------------------------------------------------
def test_interface_matches_chain_ode():
    model, ref, fst = systems(chain_scene(3, "free"))
    assert fst.size == ref.size == model.size
    np.testing.assert_array_equal(fst.quat_index, ref.quat_index)
    assert fst.model is model
    assert isinstance(fst.data, dyn.Data)
    y = initial_state(model)
    out = fst.rhs(0.0, y)
    assert out is not fst.rhs(0.0, y)  # a new array each call
    assert fst.nfev == 2


def test_hold_and_spins_forward_to_reference():
    model, ref, fst = systems(chain_scene(0, "fixed"))
    assert len(model.torque_body)
    np.testing.assert_array_equal(fst.spins(0.5), ref.spins(0.5))
    hold_random(np.random.default_rng(0), model, ref, fst)
    for t in (0.0, 0.25, 2.0):
        np.testing.assert_array_equal(fst.spins(t), ref.spins(t))


def test_out_uses_the_reference_path():
    """rhs(t, y, out=ev) (the Simulator's outputs) fills ev and data as ChainODE does."""
    model, ref, fst = systems(chain_scene(2, "moving"))
    rng = np.random.default_rng(2)
    hold_random(rng, model, ref, fst)
    y = random_state(rng, model)
    ev_ref, ev_fast = dyn.Evaluation(), dyn.Evaluation()
    a = ref.rhs(0.1, y, out=ev_ref)
    b = fst.rhs(0.1, y, out=ev_fast)
    np.testing.assert_array_equal(a, b)
    for name in ("udot", "acc_w", "acc_v", "f_ang", "f_lin"):
        np.testing.assert_array_equal(getattr(ev_fast, name), getattr(ev_ref, name))
    np.testing.assert_array_equal(fst.data.O, ref.data.O)
    assert_rhs_equal(model, a, fst.rhs(0.1, y))


def test_project_normalises_like_reference():
    model, ref, fst = systems(chain_scene(4, "free"))
    y = random_state(np.random.default_rng(4), model)
    a, b = y.copy(), y.copy()
    ref.project(a)
    fst.project(b)
    np.testing.assert_allclose(b, a, rtol=0, atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(b[model.i_quat], axis=1), 1.0, rtol=0, atol=1e-15)


def test_unavailable_numba_is_reported(monkeypatch):
    assert isinstance(fast.available(), bool)
    monkeypatch.setattr(jit, "numba", None)
    assert not fast.available()
    model = compile_model(load_scene(chain_scene(1, "fixed")))
    with pytest.raises(ImportError):
        FastChainODE(model)


# --- trajectories ----------------------------------------------------------------------------
@pytest.mark.parametrize("seed,base", [(0, "fixed"), (3, "free"), (5, "moving")])
def test_trajectory_equals_reference(seed, base):
    """One second of DOP853 at rtol 1e-11 with commands held: the same final state."""
    model, ref, fst = systems(chain_scene(seed, base))
    rng = np.random.default_rng(seed)
    hold_random(rng, model, ref, fst)
    y0 = initial_state(model)
    finals = []
    for system in (ref, fst):
        integ = make_integrator("dop853", system, rtol=1e-11, atol=1e-12)
        finals.append(integ.advance(0.0, y0, 1.0))
    np.testing.assert_allclose(finals[1], finals[0], rtol=0, atol=1e-9)


def test_wrong_state_size_is_rejected():
    """The kernel reads y without bounds checks: its size is checked before."""
    model, _, fst = systems(chain_scene(1, "fixed"))
    with pytest.raises(ValueError, match="shape"):
        fst.rhs(0.0, np.zeros(model.size - 1))
    with pytest.raises(ValueError, match="shape"):
        fst.project(np.zeros(model.size + 1))


@pytest.mark.parametrize("backend", BACKENDS)
def test_make_system(backend):
    model = compile_model(load_scene(chain_scene(2, "free")))
    system = make_system(model, backend)
    expected = ChainODE if backend == "numpy" else FastChainODE
    assert type(system) is expected
    assert system.nfev == 0
    y = initial_state(model)
    assert_rhs_equal(model, ChainODE(model).rhs(0.0, y), system.rhs(0.0, y))


def test_make_system_falls_back_without_numba(monkeypatch):
    model = compile_model(load_scene(chain_scene(2, "fixed")))
    with pytest.raises(ValueError, match="backend"):
        make_system(model, "cuda")
    monkeypatch.setattr(jit, "numba", None)
    assert type(make_system(model, "auto")) is ChainODE
    with pytest.raises(ImportError):
        make_system(model, "numba")


def test_auto_backend_stays_compiled_on_a_heavy_tip():
    """No mass-ratio fallback: "auto" compiles a heavy tip (1e6) as any other chain; its
    accuracy is test/core/test_heavy_tip.py's."""
    from gyro_sim.bench.extreme import mass_ratio_chain

    heavy = compile_model(load_scene(mass_ratio_chain(1e6)))
    assert heavy_subtree_ratio(heavy) > 1e5
    assert isinstance(make_system(heavy, "auto"), FastChainODE)
    light = compile_model(load_scene(mass_ratio_chain(1e-6)))
    assert isinstance(make_system(light, "auto"), FastChainODE)
