"""Locked joints: `--lock JOINT[=VALUE]`, `load_scene(..., lock=...)`, the node's `lock`
(gyro_sim.scene.mjcf, docs/models.md "Locked joints").

The judges are MuJoCo's: the locked scene must move as MuJoCo moves the same file with the
locked joints removed from its spec (their bodies then welded at the reference pose), and a
joint locked elsewhere must carry its body to where MuJoCo's kinematics puts it at that joint
value (the merged body's mass and centre of mass against MuJoCo's subtree).
"""
from __future__ import annotations

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco", reason="MuJoCo is the optional extra [models]")

from gyro_sim import Simulator
from gyro_sim.cli import main
from gyro_sim.scene.load import SceneError, load_scene
from test.scene.test_model_import import (
    AGREEMENT,
    INSTANTS,
    deviations,
    gyro_run,
    mujoco_run,
    write,
)

INERTIAL = ('<inertial><origin xyz="{c}"/><mass value="{m}"/>'
            '<inertia ixx="{a}" iyy="{b}" izz="{b}" ixy="0" ixz="0" iyz="0"/></inertial>')

#: a two-joint arm with a hand on a fixed joint and two prismatic fingers, the second mimicking
#: the first (an equality constraint in MuJoCo), as a Panda's gripper is described
GRIPPER_URDF = f"""<?xml version="1.0"?>
<robot name="gripper_arm">
  <link name="base_link"/>
  <joint name="joint1" type="revolute">
    <parent link="base_link"/><child link="link1"/>
    <origin xyz="0 0 0.4"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="50" velocity="2"/>
  </joint>
  <link name="link1">{INERTIAL.format(c="0.02 0 0.1", m=2.0, a=0.02, b=0.018)}</link>
  <joint name="joint2" type="revolute">
    <parent link="link1"/><child link="link2"/>
    <origin xyz="0 0 0.2" rpy="0.3 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="50" velocity="2"/>
    <dynamics damping="0.1"/>
  </joint>
  <link name="link2">{INERTIAL.format(c="0.15 0 0", m=1.2, a=0.002, b=0.01)}</link>
  <joint name="hand_joint" type="fixed">
    <parent link="link2"/><child link="hand"/>
    <origin xyz="0.3 0 0" rpy="0 1.5707963267948966 0"/>
  </joint>
  <link name="hand">{INERTIAL.format(c="0 0 0.03", m=0.6, a=0.001, b=0.0012)}</link>
  <joint name="finger_joint1" type="prismatic">
    <parent link="hand"/><child link="left_finger"/>
    <origin xyz="0 0 0.06"/><axis xyz="0 1 0"/>
    <limit lower="0" upper="0.04" effort="20" velocity="0.2"/>
  </joint>
  <link name="left_finger">{INERTIAL.format(c="0 0.01 0.02", m=0.05, a=2e-5, b=1e-5)}</link>
  <joint name="finger_joint2" type="prismatic">
    <parent link="hand"/><child link="right_finger"/>
    <origin xyz="0 0 0.06" rpy="0 0 0.2"/><axis xyz="0 -1 0"/>
    <limit lower="0" upper="0.04" effort="20" velocity="0.2"/>
    <mimic joint="finger_joint1"/>
  </joint>
  <link name="right_finger">{INERTIAL.format(c="0 -0.01 0.02", m=0.05, a=2e-5, b=1e-5)}</link>
</robot>
"""
FINGERS = ["finger_joint1", "finger_joint2"]


def without_joints(path, joints):
    """The MuJoCo judge's model: the file with `joints` removed from its spec (and the
    equalities coupling them), compiled."""
    spec = mujoco.MjSpec.from_file(str(path))
    for equality in list(spec.equalities):
        if equality.name1 in joints or equality.name2 in joints:
            spec.delete(equality)
    for name in joints:
        spec.delete(spec.joint(name))
    return spec.compile()


def test_a_gripper_left_unlocked_is_refused_suggesting_lock(tmp_path):
    path = write(tmp_path, "gripper.urdf", GRIPPER_URDF)
    with pytest.raises(SceneError) as info:
        load_scene(path)
    assert info.value.errors == [
        f"{path}: equality #0: equality constraints are not supported (an open tree only); "
        "--lock the joints it couples to weld them"]


def test_locked_fingers_move_as_in_mujoco_without_them(tmp_path):
    path = write(tmp_path, "gripper.urdf", GRIPPER_URDF)
    scene = load_scene(path, lock=FINGERS)
    assert [b.name for b in scene.bodies] == ["joint1", "joint2"]
    forces = {"joint1": 0.5, "joint2": -0.3}
    mj_out = mujoco_run(None, {}, forces, INSTANTS, model=without_joints(path, FINGERS))
    gs_out = gyro_run(scene, forces, INSTANTS)
    worst = deviations(scene, mj_out, gs_out, bodies={"joint1": ["link1"], "joint2": ["link2"]},
                       rotors={}, hinges=["joint1", "joint2"])
    print("gripper arm, fingers locked, vs MuJoCo without them:", {k: f"{v:.2g}" for k, v in worst.items()})
    assert max(worst.values()) < AGREEMENT, worst
    assert abs(gs_out[-1][1]["joint2"]) > 0.05  # the comparison is of a motion


def test_a_joint_locked_at_a_value_carries_its_body_there(tmp_path):
    """Fingers locked open: the merged body's mass and centre of mass are MuJoCo's subtree's
    with the fingers at those values (and the arm turned, to see the frames too)."""
    path = write(tmp_path, "gripper.urdf", GRIPPER_URDF)
    values = {"finger_joint1": 0.02, "finger_joint2": 0.035}
    scene = load_scene(path, lock=[f"{k}={v}" for k, v in values.items()])
    assert scene.bodies[-1].mass == pytest.approx(1.2 + 0.6 + 0.05 + 0.05, rel=1e-15)
    m = mujoco.MjModel.from_xml_path(str(path))
    d = mujoco.MjData(m)
    for name, v in values.items():
        d.qpos[m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)]] = v
    mujoco.mj_forward(m, d)
    link2 = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "link2")
    sim = Simulator(scene, integrator="rk4", step=1e-3, backend="numpy")
    state = {b.name: b for b in sim.body_states()}["joint2"]
    centre = state.position + state.rotation @ scene.bodies[-1].com
    assert np.max(np.abs(centre - d.subtree_com[link2])) < 1e-13
    assert scene.bodies[-1].mass == pytest.approx(m.body_subtreemass[link2], rel=1e-14)


def test_lock_on_the_command_line_and_bad_locks(tmp_path, capsys):
    path = write(tmp_path, "gripper.urdf", GRIPPER_URDF)
    assert main(["run", "--scene", str(path), "--duration", "0.01",
                 "--lock", "finger_joint1", "--lock", "finger_joint2=0.01"]) == 0
    assert main(["import", str(path), "-o", str(tmp_path / "g.yaml"), "--lock", "finger_joint1",
                 "--lock", "finger_joint2"]) == 0
    out = capsys.readouterr().out
    assert "note: joint 'finger_joint1': locked at 0" in out
    for bad, said in ((["--lock", "finger_joint1=open"],
                       "lock: joint 'finger_joint1': the value must be a finite number"),
                      (["--lock", "finger_joint1=nan"], "must be a finite number")):
        assert main(["run", "--scene", str(path), "--duration", "0.01", *bad]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and said in err[0], err
    # a joint that is not there is said with every other problem of the file (the fingers,
    # not locked, are coupled), in one refusal
    assert main(["run", "--scene", str(path), "--duration", "0.01", "--lock", "nope"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert "lock: no joint named 'nope'" in err[1] and "(2 errors)" in err[0], err
    assert "equality #0" in err[2], err
    # and what each suggests, --lock the fingers, is what then loads
    assert main(["run", "--scene", str(path), "--duration", "0.01", "--lock", "finger_joint1",
                 "--lock", "finger_joint2"]) == 0
    with pytest.raises(SceneError, match="lock: only the joints of an MJCF or URDF model are locked"):
        load_scene("hinge_chain", lock=["arm3"])


def test_the_node_takes_lock_and_package_path(tmp_path):
    from gyro_sim.ros.params import validate

    path = write(tmp_path, "gripper.urdf", GRIPPER_URDF)
    config = validate({"scene": str(path), "lock": "finger_joint1, finger_joint2=0.01",
                       "package_path": str(tmp_path)})
    assert [b.name for b in config.scene.bodies] == ["joint1", "joint2"]
