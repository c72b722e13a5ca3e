"""Whole integration loops compiled with numba: many steps in one call of compiled code.

:func:`erk_march` takes `nsteps` equal steps of an explicit Runge-Kutta tableau (the method's
own class attributes, e.g. :class:`gyro_sim.integrators.rk4.driver.RK4`) from (t0, y), calling
the articulated-body kernel :func:`gyro_sim.dynamics.kernel.rhs_kernel` (through its compiled C
function, `fast.rhs_call`: the kernel is compiled once, not into each loop) and the tableau's
arithmetic of :mod:`gyro_sim.integrators.rk4.kernels` (the very functions the Python driver of the
method calls for other systems): no Python between two evaluations. After every step the
quaternions are renormalised (`project`) and the state checked finite, as
:class:`gyro_sim.integrators.base.FixedStepIntegrator` does.

:class:`gyro_sim.dynamics.system.FastChainODE` offers it as `march_explicit_rk`; the fixed-step
integrators dispatch to it when their system has it.

Caching: numba's disk cache keys a kernel on its own file only (numba docs, "Cache
limitations"), and these loops inline functions of fast.py and rk_kernels.py: cached the
usual way, a loop would survive an edit of those files and run stale code. So their cache
lives in a directory named after a digest of all three files (:func:`cache_directory`): an
edit of any of them starts an empty one. Compiling costs ~0.6 s once per version (the kernel
itself, its C function, ~12 s: `fast.kernel_address`).
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path

from gyro_sim.dynamics import kernel as fast
from gyro_sim.integrators.rk4 import kernels as rk_kernels
from gyro_sim.integrators.rk4.kernels import erk_stage_state, erk_update

try:
    import numba
except ImportError:  # pragma: no cover - exercised only where numba is missing
    numba = None

def cache_directory(files) -> Path:
    """Where kernels compiled from `files` (paths) are cached: `fast_loop-<digest of the files>`
    under NUMBA_CACHE_DIR when set, else under this package's __pycache__ (if writable), else
    under ~/.cache/gyro_sim."""
    digest = hashlib.sha256(b"".join(Path(p).read_bytes() for p in files)).hexdigest()[:16]
    if numba is not None and numba.config.CACHE_DIR:
        base = Path(numba.config.CACHE_DIR)
    else:
        base = Path(__file__).parent / "__pycache__"
        if not os.access(base if base.exists() else base.parent, os.W_OK):
            base = Path.home() / ".cache" / "gyro_sim"
    return base / f"fast_loop-{digest}"


def njit_with_dependencies(*files):
    """A decorator: compiled in nopython mode (IEEE arithmetic, numpy's error model, as
    gyro_sim.dynamics.kernel), cached on disk in :func:`cache_directory` of `files`, the files of
    every kernel the function compiles in (its own included): an edit of any starts afresh."""

    def decorate(fn):
        if numba is None:
            return fn
        saved = numba.config.CACHE_DIR
        numba.config.CACHE_DIR = str(cache_directory(files))  # read when the dispatcher is made
        try:
            return numba.njit(cache=True, error_model="numpy")(fn)
        finally:
            numba.config.CACHE_DIR = saved

    return decorate


def cfunc_with_dependencies(signature, *files, **options):
    """A decorator: compiled as a C function of `signature` (numba.cfunc: its `address` is what
    compiled code calls, `gyro_sim.dynamics.kernel.call_address`), in nopython mode with numpy's error
    model, cached on disk in :func:`cache_directory` of `files` (as `njit_with_dependencies`).
    Compiles (or loads) when applied: apply it when the function is first needed."""

    def decorate(fn):
        saved = numba.config.CACHE_DIR
        numba.config.CACHE_DIR = str(cache_directory(files))  # read when the cache is made
        try:
            return numba.cfunc(signature, cache=True, error_model="numpy", **options)(fn)
        finally:
            numba.config.CACHE_DIR = saved

    return decorate


class Direct:
    """A compiled kernel called without numba's per-call type dispatch: the first call goes
    through the dispatcher (compiling or loading), later calls straight to the compiled
    entry point of that first call's signature (numba resolves the types of every argument on
    every call otherwise: ~0.3 us an argument, 5-10 us for the kernels here).

    The caller guarantees that every later call passes arguments of the first call's types
    (dtype, dimensions, C-contiguous arrays; float and int scalars): the entry point converts,
    it does not check. Without numba, the plain function is called.
    """

    def __init__(self, kernel):
        self.kernel = kernel
        self.entry = None

    def __call__(self, *args):
        if self.entry is not None:
            return self.entry(*args)
        out = self.kernel(*args)
        if numba is not None:
            signature = tuple(numba.typeof(a) for a in args)
            self.entry = self.kernel.overloads[signature].entry_point
        return out


#: the files whose kernels the loops compile in (the key of their cache directory)
DEPENDENCIES = (Path(fast.__file__), Path(rk_kernels.__file__), Path(__file__))
_njit = njit_with_dependencies(*DEPENDENCIES)


@_njit
def finite(y):
    """True when every entry of y (size,) is finite (the loops' test of a new state)."""
    for i in range(y.shape[0]):
        if not (abs(y[i]) < float("inf")):
            return False
    return True


@_njit
def erk_march(t0, h, nsteps, y, A, B, C, K, ys, i_q0, nq,
              work, is_hinge, qrow, own_col, col_start, hinge_axis, s, mass, first_moment,
              inertia, lam_speed, torque_body, torque_axis, torque_A, flags, base,
              ht0, p0, pdot, L_rotor, tau):
    """`nsteps` steps of size h of the explicit tableau (A, B, C) from (t0, y), y (size,) in
    place; step k starts at t0 + k h. K (stages, size), ys (size,): scratch.

    After each step: quaternions y[i_q0 + 4 j : +4], j < nq, renormalised; the state checked.
    Returns the number of steps completed with a finite state: nsteps, or k < nsteps when step
    k left a non-finite state (y is then that state). The arguments from `work` on are those of
    fast.rhs_kernel (`ht0` its `t0`, the start of the hold).
    """
    stages = B.shape[0]
    hA = A * h
    hB = B * h
    for k in range(nsteps):
        t = t0 + k * h
        fast.rhs_call(t, y, K[0], work, is_hinge, qrow, own_col, col_start, hinge_axis, s, mass,
                        first_moment, inertia, lam_speed, torque_body, torque_axis, torque_A,
                        flags, base, ht0, p0, pdot, L_rotor, tau)
        for st in range(1, stages):
            erk_stage_state(y, K, hA, st, ys)
            fast.rhs_call(t + C[st] * h, ys, K[st], work, is_hinge, qrow, own_col, col_start,
                            hinge_axis, s, mass, first_moment, inertia, lam_speed, torque_body,
                            torque_axis, torque_A, flags, base, ht0, p0, pdot, L_rotor, tau)
        erk_update(y, K, hB)
        fast.normalize_quaternions(y, i_q0, nq)
        if not finite(y):
            return k
    return nsteps
