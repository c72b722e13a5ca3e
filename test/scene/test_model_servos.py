"""A model's affine actuators (MuJoCo's position, velocity and general with a bias, and its
motors beside them) imported as the hinges' servos (docs/models.md, "Servo actuators"), against
MuJoCo: accelerations at random states and controls, and the motion."""
from __future__ import annotations

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco", reason="MuJoCo is the optional extra [models]")

from gyro_sim import Simulator
from gyro_sim.dynamics.model import initial_state
from gyro_sim.scene.load import load_scene
from gyro_sim.scene.mjcf import import_model, scene_yaml
from test.scene.test_model_import import write
from test.scene.test_model_joint_terms import mujoco_model

#: a four-hinge arm under gravity: a position servo with kv, control and force ranges (and the
#: joint's armature and damper), a geared position servo with a control range, a velocity servo
#: with a force range, a geared general actuator with an affine bias, and a motor on a fifth hinge
SERVO_ARM = """<mujoco model="servo_arm">
  <compiler angle="radian"/>
  <option gravity="0 0 -9.81"/>
  <worldbody>
    <body name="upper" pos="0 0 1">
      <joint name="shoulder" type="hinge" axis="0 1 0" armature="0.01" damping="0.05"/>
      <inertial pos="0.1 0 0" mass="1.1" diaginertia="0.002 0.01 0.011"/>
      <body name="fore" pos="0.25 0 0" quat="0.98 0.1 0.1 0">
        <joint name="elbow" type="hinge" axis="0 0 1"/>
        <inertial pos="0.08 0.01 0" mass="0.6" diaginertia="0.001 0.004 0.0045"/>
        <body name="hand" pos="0.2 0 0">
          <joint name="wrist" type="hinge" axis="1 0 0"/>
          <inertial pos="0.03 0 0.02" mass="0.3" diaginertia="0.0004 0.0005 0.0003"/>
          <body name="tip" pos="0.05 0 0">
            <joint name="twist" type="hinge" axis="0 1 0"/>
            <inertial pos="0.02 0.01 0" mass="0.2" diaginertia="0.0002 0.0003 0.0002"/>
            <body name="finger" pos="0.04 0 0">
              <joint name="flick" type="hinge" axis="0 0 1"/>
              <inertial pos="0.02 0 0.01" mass="0.1" diaginertia="0.0001 0.00012 0.0001"/>
            </body>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
  <actuator>
    <position name="shoulder_pos" joint="shoulder" kp="30" kv="3" ctrlrange="-1.5 1.5" forcerange="-12 12"/>
    <position name="elbow_pos" joint="elbow" kp="10" gear="2" ctrlrange="-1 1"/>
    <velocity name="wrist_vel" joint="wrist" kv="0.4" forcerange="-0.5 0.5"/>
    <general name="twist_gen" joint="twist" gainprm="3" biastype="affine" biasprm="0.1 -2 -0.3" gear="1.5"/>
    <motor name="flick_motor" joint="flick" gear="0.5" ctrlrange="-0.2 0.2"/>
  </actuator>
  <keyframe><key name="bent" qpos="0.9 -0.6 0.4 0.2 -0.1" qvel="0.5 -1 0.5 0.3 0.2"/></keyframe>
</mujoco>
"""
JOINTS = ("shoulder", "elbow", "wrist", "twist", "flick")


def test_the_actuators_become_the_hinges_servos(tmp_path):
    imported = import_model(write(tmp_path, "arm.xml", SERVO_ARM))
    servos = {b["name"]: b["joint"]["servo"] for b in imported.mapping["bodies"]}
    assert servos["shoulder"] == {"name": "shoulder_pos", "gain": 30.0, "bias": [0.0, -30.0, -3.0],
                                  "ctrl_range": [-1.5, 1.5], "force_range": [-12.0, 12.0]}
    assert servos["elbow"] == {"name": "elbow_pos", "gain": 10.0, "bias": [0.0, -10.0, 0.0], "gear": 2.0,
                               "ctrl_range": [-1.0, 1.0]}
    assert servos["wrist"] == {"name": "wrist_vel", "gain": 0.4, "bias": [0.0, 0.0, -0.4],
                               "force_range": [-0.5, 0.5]}
    assert servos["twist"]["bias"] == [0.1, -2.0, -0.3] and servos["twist"]["gear"] == 1.5
    assert servos["flick"] == {"name": "flick_motor", "gain": 1.0, "bias": [0.0, 0.0, 0.0], "gear": 0.5,
                               "ctrl_range": [-0.2, 0.2]}
    assert imported.commands == ()
    assert "#   elbow_pos -> joint elbow\n" in scene_yaml(imported)
    sim = Simulator(load_scene(imported.mapping), backend="numpy")
    assert sim.control_names == ("shoulder_pos", "elbow_pos", "wrist_vel", "twist_gen", "flick_motor")
    assert sim.axis_names == []  # every hinge is commanded by its servo's control


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_servos_accelerate_as_in_mujoco(tmp_path, backend):
    """MuJoCo's qacc at random states and controls (inside and beyond the ranges: the clips on
    both sides) to 1e-9 relative, and the published efforts are MuJoCo's qfrc_actuator (with the
    shoulder's damper, as every hinge's friction is published in its effort)."""
    path = write(tmp_path, "arm.xml", SERVO_ARM)
    m = mujoco_model(path)
    d = mujoco.MjData(m)
    sim = Simulator(load_scene(path), backend=backend)
    model = sim.model
    rng = np.random.default_rng(5)
    worst = worst_effort = 0.0
    clipped = set()
    for _ in range(12):
        d.qpos[:], d.qvel[:] = rng.uniform(-2, 2, 5), rng.normal(scale=2.0, size=5)
        d.ctrl[:] = rng.uniform(-2, 2, 5)
        mujoco.mj_forward(m, d)
        clipped |= {a for a in range(5) if m.actuator_forcelimited[a] and
                    abs(d.actuator_force[a]) == m.actuator_forcerange[a, 1]}
        y = initial_state(model)
        y[model.i_phi], y[model.i_vel] = d.qpos, d.qvel
        sim.set_controls(d.ctrl.copy())
        udot = sim.held_rhs()(0.0, y)[model.i_vel]
        worst = max(worst, float(np.max(np.abs(udot - d.qacc)) / np.max(np.abs(d.qacc))))
        sim._y = y  # the outputs at this state
        sim._outputs.moved(0.0, y, None, sim.axis_moments)
        effort = np.asarray(sim.joint_states().effort)
        expected = d.qfrc_actuator - m.dof_damping * d.qvel
        worst_effort = max(worst_effort, float(np.max(np.abs(effort - expected))))
    assert worst <= 1e-9
    assert worst_effort <= 1e-12
    assert clipped == {0, 2}  # both force ranges were reached


def test_servos_move_as_in_mujoco(tmp_path):
    """The motion from the keyframe with held controls for 0.5 s (MuJoCo's RK4 at 5e-5 s, whose
    own error there is 6e-10, 9e-9 at 1e-4 s; gyro_sim's dop853 at 1e-12) to 1e-9, the ranges
    not reached (a clip's kink costs RK4 its order)."""
    path = write(tmp_path, "arm.xml", SERVO_ARM)
    m = mujoco_model(path)
    m.opt.timestep = 5e-5
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, 0)
    controls = np.array([0.7, -0.3, 0.2, 0.5, 0.002])
    d.ctrl[:] = controls
    mujoco.mj_step(m, d, nstep=10000)
    assert np.all(np.abs(d.actuator_force[[0, 2]]) < m.actuator_forcerange[[0, 2], 1])
    sim = Simulator(load_scene(path), integrator="dop853", rtol=1e-12, atol=1e-12, backend="numpy")
    sim.set_controls(dict(zip(("shoulder_pos", "elbow", "wrist_vel", "twist", "flick_motor"), controls)))
    sim.advance(d.time)
    state = sim.joint_states()
    assert np.max(np.abs(np.asarray(state.position) - d.qpos)) < 1e-9
    assert np.max(np.abs(np.asarray(state.velocity) - d.qvel)) < 1e-8
    assert np.allclose(state.effort, d.qfrc_actuator - m.dof_damping * d.qvel, rtol=1e-8, atol=1e-9)


#: a Menagerie-style arm: position servos on three hinges under gravity and a "home" keyframe
#: whose ctrl is its qpos (the servos hold the pose from t = 0 with no command)
HOME_ARM = """<mujoco model="home_arm">
  <option gravity="0 0 -9.81"/>
  <worldbody>
    <body name="link1" pos="0 0 0.5">
      <joint name="base_yaw" axis="0 0 1" damping="0.5"/>
      <inertial pos="0 0 0.05" mass="2" diaginertia="0.01 0.01 0.006"/>
      <body name="link2" pos="0 0 0.1">
        <joint name="shoulder" axis="0 1 0"/>
        <inertial pos="0.15 0 0" mass="1.2" diaginertia="0.002 0.012 0.012"/>
        <body name="link3" pos="0.3 0 0">
          <joint name="elbow" axis="0 1 0" armature="0.01"/>
          <inertial pos="0.12 0 0" mass="0.6" diaginertia="0.001 0.005 0.005"/>
        </body>
      </body>
    </body>
  </worldbody>
  <actuator>
    <position name="base_yaw" joint="base_yaw" kp="200" kv="20" ctrlrange="-3 3"/>
    <position name="shoulder" joint="shoulder" kp="400" kv="30" ctrlrange="-2 2"/>
    <position name="elbow" joint="elbow" kp="200" kv="10" ctrlrange="-2.5 2.5"/>
  </actuator>
  <keyframe>
    <key name="home" qpos="0.4 -0.7 1.2" ctrl="0.4 -0.7 1.2"/>
  </keyframe>
</mujoco>
"""


@pytest.mark.slow
def test_a_keyframes_ctrl_holds_its_pose_from_the_start(tmp_path):
    """The keyframe's ctrl becomes each servo's initial `control` (a reset restores it): with
    no command the arm stays near its home pose (the servos' sag under gravity only), where
    the same arm without the keyframe's ctrl falls away from it, and the motion over 1 s is
    MuJoCo's from the same keyframe to 1e-9 rad (RK4 at 2e-5 s there)."""
    path = write(tmp_path, "arm.xml", HOME_ARM)
    imported = import_model(path)
    controls = {b["name"]: b["joint"]["servo"].get("control") for b in imported.mapping["bodies"]}
    assert controls == {"base_yaw": 0.4, "shoulder": -0.7, "elbow": 1.2}
    assert not any("ctrl" in note for note in imported.notes)
    q0 = np.array([0.4, -0.7, 1.2])
    m = mujoco_model(path)
    m.opt.timestep = 2e-5
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, 0)
    assert np.array_equal(d.ctrl, q0)  # MuJoCo starts from the keyframe's ctrl too
    mujoco.mj_step(m, d, nstep=50000)
    sim = Simulator(load_scene(imported.mapping), integrator="dop853", rtol=1e-12, atol=1e-12, backend="numpy")
    assert np.array_equal(sim.controls, q0) and np.array_equal(sim.initial_controls, q0)
    sim.advance(1.0)
    q = np.asarray(sim.joint_states().position)
    assert np.max(np.abs(q - d.qpos)) < 1e-9
    assert np.max(np.abs(q - q0)) < 0.02  # held, the sag of a finite kp under gravity aside
    sim.set_controls([0.0, 0.0, 0.0])
    sim.reset()
    assert np.array_equal(sim.controls, q0)  # a reset restores the initial controls
    unheld = load_scene(without_controls(imported.mapping))
    loose = Simulator(unheld, integrator="dop853", rtol=1e-10, atol=1e-10, backend="numpy")
    loose.advance(1.0)
    assert np.max(np.abs(np.asarray(loose.joint_states().position) - q0)) > 0.3


def without_controls(mapping: dict) -> dict:
    """A copy of an imported mapping with its servos' initial controls taken out."""
    import copy

    out = copy.deepcopy(mapping)
    for body in out["bodies"]:
        body["joint"]["servo"].pop("control")
    return out
