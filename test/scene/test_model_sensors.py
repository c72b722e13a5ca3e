"""A model's IMU sensors as the scene's IMUs (gyro_sim.scene.mjcf, gyro_sim.scene.gazebo,
docs/models.md "Sensors").

The judge of frames and physics is MuJoCo's own sensors: sites at random poses on every body
of the shipped models (a welded tool included), gyro, accelerometer, framequat and framelinacc
on each, at random moving states and commands; gyro_sim's IMU readings at the same state
must equal MuJoCo's ``sensordata`` to round-off (READING_RTOL). The judge of the noise
mapping is the noise model's definition: white noise of density N sampled at f has the
standard deviation N sqrt(f) per sample, which must come back as the file's stddev; a
Gazebo dynamic bias step is checked against gz-sensors' Gauss-Markov formula. The judge of
a Gazebo ``<pose>`` is MuJoCo's URDF reader: the same pose as a fixed joint's origin.
"""
from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco", reason="MuJoCo is the optional extra [models]")

from gyro_sim import Simulator
from gyro_sim.cli import main
from gyro_sim.dynamics.imu import ImuNoise, check_rates
from gyro_sim.dynamics.rotations import quat_to_matrix
from gyro_sim.paths import find_scene
from gyro_sim.scene.load import SceneError, load_scene, parse_yaml
from gyro_sim.scene.mjcf import ModelError, import_model
from gyro_sim.dynamics.imu import DEFAULT_IMU_RATE

#: gyro_sim's IMU readings against MuJoCo's sensordata at the same state: the two compute the
#: same kinematics and forward dynamics by different algorithms (MuJoCo's CRB and RNE,
#: gyro_sim's eqs of motion), so they agree to the round-off of ~1e3 operations on numbers of
#: order 10 (relative to each reading's scale, with the scale at least 1)
READING_RTOL = 1e-10
#: MuJoCo's RK4 step and gyro_sim's tolerances when both advance before the comparison, and
#: what the readings must then agree to (the integrators' errors, as test_model_import.py)
MUJOCO_STEP = 1e-4
RTOL = ATOL = 1e-12
ADVANCED_AGREEMENT = 1e-7
#: samples drawn to measure a noise's standard deviation, and the relative tolerance on it
#: (the standard error of a standard deviation from n normal samples is 1 / sqrt(2 n): 0.35%
#: for 40000 samples; 2% is more than five of them)
NOISE_SAMPLES = 40000
NOISE_RTOL = 0.02

ARM = find_scene("arm_flywheel.xml")
SATELLITE = find_scene("satellite_wheels.xml")
SENSOR_TYPES = {"gyro": mujoco.mjtSensor.mjSENS_GYRO, "acc": mujoco.mjtSensor.mjSENS_ACCELEROMETER,
                "quat": mujoco.mjtSensor.mjSENS_FRAMEQUAT, "linacc": mujoco.mjtSensor.mjSENS_FRAMELINACC}


def write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def random_quat(rng) -> np.ndarray:
    q = rng.normal(size=4)
    return q / np.linalg.norm(q)


def with_imu_sites(source: Path, bodies: list[str], rng, tmp_path: Path, states: int = 2) -> Path:
    """`source` with a site at a random pose on each of `bodies`, the four IMU sensors on each
    (named <site>_gyro, _acc, _quat, _linacc) and `states` random keyframes (probe0, ...)."""
    spec = mujoco.MjSpec.from_file(str(source))
    for body in bodies:
        site = f"imu_{body}"
        spec.body(body).add_site(name=site, pos=rng.uniform(-0.2, 0.2, 3), quat=random_quat(rng))
        for suffix, kind in SENSOR_TYPES.items():
            spec.add_sensor(name=f"{site}_{suffix}", type=kind, objtype=mujoco.mjtObj.mjOBJ_SITE, objname=site)
    m = spec.compile()
    for k in range(states):
        qpos, qvel = [], rng.normal(scale=1.5, size=m.nv)
        for j in range(m.njnt):
            kind = int(m.jnt_type[j])
            if kind == int(mujoco.mjtJoint.mjJNT_FREE):
                qpos += list(rng.uniform(-1, 1, 3)) + list(random_quat(rng))
            elif kind == int(mujoco.mjtJoint.mjJNT_BALL):
                qpos += list(random_quat(rng))
            else:
                qpos.append(rng.uniform(-1.5, 1.5))
        spec.add_key(name=f"probe{k}", qpos=qpos, qvel=list(qvel))
    return write(tmp_path, f"probe_{source.name}", spec.to_xml())


def mujoco_readings(model, ctrl: np.ndarray, advance: float = 0.0, key: str | None = None,
                    qpos=None, qvel=None) -> dict:
    """MuJoCo's sensordata by sensor name for `model` (an MjModel, or a file) at keyframe `key`
    or at (qpos, qvel), after `advance` s of RK4 with contacts and constraints off."""
    m = model if isinstance(model, mujoco.MjModel) else mujoco.MjModel.from_xml_path(str(model))
    m.opt.integrator = mujoco.mjtIntegrator.mjINT_RK4
    m.opt.timestep = MUJOCO_STEP
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT) | int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    d = mujoco.MjData(m)
    if key is not None:
        mujoco.mj_resetDataKeyframe(m, d, mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, key))
    else:
        d.qpos[:], d.qvel[:] = qpos, qvel
    d.ctrl[:] = ctrl
    if advance:
        mujoco.mj_step(m, d, nstep=int(round(advance / MUJOCO_STEP)))
    mujoco.mj_forward(m, d)
    out = {}
    for s in range(m.nsensor):
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_SENSOR, s)
        out[name] = d.sensordata[m.sensor_adr[s]:m.sensor_adr[s] + m.sensor_dim[s]].copy()
    return out


def gyro_readings(path: Path, keyframe: str, ctrl: np.ndarray, advance: float = 0.0) -> dict:
    """gyro_sim's IMU readings by IMU name from the model imported at `keyframe`, commanded as
    MuJoCo's ctrl maps through the gears (numpy backend)."""
    imported = import_model(path, keyframe)
    sim = Simulator(load_scene(path, keyframe=keyframe), integrator="dop853", rtol=RTOL, atol=ATOL,
                    backend="numpy")
    moments = {c.axis: c.factor * ctrl[i] for i, c in enumerate(imported.commands)}
    sim.set_axis_moments([moments.get(a, 0.0) for a in sim.axis_names])
    if advance:
        sim.advance(advance)
    return {r.name: r for r in sim.imus()}


def deviation(mj: dict, gs: dict, sites: list[str]) -> float:
    """The largest difference between MuJoCo's sensors and gyro_sim's IMUs, relative to each
    reading's scale (at least 1): gyro, accelerometer, orientation (either sign), and the
    world-frame acceleration as orientation x linear_acceleration."""
    worst = 0.0
    for site in sites:
        r = gs[site]
        world = quat_to_matrix(r.orientation) @ r.linear_acceleration
        q = mj[f"{site}_quat"]
        pairs = [(mj[f"{site}_gyro"], r.angular_velocity), (mj[f"{site}_acc"], r.linear_acceleration),
                 (q if q @ r.orientation >= 0 else -q, r.orientation), (mj[f"{site}_linacc"], world)]
        for expected, got in pairs:
            worst = max(worst, float(np.max(np.abs(got - expected))) / max(1.0, float(np.max(np.abs(expected)))))
    return worst


# ------------------------------------------------------------------------------ MJCF: agreement
MOVING = {  # the model, the bodies carrying sites (the tool is welded to the hand)
    "arm_flywheel": (ARM, ["upper", "fore", "hand", "tool"]),
    "satellite_wheels": (SATELLITE, ["bus", "panel"]),
}


@pytest.mark.parametrize("name", sorted(MOVING))
def test_imu_readings_are_mujocos_sensordata(name, tmp_path):
    source, bodies = MOVING[name]
    rng = np.random.default_rng(sum(map(ord, name)))
    path = with_imu_sites(source, bodies, rng, tmp_path)
    imported = import_model(path, "probe0")
    sites = [f"imu_{b}" for b in bodies]
    assert [imu["name"] for imu in imported.mapping["imus"]] == sites  # named after the site, one each
    assert not any("not imported" in note for note in imported.notes)
    nu = len(imported.commands)
    worst = 0.0
    for key in ("probe0", "probe1"):
        ctrl = rng.uniform(-0.9, 0.9, nu)  # inside every ctrlrange: MuJoCo would clamp
        worst = max(worst, deviation(mujoco_readings(path, ctrl, key=key), gyro_readings(path, key, ctrl), sites))
    print(f"{name}: largest relative deviation from MuJoCo's sensordata {worst:.2g}")
    assert worst < READING_RTOL


@pytest.mark.slow
def test_imu_readings_follow_mujoco_as_the_model_moves(tmp_path):
    rng = np.random.default_rng(7)
    source, bodies = MOVING["arm_flywheel"]
    path = with_imu_sites(source, bodies, rng, tmp_path, states=1)
    ctrl = np.array([0.4, -0.3])
    sites = [f"imu_{b}" for b in bodies]
    mj = mujoco_readings(path, ctrl, advance=0.5, key="probe0")
    gs = gyro_readings(path, "probe0", ctrl, advance=0.5)
    worst = deviation(mj, gs, sites)
    print(f"after 0.5 s: largest relative deviation {worst:.2g}")
    assert worst < ADVANCED_AGREEMENT
    assert max(np.linalg.norm(mj[f"{s}_gyro"]) for s in sites) > 1.0  # it does move


#: (d): an URDF arm with an IMU link on a fixed joint (MuJoCo fuses it into the forearm)
URDF_IMU = """<?xml version="1.0"?>
<robot name="imu_arm">
  <link name="base_link"/>
  <joint name="shoulder" type="revolute">
    <parent link="base_link"/><child link="upper"/>
    <origin xyz="0 0 0.8" rpy="0.3 0.2 0.1"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" effort="20" velocity="5"/>
  </joint>
  <link name="upper">
    <inertial><origin xyz="0.12 0.01 0.02" rpy="0 0.1 0"/><mass value="1.2"/>
      <inertia ixx="1e-3" iyy="6e-3" izz="6.2e-3" ixy="1e-4" ixz="0" iyz="-5e-5"/></inertial>
  </link>
  <joint name="elbow" type="continuous">
    <parent link="upper"/><child link="fore"/>
    <origin xyz="0.25 0 0" rpy="0 0 0.4"/><axis xyz="0 1 0"/>
  </joint>
  <link name="fore">
    <inertial><origin xyz="0.1 0 -0.01"/><mass value="0.7"/>
      <inertia ixx="4e-4" iyy="2.6e-3" izz="2.7e-3" ixy="0" ixz="2e-5" iyz="0"/></inertial>
  </link>
  <joint name="imu_joint" type="fixed">
    <parent link="fore"/><child link="imu_link"/>
    <origin xyz="{xyz}" rpy="{rpy}"/>
  </joint>
  <link name="imu_link"/>
  <gazebo reference="{link}">
    <sensor name="imu_sensor" type="imu">{sensor}</sensor>
  </gazebo>
</robot>
"""


def urdf(tmp_path: Path, name: str = "arm.urdf", xyz: str = "0.2 0.03 -0.01", rpy: str = "0.3 -0.5 1.1",
         link: str = "imu_link", sensor: str = "") -> Path:
    return write(tmp_path, name, URDF_IMU.replace("{xyz}", xyz).replace("{rpy}", rpy)
                 .replace("{link}", link).replace("{sensor}", sensor))


def test_a_gazebo_imu_reads_as_mujoco_sensors_on_its_link(tmp_path):
    """The judge puts MuJoCo's own sensors on a site at the IMU link's origin (MuJoCo's URDF
    reader places the link, fused into the forearm) at a random moving state, compiled in
    memory (an MJCF written out keeps 6 digits); gyro_sim starts from the same hinge angles
    and rates (a URDF has no keyframes: they go into the scene)."""
    path = urdf(tmp_path)
    rng = np.random.default_rng(3)
    spec = mujoco.MjSpec.from_file(str(path))
    spec.body("imu_link").add_site(name="imu_sensor")
    for suffix, kind in SENSOR_TYPES.items():
        spec.add_sensor(name=f"imu_sensor_{suffix}", type=kind, objtype=mujoco.mjtObj.mjOBJ_SITE,
                        objname="imu_sensor")
    qpos, qvel = rng.uniform(-1.5, 1.5, 2), rng.normal(scale=2.0, size=2)
    mj = mujoco_readings(spec.compile(), np.zeros(0), qpos=qpos, qvel=qvel)
    mapping = copy.deepcopy(import_model(path).mapping)
    assert [b["name"] for b in mapping["bodies"]] == ["shoulder", "elbow"]  # MuJoCo's joint order
    for body, angle, rate in zip(mapping["bodies"], qpos, qvel):
        body["initial"] = {"angle": float(angle), "rate": float(rate)}
    scene = load_scene(mapping)
    assert [(imu.name, imu.body) for imu in scene.imus] == [("imu_sensor", "elbow")]
    gs = {r.name: r for r in Simulator(scene, backend="numpy").imus()}
    worst = deviation(mj, gs, ["imu_sensor"])
    print(f"URDF: largest relative deviation from MuJoCo's sensordata {worst:.2g}")
    assert worst < READING_RTOL


# ------------------------------------------------------------------------------ what is not an IMU
def test_a_model_without_sensors_has_no_imus():
    for path in (ARM, SATELLITE):
        imported = import_model(path)
        assert "imus" not in imported.mapping
        assert load_scene(path).imus == ()
        assert not any("sensor" in note for note in imported.notes)


PENDULUM = """<mujoco model="pendulum">
  <option gravity="0 0 -9.81"/>
  <worldbody>
    <site name="ground"/>
    <body name="stand" pos="0 0 1"><site name="on_stand"/>
      <body name="arm"><joint name="swing" type="hinge" axis="1 0 0"/>
        <inertial pos="0 0 -0.3" mass="1" diaginertia="0.01 0.01 0.001"/>
        <site name="tip" pos="0 0 -0.6"/>
        <body name="wheel" pos="0 0 -0.6"><joint name="spin" type="hinge" axis="0 0 1"/>
          <inertial pos="0 0 0" mass="0.2" diaginertia="1e-4 1e-4 2e-4"/>
          <site name="on_wheel" pos="0.01 0 0"/>
        </body>
      </body>
    </body>
  </worldbody>
  <sensor>{sensors}</sensor>
</mujoco>"""


def pendulum(tmp_path: Path, sensors: str, name: str = "pendulum.xml") -> Path:
    return write(tmp_path, name, PENDULUM.replace("{sensors}", sensors))


def test_a_sensor_that_cannot_be_an_imu_is_named_in_the_notes(tmp_path):
    path = pendulum(tmp_path, """
        <gyro site="tip" name="tip_gyro"/><accelerometer site="tip" name="tip_acc"/>
        <gyro site="ground" name="ground_gyro"/>
        <accelerometer site="on_stand" name="stand_acc"/>
        <gyro site="on_wheel" name="wheel_gyro"/>
        <jointpos joint="swing" name="angle"/><framepos objtype="site" objname="tip"/>
        <framequat objtype="body" objname="arm" name="arm_quat"/>
        <framequat objtype="site" objname="on_stand" name="stand_quat"/>""")
    imported = import_model(path)
    assert [(imu["name"], imu["body"]) for imu in imported.mapping["imus"]] == [("tip", "swing")]
    notes = "\n".join(imported.notes)
    assert ("sensors not imported (an IMU is a gyro or an accelerometer on a site): jointpos 'angle', "
            "framepos #6, framequat 'arm_quat'") in notes
    assert "site 'ground' (gyro 'ground_gyro'): not imported: on the world body" in notes
    assert ("site 'on_stand' (accelerometer 'stand_acc', framequat 'stand_quat'): not imported: on the "
            "static body 'stand'") in notes
    assert "site 'on_wheel' (gyro 'wheel_gyro'): not imported: on the rotor of joint 'spin'" in notes
    for sensor in ("angle", "framepos #6", "arm_quat", "stand_quat", "ground_gyro", "stand_acc", "wheel_gyro"):
        assert sum(sensor in note for note in imported.notes) == 1, sensor  # each named, in one line


def test_an_imu_is_named_after_its_site_and_made_unique(tmp_path):
    xml = PENDULUM.replace('<site name="tip" pos="0 0 -0.6"/>',
                           '<site name="tip" pos="0 0 -0.6"/><site name="swing" pos="0 0 -0.2"/>')
    path = write(tmp_path, "names.xml", xml.replace("{sensors}", """
        <gyro site="tip" name="imu_gyro"/><accelerometer site="tip" name="imu_accel"/>
        <gyro site="swing" name="g"/>"""))
    imported = import_model(path)
    assert [imu["name"] for imu in imported.mapping["imus"]] == ["tip", "swing_imu"]  # 'swing': the hinge body
    assert "site 'swing' (gyro 'g'): named 'swing_imu': 'swing' is a body's or another IMU's name" \
        in imported.notes
    assert [imu.name for imu in load_scene(path).imus] == ["tip", "swing_imu"]


def test_a_name_no_frame_can_have_is_refused_naming_the_site(tmp_path):
    path = pendulum(tmp_path, '<gyro site="tip"/>').read_text().replace('"tip"', '"tip 1"')
    with pytest.raises(SceneError) as err:
        load_scene(write(tmp_path, "bad.xml", path))
    assert len(err.value.errors) == 1
    assert err.value.errors[0].startswith(f"{tmp_path / 'bad.xml'}: site 'tip 1' (gyro #0): name: ")


def test_a_site_name_that_is_no_ros_token_is_kept_and_its_topic_made_one(tmp_path):
    path = pendulum(tmp_path, '<gyro site="tip"/>').read_text().replace('"tip"', '"tip-1"')
    scene = load_scene(write(tmp_path, "named.xml", path))
    assert [imu.name for imu in scene.imus] == ["tip-1"]


# ------------------------------------------------------------------------------ MJCF: rate and noise
def white_std(density: float, rate: float) -> float:
    """The standard deviation per sample of gyro_sim's white noise of `density` sampled at
    `rate`, measured on NOISE_SAMPLES samples of the IMU noise model."""
    record = ImuNoise(density, 0.0, 0.0, 0.0, rate, seed=11).record(NOISE_SAMPLES)
    return float(record[:, :3].std())


def test_mujoco_interval_is_the_rate_and_noise_the_per_sample_deviation(tmp_path):
    path = pendulum(tmp_path, """
        <gyro site="tip" noise="0.02" nsample="1" interval="0.02"/>
        <accelerometer site="tip" noise="0.3" nsample="1" interval="0.02"/>""")
    imported = import_model(path)
    imu = imported.mapping["imus"][0]
    assert imu["rate"] == 50.0
    assert imu["gyro_noise_density"] == pytest.approx(0.02 / math.sqrt(50.0), rel=1e-12)
    assert imu["accel_noise_density"] == pytest.approx(0.3 / math.sqrt(50.0), rel=1e-12)
    assert white_std(imu["gyro_noise_density"], imu["rate"]) == pytest.approx(0.02, rel=NOISE_RTOL)
    assert "gyro_bias_instability" not in imu and "accel_bias_instability" not in imu
    assert not imported.notes or not any("rate" in n for n in imported.notes)
    assert check_rates(load_scene(path), DEFAULT_IMU_RATE) is None


def test_without_an_interval_the_noise_is_kept_at_the_default_publish_rate(tmp_path):
    path = pendulum(tmp_path, '<gyro site="tip" noise="0.02"/><accelerometer site="tip"/>')
    imported = import_model(path)
    imu = imported.mapping["imus"][0]
    assert "rate" not in imu and "accel_noise_density" not in imu
    assert white_std(imu["gyro_noise_density"], DEFAULT_IMU_RATE) == pytest.approx(0.02, rel=NOISE_RTOL)
    assert any(n.startswith("site 'tip' (gyro #0, accelerometer #1): no rate: the noise per sample is "
                            "the model's at 100 Hz") for n in imported.notes)


def test_imported_imus_with_noise_draw_different_noise(tmp_path):
    xml = PENDULUM.replace('<site name="tip" pos="0 0 -0.6"/>', '<site name="tip" pos="0 0 -0.6"/><site name="mid"/>')
    path = write(tmp_path, "two.xml", xml.replace("{sensors}", """
        <gyro site="tip" noise="0.01"/><gyro site="mid" noise="0.01"/>"""))
    tip, mid = load_scene(path).imus
    assert (tip.seed, mid.seed) == (0, 1)
    draws = [ImuNoise(imu.gyro_noise_density, 0.0, 0.0, 0.0, DEFAULT_IMU_RATE, imu.seed).record(100)[:, :3]
             for imu in (tip, mid)]
    assert abs(np.corrcoef(draws[0].ravel(), draws[1].ravel())[0, 1]) < 0.3  # independent, not the same draws


def test_what_mujoco_says_of_a_sensor_and_gyro_sim_does_not_model_is_noted(tmp_path):
    path = pendulum(tmp_path, """
        <gyro site="tip" name="g" nsample="3" interval="0.01" delay="0.01" cutoff="5"/>
        <accelerometer site="tip" name="a" nsample="1" interval="0.02 -0.01"/>
        <framequat objtype="site" objname="tip" name="q" noise="0.1"/>
        <framelinacc objtype="site" objname="tip" name="l"/>""")
    imported = import_model(path)
    assert imported.mapping["imus"][0]["rate"] == 100.0  # the faster
    notes = [n.removeprefix("site 'tip' (gyro 'g', accelerometer 'a', framequat 'q', framelinacc 'l'): ")
             for n in imported.notes]
    for expected in ("its sensors' intervals differ (0.01 s, 0.02 s): the IMU samples at 100 Hz",
                     "interval phase not kept", "gyro 'g': delay 0.01 s not modelled",
                     "gyro 'g': cutoff 5 not enforced", "framequat 'q': noise not modelled",
                     "framelinacc 'l': given by the IMU in its own frame"):
        assert any(n.startswith(expected) for n in notes), expected


# ------------------------------------------------------------------------------ URDF: Gazebo IMUs
def axis_noise(stddev: float, extra: str = "") -> str:
    return "".join(f'<{a}><noise type="gaussian"><mean>0</mean><stddev>{stddev}</stddev>{extra}</noise></{a}>'
                   for a in "xyz")


GZ_SIM = ("<always_on>1</always_on><update_rate>100</update_rate><topic>imu</topic>"
          "<imu><angular_velocity>" + axis_noise(2e-4, "<bias_mean>7.5e-6</bias_mean><bias_stddev>8e-7</bias_stddev>")
          + "</angular_velocity><linear_acceleration>"
          + axis_noise(1.7e-2, "<dynamic_bias_stddev>4e-3</dynamic_bias_stddev>"
                               "<dynamic_bias_correlation_time>1000</dynamic_bias_correlation_time>")
          + "</linear_acceleration></imu>")


def test_a_gazebo_imu_takes_its_rate_and_noise(tmp_path):
    imported = import_model(urdf(tmp_path, sensor=GZ_SIM))
    imu = imported.mapping["imus"][0]
    assert (imu["name"], imu["body"], imu["rate"]) == ("imu_sensor", "elbow", 100.0)
    assert white_std(imu["gyro_noise_density"], imu["rate"]) == pytest.approx(2e-4, rel=NOISE_RTOL)
    assert white_std(imu["accel_noise_density"], imu["rate"]) == pytest.approx(1.7e-2, rel=NOISE_RTOL)
    # gz-sensors' bias step at dt = 1 / rate: sqrt(-sigma_b^2 tau / 2 expm1(-2 dt / tau)); ours B / sqrt(rate)
    dt, sigma_b, tau = 1.0 / imu["rate"], 4e-3, 1000.0
    gazebo_step = math.sqrt(-sigma_b ** 2 * tau / 2 * math.expm1(-2 * dt / tau))
    assert imu["accel_bias_instability"] / math.sqrt(imu["rate"]) == pytest.approx(gazebo_step, rel=1e-5)
    assert "gyro_bias_instability" not in imu
    notes = [n.removeprefix("gazebo sensor 'imu_sensor' on link 'imu_link': ") for n in imported.notes]
    assert any(n.startswith("gyro bias_mean, bias_stddev not modelled") for n in notes)
    assert any(n.startswith("accelerometer dynamic bias: correlation time 1000 s not kept") for n in notes)
    scene = load_scene(urdf(tmp_path, sensor=GZ_SIM))
    assert scene.imus[0].seed == 0 and check_rates(scene, DEFAULT_IMU_RATE) is None


GZ_CLASSIC = ("<update_rate>50</update_rate><imu><noise><type>gaussian</type>"
              "<rate><mean>0</mean><stddev>3e-3</stddev><bias_mean>0</bias_mean><bias_stddev>0</bias_stddev></rate>"
              "<accel><mean>0</mean><stddev>0.05</stddev><bias_mean>0.1</bias_mean><bias_stddev>0</bias_stddev></accel>"
              "</noise></imu>")


def test_the_sdf_1_4_noise_form_of_gazebo_classic(tmp_path):
    imported = import_model(urdf(tmp_path, sensor=GZ_CLASSIC))
    imu = imported.mapping["imus"][0]
    assert imu["rate"] == 50.0
    assert white_std(imu["gyro_noise_density"], 50.0) == pytest.approx(3e-3, rel=NOISE_RTOL)
    assert white_std(imu["accel_noise_density"], 50.0) == pytest.approx(0.05, rel=NOISE_RTOL)
    assert any(n.endswith("accelerometer bias_mean not modelled (gyro_sim's bias starts at 0 and walks; "
                          "no offset, no quantization)") for n in imported.notes)


def test_a_gazebo_pose_is_placed_as_a_fixed_joint_would_place_it(tmp_path):
    """MuJoCo's URDF reader is the judge: a sensor on the forearm at pose P sits where a link on
    a fixed joint of origin P puts it; in every form SDF writes a pose."""
    xyz, rpy = "0.2 0.03 -0.01", "0.3 -0.5 1.1"
    by_joint = import_model(urdf(tmp_path, "joint.urdf", xyz=xyz, rpy=rpy)).mapping["imus"][0]
    roll, pitch, yaw = (float(a) for a in rpy.split())
    q = mujoco_quat_of_rpy(roll, pitch, yaw)
    degrees = " ".join(repr(math.degrees(a)) for a in (roll, pitch, yaw))
    xyzw = " ".join(repr(float(c)) for c in q[[1, 2, 3, 0]])
    forms = {"rpy": f"<pose>{xyz} {rpy}</pose>",
             "degrees": f'<pose degrees="true">{xyz} {degrees}</pose>',
             "quat_xyzw": f'<pose rotation_format="quat_xyzw">{xyz} {xyzw}</pose>',
             "relative_to_link": f'<pose relative_to="fore">{xyz} {rpy}</pose>'}
    for form, pose in forms.items():
        on_fore = import_model(urdf(tmp_path, f"{form}.urdf", xyz="0 0 0", rpy="0 0 0", link="fore",
                                    sensor=pose)).mapping["imus"][0]
        assert on_fore["body"] == by_joint["body"]
        assert np.allclose(on_fore["position"], by_joint["position"], rtol=0, atol=1e-14), form
        a, b = np.array(on_fore["orientation"]), np.array(by_joint["orientation"])
        assert abs(abs(a @ b) - 1.0) < 1e-14, form


def mujoco_quat_of_rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """MuJoCo's quaternion of URDF's rpy: a fixed joint's origin read by MuJoCo's URDF reader."""
    text = URDF_IMU.replace("{xyz}", "0 0 0").replace("{rpy}", f"{roll!r} {pitch!r} {yaw!r}") \
        .replace("{link}", "imu_link").replace("{sensor}", "")
    spec = mujoco.MjSpec.from_string(text)
    spec.compiler.fusestatic = False
    m = spec.compile()
    return np.array(m.body_quat[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "imu_link")])


def test_gazebo_sensors_that_are_no_imus_are_named_in_the_notes(tmp_path):
    text = urdf(tmp_path, sensor="<update_rate>100</update_rate>").read_text().replace("</robot>", """
      <gazebo reference="upper"><sensor name="cam" type="camera"/><sensor name="lidar" type="gpu_lidar"/></gazebo>
      <gazebo><sensor name="loose" type="imu"/></gazebo>
      <gazebo reference="nowhere"><sensor name="lost" type="imu"/></gazebo>
      <gazebo reference="base_link"><sensor name="fixed" type="imu"/></gazebo>
      <gazebo reference="fore">
        <sensor name="far" type="imu"><pose relative_to="upper">0 0 0 0 0 0</pose></sensor>
      </gazebo>
    </robot>""")
    imported = import_model(write(tmp_path, "many.urdf", text))
    assert [imu["name"] for imu in imported.mapping["imus"]] == ["imu_sensor"]
    notes = "\n".join(imported.notes)
    for expected in ("gazebo sensors not imported (IMUs only): 'cam' (camera) on link 'upper', 'lidar' (gpu_lidar) "
                     "on link 'upper'",
                     "gazebo sensor 'loose': not imported: no reference link",
                     "gazebo sensor 'lost': not imported: no link named 'nowhere'",
                     "gazebo sensor 'fixed' on link 'base_link': not imported: on the world body",
                     "gazebo sensor 'far' on link 'fore': not imported: its <pose> is relative to 'upper'"):
        assert expected in notes, expected


@pytest.mark.parametrize("sensor, expected", [
    ("<update_rate>fast</update_rate>", "<update_rate> 'fast' is not a number"),
    ("<update_rate>-5</update_rate>", "<update_rate> must be >= 0 (got -5)"),
    ("<pose>0 0 0 0 0</pose>", "<pose> '0 0 0 0 0' must be 6 finite numbers"),
    ("<imu><angular_velocity><x><noise type='gaussian'><stddev>nan</stddev></noise></x></angular_velocity></imu>",
     "gyro <stddev> must be finite (got nan)"),
    ("<imu><linear_acceleration><y><noise type='gaussian'><stddev>-1</stddev></noise></y></linear_acceleration></imu>",
     "accelerometer <stddev> must be >= 0 (got -1)"),
])
def test_a_gazebo_imu_number_that_cannot_be_read_is_refused_in_one_line(tmp_path, sensor, expected):
    path = urdf(tmp_path, sensor=sensor)
    with pytest.raises(ModelError) as err:
        import_model(path)
    assert err.value.errors == [f"{path}: gazebo sensor 'imu_sensor' on link 'imu_link': {expected}"]


# ------------------------------------------------------------------------------ rates
def test_a_rate_the_default_publications_cannot_sample_is_kept_and_said(tmp_path):
    path = urdf(tmp_path, sensor="<update_rate>200</update_rate>")
    imported = import_model(path)
    assert imported.mapping["imus"][0]["rate"] == 200.0
    assert ("gazebo sensor 'imu_sensor' on link 'imu_link': rate 200 Hz kept: publications at the default "
            "100 Hz cannot sample it (publish at a multiple of 200 Hz)") in imported.notes
    scene = load_scene(path)
    assert check_rates(scene, 200.0) is None and check_rates(scene, 1000.0) is None
    assert check_rates(scene, DEFAULT_IMU_RATE) == (
        "imus[0].rate: 200 Hz must divide the publish rate 100 Hz (publish_rate / rate a whole number): "
        "IMUs are sampled at publications")  # the line the node and gyro-sim run refuse with


def test_gazebo_update_rate_zero_samples_at_every_publication(tmp_path):
    imu = import_model(urdf(tmp_path, sensor="<update_rate>0</update_rate>")).mapping["imus"][0]
    assert "rate" not in imu


# ------------------------------------------------------------------------------ gyro-sim import
def test_import_writes_the_imus_and_says_the_notes(tmp_path, capsys):
    path = urdf(tmp_path, sensor=GZ_SIM)
    out = tmp_path / "arm.yaml"
    assert main(["import", str(path), "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "IMUs ['imu_sensor']" in printed.splitlines()[0]
    assert "  note: gazebo sensor 'imu_sensor' on link 'imu_link': gyro bias_mean" in printed
    text = out.read_text()
    assert "#   gazebo sensor 'imu_sensor' on link 'imu_link' -> imu_sensor" in text
    assert parse_yaml(text, str(out)) == import_model(path).mapping
    for written, direct in zip(load_scene(out).imus, load_scene(path).imus, strict=True):
        assert (written.name, written.body, written.rate, written.seed) == (direct.name, direct.body, direct.rate, 0)
        assert np.array_equal(written.position, direct.position)
        assert np.array_equal(written.orientation, direct.orientation)
