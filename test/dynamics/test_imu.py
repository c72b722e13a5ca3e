"""IMUs on bodies (docs/scene-format.md, `imus[j]`): the loader's refusals, the readings against
finite differences of the poses and closed forms, both backends, and the noise's Allan deviation."""
from __future__ import annotations

import copy
import math

import numpy as np
import pytest

from gyro_sim.dynamics.imu import ImuNoise, ImuTicks, check_rates, sample_index
from gyro_sim.dynamics.rotations import quat_to_matrix
from gyro_sim.scene.load import SceneError, load_scene
from gyro_sim.simulator import Simulator

G = 9.81

#: a hinge chain with a spherical link and commanded moments, IMUs off the joint points, turned
CHAIN = {
    "name": "imu chain",
    "gravity": [0.0, 0.0, -G],
    "base": {"type": "fixed", "position": [0.0, 0.0, 1.0]},
    "bodies": [
        {"name": "arm1", "joint": {"type": "spherical"}, "mass": 0.6, "com": [0.0, 0.0, 0.1],
         "inertia": {"axial": 1.2e-4, "transverse": 8.06e-3}, "next_joint": [0.0, 0.0, 0.2],
         "initial": {"euler": [0.0, 0.7, 0.0], "euler_rates": [1.5, 0.3, 2.0]}},
        {"name": "arm2", "joint": {"type": "hinge", "axis": [1.0, 0.0, 0.0]}, "mass": 0.3,
         "com": [0.0, 0.0, 0.075], "inertia": {"axial": 3.4e-5, "transverse": 2.3e-3},
         "rotors": [{"name": "wheel", "axis": [0.0, 0.0, 1.0], "position": [0.0, 0.0, 0.1], "mass": 0.1,
                     "axial_inertia": 4.5e-5, "transverse_inertia": 2.4e-5, "mode": "torque", "spin": 50.0,
                     "actuated": True}],
         "initial": {"angle": 0.4, "rate": -1.0}},
    ],
    "imus": [
        {"name": "imu1", "body": "arm1", "position": [0.03, -0.02, 0.15], "orientation": [0.9, 0.1, 0.3, -0.2]},
        {"name": "imu2", "body": "arm2", "position": [0.01, 0.04, 0.12]},
    ],
}
#: commanded moments (wheel, arm2's hinge): the accelerations depend on them
MOMENTS = [0.01, -0.02]


def with_imus(scene: dict, imus: list) -> dict:
    out = copy.deepcopy(scene)
    out["imus"] = imus
    return out


def errors(scene: dict) -> list[str]:
    with pytest.raises(SceneError) as info:
        load_scene(scene)
    return info.value.errors


# --- the loader -------------------------------------------------------------------------------------


def test_imus_load_with_their_defaults():
    scene = load_scene(with_imus(CHAIN, [{"name": "a", "body": "arm2"}, CHAIN["imus"][0]]))
    a, b = scene.imus
    assert (a.body, a.rate, a.seed, a.gyro_noise_density, a.accel_bias_instability) == ("arm2", None, 0, 0.0, 0.0)
    assert np.array_equal(a.position, np.zeros(3)) and np.array_equal(a.orientation, [1, 0, 0, 0])
    assert math.isclose(np.linalg.norm(b.orientation), 1.0)
    assert load_scene(CHAIN | {"imus": None}).imus == ()


@pytest.mark.parametrize("imus, path, rule", [
    ([{"name": "a", "body": "nobody"}], "imus[0].body", "no body named 'nobody'"),
    ([{"name": "a", "body": "arm1"}, {"name": "a", "body": "arm2"}], "imus[1].name", "duplicate name 'a'"),
    ([{"name": "arm1", "body": "arm1"}], "imus[0].name", "is a body's name"),
    ([{"name": "a", "body": "arm1", "gyro_noise_density": -1e-3}], "imus[0].gyro_noise_density", "must be >= 0"),
    ([{"name": "a", "body": "arm1", "accel_bias_instability": float("nan")}], "imus[0].accel_bias_instability",
     "must be finite"),
    ([{"name": "a", "body": "arm1", "position": [0.0, float("inf"), 0.0]}], "imus[0].position[1]", "must be finite"),
    ([{"name": "a", "body": "arm1", "rate": 0.0}], "imus[0].rate", "must be > 0"),
    ([{"name": "a", "body": "arm1", "rate": float("nan")}], "imus[0].rate", "must be finite"),
    ([{"name": "a", "body": "arm1", "orientation": [0, 0, 0, 0]}], "imus[0].orientation", "zero vector"),
    ([{"name": "a", "body": "arm1", "seed": -1}], "imus[0].seed", "must be an integer"),
    ([{"name": "a", "body": "arm1", "seed": 1.5}], "imus[0].seed", "must be an integer"),
    ([{"name": "a", "body": "arm1", "sead": 1}], "imus[0].sead", "unknown key (did you mean 'seed'?)"),
    ([{"body": "arm1"}], "imus[0].name", "required key missing"),
    ({"name": "a"}, "imus", "must be a list of IMUs"),
])
def test_bad_imus_are_refused_naming_the_key(imus, path, rule):
    assert any(e.startswith(f"{path}: ") and rule in e for e in errors(with_imus(CHAIN, imus))), \
        errors(with_imus(CHAIN, imus))


# --- the readings -----------------------------------------------------------------------------------


def simulator(scene, backend="numpy", **kw) -> Simulator:
    sim = Simulator(scene, backend=backend, integrator="dop853", rtol=1e-13, atol=1e-14, **kw)
    sim.set_axis_moments(MOMENTS)
    return sim


def point_and_frame(sim: Simulator):
    """World position of each IMU's point and world_R_imu, from the poses (body_states)."""
    states = {b.name: b for b in sim.body_states()}
    out = []
    for imu in sim.scene.imus:
        b = states[imu.body]
        out.append((b.position + b.rotation @ imu.position, b.rotation @ quat_to_matrix(imu.orientation),
                    b.quaternion))
    return out


def finite_difference_errors(h: float) -> np.ndarray:
    """(IMU, [gyro, accelerometer]) largest deviation of the readings at t = 0.3 s from the
    central differences of step h of the poses (body_states), relative to the magnitude."""
    sim = simulator(CHAIN)
    sim.advance(0.3 - h)
    before = point_and_frame(sim)
    sim.advance(h)
    now = point_and_frame(sim)
    readings = sim.imus()
    sim.advance(h)
    after = point_and_frame(sim)
    g = np.array([0.0, 0.0, -G])
    out = []
    for (p0, _, q0), (p1, R1, q1), (p2, _, q2), reading in zip(before, now, after, readings):
        # world_R_body' = [w]x world_R_body: w from the skew part of (R2 - R0) R1^T / 2h
        Rb0, Rb1, Rb2 = quat_to_matrix(q0), quat_to_matrix(q1), quat_to_matrix(q2)
        W = (Rb2 - Rb0) / (2 * h) @ Rb1.T
        w = np.array([W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1]]) / 2
        f = (p2 - 2 * p1 + p0) / h ** 2 - g
        out.append([np.abs(reading.angular_velocity - R1.T @ w).max() / np.linalg.norm(w),
                    np.abs(reading.linear_acceleration - R1.T @ f).max() / np.linalg.norm(f)])
        assert np.allclose(quat_to_matrix(reading.orientation), R1, atol=1e-12)  # world_R_imu
        assert reading.orientation[0] >= 0
    return np.array(out)


def test_gyro_and_accelerometer_match_finite_differences_of_the_poses():
    """Gyro: the body's angular velocity from the central difference of its orientation; the
    accelerometer: the second difference of the IMU point's position, minus gravity; both in the
    IMU frame, from body_states (not from the accelerations the IMU uses). The deviation is the
    differences' truncation: O(h^2), a quarter when h halves (the integration's, rtol 1e-13,
    is far below), so the readings are the limit."""
    coarse, fine = finite_difference_errors(2e-4), finite_difference_errors(1e-4)
    assert np.all(fine < 3e-6), fine
    assert np.all((coarse / fine > 3.5) & (coarse / fine < 4.5)), coarse / fine


def test_both_backends_give_the_same_readings():
    pytest.importorskip("numba")
    out = []
    for backend in ("numpy", "numba"):
        sim = simulator(CHAIN, backend)
        sim.advance(0.2)
        out.append(sim.imus())
        # the same again, after a publication with wrenches (its accelerations reused)
        sim.snapshot()
        assert [r.linear_acceleration.tolist() for r in sim.imus()] == \
            [r.linear_acceleration.tolist() for r in out[-1]]
    for a, b in zip(*out):
        assert a.name == b.name
        for field in ("orientation", "angular_velocity", "linear_acceleration"):
            x, y = getattr(a, field), getattr(b, field)
            assert np.allclose(x, y, rtol=1e-11, atol=1e-11 * max(1.0, np.abs(x).max())), field


#: a body spinning steadily about its symmetry axis: fixed point, no gravity
SPIN = 7.0
RADIUS = 0.05
SPINNER = {
    "name": "spinner",
    "base": {"type": "fixed"},
    "bodies": [{"name": "disc", "joint": {"type": "spherical"}, "mass": 1.0,
                "inertia": {"axial": 2e-3, "transverse": 1.5e-3},
                "initial": {"quaternion": [1.0, 0.0, 0.0, 0.0], "angular_velocity": [0.0, 0.0, SPIN]}}],
    "imus": [{"name": "rim", "body": "disc", "position": [RADIUS, 0.0, 0.02]},
             {"name": "rim_turned", "body": "disc", "position": [0.0, RADIUS, 0.0],
              "orientation": [math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4)]}],
}


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_a_steady_spin_reads_its_rate_and_the_centripetal_force(backend):
    """omega about z, the IMU at radius r: gyro (0, 0, omega), specific force omega^2 r towards
    the axis; an IMU turned 90 degrees about z reads it along its own -x."""
    if backend == "numba":
        pytest.importorskip("numba")
    sim = Simulator(SPINNER, backend=backend, integrator="dop853", rtol=1e-12, atol=1e-14)
    sim.advance(0.37)
    rim, turned = sim.imus()
    c = SPIN ** 2 * RADIUS
    assert np.allclose(rim.angular_velocity, [0.0, 0.0, SPIN], atol=1e-10)
    assert np.allclose(rim.linear_acceleration, [-c, 0.0, 0.0], atol=1e-9 * c)
    assert np.allclose(turned.angular_velocity, [0.0, 0.0, SPIN], atol=1e-10)
    # at (0, r, 0) the force points along the body's -y, which is the turned frame's -x
    assert np.allclose(turned.linear_acceleration, [-c, 0.0, 0.0], atol=1e-9 * c)
    angle = SPIN * 0.37  # the IMU frame turned about the world z by omega t
    assert np.allclose(quat_to_matrix(rim.orientation)[:2, 0], [math.cos(angle), math.sin(angle)], atol=1e-9)


#: a pendulum at rest hanging from a hinge: the accelerometer reads g "up", whatever the IMU's place
HANGING = {
    "name": "hanging",
    "gravity": [0.0, 0.0, -G],
    "base": {"type": "fixed"},
    "bodies": [{"name": "rod", "joint": {"type": "hinge", "axis": [1.0, 0.0, 0.0]}, "mass": 0.5,
                "com": [0.0, 0.0, -0.15], "inertia": {"axial": 1e-4, "transverse": 1.5e-2}}],
    "imus": [{"name": "tip", "body": "rod", "position": [0.02, 0.0, -0.3],
              "orientation": [math.cos(0.3), math.sin(0.3), 0.0, 0.0]}],
}


def test_a_body_at_rest_under_gravity_reads_minus_g():
    sim = Simulator(HANGING, backend="numpy")
    sim.advance(0.5)
    (tip,) = sim.imus()
    # the IMU frame is the body's turned by 0.6 rad about x: world up (0, 0, g) in it
    c, s = math.cos(0.6), math.sin(0.6)
    assert np.allclose(tip.linear_acceleration, [0.0, G * s, G * c], atol=1e-12)
    assert np.allclose(tip.angular_velocity, 0.0, atol=1e-14)


# --- the noise ---------------------------------------------------------------------------------------


def allan_deviation(x: np.ndarray, m: int) -> tuple[float, int]:
    """The non-overlapping Allan deviation of samples x at clusters of m samples, and the number
    of cluster differences it averages."""
    means = x[: len(x) // m * m].reshape(-1, m).mean(axis=1)
    d = np.diff(means)
    return math.sqrt(0.5 * np.mean(d * d)), len(d)


RATE = 100.0
N_GYRO, N_ACCEL = 1e-3, 2e-2


def test_white_noise_allan_deviation_at_one_second_is_the_density():
    """Allan deviation N / sqrt(tau): at tau = 1 s (100 samples), N. Each of the K cluster
    differences is an independent normal here, so the estimated Allan variance has the relative
    standard error sqrt(2 / K), the deviation half of it; the tolerance is 5 such errors."""
    samples = 1_000_000
    record = ImuNoise(N_GYRO, 0.0, N_ACCEL, 0.0, RATE, seed=11).record(samples)
    for axis, density in ((0, N_GYRO), (4, N_ACCEL)):
        for tau in (0.1, 1.0, 10.0):
            adev, k = allan_deviation(record[:, axis], int(tau * RATE))
            assert abs(adev / (density / math.sqrt(tau)) - 1) < 5 * math.sqrt(2 / k) / 2, (axis, tau, adev, k)


def test_bias_random_walk_allan_deviation_has_slope_one_half():
    """Allan deviation of a discrete random walk of step sigma_b = B / sqrt(f) at clusters of m
    samples: sigma_b sqrt((2 m^2 + 1) / (6 m)) -> B sqrt(tau / 3). Cluster differences two apart
    are independent (each spans two clusters' increments), so at least K / 2 of the K are:
    relative standard error of the deviation <= sqrt(2 / (K / 2)) / 2; tolerance 5 of those."""
    walk_gyro, walk_accel = 2e-4, 3e-3
    samples = 1_000_000
    record = ImuNoise(0.0, walk_gyro, 0.0, walk_accel, RATE, seed=5).record(samples)
    for axis, density in ((1, walk_gyro), (5, walk_accel)):
        for tau in (1.0, 10.0, 40.0):
            m = int(tau * RATE)
            sigma_b = density / math.sqrt(RATE)
            expected = sigma_b * math.sqrt((2 * m * m + 1) / (6 * m))
            adev, k = allan_deviation(record[:, axis], m)
            assert abs(adev / expected - 1) < 5 * math.sqrt(2 / (k / 2)) / 2, (axis, tau, adev / expected, k)
            assert math.isclose(expected, density * math.sqrt(tau / 3), rel_tol=1e-4)


def test_noise_depends_only_on_the_seed_and_the_sample():
    """The same numbers bit for bit whether the samples are drawn one by one, skipped over, or in
    blocks of any size."""
    whole = ImuNoise(1e-3, 1e-4, 1e-2, 1e-3, RATE, seed=3).record(2000)
    one = ImuNoise(1e-3, 1e-4, 1e-2, 1e-3, RATE, seed=3)
    assert np.array_equal(np.array([one.at(i) for i in range(2000)]), whole)
    skipping = ImuNoise(1e-3, 1e-4, 1e-2, 1e-3, RATE, seed=3)
    for i in (0, 1, 7, 500, 1999):
        assert np.array_equal(skipping.at(i), whole[i])
    assert np.array_equal(skipping.at(1999), whole[1999])  # the same sample asked again
    other = ImuNoise(1e-3, 1e-4, 1e-2, 1e-3, RATE, seed=4).record(10)
    assert not np.array_equal(other, whole[:10])


def test_a_body_at_rest_reads_the_noise_of_its_samples_and_a_reset_repeats_it():
    """A free body without gravity at rest: each sample reads the noise model's record exactly,
    with the white noise's variance in the readings; a reset starts the same record again."""
    scene = {"name": "still", "base": {"type": "free"},
             "bodies": [{"name": "box", "joint": {"type": "spherical"}, "mass": 1.0,
                         "inertia": {"axial": 1e-3, "transverse": 1e-3}}],
             "imus": [{"name": "imu", "body": "box", "rate": 50.0, "gyro_noise_density": N_GYRO,
                       "gyro_bias_instability": 1e-4, "accel_noise_density": N_ACCEL,
                       "accel_bias_instability": 1e-3, "seed": 9}]}
    sim = Simulator(scene, backend="numpy", integrator="rk4", step=0.02)
    expected = ImuNoise(N_GYRO, 1e-4, N_ACCEL, 1e-3, 50.0, seed=9).record(200)
    got = []
    for _ in range(200):
        (r,) = sim.imus()
        got.append(np.concatenate((r.angular_velocity, r.linear_acceleration)))
        sim.advance(0.02)
    assert np.array_equal(np.array(got), expected)
    assert math.isclose(r.angular_velocity_variance, N_GYRO ** 2 * 50.0)
    assert math.isclose(r.linear_acceleration_variance, N_ACCEL ** 2 * 50.0)
    sim.reset()
    (r,) = sim.imus()
    assert np.array_equal(np.concatenate((r.angular_velocity, r.linear_acceleration)), expected[0])


def test_sample_ticks_and_rates():
    assert sample_index(0.3, 10.0) == 3  # 0.3 * 10 = 2.9999999999999996
    ticks = ImuTicks([100.0, 25.0])
    due = [ticks.due(i * 0.01) for i in range(9)]
    assert due == [[0, 1], [0], [0], [0], [0, 1], [0], [0], [0], [0, 1]]
    assert ticks.due(0.0) == [0, 1]  # time went back: a reset
    scene = load_scene(with_imus(CHAIN, [{"name": "a", "body": "arm1", "rate": 30.0}]))
    assert check_rates(scene, 90.0) is None
    assert "imus[0].rate: 30 Hz must divide the publish rate 100 Hz" in check_rates(scene, 100.0)
    assert "must divide" in check_rates(scene, 20.0)


def test_a_scene_without_imus_runs_no_imu_code(monkeypatch, tmp_path):
    """No IMU object, no IMU message, and the IMU functions never called on its path."""
    from gyro_sim.dynamics import imu as imu_module
    from gyro_sim.log.mcap_log import read_info
    from gyro_sim.log.record import record_run

    def refuse(*args, **kwargs):
        raise AssertionError("IMU code ran for a scene without IMUs")

    for name in ("ImuSet", "ImuTicks", "check_rates", "compiled_accelerations", "sample_index"):
        monkeypatch.setattr(imu_module, name, refuse)
    scene = copy.deepcopy(CHAIN)
    del scene["imus"]
    sim = Simulator(scene, backend="numpy", integrator="rk4", step=1e-3)
    assert sim.imus() == [] and sim.imu_names == ()
    record_run(sim, tmp_path / "run.mcap", duration=0.05, publish_rate=100.0)
    assert not [t for t in read_info(tmp_path / "run.mcap").topics if "/imu/" in t]


def test_imus_reuse_the_evaluation_of_the_outputs():
    """After a snapshot of the same state and commands the IMUs evaluate no dynamics again
    (numba: no compiled call; numpy: no right-hand side); after a step or new commands, one."""
    pytest.importorskip("numba")
    sim = simulator(CHAIN, "numba")
    sim.advance(0.1)
    sim.snapshot()
    calls = []
    kernel = sim._outputs.kernel
    sim._outputs.kernel = lambda *args: calls.append(1) or kernel(*args)
    sim.imus()
    assert calls == []
    sim.advance(0.01)
    sim.imus()
    sim.imus()
    assert calls == [1]
    sim.set_axis_moments([0.0, 0.0])
    sim.imus()
    assert calls == [1, 1]

    sim = simulator(CHAIN, "numpy")
    sim.advance(0.1)
    sim.wrenches()
    rhs = sim.system.rhs
    evaluations = []
    sim.system.rhs = lambda *args, **kw: evaluations.append(1) or rhs(*args, **kw)
    sim.imus()
    assert evaluations == []
    sim.advance(0.01)
    evaluations.clear()
    sim.imus()
    sim.imus()
    assert evaluations == [1]


def test_noise_drawn_ahead_is_the_noise_drawn_sample_by_sample():
    """`at` draws DRAW_AHEAD samples at once when asked one after another: the same numbers as a
    record of them, across block boundaries, mixed with records, and again after a reset."""
    from gyro_sim.dynamics.imu import DRAW_AHEAD

    n = 3 * DRAW_AHEAD + 17
    whole = ImuNoise(1e-3, 1e-4, 1e-2, 1e-3, RATE, seed=9).record(n + 50)
    noise = ImuNoise(1e-3, 1e-4, 1e-2, 1e-3, RATE, seed=9)
    for _ in range(2):
        got = [noise.at(i) for i in range(n)]
        assert np.array_equal(np.array(got), whole[:n])
        assert np.array_equal(noise.record(50), whole[n:])  # what was drawn ahead first, then new draws
        noise.reset()
