"""The node's fixed-step method for a scene: rk4 where it is stable at the step, gauss4 where
the scene is stiff (issue 10, item 2).

RK4 is stable for h lambda inside its stability region, which reaches RK4_IMAG_LIMIT = 2 sqrt 2
along the imaginary axis (gyroscopic nutation: eigenvalues +-i w) and 2.785 along the negative
real axis (Hairer, Wanner, "Solving Ordinary Differential Equations II", 2nd ed., Springer 1996,
sec. IV.2, Fig. 2.1). The scene's largest |lambda| is estimated at the initial state, with the
commands held, from Krylov (Arnoldi) iterations on Jacobian-vector products of the rhs by
forward differences: O(size) memory, at most KRYLOV_DIM + 1 rhs evaluations, and exact (up to
the differences) when size <= KRYLOV_DIM. rk4 is chosen when h |lambda| stays below
RK4_SAFETY x RK4_IMAG_LIMIT (the margin covers the estimate and the motion moving the
eigenvalues); otherwise gauss4, A-stable, whose Newton iteration is the remaining limit.

    name, reason = fixed_step_method(sim, 1e-3)   # ("rk4", "rk4: h |lambda| = 0.12 ...")
"""
from __future__ import annotations

import math
import numpy as np

from .base import EPS

#: RK4's stability limit on the imaginary axis, |h lambda| <= 2 sqrt 2
RK4_IMAG_LIMIT = 2.0 * math.sqrt(2.0)
#: rk4 only below this fraction of its limit
RK4_SAFETY = 0.5
#: most Krylov vectors (rhs evaluations) for the eigenvalue estimate
KRYLOV_DIM = 30
#: relative size of the finite-difference perturbation, sqrt(machine epsilon)
JVP_REL_STEP = math.sqrt(EPS)
#: an Arnoldi vector below this norm (relative) ends the Krylov space early (invariant subspace)
BREAKDOWN = 1e-12


def spectral_radius_estimate(rhs, t: float, y: np.ndarray, dim: int = KRYLOV_DIM) -> float:
    """Largest |eigenvalue| of d rhs / dy at (t, y), y (size,): Ritz values of `dim` Arnoldi
    steps on forward-difference Jacobian-vector products (dim + 1 rhs calls, (dim, size) memory).
    """
    y = np.asarray(y, dtype=float)
    n = y.size
    m = min(dim, n)
    f0 = np.array(rhs(t, y), dtype=float)  # a copy: rhs may return its workspace
    eps = JVP_REL_STEP * max(1.0, float(np.linalg.norm(y)))
    V = np.zeros((m + 1, n))
    H = np.zeros((m + 1, m))
    v = np.random.default_rng(0).standard_normal(n)  # fixed seed: the same choice every time
    V[0] = v / np.linalg.norm(v)
    k = m
    for j in range(m):
        w = (np.asarray(rhs(t, y + eps * V[j]), dtype=float) - f0) / eps  # J V[j]
        for i in range(j + 1):  # modified Gram-Schmidt
            H[i, j] = V[i] @ w
            w -= H[i, j] * V[i]
        H[j + 1, j] = np.linalg.norm(w)
        if not np.isfinite(H[: j + 2, j]).all():
            return math.inf
        if H[j + 1, j] <= BREAKDOWN * max(1.0, np.abs(H[: j + 1, j]).max()):
            k = j + 1
            break
        V[j + 1] = w / H[j + 1, j]
    return float(np.abs(np.linalg.eigvals(H[:k, :k])).max())


def fixed_step_method(sim, dt: float) -> tuple[str, str]:
    """The fixed-step integrator for the scene of `sim` (a gyro_sim.core.simulator.Simulator;
    not imported: the integrators know the simulator by its attributes only) at step `dt` (s), and a one-line reason.

    Returns ("rk4", "rk4: h |lambda| = 0.12 (stable below 1.4)") when dt times the estimated
    largest |eigenvalue| of the rhs's Jacobian at the current state (commands held) is below
    RK4_SAFETY x RK4_IMAG_LIMIT, else ("gauss4", "gauss4: h |lambda| = 35: stiff for rk4 ...").
    Call it on a Simulator just built or reset (the node chooses at start): the rhs is held
    with the scene's own rotor spins and no commanded moments. `sim` is not advanced.
    """
    if not (dt > 0 and math.isfinite(dt)):
        raise ValueError(f"dt must be a positive finite number, got {dt!r}")
    m = sim.model
    p0 = m.torque_p0.copy() if len(m.torque_body) else None
    sim.system.hold(sim.time, p0, None, None)  # the reset state's inputs, as advance holds them
    lam = spectral_radius_estimate(sim.system.rhs, sim.time, sim.state)
    hl, limit = dt * lam, RK4_SAFETY * RK4_IMAG_LIMIT
    if hl < limit:
        return "rk4", f"rk4: h |lambda| = {hl:.2g} (stable below {limit:.2g})"
    return "gauss4", (f"gauss4: h |lambda| = {hl:.2g}: stiff for rk4 "
                      f"(rk4 needs below {limit:.2g} at h = {dt:g} s)")
