"""Several joints in one MJCF body (docs/models.md, "Several joints in one body"): a body with
joints j1..jm becomes m scene bodies, the first m - 1 massless frames each carrying one joint,
the last the body's inertia; `--lock` welds any one of them.

MuJoCo is the judge: a universal-joint pendulum written here (two hinges in one body, their
anchors apart, a second body below) must accelerate as MuJoCo's forward dynamics at random
states (contacts and constraints off) and move as MuJoCo's RK4 over 2 s to MULTIJOINT_AGREEMENT;
with joints locked, the accelerations are MuJoCo's with those joints held (its mass matrix
reduced to the free joints) wherever the locked joints sit in the body's order.

Gymnasium 1.4.0's planar models (test/scene/models/gymnasium/, MIT, as published): the hopper
whole (its torso on slide x, slide z and hinge y: two massless frames on the world, then the
torso), the walker with its left leg locked (a chain only: the two legs branch from the torso),
the reacher with its target's two slides locked (the arm) or its arm locked (the target on its
two slides); contacts and constraints (limits) off in MuJoCo, where they are ignored in
gyro_sim. Each: accelerations at random states, and a motion under a constant generalised
force on every joint left, over 2 s against MuJoCo's RK4 on the file with the locked joints
deleted from its spec.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco", reason="MuJoCo is the optional extra [models]")

from gyro_sim import Simulator
from gyro_sim.dynamics.model import initial_state
from gyro_sim.scene.load import SceneError, load_scene
from gyro_sim.scene.mjcf import caught_warnings, import_model
from test.scene.test_model_import import INSTANTS, gyro_run, mujoco_run, write
from test.scene.test_model_sensors import READING_RTOL, deviation, gyro_readings, mujoco_readings, with_imu_sites

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
GYMNASIUM = Path(__file__).parent / "models" / "gymnasium"
REACHER = GYMNASIUM / "reacher.xml"
LEFT_LEG = ("thigh_left_joint", "leg_left_joint", "foot_left_joint")
#: per model: the file, the joints locked (at 0, their reference), the scene's bodies, and a
#: generalised force per joint left (N or N m)
PLANAR = {
    "hopper": (GYMNASIUM / "hopper.xml", (), ["rootx", "rootz", "rooty", "thigh_joint", "leg_joint", "foot_joint"],
               {"rootx": 2.0, "rootz": 30.0, "rooty": 0.5, "thigh_joint": 3.0, "leg_joint": -2.0, "foot_joint": 1.0}),
    "walker2d, left leg locked": (GYMNASIUM / "walker2d.xml", LEFT_LEG,
                                  ["rootx", "rootz", "rooty", "thigh_joint", "leg_joint", "foot_joint"],
                                  {"rootx": 2.0, "rootz": 40.0, "rooty": 0.5, "thigh_joint": 3.0,
                                   "leg_joint": -2.0, "foot_joint": 1.0}),
    "reacher, target locked": (REACHER, ("target_x", "target_y"), ["joint0", "joint1"],
                               {"joint0": 0.2, "joint1": -0.1}),
    "reacher, arm locked": (REACHER, ("joint0", "joint1"), ["target_x", "target_y"],
                            {"target_x": 0.002, "target_y": -0.001}),
}


def judge(m):
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT) | int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    return m


def held_accelerations(path: Path, locked: dict[str, float], seed: int = 1, states: int = 5,
                       backend: str = "numpy") -> float:
    """The largest difference of gyro_sim's accelerations (the file loaded with `locked`) from
    MuJoCo's with the locked joints held at their values (M reduced to the free joints: M_ff
    qacc_f = (qfrc_passive - qfrc_bias + qfrc_applied)_f), at random states under random
    generalised forces on the joints left; relative to the largest. `backend`: the Simulator's."""
    scene = load_scene(path, lock=[f"{k}={v}" for k, v in locked.items()])
    with caught_warnings(mujoco):  # a deprecated attribute's warning, not a file in the working directory
        m = judge(mujoco.MjModel.from_xml_path(str(path)))
    d = mujoco.MjData(m)
    sim = Simulator(scene, backend=backend)
    model = sim.model
    joint = {mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j): j for j in range(m.njnt)}
    names = list(sim.joint_states().name)
    assert sorted(names + list(locked)) == sorted(joint)  # the joint states keep MuJoCo's names
    qf = [int(m.jnt_qposadr[joint[n]]) for n in names]
    vf = [int(m.jnt_dofadr[joint[n]]) for n in names]
    rng = np.random.default_rng(seed)
    forces = rng.normal(size=len(names))
    sim.set_axis_moments([forces[names.index(a)] for a in sim.axis_names])
    d.qfrc_applied[vf] = forces
    worst = 0.0
    for _ in range(states):
        d.qpos[:], d.qvel[:] = rng.uniform(-2.0, 2.0, m.nq), rng.normal(size=m.nv)
        for name, value in locked.items():
            d.qpos[m.jnt_qposadr[joint[name]]], d.qvel[m.jnt_dofadr[joint[name]]] = value, 0.0
        mujoco.mj_forward(m, d)
        M = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, M)
        qacc = np.linalg.solve(M[np.ix_(vf, vf)], (d.qfrc_passive - d.qfrc_bias + d.qfrc_applied)[vf])
        y = initial_state(model)
        y[model.i_phi], y[model.i_vel] = d.qpos[qf], d.qvel[vf]
        udot = sim.held_rhs()(0.0, y)[model.i_vel]
        assert np.max(np.abs(qacc)) > 0.0
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


def moves_as_in_mujoco(path: Path, locked: tuple[str, ...], forces: dict[str, float]) -> tuple[float, float]:
    """The largest difference of the joints' positions and velocities from MuJoCo's (RK4 at
    1e-4 s on the file with the `locked` joints deleted) over 2 s under constant `forces` by
    joint, and how far MuJoCo's joints moved."""
    model = None
    if locked:  # the judge: the locked joints deleted, with the actuators that drive them
        spec = mujoco.MjSpec.from_file(str(path))
        for actuator in [a for a in spec.actuators if a.target in locked]:
            spec.delete(actuator)
        for name in locked:
            spec.delete(spec.joint(name))
        model = spec.compile()
    mj_out = mujoco_run(path, {}, forces, INSTANTS, model=model)
    gs_out = gyro_run(load_scene(path, lock=list(locked)), forces, INSTANTS)
    worst = moved = 0.0
    for (m, d), (_, position, velocity) in zip(mj_out, gs_out):
        for j in range(m.njnt):
            name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j)
            worst = max(worst, abs(position[name] - d.qpos[m.jnt_qposadr[j]]),
                        abs(velocity[name] - d.qvel[m.jnt_dofadr[j]]))
        moved = max(moved, float(np.max(np.abs(d.qpos - mj_out[0][1].qpos))))
    return worst, moved


@pytest.mark.slow
def test_a_universal_joint_moves_as_in_mujoco(tmp_path):
    worst, moved = moves_as_in_mujoco(write(tmp_path, "universal.xml", UNIVERSAL), (),
                                      {"ux": 0.3, "uy": -0.2, "tipj": 0.1})
    print(f"universal joint: angles and rates within {worst:.2g} of MuJoCo's over 2 s (moved {moved:.2g} rad)")
    assert worst <= MULTIJOINT_AGREEMENT and moved > 0.1


@pytest.mark.parametrize("locked", [{"ux": 0.3}, {"uy": 0.7}, {"uz": -0.4}, {"ux": 0.2, "uz": 1.1},
                                    {"uy": 0.3, "uz": 1.1}, {"ux": 0.2, "uy": -0.5}])
def test_any_joint_of_a_body_is_locked_as_mujoco_holds_it(locked, tmp_path):
    """Three hinges in one body, one or two locked at a value wherever they sit in the order."""
    worst = held_accelerations(write(tmp_path, "gimbal.xml", THREE), locked)
    print(f"three hinges in one body, {', '.join(locked)} locked: accelerations within {worst:.2g} (relative)")
    assert worst <= QACC_RTOL


def test_a_massless_frame_turning_about_its_childs_axis_is_refused_naming_it(tmp_path):
    coaxial = UNIVERSAL.replace('pos="0.03 -0.01 0.05" axis="0 1 0"', 'pos="0.01 0.02 0.05" axis="1 0 0.2"')
    path = write(tmp_path, "coaxial.xml", coaxial)
    with pytest.raises(SceneError) as info, pytest.warns(UserWarning):  # MuJoCo's: its inertia is singular
        load_scene(path)
    assert info.value.errors == [
        f"{path}: body 'rod' (hinge joint 'ux', a massless frame): mass: 0 (a massless frame), and what it "
        "carries has no inertia about its hinge axis at the initial state: its joint's acceleration is "
        "undetermined; give it a mass, or give what it carries that inertia"]


@pytest.mark.parametrize("name", list(PLANAR))
def test_gymnasiums_planar_models_accelerate_as_in_mujoco(name):
    path, locked, bodies, _ = PLANAR[name]
    assert [b.name for b in load_scene(path, lock=list(locked)).bodies] == bodies
    worst = held_accelerations(path, dict.fromkeys(locked, 0.0))
    print(f"{name}: accelerations within {worst:.2g} (relative) of MuJoCo's")
    assert worst <= QACC_RTOL


@pytest.mark.slow
@pytest.mark.parametrize("name", list(PLANAR))
def test_gymnasiums_planar_models_move_as_in_mujoco(name):
    path, locked, _, forces = PLANAR[name]
    worst, moved = moves_as_in_mujoco(path, locked, forces)
    print(f"{name}: positions and velocities within {worst:.2g} of MuJoCo's over 2 s (moved {moved:.2g})")
    assert worst <= MULTIJOINT_AGREEMENT and moved > 0.1


def test_unnamed_joints_of_a_body_take_names_that_collide_with_none(tmp_path):
    text = UNIVERSAL.replace('<joint name="ux" ', "<joint ").replace('<joint name="uy" ', "<joint ")
    text = text.replace('<body name="tip"', '<body name="rod_joint0"').replace("<keyframe>", "<!--").replace(
        "</keyframe>", "-->")
    imported = import_model(write(tmp_path, "unnamed.xml", text))
    assert [n for _, n in imported.names] == ["rod_joint0_", "rod_joint1", "tipj"]
    load_scene(write(tmp_path, "unnamed.xml", text))  # and they load


def test_a_reference_angle_or_position_is_where_the_file_draws_the_body():
    """A joint's ref (the finger's proximal at -90 degrees, the hopper's rootz at 1.25 m) is its
    qpos at rest: the scene's coordinate is MuJoCo's qpos, and the finger (its spinner locked)
    accelerates as MuJoCo's from random states."""
    finger = GYMNASIUM.parent / "dm_control" / "finger.xml"
    scene = load_scene(finger, lock=["hinge"])
    assert scene.bodies[0].initial.angle == pytest.approx(-np.pi / 2, abs=1e-12)
    assert load_scene(GYMNASIUM / "hopper.xml").bodies[1].initial.position == 1.25
    worst = held_accelerations(finger, {"hinge": 0.0})
    print(f"finger, spinner locked: accelerations within {worst:.2g} (relative) of MuJoCo's")
    assert worst <= QACC_RTOL


@pytest.mark.parametrize("locked", [{"rooty": 0.3}, {"rootz": 1.0}, {"rootx": 0.4, "rooty": -0.7},
                                    {"rootx": 0.4, "rootz": 0.9}])
def test_any_joint_of_the_hoppers_planar_root_is_locked_as_mujoco_holds_it(locked):
    """Slides and a hinge in one body: the hinge locked turns the slides before it back (their
    axes stay the world's), a slide locked moves the body along its axis (rootz from its ref)."""
    worst = held_accelerations(GYMNASIUM / "hopper.xml", locked)
    print(f"hopper, {', '.join(locked)} locked: accelerations within {worst:.2g} (relative)")
    assert worst <= QACC_RTOL


@pytest.mark.parametrize("model, bodies", [("universal", ["rod", "tip"]), ("hopper", ["torso", "foot"])])
def test_imus_on_a_body_with_several_joints_read_as_mujocos_sensors(model, bodies, tmp_path):
    """A site on a body with several joints rides its last frame: gyro, accelerometer,
    orientation and world-frame acceleration as MuJoCo's sensors at random keyframes."""
    source = write(tmp_path, "universal.xml", UNIVERSAL) if model == "universal" else GYMNASIUM / "hopper.xml"
    path = with_imu_sites(source, bodies, np.random.default_rng(5), tmp_path)
    sites = [f"imu_{b}" for b in bodies]
    for key in ("probe0", "probe1"):
        ctrl = np.zeros(mujoco.MjModel.from_xml_path(str(path)).nu)
        worst = deviation(mujoco_readings(path, ctrl, key=key), gyro_readings(path, key, ctrl), sites)
        assert worst <= READING_RTOL, (key, worst)
