"""The table of public models in docs/models.md: each description imported as it is published,
then gyro_sim against MuJoCo on the same file.

    python -m test.scene.models.survey EXAMPLE_ROBOT_DATA DM_CONTROL

EXAMPLE_ROBOT_DATA and DM_CONTROL are clones of github.com/Gepetto/example-robot-data and
github.com/google-deepmind/dm_control. For each model: the import's result and, when it runs,
the largest hinge-angle difference over 2 s between gyro_sim (dop853, rtol 1e-12) and MuJoCo
(RK4 at 1e-4 s, contacts and constraints off, damper on) under 0.2 N m on every hinge, from
the file's initial state (locked joints removed from MuJoCo's spec). Z1's dry friction (a
constraint in MuJoCo) is taken out of a copy for the comparison.
"""
from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import mujoco
import numpy as np

from gyro_sim import Simulator
from gyro_sim.scene.load import SceneError, load_scene
from gyro_sim.scene.mjcf import caught_warnings

FINGERS = ("panda_finger_joint1", "panda_finger_joint2")
#: (collection, path in it, locked joints)
MODELS = [
    ("erd", "robots/ur_description/urdf/ur3_robot.urdf", ()),
    ("erd", "robots/ur_description/urdf/ur3_gripper.urdf", ()),
    ("erd", "robots/ur_description/urdf/ur5_robot.urdf", ()),
    ("erd", "robots/ur_description/urdf/ur5_joint_limited_robot.urdf", ()),
    ("erd", "robots/ur_description/urdf/ur5_gripper.urdf", ()),
    ("erd", "robots/ur_description/urdf/ur10_robot.urdf", ()),
    ("erd", "robots/panda_description/urdf/panda.urdf", ()),
    ("erd", "robots/panda_description/urdf/panda.urdf", FINGERS),
    ("erd", "robots/panda_description/urdf/panda_collision.urdf", FINGERS),
    ("erd", "robots/double_pendulum_description/urdf/double_pendulum.urdf", ()),
    ("erd", "robots/double_pendulum_description/urdf/double_pendulum_continuous.urdf", ()),
    ("erd", "robots/double_pendulum_description/urdf/double_pendulum_simple.urdf", ()),
    ("erd", "robots/kinova_description/robots/kinova.urdf", ()),
    ("erd", "robots/z1_description/urdf/z1.urdf", ()),
    ("erd", "robots/talos_data/robots/talos_left_arm.urdf", ()),
    ("erd", "robots/asr_twodof_description/urdf/TwoDofs.urdf", ()),
    ("erd", "robots/borinot_description/urdf/borinot_flying_arm_2.urdf", ()),
    ("dmc", "dm_control/suite/acrobot.xml", ()),
    ("dmc", "dm_control/suite/pendulum.xml", ()),
    ("dmc", "dm_control/suite/reacher.xml", ()),
    ("dmc", "dm_control/suite/finger.xml", ()),
    ("dmc", "dm_control/suite/cartpole.xml", ()),
    ("dmc", "dm_control/suite/swimmer.xml", ()),
    ("dmc", "dm_control/suite/point_mass.xml", ()),
]
STEP = 1e-4
FORCE = 0.2
HORIZON = 2.0


def judge(path: Path, locked) -> mujoco.MjModel:
    """MuJoCo's model of the file, locked joints (and their equalities) and meshes removed."""
    with caught_warnings(mujoco):
        spec = mujoco.MjSpec.from_file(str(path))
        for equality in list(spec.equalities):
            if equality.name1 in locked or equality.name2 in locked:
                spec.delete(equality)
        for name in locked:
            spec.delete(spec.joint(name))
        for mesh in list(spec.meshes):
            for geom in [g for g in spec.geoms if g.meshname == mesh.name]:
                spec.delete(geom)
            spec.delete(mesh)
        m = spec.compile()
    m.opt.integrator = mujoco.mjtIntegrator.mjINT_RK4
    m.opt.timestep = STEP
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT) | int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    return m


def compare(path: Path, scene, locked) -> tuple[float, float]:
    """Largest hinge-angle difference and how far the hinges moved (rad)."""
    m = judge(path, locked)
    d = mujoco.MjData(m)
    if m.nkey:
        mujoco.mj_resetDataKeyframe(m, d, 0)
    sim = Simulator(scene, integrator="dop853", rtol=1e-12, atol=1e-12)
    hinges = [b.name for b in scene.bodies if b.joint.type == "hinge"]
    sim.set_axis_moments([FORCE if a in hinges else 0.0 for a in sim.axis_names])
    joint = {h: mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, h) for h in hinges}
    for h in hinges:
        d.qfrc_applied[m.jnt_dofadr[joint[h]]] = FORCE
    worst = moved = 0.0
    start = None
    for t in np.linspace(0.0, HORIZON, 9):
        n = round((t - d.time) / STEP)
        if n:
            mujoco.mj_step(m, d, nstep=n)
        if d.time > sim.time:
            sim.advance(d.time - sim.time)
        js = sim.joint_states()
        position = dict(zip(js.name, js.position))
        q = np.array([d.qpos[m.jnt_qposadr[joint[h]]] for h in hinges])
        start = q if start is None else start
        moved = max(moved, float(np.max(np.abs(q - start))))
        worst = max(worst, float(np.max(np.abs(q - [position[h] for h in hinges]))))
    return worst, moved


def main(argv: list[str]) -> int:
    roots = {"erd": Path(argv[0]), "dmc": Path(argv[1])}
    with tempfile.TemporaryDirectory() as tmp:
        for collection, rel, locked in MODELS:
            path = roots[collection] / rel
            label = path.name + (f" --lock {' --lock '.join(locked)}" if locked else "")
            try:
                scene = load_scene(path, lock=list(locked))
            except SceneError as exc:
                print(f"| {label} | refused | {exc.errors[0].split(': ', 1)[1]} |")
                continue
            if path.name == "z1.urdf":  # its dry friction is a constraint in MuJoCo: out of a copy
                text = path.read_text()
                path = Path(tmp) / "z1_without_dry_friction.urdf"
                path.write_text(text.replace('friction="1.0"', "").replace('friction="2.0"', ""))
                scene = load_scene(path)
            worst, moved = compare(path, scene, locked)
            print(f"| {label} | runs: {len(scene.bodies)} bodies | {worst:.1e} (moved {moved:.3g} rad) |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
