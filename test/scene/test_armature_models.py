"""Published models with armature and dampers on their hinges, against MuJoCo (docs/models.md,
"Armature and joint springs"): Gymnasium 1.4.0's reacher and pusher (v5) and its inverted
double pendulum (test/scene/models/gymnasium/, MIT), and the refusal of dm_control's fish,
whose joints are driven by position servos (test/scene/models/dm_control/, Apache-2.0).

The files are kept as published. The reacher's target and the pusher's object and goal sit
on two slide joints each: the judged copy has those joints taken out of its text (`judged`), so
that the bodies stand still as part of the base (--lock welds them as well:
test/scene/test_model_multijoint.py); everything else (armature, damping, inertias from the geoms, motors) is
the file's. The pendulum's cart slider is welded with --lock at the keyframe the copy is given
(unlocked, it is judged in test/scene/test_slide_models.py).
Two judges: MuJoCo's forward dynamics (qacc of mj_forward, contacts and constraints off) at
random states, which must agree with gyro_sim's accelerations to QACC_RTOL relative, and a
motion from the keyframe under gravity and a constant moment on every hinge, which must agree
to AGREEMENT over 0.5 s (MuJoCo's RK4 at MUJOCO_STEP is the larger error there).
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco", reason="MuJoCo is the optional extra [models]")

from gyro_sim import Simulator
from gyro_sim.dynamics.model import initial_state
from gyro_sim.scene.load import SceneError, load_scene
from gyro_sim.scene.mjcf import caught_warnings, import_model
from test.scene.test_model_import import AGREEMENT, MUJOCO_STEP

MODELS = Path(__file__).parent / "models"
REACHER = MODELS / "gymnasium" / "reacher.xml"
PUSHER = MODELS / "gymnasium" / "pusher_v5.xml"
PENDULUM = MODELS / "gymnasium" / "inverted_double_pendulum.xml"
FISH = MODELS / "dm_control" / "fish.xml"
#: agreement of the accelerations with MuJoCo's at one state, relative to their largest
QACC_RTOL = 1e-9
#: the generalised force on every hinge in the motion judged (N m)
FORCE = 0.5


class Judged:
    """A published file as judged: the joints taken out of its text (`removed`), the joints
    locked (`locked`: name -> the value in the keyframe), the armature of every hinge left, and
    the keyframe written into the copy (qpos, qvel, the locked joints included)."""

    def __init__(self, path, removed, locked, armature, qpos, qvel):
        self.path, self.removed, self.locked, self.armature = path, removed, locked, armature
        self.qpos, self.qvel = qpos, qvel


CASES = {
    "reacher": Judged(REACHER, ("target_x", "target_y"), {}, 1.0, "0.7 -1.9", "1.5 -2"),
    "pusher": Judged(PUSHER, ("obj_slidey", "obj_slidex", "goal_slidey", "goal_slidex"), {}, 0.04,
                     "0.3 0.4 -0.6 -1.2 0.8 -0.5 1.1", "0.5 -0.4 1 0.8 -1.5 2 -1"),
    "inverted double pendulum, cart locked": Judged(PENDULUM, (), {"slider": 0.2}, 0.0,
                                                    "0.2 0.4 -0.7", "0 1.2 -0.8"),
}


def judged(case: Judged, tmp_path: Path) -> Path:
    """The copy judged: `case.removed` joints out of the text, and the case's keyframe."""
    text = case.path.read_text()
    for name in case.removed:
        text, found = re.subn(rf'\s*<joint [^>]*name="{name}"[^>]*/>', "", text)
        assert found == 1, name
    key = f'<keyframe><key name="judged" qpos="{case.qpos}" qvel="{case.qvel}"/></keyframe>'
    text = text.replace("</mujoco>", key + "\n</mujoco>")
    out = tmp_path / case.path.name
    out.write_text(text)
    return out


def mujoco_model(path: Path, locked: dict[str, float]):
    """MuJoCo's model of the file with the `locked` slide joints welded at their values (their
    bodies moved there, then the joints deleted), equalities, tendons, actuators (at ctrl 0 the
    motors judged push nothing), sensors, meshes and keyframes removed, contacts and constraints
    off; and the first keyframe's qpos and qvel without the locked joints' entries."""
    with caught_warnings(mujoco):
        spec = mujoco.MjSpec.from_file(str(path))
    key = ((np.asarray(spec.keys[0].qpos, dtype=float), np.asarray(spec.keys[0].qvel, dtype=float))
           if len(spec.keys) else None)
    for element in (list(spec.equalities) + list(spec.tendons) + list(spec.actuators) + list(spec.sensors)
                    + list(spec.keys)):
        spec.delete(element)
    for mesh in list(spec.meshes):
        for geom in [g for g in spec.geoms if g.meshname == mesh.name]:
            spec.delete(geom)
        spec.delete(mesh)
    with caught_warnings(mujoco):
        full = spec.compile()
    drop = []
    for name, value in locked.items():
        joint = spec.joint(name)
        assert joint.type == mujoco.mjtJoint.mjJNT_SLIDE  # moved along its axis
        body = joint.parent
        R = np.zeros(9)
        mujoco.mju_quat2Mat(R, np.asarray(body.quat, dtype=float) / np.linalg.norm(body.quat))
        axis = np.asarray(joint.axis) / np.linalg.norm(joint.axis)
        body.pos = np.asarray(body.pos) + R.reshape(3, 3) @ (value * axis)
        drop.append(int(full.jnt_qposadr[mujoco.mj_name2id(full, mujoco.mjtObj.mjOBJ_JOINT, name)]))
        spec.delete(joint)
    with caught_warnings(mujoco):
        m = spec.compile()
    m.opt.integrator = mujoco.mjtIntegrator.mjINT_RK4
    m.opt.timestep = MUJOCO_STEP
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT) | int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    return m, (None if key is None else tuple(np.delete(k, drop) for k in key))


@pytest.mark.parametrize("name", list(CASES))
def test_a_model_with_armature_accelerates_as_in_mujoco(name, tmp_path):
    case = CASES[name]
    copy = judged(case, tmp_path)
    lock = list(case.locked)  # welded at the keyframe's position
    joints = [b["joint"] for b in import_model(copy, lock=lock).mapping["bodies"]]
    assert all(j["type"] == "hinge" and j.get("armature", 0.0) == case.armature
               and j["friction"]["viscous"] > 0.0 for j in joints), joints
    scene = load_scene(copy, lock=lock)
    m, _ = mujoco_model(copy, case.locked)
    assert m.nv == len(scene.bodies)  # every joint a hinge of the chain, in MuJoCo's order
    sim = Simulator(scene, backend="numpy")
    model = sim.model
    d = mujoco.MjData(m)
    rng = np.random.default_rng(1)
    worst = 0.0
    for _ in range(5):
        d.qpos[:] = rng.uniform(-1.5, 1.5, m.nq)
        d.qvel[:] = rng.normal(size=m.nv)
        mujoco.mj_forward(m, d)
        y = initial_state(model)
        y[model.i_phi], y[model.i_vel] = d.qpos, d.qvel
        udot = sim.held_rhs()(0.0, y)[model.i_vel]
        worst = max(worst, float(np.max(np.abs(udot - d.qacc)) / np.max(np.abs(d.qacc))))
    print(f"{name}: accelerations within {worst:.2g} (relative) of MuJoCo's")
    assert worst <= QACC_RTOL


@pytest.mark.parametrize("name", list(CASES))
def test_a_model_with_armature_moves_as_in_mujoco(name, tmp_path):
    case = CASES[name]
    copy = judged(case, tmp_path)
    scene = load_scene(copy, lock=list(case.locked))
    m, (qpos, qvel) = mujoco_model(copy, case.locked)
    d = mujoco.MjData(m)
    d.qpos[:], d.qvel[:] = qpos, qvel
    d.qfrc_applied[:] = FORCE
    sim = Simulator(scene, integrator="dop853", rtol=1e-12, atol=1e-12, backend="numpy")
    assert np.allclose(sim.joint_states().position, qpos) and np.allclose(sim.joint_states().velocity, qvel)
    sim.set_axis_moments([FORCE] * len(sim.axis_names))
    worst = moved = 0.0
    for t in np.linspace(0.0, 0.5, 6):
        n = int(round((t - d.time) / MUJOCO_STEP))
        if n:
            mujoco.mj_step(m, d, nstep=n)
        if d.time > sim.time:
            sim.advance(d.time - sim.time)
        q = np.asarray(sim.joint_states().position)
        worst = max(worst, float(np.max(np.abs(q - d.qpos))))
        moved = max(moved, float(np.max(np.abs(d.qpos - qpos))))
    print(f"{name}: hinge angles within {worst:.2g} rad of MuJoCo over 0.5 s (moved {moved:.2g} rad)")
    assert worst < AGREEMENT and moved > 0.01


def test_as_published_the_fish_is_refused_for_what_it_needs_not_for_its_servos():
    """dm_control's fish: its position actuators are the hinges' servos now; the one refusal
    names what the fish still needs (fluid forces, tendons) and, of its actuators,
    only the one on a tendon."""
    with pytest.raises(SceneError) as info:
        load_scene(FISH)
    errors = info.value.errors
    named = {re.search(r"actuator '([^']+)'", e).group(1) for e in errors if "actuator '" in e}
    assert named == {"fins_flap"}, errors
    assert any("density and viscosity" in e for e in errors)
