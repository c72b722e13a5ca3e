"""The compiled part of the exact Coulomb friction's stepping (gyro_sim.integrators.coulomb.driver):
the joint-space inverse mass of the friction axes, as the accelerations' responses to unit
moments, in one call of compiled code (one evaluation of the kernel per axis, no Python between)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from gyro_sim import jit
from gyro_sim.dynamics import kernel as fast

#: the files whose kernels `responses` compiles in (the key of its cache directory)
DEPENDENCIES = (*fast.DEPENDENCIES, Path(__file__))
_njit = jit.njit_with_dependencies(*DEPENDENCIES)


@_njit
def responses(t, y, cols, i_vel, out, ydot, model, data, inputs):
    """The generalised accelerations' responses (N, nf) `out` at (t, y) to a unit moment on each
    velocity column `cols[j]`, by one evaluation of the kernel with the moments held and one with
    each unit moment added (the accelerations are affine in them); returns nothing. ydot (size,)
    holds y' with the moments held. model, data, inputs: the kernel's records."""
    size = y.shape[0]
    N = out.shape[0]
    base = np.empty(N)
    fast.rhs_call(t, y, ydot, model, data, inputs)
    for i in range(N):
        base[i] = ydot[i_vel + i]
    other = np.empty(size)
    for j in range(cols.shape[0]):
        c = cols[j]
        held = inputs.tau[c]
        inputs.tau[c] = held + 1.0
        fast.rhs_call(t, y, other, model, data, inputs)
        inputs.tau[c] = held
        for i in range(N):
            out[i, j] = other[i_vel + i] - base[i]
