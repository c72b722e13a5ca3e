"""What the outside sees of a simulation at one instant: one typed record per publication.

`Simulator.snapshot` fills it; :mod:`gyro_sim.msgs.messages` turns it into every message (joint
states, wrenches, poses, /tf, /clock, diagnostics), for the node and for offline logs alike.
Parts nobody asked for are None and are not computed.

Work and energy balance
-----------------------
Commanded axis moments are internal moments (hinge motors between body k-1 and body k, rotor
motors between a carrier and its rotor), so they change the energy but not the momenta. Their
power is the moment times the relative rate of the axis it drives: tau * phi' for a hinge,
L * kappa' for a rotor (eqs 18-19). Under the zero-order hold the moment is constant over an
`advance`, so the work of that call is exactly moment * (change of the axis angle): the
Simulator sums it in `work`. Then

    energy_balance = E(t) - E(0) - W(t)

is conserved with or without commands wherever the energy is conserved without them
(fixed base, no speed rotors): the drift a user wants to watch on a commanded chain.
With actuator friction (docs/scene-format.md) its work W_f <= 0 (the energy dissipated) is
integrated with the motion and counted apart: energy_balance = E(t) - E(0) - W(t) - W_f(t).
A servo's moment depends on the state: its work (moment x joint rate) is integrated with the
motion too, and is part of W.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np


@dataclass(frozen=True)
class Snapshot:
    """The simulation's outputs at simulated time `time` (since the last reset).

    Arrays are copies owned by the snapshot. `n`: bodies; `J`: joint-state entries.
    """

    time: float
    joint_names: tuple[str, ...]
    position: np.ndarray  # (J,) Euler angles, hinge angles, rotor angles (rad)
    velocity: np.ndarray  # (J,)
    effort: np.ndarray  # (J,) moments applied over the last step (N m)
    axis_names: tuple[str, ...]
    axis_moments: np.ndarray  # (na,) commanded moments in force (N m)
    integrator: str
    error_estimate: float | None  # local error of the last step / tolerance (adaptive methods)
    body_names: tuple[str, ...]
    body_position: np.ndarray | None = None  # (n, 3) O^k, world
    body_quaternion: np.ndarray | None = None  # (n, 4) w, x, y, z: world from body
    wrench_force: np.ndarray | None = None  # (n, 3) R^k (eq 40), body k's frame
    wrench_moment: np.ndarray | None = None  # (n, 3) L^k (eq 48), body k's frame
    invariants: Mapping[str, object] | None = None  # gyro_sim.dynamics.invariants.invariants
    drift: Mapping[str, float] | None = None  # conserved invariant -> relative drift since reset
    work: float | None = None  # work of the commanded moments since reset (J)
    energy_balance: float | None = None  # E - E(0) - W (J); None where E is not conserved
    energy_scale: float | None = None  # what energy_balance is relative to (J)
    method: str | None = None  # the method stepping now, when the integrator chooses ("fixed")
    method_reason: str | None = None  # why that one (one line)
    substeps: int | None = None  # its substeps of one physics step (a fast-turning body is resolved)
    h_lambda: float | None = None  # the chooser's last estimate of h |lambda| (step x largest |eigenvalue|)
    #: "fixed" over its real-time budget: calls kept beyond the energy watchdog's limit since the
    #: reset, and the sum of their energy errors (each relative to the kinetic energy)
    budget_calls: int | None = None
    budget_energy_error: float | None = None
    friction_work: float | None = None  # work of actuator friction since reset (J, <= 0); scenes with limits
    saturated_commands: int | None = None  # commanded moments clipped to max_torque since reset
    #: the compiled outputs found every number of the arrays they computed (joint states, poses,
    #: wrenches) finite as they wrote them: `nonfinite` need not look at those again
    arrays_checked: bool = field(default=False, repr=False, compare=False)

    def nonfinite(self) -> str | None:
        """The name of the first field holding NaN or infinity (None when all are finite)."""
        names = ("axis_moments",) if self.arrays_checked else (
            "position", "velocity", "effort", "axis_moments", "body_position", "body_quaternion", "wrench_force",
            "wrench_moment")
        for name in names:
            v = getattr(self, name)
            if v is not None and v.size and not np.all(np.isfinite(v)):
                return name
        for name in ("time", "error_estimate", "work", "energy_balance", "h_lambda", "friction_work",
                     "budget_energy_error"):
            v = getattr(self, name)
            if v is not None and not math.isfinite(v):
                return name
        for group in ("invariants", "drift"):
            for key, v in (getattr(self, group) or {}).items():
                if not np.all(np.isfinite(v)):
                    return f"{group}.{key}"
        return None


@dataclass(frozen=True)
class Scatter:
    """Where `Simulator.snapshot(into=...)` also writes the numbers it computes: float64 slots of
    one flat buffer (e.g. the bytes of every message of a publication, gyro_sim.msgs.messages), so
    that nothing is copied between the outputs and what leaves. Each index array holds c copies
    (c = 0: not written); the parts with slots must be asked of the snapshot.

    dst : (m,) float64, contiguous and 8-byte aligned
    joint : (c, 3, J) int64, slots of the joint states' position, velocity, effort
    position : (c, n, 3) int64, slots of body_position
    quaternion : (c, n, 4) int64, slots of body_quaternion (w, x, y, z)
    wrench : (c, n, 6) int64, slots of wrench_force, then wrench_moment
    """

    dst: np.ndarray
    joint: np.ndarray
    position: np.ndarray
    quaternion: np.ndarray
    wrench: np.ndarray

    def __post_init__(self) -> None:
        d = self.dst
        if d.dtype != np.float64 or d.ndim != 1 or not d.flags.c_contiguous or not d.flags.aligned:
            raise ValueError("dst must be a contiguous, aligned float64 vector")
        for name, ndim, last in (("joint", 3, None), ("position", 3, 3), ("quaternion", 3, 4), ("wrench", 3, 6)):
            a = getattr(self, name)
            if a.dtype != np.int64 or a.ndim != ndim or not a.flags.c_contiguous or (last and a.shape[-1] != last):
                raise ValueError(f"{name}: expected a contiguous int64 array (c, ..., {last or 'J'})")
            if a.size and (a.min() < 0 or a.max() >= d.size):
                raise ValueError(f"{name}: slots outside dst")

    def write(self, snap: Snapshot) -> None:
        """The snapshot's numbers into their slots (what the compiled outputs do as they compute)."""
        d = self.dst
        for c in range(self.joint.shape[0]):
            for i, v in enumerate((snap.position, snap.velocity, snap.effort)):
                d[self.joint[c, i]] = v
        for c in range(self.position.shape[0]):
            d[self.position[c]] = snap.body_position
        for c in range(self.quaternion.shape[0]):
            d[self.quaternion[c]] = snap.body_quaternion
        for c in range(self.wrench.shape[0]):
            d[self.wrench[c, :, :3]] = snap.wrench_force
            d[self.wrench[c, :, 3:]] = snap.wrench_moment
