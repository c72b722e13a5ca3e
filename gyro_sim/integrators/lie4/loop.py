"""The lie4 march compiled with numba: `nsteps` steps of the commutator-free Lie group method
CF4 in one call.

:func:`lie_march` is the Python driver :meth:`gyro_sim.integrators.lie4.driver.Lie4._step` (with
the base's projection and finiteness check) statement for statement, calling the
articulated-body kernel :func:`gyro_sim.dynamics.kernel.rhs_kernel` (through its compiled C function,
`fast.rhs_call`) and the arithmetic of
:mod:`gyro_sim.integrators.lie4.kernels` (the very functions the Python driver calls): no Python
between two evaluations, and the same steps bit for bit (test/core/test_fast_lie.py).
:class:`LieMarch` binds it to a :class:`gyro_sim.dynamics.system.FastChainODE` through the
system's public `kernel_arguments()` and `quaternion_block()`; `Lie4` uses it when its system
offers them.

Caching: the march inlines fast.py and lie_kernels.py, so its numba cache lives in a directory
keyed on all the files it compiles in (:func:`gyro_sim.jit.njit_with_dependencies`): an edit of
any of them starts an empty one.
"""
from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np

from gyro_sim.dynamics import kernel as fast
from gyro_sim import jit
from gyro_sim.integrators.rk4 import loop as fast_loop
from gyro_sim.integrators.lie4 import kernels as lk

#: the files the march compiles in (the key of its cache directory)
DEPENDENCIES = (*fast.DEPENDENCIES, Path(lk.__file__), Path(fast_loop.__file__), Path(__file__))
_njit = jit.njit_with_dependencies(*DEPENDENCIES)


class Method(NamedTuple):
    """CF4's coefficients (lie_kernels): ALPHA (stages, stages), BASE (stages,) int, BETA
    (3, stages) = (B, BETA1, BETA2), C (stages,)."""

    ALPHA: np.ndarray
    BASE: np.ndarray
    BETA: np.ndarray
    C: np.ndarray


class Layout(NamedTuple):
    """Where the state's parts are: qi (nq, 4) the quaternion blocks, li (nl,) the other
    components, the quaternions y[i_q0 + 4 j : +4], j < nq (their renormalisation)."""

    qi: np.ndarray
    li: np.ndarray
    i_q0: int
    nq: int


class Scratch(NamedTuple):
    """Y (stages, size), F (size,), W (stages, nq, 3), V (stages, nl)."""

    Y: np.ndarray
    F: np.ndarray
    W: np.ndarray
    V: np.ndarray


@_njit
def lie_march(t0, h, nsteps, y, method, layout, scratch, model, data, inputs):
    """`nsteps` CF4 steps of size h from (t0, y), y (size,) in place; step k starts at
    t0 + k h. method (Method): the coefficients; layout (Layout): the quaternion blocks and the
    other components of y; scratch (Scratch).

    After each step: quaternions y[i_q0 + 4 j : +4], j < nq, renormalised; the state checked.
    Returns the number of steps completed with a finite state: nsteps, or k < nsteps when step
    k left a non-finite state (y is then that state). model, data, inputs: fast.rhs_kernel's
    records.
    """
    ALPHA, BASE, BETA, C = method
    qi, li, i_q0, nq = layout
    Y, F, W, V = scratch
    stages = C.shape[0]
    hALPHA = ALPHA * h
    hBETA = BETA * h
    for k in range(nsteps):
        t = t0 + k * h
        lk.lie_start(y, Y)
        fast.rhs_call(t, Y[0], F, model, data, inputs)
        lk.lie_field(Y, F, 0, qi, li, W, V)
        for st in range(1, stages):
            lk.lie_stage(Y, W, V, hALPHA, st, BASE[st], qi, li)
            fast.rhs_call(t + C[st] * h, Y[st], F, model, data, inputs)
            lk.lie_field(Y, F, st, qi, li, W, V)
        lk.lie_update(y, W, V, hBETA, qi, li)
        fast.normalize_quaternions(y, i_q0, nq)
        if not fast_loop.finite(y):
            return k
    return nsteps


class LieMarch:
    """:func:`lie_march` bound to a FastChainODE `system` and a method's coefficients (the
    kernel arguments read at every call: they change with `hold`); called through
    `jit.Direct` (the types stay the same). Counts the rhs evaluations in
    `system.nfev`, as `gyro_sim.integrators.rk4.loop.ErkMarch` does.

    qi (nq, 4), li (nl,) int64: the integrator's quaternion blocks and other components, which
    must be the system's `quaternion_block()` (the renormalisation's blocks)."""

    def __init__(self, system, qi, li, ALPHA, BASE, BETA, C):
        self.system = system
        i_q0, nq = system.quaternion_block()
        if not np.array_equal(np.asarray(qi).ravel(), i_q0 + np.arange(4 * nq)):
            raise ValueError("the quaternion blocks are not the system's quaternion_block()")
        self._qi = np.ascontiguousarray(qi, dtype=np.int64)
        self._li = np.ascontiguousarray(li, dtype=np.int64)
        self._i_q0, self._nq = int(i_q0), int(nq)
        self._ALPHA = np.array(ALPHA, dtype=np.float64)
        self._BASE = np.array(BASE, dtype=np.int64)
        self._BETA = np.array(BETA, dtype=np.float64)
        self._C = np.array(C, dtype=np.float64)
        self._F = np.empty(system.size)
        self._method = Method(self._ALPHA, self._BASE, self._BETA, self._C)
        self._layout = Layout(self._qi, self._li, self._i_q0, self._nq)
        self._march = jit.Direct(lie_march)

    def __call__(self, t0, y, h, nsteps, Y, W, V) -> int:
        """Steps completed with a finite state of `nsteps` steps (see lie_march); Y (stages,
        size), W (stages, nq, 3), V (stages, nl) float64 scratch."""
        if y.shape != (self.system.size,) or y.dtype != np.float64 or not y.flags.c_contiguous:
            raise ValueError(f"y must be a contiguous float64 array of shape ({self.system.size},)")
        done = self._march(float(t0), float(h), int(nsteps), y, self._method, self._layout,
                           Scratch(Y, self._F, W, V), *self.system.kernel_arguments())
        self.system.nfev += self._C.shape[0] * min(done + 1, nsteps)
        return int(done)
