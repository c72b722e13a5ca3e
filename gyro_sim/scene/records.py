"""Scene description: the validated, immutable form of a scene file (docs/scene-format.md).

`load_scene` (in :mod:`gyro_sim.scene.load`) turns a YAML file or a dict into these
records; everything downstream (model compilation, logs) reads only these records.
All vectors are float numpy arrays of shape (3,) in the frame the SPEC names; a body's
vectors are in its own frame (origin at its joint point O^k, z-axis = its axis).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

JOINT_TYPES = ("spherical", "hinge", "slide")
#: the joints of one coordinate: a hinge turns about its axis, a slide translates along it
ONE_AXIS_JOINTS = ("hinge", "slide")
BASE_TYPES = ("fixed", "moving", "free")
ROTOR_MODES = ("torque", "speed")


#: default speed (rad/s) below which Coulomb friction is linear in the speed (Basilisk's
#: omegaLimitCycle): friction is then a continuous function of the speed
DEFAULT_STICK_SPEED = 1e-4


@dataclass(frozen=True, eq=False)
class Friction:
    """Friction of a torque rotor's bearing or of a hinge, as a function of the relative speed
    w (rad/s) of the axis (docs/scene-format.md, "Actuator limits and friction").

    F(w) = sqrt(2 e) (static - coulomb) exp(-(w / b)^2 / 2) w / (b sqrt 2)
           + coulomb tanh(10 w / b) + viscous w                    (b = stribeck_speed given)
    F(w) = coulomb sgn(w) + viscous w                              (otherwise)
    and F(w) = F(stick_speed) w / stick_speed for |w| < stick_speed; the torque is -F(w).

    A friction with neither `stick_speed` nor the Stribeck term written is exact Coulomb friction
    (`exact`): its viscous part stays in F, its coulomb is the bound of a stick/slip torque that
    the time-stepping of :mod:`gyro_sim.integrators.coulomb.driver` solves.
    """

    coulomb: float = 0.0  # N m
    viscous: float = 0.0  # N m s/rad
    static: float | None = None  # N m, peak of the Stribeck term (with stribeck_speed)
    stribeck_speed: float | None = None  # rad/s
    stick_speed: float | None = None  # rad/s; None: not written (DEFAULT_STICK_SPEED where regularised)

    @property
    def exact(self) -> bool:
        """Whether its Coulomb part is exact (neither stick_speed nor Stribeck written)."""
        return self.stick_speed is None and self.stribeck_speed is None and self.coulomb > 0.0


@dataclass(frozen=True, eq=False)
class Limits:
    """Limits and friction of an actuated axis (a torque rotor or a hinge); None: no limit."""

    max_torque: float | None = None  # N m: a command is saturated to +-max_torque
    max_speed: float | None = None  # rad/s, rotors: a torque driving |kappa_i'| past it is cut
    friction: Friction | None = None

    @property
    def speed_dependent(self) -> bool:
        """Whether the applied torque depends on the axis's speed (friction, max_speed)."""
        return self.friction is not None or self.max_speed is not None


@dataclass(frozen=True, eq=False)
class Rotor:
    """A balanced, axially symmetric rotor on a carrier (docs/theory.md section 1)."""

    name: str
    axis: np.ndarray  # (3,) unit vector e_i in the carrier frame
    position: np.ndarray  # (3,) h_i: the rotor's centre from O^k, carrier frame
    mass: float  # m_i
    axial_inertia: float  # A_i about its own centre
    transverse_inertia: float  # B_i about its own centre
    mode: str  # "torque" (spin p_i integrates L_i / A_i) | "speed" (kappa_i' prescribed)
    spin: float  # torque: initial absolute spin p_i; speed: kappa_i'
    actuated: bool  # torque rotors only: the axial torque L_i is a commanded axis moment
    limits: Limits | None = None  # torque rotors only


@dataclass(frozen=True, eq=False)
class Spring:
    """A hinge's torsion spring: the moment -stiffness (phi - reference) about its axis."""

    stiffness: float  # N m/rad
    reference: float = 0.0  # rad: the angle where the spring is relaxed


@dataclass(frozen=True, eq=False)
class Servo:
    """A hinge's affine actuator (MuJoCo's motor, position, velocity and general with a fixed
    gain and an affine bias): the actuator force f = gain clip(ctrl, ctrl_range) + b0 + b1 gear
    phi + b2 gear phi', clipped to force_range; the joint's moment gear f (docs/models.md,
    "Servo actuators")."""

    name: str  # the control's name (the actuator's), unique among the scene's servos
    gain: float  # per unit of ctrl
    bias: tuple[float, float, float]  # b0, b1, b2
    gear: float = 1.0
    ctrl_range: tuple[float, float] | None = None  # None: the control is not clipped
    force_range: tuple[float, float] | None = None  # None: the force is not clipped
    control: float = 0.0  # the control from the start and after a reset, until one is set

    @property
    def command(self) -> str:
        """What a JointState command sets: "position" (b1 != 0), "velocity" (b2 != 0) or
        "effort" (a motor)."""
        return "position" if self.bias[1] != 0.0 else "velocity" if self.bias[2] != 0.0 else "effort"


@dataclass(frozen=True, eq=False)
class Motor:
    """A hinge's geared motor: a rotor on the parent body, spinning about `axis` (fixed in the
    parent) at gear times the joint's rate relative to the parent (docs/theory.md, "The geared
    motor"). Its mass and transverse inertia are the parent body's; its axial inertia is added
    to the parent's inertia operator by the model."""

    inertia: float  # J, the rotor's axial moment of inertia (kg m^2), > 0
    gear: float  # G, the rotor's rate relative to the parent over the joint's rate, != 0
    axis: np.ndarray  # (3,) unit axis a of the rotor in the parent's frame


@dataclass(frozen=True, eq=False)
class Joint:
    """The joint at O^k between body k's parent (or the base) and body k."""

    type: str  # "spherical" | "hinge" | "slide"
    #: hinge and slide: (3,) unit axis in the parent's frame (a slide translates along it)
    axis: np.ndarray | None = None
    #: hinge and slide (max_torque, friction; a slide's in N and m/s). Here and below, "hinge
    #: only" means a joint of one axis, hinge or slide
    limits: Limits | None = None
    #: hinge only: a reflected rotor inertia (kg m^2) on the joint's own diagonal of the mass
    #: matrix (MuJoCo's armature, docs/theory.md "Armature and joint springs")
    armature: float = 0.0
    spring: Spring | None = None  # hinge only
    servo: Servo | None = None  # hinge only: its actuator, commanded by a control (not an axis moment)
    motor: Motor | None = None  # hinge only: its geared motor's rotor, on the parent
    #: (3,) the joint point O^k from O^parent in the parent's frame (from the base's position in
    #: the world frame on the base); None: the parent's next_joint (the base's position)
    at: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class Initial:
    """Initial state of one body's joint, as written in the scene.

    Spherical joints give either Euler angles (psi, theta, phi) with their rates, or a
    quaternion (w, x, y, z; world from body) with a body-frame angular velocity. Exactly one
    of the two forms is set (the loader fills the Euler form with zeros when neither is
    given). Hinge joints give `angle` and `rate`, slide joints `position` and `velocity`.
    """

    euler: np.ndarray | None = None  # (3,) psi, theta, phi
    euler_rates: np.ndarray | None = None  # (3,) psi', theta', phi'
    quaternion: np.ndarray | None = None  # (4,) unit, w first
    angular_velocity: np.ndarray | None = None  # (3,) body frame
    angle: float = 0.0  # hinge
    rate: float = 0.0  # hinge
    position: float = 0.0  # slide: d_k (m) along its axis
    velocity: float = 0.0  # slide: d_k' (m/s)


@dataclass(frozen=True, eq=False)
class Body:
    """The carrier S_0^k of gyrostat k with its rotors."""

    name: str
    joint: Joint
    mass: float  # the carrier alone
    com: np.ndarray  # (3,) from O^k to the carrier's centre of mass
    inertia: np.ndarray  # (3, 3) carrier inertia about O^k, body frame, symmetric
    next_joint: np.ndarray | None  # (3,) s^k from O^k to O^{k+1}; None on a body without children
    rotors: tuple[Rotor, ...]
    initial: Initial
    visual_radius: float | None = None
    #: index of the parent body in the scene's bodies, -1: the base (docs/scene-format.md,
    #: `parent`); None: the body before it (the base for the first), as in a chain
    parent: int | None = None


@dataclass(frozen=True, eq=False)
class Base:
    """Where the chain hangs: O^1."""

    type: str  # "fixed" | "moving" | "free"
    position: np.ndarray  # (3,) O^1 in the world frame (initial position for "free")
    amplitude: np.ndarray | None = None  # moving: O^1 = position + amplitude sin(2 pi f t)
    frequency: float | None = None  # moving, Hz
    velocity: np.ndarray | None = None  # free: initial velocity of O^1, world frame


@dataclass(frozen=True, eq=False)
class Imu:
    """An inertial measurement unit fixed to a body (docs/scene-format.md, `imus`).

    Noise densities are those of the continuous-time model (white noise and bias random walk,
    :mod:`gyro_sim.dynamics.imu`); zero means none.
    """

    name: str
    body: str  # the name of the body it is fixed to
    position: np.ndarray  # (3,) the IMU's point from O^k, body frame
    orientation: np.ndarray  # (4,) unit, w first: the rotation body from IMU (body_R_imu)
    rate: float | None  # samples per simulated second (Hz); None: the publish rate
    gyro_noise_density: float  # rad/s/sqrt(Hz)
    gyro_bias_instability: float  # rad/s^2/sqrt(Hz): density of the gyro bias random walk
    accel_noise_density: float  # m/s^2/sqrt(Hz)
    accel_bias_instability: float  # m/s^3/sqrt(Hz): density of the accelerometer bias random walk
    seed: int  # of the IMU's own random generator


@dataclass(frozen=True, eq=False)
class Scene:
    """A whole validated scene. `source` is the mapping it was loaded from (for logs)."""

    name: str
    gravity: np.ndarray | None  # (3,) world frame, m/s^2; None when the file has no gravity
    base: Base
    bodies: tuple[Body, ...]
    source: dict[str, Any] = field(default_factory=dict, compare=False)
    path: str | None = None
    imus: tuple[Imu, ...] = ()
    robot: Any = None  # gyro_sim.scene.robot.RobotDescription of a URDF model; None otherwise
