"""gauss4s on trees of gyrostats (docs/theory.md section 11): the canonical form's subtree sums;
and on geared motors on a turning parent (section 10, eq 51b), on chains and trees.

Checked against what does not share the canonical code: the kernel's y' (the articulated-body
recursion on the package's state) pushed through the canonical transformation by a complex step
(exact to round-off, unlike a difference quotient); dop853 at tight tolerance on the package's
state; the conservation laws of a free-floating tree (energy bounded, momenta to round-off); and
the compiled field against the numpy one on random trees.
"""
from __future__ import annotations

import copy

import numpy as np
import pytest

from gyro_sim import load_scene, paths
from gyro_sim.dynamics import kernel as fast
from gyro_sim.dynamics.canonical import CanonicalChain
from gyro_sim.dynamics.invariants import conserved
from gyro_sim.dynamics.model import compile_model, initial_state
from gyro_sim.dynamics.system import ChainODE, FastChainODE
from gyro_sim.integrators import RK4, Gauss4
from gyro_sim.simulator import Simulator

from test.dynamics.test_geared_motor import free_chain as motor_chain
from test.dynamics.test_geared_motor import turntable
from test.dynamics.test_kernel import hold_random
from test.dynamics.test_tree_kernel import random_tree

needs_numba = pytest.mark.skipif(not fast.available(), reason="numba is not installed")

G = 9.81


def _diagonal(a, b, c):
    return [[a, 0.0, 0.0], [0.0, b, 0.0], [0.0, 0.0, c]]


def _sphere(name, parent, at, mass=1.0, com=(0.0, 0.0, -0.3), rates=(0.5, -0.3, 0.8), **extra):
    return {"name": name, "parent": parent, "joint": {"type": "spherical", "at": list(at)}, "mass": mass,
            "com": list(com), "inertia_com": _diagonal(0.03 * mass, 0.025 * mass, 0.02 * mass),
            "initial": {"euler": [0.3, 0.4, -0.2], "euler_rates": list(rates)}, **extra}


def _hinge(name, parent, at, axis, angle=0.4, rate=1.0, kind="hinge", mass=0.8, com=(0.0, 0.0, -0.25)):
    initial = {"angle": angle, "rate": rate} if kind == "hinge" else {"position": angle * 0.1, "velocity": rate}
    return {"name": name, "parent": parent, "joint": {"type": kind, "axis": list(axis), "at": list(at)},
            "mass": mass, "com": list(com), "inertia_com": _diagonal(0.02, 0.015, 0.01), "initial": initial}


def hub_with_two_pendulums() -> dict:
    """A spherical hub on a fixed base with two pendulums, a hinge and a spherical one; the hinge
    carries a spherical body (the hub's next spherical bodies: the spherical pendulum and, across
    the hinge, its child)."""
    hub = _sphere("hub", "base", (0.0, 0.0, 0.0), mass=3.0, com=(0.0, 0.0, 0.2))
    bodies = [hub, _hinge("left", "hub", (0.3, 0.0, 0.2), (0.0, 1.0, 0.0)),
              _sphere("right", "hub", (-0.3, 0.0, 0.2)),
              _sphere("bob", "left", (0.0, 0.0, -0.5), mass=0.5, rates=(2.0, 0.0, -1.0))]
    return {"name": "hub with two pendulums", "gravity": [0, 0, -G], "base": {"type": "fixed"}, "bodies": bodies}


def free_tree_with_rotors(spin: float = 40.0) -> dict:
    """A free-floating tree without gravity: a hub with a torque rotor and a speed rotor, a
    hinged arm carrying a spherical body with its own rotor, and a spherical arm."""
    rotor = {"axis": [0.0, 0.0, 1.0], "mass": 0.1, "axial_inertia": 0.01, "transverse_inertia": 0.006}
    hub = _sphere("hub", None, (0.0, 0.0, 0.0), mass=5.0, com=(0.05, 0.0, 0.0), rates=(0.4, -0.2, 0.6))
    hub["joint"] = {"type": "spherical"}
    hub.pop("parent")
    hub["rotors"] = [dict(rotor, name="wheel", mode="torque", spin=spin),
                     dict(rotor, name="fan", mode="speed", spin=0.5 * spin, axis=[1.0, 0.0, 0.0])]
    arm = _hinge("arm", "hub", (0.4, 0.0, 0.0), (0.0, 0.6, 0.8), rate=2.0)
    tip = _sphere("tip", "arm", (0.0, 0.0, -0.5), mass=0.6, rates=(3.0, 1.0, 0.0))
    tip["rotors"] = [dict(rotor, name="tip_wheel", mode="torque", spin=-spin, axis=[0.0, 1.0, 0.0])]
    other = _sphere("other", "hub", (-0.4, 0.1, 0.0), mass=0.9, rates=(0.0, -2.0, 1.5))
    return {"name": "free tree with rotors", "base": {"type": "free", "velocity": [0.1, -0.2, 0.05]},
            "bodies": [hub, arm, tip, other]}


def tree_with_slide() -> dict:
    """A spherical hub on a fixed base with a slide (carrying a spherical body) and a hinge."""
    hub = _sphere("hub", "base", (0.0, 0.0, 0.0), mass=2.0, com=(0.0, 0.0, 0.2))
    bodies = [hub, _hinge("carriage", "hub", (0.2, 0.0, 0.1), (1.0, 0.0, 0.3), kind="slide", rate=0.5),
              _sphere("rider", "carriage", (0.0, 0.0, -0.1), mass=0.7),
              _hinge("flap", "hub", (-0.2, 0.0, 0.1), (0.0, 0.0, 1.0), rate=-1.5)]
    return {"name": "tree with a slide", "gravity": [0, 0, -G], "base": {"type": "fixed"}, "bodies": bodies}


def spacecraft(spin: float = 0.0) -> dict:
    """config/spacecraft_panels.yaml, its wheels spun up to `spin` rad/s."""
    import yaml

    scene = yaml.safe_load(paths.find_scene("spacecraft_panels").read_text())
    for r in scene["bodies"][0]["rotors"]:
        r["spin"] = spin * (1.0 + 0.3 * r["axis"].index(1.0))
    return scene


def free_tree_with_motors() -> dict:
    """free_tree_with_rotors with geared motors on its hinged arm (a bevel axis) and on a hinge
    added below the spherical tip."""
    scene = free_tree_with_rotors()
    scene["bodies"][1]["joint"]["motor"] = {"inertia": 2e-4, "gear": 40.0, "axis": [1.0, 0.0, 0.5]}
    hand = _hinge("hand", "tip", (0.0, 0.0, -0.3), (1.0, 0.0, 0.0), rate=-3.0, mass=0.3)
    hand["joint"]["motor"] = {"inertia": 1e-4, "gear": -25.0}
    scene["bodies"].append(hand)
    return scene


NAMED = {"spacecraft_panels": lambda: spacecraft(300.0), "hub_with_two_pendulums": hub_with_two_pendulums,
         "free_tree_with_rotors": free_tree_with_rotors, "tree_with_slide": tree_with_slide,
         "free_tree_with_motors": free_tree_with_motors}
#: geared motors on chains (test/dynamics/test_geared_motor.py's scenes)
MOTOR_CHAINS = {"turntable": lambda: turntable(), "free_motor_chain": lambda: motor_chain("free"),
                "fixed_motor_chain": lambda: motor_chain("fixed")}
#: random trees (seed, base, options of random_tree): slides, speed and torque rotors; massless
#: hinge frames carrying a hinge
RANDOM = [(seed, base, {}) for seed in range(4) for base in ("fixed", "free", "moving")] + [
    (31, "fixed", {"massless": True}), (33, "free", {"massless": True})] + [
    (41, "fixed", {"motors": True}), (42, "moving", {"motors": True}), (22, "free", {"motors": True}),
    (32, "free", {"massless": True, "motors": True})]


def _scene(case) -> dict:
    if isinstance(case, str):
        return {**NAMED, **MOTOR_CHAINS}[case]()
    return random_tree(case[0], case[1], **case[2])


def _model(case):
    model = compile_model(load_scene(_scene(case)))
    chain = isinstance(case, str) and case in MOTOR_CHAINS
    assert model.chain == chain
    if chain or "motor" in str(case):
        assert model.motor is not None  # on a turning parent
    return model


CASES = list(NAMED) + list(MOTOR_CHAINS) + RANDOM


@needs_numba
@pytest.mark.parametrize("case", CASES, ids=str)
def test_canonical_rates_are_the_kernels_rates(case):
    """z' of the canonical field equals d/dt z(t, y(t)) along the compiled kernel's y' (the
    articulated-body recursion on the package's state), the canonical transformation z(t, y)
    differentiated by a complex step: to round-off. Also the transformation's round trip."""
    model = _model(case)
    seed = 7 if isinstance(case, str) else case[0]
    ode, kern = ChainODE(model), FastChainODE(model)
    hold_random(np.random.default_rng(seed), model, ode, kern)
    can = CanonicalChain(ode)
    t = 0.3
    y = initial_state(model)
    z = can.momenta(t, y)
    assert np.abs(can.state(t, z) - y).max() <= 1e-12 * max(1.0, np.abs(y).max())
    yd = kern.rhs(t, y)
    h = 1e-30
    along = can.momenta(t + 1j * h, y + 1j * h * yd).imag / h
    zd = can.rhs(t, z)
    assert np.abs(zd - along).max() <= 1e-12 * np.abs(zd).max()


@pytest.mark.parametrize("case", ["hub_with_two_pendulums", "free_tree_with_rotors", "tree_with_slide",
                                  "free_tree_with_motors", "turntable"])
def test_tree_field_is_hamiltonian(case):
    """f = J grad H on a tree: J^T f' is symmetric, also off |q| = 1 and q . p = 0 (the subtree
    sums must make the momenta conjugate to the coordinates, or the Gauss method is not
    symplectic)."""
    from test.integrators.test_gauss4s import field_hessian

    model = _model(case)
    hess = field_hessian(model, CanonicalChain(ChainODE(model)))
    assert np.abs(hess - hess.T).max() <= 1e-6 * np.abs(hess).max()


@pytest.mark.slow
def test_step_map_on_a_tree_is_symplectic():
    """One gauss4s step on the hub with two pendulums is a symplectic map of the canonical
    variables; one rk4 step of the same field is not (the check can fail)."""
    from test.integrators.test_gauss4s import _step_map_defect

    model = _model("hub_with_two_pendulums")
    can = CanonicalChain(ChainODE(model))
    z = can.momenta(0.0, initial_state(model))
    h = 0.05
    gauss = _step_map_defect(Gauss4(can, step=h), can, 0.0, z, h)
    rk4 = _step_map_defect(RK4(can, step=h), can, 0.0, z, h)
    assert gauss <= 1e-7, gauss
    assert rk4 >= 1e3 * gauss and rk4 >= 1e-6, (rk4, gauss)


@needs_numba
@pytest.mark.parametrize("case", CASES + [(11, "fixed", {"heavy": True}), (13, "moving", {"heavy": True})],
                         ids=str)
def test_compiled_tree_field_matches_numpy(case):
    """canonical_kernel's sweeps over a tree against canonical.py's numpy form (subtree sums,
    a dense solve of M), off |q| = 1 and q . p = 0 too; heavy tips take the square-root
    elimination."""
    from gyro_sim.dynamics.canonical_kernel import FastCanonicalChain

    model = _model(case)
    ode, fode = ChainODE(model), FastChainODE(model)
    hold_random(np.random.default_rng(3), model, ode, fode)
    from test.integrators.test_gauss4s import compiled_against_numpy

    field, state = compiled_against_numpy(model, CanonicalChain(ode), FastCanonicalChain(fode))
    assert field <= 1e-12 and state <= 1e-12


@needs_numba
@pytest.mark.slow
@pytest.mark.parametrize("case", list(NAMED) + list(MOTOR_CHAINS))
def test_gauss4s_follows_dop853_on_trees(case):
    """1 s at 1 ms steps: gauss4s (compiled) on the canonical equations against dop853 at
    rtol 1e-12 on the package's state (no code of the canonical form): the coordinates and
    rates to gauss4s's truncation (measured 1.3e-8 on the hub with two pendulums, 2e-13 to
    4e-10 on the others), the rotor angles (hundreds of radians) relative to their size."""
    scene = _scene(case)
    sims = {name: Simulator(copy.deepcopy(scene), integrator=name, step=1e-3, rtol=1e-12, atol=1e-12)
            for name in ("gauss4s", "dop853")}
    for sim in sims.values():
        sim.advance(1.0)
    a, b = sims["gauss4s"].state, sims["dop853"].state
    rotors = np.zeros(a.size, dtype=bool)
    rotors[sims["dop853"].model.i_kappa] = True
    assert np.abs(a - b)[~rotors].max() <= 1e-7 * max(1.0, np.abs(b[~rotors]).max())
    if rotors.any():
        assert np.abs(a - b)[rotors].max() <= 1e-10 * np.abs(b[rotors]).max()


def _momenta(sim, can):
    """(world angular momentum about the origin, linear momentum) of sim's state: bilinear in z."""
    z = can.momenta(sim.time, sim.state)
    return can.angular_momentum(z), z[can.i_pr]


@needs_numba
@pytest.mark.slow
@pytest.mark.parametrize("case", ["free_tree_with_rotors", "free_tree_with_motors"])
def test_free_tree_keeps_energy_bounded_and_momenta_to_round_off(case):
    """2e4 steps of 1 ms on a free-floating tree with spinning rotors (and geared motors): with
    gauss4s the linear and angular momentum stay at their initial values to round-off, and the
    error of the Jacobi integral (the energy less the speed rotor's part: what such a rotor
    conserves) does not grow beyond round-off (its largest over the second 10 s is within twice
    that over the first, plus 1e-12: measured 1e-13 to 6e-13, wandering); gauss4 on the
    package's state keeps the momenta only to its truncation (the check can fail)."""
    drift, energy = {}, {}
    for name in ("gauss4s", "gauss4"):
        sim = Simulator(NAMED[case](), integrator=name, step=1e-3)
        can = CanonicalChain(ChainODE(sim.model))
        L0, P0 = _momenta(sim, can)
        assert "jacobi" in conserved(sim.model)
        E0 = sim.invariants()["jacobi"]
        worst, halves = 0.0, [0.0, 0.0]
        for i in range(20):
            sim.advance(1.0)
            L, P = _momenta(sim, can)
            r0 = sim.state[sim.model.i_r0]
            scale = np.abs(L0).max() + np.linalg.norm(r0) * np.linalg.norm(P0)
            worst = max(worst, np.abs(L - L0).max() / scale, np.abs(P - P0).max() / np.abs(P0).max())
            halves[i // 10] = max(halves[i // 10], abs(sim.invariants()["jacobi"] - E0) / abs(E0))
        drift[name], energy[name] = worst, halves
    assert drift["gauss4s"] <= 5e-14, drift
    assert drift["gauss4"] >= 30 * drift["gauss4s"], drift
    assert energy["gauss4s"][1] <= 2.0 * energy["gauss4s"][0] + 1e-12, energy
    assert max(energy["gauss4s"]) <= 5e-12, energy


@needs_numba
def test_fixed_takes_gauss4s_on_a_stiff_tree():
    """The spacecraft with its panels' springs stiffened to 2e8 N m/rad (h |lambda| = 3.4 at
    1 ms, beyond rk4's 1.4) and its wheels at 300-480 rad/s: "fixed" chooses gauss4s, as on a
    stiff chain, and keeps the energy (5e-11 of it over 0.2 s, measured)."""
    scene = spacecraft(300.0)
    for panel in scene["bodies"][1:]:
        panel["joint"]["spring"]["stiffness"] = 2e8
        panel["initial"] = {"angle": 1e-4, "rate": 0.0}
    sim = Simulator(scene, integrator="fixed", step=1e-3)
    E0 = sim.invariants()["energy"]
    sim.advance(0.2)
    fixed = sim.integrator
    assert fixed.implicit == "gauss4s"
    assert fixed.current == "gauss4s" and fixed.switches == [], fixed.reason
    assert abs(sim.invariants()["energy"] - E0) <= 1e-9 * abs(E0)
