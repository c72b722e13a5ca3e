"""First integrals and other monitors of the motion, from the state alone.

- energy: T + V, T by eq (33) summed over the chain, V = -g . sum m^k r_c^k; the hinges'
  armatures add 1/2 a phi'^2 to T, their geared motors phi' J G a . w^{k-1} + 1/2 J G^2 phi'^2
  (and their rotors' spin J G phi' a to the parent's angular momentum), their springs
  1/2 k (phi - phi_ref)^2 to V.
  Conserved with a fixed base, no speed rotors and zero commands.
- angular_momentum_O1: the angular momentum vector about O^1 (3,), world frame.
- vertical_momentum: angular momentum about the vertical through O^1 (eq 79), component along
  the upward vertical -nu (+z without gravity). Conserved with a fixed base whose first joint
  is spherical (commands are internal moments).
- jacobi (scenes with speed rotors): T2 + V + sum_torque A_i p_i^2 / 2, the Jacobi integral of
  the rheonomic constraint kappa_i' = const: conserved when the energy is not; with commands
  it changes by their work, as the energy does without speed rotors.
- linear_momentum, angular_momentum (free base): total momentum and angular momentum about
  the chain's centre of mass; the latter is conserved under gravity, both without it.
- Lagrange chains (all spherical, axisymmetric, fixed base): the paper's own integrals
  (82), (85) from :mod:`gyro_sim.analytic.lagrange`, which check the two above independently.
"""
from __future__ import annotations

import numpy as np

from gyro_sim.dynamics.reference import Data, cross, joint_energy, lam, matvec
from gyro_sim.dynamics.model import Model


def balanced_energy(model: Model) -> str | None:
    """The integral whose balance the exact motion keeps: "energy" (E - E0 = the work of the
    commands, of the servos and of friction), or "jacobi" with speed rotors (J - J0 = the same
    work: the rheonomic constraint kappa_i' = const leaves the Lagrangian free of t, so the
    Jacobi integral changes by the power of the generalised forces alone, while the speed
    rotors' motors do work on the energy); None on a moving base."""
    if model.base_type == "moving":
        return None
    return "jacobi" if len(model.speed_body) else "energy"


def conserved(model: Model) -> tuple[str, ...]:
    """Names of the invariants the exact motion keeps in this scene (commands zero). Friction
    (gyro_sim.dynamics.actuators) dissipates the energy: no energy or Jacobi integral then (its
    balance, `balanced_energy`, still holds); it acts between two bodies of the chain or against
    the base, so the momenta below are kept as without it."""
    names = []
    energy = balanced_energy(model)
    dissipates = model.actuators is not None and any(t.endswith(".friction") for t in model.actuators.terms)
    if energy is not None and not dissipates and model.servo is None:  # a servo works on the chain
        names.append(energy)
    if model.base_type == "fixed" and not model.is_hinge[0]:
        names.append("vertical_momentum")
    if model.free:
        names.append("angular_momentum")
        if model.gravity is None:
            names.append("linear_momentum")
    return tuple(names)


def invariants(model: Model, data: Data, p: np.ndarray | None, t: float, y: np.ndarray | None = None) -> dict:
    """All monitors of the current kinematics in `data` (positions and velocities filled) of
    state y (needed only for the hinges' armatures and springs)."""
    m, h, J, w, v = model.mass, data.h, data.J, data.w, data.v_o
    lam_w, _ = lam(model, data, p, None)
    ang = matvec(J, w) + cross(h, v)  # angular momentum about the origin, lambda excluded
    lin = m[:, None] * v + cross(w, h)
    # (33): 2T = w.A.w + 2 m v0.(w x c) + m v0^2 (here about the origin) + rotor terms
    T = 0.5 * float(np.sum(w * ang) + np.sum(v * lin))
    lam_speed_dot = 0.0
    if model.lam_speed is not None:
        lam_speed_dot = float(np.sum(w * matvec(data.R, model.lam_speed)))  # 2 sum A_i (w.e_i) kappa_i' / 2
        T += lam_speed_dot + 0.5 * float(np.sum(model.speed_A * model.speed_rate**2))
    if p is not None:
        T += 0.5 * float(np.sum(model.torque_A * p**2))
    V = 0.0 if model.gravity is None else -float(model.gravity @ h.sum(axis=0))
    if model.armature is not None or model.spring is not None or model.motor is not None:
        T_joint, V_joint = joint_energy(model, y, data)
        T, V = T + T_joint, V + V_joint
    out = {"energy": T + V, "kinetic": T, "potential": V}
    if model.lam_speed is not None:
        out["jacobi"] = T + V - lam_speed_dot - float(np.sum(model.speed_A * model.speed_rate**2))
    L = ang.sum(axis=0) + (0.0 if lam_w is None else lam_w.sum(axis=0))
    P = lin.sum(axis=0)
    O1 = data.O[0]
    up = -model.down[:, 2]
    H_O1 = L - cross(O1, P)  # angular momentum about O^1, rotors included
    out["angular_momentum_O1"] = H_O1
    out["vertical_momentum"] = float(up @ H_O1)  # (79)
    if model.free:
        rc = h.sum(axis=0) / m.sum()
        out["linear_momentum"] = P
        out["angular_momentum"] = L - cross(rc, P)
    return out


#: a drift is measured against max(scale, DRIFT_FLOOR): an integral whose scale is zero (a
#: chain at rest without gravity) still gets a finite, meaningful number
DRIFT_FLOOR = 1e-12


def drift_scale(name: str, reference: dict) -> float:
    """The magnitude a change of invariant `name` is measured against, from the reference values.

    Energies (energy, jacobi) against T + |V| at the reference, so that an energy near zero
    (potential measured from the joint) does not inflate the drift; momenta against the whole
    angular momentum about O^1 (a vertical component near zero is common); vectors against
    their norm.
    """
    ref = np.asarray(reference[name], dtype=float)
    scale = float(np.linalg.norm(ref))
    if name in ("energy", "jacobi"):
        scale = max(scale, abs(float(reference["kinetic"])) + abs(float(reference["potential"])))
    elif name == "vertical_momentum" and "angular_momentum_O1" in reference:
        scale = max(scale, float(np.linalg.norm(reference["angular_momentum_O1"])))
    return max(scale, DRIFT_FLOOR)


def relative_drift(name: str, reference: dict, value) -> float:
    """Change of invariant `name` since `reference`, relative to :func:`drift_scale`: signed
    for a scalar, the norm of the change for a vector."""
    d = np.asarray(value, dtype=float) - np.asarray(reference[name], dtype=float)
    change = float(d) if d.ndim == 0 else float(np.linalg.norm(d))
    return change / drift_scale(name, reference)
