"""The linear model against MuJoCo on the same imported model, at equilibria: MuJoCo's own
dynamics (mj_forward) finite-differenced in its tangent space (mj_integratePos), and its RK4
step differenced as mjd_transitionFD defines it (which refuses RK4 itself) against
discrete(h, "rk4") at the same step. The charts differ (MuJoCo: a ball joint's rotation in local
axes, wheel rates relative), so the eigenvalues are compared: a change of coordinates that fixes
an equilibrium is a similarity."""
from __future__ import annotations

import numpy as np
import pytest

from gyro_sim import Simulator
from gyro_sim.paths import find_scene
from gyro_sim.scene.load import load_scene

mujoco = pytest.importorskip("mujoco", reason="MuJoCo is the optional extra [models]")

#: central differences of MuJoCo: step, and the agreement asked of the eigenvalues, relative
#: to max(1, |A|, the largest eigenvalue): the differenced entries err by ~1e-9 |A| (round-off
#: over the step), and a simple eigenvalue moves by about as much as the entries do
FD_STEP = 1e-6
AGREEMENT = 1e-6
#: below this fraction of that scale an eigenvalue counts as zero (MuJoCo's differenced Jordan
#: blocks of zero split by ~ sqrt(its error): matched by count, not by value)
ZERO = 1e-3

#: a ball joint and a hinge hanging straight down at rest, a flywheel spinning at 60 rad/s on
#: the forearm (not parallel to the hinge: it couples the swings)
ARM = """<mujoco model="hanging_flywheel">
  <option gravity="0 0 -9.81" timestep="0.001"/>
  <worldbody>
    <body name="upper" pos="0 0 1">
      <joint name="shoulder" type="ball"/>
      <inertial pos="0 0 -0.15" mass="0.8" diaginertia="4.5e-3 4.4e-3 3e-4"/>
      <body name="fore" pos="0 0 -0.3">
        <joint name="elbow" type="hinge" axis="1 0 0"/>
        <inertial pos="0 0 -0.12" mass="0.5" diaginertia="2.3e-3 2.2e-3 1.5e-4"/>
        <body name="flywheel" pos="0 0 -0.2">
          <joint name="spin" type="hinge" axis="0 1 0"/>
          <inertial pos="0 0 0" mass="0.2" diaginertia="2.5e-5 4.5e-5 2.5e-5"/>
        </body>
      </body>
    </body>
  </worldbody>
  <actuator><motor name="elbow_motor" joint="elbow"/><motor name="spin_motor" joint="spin"/></actuator>
  <keyframe><key name="rest" qpos="1 0 0 0  0  0" qvel="0 0 0  0  60"/></keyframe>
</mujoco>
"""


def _satellite(tmp_path):
    """The shipped satellite with a keyframe at rest, its wheels spinning: a free gyrostat at rest."""
    xml = find_scene("satellite_wheels.xml").read_text()
    rest = ('<key name="rest" qpos="0.1 -0.2 0.3  0.5 0.5 -0.1 0.7  0 0 0  0.3" '
            'qvel="0 0 0  0 0 0  50 -30 20  0"/>')
    path = tmp_path / "satellite_rest.xml"
    path.write_text(xml.replace("<keyframe>", "<keyframe>\n    " + rest))
    return path


def _models(tmp_path, which):
    if which == "arm":
        path = tmp_path / "arm.xml"
        path.write_text(ARM)
    else:
        path = _satellite(tmp_path)
    m = mujoco.MjModel.from_xml_path(str(path))
    m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT | mujoco.mjtDisableBit.mjDSBL_CONSTRAINT
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, "rest"))
    mujoco.mj_forward(m, d)
    return path, m, d


def _mujoco_continuous(m, d0):
    """A of MuJoCo's dynamics in its tangent space (dq, v), by central differences."""
    nv = m.nv
    d = mujoco.MjData(m)

    def qacc(dq, dv):
        d.qpos[:] = d0.qpos
        mujoco.mj_integratePos(m, d.qpos, dq, 1.0)
        d.qvel[:] = d0.qvel + dv
        d.ctrl[:] = 0.0
        mujoco.mj_forward(m, d)
        return d.qacc.copy()

    A = np.zeros((2 * nv, 2 * nv))
    A[:nv, nv:] = np.eye(nv)  # dq' = v (at rest the local charts' rates are the velocities)
    zero = np.zeros(nv)
    for j in range(nv):
        e = np.zeros(nv)
        e[j] = FD_STEP
        A[nv:, j] = (qacc(e, zero) - qacc(-e, zero)) / (2 * FD_STEP)
        A[nv:, nv + j] = (qacc(zero, e) - qacc(zero, -e)) / (2 * FD_STEP)
    return A


def _agree(ours, theirs, norm):
    scale = max(1.0, norm, np.max(np.abs(ours)), np.max(np.abs(theirs)))
    big_o = sorted((e for e in ours if abs(e) > ZERO * scale), key=lambda e: (round(e.real, 6), e.imag))
    big_t = [e for e in theirs if abs(e) > ZERO * scale]
    assert len(big_o) == len(big_t) and len(ours) == len(theirs), (ours, theirs)
    for e in big_o:
        i = int(np.argmin([abs(t - e) for t in big_t]))
        assert abs(big_t[i] - e) <= AGREEMENT * scale, (e, big_t[i])
        big_t.pop(i)


@pytest.mark.parametrize("which", ["arm", "satellite"])
def test_eigenvalues_agree_with_mujocos_differenced_dynamics(tmp_path, which):
    path, m, d = _models(tmp_path, which)
    sim = Simulator(load_scene(path, keyframe="rest"), backend="numpy")
    lin = sim.linearize(rotor_angles=True)  # MuJoCo's state has the wheels' angles
    assert lin.is_equilibrium
    ours = lin.eigenvalues()
    A = _mujoco_continuous(m, d)
    _agree(ours, np.linalg.eigvals(A), np.linalg.norm(A, 2))
    if which == "arm":  # the swings: two pairs of imaginary eigenvalues each side, no growth
        assert np.sum(np.abs(ours.imag) > 1.0) >= 6 and lin.verdict() == "marginal"


def _mujoco_rk4_transition(m, d0):
    """The derivative of one step of MuJoCo's RK4 (mj_step) in its tangent space, by central
    differences: mjd_transitionFD's definition (positions through mj_integratePos and
    mj_differentiatePos), which mjd_transitionFD itself refuses for RK4."""
    nv = m.nv
    d = mujoco.MjData(m)

    def step(dq, dv):
        d.time = d0.time
        d.qpos[:] = d0.qpos
        mujoco.mj_integratePos(m, d.qpos, dq, 1.0)
        d.qvel[:] = d0.qvel + dv
        d.ctrl[:] = 0.0
        mujoco.mj_step(m, d)
        return d.qpos.copy(), d.qvel.copy()

    zero = np.zeros(nv)
    q1, v1 = step(zero, zero)
    A = np.zeros((2 * nv, 2 * nv))
    for j in range(2 * nv):
        e = np.zeros(2 * nv)
        e[j] = FD_STEP
        cols = []
        for sgn in (1.0, -1.0):
            q, v = step(sgn * e[:nv], sgn * e[nv:])
            dq = np.zeros(nv)
            mujoco.mj_differentiatePos(m, dq, 1.0, q1, q)
            cols.append(np.concatenate((dq, v - v1)))
        A[:, j] = (cols[0] - cols[1]) / (2 * FD_STEP)
    return A


@pytest.mark.parametrize("which", ["arm", "satellite"])
def test_discrete_rk4_agrees_with_mujocos_rk4_transition(tmp_path, which):
    h = 0.002
    path, m, d = _models(tmp_path, which)
    m.opt.integrator = mujoco.mjtIntegrator.mjINT_RK4
    m.opt.timestep = h
    A = _mujoco_rk4_transition(m, d)
    n = A.shape[0]
    lin = Simulator(load_scene(path, keyframe="rest"), backend="numpy").linearize(rotor_angles=True)
    Ad = lin.discrete(h, "rk4").Ad
    z_ours, z_theirs = np.linalg.eigvals(Ad), np.linalg.eigvals(A)
    # the eigenvalues cluster at 1: compare the modes log z / h
    _agree(np.log(z_ours.astype(complex)) / h, np.log(z_theirs.astype(complex)) / h,
           np.linalg.norm(A - np.eye(n), 2) / h)
