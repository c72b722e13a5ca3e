"""The commutator-free Lie group Runge-Kutta method CF4 (lie4): order 4, fixed step."""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..rotations import quat_conj, quat_exp, quat_mul
from .base import FixedStepIntegrator

if TYPE_CHECKING:
    from ..system import OdeSystem

# Quaternion products as matrices, for stacks (nq, 4) at a few microseconds (rotations.quat_mul
# is the reference; these tensors are built from it). L(a) b = a (x) b with
# L(a) = (a @ _HAMILTON_LEFT).reshape(4, 4); and 2 vec(p (x) conj(q)) = G(q) p with
# G(q) = (q @ _OMEGA_OF_QDOT).reshape(3, 4).
_E4 = np.identity(4)
_HAMILTON_LEFT = (np.array([[quat_mul(ej, ek) for ek in _E4] for ej in _E4])
                  .transpose(0, 2, 1).reshape(4, 16))
_OMEGA_OF_QDOT = (2.0 * np.array([[quat_mul(ek, quat_conj(ej)) for ek in _E4] for ej in _E4])
                  .transpose(0, 2, 1)[:, 1:, :].reshape(4, 12))


def _quat_left(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a (x) b for stacks (nq, 4) (= rotations.quat_mul, as a batched matrix product)."""
    return np.matmul((a @ _HAMILTON_LEFT).reshape(-1, 4, 4), b[:, :, None])[:, :, 0]


class Lie4(FixedStepIntegrator):
    """Commutator-free Lie group Runge-Kutta method CF4, order 4, fixed step.

    The group SO(3)^nq x R^m acts on the state: a quaternion block by q <- exp(theta) (x) q
    (left multiplication, theta a world-frame rotation vector), every other component by
    translation y <- y + d. The vector field in the algebra is F = (omega, y'), omega the
    world angular velocity recovered from rhs as omega = 2 vec(q' (x) conj(q)). With
    exp(h F) y as that action, the order-4 scheme CF4 of [1] is

        Y1 = y                                  F1 = F(t, Y1)
        Y2 = exp(h/2 F1) y                      F2 = F(t + h/2, Y2)
        Y3 = exp(h/2 F2) y                      F3 = F(t + h/2, Y3)
        Y4 = exp(h F3 - h/2 F1) Y2              F4 = F(t + h, Y4)
        y1 = exp(h sum_i BETA2_i F_i) exp(h sum_i BETA1_i F_i) y   (the right one acts first)

    On the translation part it is the classical RK4. Quaternions stay unit to round-off by
    construction (no projection needed; `project` is called anyway), rotations stay on
    SO(3). Four rhs evaluations per step; no error estimate.

    References
    ----------
    .. [1] E. Celledoni, A. Marthinsen, B. Owren, "Commutator-free Lie group methods",
           Future Generation Computer Systems 19 (2003) 341-352.
    """

    name = "lie4"
    order = 4
    n_stages = 4
    C = np.array([0.0, 0.5, 0.5, 1.0])
    #: stage exponents: Y_s = exp(h sum_j ALPHA[s, j] F_j) Y_{BASE[s]}
    ALPHA = np.array([
        [0.0, 0.0, 0.0, 0.0],
        [0.5, 0.0, 0.0, 0.0],
        [0.0, 0.5, 0.0, 0.0],
        [-0.5, 0.0, 1.0, 0.0],
    ])
    BASE = (0, 0, 0, 1)
    #: output: y1 = exp(h BETA2 . F) exp(h BETA1 . F) y
    BETA1 = np.array([1 / 4, 1 / 6, 1 / 6, -1 / 12])
    BETA2 = np.array([-1 / 12, 1 / 6, 1 / 6, 1 / 4])
    #: BETA1 + BETA2: the weights of the translation part (classical RK4)
    B = BETA1 + BETA2

    def __init__(self, system: OdeSystem, **options):
        super().__init__(system, **options)
        nq, nl = len(self.quat_index), self.lin_index.size
        self._Y = np.empty((self.n_stages, self.n))  # stage states
        self._W = np.empty((self.n_stages, nq, 3))  # omega of each stage (world)
        self._V = np.empty((self.n_stages, nl))  # y' of each stage, translation part
        self._qi, self._li = self.quat_index, self.lin_index
        self._BETA = np.array([self.BETA1, self.BETA2])  # (2, 4): both output exponents

    def _field(self, s: int, t: float, Y: np.ndarray) -> None:
        """F_s = F(t, Y): omega of every quaternion block into W[s], the rest into V[s]."""
        f = self._fun(t, Y)
        self._V[s] = f[self._li]
        if len(self._qi):
            # omega = 2 vec(q' (x) conj(q))
            G = (Y[self._qi] @ _OMEGA_OF_QDOT).reshape(-1, 3, 4)
            np.matmul(G, f[self._qi][:, :, None], out=self._W[s][:, :, None])

    def _act(self, theta: np.ndarray, d: np.ndarray, y: np.ndarray, out: np.ndarray) -> None:
        """out = exp(theta, d) y: quaternions q <- quat_exp(theta) (x) q, the rest y + d."""
        out[self._li] = y[self._li] + d
        if len(self._qi):
            out[self._qi] = _quat_left(quat_exp(theta), y[self._qi])

    def _step(self, t: float, y: np.ndarray, h: float) -> None:
        Y, W, V = self._Y, self._W, self._V
        W2 = W.reshape(self.n_stages, -1)
        Y[0] = y
        self._field(0, t, y)
        for s in range(1, self.n_stages):
            a = h * self.ALPHA[s, :s]
            theta = (a @ W2[:s]).reshape(-1, 3)
            self._act(theta, a @ V[:s], Y[self.BASE[s]], Y[s])
            self._field(s, t + self.C[s] * h, Y[s])
        # translation part: y + h sum_i B_i V_i (the two exponentials commute there)
        y[self._li] += (h * self.B) @ V
        if len(self._qi):
            e1, e2 = quat_exp(((h * self._BETA) @ W2).reshape(2, -1, 3))
            y[self._qi] = _quat_left(e2, _quat_left(e1, y[self._qi]))
