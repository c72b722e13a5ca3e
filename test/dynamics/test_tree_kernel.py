"""The compiled kernel on trees (docs/theory.md section 11) against the numpy reference: random
trees on fixed, moving and free bases with spherical joints, hinges, slides, torque and speed
rotors, geared motors, massless frames and heavy tips (the square-root elimination), one
evaluation at random states to round-off; the publication kernel's joint wrenches (eq 48T),
joint points and invariants against the reference's.
"""
import copy

import numpy as np
import pytest

from gyro_sim import load_scene
from gyro_sim.dynamics import kernel as fast
from gyro_sim.dynamics import reference as dyn
from gyro_sim.dynamics.invariants import invariants
from gyro_sim.dynamics.outputs import INV_ENERGY
from gyro_sim.dynamics.model import compile_model, initial_state
from gyro_sim.dynamics.system import ChainODE, FastChainODE

from test.dynamics.chains import random_chain
from test.dynamics.test_kernel import MOVING_BASE, assert_rhs_equal, hold_random, random_state

pytestmark = pytest.mark.skipif(not fast.available(), reason="numba is not installed")


def random_tree(seed: int, base: str, *, heavy: bool = False, motors: bool = False, massless: bool = False) -> dict:
    """random_chain's bodies hung from random parents (each joint point given by `joint.at`), some
    joints made slides; `heavy`: one leaf 1e4 times heavier; `motors`: geared motors on hinges
    whose parent is a body; `massless`: a massless hinge frame carrying a hinge about another axis."""
    rng = np.random.default_rng(seed)
    scene = random_chain(seed, base="free" if base == "free" else "fixed", n=int(rng.integers(4, 8)))
    if base == "moving":
        scene["base"] = copy.deepcopy(MOVING_BASE)
    bodies = scene["bodies"]
    names = [b["name"] for b in bodies]
    parents = [-1]
    for k, b in enumerate(bodies):
        b.pop("next_joint", None)
        if k == 0:
            if base != "free":
                b["joint"]["at"] = (rng.normal(size=3) * 0.1).tolist()
            continue
        low = 0 if base == "free" else -1
        p = int(rng.integers(low, k))
        parents.append(p)
        b["parent"] = "base" if p < 0 else names[p]
        b["joint"]["at"] = (rng.normal(size=3) * 0.05 + [0, 0, 0.15]).tolist()
        if b["joint"]["type"] == "hinge" and rng.random() < 0.35:
            b["joint"]["type"] = "slide"
            b["initial"] = {"position": float(rng.normal() * 0.05), "velocity": float(rng.normal())}
        elif b["joint"]["type"] == "hinge" and motors and p >= 0:
            b["joint"]["motor"] = {"inertia": 1e-4, "gear": float(rng.uniform(5, 50)),
                                   "axis": rng.normal(size=3).tolist()}
    if heavy:
        leaf = max(k for k in range(len(bodies)) if k not in parents)
        leaf_body = bodies[leaf]
        leaf_body["mass"] *= 1e4
        leaf_body["inertia_com"] = (np.array(leaf_body["inertia_com"]) * 1e4).tolist()
    if massless:
        frame = {"name": "frame", "parent": names[0], "mass": 0.0,
                 "joint": {"type": "hinge", "axis": [1.0, 0.0, 0.0], "at": [0.05, 0.0, 0.1]},
                 "inertia_com": [[0.0] * 3] * 3, "initial": {"angle": 0.3, "rate": 0.5}}
        child = {"name": "on_frame", "parent": "frame", "mass": 0.4, "com": [0.0, 0.0, 0.1],
                 "joint": {"type": "hinge", "axis": [0.0, 1.0, 0.0], "at": [0.0, 0.0, 0.0]},
                 "inertia": {"axial": 0.002, "transverse": 0.006}, "initial": {"angle": -0.2, "rate": 1.0}}
        bodies += [frame, child]
    scene["name"] = f"random tree {seed}"
    return scene


CASES = [(seed, base, {}) for seed in range(6) for base in ("fixed", "free", "moving")] + [
    (11, "fixed", {"heavy": True}), (12, "free", {"heavy": True}), (13, "moving", {"heavy": True}),
    (21, "fixed", {"motors": True}), (22, "free", {"motors": True, "heavy": True}),
    (31, "fixed", {"massless": True}), (32, "free", {"massless": True, "motors": True}),
]


def _systems(scene: dict):
    model = compile_model(load_scene(scene))
    assert not model.chain
    return model, ChainODE(model), FastChainODE(model)


@pytest.mark.parametrize("seed,base,options", CASES)
def test_tree_rhs_and_outputs_equal_the_reference(seed, base, options):
    model, ref, fst = _systems(random_tree(seed, base, **options))
    chain = fast.chain_model(model)
    assert chain.flags[fast.FLAG_TREE] == 1
    heavy = options.get("heavy", False)
    assert (chain.flags[fast.FLAG_HEAVY] != 0) == heavy == fast.heavy_subtrees(model.mass, model.parent)
    rng = np.random.default_rng(500 + seed)
    for i in range(4):
        if i:
            hold_random(rng, model, ref, fst)
        t = float(rng.uniform(-1.0, 1.0)) if i else 0.0
        y = random_state(rng, model) if i else initial_state(model)
        # measured: below 1e-13 relative, and 3e-11 with a tip 1e4 times heavier
        assert_rhs_equal(model, ref.rhs(t, y), fst.rhs(t, y), rtol=1e-10 if heavy else 1e-12)
        out = fst.outputs(t, y)
        ev = dyn.Evaluation()
        ref.rhs(t, y, out=ev)
        R_ref, L_ref = dyn.reactions(model, ref.data, ev.f_ang, ev.f_lin)
        Rb = ref.data.R
        force = np.einsum("kji,kj->ki", Rb, R_ref)  # in body k's frame
        moment = np.einsum("kji,kj->ki", Rb, L_ref)
        # a free tree in gravity falls: its joints may carry nothing but round-off; the scale is
        # then the bodies' weights
        scale_f = max(np.abs(force).max(), 9.81 * model.mass.max())
        scale_m = max(np.abs(moment).max(), 0.1 * scale_f)
        tol = 1e-9 if heavy else 1e-11
        assert np.abs(out["wrench_force"] - force).max() <= tol * scale_f
        assert np.abs(out["wrench_moment"] - moment).max() <= tol * scale_m
        np.testing.assert_allclose(out["O"], ref.data.O, rtol=0, atol=1e-13)
        np.testing.assert_allclose(out["w"], ref.data.w, rtol=0, atol=1e-12 * max(1.0, np.abs(ref.data.w).max()))
        np.testing.assert_allclose(out["vO"], ref.data.vO, rtol=0, atol=1e-12 * max(1.0, np.abs(ref.data.vO).max()))
        inv = out["inv"]
        expected = invariants(model, ref.data, ref.spins(t), t, y)
        assert abs(inv[INV_ENERGY] - expected["energy"]) <= 1e-12 * max(1.0, abs(expected["energy"]))


@pytest.mark.parametrize("seed,base", [(1, "fixed"), (2, "free"), (4, "moving")])
def test_tree_invariants_equal_the_reference(seed, base):
    from gyro_sim import Simulator

    scene = random_tree(seed, base)
    a, b = Simulator(scene, backend="numpy"), Simulator(scene, backend="numba")
    assert a.backend == "numpy" and b.backend == "numba"
    ia, ib = a.invariants(), b.invariants()
    for key, value in ia.items():
        np.testing.assert_allclose(ib[key], value, rtol=1e-12, atol=1e-12, err_msg=key)
    for wa, wb in zip(a.wrenches(), b.wrenches()):
        np.testing.assert_allclose(wb.force, wa.force, rtol=0, atol=1e-10)
        np.testing.assert_allclose(wb.moment, wa.moment, rtol=0, atol=1e-10)
