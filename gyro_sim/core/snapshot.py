"""What the outside sees of a simulation at one instant: one typed record per publication.

`Simulator.snapshot` fills it; :mod:`gyro_sim.io.messages` turns it into every message (joint
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
"""
from __future__ import annotations

from dataclasses import dataclass
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
    invariants: Mapping[str, object] | None = None  # gyro_sim.core.invariants.invariants
    drift: Mapping[str, float] | None = None  # conserved invariant -> relative drift since reset
    work: float | None = None  # work of the commanded moments since reset (J)
    energy_balance: float | None = None  # E - E(0) - W (J); None where E is not conserved
    energy_scale: float | None = None  # what energy_balance is relative to (J)
    method: str | None = None  # the method stepping now, when the integrator chooses ("fixed")
    method_reason: str | None = None  # why that one (one line)
    h_lambda: float | None = None  # the chooser's last estimate of h |lambda| (step x largest |eigenvalue|)

    def nonfinite(self) -> str | None:
        """The name of the first field holding NaN or infinity (None when all are finite)."""
        for name in ("position", "velocity", "effort", "axis_moments", "body_position", "body_quaternion",
                     "wrench_force", "wrench_moment"):
            v = getattr(self, name)
            if v is not None and not np.all(np.isfinite(v)):
                return name
        for name in ("time", "error_estimate", "work", "energy_balance", "h_lambda"):
            v = getattr(self, name)
            if v is not None and not np.isfinite(v):
                return name
        for group in ("invariants", "drift"):
            for key, v in (getattr(self, group) or {}).items():
                if not np.all(np.isfinite(v)):
                    return f"{group}.{key}"
        return None
