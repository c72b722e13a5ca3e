"""Gauss-Legendre collocation, 2 stages (gauss4): order 4, fixed step, implicit.

A-stable, symplectic and conserving every quadratic invariant of the flow exactly (Hairer,
Lubich, Wanner, "Geometric Numerical Integration", 2nd ed., Springer 2006, sec. IV.2): the
norms |q|^2 of the quaternion blocks (q' = 1/2 (0, w) (x) q keeps them for any w), so
rotations stay on SO(3) without projection (`project` is still called, a no-op to round-off),
and the angular momentum of a free chain. For stiff (gyroscopic) scenes at the node's fixed
step, where rk4 goes unstable.

Nonlinear solve: simplified Newton on the stage increments Z (2, size), with the iteration
matrix I - h A (x) J from a finite-difference Jacobian J of the rhs, reused across steps and
refreshed only when the iteration slows (contraction rate above NEWTON_SLOW_RATE) or fails.
At most NEWTON_CAP iterations per attempt and one refresh per step, so a step costs at most
2 (NEWTON_CAP + 1) rhs evaluations plus one Jacobian (size evaluations): a known worst case.
A step that does not converge raises IntegrationError with the reason (never silent).

This first version keeps J dense, (size, size), and factors the (2 size)^2 iteration matrix
by LU: O(n^2) memory and O(n^3) per refresh. The chain's Jacobian is block-tridiagonal in
bodies; the structured solve is left to do.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from scipy.linalg import lu_factor, lu_solve

from .base import EPS, FixedStepIntegrator, IntegrationError, describe_nonfinite
from .radau import FD_MIN_SCALE, FD_REL_STEP

if TYPE_CHECKING:
    from ..system import OdeSystem

_S3 = math.sqrt(3.0)
#: most simplified-Newton iterations per attempt (an attempt with a fresh Jacobian follows once)
NEWTON_CAP = 8
#: contraction rate above which the iteration counts as slow: the Jacobian is refreshed
NEWTON_SLOW_RATE = 0.5
#: converged when the scaled Newton update is below this
NEWTON_TOL = 1e-12


class Gauss4(FixedStepIntegrator):
    """Two-stage Gauss-Legendre collocation, order 4, fixed step (see the module docstring).

    References
    ----------
    .. [1] E. Hairer, G. Wanner, "Solving Ordinary Differential Equations II", 2nd ed.,
           Springer 1996, sec. IV.5 (tableau, Table 5.1) and IV.8 (simplified Newton).
    .. [2] E. Hairer, C. Lubich, G. Wanner, "Geometric Numerical Integration", 2nd ed.,
           Springer 2006, sec. IV.2 (quadratic invariants).
    """

    name = "gauss4"
    order = 4
    n_stages = 2
    C = np.array([0.5 - _S3 / 6, 0.5 + _S3 / 6])
    A = np.array([[0.25, 0.25 - _S3 / 6], [0.25 + _S3 / 6, 0.25]])
    B = np.array([0.5, 0.5])
    #: y1 = y + D . Z: B^T A^-1 (no rhs evaluation at the stages' end)
    D = np.array([-_S3, _S3])

    def __init__(self, system: OdeSystem, **options):
        super().__init__(system, **options)
        self._J: np.ndarray | None = None
        self._lu = None
        self._lu_h: float | None = None
        self._Z = np.zeros((2, self.n))
        self.nrefresh = 0

    def reset(self) -> None:
        super().reset()
        self._J = None
        self._lu = None
        self._Z[:] = 0.0

    def _jacobian(self, t: float, y: np.ndarray) -> None:
        """J = d rhs / dy at (t, y) by forward differences (size evaluations)."""
        f0 = self._fun(t, y).copy()  # the rhs may return its workspace
        J = np.empty((self.n, self.n))
        yp = y.copy()
        for i in range(self.n):
            d = FD_REL_STEP * max(abs(y[i]), FD_MIN_SCALE)
            yp[i] = y[i] + d
            J[:, i] = (self._fun(t, yp) - f0) / d
            yp[i] = y[i]
        self._J = J
        self._lu = None
        self.njev += 1

    def _factor(self, h: float) -> None:
        n, J = self.n, self._J
        M = np.eye(2 * n)
        for i in range(2):
            for j in range(2):
                M[i * n:(i + 1) * n, j * n:(j + 1) * n] -= h * self.A[i, j] * J
        self._lu = lu_factor(M, overwrite_a=True, check_finite=False)
        self._lu_h = h
        self.nlu += 1

    def _solve(self, t: float, y: np.ndarray, h: float) -> tuple[bool, str]:
        """Simplified Newton on Z; True when converged (Z holds the stage increments)."""
        n, Z = self.n, self._Z
        scale = np.maximum(np.abs(y), 1.0)
        F = np.empty((2, n))
        prev = None
        Z[:] = 0.0
        for it in range(NEWTON_CAP):
            for s in range(2):
                F[s] = self._fun(t + self.C[s] * h, y + Z[s])
            if not np.isfinite(F).all():
                return False, f"rhs not finite at the stages ({describe_nonfinite(F)})"
            G = -(Z - h * (self.A @ F))
            dZ = lu_solve(self._lu, G.ravel(), check_finite=False).reshape(2, n)
            Z += dZ
            norm = math.sqrt(float(np.mean((dZ / scale) ** 2)))
            if norm <= NEWTON_TOL or norm <= 4 * EPS:
                return True, ""
            if prev is not None and prev > 0 and norm / prev > NEWTON_SLOW_RATE:
                return False, f"Newton iteration slow (rate {norm / prev:.2g} at iteration {it})"
            prev = norm
        return False, f"Newton iteration did not converge in {NEWTON_CAP} iterations (update {norm:.2g})"

    def _step(self, t: float, y: np.ndarray, h: float) -> None:
        if self._J is None:
            self._jacobian(t, y)
        if self._lu is None or self._lu_h != h:
            self._factor(h)
        ok, why = self._solve(t, y, h)
        if not ok:
            self._jacobian(t, y)  # the Jacobian is stale: refresh once
            self._factor(h)
            self.nrefresh += 1
            ok, why2 = self._solve(t, y, h)
            if not ok:
                raise IntegrationError(self.name, "Newton iteration failed", t, h,
                                       f"{why}; with a fresh Jacobian: {why2}")
        y += self.D @ self._Z
