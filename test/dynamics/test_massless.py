"""Massless bodies (mass 0, no inertia): frames that only carry a joint, as a body with
several joints of an MJCF model becomes (docs/models.md, "Several joints in one body").

The compiled elimination against the numpy reference's dense solve at random states (also on
the square-root path, a light link before the massless frame and a heavy body after it), and
the energy kept by a tight integrator: the equations stay well posed when what a massless
frame carries has inertia about its axis. MuJoCo is the judge of the import
(test/scene/test_model_multijoint.py).
"""
import numpy as np
import pytest

from gyro_sim import Simulator
from gyro_sim.dynamics import kernel as fast
from gyro_sim.dynamics.model import compile_model, initial_state
from gyro_sim.dynamics.system import ChainODE, FastChainODE, heavy_subtree_ratio
from gyro_sim.scene.load import load_scene

ZERO = [[0.0] * 3 for _ in range(3)]
INERTIA = [[0.02, 0.001, 0.0], [0.001, 0.03, 0.0], [0.0, 0.0, 0.015]]


def universal_pendulum(light: float | None = None) -> dict:
    """A pendulum on a universal joint (a massless frame on a hinge about x, the rod on a hinge
    about y at the same point) carrying a second body on a skew hinge; with `light`, a link of
    that mass on a hinge first (so the rod is far heavier than the link carrying it)."""
    bodies = [
        {"name": "ux", "joint": {"type": "hinge", "axis": [1.0, 0.0, 0.0]}, "mass": 0.0, "inertia_com": ZERO,
         "next_joint": [0.0, 0.0, 0.0], "initial": {"angle": 0.3, "rate": 0.5}},
        {"name": "uy", "joint": {"type": "hinge", "axis": [0.0, 1.0, 0.0]}, "mass": 1.0, "com": [0.05, 0.0, -0.3],
         "inertia_com": INERTIA, "next_joint": [0.0, 0.0, -0.5], "initial": {"angle": -0.2, "rate": 1.0}},
        {"name": "b2", "joint": {"type": "hinge", "axis": [0.0, 0.6, 0.8]}, "mass": 0.5, "com": [0.0, 0.0, -0.2],
         "inertia_com": INERTIA, "initial": {"angle": 0.4, "rate": -0.7}},
    ]
    if light is not None:
        scale = light / 1.0
        bodies.insert(0, {"name": "link", "joint": {"type": "hinge", "axis": [0.0, 0.0, 1.0]}, "mass": light,
                          "com": [0.1, 0.0, 0.0], "inertia_com": (np.asarray(INERTIA) * scale).tolist(),
                          "next_joint": [0.2, 0.0, 0.0], "initial": {"angle": 0.1, "rate": 0.2}})
    return {"name": "universal pendulum", "gravity": [0.0, 0.0, -9.81], "base": {"type": "fixed"},
            "bodies": bodies}


def test_a_massless_carrier_is_no_heavy_subtree():
    """A massless frame has no inertia of its own to lose: the classic elimination is kept for
    it (no division by its zero mass), and a light link before it still takes the square-root
    path."""
    assert not fast.heavy_subtrees(np.array([0.0, 1.0, 0.5]))
    assert fast.heavy_subtrees(np.array([1e-4, 0.0, 1.0, 0.5]))
    assert heavy_subtree_ratio(compile_model(load_scene(universal_pendulum()))) == pytest.approx(0.5)


@pytest.mark.skipif(not fast.available(), reason="needs numba")
@pytest.mark.parametrize("light", [None, 1e-4])
def test_the_compiled_elimination_agrees_with_the_dense_solve(light):
    model = compile_model(load_scene(universal_pendulum(light)))
    assert fast.heavy_subtrees(model.mass) == (light is not None)
    comp, ref = FastChainODE(model), ChainODE(model)
    rng = np.random.default_rng(3)
    tau = rng.normal(size=len(model.hinge_bodies))
    for ode in (comp, ref):
        ode.hold(0.0, ode.spins(0.0), tau, None)
    for _ in range(5):
        y = initial_state(model)
        y[model.i_phi] = rng.uniform(-2.0, 2.0, y[model.i_phi].shape)
        y[model.i_vel] = rng.normal(size=y[model.i_vel].shape)
        a, b = comp.rhs(0.0, y), ref.rhs(0.0, y)
        assert np.all(np.isfinite(a))
        assert np.abs(a - b).max() <= 1e-11 * np.abs(b).max()


def test_the_energy_is_kept():
    """No friction, no command: the energy (kinetic and gravity's) kept to 1e-10 over 2 s."""
    sim = Simulator(load_scene(universal_pendulum()), integrator="dop853", rtol=1e-12, atol=1e-12,
                    backend="numpy")
    sim.advance(2.0)
    snapshot = sim.snapshot()
    assert abs(snapshot.drift["energy"]) <= 1e-10
    assert abs(sim.joint_states().position[0] - 0.3) > 0.05  # the massless frame turned



@pytest.mark.parametrize("frame", ["hinge", "slide"])
def test_the_canonical_integrator_takes_massless_frames(frame):
    """gauss4s (the chain as a Hamiltonian system: the momenta through the mass matrix) on a
    massless hinge or slide frame: the motion of dop853 at 1e-12 over 0.5 s, to 1e-9."""
    data = universal_pendulum()
    if frame == "slide":
        data["bodies"][0]["joint"] = {"type": "slide", "axis": [1.0, 0.0, 0.0]}
        data["bodies"][0]["initial"] = {"position": 0.1, "velocity": 0.5}
    scene = load_scene(data)
    reference = Simulator(scene, integrator="dop853", rtol=1e-12, atol=1e-12, backend="numpy")
    reference.advance(0.5)
    expected = np.asarray(reference.joint_states().position)
    for backend in ("numpy", "numba") if fast.available() else ("numpy",):
        sim = Simulator(scene, integrator="gauss4s", step=1e-3, backend=backend)
        sim.advance(0.5)
        assert np.max(np.abs(np.asarray(sim.joint_states().position) - expected)) <= 1e-9
