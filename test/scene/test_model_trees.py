"""Branched models imported as trees (docs/models.md, "Trees"): every parent before its
children, `parent` and `joint.at` written where a body is not its parent's first child, bodies
with several joints as massless frames, a free base carrying several chains, several chains on
the world; `--lock` welding a whole branch.

MuJoCo is the judge. The structure: the tree's forward kinematics is written out here from the
imported scene mapping alone (each body's frame from its parent's, its joint point `joint.at`
or the parent's `next_joint`, its hinge turned or its slide moved by MuJoCo's qpos), and every
MuJoCo body (welded ones included) must sit where its scene body carries it, and every joint's
anchor at its body's O^k, at qpos0 and at random qpos, to POSE_ATOL. The dynamics (contacts
and constraints off in MuJoCo, as they are ignored here): MuJoCo's qacc at random states
(hinges and slides), an IMU on every moving body reading as MuJoCo's sensors (ball and free
joints), and the motion against MuJoCo's RK4 (2 s of joint positions and velocities; 0.5 s of
the IMUs' readings). Models: Gymnasium 1.4.0's ant (free, and with its free root deleted: a
fixed-base ant, its four legs chains on the world), walker2d (both legs), reacher and pusher as
published (their targets chains on the world), robosuite 1.5.2's baxter (two arms on a static
torso, armature on every joint), dm_control's cheetah (a planar root and two legs) and humanoid
(a free torso, arms, legs, hips of three hinges), and two arms written here
(test/scene/models/, licences there).
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco", reason="MuJoCo is the optional extra [models]")

from gyro_sim.dynamics.rotations import axis_angle_matrix, quat_to_matrix
from gyro_sim.scene.load import load_scene
from gyro_sim.scene.mjcf import ModelError, caught_warnings, import_model
from test.scene import test_model_sensors
from test.scene.test_model_import import write
from test.scene.test_model_lock import GRIPPER_URDF
from test.scene.test_model_multijoint import MULTIJOINT_AGREEMENT, QACC_RTOL, held_accelerations, moves_as_in_mujoco
from test.scene.test_model_sensors import READING_RTOL, deviation, gyro_readings, mujoco_readings, with_imu_sites

MODELS = Path(__file__).parent / "models"
GYMNASIUM = MODELS / "gymnasium"
DMC = MODELS / "dm_control"
BAXTER = MODELS / "robosuite" / "baxter" / "robot.xml"
TIAGO = MODELS / "robosuite" / "tiago" / "robot.xml"
#: positions (m) and rotation matrices of MuJoCo's bodies against the scene's tree (measured: 1e-15)
POSE_ATOL = 1e-12

#: two arms of three bodies on a torso: the torso on a hinge (or free: {root}), the left arm a
#: ball joint, a universal joint (two hinges in one body, anchors apart) and a slide; the right
#: arm hinges, a balanced wheel on its forearm (a rotor) and a welded hand; a third body on the
#: torso's far side, so that the torso carries three children
TWO_ARMS = """<mujoco model="two arms">
  <option gravity="0 0 -9.81"/>
  <worldbody>
    <body name="torso" pos="0 0 1.2" quat="0.98 0.05 0.1 0.02">
      {root}
      <inertial pos="0 0 0.1" mass="4" fullinertia="0.2 0.25 0.1 0.01 0 0.005"/>
      <body name="l_upper" pos="0 0.25 0.3" quat="0.9 0.3 0.1 0">
        <joint name="l_shoulder" type="ball" pos="0 0.02 0"/>
        <inertial pos="0 0 -0.15" mass="1" diaginertia="0.01 0.011 0.002"/>
        <body name="l_fore" pos="0 0 -0.3">
          <joint name="l_elbow_x" type="hinge" pos="0.01 0 0.02" axis="1 0 0"/>
          <joint name="l_elbow_y" type="hinge" pos="0 0.02 0.01" axis="0 1 0.3"/>
          <inertial pos="0.02 0 -0.12" mass="0.6" diaginertia="0.005 0.006 0.001"/>
          <body name="l_hand" pos="0 0 -0.25">
            <joint name="l_slide" type="slide" axis="0.2 0 -1"/>
            <inertial pos="0 0.01 -0.05" mass="0.3" diaginertia="0.001 0.0012 0.0004"/>
          </body>
        </body>
      </body>
      <body name="r_upper" pos="0 -0.25 0.3" euler="0.3 0 0.2">
        <joint name="r_shoulder" type="hinge" axis="0 1 0"/>
        <inertial pos="0 0 -0.15" mass="1" diaginertia="0.01 0.012 0.002"/>
        <body name="r_fore" pos="0 0 -0.3">
          <joint name="r_elbow" type="hinge" axis="1 0 0.1"/>
          <inertial pos="0 0 -0.12" mass="0.6" diaginertia="0.005 0.006 0.001"/>
          <body name="wheel" pos="0 0.05 -0.1">
            <joint name="r_wheel" type="hinge" axis="0 1 0"/>
            <inertial pos="0 0 0" mass="0.2" diaginertia="2e-4 4e-4 2e-4"/>
          </body>
          <body name="r_hand" pos="0 0 -0.25">
            <joint name="r_wrist" type="hinge" axis="0 0 1"/>
            <inertial pos="0 0 -0.04" mass="0.3" diaginertia="0.001 0.0011 0.0003"/>
            <body name="r_tool" pos="0 0 -0.08">
              <inertial pos="0 0 -0.02" mass="0.1" diaginertia="1e-4 1e-4 5e-5"/>
            </body>
          </body>
        </body>
      </body>
      <body name="tail" pos="-0.2 0 0">
        <joint name="tail" type="hinge" axis="0 1 0"/>
        <inertial pos="-0.1 0 0" mass="0.5" diaginertia="0.002 0.003 0.001"/>
      </body>
    </body>
    {beside}
  </worldbody>
  {key}
</mujoco>
"""
HINGED = '<joint name="waist" type="hinge" axis="0 0 1" pos="0 0 -0.1"/>'
FREE = '<freejoint name="root"/>'
#: a second chain on the world, beside the torso
POLE = ('<body name="pole" pos="1 0.5 0.5"><joint name="pole" type="hinge" axis="1 0 0"/>'
        '<inertial pos="0 0 0.3" mass="0.4" diaginertia="0.01 0.01 0.001"/>'
        '<body name="flag" pos="0 0 0.6"><joint name="flag" type="hinge" axis="0 0 1"/>'
        '<inertial pos="0.1 0 0" mass="0.1" diaginertia="1e-4 1e-3 1e-3"/></body></body>')


def unit(*q: float) -> str:
    return " ".join(repr(float(x)) for x in np.asarray(q) / np.linalg.norm(q))


#: a keyframe of the free two arms: the torso's pose, the left shoulder's quaternion, the hinges and the slide
KEY = (f'<keyframe><key name="pose" qpos="0.3 -0.2 1.5 {unit(0.9, 0.1, -0.3, 0.2)} {unit(0.8, 0.2, 0.4, -0.3)} '
       '0.5 -0.4 0.1 0.7 -0.6 1.2 0.3 -0.5"/></keyframe>')


def two_arms(tmp_path: Path, root: str = HINGED, beside: str = "", key: str = "") -> Path:
    return write(tmp_path, "two_arms.xml", TWO_ARMS.format(root=root, beside=beside, key=key))


def tree(mapping: dict) -> list[int]:
    """Each body's parent (its index; -1: the base), as docs/scene-format.md defines it: the
    body before it unless `parent` names another (or the base)."""
    names = [b["name"] for b in mapping["bodies"]]
    out = []
    for k, b in enumerate(mapping["bodies"]):
        parent = b.get("parent")
        out.append(k - 1 if parent is None else -1 if parent == "base" else names.index(parent))
        assert out[-1] < k  # every parent before its children
    return out


def forward(mapping: dict, values: dict[str, object]) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each scene body's (O^k, world_R_body), written out from the scene mapping: its parent's
    frame, its joint point (`joint.at`, else the parent's `next_joint`; from the base: the base's
    position), turned by its hinge angle about the axis in the parent's frame, moved along a
    slide's axis, or a spherical body's world orientation; `values` by body name (angles, slide
    positions, quaternions), the free base's O^1 under "base"."""
    bodies, parents = mapping["bodies"], tree(mapping)
    out: list[tuple[np.ndarray, np.ndarray]] = []
    for k, b in enumerate(bodies):
        p = parents[k]
        O_p, R_p = out[p] if p >= 0 else (np.asarray(mapping["base"]["position"], float), np.eye(3))
        joint = b["joint"]
        at = joint.get("at", bodies[p].get("next_joint") if p >= 0 else [0.0, 0.0, 0.0])
        O = O_p + R_p @ np.asarray(at, float)
        if k == 0 and mapping["base"]["type"] == "free":
            O = np.asarray(values["base"], float)
        if joint["type"] == "spherical":
            R = quat_to_matrix(np.asarray(values[b["name"]], float))
        elif joint["type"] == "hinge":
            R = R_p @ axis_angle_matrix(np.asarray(joint["axis"], float) / np.linalg.norm(joint["axis"]),
                                        float(values[b["name"]]))
        else:
            axis = np.asarray(joint["axis"], float) / np.linalg.norm(joint["axis"])
            O, R = O + R_p @ axis * float(values[b["name"]]), R_p
        out.append((O, R))
    return out


def scene_values(m, d, mapping: dict) -> dict[str, object]:
    """The scene's coordinates at MuJoCo's state `d`: a hinge's angle and a slide's position are
    qpos by joint name, a spherical body's quaternion its MuJoCo body's (a free root's position
    its qpos)."""
    out: dict[str, object] = {}
    for j in range(m.njnt):
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j)
        q = int(m.jnt_qposadr[j])
        body = int(m.jnt_bodyid[j])
        if int(m.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_FREE):
            out["base"] = d.qpos[q:q + 3].copy()
            out[mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, body)] = d.xquat[body].copy()
        elif int(m.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_BALL):
            out[mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, body)] = d.xquat[body].copy()
        else:
            out[name] = float(d.qpos[q])
    return out


def carriers(m, mapping: dict) -> dict[int, int]:
    """MuJoCo body -> the scene body it rides (the last joint of its weld group names it: a
    hinge's or slide's joint, a ball or free body's body); rotors and static bodies left out."""
    names = [b["name"] for b in mapping["bodies"]]
    out = {}
    for b in range(1, m.nbody):
        root = int(m.body_weldid[b])
        if root == 0:
            continue
        j = int(m.body_jntadr[root]) + int(m.body_jntnum[root]) - 1
        one = int(m.jnt_type[j]) in (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT if one else mujoco.mjtObj.mjOBJ_BODY,
                                 j if one else root)
        if name in names:
            out[b] = names.index(name)
    return out


def anchors(m, mapping: dict) -> dict[int, tuple[int, int]]:
    """Scene body -> (its MuJoCo joint, its MuJoCo body): the joint whose anchor is O^k (a hinge's
    or slide's by name, a ball body's joint; -1 for the free root, whose O^1 is its body's origin)."""
    out = {}
    for k, b in enumerate(mapping["bodies"]):
        j = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, b["name"])
        if b["joint"]["type"] == "spherical":
            body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, b["name"])
            j = int(m.body_jntadr[body])
            out[k] = (-1 if int(m.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_FREE) else j, body)
        else:
            out[k] = (j, int(m.jnt_bodyid[j]))
    return out


def random_state(m, d, rng) -> None:
    """MuJoCo's qpos at random: hinges within +-pi, slides within +-0.3 m, balls and free
    roots at random orientations (a free root also at a random place)."""
    for j in range(m.njnt):
        q, kind = int(m.jnt_qposadr[j]), int(m.jnt_type[j])
        if kind == int(mujoco.mjtJoint.mjJNT_FREE):
            d.qpos[q:q + 3] = rng.normal(size=3)
            quat = rng.normal(size=4)
            d.qpos[q + 3:q + 7] = quat / np.linalg.norm(quat)
        elif kind == int(mujoco.mjtJoint.mjJNT_BALL):
            quat = rng.normal(size=4)
            d.qpos[q:q + 4] = quat / np.linalg.norm(quat)
        elif kind == int(mujoco.mjtJoint.mjJNT_HINGE):
            d.qpos[q] = rng.uniform(-np.pi, np.pi)
        else:
            d.qpos[q] = rng.uniform(-0.3, 0.3)


def pose_deviation(path: Path, lock: tuple[str, ...] = (), states: int = 4, seed: int = 3) -> tuple[float, int]:
    """The largest difference between every MuJoCo body's world position and orientation and
    where the imported tree carries it, and between every joint's anchor and its scene body's
    O^k, at the reference pose and at `states` random qpos; and how many MuJoCo bodies were
    compared. MuJoCo's model is the file's, its meshes left out, its locked joints held where
    the lock welds them (the first keyframe's, else qpos0)."""
    mapping = import_model(path, lock=list(lock)).mapping
    with caught_warnings(mujoco):
        spec = mujoco.MjSpec.from_file(str(path))
        for mesh in list(spec.meshes):  # left out as the import leaves them (not in the wheel's robot.xml)
            for geom in [g for g in spec.geoms if g.meshname == mesh.name]:
                spec.delete(geom)
            spec.delete(mesh)
        m = spec.compile()
    d = mujoco.MjData(m)
    held = {}  # qpos index -> the locked joint's value there
    for name in lock:
        j = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)
        qa = int(m.jnt_qposadr[j])
        n = {int(mujoco.mjtJoint.mjJNT_FREE): 7, int(mujoco.mjtJoint.mjJNT_BALL): 4}.get(int(m.jnt_type[j]), 1)
        held.update({q: (m.key_qpos[0] if m.nkey else m.qpos0)[q] for q in range(qa, qa + n)})
    ride = carriers(m, mapping)
    one = [int(m.jnt_qposadr[j]) for j in range(m.njnt)
           if int(m.jnt_type[j]) in (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))]
    d.qpos[:] = m.qpos0
    d.qpos[one] = 0.0  # the reference pose: every hinge and slide at 0 (docs/models.md, Frames)
    d.qpos[list(held)] = list(held.values())
    mujoco.mj_kinematics(m, d)
    ref = forward(mapping, scene_values(m, d, mapping))
    # each MuJoCo body in its scene body's frame, at the reference pose
    local = {b: (ref[k][1].T @ (d.xpos[b] - ref[k][0]), ref[k][1].T @ d.xmat[b].reshape(3, 3))
             for b, k in ride.items()}
    rng = np.random.default_rng(seed)
    worst = 0.0
    for i in range(states + 1):
        if i:
            random_state(m, d, rng)
            d.qpos[list(held)] = list(held.values())
            mujoco.mj_kinematics(m, d)
        values = scene_values(m, d, mapping)
        poses = forward(mapping, values)
        for k, (j, b) in anchors(m, mapping).items():  # the joint points O^k, massless frames' too
            joint = mapping["bodies"][k]["joint"]
            O = poses[k][0]
            if joint["type"] == "slide":  # MuJoCo's anchor is where the slide starts from
                O = O - poses[k][1] @ np.asarray(joint["axis"], float) / np.linalg.norm(joint["axis"]) * \
                    values[mapping["bodies"][k]["name"]]
            worst = max(worst, float(np.max(np.abs(O - (d.xpos[b] if j < 0 else d.xanchor[j])))))
        for b, k in ride.items():
            O, R = poses[k]
            p, Rb = local[b]
            worst = max(worst, float(np.max(np.abs(O + R @ p - d.xpos[b]))),
                        float(np.max(np.abs(R @ Rb - d.xmat[b].reshape(3, 3)))))
    return worst, len(ride)


#: per model: the file (a function of tmp_path), the joints locked, the scene's base, each
#: body's parent (None: the body before it) in the scene's order
CASES = {
    "ant": (lambda tmp: GYMNASIUM / "ant.xml", (), "free",
            [("torso", None), ("hip_1", None), ("ankle_1", None), ("hip_2", "torso"), ("ankle_2", None),
             ("hip_3", "torso"), ("ankle_3", None), ("hip_4", "torso"), ("ankle_4", None)]),
    "walker2d": (lambda tmp: GYMNASIUM / "walker2d.xml", (), "fixed",
                 [("rootx", None), ("rootz", None), ("rooty", None), ("thigh_joint", None), ("leg_joint", None),
                  ("foot_joint", None), ("thigh_left_joint", "rooty"), ("leg_left_joint", None),
                  ("foot_left_joint", None)]),
    "reacher": (lambda tmp: GYMNASIUM / "reacher.xml", (), "fixed",
                [("joint0", None), ("joint1", None), ("target_x", "base"), ("target_y", None)]),
    "pusher": (lambda tmp: GYMNASIUM / "pusher_v5.xml", (), "fixed",
               [("r_shoulder_pan_joint", None), ("r_shoulder_lift_joint", None), ("r_upper_arm_roll_joint", None),
                ("r_elbow_flex_joint", None), ("r_forearm_roll_joint", None), ("r_wrist_flex_joint", None),
                ("r_wrist_roll_joint", None), ("obj_slidey", "base"), ("obj_slidex", None),
                ("goal_slidey", "base"), ("goal_slidex", None)]),
    "baxter": (lambda tmp: BAXTER, (), "fixed",
               [(f"{side}_{j}", "base" if side == "left" and j == "s0" else None)
                for side in ("right", "left") for j in ("s0", "s1", "e0", "e1", "w0", "w1", "w2")]),
    "dm_control cheetah": (lambda tmp: DMC / "cheetah.xml", (), "fixed",
                           [("rootx", None), ("rootz", None), ("rooty", None), ("bthigh", None), ("bshin", None),
                            ("bfoot", None), ("fthigh", "rooty"), ("fshin", None), ("ffoot", None)]),
    "dm_control humanoid": (lambda tmp: DMC / "humanoid.xml", (), "free",
                            [("torso", None), ("abdomen_z", None), ("abdomen_y", None), ("abdomen_x", None),
                             ("right_hip_x", None), ("right_hip_z", None), ("right_hip_y", None),
                             ("right_knee", None), ("right_ankle_y", None), ("right_ankle_x", None),
                             ("left_hip_x", "abdomen_x"), ("left_hip_z", None), ("left_hip_y", None),
                             ("left_knee", None), ("left_ankle_y", None), ("left_ankle_x", None),
                             ("right_shoulder1", "torso"), ("right_shoulder2", None), ("right_elbow", None),
                             ("left_shoulder1", "torso"), ("left_shoulder2", None), ("left_elbow", None)]),
    "two arms": (lambda tmp: two_arms(tmp), (), "fixed",
                 [("waist", None), ("l_upper", None), ("l_elbow_x", None), ("l_elbow_y", None), ("l_slide", None),
                  ("r_shoulder", "waist"), ("r_elbow", None), ("r_wrist", None), ("tail", "waist")]),
    "two arms, free": (lambda tmp: two_arms(tmp, FREE), (), "free",
                       [("torso", None), ("l_upper", None), ("l_elbow_x", None), ("l_elbow_y", None),
                        ("l_slide", None), ("r_shoulder", "torso"), ("r_elbow", None), ("r_wrist", None),
                        ("tail", "torso")]),
    "two arms and a pole on the world": (lambda tmp: two_arms(tmp, beside=POLE), (), "fixed",
                                         [("waist", None), ("l_upper", None), ("l_elbow_x", None),
                                          ("l_elbow_y", None), ("l_slide", None), ("r_shoulder", "waist"),
                                          ("r_elbow", None), ("r_wrist", None), ("tail", "waist"),
                                          ("pole", "base"), ("flag", None)]),
    "ant, its free root locked (a fixed-base ant)": (lambda tmp: GYMNASIUM / "ant.xml", ("root",), "fixed",
                                                     [("hip_1", None), ("ankle_1", None), ("hip_2", "base"),
                                                      ("ankle_2", None), ("hip_3", "base"), ("ankle_3", None),
                                                      ("hip_4", "base"), ("ankle_4", None)]),
    "two arms, free, its root and left shoulder locked at a keyframe": (
        lambda tmp: two_arms(tmp, FREE, key=KEY), ("root", "l_shoulder"), "fixed",
        [("l_elbow_x", None), ("l_elbow_y", None), ("l_slide", None), ("r_shoulder", "base"), ("r_elbow", None),
         ("r_wrist", None), ("tail", "base")]),
    "two arms, left arm and tail locked": (lambda tmp: two_arms(tmp), ("l_elbow_x", "l_elbow_y", "l_slide", "tail"),
                                           "fixed", [("waist", None), ("l_upper", None), ("r_shoulder", "waist"),
                                                     ("r_elbow", None), ("r_wrist", None)]),
}


@pytest.mark.parametrize("name", list(CASES))
def test_a_branched_model_is_imported_as_its_tree(name, tmp_path):
    """Parents as MuJoCo's (welded bodies, frames and rotors taken out), `parent` written only
    where a body does not follow its parent, `joint.at` exactly there, a `next_joint` on every
    body with a child and on no other."""
    source, lock, base, expected = CASES[name]
    mapping = import_model(source(tmp_path), lock=list(lock)).mapping
    bodies = mapping["bodies"]
    assert mapping["base"]["type"] == base
    assert [(b["name"], b.get("parent")) for b in bodies] == expected
    parents = tree(mapping)
    for k, b in enumerate(bodies):
        assert ("at" in b["joint"]) == (parents[k] != k - 1), b["name"]
        assert ("next_joint" in b) == (k in parents), b["name"]


@pytest.mark.parametrize("name", list(CASES))
def test_the_trees_frames_carry_every_body_as_mujoco_does(name, tmp_path):
    source, lock, _, _ = CASES[name]
    worst, compared = pose_deviation(source(tmp_path), lock)
    print(f"{name}: {compared} MuJoCo bodies within {worst:.2g} of the tree's frames")
    bodies = import_model(source(tmp_path), lock=list(lock)).mapping["bodies"]
    assert compared >= sum(b["mass"] > 0.0 for b in bodies) and worst <= POSE_ATOL


def test_the_two_arms_keep_their_rotor_and_welded_hand(tmp_path):
    bodies = {b["name"]: b for b in import_model(two_arms(tmp_path)).mapping["bodies"]}
    assert [r["name"] for r in bodies["r_elbow"]["rotors"]] == ["r_wheel"]
    assert bodies["r_wrist"]["mass"] == pytest.approx(0.4)  # the tool welded to the hand
    assert bodies["l_elbow_x"]["mass"] == 0.0  # the universal joint's massless frame


def test_a_free_base_beside_another_chain_on_the_world_is_refused_naming_it(tmp_path):
    with pytest.raises(ModelError) as info:
        import_model(two_arms(tmp_path, FREE, POLE))
    path = tmp_path / "two_arms.xml"
    assert info.value.errors == [
        f"{path}: worldbody: 1 moving body hangs from the world ('pole') beside the free body 'torso': a free "
        "base carries the whole tree; weld them with --lock JOINT (their joints: 'pole', 'flag')"]
    import_model(path, lock=["pole", "flag"])  # and the lock it suggests makes it one


# ------------------------------------------------------------------ the dynamics against MuJoCo
def judged_copy(path: Path, tmp_path: Path, delete: tuple[str, ...] = (), dry_friction: bool = True) -> Path:
    """`path` as MuJoCo writes it back, its meshes and their geoms left out (the import leaves
    them out: robosuite's files come without them), the joints `delete` deleted (the ant's free
    root: a fixed-base ant, its torso part of the base) and every body named (body<i>), so that
    a site can be put on it. Without `dry_friction` the joints' frictionloss is taken out
    (MuJoCo's is a constraint, off in the judge, where gyro_sim's Coulomb friction acts: judged
    in test/scene/test_model_friction.py)."""
    with caught_warnings(mujoco):
        spec = mujoco.MjSpec.from_file(str(path))
    for joint in spec.joints if not dry_friction else ():
        joint.frictionloss = 0.0
    for mesh in list(spec.meshes):
        for geom in [g for g in spec.geoms if g.meshname == mesh.name]:
            spec.delete(geom)
        spec.delete(mesh)
    for name in delete:
        spec.delete(spec.joint(name))
    for i, body in enumerate(spec.bodies):
        if not body.name:
            body.name = f"body{i}"
    with caught_warnings(mujoco):
        spec.compile()
        return write(tmp_path, f"judged_{path.name}", spec.to_xml())


#: models of hinges and slides only: the file (a function of tmp_path), as published unless said
HINGED = {
    "ant, fixed base (its free root deleted)": lambda tmp: judged_copy(GYMNASIUM / "ant.xml", tmp, ("root",)),
    "walker2d": lambda tmp: GYMNASIUM / "walker2d.xml",
    "reacher": lambda tmp: GYMNASIUM / "reacher.xml",
    "pusher": lambda tmp: GYMNASIUM / "pusher_v5.xml",
    "baxter": lambda tmp: judged_copy(BAXTER, tmp),
    "tiago (a torso on a slide, a head, two arms)": lambda tmp: judged_copy(TIAGO, tmp),
    "dm_control cheetah": lambda tmp: DMC / "cheetah.xml",
    "dm_control finger, its spinner's dry friction out": lambda tmp: judged_copy(DMC / "finger.xml", tmp,
                                                                                 dry_friction=False),
}


@pytest.mark.parametrize("backend", ["numpy", "numba"])
@pytest.mark.parametrize("name", list(HINGED))
def test_a_tree_of_hinges_and_slides_accelerates_as_in_mujoco(name, backend, tmp_path):
    """MuJoCo's qacc (mj_forward, contacts and constraints off: armature, damping and gravity
    the file's) at random states under random generalised forces, on both backends."""
    worst = held_accelerations(HINGED[name](tmp_path), {}, backend=backend)
    print(f"{name} ({backend}): accelerations within {worst:.2g} (relative) of MuJoCo's")
    assert worst <= QACC_RTOL


@pytest.mark.slow
@pytest.mark.parametrize("name", list(HINGED))
def test_a_tree_of_hinges_and_slides_moves_as_in_mujoco(name, tmp_path):
    """Over 2 s under a constant generalised force on every joint (alternating +-0.3 N m or N),
    MuJoCo's RK4 at 1e-4 s against dop853 at 1e-12: every joint's position and velocity."""
    path = HINGED[name](tmp_path)
    names = [b.name for b in load_scene(path).bodies]
    worst, moved = moves_as_in_mujoco(path, (), {n: 0.3 * (-1) ** i for i, n in enumerate(names)})
    print(f"{name}: positions and velocities within {worst:.2g} of MuJoCo's over 2 s (moved {moved:.2g})")
    assert worst <= MULTIJOINT_AGREEMENT and moved > 0.1


def probed(path: Path, tmp_path: Path, states: int = 2) -> tuple[Path, list[str]]:
    """A copy of `path` with a site and MuJoCo's four IMU sensors on every moving body but the
    rotors (no bodies of the scene), at a random pose in it, and `states` random keyframes; the
    sites' names."""
    copy = judged_copy(path, tmp_path)
    m = mujoco.MjModel.from_xml_path(str(copy))
    rotors = {r["name"] for b in import_model(copy).mapping["bodies"] for r in b.get("rotors", [])}
    bodies = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) for b in range(1, m.nbody) if m.body_weldid[b]
              and mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, int(m.body_jntadr[m.body_weldid[b]])) not in rotors]
    return with_imu_sites(copy, bodies, np.random.default_rng(11), tmp_path, states), [f"imu_{b}" for b in bodies]


#: MuJoCo's RK4 step judging the motion of the trees with spherical joints (its own error over
#: 0.5 s: 2e-9 at 1e-4 s on the two arms and the pole, 4e-11 at this step)
MOTION_STEP = 2.5e-5
#: models with ball and free joints: the file (a function of tmp_path)
SPHERICAL = {
    "ant": lambda tmp: GYMNASIUM / "ant.xml",
    "dm_control humanoid": lambda tmp: DMC / "humanoid.xml",
    "two arms": two_arms,
    "two arms, free": lambda tmp: two_arms(tmp, FREE),
    "two arms and a pole on the world": lambda tmp: two_arms(tmp, beside=POLE),
}


@pytest.mark.parametrize("name", list(SPHERICAL))
def test_a_tree_with_ball_and_free_joints_accelerates_as_in_mujoco(name, tmp_path):
    """An IMU on every moving body reads as MuJoCo's gyro, accelerometer, framequat and
    framelinacc (the site's acceleration: every joint's acceleration enters it) at random states."""
    path, sites = probed(SPHERICAL[name](tmp_path), tmp_path)
    ctrl = np.zeros(mujoco.MjModel.from_xml_path(str(path)).nu)
    worst = max(deviation(mujoco_readings(path, ctrl, key=key), gyro_readings(path, key, ctrl), sites)
                for key in ("probe0", "probe1"))
    print(f"{name}: {len(sites)} IMUs within {worst:.2g} (relative) of MuJoCo's sensors")
    assert worst <= READING_RTOL


@pytest.mark.slow
@pytest.mark.parametrize("name", list(SPHERICAL))
def test_a_tree_with_ball_and_free_joints_moves_as_in_mujoco(name, tmp_path, monkeypatch):
    """From a random state, 0.5 s of MuJoCo's RK4 at MOTION_STEP against dop853 at 1e-12: every
    IMU's readings (the bodies' orientations, angular velocities and accelerations) after it."""
    monkeypatch.setattr(test_model_sensors, "MUJOCO_STEP", MOTION_STEP)
    path, sites = probed(SPHERICAL[name](tmp_path), tmp_path, states=1)
    ctrl = np.zeros(mujoco.MjModel.from_xml_path(str(path)).nu)
    worst = deviation(mujoco_readings(path, ctrl, advance=0.5, key="probe0"),
                      gyro_readings(path, "probe0", ctrl, advance=0.5), sites)
    print(f"{name}: {len(sites)} IMUs within {worst:.2g} of MuJoCo's sensors after 0.5 s")
    assert worst <= MULTIJOINT_AGREEMENT


def test_a_whole_branch_is_locked_as_mujoco_holds_it(tmp_path):
    """Baxter's left arm welded at a pose (seven hinges): the right arm accelerates as MuJoCo's
    with the left arm's joints held there, and the scene is a chain again."""
    path = judged_copy(BAXTER, tmp_path)
    left = dict(zip([f"left_{j}" for j in ("s0", "s1", "e0", "e1", "w0", "w1", "w2")],
                    (0.4, -0.6, 1.1, 0.9, -0.3, 0.7, 1.5)))
    mapping = import_model(path, lock=[f"{k}={v}" for k, v in left.items()]).mapping
    assert [b["name"] for b in mapping["bodies"]] == [f"right_{j}" for j in ("s0", "s1", "e0", "e1", "w0", "w1", "w2")]
    assert not any("parent" in b or "at" in b["joint"] for b in mapping["bodies"])
    worst = held_accelerations(path, left)
    print(f"baxter, left arm locked: accelerations within {worst:.2g} (relative) of MuJoCo's")
    assert worst <= QACC_RTOL


def test_the_base_is_named_as_scene_files_name_it():
    from gyro_sim.scene import load, mjcf

    assert mjcf.BASE_PARENT == load.BASE_PARENT


def test_gyro_sim_import_writes_the_tree_as_a_scene_file(tmp_path):
    """`gyro-sim import` writes `parent` and `joint.at`; the file loads into the same tree."""
    from gyro_sim.cli import main

    source = two_arms(tmp_path, beside=POLE)
    out = tmp_path / "two_arms.yaml"
    assert main(["import", str(source), "-o", str(out)]) == 0
    text = out.read_text()
    assert "parent: waist" in text and "parent: base" in text and "at: [" in text
    written, direct = load_scene(out), load_scene(source)
    parents = [-1, 0, 1, 2, 3, 0, 5, 6, 0, -1, 9]
    assert [b.parent for b in written.bodies] == [b.parent for b in direct.bodies] == parents
    for a, b in zip(written.bodies, direct.bodies):
        assert (a.joint.at is None) == (b.joint.at is None)
        assert a.joint.at is None or np.array_equal(a.joint.at, b.joint.at)


def test_a_urdf_tree_is_imported_and_accelerates_as_in_mujoco(tmp_path):
    """A URDF arm whose hand (on a fixed joint) carries two prismatic fingers, the mimic taken
    out: the fingers branch from the arm's last body (the hand merged into it)."""
    path = write(tmp_path, "gripper.urdf", GRIPPER_URDF.replace('<mimic joint="finger_joint1"/>', ""))
    bodies = import_model(path).mapping["bodies"]
    assert [(b["name"], b.get("parent")) for b in bodies] == [("joint1", None), ("joint2", None),
                                                              ("finger_joint1", None), ("finger_joint2", "joint2")]
    worst = held_accelerations(path, {})
    print(f"URDF gripper, fingers free: accelerations within {worst:.2g} (relative) of MuJoCo's")
    assert worst <= QACC_RTOL


def test_a_locked_free_root_is_the_file_without_it(tmp_path):
    """`--lock root` on the ant welds its torso where the file puts it: the scene of the file
    with its free joint taken out of its text (a fixed-base ant, judged above)."""
    locked = import_model(GYMNASIUM / "ant.xml", lock=["root"])
    assert "joint 'root': locked at its reference pose (its body welded to its parent)" in locked.notes
    text, found = re.subn(r'\s*<joint [^>]*name="root"[^>]*type="free"/>', "", (GYMNASIUM / "ant.xml").read_text())
    assert found == 1
    deleted = import_model(write(tmp_path, "ant.xml", text)).mapping
    assert locked.mapping["bodies"] == deleted["bodies"] and locked.mapping["base"] == deleted["base"]
    with pytest.raises(ModelError, match="is locked where it is"):
        import_model(GYMNASIUM / "ant.xml", lock=["root=0.3"])
