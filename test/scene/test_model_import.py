"""MJCF and URDF models as scenes (gyro_sim.scene.mjcf, docs/models.md).

The independent judge is MuJoCo simulating the same file: RK4 at 1e-4 s with contacts and
constraints disabled, against gyro_sim's dop853 at rtol 1e-12, under the same constant
commands; the world positions of every body's centre of mass, the hinge angles and the wheel
rates must agree to AGREEMENT over 2 s. The names expected below are the rule of
docs/models.md (a hinge and a rotor take their joint's name, a ball or free body its body's),
the gears and commands are the files' own. A second judge is the inverse mapping of
gyro_sim.bench.peers (a scene written as MJCF): a scene exported there and imported here must
come back the same.
"""
from __future__ import annotations

import copy
import re
import sys
from pathlib import Path

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco", reason="MuJoCo is the optional extra [models]")

from gyro_sim import Simulator
from gyro_sim.cli import main
from gyro_sim.dynamics.model import compile_model, initial_state
from gyro_sim.paths import find_scene, shipped_models
from gyro_sim.scene.load import SceneError, load_scene, parse_yaml
from gyro_sim.scene.mjcf import ModelError, import_model
from test.dynamics.chains import random_chain

#: largest difference allowed between MuJoCo and gyro_sim on the same file (m, rad, rad/s)
AGREEMENT = 1e-7
#: MuJoCo's step, and gyro_sim's tolerances, for the comparison
MUJOCO_STEP = 1e-4
RTOL = ATOL = 1e-12
#: simulated seconds compared, and the instants compared at
HORIZON = 2.0
INSTANTS = np.linspace(0.0, HORIZON, 9)
#: a hinge angle that changes by more than this over the horizon has moved (rad)
MOVES = 0.05

ARM = find_scene("arm_flywheel.xml")
SATELLITE = find_scene("satellite_wheels.xml")

#: (c): a URDF arm on a fixed stand, two revolute joints with limits, a flange on a fixed joint
#: (MuJoCo fuses it into the forearm) and a symmetric wheel on a continuous joint
ARM_URDF = """<?xml version="1.0"?>
<robot name="arm_wheel">
  <link name="base_link">
    <inertial><mass value="3.0"/><inertia ixx="0.02" iyy="0.02" izz="0.02" ixy="0" ixz="0" iyz="0"/></inertial>
  </link>
  <joint name="shoulder" type="revolute">
    <parent link="base_link"/><child link="upper"/>
    <origin xyz="0 0 0.8" rpy="0.3 0.2 0.1"/>
    <axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" effort="20" velocity="5"/>
  </joint>
  <link name="upper">
    <inertial>
      <origin xyz="0.12 0.01 0.02" rpy="0 0.1 0"/>
      <mass value="1.2"/>
      <inertia ixx="1e-3" iyy="6e-3" izz="6.2e-3" ixy="1e-4" ixz="0" iyz="-5e-5"/>
    </inertial>
  </link>
  <joint name="elbow" type="revolute">
    <parent link="upper"/><child link="fore"/>
    <origin xyz="0.25 0 0" rpy="0 0 0.4"/>
    <axis xyz="0 1 0"/>
    <limit lower="-2.5" upper="2.5" effort="10" velocity="5"/>
  </joint>
  <link name="fore">
    <inertial>
      <origin xyz="0.1 0 -0.01"/>
      <mass value="0.7"/>
      <inertia ixx="4e-4" iyy="2.6e-3" izz="2.7e-3" ixy="0" ixz="2e-5" iyz="0"/>
    </inertial>
  </link>
  <joint name="flange" type="fixed">
    <parent link="fore"/><child link="flange_link"/>
    <origin xyz="0.2 0 0" rpy="0 0.5 0"/>
  </joint>
  <link name="flange_link">
    <inertial><origin xyz="0.01 0 0"/><mass value="0.1"/>
      <inertia ixx="1e-5" iyy="1e-5" izz="1e-5" ixy="0" ixz="0" iyz="0"/></inertial>
  </link>
  <joint name="wheel" type="continuous">
    <parent link="fore"/><child link="wheel_link"/>
    <origin xyz="0.22 0 0" rpy="0 1.5707963267948966 0"/>
    <axis xyz="0 0 1"/>
  </joint>
  <link name="wheel_link">
    <inertial><origin xyz="0 0 0.01"/><mass value="0.3"/>
      <inertia ixx="1.5e-4" iyy="1.5e-4" izz="2.8e-4" ixy="0" ixz="0" iyz="0"/></inertial>
  </link>
</robot>
"""


def write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


# ------------------------------------------------------------------------------ the judges
def mujoco_run(path: Path | None, ctrl: dict[str, float], forces: dict[str, float], instants,
               model=None) -> list:
    """MuJoCo on the file itself (or on `model`, compiled from it) from its first keyframe (or
    qpos0 at rest): RK4 at MUJOCO_STEP, contacts and constraints off, constant ctrl (by
    actuator) and generalised forces (by joint). Per instant: (model, data copy)."""
    m = mujoco.MjSpec.from_file(str(path)).compile() if model is None else model
    m.opt.integrator = mujoco.mjtIntegrator.mjINT_RK4
    m.opt.timestep = MUJOCO_STEP
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT) | int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    d = mujoco.MjData(m)
    if m.nkey:
        mujoco.mj_resetDataKeyframe(m, d, 0)
    for name, u in ctrl.items():
        d.ctrl[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, name)] = u
    for name, f in forces.items():
        d.qfrc_applied[m.jnt_dofadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)]] = f
    out = []
    for t in instants:
        n = int(round((t - d.time) / MUJOCO_STEP))
        if n:
            mujoco.mj_step(m, d, nstep=n)
        mujoco.mj_forward(m, d)
        out.append((m, copy.copy(d)))
    return out


def gyro_run(scene, moments: dict[str, float], instants) -> list:
    """gyro_sim (dop853, RTOL, numpy backend) from the scene's initial state with constant axis
    moments (by axis name). Per instant: (body states by name, joint positions, velocities)."""
    sim = Simulator(scene, integrator="dop853", rtol=RTOL, atol=ATOL, backend="numpy")
    assert set(moments) <= set(sim.axis_names)
    sim.set_axis_moments([moments.get(a, 0.0) for a in sim.axis_names])
    out = []
    for t in instants:
        if t > sim.time:
            sim.advance(t - sim.time)
        js = sim.joint_states()
        out.append(({b.name: b for b in sim.body_states()}, dict(zip(js.name, js.position)),
                    dict(zip(js.name, js.velocity))))
    return out


def deviations(scene, mj_out, gs_out, bodies, rotors, hinges) -> dict[str, float]:
    """Largest differences over the instants: centres of mass (bodies: gyro_sim body -> the
    MuJoCo bodies it is made of; rotors: MuJoCo body -> (carrier, rotor)), hinge angles and
    wheel rates (by joint name)."""
    worst = dict.fromkeys(("centre of mass", "hinge angle", "wheel rate"), 0.0)
    records = {b.name: b for b in scene.bodies}
    for (m, d), (states, position, velocity) in zip(mj_out, gs_out):
        def body(name):
            return mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name)

        def joint(name):
            return mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)

        centres = []
        for gs_name, mj_names in bodies.items():
            s = states[gs_name]
            ids = [body(n) for n in mj_names]
            mj_com = sum(m.body_mass[i] * d.xipos[i] for i in ids) / sum(m.body_mass[i] for i in ids)
            centres.append((s.position + s.rotation @ records[gs_name].com, mj_com))
        for mj_name, (carrier, rotor) in rotors.items():
            s = states[carrier]
            r = next(r for r in records[carrier].rotors if r.name == rotor)
            centres.append((s.position + s.rotation @ r.position, d.xipos[body(mj_name)]))
            rate = velocity[rotor] - d.qvel[m.jnt_dofadr[joint(rotor)]]
            worst["wheel rate"] = max(worst["wheel rate"], abs(rate))
        for a, b in centres:
            worst["centre of mass"] = max(worst["centre of mass"], float(np.max(np.abs(a - b))))
        for h in hinges:
            angle = position[h] - d.qpos[m.jnt_qposadr[joint(h)]]
            worst["hinge angle"] = max(worst["hinge angle"], abs(angle))
    return worst


# ------------------------------------------------------------------- (a), (b), (c) in MuJoCo
#: per model: MuJoCo ctrl by actuator, gear x gain of each actuator (the files' own), forces
#: by joint (URDF: no actuators), and what is compared
CASES = {
    "arm_flywheel": dict(
        ctrl={"elbow_motor": 0.1, "spin_motor": 0.02},
        gear={"elbow_motor": ("elbow", 2.0), "spin_motor": ("spin", 0.5)},
        forces={}, bodies={"upper": ["upper"], "elbow": ["fore"], "hand": ["hand", "tool"]},
        rotors={"flywheel": ("elbow", "spin")}, hinges=["elbow"]),
    "satellite_wheels": dict(
        ctrl={"wx_motor": 0.01, "wy_motor": -0.02, "wz_motor": 0.015, "deploy_motor": 0.05},
        gear={"wx_motor": ("wx", 1.0), "wy_motor": ("wy", 1.0), "wz_motor": ("wz", 1.0),
              "deploy_motor": ("deploy", 3.0)},
        forces={}, bodies={"bus": ["bus"], "deploy": ["panel"]},
        rotors={"wheel_x": ("bus", "wx"), "wheel_y": ("bus", "wy"), "wheel_z": ("bus", "wz")}, hinges=["deploy"]),
    "arm_wheel_urdf": dict(
        ctrl={}, gear={}, forces={"shoulder": 0.3, "elbow": -0.2, "wheel": 0.01},
        bodies={"shoulder": ["upper"], "elbow": ["fore"]},
        rotors={"wheel_link": ("elbow", "wheel")}, hinges=["shoulder", "elbow"]),
}


def case_path(name: str, tmp_path: Path) -> Path:
    return {"arm_flywheel": ARM, "satellite_wheels": SATELLITE}.get(name) or write(tmp_path, "arm_wheel.urdf", ARM_URDF)


@pytest.mark.parametrize("name", list(CASES))
@pytest.mark.slow
def test_the_model_moves_as_in_mujoco(name, tmp_path):
    case = CASES[name]
    path = case_path(name, tmp_path)
    scene = load_scene(path)
    moments = {axis: gear * case["ctrl"][actuator] for actuator, (axis, gear) in case["gear"].items()}
    moments.update(case["forces"])
    mj_out = mujoco_run(path, case["ctrl"], case["forces"], INSTANTS)
    gs_out = gyro_run(scene, moments, INSTANTS)
    worst = deviations(scene, mj_out, gs_out, case["bodies"], case["rotors"], case["hinges"])
    print(f"{name}: largest deviation from MuJoCo over {HORIZON:g} s: "
          + ", ".join(f"{k} {v:.2e}" for k, v in worst.items()))
    assert max(worst.values()) <= AGREEMENT, worst
    # the motion is no trivial one: every hinge turns by far more than the agreement asked
    for h in case["hinges"]:
        assert abs(gs_out[-1][1][h] - gs_out[0][1][h]) > MOVES


def test_the_commands_map_through_the_gear():
    """A motor's ctrl u is the axis moment gear x gain x u: the importer says so per actuator."""
    imported = import_model(ARM)
    assert {(c.actuator, c.axis, c.factor) for c in imported.commands} == {
        ("elbow_motor", "elbow", 2.0), ("spin_motor", "spin", 0.5)}


def test_names_and_structure_follow_the_documented_rule(tmp_path):
    arm = load_scene(ARM)
    assert [(b.name, b.joint.type, [r.name for r in b.rotors]) for b in arm.bodies] == [
        ("upper", "spherical", []), ("elbow", "hinge", ["spin"]), ("hand", "spherical", [])]
    assert arm.base.type == "fixed" and arm.gravity is not None
    sat = load_scene(SATELLITE)
    assert sat.base.type == "free" and sat.gravity is None
    assert [(b.name, [r.name for r in b.rotors]) for b in sat.bodies] == [("bus", ["wx", "wy", "wz"]), ("deploy", [])]
    assert all(r.mode == "torque" and r.actuated for r in sat.bodies[0].rotors)
    urdf = load_scene(write(tmp_path, "arm.urdf", ARM_URDF))
    assert [b.name for b in urdf.bodies] == ["shoulder", "elbow"]
    assert urdf.bodies[1].rotors[0].actuated  # URDF: every revolute or continuous joint is commanded
    assert Simulator(urdf, backend="numpy").axis_names == ["shoulder", "elbow", "wheel"]
    named_xml = ARM_URDF.replace("<robot", "<!-- a URDF named .xml -->\n<robot", 1)
    as_xml = import_model(write(tmp_path, "arm.xml", named_xml))
    assert as_xml.kind == "URDF" and as_xml.mapping["bodies"][1]["rotors"][0]["actuated"]


def test_shipped_models_are_found_by_name_from_anywhere(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert {p.name for p in shipped_models()} >= {"arm_flywheel.xml", "satellite_wheels.xml"}
    assert load_scene("arm_flywheel.xml").path == str(ARM)
    with pytest.raises(SceneError, match=r"model 'robot.urdf' not found \(shipped models: arm_flywheel.xml, "):
        load_scene("robot.urdf")
    own = write(tmp_path, "arm_flywheel.xml", SATELLITE.read_text())  # a file here wins
    assert load_scene("arm_flywheel.xml").path == "arm_flywheel.xml" and own.is_file()
    assert load_scene("arm_flywheel.xml").base.type == "free"


def test_welded_and_static_bodies(tmp_path):
    """A body without a joint is part of its parent: the hand carries the tool's mass, the stand
    is part of the base."""
    m = mujoco.MjModel.from_xml_path(str(ARM))
    hand_tool = sum(m.body_mass[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, n)] for n in ("hand", "tool"))
    assert load_scene(ARM).bodies[2].mass == pytest.approx(hand_tool, rel=1e-14)
    notes = import_model(ARM).notes
    assert any("'tool'" in n and "merged" in n for n in notes)
    assert any("'stand'" in n for n in notes)


# ---------------------------------------------------------------------------- keyframes
def test_keyframes_choose_the_initial_state(tmp_path):
    text = ARM.read_text().replace(
        "</keyframe>", '  <key name="still" qpos="1 0 0 0  0.2  0  1 0 0 0"/>\n  </keyframe>')
    path = write(tmp_path, "arm.xml", text)
    first = load_scene(path)
    assert first.bodies[1].initial.angle == 0.6  # the first keyframe, "swing"
    still = load_scene(path, keyframe="still")
    assert still.bodies[1].initial.angle == 0.2 and still.bodies[1].initial.rate == 0.0
    assert still.bodies[1].rotors[0].spin == 0.0
    turned = write(tmp_path, "turned.xml", ARM.read_text().replace("0.6  0  0.7", "0.6  1.25  0.7"))
    assert "joint 'spin': the keyframe's angle 1.25 not kept" in " ".join(import_model(turned).notes)
    with pytest.raises(SceneError, match=r"keyframe 'nope': no such keyframe \(the model's: 'swing', 'still'\)"):
        load_scene(path, keyframe="nope")
    rest = write(tmp_path, "rest.xml", re.sub(r"<keyframe>.*</keyframe>", "", ARM.read_text(), flags=re.S))
    scene = load_scene(rest)  # no keyframe: the reference pose at rest
    assert scene.bodies[1].initial.angle == 0.0 and scene.bodies[1].rotors[0].spin == 0.0
    assert np.allclose(scene.bodies[0].initial.angular_velocity, 0.0)


def test_a_keyframe_for_a_yaml_scene_is_refused():
    with pytest.raises(SceneError, match="keyframe: only an MJCF or URDF model has keyframes"):
        load_scene("hinge_chain", keyframe="swing")


def test_free_joint_velocities_take_the_scene_conventions():
    """MuJoCo's free joint: qvel linear in the world frame, angular in the body frame; the scene:
    the velocity of O^1 in the world frame, the angular velocity in the body frame."""
    sat = load_scene(SATELLITE)
    assert list(sat.base.position) == [0.1, -0.2, 0.3]
    assert list(sat.base.velocity) == [0.05, 0.02, -0.01]
    assert list(sat.bodies[0].initial.quaternion) == pytest.approx([0.5, 0.5, -0.1, 0.7], abs=1e-15)
    assert list(sat.bodies[0].initial.angular_velocity) == pytest.approx([0.1, -0.2, 0.3], abs=1e-15)
    # a torque rotor's spin is absolute: p = w . e + kappa' (wheel_x: e = the bus's x axis)
    assert sat.bodies[0].rotors[0].spin == pytest.approx(0.1 + 50.0, abs=1e-13)


# --------------------------------------------------------------- the inverse mapping (peers)
def exported(scene_map: dict, tmp_path: Path) -> Path:
    """The scene written as MJCF by gyro_sim.bench.peers (names without their prefixes), with
    peers' own initial MuJoCo state as a keyframe."""
    from gyro_sim.bench.peers import MujocoChain, mjcf

    scene = load_scene(scene_map)
    chain = MujocoChain(scene, MUJOCO_STEP, "RK4")
    key = (f'  <keyframe><key name="start" qpos="{" ".join(map(repr, chain.d.qpos.tolist()))}" '
           f'qvel="{" ".join(map(repr, chain.d.qvel.tolist()))}"/></keyframe>\n</mujoco>')
    text = re.sub(r'name="(?:body|joint|rotor):', 'name="', mjcf(scene, MUJOCO_STEP, "RK4"))
    return write(tmp_path, "exported.xml", text.replace("</mujoco>", key))


@pytest.mark.parametrize("seed, base", [(1, "fixed"), (2, "fixed"), (3, "free"), (4, "free"), (5, "fixed")])
@pytest.mark.slow
def test_a_scene_exported_by_peers_comes_back_the_same(seed, base, tmp_path):
    scene_map = random_chain(seed, base=base, speed_rotors=False, gravity=base == "fixed")
    original = load_scene(scene_map)
    back = load_scene(exported(scene_map, tmp_path))
    assert [(b.name, b.joint.type) for b in back.bodies] == [(b.name, b.joint.type) for b in original.bodies]
    for a, b in zip(original.bodies, back.bodies):
        assert b.mass == pytest.approx(a.mass, rel=1e-13)
        assert np.allclose(b.com, a.com, rtol=1e-12, atol=1e-15)
        assert np.allclose(b.inertia, a.inertia, rtol=1e-10, atol=1e-14 * np.max(np.abs(a.inertia)))
        if a.joint.type == "hinge":
            assert np.allclose(b.joint.axis, a.joint.axis, atol=1e-14)
        if a.next_joint is not None:
            assert np.allclose(b.next_joint, a.next_joint, atol=1e-15)
        assert [r.name for r in b.rotors] == [r.name for r in a.rotors]
        for ra, rb in zip(a.rotors, b.rotors):
            assert np.allclose(rb.axis, ra.axis, atol=1e-14) and np.allclose(rb.position, ra.position, atol=1e-15)
            assert (rb.mass, rb.mode) == (ra.mass, ra.mode)
            assert rb.axial_inertia == pytest.approx(ra.axial_inertia, rel=1e-12)
            assert rb.transverse_inertia == pytest.approx(ra.transverse_inertia, rel=1e-12)
            assert rb.spin == pytest.approx(ra.spin, rel=1e-12, abs=1e-12)
    from gyro_sim.bench.peers import frames_of_state

    fa = frames_of_state(compile_model(original), 0.0, initial_state(compile_model(original)))
    fb = frames_of_state(compile_model(back), 0.0, initial_state(compile_model(back)))
    for x, y in ((fa.R, fb.R), (fa.w, fb.w), (fa.O1, fb.O1), (fa.v1, fb.v1)):
        assert np.allclose(x, y, atol=1e-12)
    # and the same motion
    moments = {}
    a_out = gyro_run(original, moments, [0.0, 0.3])
    b_out = gyro_run(back, moments, [0.0, 0.3])
    for name, state in a_out[-1][0].items():
        assert np.allclose(b_out[-1][0][name].position, state.position, atol=1e-9)
        assert np.allclose(b_out[-1][0][name].rotation, state.rotation, atol=1e-9)


# ------------------------------------------------------------------------- rotors or bodies
WHEEL = """<mujoco model="wheel">
  <compiler angle="radian"/>
  <worldbody>
    <body name="link" pos="0 0 1">
      <joint name="pivot" type="hinge" axis="1 0 0"/>
      <inertial pos="0 0 -0.1" mass="1" diaginertia="0.01 0.011 0.002"/>
      <body name="disc" pos="0 0 -0.2">
        <joint name="spin" type="hinge" axis="0 0 1"/>
        <inertial pos="{pos}" mass="0.2" diaginertia="{inertia}"/>
      </body>
      {more}
    </body>
  </worldbody>
</mujoco>
"""


def wheel(tmp_path, pos="0 0 0", inertia="2e-5 2e-5 4e-5", more="") -> Path:
    return write(tmp_path, "wheel.xml", WHEEL.format(pos=pos, inertia=inertia, more=more))


def test_a_symmetric_wheel_on_its_axis_is_a_rotor(tmp_path):
    scene = load_scene(wheel(tmp_path))
    assert [b.name for b in scene.bodies] == ["pivot"]
    assert scene.bodies[0].rotors[0].name == "spin"
    assert not scene.bodies[0].rotors[0].actuated  # no motor on it (MJCF)


@pytest.mark.parametrize("pos, inertia", [("1e-4 0 0", "2e-5 2e-5 4e-5"), ("0 0 0", "2e-5 2.1e-5 4e-5")])
def test_an_unbalanced_wheel_is_a_body_and_a_branch_beside_another(tmp_path, pos, inertia):
    """Off its axis or not symmetric about it, the wheel is a hinge body (exact all the same); with
    another moving child of its carrier, a branch of the tree (test/scene/test_model_trees.py)."""
    scene = load_scene(wheel(tmp_path, pos, inertia))
    assert [b.name for b in scene.bodies] == ["pivot", "spin"]
    more = ('<body name="other" pos="0 0.1 -0.2"><joint name="swing" type="hinge" axis="0 1 0"/>'
            '<inertial pos="0 0 -0.05" mass="0.1" diaginertia="1e-4 1e-4 1e-5"/></body>')
    bodies = import_model(wheel(tmp_path, pos, inertia, more)).mapping["bodies"]
    assert [(b["name"], b.get("parent")) for b in bodies] == [("pivot", None), ("spin", None), ("swing", "pivot")]
    balanced = import_model(wheel(tmp_path, more=more)).mapping["bodies"]  # a rotor is no branch
    assert [b["name"] for b in balanced] == ["pivot", "swing"] and balanced[0]["rotors"][0]["name"] == "spin"


# -------------------------------------------------------------------------------- refusals
BASE = """<mujoco model="bad">
  <compiler angle="radian"/>
  {option}
  <worldbody>
    <body name="link" pos="0 0 1" {body_attrs}>
      <joint name="pivot" type="hinge" axis="1 0 0" {joint_attrs}/>
      <inertial pos="0 0 -0.1" mass="1" diaginertia="0.01 0.011 0.002"/>
      <site name="tip" pos="0 0 -0.2"/>
      {inner}
    </body>
    {outer}
  </worldbody>
  {extra}
</mujoco>
"""
CHILD = ('<body name="{name}" pos="0 0 -0.2"><joint name="{joint}" type="{type}" {attrs}/>'
         '<inertial pos="0 0 -0.05" mass="0.1" diaginertia="1e-4 1.1e-4 1e-5"/></body>')


def bad(**parts) -> str:
    values = dict(option="", body_attrs="", joint_attrs="", inner="", outer="", extra="")
    values.update(parts)
    return BASE.format(**values)


#: one refused element each: (the model, the one error line's element and reason)
REFUSED = {
    "tendon": (bad(extra='<tendon><fixed name="cable"><joint joint="pivot" coef="1"/></fixed></tendon>'),
               "tendon 'cable': tendons are not supported"),
    "equality": (bad(inner=CHILD.format(name="arm", joint="elbow", type="hinge", attrs='axis="1 0 0"'),
                     extra='<equality><joint name="coupling" joint1="pivot" joint2="elbow"/></equality>'),
                 "equality 'coupling': equality constraints are not supported"),
    "spring on a ball joint": (bad(inner=CHILD.format(name="hand", joint="wrist", type="ball", attrs='stiffness="2"')),
                               "joint 'wrist': stiffness on a ball joint is not supported"),
    "nonlinear spring": (bad(joint_attrs='stiffness="2 0.5"'),
                         "joint 'pivot': stiffnesspoly (a nonlinear spring) is not supported"),
    "damping of a ball joint": (bad(inner=CHILD.format(name="hand", joint="wrist", type="ball", attrs='damping="0.1"')),
                                "joint 'wrist': damping on a ball joint is not supported"),
    "armature on a ball joint": (bad(inner=CHILD.format(name="hand", joint="wrist", type="ball",
                                                        attrs='armature="0.01"')),
                                 "joint 'wrist': armature on a ball joint is not supported"),
    "friction loss of a ball joint": (bad(inner=CHILD.format(name="hand", joint="wrist", type="ball",
                                                             attrs='frictionloss="0.1"')),
                                      "joint 'wrist': frictionloss on a ball joint is not supported"),
    "a ball joint with another in a body": (bad(inner='<joint name="roll" type="ball"/>'),
                                            "body 'link': 2 joints, a ball or free joint among them; several "
                                            "joints in one body are hinge and slide joints only"),
    "a free body beside another on the world": (
        bad(outer='<body name="other" pos="1 0 1"><joint name="o" type="ball"/>'
                  '<inertial pos="0 0 -0.1" mass="1" diaginertia="0.01 0.01 0.002"/></body>').replace(
            '<joint name="pivot" type="hinge" axis="1 0 0" />', '<freejoint name="pivot"/>'),
        "worldbody: 1 moving body hangs from the world ('other') beside the free body 'link': a free base "
        "carries the whole tree; weld them with --lock JOINT (their joints: 'o')"),
    "nothing moves": (bad().replace('<joint name="pivot" type="hinge" axis="1 0 0" />', ""),
                      "worldbody: no body has a joint: nothing moves"),
    "gravity compensation": (bad(body_attrs='gravcomp="1"'),
                             "body 'link': gravcomp (gravity compensation) is not supported"),
    "fluid forces": (bad(option='<option density="1.2"/>'),
                     "option: density and viscosity (fluid forces) are not supported"),
    "variable gain": (bad(extra='<actuator><general name="servo" joint="pivot" gaintype="affine" '
                                'gainprm="10 1"/></actuator>'),
                      "actuator 'servo': a variable gain or a muscle's bias is not supported"),
    "two servos on a hinge": (bad(extra='<actuator><position name="servo" joint="pivot" kp="10"/>'
                                        '<velocity name="damper" joint="pivot" kv="1"/></actuator>'),
                              "actuator 'damper': drives joint 'pivot', which another actuator drives "
                              "('servo'); one servo per hinge is supported"),
    "activation dynamics": (bad(extra='<actuator><general name="filtered" joint="pivot" dyntype="filter" '
                                      'dynprm="0.1"/></actuator>'),
                            "actuator 'filtered': activation dynamics are not supported"),
    "site transmission": (bad(extra='<actuator><motor name="thruster" site="tip" gear="0 0 1 0 0 0"/></actuator>'),
                          "actuator 'thruster': drives a site; actuators on hinge and slide joints are supported "
                          "(motors, position, velocity and affine general servos)"),
    "motor on a ball joint": (bad(inner=CHILD.format(name="hand", joint="wrist", type="ball", attrs=""),
                                  extra='<actuator><motor name="twist" joint="wrist" gear="0 0 1"/></actuator>'),
                              "actuator 'twist': drives the ball joint 'wrist'; only hinges and slides take a "
                              "commanded moment"),
    "a name no frame can have": (bad(inner=CHILD.format(name="hand", joint="wrist 1", type="hinge",
                                                        attrs='axis="1 0 0"')),
                                 "body 'hand' (hinge joint 'wrist 1'): name: must not contain whitespace"),
}


@pytest.mark.parametrize("what", list(REFUSED))
def test_what_gyro_sim_cannot_express_is_refused_in_one_line(what, tmp_path):
    text, expected = REFUSED[what]
    path = write(tmp_path, "bad.xml", text)
    mujoco.MjSpec.from_file(str(path)).compile()  # MuJoCo itself takes the model
    with pytest.raises(SceneError) as info:
        load_scene(path)
    (error,) = info.value.errors
    assert error.startswith(f"{path}: {expected}"), error
    assert "\n" not in error


URDF_JOINT = """<robot name="bad">
  <link name="base"/>
  <joint name="{name}" type="{type}">
    <parent link="base"/><child link="slider"/>
    <origin xyz="0 0 1"/><axis xyz="1 0 0"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/>
    {dynamics}
  </joint>
  <link name="slider">
    <inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>
  </link>
</robot>
"""


@pytest.mark.parametrize("dynamics, friction", [
    ("", None),
    ('<dynamics damping="0.2" friction="0.1"/>', {"coulomb": 0.1, "viscous": 0.2}),
])
def test_urdf_prismatic_joints_are_slides(tmp_path, dynamics, friction):
    """A prismatic joint is a slide along its axis, its damping and friction the slide's (N s/m, N)."""
    path = write(tmp_path, "rail.urdf", URDF_JOINT.format(name="rail", type="prismatic", dynamics=dynamics))
    (body,) = import_model(path).mapping["bodies"]
    assert body["name"] == "rail" and body["joint"]["type"] == "slide" and body["joint"]["axis"] == [1.0, 0.0, 0.0]
    assert body["joint"].get("friction") == friction
    assert body["initial"] == {"position": 0.0, "velocity": 0.0}
    assert len(load_scene(path).bodies) == 1


def test_a_scene_rule_broken_by_the_names_is_said_by_elements(tmp_path):
    """The scene's own checks run on the model's scene; their key paths become the elements."""
    text = bad(inner=CHILD.format(name="hand", joint="wrist", type="ball", attrs="")
               .replace("</body>", CHILD.format(name="finger", joint="hand_psi", type="hinge",
                                                attrs='axis="1 0 0"') + "</body>"))
    path = write(tmp_path, "names.xml", text)
    with pytest.raises(SceneError) as info:
        load_scene(path)
    (error,) = info.value.errors
    assert error == (f"{path}: body 'finger' (hinge joint 'hand_psi'): name: joint-state name 'hand_psi' is "
                     "also produced by body 'hand' (ball joint 'wrist') (a spherical joint publishes "
                     "<body>_psi, _theta, _phi)")


def test_the_refusals_come_before_anything_runs(tmp_path, capsys):
    path = write(tmp_path, "bad.xml", REFUSED["tendon"][0])
    assert main(["run", "--scene", str(path), "--duration", "1"]) == 2
    assert "tendon 'cable': tendons are not supported" in capsys.readouterr().err


def test_every_refusal_is_reported_at_once(tmp_path):
    path = write(tmp_path, "bad.xml", bad(inner=CHILD.format(name="hand", joint="wrist", type="ball",
                                                             attrs='stiffness="0.1" armature="0.01"'),
                                          extra='<tendon><fixed name="cable"><joint joint="pivot" coef="1"/>'
                                                '</fixed></tendon>'))
    with pytest.raises(SceneError) as info:
        load_scene(path)
    assert len(info.value.errors) == 3


@pytest.mark.parametrize("text, expected", [
    ("<mujoco><worldbody>", "MuJoCo cannot read it: XML parse error"),
    ("<mujoco><bogus/></mujoco>", "MuJoCo cannot read it: XML Error: Schema violation: unrecognized element"),
])
def test_a_file_mujoco_cannot_read(tmp_path, text, expected):
    path = write(tmp_path, "broken.xml", text)
    with pytest.raises(SceneError) as info:
        load_scene(path)
    (error,) = info.value.errors
    assert error.startswith(f"{path}: {expected}") and "\n" not in error


def test_a_missing_model_file(tmp_path):
    with pytest.raises(SceneError, match="absent.urdf: file not found"):
        load_scene(tmp_path / "absent.urdf")


def test_a_model_file_beyond_the_size_bound_is_refused_unread(tmp_path):
    from gyro_sim.scene.mjcf import MAX_MODEL_BYTES

    path = tmp_path / "huge.xml"
    with open(path, "wb") as stream:
        stream.truncate(MAX_MODEL_BYTES + 1)  # sparse: nothing is written
    with pytest.raises(SceneError, match=f"{MAX_MODEL_BYTES + 1} bytes, more than a model file holds"):
        load_scene(path)


def test_without_mujoco_the_error_names_the_extra(monkeypatch, tmp_path, capsys):
    monkeypatch.setitem(sys.modules, "mujoco", None)  # import mujoco raises ImportError
    with pytest.raises(ModelError,
                       match=r"needs mujoco, not installed; install it with: pip install 'gyro_sim\[models\]'"):
        import_model(ARM)
    with pytest.raises(SceneError, match=r"gyro_sim\[models\]"):
        load_scene(ARM)
    assert main(["import", str(ARM), "-o", str(tmp_path / "arm.yaml")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "pip install 'gyro_sim[models]'" in err, err
    assert not (tmp_path / "arm.yaml").exists()


# ----------------------------------------------------------------------------- what is left out
def test_contacts_limits_and_control_ranges_are_left_out_and_listed(tmp_path):
    path = write(tmp_path, "limited.xml", bad(joint_attrs='range="-1 1"', inner='<geom type="sphere" size="0.05"/>',
                                              extra='<actuator><motor name="m" joint="pivot" ctrlrange="-2 2" '
                                                    'forcerange="-3 3"/></actuator>'))
    notes = import_model(path).notes
    assert notes[0] == "contacts: ignored (no contacts in gyro_sim)"
    assert "joint 'pivot': limits [-1, 1] not enforced" in notes
    assert "actuator 'm': ctrlrange [-2, 2] not enforced" in notes
    assert "actuator 'm': forcerange [-3, 3] not enforced" in notes
    load_scene(path)


# ------------------------------------------------------------------------------- gyro-sim import
@pytest.mark.slow
def test_import_writes_a_scene_that_loads_and_moves_as_the_model(tmp_path, capsys):
    out = tmp_path / "arm.yaml"
    assert main(["import", str(ARM), "-o", str(out)]) == 0
    said = capsys.readouterr().out
    assert said.startswith(f"wrote {out}: scene 'arm_flywheel (MJCF arm_flywheel.xml)', 3 bodies, 1 rotors")
    text = out.read_text()
    assert text.startswith("# gyro_sim scene imported by gyro-sim import from arm_flywheel.xml (MJCF)")
    assert "#   elbow_motor -> axis elbow: moment = 2.0 x ctrl" in text
    from_yaml, from_model = load_scene(out), load_scene(ARM)
    assert from_yaml.source == from_model.source
    moments = {"elbow": 0.2, "spin": 0.01}
    a = gyro_run(from_yaml, moments, [0.0, 0.5])[-1]
    b = gyro_run(from_model, moments, [0.0, 0.5])[-1]
    assert a[1] == b[1] and a[2] == b[2]  # the same numbers: the same motion, bit for bit


def test_import_never_replaces_a_file_without_force(tmp_path, capsys):
    out = write(tmp_path, "scene.yaml", "precious\n")
    assert main(["import", str(ARM), "-o", str(out)]) == 2
    assert "exists; refused to overwrite it" in capsys.readouterr().err
    assert out.read_text() == "precious\n"
    assert main(["import", str(SATELLITE), "-o", str(out), "--force"]) == 0
    assert load_scene(out).base.type == "free"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.yaml"]  # no temporary left


def test_import_refuses_bad_input_with_exit_2(tmp_path, capsys):
    bad_model = write(tmp_path, "bad.xml", REFUSED["tendon"][0])
    assert main(["import", str(bad_model), "-o", str(tmp_path / "a.yaml")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"gyro-sim import: {bad_model}: tendon 'cable': tendons are not supported (a tree of "
                   "rigid bodies and rotors only); --lock its joints ('pivot') to weld them: the tendon goes with them"]
    assert main(["import", str(ARM), "-o", str(tmp_path / "b.yaml"), "--keyframe", "nope"]) == 2
    assert "keyframe 'nope': no such keyframe" in capsys.readouterr().err
    assert main(["import", "hinge_chain", "-o", str(tmp_path / "c.yaml")]) == 2
    assert "not an MJCF or URDF model" in capsys.readouterr().err
    assert main(["import", str(tmp_path / "none.xml"), "-o", str(tmp_path / "d.yaml")]) == 2
    assert "no such file" in capsys.readouterr().err
    assert main(["import", str(ARM), "-o", str(tmp_path / "no" / "dir.yaml")]) == 2
    assert "does not exist" in capsys.readouterr().err
    copy = write(tmp_path, "model.xml", ARM.read_text())
    assert main(["import", str(copy), "-o", str(copy), "--force"]) == 2  # never the model itself
    assert copy.read_text() == ARM.read_text()
    assert not list(tmp_path.glob("*.yaml"))


def test_a_write_that_fails_mid_way_exits_1_and_leaves_nothing(tmp_path, capsys, monkeypatch):
    import errno
    import os

    def full(*args):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "link", full)
    assert main(["import", str(ARM), "-o", str(tmp_path / "arm.yaml")]) == 1
    assert "cannot write (No space left on device)" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_the_written_yaml_reads_back_exactly(tmp_path):
    from gyro_sim.scene.mjcf import scene_yaml

    for path in (ARM, SATELLITE, write(tmp_path, "arm.urdf", ARM_URDF)):
        imported = import_model(path)
        assert parse_yaml(scene_yaml(imported)) == imported.mapping


def test_a_log_embeds_the_scene_of_a_model():
    """A run of a model records the scene mapping: re-simulating a log needs no model file."""
    from gyro_sim.log.mcap_log import scene_yaml as log_scene_yaml

    scene = load_scene(ARM)
    assert load_scene(parse_yaml(log_scene_yaml(scene))).source == scene.source


def test_the_node_takes_a_model_as_its_scene(tmp_path):
    from gyro_sim.ros.params import validate

    path = write(tmp_path, "arm.urdf", ARM_URDF)
    config = validate({"scene": str(path)})
    assert [b.name for b in config.scene.bodies] == ["shoulder", "elbow"]


def test_run_takes_a_keyframe(tmp_path, capsys, monkeypatch):
    """`gyro-sim run --scene MODEL --keyframe NAME` starts from that keyframe (recorded in the
    log's embedded scene); an unknown keyframe is exit 2 naming the model's keyframes."""
    from gyro_sim.log.mcap_log import read_info

    text = ARM.read_text().replace(
        "</keyframe>", '  <key name="still" qpos="1 0 0 0  0.2  0  1 0 0 0"/>\n  </keyframe>')
    path = write(tmp_path, "arm.xml", text)
    monkeypatch.chdir(tmp_path)
    assert main(["run", "--scene", str(path), "--keyframe", "still", "--duration", "0.01",
                 "--integrator", "rk4", "--record", "still.mcap"]) == 0
    info = read_info(tmp_path / "still.mcap")
    assert load_scene(info.scene_source()).bodies[1].initial.angle == 0.2
    capsys.readouterr()
    assert main(["run", "--scene", str(path), "--keyframe", "nope", "--duration", "0.01"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no such keyframe" in err[0] and "'still'" in err[0], err
