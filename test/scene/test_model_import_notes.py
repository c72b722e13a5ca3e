"""What an imported model keeps, notes or refuses where public arms differ from the plain case
(docs/models.md): `--keyframe none`, a joint's actuatorfrcrange, equalities welded by `--lock`,
missing meshes, and keyframes whose servo targets differ from their pose. Each on a small MJCF
written here; the physics against MuJoCo on the same file."""
from __future__ import annotations

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco", reason="MuJoCo is the optional extra [models]")

from gyro_sim import Simulator
from gyro_sim.cli import main
from gyro_sim.dynamics.model import initial_state
from gyro_sim.scene.load import load_scene, parse_yaml
from gyro_sim.scene.mjcf import ModelError, import_model
from test.scene.test_model_import import write
from test.scene.test_model_joint_terms import mujoco_model

#: two hinges under gravity, position servos, a keyframe "bent"
BENT_ARM = """<mujoco model="bent_arm">
  <option gravity="0 0 -9.81"/>
  <worldbody>
    <body name="upper" pos="0 0 1">
      <joint name="shoulder" axis="0 1 0"/>
      <inertial pos="0.1 0 0" mass="1" diaginertia="0.002 0.01 0.01"/>
      <body name="fore" pos="0.2 0 0">
        <joint name="elbow" axis="0 1 0"/>
        <inertial pos="0.1 0 0" mass="0.5" diaginertia="0.001 0.005 0.005"/>
      </body>
    </body>
  </worldbody>
  <actuator>
    <position name="shoulder_pos" joint="shoulder" kp="50"/>
    <position name="elbow_pos" joint="elbow" kp="20"/>
  </actuator>
  <keyframe><key name="bent" qpos="0.5 -0.4" ctrl="0.5 -0.4"/></keyframe>
</mujoco>
"""


# ------------------------------------------------------------------------- --keyframe none
def test_keyframe_none_is_the_rest_pose(tmp_path, capsys):
    """`--keyframe none` starts at the reference pose at rest with zero controls (exit 0), in
    `gyro-sim import`, `gyro-sim run` and load_scene; a keyframe named "none" is still that
    keyframe; an unknown name stays exit 2."""
    path = write(tmp_path, "arm.xml", BENT_ARM)
    bent = import_model(path)
    assert [b["initial"]["angle"] for b in bent.mapping["bodies"]] == [0.5, -0.4]
    rest = import_model(path, keyframe="none")
    assert rest.keyframe is None
    assert [b["initial"] for b in rest.mapping["bodies"]] == [{"angle": 0.0, "rate": 0.0}] * 2
    assert all("control" not in b["joint"]["servo"] for b in rest.mapping["bodies"])
    assert [b.initial.angle for b in load_scene(path, keyframe="none").bodies] == [0.0, 0.0]
    locked = import_model(path, keyframe="none", lock=["elbow"])  # locked at the reference
    assert "joint 'elbow': locked at 0 (its body welded to its parent)" in locked.notes
    out = tmp_path / "rest.yaml"
    assert main(["import", str(path), "-o", str(out), "--keyframe", "none"]) == 0
    assert [b["initial"]["angle"] for b in parse_yaml(out.read_text())["bodies"]] == [0.0, 0.0]
    assert main(["run", "--scene", str(path), "--keyframe", "none", "--duration", "0.01",
                 "--integrator", "rk4"]) == 0
    capsys.readouterr()
    assert main(["run", "--scene", str(path), "--keyframe", "nope", "--duration", "0.01"]) == 2
    assert "keyframe 'nope': no such keyframe" in capsys.readouterr().err
    named = write(tmp_path, "named.xml", BENT_ARM.replace('name="bent"', 'name="none"'))
    assert [b["initial"]["angle"] for b in import_model(named, keyframe="none").mapping["bodies"]] == [0.5, -0.4]


# ------------------------------------------------------------------------- missing meshes
def test_missing_meshes_are_one_note_and_unused_ones_none(tmp_path):
    """Five meshes on moving bodies with given inertials, missing: one note naming the count and
    the first three files; a missing mesh no geom uses is not mentioned; one missing mesh keeps
    its own note."""
    assets = "".join(f'<mesh name="m{i}" file="part{i}.stl"/>' for i in range(5))
    assets += '<mesh name="spare" file="spare.stl"/>'
    geoms = "".join(f'<geom type="mesh" mesh="m{i}"/>' for i in range(5))
    text = BENT_ARM.replace("<worldbody>", f"<asset>{assets}</asset>\n  <worldbody>").replace(
        '<joint name="elbow" axis="0 1 0"/>', '<joint name="elbow" axis="0 1 0"/>' + geoms)
    imported = import_model(write(tmp_path, "arm.xml", text))
    said = [n for n in imported.notes if "mesh" in n or ".stl" in n]
    assert said == ["5 meshes left out with their geoms (part0.stl, part1.stl, part2.stl and 2 more): they cannot "
                    f"be read (the first: no such file ({tmp_path / 'part0.stl'})); the motion does not need them "
                    "(masses and inertias are given)"]
    one = import_model(write(tmp_path, "one.xml", text.replace(geoms, geoms[:geoms.index("/>") + 2])))
    assert [n for n in one.notes if ".stl" in n] == [
        f"mesh part0.stl (on 'fore'): left out, no such file ({tmp_path / 'part0.stl'}); the motion does not "
        "need it (masses and inertias are given)"]


# ------------------------------------------------------------------- equalities welded by --lock
#: an arm with a gripper whose finger closes a loop with its knuckle (a `connect`), and a `weld`
#: between the other finger's tip (a site) and the hand
GRIPPER = """<mujoco model="gripper">
  <option gravity="0 0 -9.81"/>
  <worldbody>
    <body name="arm" pos="0 0 1">
      <joint name="shoulder" axis="0 1 0"/>
      <inertial pos="0.1 0 0" mass="1" diaginertia="0.002 0.01 0.01"/>
      <body name="hand" pos="0.2 0 0">
        <joint name="wrist" axis="1 0 0"/>
        <inertial pos="0.02 0 0" mass="0.3" diaginertia="0.0003 0.0003 0.0003"/>
        <body name="knuckle" pos="0.03 0.01 0">
          <joint name="knuckle_joint" axis="0 0 1"/>
          <inertial pos="0.01 0 0" mass="0.02" diaginertia="1e-6 1e-6 1e-6"/>
        </body>
        <body name="finger" pos="0.03 0.02 0">
          <joint name="finger_joint" axis="0 0 1"/>
          <inertial pos="0.01 0 0" mass="0.03" diaginertia="1e-6 1e-6 1e-6"/>
        </body>
        <body name="other" pos="0.03 -0.02 0">
          <joint name="other_joint" axis="0 0 1"/>
          <inertial pos="0.01 0 0" mass="0.03" diaginertia="1e-6 1e-6 1e-6"/>
          <site name="tip" pos="0.02 0 0"/>
        </body>
      </body>
    </body>
  </worldbody>
  <equality>
    <connect body1="finger" body2="knuckle" anchor="0.01 0 0"/>
    <weld name="grip" site1="tip" site2="hand_site"/>
  </equality>
</mujoco>
"""
FINGERS = ["knuckle_joint", "finger_joint", "other_joint"]


def test_equalities_inside_one_welded_body_are_left_out(tmp_path):
    """A connect and a weld whose two ends --lock welds into one body are left out with a note
    each (a constraint inside one rigid body moves nothing: the scene is the one of the file
    without them); unlocked, or one finger left free, they are refused."""
    text = GRIPPER.replace('<body name="knuckle"', '<site name="hand_site" pos="0.05 -0.02 0"/>\n'
                           '        <body name="knuckle"')
    path = write(tmp_path, "gripper.xml", text)
    imported = import_model(path, lock=FINGERS)
    assert "equality #0: left out, body 'finger' and body 'knuckle' are welded into one by --lock " \
           "(it moves nothing)" in imported.notes
    assert "equality 'grip': left out, body 'other' and body 'hand' are welded into one by --lock " \
           "(it moves nothing)" in imported.notes
    (tmp_path / "bare").mkdir()
    bare = write(tmp_path / "bare", "gripper.xml", text[:text.index("<equality>")] + "</mujoco>\n")
    assert imported.mapping == import_model(bare, lock=FINGERS).mapping
    with pytest.raises(ModelError) as info:
        import_model(path, lock=FINGERS[1:])  # the knuckle moves: the loop is a constraint
    assert [e for e in info.value.errors if "equality" in e] == [
        f"{path}: equality #0: equality constraints are not supported (an open tree only): it closes a loop "
        "from body 'finger' to body 'knuckle'; --lock the joints of the loop to weld it ('knuckle_joint')"]


# ------------------------------------------------------------- a keyframe's ctrl against its pose
def test_a_keyframe_whose_servo_targets_are_not_its_pose_is_noted(tmp_path):
    """A position servo's target (where its force vanishes at rest: ctrl / gear for a position
    actuator, clipped to its ctrlrange) away from the keyframe's pose is noted with the gap; a
    keyframe whose ctrl is its pose (or a velocity servo) is not; MuJoCo's force at the keyframe
    vanishes exactly at the targets the note gives."""
    text = BENT_ARM.replace('kp="20"', 'kp="20" gear="2"').replace('ctrl="0.5 -0.4"', 'ctrl="0 -0.8"')
    path = write(tmp_path, "arm.xml", text)
    imported = import_model(path)
    assert ("keyframe 'bent': its ctrl is not its pose, the servos pull away from it at t = 0: "
            "'shoulder_pos' target 0, pose 0.5 (-0.5 rad)") in imported.notes
    assert not any("elbow_pos" in n for n in imported.notes)  # ctrl -0.8 / gear 2 is its pose -0.4
    m = mujoco.MjSpec.from_file(str(path)).compile()
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, 0)
    d.qpos[0] = 0.0  # at the target the note gives, the servo pushes nothing
    mujoco.mj_forward(m, d)
    assert d.actuator_force[0] == 0.0 and d.actuator_force[1] == 0.0
    held = import_model(write(tmp_path, "held.xml", BENT_ARM))
    assert not any("its ctrl is not its pose" in n for n in held.notes)


# ----------------------------------------------------------------- a joint's actuatorfrcrange
#: three hinges under gravity, each driven by one actuator and bounded by actuatorfrcrange: a
#: geared position servo with its own forcerange, a servo of negative gear, and a motor (every
#: actuator a servo then)
FRC_ARM = """<mujoco model="frc_arm">
  <option gravity="0 0 -9.81"/>
  <worldbody>
    <body name="upper" pos="0 0 1">
      <joint name="shoulder" axis="0 1 0" actuatorfrcrange="-20 40"/>
      <inertial pos="0.1 0 0" mass="1.1" diaginertia="0.002 0.01 0.011"/>
      <body name="fore" pos="0.25 0 0" quat="0.98 0.1 0.1 0">
        <joint name="elbow" axis="0 0 1" actuatorfrcrange="-3 6"/>
        <inertial pos="0.08 0.01 0" mass="0.6" diaginertia="0.001 0.004 0.0045"/>
        <body name="hand" pos="0.2 0 0">
          <joint name="wrist" axis="1 0 0" actuatorfrcrange="-1 1"/>
          <inertial pos="0.03 0 0.02" mass="0.3" diaginertia="0.0004 0.0005 0.0003"/>
        </body>
      </body>
    </body>
  </worldbody>
  <actuator>
    <position name="shoulder_pos" joint="shoulder" kp="100" kv="5" gear="2" forcerange="-30 30"/>
    <position name="elbow_pos" joint="elbow" kp="50" gear="-1.5"/>
    <motor name="wrist_motor" joint="wrist" gear="0.5"/>
  </actuator>
</mujoco>
"""


def test_actuatorfrcrange_bounds_a_joints_one_servo_as_in_mujoco(tmp_path):
    """A joint's actuatorfrcrange bounds gear x force: its one servo's force range becomes its own
    forcerange met with the joint's range / gear (flipped for a negative gear). MuJoCo's qacc
    at random states and controls driving every servo into the bound, on both sides, to 1e-9
    relative."""
    path = write(tmp_path, "arm.xml", FRC_ARM)
    imported = import_model(path)
    ranges = [b["joint"]["servo"]["force_range"] for b in imported.mapping["bodies"]]
    assert ranges == [[-10.0, 20.0], [-4.0, 2.0], [-2.0, 2.0]]
    assert not any("actuatorfrcrange" in n for n in imported.notes)
    m = mujoco_model(path)
    d = mujoco.MjData(m)
    sim = Simulator(load_scene(path), backend="numpy")
    model = sim.model
    rng = np.random.default_rng(7)
    worst, bound = 0.0, set()
    for _ in range(16):
        d.qpos[:], d.qvel[:] = rng.uniform(-2, 2, 3), rng.normal(scale=2.0, size=3)
        d.ctrl[:] = rng.uniform(-8, 8, 3)
        mujoco.mj_forward(m, d)
        bound |= {(j, int(np.sign(d.qfrc_actuator[j]))) for j in range(3)
                  if abs(d.qfrc_actuator[j]) in np.abs(m.jnt_actfrcrange[j])}
        y = initial_state(model)
        y[model.i_phi], y[model.i_vel] = d.qpos, d.qvel
        sim.set_controls(d.ctrl.copy())
        udot = sim.held_rhs()(0.0, y)[model.i_vel]
        worst = max(worst, float(np.max(np.abs(udot - d.qacc)) / np.max(np.abs(d.qacc))))
    assert worst <= 1e-9
    assert bound == {(j, s) for j in range(3) for s in (-1, 1)}  # every bound reached, both sides


#: a motor bounded by a symmetric actuatorfrcrange, two motors on one joint, an asymmetric range
FRC_MOTORS = FRC_ARM.replace(
    '<position name="shoulder_pos" joint="shoulder" kp="100" kv="5" gear="2" forcerange="-30 30"/>',
    '<motor name="shoulder_motor" joint="shoulder" gear="2"/>').replace(
    '<position name="elbow_pos" joint="elbow" kp="50" gear="-1.5"/>',
    '<motor name="elbow_a" joint="elbow"/><motor name="elbow_b" joint="elbow" gear="2"/>').replace(
    'actuatorfrcrange="-20 40"', 'actuatorfrcrange="-5 5"').replace(
    'actuatorfrcrange="-1 1"', 'actuatorfrcrange="-1 2"')


def test_actuatorfrcrange_of_a_joints_one_motor_is_its_max_torque(tmp_path):
    """A motor's axis moment is gear x ctrl, which MuJoCo clips to the joint's actuatorfrcrange:
    a symmetric range becomes the axis's max_torque (MuJoCo's qacc with the moment beyond it,
    to 1e-9 relative); two motors on one joint, or an asymmetric range, stay a note."""
    path = write(tmp_path, "motors.xml", FRC_MOTORS)
    imported = import_model(path)
    joints = {b["name"]: b["joint"] for b in imported.mapping["bodies"]}
    assert joints["shoulder"]["max_torque"] == 5.0
    assert "max_torque" not in joints["elbow"] and "max_torque" not in joints["wrist"]
    assert "joint 'elbow': actuatorfrcrange [-3, 6] not enforced (2 actuators drive it)" in imported.notes
    assert ("joint 'wrist': actuatorfrcrange [-1, 2] not enforced (not symmetric: a max_torque bounds a "
            "moment on both sides alike)") in imported.notes
    m = mujoco_model(path)
    d = mujoco.MjData(m)
    sim = Simulator(load_scene(path), backend="numpy")
    model = sim.model
    factors = {c.axis: [] for c in imported.commands}
    for a, c in enumerate(imported.commands):
        factors[c.axis].append((a, c.factor))
    rng = np.random.default_rng(3)
    worst = 0.0
    for shoulder in (4.0, -4.0, 1.0):  # 8 N m and -8 N m clipped to 5, 2 N m inside
        d.qpos[:], d.qvel[:] = rng.uniform(-2, 2, 3), rng.normal(size=3)
        d.ctrl[:] = [shoulder, 0.5, 0.5, 0.6]  # the elbow's and wrist's inside their ranges
        mujoco.mj_forward(m, d)
        y = initial_state(model)
        y[model.i_phi], y[model.i_vel] = d.qpos, d.qvel
        sim.set_axis_moments([sum(f * d.ctrl[a] for a, f in factors[axis]) for axis in sim.axis_names])
        udot = sim.held_rhs()(0.0, y)[model.i_vel]
        worst = max(worst, float(np.max(np.abs(udot - d.qacc)) / np.max(np.abs(d.qacc))))
    assert worst <= 1e-9
