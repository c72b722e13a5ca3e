"""Trees of gyrostats (docs/theory.md section 11) against the closed forms of
test/oracles/tree_closed_forms.py, and the tree's code paths against the chain's:

- two equal pendulums on a hub pendulum: the eigenvalues of the linear model are (a.1), the
  antisymmetric mode at the single pendulum's frequency, and the two roots of (a.2); on a hub
  that slides: (a.3) and a zero frequency;
- a free hub with two hinged panels on springs, no gravity: the pinwheel deployment turns the
  hub as (b.2) says, the flapping one moves it as (b.4) says, with the panels' rates of (b.3),
  (b.5); the linear and angular momenta and the energy are kept to 1e-12;
- a chain written as a tree (its first joint point given by `joint.at`, so the tree's sums run)
  moves as the chain does, to round-off; a tree listed in another order moves the same;
- the loader's refusals name the key.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # test/: the oracles package

from oracles.tree_closed_forms import (
    FreeHubPanels,
    HubPendulums,
    bar,
    flapping_hub_offset,
    flapping_rate_squared,
    hub_pendulum_frequencies,
    pinwheel_hub_angle,
    pinwheel_rate_squared,
    slider_frequencies,
)

from gyro_sim import Simulator
from gyro_sim.dynamics.model import compile_model
from gyro_sim.scene.load import SceneError, load_scene

G = 9.81


def _pendulum(name: str, mass: float, com: float, about_hinge: float, **extra) -> dict:
    """A body on a hinge about x, its centre of mass `com` below the hinge, moment `about_hinge`."""
    about_com = about_hinge - mass * com * com
    body = {"name": name, "joint": {"type": "hinge", "axis": [1, 0, 0]}, "mass": mass, "com": [0, 0, -com],
            "inertia_com": [[about_com, 0, 0], [0, about_com, 0], [0, 0, 1e-3]]}
    body.update(extra)
    return body


def _frequencies(sim: Simulator) -> np.ndarray:
    """The oscillation frequencies (rad/s) of the linear model at the scene's state, ascending."""
    ev = np.linalg.eigvals(sim.linearize().A)
    return np.sort(np.abs(ev.imag))[::2]


def test_two_pendulums_on_a_hub_pendulum_have_the_closed_form_frequencies():
    p = HubPendulums(hub_mass=2.0, hub_com=0.3, hub_inertia=0.5, attach_down=0.5, attach_side=0.2,
                     mass=0.5, com=bar(0.5, 0.8)[0], inertia=bar(0.5, 0.8)[1], g=G)
    hub = _pendulum("hub", p.hub_mass, p.hub_com, p.hub_inertia)
    arms = [_pendulum(f"arm{i}", p.mass, p.com, p.inertia, parent="hub") for i in (1, 2)]
    arms[0]["joint"]["at"] = [0, p.attach_side, -p.attach_down]
    arms[1]["joint"]["at"] = [0, -p.attach_side, -p.attach_down]
    sim = Simulator({"name": "hub", "gravity": [0, 0, -G], "base": {"type": "fixed"}, "bodies": [hub, *arms]})
    anti, (low, high) = hub_pendulum_frequencies(p)
    np.testing.assert_allclose(_frequencies(sim), [low, anti, high], rtol=1e-12)


def test_two_pendulums_on_a_sliding_hub_have_the_closed_form_frequencies():
    hub_mass, m = 3.0, 0.4
    l, J = bar(m, 0.6)
    hub = {"name": "cart", "joint": {"type": "slide", "axis": [0, 1, 0]}, "mass": hub_mass,
           "inertia": {"axial": 0.01, "transverse": 0.01}}
    arms = [_pendulum(f"arm{i}", m, l, J, parent="cart") for i in (1, 2)]
    arms[0]["joint"]["at"], arms[1]["joint"]["at"] = [0.3, 0, 0], [-0.3, 0, 0]
    # the pendulums swing in the y-z plane, across the slide's axis y
    sim = Simulator({"name": "cart", "gravity": [0, 0, -G], "base": {"type": "fixed"}, "bodies": [hub, *arms]})
    anti, sym = slider_frequencies(hub_mass, m, l, J, G)
    np.testing.assert_allclose(_frequencies(sim), [0.0, anti, sym], rtol=1e-12, atol=1e-9)


PANELS = FreeHubPanels(hub_mass=50.0, hub_inertia=8.0, hinge=0.8, mass=4.0, com=1.2, inertia=1.5, stiffness=3.0)


def free_hub_scene(p: FreeHubPanels, mirror: bool, beta0: float) -> dict:
    """Part b of the oracle: the plane is x-y, the hinges' axes along z (the second's along -z
    when mirrored), the hub's centre of mass at its joint point, both panels at beta0, at rest."""
    def panel(name, side, axis):
        return {"name": name, "parent": "hub", "mass": p.mass, "com": [side * p.com, 0, 0],
                "joint": {"type": "hinge", "axis": axis, "at": [side * p.hinge, 0, 0],
                          "spring": {"stiffness": p.stiffness}},
                "inertia_com": [[0.7, 0, 0], [0, p.inertia + 0.3, 0], [0, 0, p.inertia]],
                "initial": {"angle": beta0}}

    hub = {"name": "hub", "joint": {"type": "spherical"}, "mass": p.hub_mass,
           "inertia_com": [[5.0, 0, 0], [0, 6.0, 0], [0, 0, p.hub_inertia]],
           "initial": {"quaternion": [1, 0, 0, 0]}}
    return {"name": "panels", "base": {"type": "free"},
            "bodies": [hub, panel("one", 1, [0, 0, 1]), panel("two", -1, [0, 0, -1] if mirror else [0, 0, 1])]}


def _deploy(mirror: bool, beta0: float, backend: str = "auto"):
    sim = Simulator(free_hub_scene(PANELS, mirror, beta0), integrator="dop853", rtol=1e-12, atol=1e-14,
                    backend=backend)
    m = sim.model
    before = sim.invariants()
    states = []
    for _ in range(300):
        sim.advance(0.02)
        states.append(sim.state)
    y = np.array(states)
    return sim, before, y, y[:, m.i_phi], y[:, m.i_vel][:, m.col_hinge]


def _kept(sim: Simulator, before: dict) -> None:
    after = sim.invariants()
    assert abs(after["energy"] - before["energy"]) < 1e-12 * abs(before["energy"])
    for key in ("linear_momentum", "angular_momentum"):
        np.testing.assert_allclose(after[key], before[key], rtol=0, atol=1e-12)


def test_pinwheel_deployment_turns_the_free_hub_as_the_closed_form_says():
    beta0 = 1.1
    sim, before, y, beta, rate = _deploy(False, beta0)
    assert np.ptp(beta[:, 0]) > 2.0  # through beta = 0 and back
    np.testing.assert_allclose(beta[:, 1], beta[:, 0], atol=1e-12)
    q = y[:, sim.model.i_quat[0]]
    np.testing.assert_allclose(q[:, 1:3], 0.0, atol=1e-12)  # it turns about z only
    hub_angle = 2 * np.arctan2(q[:, 3], q[:, 0])
    assert np.ptp(hub_angle) > 0.1
    np.testing.assert_allclose(hub_angle, pinwheel_hub_angle(beta[:, 0], beta0, PANELS), atol=1e-11)
    np.testing.assert_allclose(rate[:, 0] ** 2, pinwheel_rate_squared(beta[:, 0], PANELS.stiffness * beta0 ** 2,
                                                                       PANELS), atol=1e-10)
    np.testing.assert_allclose(y[:, sim.model.i_r0], 0.0, atol=1e-12)  # the hub does not translate
    _kept(sim, before)


def test_flapping_deployment_moves_the_free_hub_as_the_closed_form_says():
    beta0 = 1.1
    sim, before, y, beta, rate = _deploy(True, beta0)
    assert np.ptp(beta[:, 0]) > 2.0
    np.testing.assert_allclose(beta[:, 1], beta[:, 0], atol=1e-12)
    np.testing.assert_allclose(y[:, sim.model.i_quat[0]] - [1, 0, 0, 0], 0.0, atol=1e-12)  # mirror images: no turn
    offset = y[:, sim.model.i_r0]
    assert np.ptp(offset[:, 1]) > 0.1
    np.testing.assert_allclose(offset[:, [0, 2]], 0.0, atol=1e-12)
    np.testing.assert_allclose(offset[:, 1], flapping_hub_offset(beta[:, 0], beta0, PANELS), atol=1e-11)
    np.testing.assert_allclose(rate[:, 0] ** 2, flapping_rate_squared(beta[:, 0], PANELS.stiffness * beta0 ** 2,
                                                                        PANELS), atol=1e-10)
    _kept(sim, before)


# --- the tree's code paths against the chain's -----------------------------------------------------------

def _chain_bodies() -> list[dict]:
    """Four bodies: a spherical joint with a torque rotor, a hinge, a slide, a hinge with a heavy tip."""
    return [
        {"name": "a", "joint": {"type": "spherical"}, "mass": 1.0, "com": [0.05, 0, 0.1],
         "inertia": {"axial": 0.02, "transverse": 0.03}, "next_joint": [0.0, 0.1, 0.3],
         "rotors": [{"name": "w", "axis": [1, 0, 0], "position": [0, 0, 0.1], "mass": 0.2, "axial_inertia": 0.002,
                     "transverse_inertia": 0.001, "mode": "torque", "spin": 40.0}],
         "initial": {"euler": [0.3, 0.5, 0.1], "euler_rates": [1.0, -0.5, 2.0]}},
        {"name": "b", "joint": {"type": "hinge", "axis": [0, 1, 0]}, "mass": 0.7, "com": [0, 0, 0.15],
         "inertia": {"axial": 0.01, "transverse": 0.025}, "next_joint": [0, 0, 0.3],
         "initial": {"angle": 0.4, "rate": -1.0}},
        {"name": "c", "joint": {"type": "slide", "axis": [0, 0, 1]}, "mass": 0.5, "com": [0, 0.02, 0.05],
         "inertia": {"axial": 0.004, "transverse": 0.006}, "next_joint": [0.1, 0, 0.1],
         "initial": {"position": 0.05, "velocity": 0.3}},
        {"name": "d", "joint": {"type": "hinge", "axis": [1, 0, 0]}, "mass": 5.0, "com": [0, 0, 0.2],
         "inertia": {"axial": 0.05, "transverse": 0.25}, "initial": {"angle": -0.3, "rate": 0.7}},
    ]


@pytest.mark.parametrize("base", ["fixed", "free", "moving"])
def test_a_chain_written_as_a_tree_moves_as_the_chain(base):
    at = [0.1, -0.2, 0.3]
    base_of = {"fixed": {"type": "fixed"}, "free": {"type": "free", "velocity": [0.1, 0, -0.2]},
               "moving": {"type": "moving", "motion": {"type": "sine", "amplitude": [0, 0.05, 0.02],
                                                         "frequency": 2.0}}}[base]
    chain = {"name": "c", "gravity": [0, 0, -G], "base": dict(base_of, position=at), "bodies": _chain_bodies()}
    bodies = _chain_bodies()
    # the same joint points, given by the children: the tree's sums run
    bodies[1]["joint"]["at"] = bodies[0].pop("next_joint")
    if base != "free":
        bodies[0]["joint"]["at"] = at
        base_of = dict(base_of, position=[0, 0, 0])
    else:
        base_of = dict(base_of, position=at)
    tree = {"name": "t", "gravity": [0, 0, -G], "base": base_of, "bodies": bodies}
    a, b = Simulator(chain, integrator="rk4", step=1e-3), Simulator(tree, integrator="rk4", step=1e-3)
    assert a.model.chain and not b.model.chain
    a.advance(0.2)
    b.advance(0.2)
    np.testing.assert_allclose(b.state, a.state, rtol=0, atol=1e-12)
    for wa, wb in zip(a.wrenches(), b.wrenches()):
        np.testing.assert_allclose(wb.force, wa.force, rtol=0, atol=1e-10)
        np.testing.assert_allclose(wb.moment, wa.moment, rtol=0, atol=1e-10)
    ia, ib = a.invariants(), b.invariants()
    assert abs(ia["energy"] - ib["energy"]) < 1e-10


def _branched(order: list[int]) -> dict:
    """A hub with an arm of two bodies and a single body, listed in `order` (parents first)."""
    bodies = {
        0: {"name": "hub", "joint": {"type": "spherical"}, "mass": 2.0, "com": [0, 0, 0.1],
            "inertia": {"axial": 0.05, "transverse": 0.08}, "initial": {"euler_rates": [0.5, 0.2, -0.3]}},
        1: {"name": "upper", "parent": "hub", "joint": {"type": "hinge", "axis": [1, 0, 0], "at": [0, 0.2, 0.1]},
            "mass": 0.6, "com": [0, 0, 0.15], "inertia": {"axial": 0.01, "transverse": 0.02},
            "next_joint": [0, 0, 0.3], "initial": {"angle": 0.3, "rate": 1.0}},
        2: {"name": "lower", "parent": "upper", "joint": {"type": "spherical"}, "mass": 0.4, "com": [0, 0, 0.1],
            "inertia": {"axial": 0.004, "transverse": 0.009}, "initial": {"euler_rates": [0.1, 0.4, 2.0]}},
        3: {"name": "side", "parent": "hub", "joint": {"type": "slide", "axis": [0, 1, 0], "at": [0, -0.2, 0.1]},
            "mass": 0.8, "com": [0, 0, 0.1], "inertia": {"axial": 0.003, "transverse": 0.01},
            "initial": {"position": 0.02, "velocity": -0.2}},
    }
    return {"name": "branched", "gravity": [0, 0, -G], "base": {"type": "fixed"}, "bodies": [bodies[i] for i in order]}


def test_a_tree_listed_in_another_order_moves_the_same():
    a = Simulator(_branched([0, 1, 2, 3]), integrator="rk4", step=1e-3)
    b = Simulator(_branched([0, 3, 1, 2]), integrator="rk4", step=1e-3)
    np.testing.assert_array_equal(b.model.parent, [-1, 0, 0, 2])
    a.advance(0.3)
    b.advance(0.3)
    ya, yb = a.state, b.state
    ma, mb = a.model, b.model
    pa, pb = a.body_states(), b.body_states()
    for name in ("hub", "upper", "lower", "side"):
        ka, kb = ma.names.index(name), mb.names.index(name)
        np.testing.assert_allclose(pb[kb].position, pa[ka].position, atol=1e-12)
        np.testing.assert_allclose(pb[kb].angular_velocity, pa[ka].angular_velocity, atol=1e-11)
    np.testing.assert_allclose(yb[mb.i_phi], ya[ma.i_phi][[1, 0]], atol=1e-12)
    assert abs(a.invariants()["energy"] - b.invariants()["energy"]) < 1e-12
    assert abs(a.invariants()["energy"] - a.reference_invariants()["energy"]) < 1e-6


# --- the scene format --------------------------------------------------------------------------------------

def test_a_chain_with_its_parents_written_out_is_the_same_model():
    plain = load_scene({"name": "c", "base": {"type": "fixed"}, "bodies": _chain_bodies()})
    bodies = _chain_bodies()
    bodies[0]["parent"] = "base"
    for k in range(1, 4):
        bodies[k]["parent"] = bodies[k - 1]["name"]
    written = load_scene({"name": "c", "base": {"type": "fixed"}, "bodies": bodies})
    ma, mb = compile_model(plain), compile_model(written)
    assert ma.chain and mb.chain
    for key in ("parent", "offset", "s", "inertia", "col_upper", "col_related"):
        np.testing.assert_array_equal(getattr(ma, key), getattr(mb, key))


def _refusal(scene: dict) -> str:
    with pytest.raises(SceneError) as info:
        load_scene(scene)
    return str(info.value)


def test_the_loader_refuses_bad_trees_naming_the_key():
    def bodies():
        return _branched([0, 1, 2, 3])["bodies"]

    b = bodies()
    b[1]["parent"] = "nobody"
    assert "bodies[1].parent: unknown body 'nobody'" in _refusal({"name": "x", "base": {"type": "fixed"}, "bodies": b})
    b = bodies()
    b[1]["parent"] = "side"
    assert "bodies[1].parent: 'side' is listed at or after this body" in _refusal(
        {"name": "x", "base": {"type": "fixed"}, "bodies": b})
    b = bodies()
    b[3]["parent"] = "base"
    assert "bodies[3].parent: a free base carries one body" in _refusal(
        {"name": "x", "base": {"type": "free"}, "bodies": b})
    b = bodies()
    b[2]["next_joint"] = [0, 0, 0.1]  # a leaf
    assert "bodies[2].next_joint: not allowed on a body without children" in _refusal(
        {"name": "x", "base": {"type": "fixed"}, "bodies": b})
    b = bodies()
    del b[1]["next_joint"]  # its child gives no joint.at
    assert "bodies[1].next_joint: required" in _refusal({"name": "x", "base": {"type": "fixed"}, "bodies": b})
    b = bodies()
    b[0]["joint"]["at"] = [0, 0, 1]
    assert "bodies[0].joint.at: not allowed on a free base's body" in _refusal(
        {"name": "x", "base": {"type": "free"}, "bodies": b})
    b = bodies()
    b[1]["parent"] = 3
    assert "bodies[1].parent: must be a body's name or 'base'" in _refusal(
        {"name": "x", "base": {"type": "fixed"}, "bodies": b})


def test_two_bodies_on_a_fixed_base_hang_from_its_points():
    b = _branched([0, 1, 2, 3])["bodies"]
    b[3]["parent"] = "base"
    b[3]["joint"]["at"] = [1.0, 0, 0]
    sim = Simulator({"name": "x", "gravity": [0, 0, -G], "base": {"type": "fixed", "position": [0, 0, 1]},
                     "bodies": b}, integrator="rk4")
    m = sim.model
    np.testing.assert_array_equal(m.parent, [-1, 0, 1, -1])
    assert not m.col_related[m.col_hinge[1], 0]  # the side body's slide and the hub's joint: unrelated
    before = sim.invariants()["energy"]
    sim.advance(0.2)
    assert abs(sim.invariants()["energy"] - before) < 1e-6


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_an_imu_on_a_panel_of_a_spinning_hub_reads_the_spin_and_the_centripetal_force(backend):
    """The free hub spinning about z at omega with both panels out (beta = 0, turning with it: a
    steady motion, by symmetry); an IMU at the first panel's centre of mass, at radius b + l from
    the axis, reads gyro (0, 0, omega) and the specific force omega^2 (b + l) towards the axis."""
    if backend == "numba":
        pytest.importorskip("numba")
    spin = 2.0
    scene = free_hub_scene(PANELS, False, 0.0)
    scene["bodies"][0]["initial"]["angular_velocity"] = [0.0, 0.0, spin]
    scene["imus"] = [{"name": "panel_imu", "body": "one", "position": [PANELS.com, 0.0, 0.0],
                      "orientation": [1.0, 0.0, 0.0, 0.0]}]
    sim = Simulator(scene, backend=backend, integrator="dop853", rtol=1e-12, atol=1e-14)
    sim.advance(0.4)
    (imu,) = sim.imus()
    c = spin ** 2 * (PANELS.hinge + PANELS.com)
    np.testing.assert_allclose(imu.angular_velocity, [0.0, 0.0, spin], rtol=0, atol=1e-10)
    np.testing.assert_allclose(imu.linear_acceleration, [-c, 0.0, 0.0], rtol=0, atol=1e-9 * c)
    np.testing.assert_allclose(sim.state[sim.model.i_phi], 0.0, atol=1e-12)  # the panels stay out


def _damped_hub() -> dict:
    """The hub pendulum with two arms, one with Coulomb and viscous friction, one viscous."""
    hub = _pendulum("hub", 2.0, 0.3, 0.5)
    arms = [_pendulum(f"arm{i}", 0.5, 0.4, 0.1, parent="hub") for i in (1, 2)]
    arms[0]["joint"].update(at=[0, 0.2, -0.5], friction={"coulomb": 0.02, "viscous": 0.01})
    arms[1]["joint"].update(at=[0, -0.2, -0.5], friction={"viscous": 0.03})
    arms[0]["initial"], arms[1]["initial"] = {"angle": 1.0, "rate": 0.0}, {"angle": -0.5, "rate": 2.0}
    return {"name": "damped hub", "gravity": [0, 0, -G], "base": {"type": "fixed"}, "bodies": [hub, *arms]}


def test_friction_on_a_tree_closes_the_energy_balance_on_both_backends():
    """The energy lost is the work of friction (exact Coulomb friction, the node's "fixed" and
    "auto"), to the integration's accuracy; both backends the same motion."""
    final = []
    for backend in ("numpy", "numba"):
        for integrator in ("auto", "fixed"):
            sim = Simulator(_damped_hub(), backend=backend, integrator=integrator)
            before = sim.invariants()["energy"]
            for _ in range(200):
                sim.advance(0.01)
            lost = sim.invariants()["energy"] - before
            assert lost < -0.4  # measured: -0.431 J
            assert abs(lost - sim.friction_work - sim.work) < 1e-7  # measured: 6.4e-9
            final.append(sim.state)
    np.testing.assert_allclose(final[2], final[0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(final[3], final[1], rtol=0, atol=1e-9)


def test_gauss4s_takes_a_tree_and_fixed_takes_gauss4s_for_it():
    """The canonical form on trees (test/integrators/test_gauss4s_trees.py checks it): gauss4s
    steps the free hub with its panels, and "fixed" takes it as the stiff rung, as on a chain;
    a stateful tree (friction) still gets gauss4."""
    from gyro_sim.integrators.fixed import IMPLICIT, IMPLICIT_PLAIN, implicit_for

    scene = free_hub_scene(PANELS, False, 0.5)
    sim = Simulator(scene, integrator="gauss4s")
    sim.advance(0.01)
    assert np.isfinite(sim.state).all()
    assert implicit_for(Simulator(scene).model) == IMPLICIT == "gauss4s"
    assert implicit_for(Simulator(_damped_hub()).model) == IMPLICIT_PLAIN == "gauss4"


def test_a_tree_of_lagrange_gyroscopes_is_not_a_lagrange_chain():
    from gyro_sim.analytic.lagrange import LagrangeChain

    top = {"joint": {"type": "spherical"}, "mass": 1.0, "com": [0, 0, 0.1],
           "inertia": {"axial": 0.01, "transverse": 0.02}}
    bodies = [dict(top, name="a", next_joint=[0, 0, 0.2]), dict(top, name="b"), dict(top, name="c", parent="a")]
    scene = load_scene({"name": "t", "gravity": [0, 0, -G], "base": {"type": "fixed"}, "bodies": bodies})
    assert LagrangeChain.from_scene(scene) is None
    chain = load_scene({"name": "t", "gravity": [0, 0, -G], "base": {"type": "fixed"}, "bodies": bodies[:2]})
    assert LagrangeChain.from_scene(chain) is not None
