"""A URDF robot described as itself: its own URDF and its links' frames from gyro_sim's state
(gyro_sim.scene.robot, docs/models.md "ROS sees the robot as itself").

The judge is forward kinematics by MuJoCo on the published URDF (the description a viewer or
robot_state_publisher reads) at the published joint states: every link's pose computed by
gyro_sim from its bodies' poses must be MuJoCo's to 1e-9, on a moving robot.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco", reason="MuJoCo is the optional extra [models]")

from gyro_sim import Simulator
from gyro_sim.paths import find_scene
from gyro_sim.scene.load import load_scene
from gyro_sim.scene.mjcf import caught_warnings
from gyro_sim.scene.robot import link_poses
from test.scene.test_model_import import ARM_URDF, write
from test.scene.test_model_lock import GRIPPER_URDF

ERD = Path(__file__).parent / "models" / "example_robot_data"
#: largest difference of a link's position (m) or rotation matrix entry
FK_AGREEMENT = 1e-9


def published_fk(urdf: str, joint_states: dict[str, float], tmp_path: Path):
    """MuJoCo's kinematics of the published URDF at the joint states: link -> (position, R)."""
    path = tmp_path / "published.urdf"
    path.write_text(urdf)
    with caught_warnings(mujoco):
        spec = mujoco.MjSpec.from_file(str(path))
        spec.compiler.fusestatic = False  # every link a body of its own
        for mesh in list(spec.meshes):
            for geom in [g for g in spec.geoms if g.meshname == mesh.name]:
                spec.delete(geom)
            spec.delete(mesh)
        m = spec.compile()
    d = mujoco.MjData(m)
    for j in range(m.njnt):
        d.qpos[m.jnt_qposadr[j]] = joint_states[mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j)]
    mujoco.mj_kinematics(m, d)
    return {mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b): (d.xpos[b].copy(), d.xmat[b].reshape(3, 3).copy())
            for b in range(1, m.nbody)}


#: a revolute shoulder, a prismatic joint along a tilted axis with its link's frame turned by
#: its rpy, a revolute wrist after it
PRISMATIC_URDF = """<robot name="telescope">
  <link name="base"/>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/>
    <origin xyz="0 0 1"/><axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="5" velocity="5"/></joint>
  <link name="upper"><inertial><origin xyz="0 0 -0.2"/><mass value="1"/>
    <inertia ixx="0.02" iyy="0.02" izz="0.002" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="extend" type="prismatic"><parent link="upper"/><child link="sleeve"/>
    <origin xyz="0 0.05 -0.3" rpy="0.3 0 0.2"/><axis xyz="0.2 0 -1"/>
    <limit lower="-0.2" upper="0.2" effort="5" velocity="1"/></joint>
  <link name="sleeve"><inertial><origin xyz="0 0 -0.1"/><mass value="0.5"/>
    <inertia ixx="0.004" iyy="0.004" izz="0.001" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="wrist" type="revolute"><parent link="sleeve"/><child link="hand"/>
    <origin xyz="0 0 -0.2"/><axis xyz="1 0 0"/><limit lower="-3" upper="3" effort="5" velocity="5"/></joint>
  <link name="hand"><inertial><origin xyz="0 0.02 -0.05"/><mass value="0.2"/>
    <inertia ixx="0.001" iyy="0.001" izz="0.0005" ixy="0" ixz="0" iyz="0"/></inertial></link>
</robot>
"""

CASES = {
    "shipped UR5": lambda tmp: (find_scene("ur5.urdf"), []),
    "Panda, fingers locked open": lambda tmp: (ERD / "panda.urdf", ["panda_finger_joint1=0.02",
                                                                   "panda_finger_joint2=0.03"]),
    "arm with a wheel and a fixed flange": lambda tmp: (write(tmp, "arm_wheel.urdf", ARM_URDF), []),
    "Kinova (fixed joints without an axis)": lambda tmp: (ERD / "kinova.urdf", []),
    "arm with a prismatic joint": lambda tmp: (write(tmp, "telescope.urdf", PRISMATIC_URDF), []),
    "gripper, its fingers free (a tree)": lambda tmp: (write(tmp, "gripper.urdf", GRIPPER_URDF.replace(
        '<mimic joint="finger_joint1"/>', "")), []),
}


@pytest.mark.parametrize("case", list(CASES))
def test_link_frames_are_the_published_urdfs_at_the_published_joint_states(case, tmp_path):
    path, lock = CASES[case](tmp_path)
    scene = load_scene(path, lock=lock)
    sim = Simulator(scene, integrator="dop853", rtol=1e-10, atol=1e-12, backend="numpy")
    sim.set_axis_moments([0.3] * len(sim.axis_names))
    sim.advance(0.4)
    js = sim.joint_states()
    angles = dict(zip(js.name, js.position))
    assert max(abs(a) for a in angles.values()) > 0.01  # a moving robot
    bodies = {b.name: (b.position, b.rotation) for b in sim.body_states()}
    ours = {name: (p, R) for name, p, R in link_poses(scene.robot, bodies, angles)}
    theirs = published_fk(scene.robot.urdf, angles, tmp_path)
    compared = sorted(set(ours) & set(theirs))
    moving = {link.name for link in scene.robot.links if link.body is not None}
    assert moving <= set(compared), moving - set(compared)
    worst = max(max(np.max(np.abs(ours[n][0] - theirs[n][0])), np.max(np.abs(ours[n][1] - theirs[n][1])))
                for n in compared)
    print(f"{case}: {len(compared)} links within {worst:.2g} of MuJoCo's kinematics of the published URDF")
    assert worst < FK_AGREEMENT


def test_the_published_urdf_is_the_robots_own():
    path = find_scene("ur5.urdf")
    scene = load_scene(path)
    assert scene.robot.urdf == Path(path).read_text()
    locked = load_scene(ERD / "panda.urdf", lock=["panda_finger_joint1", "panda_finger_joint2"])
    assert '<joint name="panda_finger_joint1" type="fixed">' in locked.robot.urdf
    assert "package://example-robot-data/robots/panda_description/meshes/visual/link0.dae" in locked.robot.urdf


def test_an_mjcf_model_has_no_robot_description():
    assert load_scene("arm_flywheel.xml").robot is None
