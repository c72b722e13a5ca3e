"""Whole integration loops compiled with numba: many steps in one call of compiled code.

:func:`erk_march` takes `nsteps` equal steps of an explicit Runge-Kutta tableau (the method's
own class attributes, e.g. :class:`gyro_sim.integrators.rk4.driver.RK4`) from (t0, y), calling
the articulated-body kernel :func:`gyro_sim.dynamics.kernel.rhs_kernel` (through its compiled C
function, `fast.rhs_call`: the kernel is compiled once, not into each loop) and the tableau's
arithmetic of :mod:`gyro_sim.integrators.rk4.kernels` (the very functions the Python driver of the
method calls for other systems): no Python between two evaluations. After every step the
quaternions are renormalised (`project`) and the state checked finite, as
:class:`gyro_sim.integrators.base.FixedStepIntegrator` does.

:class:`ErkMarch` binds it to a compiled system (one with `kernel_arguments`, as
:class:`gyro_sim.dynamics.system.FastChainODE`); the explicit Runge-Kutta methods march with it
on such a system.

Caching: these loops inline functions of fast.py and rk_kernels.py, so their cache lives in a
directory keyed on all of them (:func:`gyro_sim.jit.njit_with_dependencies`): an edit of any
starts an empty one. Compiling costs ~0.6 s once per version (the kernel itself, its C
function, ~12 s: `fast.kernel_address`).
"""
from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np

from gyro_sim import jit
from gyro_sim.dynamics import kernel as fast
from gyro_sim.integrators.rk4 import kernels as rk_kernels
from gyro_sim.integrators.rk4.kernels import erk_stage_state, erk_update


#: the files whose kernels the loops compile in (the key of their cache directory)
DEPENDENCIES = (*fast.DEPENDENCIES, Path(rk_kernels.__file__), Path(__file__))
_njit = jit.njit_with_dependencies(*DEPENDENCIES)


@_njit
def finite(y):
    """True when every entry of y (size,) is finite (the loops' test of a new state)."""
    for i in range(y.shape[0]):
        if not (abs(y[i]) < float("inf")):
            return False
    return True


class Tableau(NamedTuple):
    """An explicit Runge-Kutta tableau: A (s, s), B (s,), C (s,)."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray


@_njit
def erk_march(t0, h, nsteps, y, tableau, K, ys, i_q0, nq, model, data, inputs):
    """`nsteps` steps of size h of the explicit tableau (a Tableau) from (t0, y), y (size,) in
    place; step k starts at t0 + k h. K (stages, size), ys (size,): scratch.

    After each step: quaternions y[i_q0 + 4 j : +4], j < nq, renormalised; the state checked.
    Returns the number of steps completed with a finite state: nsteps, or k < nsteps when step
    k left a non-finite state (y is then that state). model, data, inputs: fast.rhs_kernel's
    records.
    """
    A, B, C = tableau
    stages = B.shape[0]
    hA = A * h
    hB = B * h
    for k in range(nsteps):
        t = t0 + k * h
        fast.rhs_call(t, y, K[0], model, data, inputs)
        for st in range(1, stages):
            erk_stage_state(y, K, hA, st, ys)
            fast.rhs_call(t + C[st] * h, ys, K[st], model, data, inputs)
        erk_update(y, K, hB)
        fast.normalize_quaternions(y, i_q0, nq)
        if not finite(y):
            return k
    return nsteps


class ErkMarch:
    """:func:`erk_march` bound to a compiled `system` (its kernel arguments read at every call:
    they change with `hold`), called through `gyro_sim.jit.Direct` (the types stay the same).
    Counts the rhs evaluations in `system.nfev`."""

    def __init__(self, system):
        self.system = system
        self._i_q0, self._nq = (int(v) for v in system.quaternion_block())
        self._ys = np.empty(system.size)
        # per tableau (by its A) the kernel's copies of A, B, C and the stages K
        self._tableaus: dict[int, tuple] = {}
        self._march = jit.Direct(erk_march)

    def __call__(self, A: np.ndarray, B: np.ndarray, C: np.ndarray, t0: float, y: np.ndarray, h: float,
                 nsteps: int) -> int:
        """`nsteps` steps of size h of the explicit Runge-Kutta tableau (A (s, s), B (s,), C (s,))
        from (t0, y) in one compiled call, with the inputs held: y (size,), float64 and
        contiguous, updated in place and projected after every step. Returns the number of
        steps that left a finite state (nsteps, or the index of the step that did not; y then
        holds its result)."""
        size = self.system.size
        if y.shape != (size,) or y.dtype != np.float64 or not y.flags.c_contiguous:
            raise ValueError(f"y must be a contiguous float64 array of shape ({size},)")
        tableau = self._tableaus.get(id(A))
        if tableau is None or tableau[0] is not A:  # the kernel's types, checked once per tableau
            stages = len(B)
            if np.shape(A) != (stages, stages) or np.shape(C) != (stages,):
                raise ValueError("A must be (s, s), B and C (s,)")
            tableau = self._tableaus[id(A)] = (A, Tableau(*(np.array(x, dtype=np.float64) for x in (A, B, C))),
                                               np.empty((stages, size)))
        _, compiled, K = tableau
        done = self._march(float(t0), float(h), int(nsteps), y, compiled, K,
                           self._ys, self._i_q0, self._nq, *self.system.kernel_arguments())
        self.system.nfev += len(compiled.B) * min(done + 1, nsteps)
        return done

    def warm_up(self, t0: float, y: np.ndarray) -> None:
        """Compile the loop (or load it from the disk cache) by a march of no step from a copy
        of y (any tableau: zero steps compile the loop for every tableau)."""
        one = np.zeros((1, 1))
        self(one, one[0], one[0], t0, np.array(y, dtype=np.float64), 1.0, 0)
