"""Public robot descriptions nobody here wrote load on the first try and move as MuJoCo moves
them (docs/models.md, "Public models"; the files in test/scene/models/, with their licences).

The judge is MuJoCo on the same file: RK4 at 1e-4 s, contacts and constraints (limits, dry
friction, equalities) off, its damper on, the same constant generalised force on every hinge,
from the same initial state; locked joints are removed from MuJoCo's spec. The hinge angles
must agree to AGREEMENT over the horizon.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco", reason="MuJoCo is the optional extra [models]")

from gyro_sim import Simulator
from gyro_sim.cli import main
from gyro_sim.paths import find_scene
from gyro_sim.scene.load import SceneError, load_scene
from gyro_sim.scene.mjcf import caught_warnings, import_model
from test.scene.test_model_import import AGREEMENT, MUJOCO_STEP

MODELS = Path(__file__).parent / "models"
ERD = MODELS / "example_robot_data"
DMC = MODELS / "dm_control"
#: the generalised force on every hinge (N m), so that every model moves
FORCE = 0.2


def mujoco_judge(path: Path, locked=()):
    """MuJoCo's model of the file, `locked` joints and the equalities on them removed, meshes
    left out, contacts and constraints off."""
    with caught_warnings(mujoco):  # MuJoCo's warnings (equal limits...) would go to a log file in the cwd
        spec = mujoco.MjSpec.from_file(str(path))
    for equality in list(spec.equalities):
        if equality.name1 in locked or equality.name2 in locked:
            spec.delete(equality)
    for name in locked:
        spec.delete(spec.joint(name))
    for mesh in list(spec.meshes):  # the motion does not need them (every link has an inertial)
        for geom in [g for g in spec.geoms if g.meshname == mesh.name]:
            spec.delete(geom)
        spec.delete(mesh)
    with caught_warnings(mujoco):
        m = spec.compile()
    m.opt.integrator = mujoco.mjtIntegrator.mjINT_RK4
    m.opt.timestep = MUJOCO_STEP
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT) | int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    return m


def agreement(scene, m, horizon: float) -> tuple[float, float]:
    """Largest hinge-angle difference between gyro_sim (dop853, rtol 1e-12) and MuJoCo model `m`
    from the scene's initial state (MuJoCo's first keyframe) under FORCE on every hinge, and
    how far the hinges moved (rad)."""
    d = mujoco.MjData(m)
    if m.nkey:
        mujoco.mj_resetDataKeyframe(m, d, 0)
    sim = Simulator(scene, integrator="dop853", rtol=1e-12, atol=1e-12, backend="numpy")
    hinges = [b.name for b in scene.bodies if b.joint.type == "hinge"]
    sim.set_axis_moments([FORCE if a in hinges else 0.0 for a in sim.axis_names])
    joint = {h: mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, h) for h in hinges}
    for h in hinges:
        d.qfrc_applied[m.jnt_dofadr[joint[h]]] = FORCE
    worst = moved = 0.0
    start = None
    for t in np.linspace(0.0, horizon, 5):
        n = int(round((t - d.time) / MUJOCO_STEP))
        if n:
            mujoco.mj_step(m, d, nstep=n)
        if d.time > sim.time:
            sim.advance(d.time - sim.time)
        js = sim.joint_states()
        position = dict(zip(js.name, js.position))
        q = np.array([d.qpos[m.jnt_qposadr[joint[h]]] for h in hinges])
        start = q if start is None else start
        moved = max(moved, float(np.max(np.abs(q - start))))
        worst = max(worst, float(np.max(np.abs(q - np.array([position[h] for h in hinges])))))
    return worst, moved


#: name -> (file, locked joints, horizon (s)), for the models that run
RUN = {
    "UR5 (shipped, package:// meshes)": (find_scene("ur5.urdf"), (), 1.0),
    "double pendulum": (ERD / "double_pendulum.urdf", (), 1.0),
    "Panda, fingers locked": (ERD / "panda.urdf", ("panda_finger_joint1", "panda_finger_joint2"), 0.5),
    "Kinova": (ERD / "kinova.urdf", (), 0.5),
    "acrobot": (DMC / "acrobot.xml", (), 1.0),
    "pendulum": (DMC / "pendulum.xml", (), 1.0),
    "reacher": (DMC / "reacher.xml", (), 1.0),
}


@pytest.mark.parametrize("name", list(RUN))
def test_a_public_model_moves_as_in_mujoco(name):
    path, locked, horizon = RUN[name]
    scene = load_scene(path, lock=list(locked))
    worst, moved = agreement(scene, mujoco_judge(path, locked), horizon)
    print(f"{name}: {len(scene.bodies)} bodies, hinge angles within {worst:.2g} rad of MuJoCo "
          f"over {horizon:g} s (moved {moved:.2g} rad)")
    assert worst < AGREEMENT
    assert moved > 0.01  # the comparison is of a motion


@pytest.mark.slow
def test_z1_with_damping_and_dry_friction_loads_and_its_damping_agrees(tmp_path):
    """Z1 declares damping and dry friction on every joint: both imported; with the dry
    friction taken out of the file (MuJoCo's is a constraint, off in the judge) the damped arm
    agrees with MuJoCo."""
    path = ERD / "z1.urdf"
    scene = load_scene(path)
    friction = scene.bodies[0].joint.limits.friction
    assert (friction.viscous, friction.coulomb) == (1.0, 1.0)
    text = path.read_text()
    without = text.replace('friction="1.0"', "").replace('friction="2.0"', "")
    assert without != text
    copy = tmp_path / "z1_damped.urdf"
    copy.write_text(without)
    worst, moved = agreement(load_scene(copy), mujoco_judge(copy), 0.5)
    print(f"Z1 damped: hinge angles within {worst:.2g} rad of MuJoCo over 0.5 s (moved {moved:.2g} rad)")
    assert worst < AGREEMENT and moved > 0.01


def test_the_shipped_arm_finds_its_meshes():
    imported = import_model(find_scene("ur5.urdf"))
    assert any(n.startswith("package 'gyro_sim_models': ") for n in imported.notes)
    assert not any("left out" in n for n in imported.notes)
    assert len(imported.mapping["bodies"]) == 6


def test_vendored_urdfs_load_with_their_meshes_missing():
    imported = import_model(ERD / "double_pendulum.urdf")
    meshes = [n for n in imported.notes if "mesh" in n]  # one note for the three
    assert len(meshes) == 1 and meshes[0].startswith("3 meshes left out with their geoms (package://")
    assert "(the first: package 'example-robot-data' not found)" in meshes[0]


@pytest.mark.parametrize("path, said", [
    (ERD / "panda.urdf", "equality #0: equality constraints are not supported (an open tree only); "
                         "--lock the joints it couples to weld them"),
])
def test_what_cannot_run_is_refused_naming_the_element(path, said, capsys):
    with pytest.raises(SceneError) as info:
        load_scene(path)
    assert any(said in e for e in info.value.errors), info.value.errors
    assert main(["run", "--scene", str(path), "--duration", "0.01"]) == 2
    err = capsys.readouterr().err
    assert said in err and "Traceback" not in err


RS = MODELS / "robosuite"


@pytest.mark.parametrize("arm", ["iiwa", "ur5e"])
def test_robosuite_arms_load_with_their_base_mesh_missing(arm, tmp_path):
    """robosuite 1.5.2's arms as published: their fixed base takes its mass from a mesh not
    vendored; welded to the world it moves nothing, so that is a note. With the dry friction
    taken out of a copy (MuJoCo's is a constraint, off in the judge) the arm moves as in
    MuJoCo."""
    path = RS / arm / "robot.xml"
    imported = import_model(path)
    assert any("'fixed_base_link' welded to the world needs no mass" in n for n in imported.notes), imported.notes
    text = path.read_text()
    without = re.sub(r'\s+frictionloss="[^"]*"', "", text)
    copy = tmp_path / "robot.xml"
    copy.write_text(without)
    worst, moved = agreement(load_scene(copy), mujoco_judge(copy), 0.5)
    print(f"robosuite {arm}: hinge angles within {worst:.2g} rad of MuJoCo over 0.5 s (moved {moved:.2g} rad)")
    assert worst < AGREEMENT and moved > 0.01
