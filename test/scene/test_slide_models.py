"""Published models on slide joints, imported unlocked, against MuJoCo (docs/models.md): dm_control's
cart-pole (test/scene/models/dm_control/, Apache-2.0) and Gymnasium 1.4.0's inverted pendulum and
inverted double pendulum (test/scene/models/gymnasium/, MIT), each a cart on a slide with
damping on its joints.

Judged as test/scene/test_armature_models.py judges (its `judged` copy with a keyframe, its
`mujoco_model`: contacts, constraints and actuators off, RK4 at MUJOCO_STEP): MuJoCo's
accelerations (mj_forward's qacc) at random states, and a motion from the keyframe under gravity
and a constant generalised force on every joint over 0.5 s, both to AGREEMENT.
"""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco", reason="MuJoCo is the optional extra [models]")

from gyro_sim import Simulator
from gyro_sim.dynamics.model import initial_state
from gyro_sim.scene.load import load_scene
from gyro_sim.scene.mjcf import import_model
from test.scene.test_armature_models import FORCE, MODELS, PENDULUM, Judged, judged, mujoco_model
from test.scene.test_model_import import MUJOCO_STEP

CARTPOLE = MODELS / "dm_control" / "cartpole.xml"
INVERTED = MODELS / "gymnasium" / "inverted_pendulum.xml"
#: agreement with MuJoCo: accelerations relative to their largest, joint positions (m, rad)
AGREEMENT = 1e-9

CASES = {
    "dm_control cartpole": (Judged(CARTPOLE, (), {}, 0.0, "0.3 0.4", "-0.5 1.2"), ["slider", "hinge_1"]),
    "gymnasium inverted pendulum": (Judged(INVERTED, (), {}, 0.0, "0.2 -0.3", "0.4 -1"), ["slider", "hinge"]),
    "gymnasium inverted double pendulum": (Judged(PENDULUM, (), {}, 0.0, "0.2 0.4 -0.7", "0.3 1.2 -0.8"),
                                           ["slider", "hinge", "hinge2"]),
}


def copy_of(case: Judged, tmp_path: Path) -> Path:
    """The judged copy, next to the files it includes."""
    if (case.path.parent / "common").is_dir():
        shutil.copytree(case.path.parent / "common", tmp_path / "common")
    return judged(case, tmp_path)


@pytest.mark.parametrize("name", list(CASES))
def test_a_cart_on_a_slide_imports_unlocked(name, tmp_path):
    case, names = CASES[name]
    copy = copy_of(case, tmp_path)
    bodies = import_model(copy).mapping["bodies"]
    assert [b["name"] for b in bodies] == names
    cart = bodies[0]["joint"]
    assert cart["type"] == "slide" and cart["axis"] == [1.0, 0.0, 0.0] and cart["friction"]["viscous"] > 0.0
    assert bodies[0]["initial"]["position"] == float(case.qpos.split()[0])
    assert all(b["joint"]["type"] == "hinge" for b in bodies[1:])


@pytest.mark.parametrize("name", list(CASES))
def test_a_cart_on_a_slide_accelerates_as_in_mujoco(name, tmp_path):
    case, _ = CASES[name]
    copy = copy_of(case, tmp_path)
    m, _ = mujoco_model(copy, {})
    sim = Simulator(load_scene(copy), backend="numpy")
    model = sim.model
    assert m.nv == model.N == len(model.hinge_bodies) and list(model.slide_bodies) == [0]
    d = mujoco.MjData(m)
    rng = np.random.default_rng(2)
    worst = 0.0
    for _ in range(5):
        d.qpos[:] = rng.uniform(-1.5, 1.5, m.nq)
        d.qvel[:] = rng.normal(size=m.nv)
        mujoco.mj_forward(m, d)
        y = initial_state(model)
        y[model.i_phi], y[model.i_vel] = d.qpos, d.qvel
        udot = sim.held_rhs()(0.0, y)[model.i_vel]
        worst = max(worst, float(np.max(np.abs(udot - d.qacc)) / np.max(np.abs(d.qacc))))
    print(f"{name}: accelerations within {worst:.2g} (relative) of MuJoCo's")
    assert worst <= AGREEMENT


@pytest.mark.parametrize("backend", ["numpy", "numba"])
@pytest.mark.parametrize("name", list(CASES))
def test_a_cart_on_a_slide_moves_as_in_mujoco(name, backend, tmp_path):
    case, _ = CASES[name]
    copy = copy_of(case, tmp_path)
    scene = load_scene(copy)
    m, (qpos, qvel) = mujoco_model(copy, {})
    d = mujoco.MjData(m)
    d.qpos[:], d.qvel[:] = qpos, qvel
    d.qfrc_applied[:] = FORCE
    sim = Simulator(scene, integrator="dop853", rtol=1e-13, atol=1e-13, backend=backend)
    assert np.allclose(sim.joint_states().position, qpos) and np.allclose(sim.joint_states().velocity, qvel)
    sim.set_axis_moments([FORCE] * len(sim.axis_names))
    worst = moved = 0.0
    for t in np.linspace(0.1, 0.5, 5):
        mujoco.mj_step(m, d, nstep=int(round((t - d.time) / MUJOCO_STEP)))
        sim.advance(d.time - sim.time)
        q = np.asarray(sim.joint_states().position)
        worst = max(worst, float(np.max(np.abs(q - d.qpos))))
        moved = max(moved, float(np.max(np.abs(d.qpos - qpos))))
    print(f"{name}: joint positions within {worst:.2g} of MuJoCo over 0.5 s (moved {moved:.2g})")
    assert worst <= AGREEMENT and moved > 0.01


#: a cart on a tilted slide with armature, stiffness (springref), damping and a position servo,
#: a pole on it, a slider on the pole along its length (a slide after a hinge)
SERVO_CART = """<mujoco model="servo_cart">
  <option gravity="0 0 -9.81"/>
  <worldbody>
    <body name="cart" pos="0 0 0.5">
      <joint name="rail" type="slide" axis="1 0 0.3" armature="0.2" stiffness="3" springref="0.1" damping="0.4"/>
      <inertial pos="0.02 0 0" mass="1.2" diaginertia="0.01 0.02 0.015"/>
      <body name="pole" pos="0 0.05 0">
        <joint name="pivot" type="hinge" axis="0 1 0"/>
        <inertial pos="0 0 0.3" mass="0.3" diaginertia="0.009 0.009 0.0002"/>
        <body name="bead" pos="0 0 0.2">
          <joint name="bead" type="slide" axis="0 0 1"/>
          <inertial pos="0 0 0" mass="0.1" diaginertia="1e-4 1e-4 1e-4"/>
        </body>
      </body>
    </body>
  </worldbody>
  <actuator>
    <position name="hold" joint="rail" kp="20" kv="3" ctrlrange="-1 1"/>
    <motor name="push" joint="bead" gear="2"/>
  </actuator>
  <keyframe><key name="off" qpos="0.2 0.5 -0.05" qvel="-0.3 0.8 0.2"/></keyframe>
</mujoco>
"""


def test_a_slides_armature_spring_damper_and_servo_are_mujocos(tmp_path):
    """The slide's terms in N, kg, N/m, N s/m: MuJoCo's qacc at random states and controls, and
    the motion from the keyframe with held controls for 0.5 s (RK4 at 5e-5 s, as the hinges'
    servos are judged), and the published efforts MuJoCo's qfrc_actuator with the damper."""
    from test.scene.test_model_import import write
    from test.scene.test_model_joint_terms import mujoco_model as plain_mujoco_model

    path = write(tmp_path, "cart.xml", SERVO_CART)
    joints = {b["name"]: b["joint"] for b in import_model(path).mapping["bodies"]}
    assert joints["rail"]["type"] == joints["bead"]["type"] == "slide"
    assert joints["rail"]["armature"] == 0.2 and joints["rail"]["spring"] == {"stiffness": 3.0, "reference": 0.1}
    assert joints["rail"]["friction"] == {"viscous": 0.4} and joints["rail"]["servo"]["name"] == "hold"
    m = plain_mujoco_model(path)
    d = mujoco.MjData(m)
    sim = Simulator(load_scene(path), backend="numpy")
    model = sim.model
    rng = np.random.default_rng(4)
    worst = 0.0
    for _ in range(8):
        d.qpos[:], d.qvel[:], d.ctrl[:] = rng.uniform(-0.8, 0.8, 3), rng.normal(size=3), rng.uniform(-0.9, 0.9, 2)
        mujoco.mj_forward(m, d)
        y = initial_state(model)
        y[model.i_phi], y[model.i_vel] = d.qpos, d.qvel
        sim.set_controls(d.ctrl.copy())
        udot = sim.held_rhs()(0.0, y)[model.i_vel]
        worst = max(worst, float(np.max(np.abs(udot - d.qacc)) / np.max(np.abs(d.qacc))))
    assert worst <= AGREEMENT
    m.opt.timestep = 5e-5
    mujoco.mj_resetDataKeyframe(m, d, 0)
    d.ctrl[:] = [0.4, -0.3]
    mujoco.mj_step(m, d, nstep=10000)
    sim = Simulator(load_scene(path), integrator="dop853", rtol=1e-12, atol=1e-12)
    sim.set_controls({"hold": 0.4, "push": -0.3})
    sim.advance(d.time)
    state = sim.joint_states()
    assert np.max(np.abs(np.asarray(state.position) - d.qpos)) < AGREEMENT
    assert np.allclose(state.effort, d.qfrc_actuator - m.dof_damping * d.qvel, rtol=1e-8, atol=1e-9)


@pytest.mark.parametrize("seed", [3, 7])
def test_a_scene_with_slides_exported_by_peers_comes_back_the_same(seed, tmp_path):
    """gyro_sim.bench.peers writes a slide as MJCF's slide (a spring's reference in m, not
    degrees), and the import reads it back: the same joints, axes, springs, initial state."""
    from test.dynamics.test_slide import slide_chain
    from test.scene.test_model_import import exported

    scene_map = slide_chain(seed, "fixed")
    for b in scene_map["bodies"]:
        b.pop("rotors", None)
    original = load_scene(scene_map)
    back = load_scene(exported(scene_map, tmp_path))
    assert [(b.name, b.joint.type) for b in back.bodies] == [(b.name, b.joint.type) for b in original.bodies]
    assert any(b.joint.type == "slide" and b.joint.spring is not None for b in original.bodies)
    for a, b in zip(original.bodies, back.bodies):
        if a.joint.type == "slide":
            assert np.allclose(b.joint.axis, a.joint.axis, atol=1e-14)
            assert b.joint.armature == pytest.approx(a.joint.armature, rel=1e-15)
            assert (b.joint.spring is None) == (a.joint.spring is None)
            if a.joint.spring is not None:
                assert b.joint.spring.reference == pytest.approx(a.joint.spring.reference, abs=1e-15)
            assert (b.initial.position, b.initial.velocity) == pytest.approx((a.initial.position, a.initial.velocity),
                                                                             abs=1e-14)


def test_imus_on_slides_read_as_mujocos_sensors(tmp_path):
    """An IMU on the cart, on the pole and on the bead sliding along the pole (a site at a random
    pose on each, MuJoCo's gyro, accelerometer, framequat and framelinacc) at two random states
    under random motor commands: the readings equal MuJoCo's sensordata (the slides' motion in
    the specific force, the bead's Coriolis term included)."""
    from test.scene.test_model_import import write
    from test.scene.test_model_sensors import READING_RTOL, deviation, gyro_readings, mujoco_readings, with_imu_sites

    motors = SERVO_CART.replace('<position name="hold" joint="rail" kp="20" kv="3" ctrlrange="-1 1"/>',
                                '<motor name="hold" joint="rail" gear="3"/>')
    source = write(tmp_path, "motor_cart.xml", motors)
    rng = np.random.default_rng(11)
    bodies = ["cart", "pole", "bead"]
    path = with_imu_sites(source, bodies, rng, tmp_path)
    sites = [f"imu_{b}" for b in bodies]
    worst = 0.0
    for key in ("probe0", "probe1"):
        ctrl = rng.uniform(-0.9, 0.9, 2)
        worst = max(worst, deviation(mujoco_readings(path, ctrl, key=key), gyro_readings(path, key, ctrl), sites))
    assert worst < READING_RTOL
