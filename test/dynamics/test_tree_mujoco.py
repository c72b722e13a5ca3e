"""A branched tree against MuJoCo: a torso turning on a hinge with two arms of two hinges each (the
right arm's elbow a slide), written here both as a gyro_sim scene (`parent`, `joint.at`) and as
an MJCF (not imported). MuJoCo's accelerations (mj_forward's qacc) at random states and forces
to round-off, and a motion under gravity and constant forces, MuJoCo's RK4 at a small step
against dop853 at tight tolerances, to 1e-9 (docs/theory.md section 11)."""
from __future__ import annotations

import numpy as np
import pytest

from gyro_sim import Simulator
from gyro_sim.dynamics.model import initial_state

mujoco = pytest.importorskip("mujoco", reason="MuJoCo is the optional extra [models]")

G = 9.81
MUJOCO_STEP = 1e-4
AGREEMENT = 1e-9
#: each body: name, parent, joint type, axis, joint point in the parent's frame, mass, centre of
#: mass, inertia about it (diagonal, body axes)
BODIES = (
    ("torso", "base", "hinge", (0, 0, 1), (0.0, 0.0, 1.0), 8.0, (0.0, 0.02, 0.25), (0.30, 0.25, 0.08)),
    ("left_upper", "torso", "hinge", (0, 1, 0), (0.25, 0.0, 0.45), 1.5, (0.05, 0.0, -0.15), (0.012, 0.014, 0.003)),
    ("left_lower", "left_upper", "hinge", (1, 0, 1), (0.05, 0.0, -0.30), 1.0, (0.0, 0.03, -0.12),
     (0.008, 0.009, 0.002)),
    ("right_upper", "torso", "hinge", (0, 1, 0), (-0.25, 0.0, 0.45), 1.5, (-0.05, 0.0, -0.15),
     (0.012, 0.014, 0.003)),
    ("right_lower", "right_upper", "slide", (0, 0, 1), (-0.05, 0.0, -0.30), 0.8, (0.0, 0.0, -0.10),
     (0.006, 0.006, 0.001)),
)


def scene(q0=(0.0,) * 5, v0=(0.0,) * 5) -> dict:
    """The tree with its joints' initial coordinates q0 and rates v0 (MuJoCo's qpos, qvel)."""
    bodies = []
    for (name, parent, kind, axis, at, mass, com, inertia), q, v in zip(BODIES, q0, v0):
        initial = {"position": float(q), "velocity": float(v)} if kind == "slide" else \
            {"angle": float(q), "rate": float(v)}
        bodies.append({"name": name, "parent": parent, "mass": mass, "com": list(com),
                       "joint": {"type": kind, "axis": list(axis), "at": list(at)},
                       "inertia_com": np.diag(inertia).tolist(), "initial": initial})
    return {"name": "torso", "gravity": [0.0, 0.0, -G], "base": {"type": "fixed"}, "bodies": bodies}


def mjcf() -> str:
    def body(index: int, indent: str) -> str:
        name, _, kind, axis, at, mass, com, inertia = BODIES[index]
        children = "".join(body(j, indent + "  ") for j, b in enumerate(BODIES) if b[1] == name)
        return (f'{indent}<body name="{name}" pos="{" ".join(map(repr, at))}">\n'
                f'{indent}  <joint name="{name}" type="{kind}" axis="{" ".join(map(str, axis))}"/>\n'
                f'{indent}  <inertial pos="{" ".join(map(repr, com))}" mass="{mass!r}" '
                f'diaginertia="{" ".join(map(repr, inertia))}"/>\n{children}{indent}</body>\n')

    return (f'<mujoco model="torso">\n  <option gravity="0 0 -{G}" timestep="{MUJOCO_STEP}" integrator="RK4">\n'
            f'    <flag contact="disable" constraint="disable"/>\n  </option>\n  <worldbody>\n'
            f'{body(0, "    ")}  </worldbody>\n</mujoco>\n')


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_torso_with_two_arms_accelerates_as_in_mujoco(backend):
    mj = mujoco.MjModel.from_xml_string(mjcf())
    d = mujoco.MjData(mj)
    sim = Simulator(scene(), backend=backend)
    model = sim.model
    assert list(model.parent) == [-1, 0, 1, 0, 3] and not model.chain
    assert [mj.body(i).name for i in range(1, mj.nbody)] == list(model.names)  # the same order
    rng = np.random.default_rng(5)
    worst = 0.0
    for _ in range(10):
        d.qpos[:], d.qvel[:] = rng.uniform(-1.5, 1.5, 5), rng.normal(size=5)
        d.qfrc_applied[:] = rng.normal(size=5)
        mujoco.mj_forward(mj, d)
        sim.set_axis_moments(d.qfrc_applied)
        y = initial_state(model)
        y[model.i_phi], y[model.i_vel] = d.qpos, d.qvel
        udot = sim.held_rhs()(0.0, y)[model.i_vel]
        worst = max(worst, float(np.max(np.abs(udot - d.qacc)) / np.max(np.abs(d.qacc))))
    assert worst <= 1e-12, worst  # measured: a few 1e-15


def test_torso_with_two_arms_moves_as_in_mujoco():
    mj = mujoco.MjModel.from_xml_string(mjcf())
    d = mujoco.MjData(mj)
    q0, v0, force = np.array([0.3, 0.8, -0.5, -0.6, 0.05]), np.array([1.0, 0.0, 2.0, -1.0, 0.3]), \
        np.array([0.5, -1.0, 0.2, 1.0, 3.0])
    d.qpos[:], d.qvel[:], d.qfrc_applied[:] = q0, v0, force
    sim = Simulator(scene(q0, v0), integrator="dop853", rtol=1e-12, atol=1e-14)
    sim.set_axis_moments(force)
    steps = int(round(0.5 / MUJOCO_STEP))
    for _ in range(steps):
        mujoco.mj_step(mj, d)
    sim.advance(steps * MUJOCO_STEP)
    y = sim.state
    assert np.ptp(d.qpos - q0) > 0.1  # it moved
    # measured: 2.7e-14 (coordinates), 6.8e-13 (rates)
    np.testing.assert_allclose(y[sim.model.i_phi], d.qpos, rtol=0, atol=AGREEMENT)
    np.testing.assert_allclose(y[sim.model.i_vel], d.qvel, rtol=0, atol=AGREEMENT)
