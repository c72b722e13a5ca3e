"""Limits and friction of the actuated axes: torque rotors and hinges (docs/scene-format.md,
"Actuator limits and friction").

Three terms, after Basilisk's reaction wheels (`reactionWheelStateEffector`):

- saturation: a commanded moment is clipped to +-max_torque. A function of the command alone,
  applied where commands become inputs (`Simulator._inputs`): no cost in the dynamics.
- speed limit (rotors): a motor torque that would drive the rotor's spin relative to its
  carrier, kappa_i', past max_speed is cut. Basilisk cuts it to zero once |kappa_i'| >=
  max_speed; here the cut is a continuous ramp over the last `MAX_SPEED_BAND` of max_speed
  (full torque below max_speed (1 - MAX_SPEED_BAND), none at max_speed), so that the
  right-hand side stays continuous and adaptive methods step through it without a switching
  surface.
- friction: -F(w) with w the axis's relative speed (kappa_i' of a rotor, phi_k' of a hinge) and
  F Basilisk's Stribeck/Coulomb/viscous form (:class:`gyro_sim.scene.records.Friction`),
  made linear below stick_speed as Basilisk does (its omegaLimitCycle). Basilisk switches
  the Stribeck term on only when the wheel starts from rest (a flag carried between control
  steps); here F is one function of the speed, the Stribeck term included whenever written,
  so that the motion is an ODE the integrators solve to their tolerance.

The speed-dependent terms (friction, max_speed) make the applied torque a function of the
state: a scene that has them carries the torque rotors' absolute spins p_i and the work of the
applied torques in its state vector (`gyro_sim.dynamics.model`, `i_spin`, `i_work`), and
the dynamics evaluates the torques at every stage: the numpy reference
(`gyro_sim.dynamics.reference.applied_torques`) and the compiled kernel
(`gyro_sim.dynamics.kernel.actuate`, its parameters in the workspace's tail). A scene
without them takes the held-input path unchanged.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gyro_sim.errors import GyroSimError
from gyro_sim.scene.records import DEFAULT_STICK_SPEED, Limits

class ActuatorError(GyroSimError, ValueError):
    """A scene's actuator terms that the method asked for does not take (one line naming the
    scene key)."""


#: the speed limit's cut is a linear ramp over this fraction of max_speed below it
MAX_SPEED_BAND = 1e-3
#: Basilisk's Stribeck constants: the tanh's sharpness (10 / stribeck_speed) and the peak
#: scale sqrt(2 e) / sqrt(2) that makes the Stribeck term equal static - coulomb at w = b
STRIBECK_TANH = 10.0
STRIBECK_PEAK = math.sqrt(2.0 * math.e) / math.sqrt(2.0)


@dataclass(frozen=True)
class AxisLimits:
    """Limits and friction of a set of axes (torque rotors, or hinges), arrays (n,).

    max_torque and max_speed are +inf where absent; stribeck_speed is 0 where there is no
    Stribeck term (static is then unused).
    """

    max_torque: np.ndarray
    max_speed: np.ndarray
    coulomb: np.ndarray
    viscous: np.ndarray
    static: np.ndarray
    stribeck_speed: np.ndarray
    stick_speed: np.ndarray
    saturates: bool  # some max_torque is finite
    speed_dependent: bool  # some friction in F, or max_speed
    exact: np.ndarray | None = None  # (n,) bounds of exact Coulomb friction; None: no axis has one

    @classmethod
    def of(cls, limits: list[Limits | None], exact: bool = False) -> "AxisLimits":
        """The arrays of `limits`; with `exact` a friction that is `Friction.exact` puts its
        coulomb in `exact` instead of F."""
        n = len(limits)
        a = {k: np.zeros(n) for k in ("coulomb", "viscous", "static", "stribeck_speed")}
        max_torque, max_speed, stick = np.full(n, np.inf), np.full(n, np.inf), np.ones(n)
        bound = np.zeros(n)
        dependent = False
        for i, lim in enumerate(limits):
            if lim is None:
                continue
            if lim.max_torque is not None:
                max_torque[i] = lim.max_torque
            if lim.max_speed is not None:
                max_speed[i] = lim.max_speed
            f = lim.friction
            dependent = dependent or lim.max_speed is not None
            if f is not None:
                a["coulomb"][i], a["viscous"][i] = f.coulomb, f.viscous
                stick[i] = DEFAULT_STICK_SPEED if f.stick_speed is None else f.stick_speed
                if f.stribeck_speed is not None:
                    a["static"][i], a["stribeck_speed"][i] = f.static, f.stribeck_speed
                if exact and f.exact:  # what stays in F: the viscous part
                    bound[i], a["coulomb"][i] = f.coulomb, 0.0
                    dependent = dependent or f.viscous > 0.0
                else:
                    dependent = True
        return cls(max_torque=max_torque, max_speed=max_speed, stick_speed=stick,
                   saturates=bool(np.any(np.isfinite(max_torque))), speed_dependent=dependent,
                   exact=bound if np.any(bound) else None, **a)

    def saturate(self, command: np.ndarray) -> np.ndarray:
        """The commands clipped to +-max_torque (a new array)."""
        return np.clip(command, -self.max_torque, self.max_torque)

    def friction(self, w: np.ndarray) -> np.ndarray:
        """The friction torque -F(w) (n,) on each axis at relative speeds w (n,)."""
        stick = np.abs(np.real(w)) < self.stick_speed  # real parts decide: w may be complex (linearisation)
        return -_friction_force(self, np.where(stick, self.stick_speed, w)) * np.where(stick, w / self.stick_speed, 1.0)

    def cut(self, torque: np.ndarray, w: np.ndarray) -> np.ndarray:
        """Motor torques (n,) with the speed limit applied at relative speeds w (n,): a torque that
        drives |w| up is scaled by the ramp of MAX_SPEED_BAND below max_speed."""
        band = MAX_SPEED_BAND * self.max_speed
        with np.errstate(invalid="ignore"):  # inf / inf where there is no limit: the where's other side
            # |w| as w sign(w) and the clip by real parts: the same for real w, analytic for
            # the complex w of the linearisation's complex step
            ramp = (self.max_speed - w * np.sign(np.real(w))) / band
            ramp = np.where(np.real(ramp) <= 0.0, 0.0, np.where(np.real(ramp) >= 1.0, 1.0, ramp))
        ramp = np.where(np.isfinite(self.max_speed), ramp, 1.0)
        return np.where(np.real(torque * w) > 0.0, torque * ramp, torque)


def _friction_force(limits: AxisLimits, w: np.ndarray) -> np.ndarray:
    """F(w) of Basilisk's friction (without the linear region below stick_speed)."""
    b = limits.stribeck_speed
    stribeck = b > 0.0
    bb = np.where(stribeck, b, 1.0)
    x = w / bb
    with_stribeck = (STRIBECK_PEAK * (limits.static - limits.coulomb) * np.exp(-0.5 * x * x) * x
                     + limits.coulomb * np.tanh(STRIBECK_TANH * x))
    return np.where(stribeck, with_stribeck, limits.coulomb * np.sign(np.real(w))) + limits.viscous * w


@dataclass(frozen=True)
class Actuators:
    """The limits of a model's torque rotors (nt,) and hinges (nh,)."""

    rotor: AxisLimits
    hinge: AxisLimits
    #: the speed-dependent terms written, "<axis>.<key>" (for messages)
    terms: tuple[str, ...] = ()
    #: the model has servos (docs/models.md, "Servo actuators"): their force depends on the
    #: state, and their work is integrated with the motion as the motors' is
    servos: bool = False

    @property
    def speed_dependent(self) -> bool:
        """Whether any applied torque depends on the state (friction, max_speed, a servo)."""
        return self.rotor.speed_dependent or self.hinge.speed_dependent or self.servos

    @property
    def exact(self) -> bool:
        """Whether some hinge or torque rotor has exact Coulomb friction (`AxisLimits.exact`)."""
        return self.hinge.exact is not None or self.rotor.exact is not None
