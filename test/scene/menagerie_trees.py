"""MuJoCo Menagerie's legged robots and humanoids, as published, against MuJoCo (docs/models.md,
"Menagerie's legged robots and humanoids"). Menagerie is not part of the repository: give the
path of a checkout (its meshes need not be there)::

    python -m test.scene.menagerie_trees PATH/TO/mujoco_menagerie [MODEL ...]

For each model (MODELS: its file, the keyframe of its home pose, the joints --lock welds): what
the import says (taken, or the first line of its refusal), and where it runs the judges of
test/scene/test_model_trees.py on a copy without meshes, dry friction and contacts (MuJoCo's
frictionloss is a constraint, off in the judge): the fixed-base robot's accelerations (its free
joint deleted) against MuJoCo's qacc at random states under random joint forces (relative to
the largest); an IMU on every moving body against MuJoCo's sensors at two random states of the
free robot (relative to each reading's scale, at least 1); and the same IMUs after 0.5 s of
motion from the home keyframe with random joint rates (MuJoCo's RK4 at STEP against dop853 at
1e-12).
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import mujoco
from gyro_sim.scene.mjcf import caught_warnings, import_model
from test.scene import test_model_sensors
from gyro_sim import Simulator
from gyro_sim.dynamics.model import initial_state
from gyro_sim.dynamics.rotations import matrix_to_quat
from gyro_sim.scene.load import SceneError, load_scene
from test.scene.test_model_multijoint import judge as without_contacts
from test.scene.test_model_sensors import deviation, gyro_readings, mujoco_readings
from test.scene.test_model_trees import MOTION_STEP, judged_copy, pose_deviation, probed

#: model -> (its file in Menagerie, the keyframe of its home pose or None, the joints locked)
MODELS = {
    "unitree_go2": ("unitree_go2/go2.xml", "home", ()),
    "unitree_a1": ("unitree_a1/a1.xml", "home", ()),
    "anybotics_anymal_c": ("anybotics_anymal_c/anymal_c.xml", None, ()),
    "unitree_h1": ("unitree_h1/h1.xml", None, ()),
    "unitree_g1": ("unitree_g1/g1.xml", None, ()),
    "boston_dynamics_spot": ("boston_dynamics_spot/spot.xml", "home", ()),
    "google_barkour_vb": ("google_barkour_vb/barkour_vb.xml", None, ()),
    "robotis_op3": ("robotis_op3/op3.xml", None, ()),
    "berkeley_humanoid": ("berkeley_humanoid/berkeley_humanoid.xml", "home", ()),
    "agility_cassie": ("agility_cassie/cassie.xml", "home", ()),
    "agility_cassie, its leg linkages locked": ("agility_cassie/cassie.xml", "home", tuple(
        f"{side}-{joint}" for side in ("left", "right") for joint in
        ("achilles-rod", "knee", "shin", "tarsus", "heel-spring", "foot-crank", "plantar-rod", "foot"))),
}
#: how long the motion runs (s)
HORIZON = 0.5
#: MuJoCo's RK4 step judging the motion: the trees' MOTION_STEP / 4, as the servos' force
#: ranges (kinks in the force) make RK4's error larger (ANYmal C: 2.5e-8 at MOTION_STEP,
#: 3.4e-9 at half of it, 4.0e-10 at a quarter, against the same dop853 run)
STEP = MOTION_STEP / 4


def refusal(path: Path, keyframe: str | None, lock: tuple[str, ...]) -> str | None:
    """None if load_scene takes the model; else its refusal's first line (and how many more)."""
    try:
        load_scene(path, keyframe, lock=list(lock))
    except SceneError as exc:
        more = f" (+{len(exc.errors) - 1} more)" if len(exc.errors) > 1 else ""
        return exc.errors[0].split(": ", 1)[-1] + more
    return None


def fixed_base(path: Path, tmp: Path) -> Path:
    """The copy judged (no meshes, no dry friction) with its free joint deleted."""
    with caught_warnings(mujoco):
        spec = mujoco.MjSpec.from_file(str(path))
    for joint in [j for j in spec.joints if j.type == mujoco.mjtJoint.mjJNT_FREE]:
        spec.delete(joint)
    for key in list(spec.keys):  # their qpos hold the free joint's
        spec.delete(key)
    out = tmp / f"fixed_{path.name}"
    out.write_text(spec.to_xml())
    return out


def accelerations(path: Path, seed: int = 1, states: int = 5) -> float:
    """test_model_multijoint.held_accelerations with the model's actuators in force: MuJoCo's
    qacc (M qacc = qfrc_passive + qfrc_actuator - qfrc_bias + qfrc_applied, ctrl 0: a servo
    pulls to its target 0, clamped to its ctrlrange) at random states, random generalised
    forces on the joints a motor drives (gyro_sim's axes); relative to the largest."""
    m = without_contacts(mujoco.MjModel.from_xml_path(str(path)))
    d = mujoco.MjData(m)
    sim = Simulator(load_scene(path), backend="numpy")
    model = sim.model
    names = list(sim.joint_states().name)
    joint = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n) for n in names]
    qf, vf = [int(m.jnt_qposadr[j]) for j in joint], [int(m.jnt_dofadr[j]) for j in joint]
    rng = np.random.default_rng(seed)
    forces = rng.normal(size=len(sim.axis_names))
    sim.set_axis_moments(list(forces))
    d.qfrc_applied[[vf[names.index(a)] for a in sim.axis_names]] = forces
    worst = 0.0
    for _ in range(states):
        d.qpos[:], d.qvel[:] = rng.uniform(-2.0, 2.0, m.nq), rng.normal(size=m.nv)
        mujoco.mj_forward(m, d)
        y = initial_state(model)
        y[model.i_phi], y[model.i_vel] = d.qpos[qf], d.qvel[vf]
        udot = sim.held_rhs()(0.0, y)[model.i_vel]
        worst = max(worst, float(np.max(np.abs(udot - d.qacc[vf])) / np.max(np.abs(d.qacc))))
    return worst


def with_home_rates(path: Path, keyframe: str, rng) -> Path:
    """`path` with a keyframe 'moving': the home pose, the free body at rest, the joints at
    random rates (rad/s)."""
    spec = mujoco.MjSpec.from_file(str(path))
    m = spec.compile()
    key = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, keyframe)
    qvel = rng.normal(scale=1.0, size=m.nv)
    qvel[:6 if m.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE else 0] = 0.0
    spec.add_key(name="moving", qpos=list(m.key_qpos[key]), qvel=list(qvel))
    out = path.with_name(f"moving_{path.name}")
    out.write_text(spec.to_xml())
    return out


def without_textures(path: Path, tmp: Path) -> Path:
    """`path` with its textures, meshes and their geoms left out, as the import leaves them
    out when their files are missing (judged_copy then names its bodies), and no `/` in a
    body's name."""
    with caught_warnings(mujoco):
        spec = mujoco.MjSpec.from_file(str(path))
    for texture in list(spec.textures):
        for material in spec.materials:
            material.textures = ["" if t == texture.name else t for t in material.textures]
        spec.delete(texture)
    for mesh in list(spec.meshes):
        for geom in [g for g in spec.geoms if g.meshname == mesh.name]:
            spec.delete(geom)
        spec.delete(mesh)
    for body in spec.bodies:  # probed() names its sites after the bodies (Barkour's "oak/")
        body.name = body.name.replace("/", "_")
    out = tmp / f"untextured_{path.name}"
    out.write_text(spec.to_xml())
    return out


def welded(path: Path, keyframe: str, lock: tuple[str, ...], tmp: Path) -> Path:
    """`path` with the joints `lock` deleted and their bodies drawn where the keyframe puts
    them relative to their parents (MuJoCo's own kinematics at the keyframe), the equalities,
    actuators and sensors on them deleted, the keyframe kept for the joints left: what --lock
    welds, written out for MuJoCo."""
    with caught_warnings(mujoco):
        spec = mujoco.MjSpec.from_file(str(path))
    m = spec.compile()
    d = mujoco.MjData(m)
    key = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, keyframe)
    mujoco.mj_resetDataKeyframe(m, d, key)
    mujoco.mj_kinematics(m, d)
    kept = [j for j in range(m.njnt) if mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) not in lock]
    size = {int(mujoco.mjtJoint.mjJNT_FREE): 7, int(mujoco.mjtJoint.mjJNT_BALL): 4}
    qpos = [x for j in kept for x in d.qpos[m.jnt_qposadr[j]:m.jnt_qposadr[j] + size.get(int(m.jnt_type[j]), 1)]]
    for name in lock:
        b = int(m.jnt_bodyid[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)])
        p = int(m.body_parentid[b])
        R_p = d.xmat[p].reshape(3, 3)
        body = spec.body(mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b))
        body.pos = R_p.T @ (d.xpos[b] - d.xpos[p])
        body.quat = matrix_to_quat(R_p.T @ d.xmat[b].reshape(3, 3))
        body.alt.type = mujoco.mjtOrientation.mjORIENTATION_QUAT
        spec.delete(spec.joint(name))
    bodies = {mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, int(m.jnt_bodyid[mujoco.mj_name2id(
        m, mujoco.mjtObj.mjOBJ_JOINT, n)])) for n in lock}
    for equality in list(spec.equalities):
        if equality.name1 in bodies or equality.name2 in bodies:
            spec.delete(equality)
    for actuator in [a for a in spec.actuators if a.target in lock]:
        spec.delete(actuator)
    for sensor in [x for x in spec.sensors if x.objname in lock or x.objtype == mujoco.mjtObj.mjOBJ_ACTUATOR]:
        spec.delete(sensor)
    for k in list(spec.keys):
        spec.delete(k)
    spec.add_key(name=keyframe, qpos=qpos)
    out = tmp / f"welded_{path.name}"
    with caught_warnings(mujoco):
        out.write_text(spec.to_xml())
    return out


def judge(path: Path, keyframe: str | None, lock: tuple[str, ...], tmp: Path) -> dict:
    row = {"refused": refusal(path, keyframe, lock)}
    if row["refused"]:
        return row
    path = without_textures(path, tmp)
    if lock:  # the locked tree's frames carry MuJoCo's moving bodies with the locked joints held
        # at the keyframe; the dynamics judged on the file with the locked joints welded there,
        # whose scene is the locked one's but for MuJoCo's writing numbers to 6 digits
        row["poses"] = pose_deviation(path, lock)[0]
        locked = import_model(path, keyframe, lock=list(lock)).mapping
        path = welded(path, keyframe, lock, tmp)
        written = import_model(path, keyframe).mapping
        row["lock"] = max(float(np.max(np.abs(np.subtract(a[k], b[k])) / max(1e-300, np.max(np.abs(a[k])))))
                          for a, b in zip(locked["bodies"], written["bodies"]) for k in ("mass", "com", "inertia_com")
                          if k in a)
    copy = judged_copy(path, tmp, dry_friction=False)
    free = mujoco.MjModel.from_xml_path(str(copy)).jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE
    row["qacc"] = accelerations(fixed_base(copy, tmp) if free else copy)
    probe, sites = probed(copy, tmp)
    ctrl = np.zeros(mujoco.MjModel.from_xml_path(str(probe)).nu)
    row["imu"] = max(deviation(mujoco_readings(probe, ctrl, key=k), gyro_readings(probe, k, ctrl), sites)
                     for k in ("probe0", "probe1"))
    start = "probe0"
    if keyframe:
        probe, start = with_home_rates(probe, keyframe, np.random.default_rng(5)), "moving"
    step, test_model_sensors.MUJOCO_STEP = test_model_sensors.MUJOCO_STEP, STEP
    try:
        row["motion"] = deviation(mujoco_readings(probe, ctrl, advance=HORIZON, key=start),
                                  gyro_readings(probe, start, ctrl, advance=HORIZON), sites)
    finally:
        test_model_sensors.MUJOCO_STEP = step
    row["from"], row["imus"] = start, len(sites)
    return row


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("menagerie", type=Path)
    parser.add_argument("models", nargs="*", default=list(MODELS))
    args = parser.parse_args(argv)
    print("| model | options | result | accelerations (fixed base, relative) | IMUs at random states | "
          f"IMUs after {HORIZON} s |")
    print("| --- | --- | --- | --- | --- | --- |")
    for name in args.models:
        file, keyframe, lock = MODELS[name]
        options = " ".join([f"--keyframe {keyframe}"] * bool(keyframe) + [f"--lock {j}" for j in lock][:1])
        options += f" (+{len(lock) - 1} --lock)" if len(lock) > 1 else ""
        t0 = time.perf_counter()
        with tempfile.TemporaryDirectory() as tmp:
            row = judge(args.menagerie / file, keyframe, lock, Path(tmp))
        if row["refused"]:
            print(f"| {name} | {options} | refused: {row['refused']} | | | |")
        elif "qacc" not in row:
            print(f"| {name} | {options} | imports | | | |")
        else:
            welds = (f"; frames within {row['poses']:.1g} m of MuJoCo's, masses within {row['lock']:.1g} of the "
                     "welded file's" if lock else "")
            print(f"| {name} | {options} | imports ({row['imus']} IMUs{welds}, {time.perf_counter() - t0:.0f} s) | "
                  f"{row['qacc']:.1g} | {row['imu']:.1g} | {row['motion']:.1g} (from {row['from']}) |")
        sys.stdout.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main())
