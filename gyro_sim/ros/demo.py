"""The node's built-in demo commands (parameter ``demo``): a sine on every actuated axis, scaled
to the scene, so that a first run shows the chain moving without a second program.

Axis i gets ``A_i sin(2 pi f t + 2 pi i / n)`` (node time t, n axes): one frequency, the phases
spread so that the axes do not all push together. Its amplitude is the moment that would swing
a free body of the axis's effective inertia J_i through ``DEMO_ANGLE`` radians at that
frequency, ``A_i = J_i (2 pi f)^2 DEMO_ANGLE``. J_i is measured on the scene's own dynamics at
its initial state (`effective_inertias`): the change of the axis's rate under a short moment
of each sign, ``J_i = 2 tau T / (rate(+tau) - rate(-tau))``; gravity and the coupling to the
other axes cancel in the difference to first order.

The commands go through the node's command path (gyro_sim.ros.command_path): they are checked,
applied and logged on ~/axis_moments as any command is, so a log of a demo re-simulates like
any other. They stop for good at the first command received from outside.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: frequency of the demo's sines (Hz)
DEMO_FREQUENCY = 0.5
#: the swing (rad) a free body of the axis's effective inertia would make under the demo's moment
DEMO_ANGLE = 0.3
#: demo commands per simulated second (well above 1 / command_timeout for the default 0.5 s)
DEMO_RATE = 20.0
#: physics steps of each probe of an axis's effective inertia
PROBE_STEPS = 10
#: the probe's moment (N m), of each sign
PROBE_MOMENT = 1e-3


def effective_inertias(sim, dt: float) -> np.ndarray:
    """J_i (kg m^2) of every actuated axis at the initial state (module docstring). The
    Simulator is reset before and after. An axis whose rate the probe does not change (or
    changes by a non-finite amount) gets 0: no demo moment on it."""
    names = list(sim.joint_names)
    n = len(sim.axis_names)
    out = np.zeros(n)
    for i, axis in enumerate(sim.axis_names):
        j = names.index(axis)
        rates = []
        for sign in (1.0, -1.0):
            sim.reset()
            moments = np.zeros(n)
            moments[i] = sign * PROBE_MOMENT
            sim.set_axis_moments(moments)
            for _ in range(PROBE_STEPS):
                sim.advance(dt)
            rates.append(float(sim.joint_states().velocity[j]))
        change = rates[0] - rates[1]
        if math.isfinite(change) and change > 0:
            out[i] = 2.0 * PROBE_MOMENT * PROBE_STEPS * dt / change
    sim.reset()
    return out


@dataclass(frozen=True)
class Demo:
    """The demo profile: `moments(t)` at node time t (s)."""

    amplitudes: np.ndarray  # N m, one per axis
    frequency: float = DEMO_FREQUENCY

    @classmethod
    def for_scene(cls, sim, dt: float) -> "Demo":
        omega = 2.0 * math.pi * DEMO_FREQUENCY
        return cls(effective_inertias(sim, dt) * omega**2 * DEMO_ANGLE)

    def moments(self, t: float) -> list[float]:
        n = len(self.amplitudes)
        return [float(a * math.sin(2.0 * math.pi * (self.frequency * t + i / n)))
                for i, a in enumerate(self.amplitudes)]

    def describe(self, axis_names) -> str:
        amps = ", ".join(f"{a} {v:.3g}" for a, v in zip(axis_names, self.amplitudes))
        return f"demo: sines of {self.frequency:g} Hz on every axis, amplitudes (N m) {amps}, until a command arrives"
