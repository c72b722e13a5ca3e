"""A model's hinge armature and springs (stiffness, springref) imported (docs/models.md,
"Armature and joint springs"), and --lock on a model with keyframes and a tendon
(docs/models.md, "Locked joints"), on small models of our own, against MuJoCo."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco", reason="MuJoCo is the optional extra [models]")

from gyro_sim import Simulator
from gyro_sim.dynamics.model import initial_state
from gyro_sim.scene.load import load_scene
from gyro_sim.scene.mjcf import import_model
from test.scene.test_armature_models import mujoco_model as welded_model
from test.scene.test_model_import import AGREEMENT, MUJOCO_STEP, write

#: a three-link arm: springs (one with a springref), armatures and a damper, under gravity
SPRING_ARM = """<mujoco model="spring_arm">
  <compiler angle="radian"/>
  <option gravity="0 0 -9.81"/>
  <worldbody>
    <body name="upper" pos="0 0 1">
      <joint name="shoulder" type="hinge" axis="0 1 0" stiffness="4" springref="0.3" armature="0.02"/>
      <inertial pos="0.1 0 0" mass="1.1" diaginertia="0.002 0.01 0.011"/>
      <body name="fore" pos="0.25 0 0" quat="0.98 0.1 0.1 0">
        <joint name="elbow" type="hinge" axis="0 0 1" stiffness="1.5" armature="0.005" damping="0.05"/>
        <inertial pos="0.08 0.01 0" mass="0.6" diaginertia="0.001 0.004 0.0045"/>
        <body name="hand" pos="0.2 0 0">
          <joint name="wrist" type="hinge" axis="1 0 0" armature="0.001"/>
          <inertial pos="0.03 0 0.02" mass="0.3" diaginertia="0.0004 0.0005 0.0003"/>
        </body>
      </body>
    </body>
  </worldbody>
  <keyframe><key name="bent" qpos="0.9 -0.6 0.4" qvel="0.5 -1 2"/></keyframe>
</mujoco>
"""

#: a hinge arm with a two-finger gripper on slide joints, coupled by a tendon and an equality,
#: with keyframes that give the fingers' positions
GRIPPER = """<mujoco model="gripper">
  <worldbody>
    <body name="arm" pos="0 0 1">
      <joint name="shoulder" type="hinge" axis="0 1 0"/>
      <inertial pos="0.15 0 0" mass="1" diaginertia="0.002 0.01 0.01"/>
      <body name="left" pos="0.3 0.02 0">
        <joint name="left_slide" type="slide" axis="0 1 0"/>
        <inertial pos="0 0 0" mass="0.05" diaginertia="1e-5 1e-5 1e-5"/>
      </body>
      <body name="right" pos="0.3 -0.02 0">
        <joint name="right_slide" type="slide" axis="0 -1 0"/>
        <inertial pos="0 0 0" mass="0.05" diaginertia="1e-5 1e-5 1e-5"/>
      </body>
    </body>
  </worldbody>
  <tendon>
    <fixed name="grip"><joint joint="left_slide" coef="0.5"/><joint joint="right_slide" coef="0.5"/></fixed>
  </tendon>
  <equality><joint name="mimic" joint1="left_slide" joint2="right_slide"/></equality>
  <actuator>
    <motor name="lift" joint="shoulder" gear="2"/>
    <motor name="squeeze" tendon="grip"/>
  </actuator>
  <sensor><tendonpos name="opening" tendon="grip"/></sensor>
  <keyframe>
    <key name="open" qpos="0.2 0.03 0.03" qvel="0.1 0 0" ctrl="0.5 1"/>
    <key name="closed" qpos="-0.4 0.01 0.01"/>
  </keyframe>
</mujoco>
"""


def mujoco_model(path: Path):
    m = mujoco.MjSpec.from_file(str(path)).compile()
    m.opt.integrator = mujoco.mjtIntegrator.mjINT_RK4
    m.opt.timestep = MUJOCO_STEP
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT) | int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    return m


def test_armature_and_springs_become_the_hinges_keys(tmp_path):
    imported = import_model(write(tmp_path, "arm.xml", SPRING_ARM))
    joints = {b["name"]: b["joint"] for b in imported.mapping["bodies"]}
    assert joints["shoulder"]["armature"] == 0.02
    assert joints["shoulder"]["spring"] == {"stiffness": 4.0, "reference": 0.3}
    assert joints["elbow"]["spring"] == {"stiffness": 1.5, "reference": 0.0}
    assert joints["elbow"]["friction"] == {"viscous": 0.05}
    assert "spring" not in joints["wrist"] and joints["wrist"]["armature"] == 0.001


def test_springs_and_armature_accelerate_and_move_as_in_mujoco(tmp_path):
    """MuJoCo's qacc at random states to 1e-9 relative (no integrator between the two), and the
    motion from the keyframe for 1 s to AGREEMENT."""
    path = write(tmp_path, "arm.xml", SPRING_ARM)
    m = mujoco_model(path)
    d = mujoco.MjData(m)
    sim = Simulator(load_scene(path), integrator="dop853", rtol=1e-12, atol=1e-12, backend="numpy")
    model = sim.model
    rng = np.random.default_rng(2)
    worst = 0.0
    for _ in range(6):
        d.qpos[:], d.qvel[:] = rng.uniform(-2, 2, 3), rng.normal(size=3)
        mujoco.mj_forward(m, d)
        y = initial_state(model)
        y[model.i_phi], y[model.i_vel] = d.qpos, d.qvel
        udot = sim.held_rhs()(0.0, y)[model.i_vel]
        worst = max(worst, float(np.max(np.abs(udot - d.qacc)) / np.max(np.abs(d.qacc))))
    assert worst <= 1e-9
    mujoco.mj_resetDataKeyframe(m, d, 0)
    mujoco.mj_step(m, d, nstep=int(round(1.0 / MUJOCO_STEP)))
    sim.advance(d.time)
    assert np.max(np.abs(np.asarray(sim.joint_states().position) - d.qpos)) < AGREEMENT


def test_the_energy_counts_the_springs_and_armatures(tmp_path):
    """Without the damper and under gravity, the energy (springs' and armatures' terms included)
    is kept to 1e-10 by a tight dop853 over 2 s while it trades between its parts."""
    path = write(tmp_path, "arm.xml", SPRING_ARM.replace(' damping="0.05"', ""))
    sim = Simulator(load_scene(path), integrator="dop853", rtol=1e-13, atol=1e-14, backend="numpy")
    e0 = sim.invariants()
    scale = abs(e0["kinetic"]) + abs(e0["potential"])
    spread = 0.0
    for _ in range(8):
        sim.advance(0.25)
        now = sim.invariants()
        assert abs(now["energy"] - e0["energy"]) <= 1e-10 * scale
        spread = max(spread, abs(now["kinetic"] - e0["kinetic"]))
    assert spread > 0.01 * scale  # energy moved between the parts


def test_lock_drops_a_tendons_coupling_with_the_tendon(tmp_path):
    """A tendon's equality (a coupling of its length, as dm_control's manipulator and
    robosuite's Jaco fingers have) goes with the tendon of locked joints, said in a note: the
    model imports."""
    coupled = GRIPPER.replace('<equality><joint name="mimic" joint1="left_slide" joint2="right_slide"/></equality>',
                              '<equality><tendon name="coupling" tendon1="grip"/></equality>')
    assert coupled != GRIPPER
    imported = import_model(write(tmp_path, "gripper.xml", coupled), lock=["left_slide", "right_slide"])
    assert "equality 'coupling': left out with the tendon 'grip'" in imported.notes
    assert [b["name"] for b in imported.mapping["bodies"]] == ["shoulder"]


def test_lock_trims_keyframes_and_drops_a_tendon_of_locked_joints(tmp_path):
    """Locking both fingers: the keyframes lose the fingers' entries (qpos, qvel; ctrl loses the
    tendon's motor), the tendon on them goes with its motor and sensor, the equality with the
    joints; each said in a note. The keyframe's fingers (0.03) are where they are welded."""
    path = write(tmp_path, "gripper.xml", GRIPPER)
    imported = import_model(path, lock=["left_slide", "right_slide"])
    notes = "\n".join(imported.notes)
    for said in ("joint 'left_slide': locked at 0.03", "joint 'right_slide': locked at 0.03",
                 "tendon 'grip': left out, its joints are all locked",
                 "actuator 'squeeze': left out with the tendon 'grip' it drives",
                 "sensor 'opening': left out with the tendon 'grip'",
                 "equality 'mimic': left out with the locked joint"):
        assert said in notes, notes
    assert [c.actuator for c in imported.commands] == ["lift"]
    body = imported.mapping["bodies"][0]
    assert body["initial"] == {"angle": 0.2, "rate": 0.1}
    # the second keyframe, trimmed too, chooses the state
    closed = import_model(path, keyframe="closed", lock=["left_slide", "right_slide"])
    assert closed.mapping["bodies"][0]["initial"]["angle"] == -0.4
    # the fingers welded at the keyframe's 0.03: the arm swings as MuJoCo's with the fingers'
    # joints deleted and their bodies moved there
    bare = GRIPPER.split("<actuator>")[0] + GRIPPER[GRIPPER.index("</sensor>") + len("</sensor>"):]
    judged = write(tmp_path, "bare.xml", bare)
    m, (key, _) = welded_model(judged, {"left_slide": 0.03, "right_slide": 0.03})
    d = mujoco.MjData(m)
    d.qpos[:] = key
    d.qvel[:] = 0.1
    mujoco.mj_step(m, d, nstep=int(round(0.5 / MUJOCO_STEP)))
    sim = Simulator(load_scene(path, lock=["left_slide", "right_slide"]), integrator="dop853", rtol=1e-12,
                    atol=1e-12, backend="numpy")
    sim.advance(d.time)
    assert abs(sim.joint_states().position[0] - d.qpos[0]) < AGREEMENT


def test_a_scene_with_joint_terms_exported_by_peers_comes_back_the_same(tmp_path):
    """The accuracy report's MJCF (gyro_sim.bench.peers) writes a hinge's armature and spring
    as MuJoCo's armature, stiffness and springref: imported back, the same terms."""
    from test.dynamics.test_joint_terms import with_joint_terms
    from test.dynamics.test_kernel import chain_scene
    from test.scene.test_model_import import exported

    scene = with_joint_terms(chain_scene(2, "fixed", n=4, speed_rotors=False), 3)
    hinges = {b["name"]: b["joint"] for b in scene["bodies"] if b["joint"]["type"] == "hinge"}
    assert hinges
    back = {b["name"]: b["joint"] for b in import_model(exported(scene, tmp_path)).mapping["bodies"]}
    for name, joint in hinges.items():
        assert back[name]["armature"] == pytest.approx(joint["armature"], rel=1e-12)
        assert back[name]["spring"]["stiffness"] == pytest.approx(joint["spring"]["stiffness"], rel=1e-12)
        assert back[name]["spring"]["reference"] == pytest.approx(joint["spring"]["reference"], rel=1e-12)
