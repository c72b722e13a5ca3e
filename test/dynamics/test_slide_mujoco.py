"""The cart-pole on a slide against MuJoCo: the same cart and pole written as an MJCF here (not
imported: the scene is test_slide.cart_pole), MuJoCo's accelerations (mj_forward's qacc) at
random states and forces, and a motion under gravity and constant forces, MuJoCo's RK4 at
test/scene's step against dop853 at tight tolerances (the imported models: test/scene/
test_slide_models.py)."""
from __future__ import annotations

import numpy as np
import pytest

from gyro_sim import Simulator
from gyro_sim.dynamics.model import initial_state

from test.dynamics.test_slide import IC, G, L, M, cart_pole, m

mujoco = pytest.importorskip("mujoco", reason="MuJoCo is the optional extra [models]")

#: MuJoCo's step (as test/scene/test_model_import.py's MUJOCO_STEP) and the agreement asked
MUJOCO_STEP = 1e-4
AGREEMENT = 1e-9

CART_POLE = f"""<mujoco model="cart-pole">
  <option gravity="0 0 -{G}" timestep="{MUJOCO_STEP}" integrator="RK4">
    <flag contact="disable" constraint="disable"/>
  </option>
  <worldbody>
    <body name="cart">
      <joint name="cart" type="slide" axis="1 0 0"/>
      <inertial pos="0 0 0" mass="{M}" diaginertia="0.1 0.2 0.3"/>
      <body name="pole">
        <joint name="pole" type="hinge" axis="0 1 0"/>
        <inertial pos="0 0 {L}" mass="{m}" diaginertia="{IC} {IC} {IC}"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_cart_pole_accelerates_as_in_mujoco(backend):
    mj = mujoco.MjModel.from_xml_string(CART_POLE)
    d = mujoco.MjData(mj)
    sim = Simulator(cart_pole(), backend=backend)
    model = sim.model
    rng = np.random.default_rng(3)
    worst = 0.0
    for _ in range(10):
        d.qpos[:], d.qvel[:], d.qfrc_applied[:] = rng.uniform(-2, 2, 2), rng.normal(size=2), rng.normal(size=2)
        mujoco.mj_forward(mj, d)
        sim.set_axis_moments(d.qfrc_applied)
        y = initial_state(model)
        y[model.i_phi], y[model.i_vel] = d.qpos, d.qvel
        udot = sim.held_rhs()(0.0, y)[model.i_vel]
        worst = max(worst, float(np.max(np.abs(udot - d.qacc)) / np.max(np.abs(d.qacc))))
    assert worst <= 1e-12


def test_cart_pole_moves_as_in_mujoco():
    mj = mujoco.MjModel.from_xml_string(CART_POLE)
    d = mujoco.MjData(mj)
    q0, v0, force = np.array([0.3, 0.4]), np.array([-0.5, 1.2]), np.array([1.5, -0.1])
    d.qpos[:], d.qvel[:], d.qfrc_applied[:] = q0, v0, force
    sim = Simulator(cart_pole(*q0[:1], *v0[:1], q0[1], v0[1]), integrator="dop853", rtol=1e-13, atol=1e-13)
    assert np.array_equal(sim.joint_states().position, q0) and np.array_equal(sim.joint_states().velocity, v0)
    sim.set_axis_moments(force)
    worst = 0.0
    for t in np.linspace(0.1, 1.0, 10):
        mujoco.mj_step(mj, d, nstep=int(round((t - d.time) / MUJOCO_STEP)))
        sim.advance(d.time - sim.time)
        js = sim.joint_states()
        worst = max(worst, float(np.max(np.abs(np.array(js.position) - d.qpos))),
                    float(np.max(np.abs(np.array(js.velocity) - d.qvel))))
    assert worst <= AGREEMENT and abs(d.qpos[1] - q0[1]) > 0.5
