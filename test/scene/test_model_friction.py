"""A model's joint damping and dry friction, imported as the hinges' and rotors' `friction`
(docs/models.md, "Damping and friction").

Three independent judges: MuJoCo simulating the same file with its damper on (viscous damping
is a passive force there, exact), the closed form of a Coulomb- and viscous-braked wheel, and
MuJoCo's frictionloss while the joint slips (a soft constraint that applies exactly the
frictionloss while the speed is far from zero).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco", reason="MuJoCo is the optional extra [models]")

from gyro_sim import Simulator
from gyro_sim.simulator import SimulationError
from gyro_sim.scene.load import SceneError, load_scene
from gyro_sim.scene.mjcf import ModelError, import_model
from test.scene.test_public_models import mujoco_judge
from test.scene.test_model_import import (
    AGREEMENT,
    INSTANTS,
    deviations,
    gyro_run,
    mujoco_run,
    write,
)

INERTIA = '<inertia ixx="{a}" iyy="{b}" izz="{c}" ixy="0" ixz="0" iyz="0"/>'

#: a URDF double pendulum under gravity with damping on both joints, dry friction on the
#: first (MuJoCo's frictionloss: off with its constraints in the judge) and a damped wheel
PENDULUM_URDF = """<?xml version="1.0"?>
<robot name="damped_pendulum">
  <link name="base_link"/>
  <joint name="shoulder" type="revolute">
    <parent link="base_link"/><child link="upper"/>
    <origin xyz="0 0 1.0" rpy="0.1 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="10" velocity="10"/>
    <dynamics damping="0.05" friction="0.02"/>
  </joint>
  <link name="upper">
    <inertial><origin xyz="0.15 0 0.01"/><mass value="1.0"/>""" + INERTIA.format(a="1e-3", b="8e-3",
                                                                                  c="8.2e-3") + """</inertial>
  </link>
  <joint name="elbow" type="continuous">
    <parent link="upper"/><child link="fore"/>
    <origin xyz="0.3 0 0"/><axis xyz="0 1 0"/>
    <dynamics damping="0.02"/>
  </joint>
  <link name="fore">
    <inertial><origin xyz="0.12 0.01 0"/><mass value="0.6"/>""" + INERTIA.format(a="5e-4", b="3e-3",
                                                                                  c="3.1e-3") + """</inertial>
  </link>
  <joint name="wheel" type="continuous">
    <parent link="fore"/><child link="wheel_link"/>
    <origin xyz="0.25 0 0" rpy="1.5707963267948966 0 0"/><axis xyz="0 0 1"/>
    <dynamics damping="0.001"/>
  </joint>
  <link name="wheel_link">
    <inertial><mass value="0.2"/>""" + INERTIA.format(a="1e-4", b="1e-4", c="1.8e-4") + """</inertial>
  </link>
</robot>
"""

#: a wheel on a vertical hinge (gravity along the axis: no moment), inertia J about it, and its
#: start (rad/s): braked by 0.01 N m it slips 1.8 s to a tenth of it (the closed forms hold for
#: any start; a faster one only makes the numpy runs longer)
WHEEL_J, WHEEL_W0 = 0.02, 1.0
WHEEL_MJCF = """<mujoco model="braked_wheel">
  <option gravity="0 0 -9.81" integrator="RK4" timestep="1e-4"/>
  <worldbody>
    <body name="disc" pos="0 0 0.5">
      <joint name="spin" type="hinge" axis="0 0 1" damping="{viscous}" frictionloss="{coulomb}"/>
      <inertial pos="0 0 0" mass="2.0" diaginertia="0.011 0.011 {J}"/>
    </body>
  </worldbody>
  <keyframe><key name="spinning" qvel="{w0}"/></keyframe>
</mujoco>
"""


def test_damping_and_friction_become_the_axes_friction(tmp_path):
    scene = load_scene(write(tmp_path, "pendulum.urdf", PENDULUM_URDF))
    joints = {b.name: b.joint for b in scene.bodies}
    assert joints["shoulder"].limits.friction.viscous == 0.05
    assert joints["shoulder"].limits.friction.coulomb == 0.02
    assert joints["elbow"].limits.friction.viscous == 0.02
    assert joints["elbow"].limits.friction.coulomb == 0.0
    wheel = scene.bodies[1].rotors[0]
    assert wheel.name == "wheel" and wheel.limits.friction.viscous == 0.001


def test_a_damped_urdf_moves_as_in_mujoco_with_its_damper_on(tmp_path):
    """Viscous damping only (the frictionloss removed: MuJoCo's is a constraint, judged below):
    MuJoCo's passive damper against gyro_sim's hinge and rotor friction, to AGREEMENT."""
    path = write(tmp_path, "pendulum.urdf", PENDULUM_URDF.replace(' friction="0.02"', ""))
    scene = load_scene(path)
    forces = {"shoulder": 0.3, "elbow": -0.1, "wheel": 0.02}
    mj_out = mujoco_run(path, {}, forces, INSTANTS)
    gs_out = gyro_run(scene, forces, INSTANTS)
    worst = deviations(scene, mj_out, gs_out, bodies={"shoulder": ["upper"], "elbow": ["fore"]},
                       rotors={"wheel_link": ("elbow", "wheel")}, hinges=["shoulder", "elbow"])
    print("damped URDF pendulum vs MuJoCo:", {k: f"{v:.2g}" for k, v in worst.items()})
    assert max(worst.values()) < AGREEMENT, worst
    moved = abs(gs_out[-1][1]["shoulder"] - gs_out[0][1]["shoulder"])
    assert moved > 0.05  # the comparison is of a motion


def braked(w0: float, coulomb: float, viscous: float, t: np.ndarray, J: float = WHEEL_J):
    """The closed form of J w' = -coulomb - viscous w from w0 > 0 while w > 0: (rate, angle)."""
    if viscous == 0.0:
        return w0 - coulomb / J * t, w0 * t - 0.5 * coulomb / J * t * t
    k, w_inf = viscous / J, coulomb / viscous
    rate = (w0 + w_inf) * np.exp(-k * t) - w_inf
    angle = (w0 + w_inf) / k * (1.0 - np.exp(-k * t)) - w_inf * t
    return rate, angle


@pytest.mark.parametrize("coulomb, viscous", [(0.01, 0.0), (0.01, 0.004)])
def test_a_braked_wheel_follows_the_closed_form(coulomb, viscous, tmp_path):
    """A wheel slowed by its frictionloss (and damping), gyro_sim against the closed form, until
    its speed is a tenth of the start: rate and angle to 1e-9."""
    w0 = WHEEL_W0
    path = write(tmp_path, "wheel.xml", WHEEL_MJCF.format(viscous=viscous, coulomb=coulomb, J=WHEEL_J, w0=w0))
    sim = Simulator(load_scene(path), integrator="dop853", rtol=1e-12, atol=1e-12, backend="numpy")
    stop = braked_until(w0, coulomb, viscous, 0.1 * w0)
    for t in np.linspace(0.0, stop, 6)[1:]:
        sim.advance(t - sim.time)
        js = sim.joint_states()
        rate, angle = braked(w0, coulomb, viscous, np.array(t))
        assert abs(js.velocity[0] - rate) < 1e-9 and abs(js.position[0] - angle) < 1e-9


def braked_until(w0: float, coulomb: float, viscous: float, w: float, J: float = WHEEL_J) -> float:
    """When the braked wheel's rate falls to `w`."""
    if viscous == 0.0:
        return (w0 - w) * J / coulomb
    w_inf = coulomb / viscous
    return J / viscous * math.log((w0 + w_inf) / (w + w_inf))


def test_dry_friction_agrees_with_mujoco_while_the_joint_slips(tmp_path):
    """MuJoCo's frictionloss (its constraints on, contacts off) while the wheel slips: it brakes
    with exactly the frictionloss, as gyro_sim's Coulomb friction does, until the speed nears
    zero (then MuJoCo's soft constraint and gyro_sim's stick_speed both smooth it their own
    way)."""
    w0, coulomb, viscous = WHEEL_W0, 0.01, 0.004
    path = write(tmp_path, "wheel.xml", WHEEL_MJCF.format(viscous=viscous, coulomb=coulomb, J=WHEEL_J, w0=w0))
    m = mujoco.MjModel.from_xml_path(str(path))
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, 0)
    sim = Simulator(load_scene(path), integrator="dop853", rtol=1e-12, atol=1e-12, backend="numpy")
    stop = braked_until(w0, coulomb, viscous, 0.1 * w0)
    worst = 0.0
    for t in np.linspace(0.0, stop, 6)[1:]:
        mujoco.mj_step(m, d, nstep=int(round((t - d.time) / m.opt.timestep)))
        sim.advance(d.time - sim.time)  # t on MuJoCo's grid of steps
        js = sim.joint_states()
        worst = max(worst, abs(js.velocity[0] - d.qvel[0]), abs(js.position[0] - d.qpos[0]))
    print(f"braked wheel vs MuJoCo's frictionloss while slipping: {worst:.2g}")
    assert worst < AGREEMENT


ROBOSUITE = Path(__file__).parent / "models" / "robosuite"


def frictionloss_judge(path: Path, timeconst: float, step: float):
    """MuJoCo's model of the file with its frictionloss a constraint of time constant `timeconst`
    (solref; critically damped) at a time step `step` (Euler), contacts, limits and equalities
    off, meshes left out: the hard-friction limit as timeconst -> 0."""
    m = mujoco_judge(path)
    m.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_LIMIT) | int(mujoco.mjtDisableBit.mjDSBL_EQUALITY)
    m.opt.integrator = mujoco.mjtIntegrator.mjINT_EULER
    m.opt.timestep = step
    m.opt.tolerance, m.opt.iterations = 1e-12, 200
    m.dof_solref[:] = [timeconst, 1.0]
    return m


@pytest.mark.slow
def test_an_arm_with_frictionloss_moves_as_mujoco_at_hard_friction():
    """robosuite's xarm7 as published (frictionloss 1 N m on every joint) falling under gravity:
    the shoulder and elbow slip, the other joints stick. gyro_sim's exact Coulomb friction against
    MuJoCo's frictionloss constraint made hard (time constant 4e-5 s, Euler step 1e-6 s) over
    0.3 s: the angles agree to 5e-5 rad (what MuJoCo's soft constraint lets a stuck joint creep:
    3.1e-5 rad, in proportion to its time constant), at gyro_sim's default step 1e-3 s as at
    1e-4 s; the two steps agree with each other to 5e-6 rad."""
    path = ROBOSUITE / "xarm7.xml"
    m = frictionloss_judge(path, 4e-5, 1e-6)
    d = mujoco.MjData(m)
    scene = load_scene(path)
    sims = {step: Simulator(scene, integrator="auto", step=step) for step in (1e-4, 1e-3)}
    hinges = [b.name for b in scene.bodies]
    address = [m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, h)] for h in hinges]
    worst = dict.fromkeys(sims, 0.0)
    apart = 0.0
    start = d.qpos[address].copy()
    for t in np.linspace(0.0, 0.3, 7)[1:]:
        mujoco.mj_step(m, d, nstep=int(round((t - d.time) / m.opt.timestep)))
        angles = {}
        for step, sim in sims.items():
            sim.advance(d.time - sim.time)
            position = dict(zip(*(sim.joint_states().name, sim.joint_states().position)))
            angles[step] = np.array([position[h] for h in hinges])
            worst[step] = max(worst[step], float(np.max(np.abs(d.qpos[address] - angles[step]))))
        apart = max(apart, float(np.max(np.abs(angles[1e-3] - angles[1e-4]))))
    moved = np.abs(d.qpos[address] - start)
    print(f"xarm7 vs MuJoCo's hard frictionloss: {worst}, steps apart {apart:.2g}, moved {moved.round(3)}")
    assert moved.max() > 0.5 and moved.min() < 1e-3  # a slip and a stick
    assert worst[1e-4] < 5e-5 and worst[1e-3] < 5e-5 and apart < 5e-6


def test_published_arms_with_dry_friction_cost_few_evaluations():
    """robosuite's xarm7 and jaco, Z1 of example-robot-data, their dry friction kept: "auto" over
    0.2 s takes fewer than 2e5 evaluations of y' per simulated second (the regularised law took
    ~1.5e8 on such an arm; Z1's damping, 1 N m s on a wrist of 1.5e-4 kg m^2, is itself what
    keeps dop853's steps near 0.1 ms there)."""
    for path in (ROBOSUITE / "xarm7.xml", ROBOSUITE / "jaco.xml", Path(__file__).parent / "models" /
                 "example_robot_data" / "z1.urdf"):
        sim = Simulator(load_scene(path), integrator="auto")
        sim.advance(0.2)
        assert sim.system.nfev / 0.2 < 2e5, (path.name, sim.system.nfev)


def test_a_failed_advance_keeps_the_state_and_the_friction_work():
    """Z1's damping is stiff for rk4 at 1 ms: the state leaves the finite within 0.05 s. The
    advance that fails raises SimulationError and keeps the time, the state and the friction's
    work of the last good one."""
    sim = Simulator(load_scene(Path(__file__).parent / "models" / "example_robot_data" / "z1.urdf"),
                    integrator="rk4", step=1e-3)
    with pytest.raises(SimulationError):
        for _ in range(200):
            kept = (sim.time, sim.state, sim.friction_work)
            sim.advance(1e-3)
    assert sim.time == kept[0] and np.array_equal(sim.state, kept[1]) and sim.friction_work == kept[2]
    assert kept[2] < 0.0


def test_what_has_no_scene_key_is_refused_in_one_line(tmp_path):
    ball = """<mujoco><worldbody><body name="arm" pos="0 0 1">
      <joint name="shoulder" type="ball" damping="0.1"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.02"/></body></worldbody></mujoco>"""
    with pytest.raises(ModelError) as info:
        import_model(write(tmp_path, "ball.xml", ball))
    assert info.value.errors == [f"{tmp_path / 'ball.xml'}: joint 'shoulder': damping on a ball joint "
                                 "is not supported (friction acts on a hinge's or rotor's axis)"]
    armature = ball.replace('damping="0.1"', 'armature="0.01"')
    with pytest.raises(SceneError, match="joint 'shoulder': armature on a ball joint is not supported"):
        load_scene(write(tmp_path, "armature.xml", armature))
