"""Several joints in one MJCF body (docs/models.md, "Several joints in one body"): a body with
joints j1..jm becomes m scene bodies, the first m - 1 massless frames each carrying one joint,
the last the body's inertia; `--lock` welds any one of them.

MuJoCo is the judge: a universal-joint pendulum written here (two hinges in one body, their
anchors apart, a second body below) must accelerate as MuJoCo's forward dynamics at random
states (contacts and constraints off) and move as MuJoCo's RK4 over 2 s to MULTIJOINT_AGREEMENT;
with joints locked, the accelerations are MuJoCo's with those joints held (its mass matrix
reduced to the free joints) wherever the locked joints sit in the body's order; Gymnasium's
reacher (test/scene/models/gymnasium/, MIT) loads with its target's two slides locked and its
arm moves as in MuJoCo (the target is a chain of its own there: nothing couples it to the arm
once contacts are off).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco", reason="MuJoCo is the optional extra [models]")

from gyro_sim import Simulator
from gyro_sim.dynamics.model import initial_state
from gyro_sim.scene.load import SceneError, load_scene
from gyro_sim.scene.mjcf import import_model
from test.scene.test_model_import import INSTANTS, gyro_run, mujoco_run, write

#: joint angles and rates of gyro_sim and MuJoCo (RK4 at 1e-4 s against dop853 at 1e-12) over 2 s
#: (measured: 2e-13)
MULTIJOINT_AGREEMENT = 1e-9
#: accelerations at one state, relative to the largest (measured: 4e-14)
QACC_RTOL = 1e-12

#: a pendulum on a universal joint (hinges about x and y, their anchors 2 and 4 cm apart from
#: the body's origin, the body turned), a third hinge in the same body for the lock cases
#: ({extra}), and a second body below on a skew hinge
GIMBAL = """<mujoco model="gimbal">
  <option gravity="0 0 -9.81"/>
  <worldbody>
    <body name="rod" pos="0 0 1" quat="0.9 0.1 0.2 0.05">
      <joint name="ux" type="hinge" pos="0.01 0.02 0.05" axis="1 0 0.2"/>
      <joint name="uy" type="hinge" pos="0.03 -0.01 0.05" axis="0 1 0"/>{extra}
      <inertial pos="0.05 0 -0.3" mass="1" fullinertia="0.02 0.03 0.015 0.001 0 0"/>
      <body name="tip" pos="0 0 -0.5">
        <joint name="tipj" type="hinge" axis="0 0.6 0.8"/>
        <inertial pos="0 0.02 -0.2" mass="0.5" diaginertia="0.01 0.012 0.004"/>
      </body>
    </body>
  </worldbody>
  {key}
</mujoco>
"""
UNIVERSAL = GIMBAL.format(extra="", key='<keyframe><key qpos="0.3 -0.2 0.4" qvel="0.5 1.0 -0.7"/></keyframe>')
THREE = GIMBAL.format(extra='\n      <joint name="uz" type="hinge" pos="-0.02 0.01 0" axis="0.1 0.2 1"/>', key="")
REACHER = Path(__file__).parent / "models" / "gymnasium" / "reacher.xml"


def judge(m):
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT) | int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    return m


def held_accelerations(path: Path, locked: dict[str, float], seed: int = 1, states: int = 5) -> float:
    """The largest difference of gyro_sim's accelerations (the file loaded with `locked`) from
    MuJoCo's with the locked joints held at their values (M reduced to the free joints: M_ff
    qacc_f = (qfrc_passive - qfrc_bias)_f), at random states; relative to the largest."""
    scene = load_scene(path, lock=[f"{k}={v}" for k, v in locked.items()])
    m = judge(mujoco.MjModel.from_xml_path(str(path)))
    d = mujoco.MjData(m)
    sim = Simulator(scene, backend="numpy")
    model = sim.model
    joint = {mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j): j for j in range(m.njnt)}
    names = list(sim.joint_states().name)
    assert sorted(names + list(locked)) == sorted(joint)  # the joint states keep MuJoCo's names
    qf = [int(m.jnt_qposadr[joint[n]]) for n in names]
    vf = [int(m.jnt_dofadr[joint[n]]) for n in names]
    rng = np.random.default_rng(seed)
    worst = 0.0
    for _ in range(states):
        d.qpos[:], d.qvel[:] = rng.uniform(-2.0, 2.0, m.nq), rng.normal(size=m.nv)
        for name, value in locked.items():
            d.qpos[m.jnt_qposadr[joint[name]]], d.qvel[m.jnt_dofadr[joint[name]]] = value, 0.0
        mujoco.mj_forward(m, d)
        M = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, M)
        qacc = np.linalg.solve(M[np.ix_(vf, vf)], (d.qfrc_passive - d.qfrc_bias)[vf])
        y = initial_state(model)
        y[model.i_phi], y[model.i_vel] = d.qpos[qf], d.qvel[vf]
        udot = sim.held_rhs()(0.0, y)[model.i_vel]
        worst = max(worst, float(np.max(np.abs(udot - qacc)) / np.max(np.abs(qacc))))
    return worst


def test_a_universal_joint_is_a_massless_frame_and_the_body(tmp_path):
    imported = import_model(write(tmp_path, "universal.xml", UNIVERSAL))
    bodies = imported.mapping["bodies"]
    assert [b["name"] for b in bodies] == ["ux", "uy", "tipj"]
    assert bodies[0]["mass"] == 0.0 and not np.any(bodies[0]["inertia_com"]) and bodies[1]["mass"] == 1.0
    assert [b["initial"] for b in bodies] == [{"angle": 0.3, "rate": 0.5}, {"angle": -0.2, "rate": 1.0},
                                              {"angle": 0.4, "rate": -0.7}]
    assert [n for _, n in imported.names] == ["ux", "uy", "tipj"]
    assert imported.names[0][0] == "body 'rod' (hinge joint 'ux', a massless frame)"


def test_a_universal_joint_accelerates_as_in_mujoco(tmp_path):
    worst = held_accelerations(write(tmp_path, "universal.xml", UNIVERSAL), {})
    print(f"universal joint: accelerations within {worst:.2g} (relative) of MuJoCo's")
    assert worst <= QACC_RTOL


@pytest.mark.slow
def test_a_universal_joint_moves_as_in_mujoco(tmp_path):
    path = write(tmp_path, "universal.xml", UNIVERSAL)
    forces = {"ux": 0.3, "uy": -0.2, "tipj": 0.1}
    mj_out = mujoco_run(path, {}, forces, INSTANTS)
    gs_out = gyro_run(load_scene(path), forces, INSTANTS)
    worst = moved = 0.0
    for (m, d), (_, position, velocity) in zip(mj_out, gs_out):
        for j in range(m.njnt):
            name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j)
            worst = max(worst, abs(position[name] - d.qpos[m.jnt_qposadr[j]]),
                        abs(velocity[name] - d.qvel[m.jnt_dofadr[j]]))
        moved = max(moved, float(np.max(np.abs(d.qpos - mj_out[0][1].qpos))))
    print(f"universal joint: angles and rates within {worst:.2g} of MuJoCo's over 2 s (moved {moved:.2g} rad)")
    assert worst <= MULTIJOINT_AGREEMENT and moved > 0.1


@pytest.mark.parametrize("locked", [{"ux": 0.3}, {"uy": 0.7}, {"uz": -0.4}, {"ux": 0.2, "uz": 1.1},
                                    {"uy": 0.3, "uz": 1.1}, {"ux": 0.2, "uy": -0.5}])
def test_any_joint_of_a_body_is_locked_as_mujoco_holds_it(locked, tmp_path):
    """Three hinges in one body, one or two locked at a value wherever they sit in the order."""
    worst = held_accelerations(write(tmp_path, "gimbal.xml", THREE), locked)
    assert worst <= QACC_RTOL


def test_a_massless_frame_turning_about_its_childs_axis_is_refused_naming_it(tmp_path):
    coaxial = UNIVERSAL.replace('pos="0.03 -0.01 0.05" axis="0 1 0"', 'pos="0.01 0.02 0.05" axis="1 0 0.2"')
    path = write(tmp_path, "coaxial.xml", coaxial)
    with pytest.raises(SceneError) as info, pytest.warns(UserWarning):  # MuJoCo's: its inertia is singular
        load_scene(path)
    assert info.value.errors == [
        f"{path}: body 'rod' (hinge joint 'ux', a massless frame): mass: 0 (a massless frame), and what it "
        "carries has no inertia about its hinge axis at the initial state: its joint's acceleration is "
        "undetermined; give it a mass, or give what it carries inertia about that axis"]


def test_the_reacher_with_its_target_locked_moves_as_in_mujoco():
    scene = load_scene(REACHER, lock=["target_x", "target_y"])
    assert [b.name for b in scene.bodies] == ["joint0", "joint1"]
    worst = held_accelerations(REACHER, {"target_x": 0.0, "target_y": 0.0})
    print(f"reacher, target locked: accelerations within {worst:.2g} (relative) of MuJoCo's")
    assert worst <= QACC_RTOL


@pytest.mark.slow
def test_the_reacher_arm_moves_as_in_mujoco_with_its_target_locked():
    forces = {"joint0": 0.2, "joint1": -0.1}
    mj_out = mujoco_run(REACHER, {}, forces, INSTANTS)
    gs_out = gyro_run(load_scene(REACHER, lock=["target_x", "target_y"]), forces, INSTANTS)
    worst = moved = 0.0
    for (m, d), (_, position, velocity) in zip(mj_out, gs_out):
        for name in forces:
            j = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)
            worst = max(worst, abs(position[name] - d.qpos[m.jnt_qposadr[j]]),
                        abs(velocity[name] - d.qvel[m.jnt_dofadr[j]]))
            moved = max(moved, abs(d.qpos[m.jnt_qposadr[j]]))
    print(f"reacher, target locked: arm angles and rates within {worst:.2g} of MuJoCo's over 2 s "
          f"(moved {moved:.2g} rad)")
    assert worst <= MULTIJOINT_AGREEMENT and moved > 0.1


def test_unnamed_joints_of_a_body_take_names_that_collide_with_none(tmp_path):
    text = UNIVERSAL.replace('<joint name="ux" ', "<joint ").replace('<joint name="uy" ', "<joint ")
    text = text.replace('<body name="tip"', '<body name="rod_joint0"').replace("<keyframe>", "<!--").replace(
        "</keyframe>", "-->")
    imported = import_model(write(tmp_path, "unnamed.xml", text))
    assert [n for _, n in imported.names] == ["rod_joint0_", "rod_joint1", "tipj"]
    load_scene(write(tmp_path, "unnamed.xml", text))  # and they load
