"""Inertial measurement units fixed to bodies: what a gyro and an accelerometer read, and their noise.

An IMU sits at a point P of body k (``position`` r from O^k, body frame) with its own frame
turned by ``orientation`` (body_R_imu) from the body's. At one state it reads

- the gyro: the body's angular velocity w^k in the IMU frame, imu_R_world w^k;
- the accelerometer: the specific force at P, imu_R_world (a_P - g), a_P the acceleration
  of the body point P in the world and g the scene's gravity (0 without gravity): at rest
  under gravity it reads -g, "up";
- the orientation of the IMU frame in the world, world_R_body body_R_imu (w, x, y, z).

a_P comes from the accelerations one dynamics evaluation leaves (the ones the joint wrenches
R^k, L^k need), never from a second solve. The compiled outputs
(:func:`gyro_sim.dynamics.outputs.publication_kernel`) give the spatial acceleration of body k
about O^k, (alpha^k, a_s(O^k)), a_s the derivative of the spatial velocity's linear part; the
numpy reference (:class:`gyro_sim.dynamics.reference.Evaluation`) the same about the world
origin, a_s(O^k) = a_s(origin) + alpha x O^k. The acceleration of the body point P = O^k + r is

    a_P = a_s(O^k) + alpha x r + w x v(O^k) + w x (w x r)

(the spatial acceleration moved to P, plus w x v(P), v(P) = v(O^k) + w x r).

Noise: the continuous-time model of Gazebo's IMU sensor, Kalibr and Basilisk, sampled at the
IMU's rate f (one sample every 1/f simulated seconds). Each axis reads
``true + b_i + sigma_w n_i`` with white noise of density N, ``sigma_w = N sqrt(f)``, and a bias
that walks, ``b_i = b_{i-1} + sigma_b m_i`` from b_{-1} = 0, with random-walk density B,
``sigma_b = B / sqrt(f)``; n_i, m_i independent standard normals. The Allan deviation of such a
record is N / sqrt(tau) (slope -1/2) where the white noise dominates and B sqrt(tau / 3)
(slope +1/2) where the walk does. Sample i is the one of the simulated time t with
i = floor(t f + SAMPLE_TOLERANCE); its draws come from the IMU's own generator
(numpy ``Generator(PCG64(seed))``), 12 standard normals per sample in a fixed order (gyro
white x y z, accelerometer white x y z, gyro walk x y z, accelerometer walk x y z), sample
after sample: the noise of a sample depends only on the seed and its index, whoever asks and
how often, so a log re-simulates bit for bit. A reset of the simulator restarts every
generator.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from gyro_sim.errors import GyroSimError
from gyro_sim.dynamics.rotations import cross, matrix_to_quat, quat_to_matrix

#: a time within this fraction of a sample of the next IMU tick counts as on it (simulated
#: times are sums of steps: t f falls a few ulps short of a whole number)
SAMPLE_TOLERANCE = 1e-6
#: standard normals drawn per sample: white and walk, gyro and accelerometer, 3 axes each
DRAWS_PER_SAMPLE = 12
#: most samples drawn in one block when a caller skips ahead (memory bound; the sequence is the
#: same whatever the block size)
DRAW_BLOCK = 65536
#: samples drawn at once when `ImuNoise.at` is asked one sample after another (a publication's
#: IMU sample: one draw per DRAW_AHEAD samples instead of one per sample)
DRAW_AHEAD = 256
#: publish_rate / rate within this relative tolerance of a whole number counts as one
RATIO_RTOL = 1e-9
#: the rate of a scene's IMUs that give none, until `Simulator.set_imu_default_rate` (Hz): the
#: publish rate of the node's and of `gyro-sim run`'s defaults
DEFAULT_IMU_RATE = 100.0


def compiled_accelerations(scratch: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Views of alpha^k and a_s(O^k) (n, 3) in the scratch of
    :func:`gyro_sim.dynamics.outputs.publication_kernel` after a call that computed the
    accelerations (wrenches asked, or speed rotors): its block ``acc`` (n, 6) after I6, pb and
    dlam_b."""
    from gyro_sim.dynamics import outputs

    assert outputs.SCRATCH_PER_BODY == 51, \
        "publication_kernel's scratch changed: update compiled_accelerations' view of it"
    start = (36 + 6 + 3) * n
    acc = scratch[start:start + 6 * n].reshape(n, 6)
    return acc[:, :3], acc[:, 3:]


class ImuRateError(GyroSimError, ValueError):
    """An IMU's rate that the publications cannot sample (it must divide the publish rate)."""


@dataclass(frozen=True)
class ImuReading:
    """What one IMU reads at one instant (sensor_msgs/Imu's content).

    orientation : (4,) w, x, y, z: the IMU frame in the world (world from IMU), w >= 0
    angular_velocity : (3,) rad/s, IMU frame
    linear_acceleration : (3,) m/s^2, IMU frame: the specific force a_P - g
    """

    name: str
    time: float
    sample: int  # the sample's index (floor(time rate)): its noise draw
    orientation: np.ndarray
    angular_velocity: np.ndarray
    linear_acceleration: np.ndarray
    angular_velocity_variance: float  # (N_gyro)^2 rate: the white noise's per-sample variance
    linear_acceleration_variance: float  # (N_accel)^2 rate


def sample_index(t: float, rate: float) -> int:
    """The index of the IMU sample in force at simulated time t (see the module docstring)."""
    return int(math.floor(t * rate + SAMPLE_TOLERANCE))


def divides(rate: float, publish_rate: float) -> bool:
    """Whether publications every 1 / publish_rate simulated seconds can sample an IMU of
    `rate` (Hz): publish_rate / rate is a whole number (to RATIO_RTOL)."""
    ratio = publish_rate / rate
    return rate <= publish_rate * (1.0 + RATIO_RTOL) and abs(ratio - round(ratio)) <= RATIO_RTOL * ratio


def check_rates(scene, publish_rate: float) -> str | None:
    """Why the publications (every 1 / publish_rate simulated seconds) cannot sample the
    scene's IMUs, or None: each IMU's rate must divide the publish rate (an IMU without a rate
    samples at the publish rate)."""
    for i, imu in enumerate(scene.imus):
        if imu.rate is None:
            continue
        if not divides(imu.rate, publish_rate):
            return (f"imus[{i}].rate: {imu.rate:g} Hz must divide the publish rate {publish_rate:g} Hz "
                    f"(publish_rate / rate a whole number): IMUs are sampled at publications")
    return None


class ImuNoise:
    """The noise of one IMU: white noise plus a bias random walk (module docstring).

    Parameters
    ----------
    gyro_density, gyro_walk, accel_density, accel_walk : N and B of each sensor
    rate : samples per simulated second
    seed : of the generator
    """

    def __init__(self, gyro_density: float, gyro_walk: float, accel_density: float, accel_walk: float,
                 rate: float, seed: int):
        root = math.sqrt(rate)
        self.white = np.array([gyro_density * root] * 3 + [accel_density * root] * 3)
        self.walk = np.array([gyro_walk / root] * 3 + [accel_walk / root] * 3)
        self.seed = seed
        self.silent = not (np.any(self.white) or np.any(self.walk))
        self.reset()

    def reset(self) -> None:
        """Back to before the first sample: the generator seeded again, the bias zero."""
        self._generator = np.random.Generator(np.random.PCG64(self.seed))
        self._bias = np.zeros(6)
        self._index = -1  # the last sample given
        self._last = np.zeros(6)
        self._ahead = np.zeros((0, 6))  # drawn and not given yet: samples _index + 1, ...

    def _draw(self, count: int) -> np.ndarray:
        """The noise (count, 6) of the next `count` samples, drawn in one block: the bias summed
        sample after sample from the last one (numpy's accumulate is sequential), so that any
        split into blocks gives the same numbers bit for bit."""
        draws = self._generator.standard_normal((count, DRAWS_PER_SAMPLE))
        steps = np.empty((count + 1, 6))
        steps[0] = self._bias
        steps[1:] = draws[:, 6:] * self.walk
        bias = np.cumsum(steps, axis=0)[1:]
        self._bias = bias[-1]
        return bias + self.white * draws[:, :6]

    def _next(self, count: int, least: int = 1) -> np.ndarray:
        """The next samples, at most `count` (at least one): those drawn ahead first, else a new
        block of max(least, count) (at most DRAW_BLOCK), the rest kept ahead."""
        if not len(self._ahead):
            self._ahead = self._draw(min(max(count, least), DRAW_BLOCK))
        out, self._ahead = self._ahead[:count], self._ahead[count:]
        self._index += len(out)
        return out

    def at(self, index: int) -> np.ndarray:
        """The noise (6,) of sample `index` (gyro x y z, accelerometer x y z): the samples up to it
        are drawn in order (DRAW_AHEAD at a time when asked one by one: the same numbers); an
        index already passed gives the last one drawn again (a new copy)."""
        if self.silent or index <= self._index:
            return self._last.copy()
        while self._index < index:
            self._last = self._next(index - self._index, DRAW_AHEAD)[-1]
        return self._last.copy()

    def record(self, count: int) -> np.ndarray:
        """The noise (count, 6) of the next `count` samples, the numbers `at` gives one by one."""
        blocks = []
        while count > 0:
            blocks.append(self._next(count))
            count -= len(blocks[-1])
        if blocks:
            self._last = blocks[-1][-1]
        return np.concatenate(blocks) if blocks else np.zeros((0, 6))


class ImuSet:
    """The scene's IMUs compiled for the Simulator: where each sits, and its noise.

    Parameters
    ----------
    scene : the Scene (its `imus`)
    body_index : body name -> its index in the chain
    gravity : (3,) world, or None
    default_rate : the rate of IMUs whose scene gives none (Hz)
    """

    def __init__(self, scene, body_index: dict, gravity, default_rate: float):
        imus = scene.imus
        self.names = tuple(imu.name for imu in imus)
        self.body = np.array([body_index[imu.body] for imu in imus], dtype=np.intp)
        self.position = np.array([imu.position for imu in imus], dtype=float).reshape(-1, 3)
        self.body_R_imu = np.array([quat_to_matrix(imu.orientation) for imu in imus]).reshape(-1, 3, 3)
        self.gravity = np.zeros(3) if gravity is None else np.asarray(gravity, dtype=float)
        self.set_default_rate(scene, default_rate)

    def set_default_rate(self, scene, default_rate: float) -> None:
        """The rates (the scene's, else `default_rate`) and the noise made again for them."""
        if not (default_rate > 0 and math.isfinite(default_rate)):
            raise ValueError(f"the IMUs' default rate must be > 0 Hz, got {default_rate!r}")
        self.rates = tuple(imu.rate if imu.rate is not None else float(default_rate) for imu in scene.imus)
        self.noise = tuple(ImuNoise(imu.gyro_noise_density, imu.gyro_bias_instability, imu.accel_noise_density,
                                    imu.accel_bias_instability, rate, imu.seed)
                           for imu, rate in zip(scene.imus, self.rates))
        self.variances = tuple((imu.gyro_noise_density ** 2 * rate, imu.accel_noise_density ** 2 * rate)
                               for imu, rate in zip(scene.imus, self.rates))

    def reset(self) -> None:
        for noise in self.noise:
            noise.reset()

    def read(self, t: float, R: np.ndarray, w: np.ndarray, vO: np.ndarray, alpha: np.ndarray,
             a_s: np.ndarray) -> list[ImuReading]:
        """Every IMU's reading at time t from the bodies' R (n, 3, 3) world_R_body, w (n, 3),
        v(O^k) (n, 3), and their spatial accelerations about O^k: alpha (n, 3), a_s(O^k) (n, 3)
        (module docstring); world components. Noise added where the scene has some."""
        gyro, accel, world_R_imu = self.true_values(R, w, vO, alpha, a_s)
        out = []
        for j, name in enumerate(self.names):
            index = sample_index(t, self.rates[j])
            g, a = gyro[j], accel[j]
            noise = self.noise[j]
            if not noise.silent:
                e = noise.at(index)
                g, a = g + e[:3], a + e[3:]
            out.append(ImuReading(name, t, index, matrix_to_quat(world_R_imu[j]), g, a, *self.variances[j]))
        return out


    def true_values(self, R: np.ndarray, w: np.ndarray, vO: np.ndarray, alpha: np.ndarray,
                    a_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """What every IMU reads without noise, from the arguments of `read`: gyro (m, 3) and
        accelerometer (m, 3) in the IMU frames, and world_R_imu (m, 3, 3). Real or complex (the
        linearisation's outputs)."""
        k = self.body  # the arrays may be stacks (leading axes before the bodies' axis)
        Rk = R[..., k, :, :]
        r = np.einsum("...nij,nj->...ni", Rk, self.position)  # P - O^k, world
        wk = w[..., k, :]
        a_P = a_s[..., k, :] + cross(alpha[..., k, :], r) + cross(wk, vO[..., k, :]) + cross(wk, cross(wk, r))
        world_R_imu = Rk @ self.body_R_imu
        gyro = np.einsum("...nji,...nj->...ni", world_R_imu, wk)  # imu_R_world w
        accel = np.einsum("...nji,...nj->...ni", world_R_imu, a_P - self.gravity)
        return gyro, accel, world_R_imu


class ImuTicks:
    """When publications sample the IMUs: at the first publication of each new sample index
    (every publication whose time starts a sample; a reset, time going back, starts again).

    Parameters
    ----------
    rates : each IMU's rate (Hz)
    """

    def __init__(self, rates: Sequence[float]):
        self.rates = tuple(rates)
        self._last: list[int | None] = [None] * len(self.rates)
        self._time = -math.inf

    def due(self, t: float) -> list[int]:
        """The IMUs (indices) to publish at simulated time t, noted as published."""
        out = []
        back, self._time = t < self._time, t
        for j, rate in enumerate(self.rates):
            index = sample_index(t, rate)
            last = self._last[j]
            if back or last is None or index != last:
                out.append(j)
                self._last[j] = index
        return out
