"""Time integrators behind one small interface, selected by name (SPEC.md, `integrator=`).

    integ = make_integrator("dop853", system, rtol=1e-8, atol=1e-10)
    y1 = integ.advance(t0, y0, t1)                    # a new array, the state at exactly t1
    y1, Y = integ.advance(t0, y0, t1, t_eval=times)   # and Y (len(times), size) on the way

========  ======================================  =====  ========  ============
name      method                                  order  steps     dense output
========  ======================================  =====  ========  ============
rk4       classical Runge-Kutta                   4      fixed     no
dop853    Dormand-Prince 8(5,3)                   8      adaptive  order 7
radau     Radau IIA, 3 stages (stiff)             5      adaptive  collocation
lie4      commutator-free Lie group RK (CF4)      4      fixed     no
auto      dop853, radau while stiff (detected)    8 / 5  adaptive  yes
========  ======================================  =====  ========  ============

The layout follows scipy's `integrate/_ivp` (`base.py`, `rk.py`, `radau.py`): the base class
:class:`Integrator` owns the bookkeeping in its public `advance` (counters, projection, health
checks, output times); a subclass implements one step. An explicit Runge-Kutta method is data:
its tableau `A`, `B`, `C`, `E` and its `order` are class attributes.

Semantics of `advance` (the simulator calls it every few milliseconds in a real-time loop, or
once for a long horizon):

- Every call starts with a fresh rhs(t0, y0): inputs of the system may have changed between
  calls, so nothing derived from the right-hand side (FSAL stage, collocation predictor of a
  different state) is carried over. Adaptive methods keep their step-size estimate across
  calls; only the first call (or the first after `reset`) selects an initial step.
- The last step of an adaptive method is shortened (or stretched by at most
  `LAST_STEP_STRETCH`) to land exactly on t1; a step shortened only for that does not shrink
  the step-size memory. A fixed-step method takes n = ceil((t1 - t0) / step) equal substeps.
- After every accepted step, ``system.project(y)`` renormalises the quaternions.
- A step size below ``MIN_STEP_RELATIVE * max(|t|, |t1|)`` or a non-finite state raises
  :class:`IntegrationError`; the caller's `y0` is never modified.

The rhs may return a view of its own workspace: the integrators copy it before calling rhs
again.
"""
from __future__ import annotations

import math
import warnings
from typing import Protocol

import numpy as np
from scipy.linalg.lapack import get_lapack_funcs

from .rotations import quat_conj, quat_exp, quat_mul

EPS = np.finfo(float).eps

# --- error control (as scipy's rk.py and radau.py) ----------------------------------------
#: step-size factors computed from the asymptotic error model are multiplied by this
SAFETY = 0.9
#: smallest allowed step-size factor after a rejected step
MIN_FACTOR = 0.2
#: largest allowed step-size factor after an accepted step
MAX_FACTOR = 10.0
#: tolerances below this are raised to it (round-off makes them meaningless)
MIN_RTOL = 100 * EPS

# --- step bookkeeping ------------------------------------------------------------------------
#: a step below this fraction of max(|t|, |t1|) has collapsed (about 45 ulps of t)
MIN_STEP_RELATIVE = 1e-14
#: the step before t1 is stretched by up to this fraction rather than leave a sliver (dop853.f)
LAST_STEP_STRETCH = 0.01
#: fixed-step methods: a substep may exceed `step` by this fraction (round-off of t1 - t0)
STEP_COUNT_SLACK = 1e-6
#: at most this many non-finite components are listed in an IntegrationError
MAX_REPORTED_COMPONENTS = 8

# --- initial step selection (Hairer, Norsett, Wanner I, sec. II.4, "starting step size") -----
_H0_NEGLIGIBLE = 1e-5  # d0 or d1 below this: the scaled state or slope is negligible
_H0_DEFAULT = 1e-6  # h0 then
_H0_FRACTION = 0.01  # h0 = 0.01 d0 / d1; h1 = (0.01 / max(d1, d2)) ** (1 / (order + 1))
_H0_GROWTH = 100.0  # the initial step is at most 100 h0
_H0_TINY_DERIVATIVES = 1e-15  # d1, d2 below this: h1 = max(1e-6, 1e-3 h0)
_H0_TINY_STEP = 1e-6
_H0_TINY_FRACTION = 1e-3

# --- Radau IIA (Hairer, Wanner II, sec. IV.8; scipy radau.py) --------------------------------
#: maximum number of simplified Newton iterations per step
NEWTON_MAXITER = 6
#: a Newton iteration that took more iterations than this, and converged more slowly than
#: RADAU_SLOW_RATE, asks for a new Jacobian
RADAU_SLOW_ITER = 2
RADAU_SLOW_RATE = 1e-3
#: after an accepted step, factors below this keep the step and its LU factors (as scipy;
#: radau5.f keeps it for factors in [QUOT1, QUOT2] = [1, 1.2])
RADAU_KEEP_STEP = 1.2
#: the step is halved after a Newton failure
RADAU_NEWTON_FAIL_FACTOR = 0.5
#: LU factors are reused if the step differs from theirs by less than this (relative)
LU_REUSE_RTOL = 1e-6
#: forward-difference Jacobian: step sqrt(eps) * max(|y_j|, FD_MIN_SCALE)
FD_REL_STEP = math.sqrt(EPS)
FD_MIN_SCALE = 1.0


class OdeSystem(Protocol):
    """The system y' = rhs(t, y) the integrators advance.

    Attributes
    ----------
    size : length of the state vector y.
    quat_index : int array (nq, 4), indices in y of unit quaternions (w, x, y, z),
        world-from-body; nq may be 0. For these blocks rhs returns
        q' = 1/2 (0, omega) (x) q, omega the world-frame angular velocity.

    Methods
    -------
    rhs(t, y) -> (size,) : dy/dt. Assumed expensive; every call is counted in `nfev`.
    project(y) -> None : renormalise the quaternions of y (size,) in place.
    jacobian(t, y) -> (size, size) : optional, d rhs / dy; used by implicit methods (radau),
        which otherwise difference rhs.
    """

    size: int
    quat_index: np.ndarray

    def rhs(self, t: float, y: np.ndarray) -> np.ndarray: ...

    def project(self, y: np.ndarray) -> None: ...


class IntegrationError(ArithmeticError):
    """The integration cannot continue: the step size collapsed or the state is not finite.

    Attributes `method`, `reason`, `t` (start of the failing step) and `h` (its size, or
    None). An ArithmeticError, as numpy's FloatingPointError: a numerical failure.
    """

    def __init__(self, method: str, reason: str, t: float, h: float | None, detail: str = ""):
        self.method, self.reason, self.t = method, reason, float(t)
        self.h = None if h is None else float(h)
        msg = f"{method}: {reason} at t = {self.t!r}"
        if self.h is not None:
            msg += f" (step h = {self.h!r})"
        super().__init__(f"{msg}: {detail}" if detail else msg)


def _rms(x: np.ndarray) -> float:
    """Root mean square of x (n,): the weighted error norm of scipy's `norm`."""
    return math.sqrt(float(np.dot(x, x)) / x.size) if x.size else 0.0


def _nonfinite(y: np.ndarray) -> str:
    """Names the non-finite components of y (n,) or (k, n) (for error messages)."""
    bad = np.flatnonzero(~np.isfinite(y).reshape(y.shape[0], -1).all(axis=1)) if y.ndim > 1 \
        else np.flatnonzero(~np.isfinite(y))
    what = "stages" if y.ndim > 1 else "components"
    more = ", ..." if bad.size > MAX_REPORTED_COMPONENTS else ""
    return f"non-finite {what} {bad[:MAX_REPORTED_COMPONENTS].tolist()}{more}"


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


class Integrator:
    """Base class: owns `advance` and the bookkeeping; subclasses implement the step.

    Parameters
    ----------
    system : OdeSystem
    rtol, atol : relative and absolute tolerance of adaptive methods; atol is a scalar or
        (size,). The local error of each step is kept below atol + rtol |y| (RMS-weighted).
    step : substep of fixed-step methods (ignored by adaptive ones).
    max_step : largest step of adaptive methods (ignored by fixed-step ones).

    Attributes
    ----------
    nfev, nsteps, nrejected, njev, nlu : cumulative counts of rhs evaluations (including
        finite-difference Jacobians), accepted steps, rejected steps, Jacobian evaluations
        and LU decompositions.
    error_estimate : weighted RMS error norm of the last accepted step (adaptive methods;
        1 is the tolerance) or None.
    last_step : size of the last step taken, or None.
    """

    name: str = NotImplemented
    order: int = NotImplemented
    adaptive: bool = False
    dense_output: bool = False

    def __init__(
        self,
        system: OdeSystem,
        *,
        rtol: float = 1e-8,
        atol: float | np.ndarray = 1e-10,
        step: float = 1e-3,
        max_step: float = np.inf,
    ):
        n = int(system.size)
        qi = np.asarray(system.quat_index, dtype=np.intp).reshape(-1, 4)
        if n < 0 or (qi.size and (qi.min() < 0 or qi.max() >= n)):
            raise ValueError(f"quat_index {qi.tolist()} out of range for size {n}")
        if np.unique(qi).size != qi.size:
            raise ValueError("quat_index has repeated indices")
        if not (rtol > 0 and math.isfinite(rtol)):
            raise ValueError(f"rtol must be positive and finite, got {rtol!r}")
        if rtol < MIN_RTOL:
            warnings.warn(f"rtol = {rtol:g} is below {MIN_RTOL:g}: using {MIN_RTOL:g}",
                          stacklevel=3)
            rtol = MIN_RTOL
        atol = np.asarray(atol, dtype=float)
        if atol.shape not in ((), (n,)) or np.any(atol < 0) or not np.isfinite(atol).all():
            raise ValueError(f"atol must be a non-negative scalar or shape ({n},)")
        if not (step > 0 and math.isfinite(step)):
            raise ValueError(f"step must be positive and finite, got {step!r}")
        if not max_step > 0:
            raise ValueError(f"max_step must be positive, got {max_step!r}")
        self.system = system
        self.n = n
        self.quat_index = qi
        self.lin_index = np.setdiff1d(np.arange(n), qi.ravel())
        self.rtol = float(rtol)
        self.atol = float(atol) if atol.ndim == 0 else atol
        self.step = float(step)
        self.max_step = float(max_step)
        self._rhs = system.rhs
        self._project = system.project
        self.nfev = self.nsteps = self.nrejected = self.njev = self.nlu = 0
        self.error_estimate: float | None = None
        self.last_step: float | None = None

    # --- public ------------------------------------------------------------------------------
    def advance(self, t0: float, y0: np.ndarray, t1: float, t_eval: np.ndarray | None = None):
        """Integrate from (t0, y0) to exactly t1.

        Parameters
        ----------
        t0, t1 : start and end time, t1 >= t0.
        y0 : (size,) state at t0 (not modified).
        t_eval : optional sorted times (k,) within [t0, t1] at which to report the state too;
            from the dense output where the method has one, else by stepping to each.

        Returns
        -------
        y1 : (size,) the state at t1, a new array; or (y1, Y) with Y (k, size) if t_eval.
        """
        t0, t1 = float(t0), float(t1)
        if not (math.isfinite(t0) and math.isfinite(t1) and t1 >= t0):
            raise ValueError(f"need finite t1 >= t0, got t0 = {t0!r}, t1 = {t1!r}")
        y = np.array(y0, dtype=float)
        if y.shape != (self.n,):
            raise ValueError(f"y0 must have shape ({self.n},), got {y.shape}")
        te = Y = None
        if t_eval is not None:
            te = np.asarray(t_eval, dtype=float)
            if te.ndim != 1 or (te.size and (np.any(np.diff(te) < 0) or te[0] < t0 or te[-1] > t1)):
                raise ValueError(f"t_eval must be a sorted 1-d array within [{t0!r}, {t1!r}]")
            Y = np.empty((te.size, self.n))
        if not np.isfinite(y).all():
            raise IntegrationError(self.name, "initial state is not finite", t0, None,
                                   _nonfinite(y))
        self._integrate(t0, y, t1, te, Y)
        return y if Y is None else (y, Y)

    def reset(self) -> None:
        """Forget the step-size memory (after a reset of the state); counters are kept."""
        self.error_estimate = None
        self.last_step = None

    # --- for subclasses ------------------------------------------------------------------------
    def _fun(self, t: float, y: np.ndarray) -> np.ndarray:
        """rhs(t, y), counted."""
        self.nfev += 1
        return self._rhs(t, y)

    def _fresh_rhs(self, t: float, y: np.ndarray, out: np.ndarray) -> None:
        """out = rhs(t, y) at the start of a call; raises if it is not finite."""
        out[:] = self._fun(t, y)
        if not np.isfinite(out).all():
            raise IntegrationError(self.name, "rhs is not finite at the initial state", t, None,
                                   _nonfinite(out))

    def _integrate(self, t0, y, t1, te, Y) -> None:
        """Advance y (size,) in place from t0 to t1, filling Y at te (or both None)."""
        raise NotImplementedError


# =========================================================================================
# Fixed-step methods
# =========================================================================================
class FixedStepIntegrator(Integrator):
    """n = ceil((t1 - t0) / step) equal substeps per interval; subclasses implement `_step`."""

    def _integrate(self, t0, y, t1, te, Y) -> None:
        t = t0
        if te is not None:
            for j, tj in enumerate(te):
                if tj > t:
                    self._march(t, y, tj)
                    t = tj
                Y[j] = y
        if t1 > t:
            self._march(t, y, t1)

    def _march(self, t0: float, y: np.ndarray, t1: float) -> None:
        span = t1 - t0
        n = max(1, math.ceil(span / self.step - STEP_COUNT_SLACK))
        h = span / n
        for k in range(n):
            t = t0 + k * h
            self._step(t, y, h)
            self._project(y)
            if not np.isfinite(y).all():
                raise IntegrationError(self.name, "state is not finite after the step", t, h,
                                       _nonfinite(y))
            self.nsteps += 1
        self.last_step = h

    def _step(self, t: float, y: np.ndarray, h: float) -> None:
        """One step of size h from (t, y); y (size,) is updated in place."""
        raise NotImplementedError


class ExplicitRungeKutta:
    """Mixin: the stages of an explicit Runge-Kutta tableau into preallocated rows of K.

    Class attributes: `A` (s, s), `B` (s,), `C` (s,), `E` (s,) or None, `order`,
    `error_estimator_order`, `n_stages`.
    """

    A: np.ndarray = NotImplemented
    B: np.ndarray = NotImplemented
    C: np.ndarray = NotImplemented
    E: np.ndarray | None = None
    order: int = NotImplemented
    error_estimator_order: int | None = None
    n_stages: int = NotImplemented

    def _stages(self, t: float, y: np.ndarray, hA: np.ndarray, h: float, first: int, stop: int):
        """K[s] = f(t + C[s] h, y + sum_j hA[s, j] K[j]) for s in [first, stop); hA = h A."""
        K, ys, C = self._K, self._ys, self._C_all
        for s in range(first, stop):
            np.dot(hA[s, :s], K[:s], out=ys)
            ys += y
            K[s] = self._fun(t + C[s] * h, ys)


class RK4(ExplicitRungeKutta, FixedStepIntegrator):
    """The classical Runge-Kutta method, order 4, fixed step.

    Four rhs evaluations per step; no error estimate, no dense output (`t_eval` times are
    stepped to exactly).

    References
    ----------
    .. [1] E. Hairer, S. P. Norsett, G. Wanner, "Solving Ordinary Differential Equations I:
           Nonstiff Problems", 2nd ed., Springer 1993, sec. II.1.
    """

    name = "rk4"
    order = 4
    n_stages = 4
    C = np.array([0.0, 0.5, 0.5, 1.0])
    A = np.array([
        [0.0, 0.0, 0.0, 0.0],
        [0.5, 0.0, 0.0, 0.0],
        [0.0, 0.5, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
    ])
    B = np.array([1 / 6, 1 / 3, 1 / 3, 1 / 6])

    def __init__(self, system: OdeSystem, **options):
        super().__init__(system, **options)
        self._K = np.empty((self.n_stages, self.n))
        self._ys = np.empty(self.n)
        self._dy = np.empty(self.n)
        self._hA = np.empty_like(self.A)
        self._C_all = self.C

    def _step(self, t: float, y: np.ndarray, h: float) -> None:
        K = self._K
        K[0] = self._fun(t, y)
        np.multiply(self.A, h, out=self._hA)
        self._stages(t, y, self._hA, h, 1, self.n_stages)
        # y1 = y + h sum_i B_i K_i
        np.dot(h * self.B, K, out=self._dy)
        y += self._dy


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


class AdaptiveIntegrator(Integrator):
    """Steps chosen by error control; subclasses implement `_step_impl`, `_accept`, `_dense`.

    The loop of `_integrate`: take one accepted step (`_step_impl` fills `_y_new`), project
    it, let the subclass finish the step (`_accept`: the rhs at the new state when another
    step or the dense output needs it), evaluate the dense output at the requested times
    inside the step, move on.
    """

    adaptive = True
    error_estimator_order: int = NotImplemented

    def __init__(self, system: OdeSystem, **options):
        super().__init__(system, **options)
        self._f = np.empty(self.n)  # rhs at the start of the current step
        self._y_new = np.empty(self.n)
        self._h_abs: float | None = None  # the step-size memory

    def reset(self) -> None:
        super().reset()
        self._h_abs = None

    def _integrate(self, t0, y, t1, te, Y) -> None:
        m = 0 if te is None else te.size
        j = 0
        while j < m and te[j] <= t0:
            Y[j] = y
            j += 1
        if t1 == t0:
            return
        self._begin(t0, y, t1)
        t, y_new = t0, self._y_new
        while t < t1:
            t_new = self._step_impl(t, y, t1)
            self._project(y_new)
            k = j
            while k < m and te[k] < t_new:
                k += 1
            self._accept(t, y, t_new, y_new, t_new < t1 or k > j)
            if k > j:
                Yk = Y[j:k]
                Yk[:] = self._dense(t, y, t_new, y_new, te[j:k])
                for row in Yk:
                    self._project(row)
                j = k
            y[:] = y_new
            t = t_new
            self.nsteps += 1
            while j < m and te[j] <= t:
                Y[j] = y
                j += 1
        self._end(t1, y)

    def _begin(self, t0: float, y: np.ndarray, t1: float) -> None:
        """A call starts: fresh rhs(t0, y0); on the first call, the initial step."""
        self._fresh_rhs(t0, y, self._f)
        if self._h_abs is None:
            self._h_abs = self._initial_step(t0, y, self._f, t1, self.error_estimator_order)

    def _end(self, t1: float, y: np.ndarray) -> None:
        """A call ends at (t1, y)."""

    def _min_step(self, t: float, t1: float) -> float:
        return MIN_STEP_RELATIVE * max(abs(t), abs(t1))

    def _collapse(self, t: float, h: float, nonfinite: str) -> IntegrationError:
        detail = f"last trial had {nonfinite}" if nonfinite else "error test keeps failing"
        return IntegrationError(self.name, "step size collapsed", t, h, detail)

    @staticmethod
    def _clip(t: float, h_abs: float, t1: float) -> tuple[float, float]:
        """(h, t_new) of a step of h_abs from t, landing exactly on t1 when near it."""
        if t + h_abs * (1.0 + LAST_STEP_STRETCH) >= t1:
            return t1 - t, t1
        t_new = t + h_abs
        return t_new - t, t_new

    def _scale(self, y: np.ndarray, y_new: np.ndarray | None = None) -> np.ndarray:
        """atol + rtol max(|y|, |y_new|), (size,)."""
        a = np.abs(y)
        if y_new is not None:
            np.maximum(a, np.abs(y_new), out=a)
        a *= self.rtol
        a += self.atol
        return a

    def _initial_step(self, t0, y0, f0, t1, order) -> float:
        """Starting step size (Hairer, Norsett, Wanner I, sec. II.4; scipy select_initial_step).

        One rhs evaluation. `order` is the order of the error estimator.
        """
        span = t1 - t0
        if self.n == 0:
            return min(span, self.max_step)
        scale = self._scale(y0)
        d0, d1 = _rms(y0 / scale), _rms(f0 / scale)
        h0 = _H0_DEFAULT if d0 < _H0_NEGLIGIBLE or d1 < _H0_NEGLIGIBLE else _H0_FRACTION * d0 / d1
        h0 = min(h0, span)
        f1 = self._fun(t0 + h0, y0 + h0 * f0)
        d2 = _rms((f1 - f0) / scale) / h0
        if not math.isfinite(d2):
            d2 = 0.0
        if d1 <= _H0_TINY_DERIVATIVES and d2 <= _H0_TINY_DERIVATIVES:
            h1 = max(_H0_TINY_STEP, h0 * _H0_TINY_FRACTION)
        else:
            h1 = (_H0_FRACTION / max(d1, d2)) ** (1.0 / (order + 1))
        return min(_H0_GROWTH * h0, h1, span, self.max_step)

    def _next_h(self, h: float, h_try: float, factor: float) -> float:
        """Step-size memory after an accepted step h with `factor`; h_try was the proposal.

        A step shortened only to land on t1 (h < h_try) that went well does not shrink it.
        """
        h_next = h * factor
        if h < h_try and factor >= 1.0:
            h_next = max(h_next, h_try)
        return h_next

    def _step_impl(self, t: float, y: np.ndarray, t1: float) -> float:
        """One accepted step from (t, y), at most to t1: fills `_y_new`, returns t_new."""
        raise NotImplementedError

    def _accept(self, t, y, t_new, y_new, need_f: bool) -> None:
        """Finish an accepted step (y_new projected); rhs(t_new, y_new) into `_f` if need_f."""
        raise NotImplementedError

    def _dense(self, t, y, t_new, y_new, tq: np.ndarray) -> np.ndarray:
        """States (k, size) at times tq (k,) inside the step (t, t_new) just accepted."""
        raise NotImplementedError

    def _rhs_at_new(self, t_new: float, y_new: np.ndarray) -> None:
        """_f = rhs(t_new, y_new) of an accepted state, which must be finite."""
        self._f[:] = self._fun(t_new, y_new)
        if not np.isfinite(self._f).all():
            raise IntegrationError(self.name, "rhs is not finite at the accepted state", t_new,
                                   self.last_step, _nonfinite(self._f))


# --- DOP853 coefficients ------------------------------------------------------------------
# Copied from scipy/integrate/_ivp/dop853_coefficients.py (scipy 1.17, BSD-3-Clause), which
# takes them from Hairer's dop853.f. Rows 0..11 of A are the stages, row 12 (= B) gives the
# FSAL stage f(t + h, y1), rows 13..15 the three extra stages of the dense output.
_DOP_N_STAGES = 12
_DOP_N_EXTENDED = 16
_DOP_N_DENSE = 7

_DOP_C = np.array([0.0,
                   0.526001519587677318785587544488e-01,
                   0.789002279381515978178381316732e-01,
                   0.118350341907227396726757197510,
                   0.281649658092772603273242802490,
                   0.333333333333333333333333333333,
                   0.25,
                   0.307692307692307692307692307692,
                   0.651282051282051282051282051282,
                   0.6,
                   0.857142857142857142857142857142,
                   1.0,
                   1.0,
                   0.1,
                   0.2,
                   0.777777777777777777777777777778])

_DOP_A = np.zeros((_DOP_N_EXTENDED, _DOP_N_EXTENDED))
_DOP_A[1, 0] = 5.26001519587677318785587544488e-2

_DOP_A[2, 0] = 1.97250569845378994544595329183e-2
_DOP_A[2, 1] = 5.91751709536136983633785987549e-2

_DOP_A[3, 0] = 2.95875854768068491816892993775e-2
_DOP_A[3, 2] = 8.87627564304205475450678981324e-2

_DOP_A[4, 0] = 2.41365134159266685502369798665e-1
_DOP_A[4, 2] = -8.84549479328286085344864962717e-1
_DOP_A[4, 3] = 9.24834003261792003115737966543e-1

_DOP_A[5, 0] = 3.7037037037037037037037037037e-2
_DOP_A[5, 3] = 1.70828608729473871279604482173e-1
_DOP_A[5, 4] = 1.25467687566822425016691814123e-1

_DOP_A[6, 0] = 3.7109375e-2
_DOP_A[6, 3] = 1.70252211019544039314978060272e-1
_DOP_A[6, 4] = 6.02165389804559606850219397283e-2
_DOP_A[6, 5] = -1.7578125e-2

_DOP_A[7, 0] = 3.70920001185047927108779319836e-2
_DOP_A[7, 3] = 1.70383925712239993810214054705e-1
_DOP_A[7, 4] = 1.07262030446373284651809199168e-1
_DOP_A[7, 5] = -1.53194377486244017527936158236e-2
_DOP_A[7, 6] = 8.27378916381402288758473766002e-3

_DOP_A[8, 0] = 6.24110958716075717114429577812e-1
_DOP_A[8, 3] = -3.36089262944694129406857109825
_DOP_A[8, 4] = -8.68219346841726006818189891453e-1
_DOP_A[8, 5] = 2.75920996994467083049415600797e1
_DOP_A[8, 6] = 2.01540675504778934086186788979e1
_DOP_A[8, 7] = -4.34898841810699588477366255144e1

_DOP_A[9, 0] = 4.77662536438264365890433908527e-1
_DOP_A[9, 3] = -2.48811461997166764192642586468
_DOP_A[9, 4] = -5.90290826836842996371446475743e-1
_DOP_A[9, 5] = 2.12300514481811942347288949897e1
_DOP_A[9, 6] = 1.52792336328824235832596922938e1
_DOP_A[9, 7] = -3.32882109689848629194453265587e1
_DOP_A[9, 8] = -2.03312017085086261358222928593e-2

_DOP_A[10, 0] = -9.3714243008598732571704021658e-1
_DOP_A[10, 3] = 5.18637242884406370830023853209
_DOP_A[10, 4] = 1.09143734899672957818500254654
_DOP_A[10, 5] = -8.14978701074692612513997267357
_DOP_A[10, 6] = -1.85200656599969598641566180701e1
_DOP_A[10, 7] = 2.27394870993505042818970056734e1
_DOP_A[10, 8] = 2.49360555267965238987089396762
_DOP_A[10, 9] = -3.0467644718982195003823669022

_DOP_A[11, 0] = 2.27331014751653820792359768449
_DOP_A[11, 3] = -1.05344954667372501984066689879e1
_DOP_A[11, 4] = -2.00087205822486249909675718444
_DOP_A[11, 5] = -1.79589318631187989172765950534e1
_DOP_A[11, 6] = 2.79488845294199600508499808837e1
_DOP_A[11, 7] = -2.85899827713502369474065508674
_DOP_A[11, 8] = -8.87285693353062954433549289258
_DOP_A[11, 9] = 1.23605671757943030647266201528e1
_DOP_A[11, 10] = 6.43392746015763530355970484046e-1

_DOP_A[12, 0] = 5.42937341165687622380535766363e-2
_DOP_A[12, 5] = 4.45031289275240888144113950566
_DOP_A[12, 6] = 1.89151789931450038304281599044
_DOP_A[12, 7] = -5.8012039600105847814672114227
_DOP_A[12, 8] = 3.1116436695781989440891606237e-1
_DOP_A[12, 9] = -1.52160949662516078556178806805e-1
_DOP_A[12, 10] = 2.01365400804030348374776537501e-1
_DOP_A[12, 11] = 4.47106157277725905176885569043e-2

_DOP_A[13, 0] = 5.61675022830479523392909219681e-2
_DOP_A[13, 6] = 2.53500210216624811088794765333e-1
_DOP_A[13, 7] = -2.46239037470802489917441475441e-1
_DOP_A[13, 8] = -1.24191423263816360469010140626e-1
_DOP_A[13, 9] = 1.5329179827876569731206322685e-1
_DOP_A[13, 10] = 8.20105229563468988491666602057e-3
_DOP_A[13, 11] = 7.56789766054569976138603589584e-3
_DOP_A[13, 12] = -8.298e-3

_DOP_A[14, 0] = 3.18346481635021405060768473261e-2
_DOP_A[14, 5] = 2.83009096723667755288322961402e-2
_DOP_A[14, 6] = 5.35419883074385676223797384372e-2
_DOP_A[14, 7] = -5.49237485713909884646569340306e-2
_DOP_A[14, 10] = -1.08347328697249322858509316994e-4
_DOP_A[14, 11] = 3.82571090835658412954920192323e-4
_DOP_A[14, 12] = -3.40465008687404560802977114492e-4
_DOP_A[14, 13] = 1.41312443674632500278074618366e-1

_DOP_A[15, 0] = -4.28896301583791923408573538692e-1
_DOP_A[15, 5] = -4.69762141536116384314449447206
_DOP_A[15, 6] = 7.68342119606259904184240953878
_DOP_A[15, 7] = 4.06898981839711007970213554331
_DOP_A[15, 8] = 3.56727187455281109270669543021e-1
_DOP_A[15, 12] = -1.39902416515901462129418009734e-3
_DOP_A[15, 13] = 2.9475147891527723389556272149
_DOP_A[15, 14] = -9.15095847217987001081870187138

_DOP_B = _DOP_A[_DOP_N_STAGES, :_DOP_N_STAGES].copy()

_DOP_E3 = np.zeros(_DOP_N_STAGES + 1)
_DOP_E3[:-1] = _DOP_B
_DOP_E3[0] -= 0.244094488188976377952755905512
_DOP_E3[8] -= 0.733846688281611857341361741547
_DOP_E3[11] -= 0.220588235294117647058823529412e-1

_DOP_E5 = np.zeros(_DOP_N_STAGES + 1)
_DOP_E5[0] = 0.1312004499419488073250102996e-1
_DOP_E5[5] = -0.1225156446376204440720569753e+1
_DOP_E5[6] = -0.4957589496572501915214079952
_DOP_E5[7] = 0.1664377182454986536961530415e+1
_DOP_E5[8] = -0.3503288487499736816886487290
_DOP_E5[9] = 0.3341791187130174790297318841
_DOP_E5[10] = 0.8192320648511571246570742613e-1
_DOP_E5[11] = -0.2235530786388629525884427845e-1

# Dense output: rows 3..6 of the interpolant; rows 0..2 come from y_old, y_new, f_old, f_new.
_DOP_D = np.zeros((_DOP_N_DENSE - 3, _DOP_N_EXTENDED))
_DOP_D[0, 0] = -0.84289382761090128651353491142e+1
_DOP_D[0, 5] = 0.56671495351937776962531783590
_DOP_D[0, 6] = -0.30689499459498916912797304727e+1
_DOP_D[0, 7] = 0.23846676565120698287728149680e+1
_DOP_D[0, 8] = 0.21170345824450282767155149946e+1
_DOP_D[0, 9] = -0.87139158377797299206789907490
_DOP_D[0, 10] = 0.22404374302607882758541771650e+1
_DOP_D[0, 11] = 0.63157877876946881815570249290
_DOP_D[0, 12] = -0.88990336451333310820698117400e-1
_DOP_D[0, 13] = 0.18148505520854727256656404962e+2
_DOP_D[0, 14] = -0.91946323924783554000451984436e+1
_DOP_D[0, 15] = -0.44360363875948939664310572000e+1

_DOP_D[1, 0] = 0.10427508642579134603413151009e+2
_DOP_D[1, 5] = 0.24228349177525818288430175319e+3
_DOP_D[1, 6] = 0.16520045171727028198505394887e+3
_DOP_D[1, 7] = -0.37454675472269020279518312152e+3
_DOP_D[1, 8] = -0.22113666853125306036270938578e+2
_DOP_D[1, 9] = 0.77334326684722638389603898808e+1
_DOP_D[1, 10] = -0.30674084731089398182061213626e+2
_DOP_D[1, 11] = -0.93321305264302278729567221706e+1
_DOP_D[1, 12] = 0.15697238121770843886131091075e+2
_DOP_D[1, 13] = -0.31139403219565177677282850411e+2
_DOP_D[1, 14] = -0.93529243588444783865713862664e+1
_DOP_D[1, 15] = 0.35816841486394083752465898540e+2

_DOP_D[2, 0] = 0.19985053242002433820987653617e+2
_DOP_D[2, 5] = -0.38703730874935176555105901742e+3
_DOP_D[2, 6] = -0.18917813819516756882830838328e+3
_DOP_D[2, 7] = 0.52780815920542364900561016686e+3
_DOP_D[2, 8] = -0.11573902539959630126141871134e+2
_DOP_D[2, 9] = 0.68812326946963000169666922661e+1
_DOP_D[2, 10] = -0.10006050966910838403183860980e+1
_DOP_D[2, 11] = 0.77771377980534432092869265740
_DOP_D[2, 12] = -0.27782057523535084065932004339e+1
_DOP_D[2, 13] = -0.60196695231264120758267380846e+2
_DOP_D[2, 14] = 0.84320405506677161018159903784e+2
_DOP_D[2, 15] = 0.11992291136182789328035130030e+2

_DOP_D[3, 0] = -0.25693933462703749003312586129e+2
_DOP_D[3, 5] = -0.15418974869023643374053993627e+3
_DOP_D[3, 6] = -0.23152937917604549567536039109e+3
_DOP_D[3, 7] = 0.35763911791061412378285349910e+3
_DOP_D[3, 8] = 0.93405324183624310003907691704e+2
_DOP_D[3, 9] = -0.37458323136451633156875139351e+2
_DOP_D[3, 10] = 0.10409964950896230045147246184e+3
_DOP_D[3, 11] = 0.29840293426660503123344363579e+2
_DOP_D[3, 12] = -0.43533456590011143754432175058e+2
_DOP_D[3, 13] = 0.96324553959188282948394950600e+2
_DOP_D[3, 14] = -0.39177261675615439165231486172e+2
_DOP_D[3, 15] = -0.14972683625798562581422125276e+3


class DOP853(ExplicitRungeKutta, AdaptiveIntegrator):
    """Explicit Runge-Kutta method of order 8 with error control and dense output.

    The Dormand-Prince 8(5,3) pair as in Hairer's dop853.f: 12 stages (the 13th, FSAL, is
    the next step's first), an error estimate combining the 5th- and 3rd-order embedded
    formulas (err = h |e5|^2 / sqrt(|e5|^2 + 0.01 |e3|^2), RMS-weighted, as scipy's DOP853),
    and a dense output of order 7 that costs 3 more rhs evaluations in the steps where it
    is asked for. Step control: h_new = h min(MAX_FACTOR, SAFETY err^(-1/8)).

    References
    ----------
    .. [1] E. Hairer, S. P. Norsett, G. Wanner, "Solving Ordinary Differential Equations I:
           Nonstiff Problems", 2nd ed., Springer 1993, sec. II.5 and II.6.
    .. [2] E. Hairer, dop853.f, http://www.unige.ch/~hairer/software.html
    .. [3] scipy.integrate.DOP853 (scipy/integrate/_ivp/rk.py): the error norm and the
           dense-output evaluation are ported from there.
    """

    name = "dop853"
    order = 8
    error_estimator_order = 7
    dense_output = True
    n_stages = _DOP_N_STAGES
    A = _DOP_A[:_DOP_N_STAGES, :_DOP_N_STAGES]
    B = _DOP_B
    C = _DOP_C[:_DOP_N_STAGES]
    #: the two embedded error estimators (stage 12, the FSAL stage, has weight 0 in both)
    E3 = _DOP_E3[:_DOP_N_STAGES]
    E5 = _DOP_E5[:_DOP_N_STAGES]
    E = E5
    #: dense output: extra stages 13..15 and the interpolant rows 3..6
    A_EXTRA = _DOP_A[_DOP_N_STAGES + 1:]
    C_EXTRA = _DOP_C[_DOP_N_STAGES + 1:]
    D = _DOP_D

    def __init__(self, system: OdeSystem, **options):
        super().__init__(system, **options)
        self._K = np.empty((_DOP_N_EXTENDED, self.n))
        self._ys = np.empty(self.n)
        self._e5 = np.empty(self.n)
        self._e3 = np.empty(self.n)
        self._hA = np.empty((_DOP_N_EXTENDED, _DOP_N_EXTENDED))
        self._C_all = _DOP_C
        self._A_all = _DOP_A
        self._h = 0.0  # the accepted step (for the dense output)
        self._exponent = -1.0 / (self.error_estimator_order + 1)

    def _error_norm(self, h: float, scale: np.ndarray) -> float:
        K, e5, e3 = self._K[:_DOP_N_STAGES], self._e5, self._e3
        np.dot(self.E5, K, out=e5)
        e5 /= scale
        np.dot(self.E3, K, out=e3)
        e3 /= scale
        n5, n3 = float(np.dot(e5, e5)), float(np.dot(e3, e3))
        if n5 == 0.0 and n3 == 0.0:
            return 0.0
        return abs(h) * n5 / math.sqrt((n5 + 0.01 * n3) * self.n)

    def _step_impl(self, t: float, y: np.ndarray, t1: float) -> float:
        K, hA, y_new = self._K, self._hA, self._y_new
        h_abs = min(self._h_abs, self.max_step)
        min_step = self._min_step(t, t1)
        rejected = False
        nonfinite = ""
        while True:
            if h_abs < min_step:
                raise self._collapse(t, h_abs, nonfinite)
            h, t_new = self._clip(t, h_abs, t1)
            K[0] = self._f
            np.multiply(self._A_all, h, out=hA)
            self._stages(t, y, hA, h, 1, _DOP_N_STAGES)
            # y1 = y + h sum_i B_i K_i  (B is row 12 of A)
            np.dot(hA[_DOP_N_STAGES, :_DOP_N_STAGES], K[:_DOP_N_STAGES], out=y_new)
            y_new += y
            error_norm = self._error_norm(h, self._scale(y, y_new))
            if not (math.isfinite(error_norm) and np.isfinite(y_new).all()):
                nonfinite = _nonfinite(K[:_DOP_N_STAGES])
                h_abs = abs(h) * MIN_FACTOR
                rejected = True
                self.nrejected += 1
                continue
            if error_norm < 1.0:
                if error_norm == 0.0:
                    factor = MAX_FACTOR
                else:
                    factor = min(MAX_FACTOR, SAFETY * error_norm ** self._exponent)
                if rejected:
                    factor = min(1.0, factor)
                self._h_abs = self._next_h(h, h_abs, factor)
                break
            h_abs = abs(h) * max(MIN_FACTOR, SAFETY * error_norm ** self._exponent)
            rejected = True
            self.nrejected += 1
        self.error_estimate = error_norm
        self.last_step = self._h = h
        return t_new

    def _accept(self, t, y, t_new, y_new, need_f: bool) -> None:
        if need_f:
            self._rhs_at_new(t_new, y_new)
            self._K[_DOP_N_STAGES] = self._f

    def _dense(self, t, y, t_new, y_new, tq: np.ndarray) -> np.ndarray:
        K, h = self._K, self._h
        # the three extra stages (hA still holds h A of this step)
        self._stages(t, y, self._hA, h, _DOP_N_STAGES + 1, _DOP_N_EXTENDED)
        F = np.empty((_DOP_N_DENSE, self.n))
        dy = y_new - y
        F[0] = dy
        F[1] = h * K[0] - dy
        F[2] = 2.0 * dy - h * (K[_DOP_N_STAGES] + K[0])
        np.dot(h * self.D, K, out=F[3:])
        # Horner in x and (1 - x), alternating (scipy's Dop853DenseOutput)
        x = ((tq - t) / h)[:, None]
        out = np.zeros((tq.size, self.n))
        for i, Fi in enumerate(F[::-1]):
            out += Fi
            out *= x if i % 2 == 0 else 1.0 - x
        out += y
        return out


# --- Radau IIA coefficients (scipy radau.py; Hairer, Wanner II, sec. IV.8) -----------------
_S6 = math.sqrt(6.0)
#: A is not used by the iteration (it works in the eigenbasis of A^-1); kept as data.
_RADAU_A = np.array([
    [(88 - 7 * _S6) / 360, (296 - 169 * _S6) / 1800, (-2 + 3 * _S6) / 225],
    [(296 + 169 * _S6) / 1800, (88 + 7 * _S6) / 360, (-2 - 3 * _S6) / 225],
    [(16 - _S6) / 36, (16 + _S6) / 36, 1 / 9],
])
_RADAU_C = np.array([(4 - _S6) / 10, (4 + _S6) / 10, 1.0])
_RADAU_E = np.array([-13 - 7 * _S6, -13 + 7 * _S6, -1.0]) / 3
# eigenvalues of A^-1: one real, a complex pair; A^-1 = T diag(MU_REAL, block(MU_COMPLEX)) TI
_MU_REAL = 3 + 3 ** (2 / 3) - 3 ** (1 / 3)
_MU_COMPLEX = 3 + 0.5 * (3 ** (1 / 3) - 3 ** (2 / 3)) - 0.5j * (3 ** (5 / 6) + 3 ** (7 / 6))
_RADAU_T = np.array([
    [0.09443876248897524, -0.14125529502095421, 0.03002919410514742],
    [0.25021312296533332, 0.20412935229379994, -0.38294211275726192],
    [1.0, 1.0, 0.0],
])
_RADAU_TI = np.array([
    [4.17871859155190428, 0.32768282076106237, 0.52337644549944951],
    [-4.17871859155190428, -0.32768282076106237, 0.47662355450055044],
    [0.50287263494578682, -2.57192694985560522, 0.59603920482822492],
])
# dense output: y(t_old + x h) = y_old + Z^T P (x, x^2, x^3)
_RADAU_P = np.array([
    [13 / 3 + 7 * _S6 / 3, -23 / 3 - 22 * _S6 / 3, 10 / 3 + 5 * _S6],
    [13 / 3 - 7 * _S6 / 3, -23 / 3 + 22 * _S6 / 3, 10 / 3 - 5 * _S6],
    [1 / 3, -8 / 3, 10 / 3],
])


class Radau(AdaptiveIntegrator):
    """Implicit Runge-Kutta method Radau IIA, 3 stages, order 5, for stiff systems.

    The algorithm of Hairer and Wanner's radau5 as ported in scipy's Radau [3]: the
    collocation system is solved by a simplified Newton iteration in the eigenbasis of A^-1,
    which splits it into one real and one complex linear system of size n (LU-factored once
    per step size and Jacobian); the error is estimated with an embedded formula of order 3
    filtered through the real LU (again with rhs(t, y + err) after a rejection); step control
    is Gustafsson's predictive controller. The Jacobian is `system.jacobian` if the system
    has one, else forward differences (n rhs evaluations, counted in nfev); it is reused
    across steps and recomputed only when Newton converged slowly (more than
    RADAU_SLOW_ITER iterations at a rate above RADAU_SLOW_RATE) or failed with an old one.
    Dense output: the collocation polynomial (order 3 between the nodes), which also predicts
    the next step's Newton start when the state continues from the previous call.

    References
    ----------
    .. [1] E. Hairer, G. Wanner, "Solving Ordinary Differential Equations II: Stiff and
           Differential-Algebraic Problems", 2nd ed., Springer 1996, sec. IV.8.
    .. [2] E. Hairer, radau5.f, http://www.unige.ch/~hairer/software.html
    .. [3] scipy.integrate.Radau (scipy/integrate/_ivp/radau.py), ported here.
    """

    name = "radau"
    order = 5
    error_estimator_order = 3
    dense_output = True
    A = _RADAU_A
    B = _RADAU_A[-1]
    C = _RADAU_C
    E = _RADAU_E
    MU_REAL = _MU_REAL
    MU_COMPLEX = _MU_COMPLEX
    T = _RADAU_T
    TI = _RADAU_TI
    P = _RADAU_P

    def __init__(self, system: OdeSystem, **options):
        super().__init__(system, **options)
        n = self.n
        jac = getattr(system, "jacobian", None)
        self._jac_fn = jac if callable(jac) else None
        self._newton_tol = max(10 * EPS / self.rtol, min(0.03, self.rtol ** 0.5))
        self._I = np.identity(n)
        self._F = np.empty((3, n))
        self._ys = np.empty(n)
        self._TI_complex = self.TI[1] + 1j * self.TI[2]
        self._y_end = np.empty(n)
        self._sol_y = np.empty(n)  # y_old of the collocation polynomial
        # LAPACK directly: scipy.linalg.lu_solve's checks cost more than the solve at n ~ 60
        self._getrf_real, self._getrs_real = get_lapack_funcs(("getrf", "getrs"), dtype=np.float64)
        self._getrf_complex, self._getrs_complex = get_lapack_funcs(("getrf", "getrs"),
                                                                    dtype=np.complex128)
        self._reset_memory()

    def _reset_memory(self) -> None:
        self._h_abs_old: float | None = None
        self._error_norm_old: float | None = None
        self._J: np.ndarray | None = None
        self._current_jac = False
        self._recompute_jac = False
        self._LU_real = self._LU_complex = None
        self._lu_h = None
        self._sol_Q: np.ndarray | None = None  # (n, 3); None: no predictor
        self._sol_t = self._sol_h = 0.0
        self._t_end: float | None = None

    def reset(self) -> None:
        super().reset()
        self._reset_memory()

    # --- linear algebra ---------------------------------------------------------------------
    def _jacobian(self, t: float, y: np.ndarray, f: np.ndarray) -> np.ndarray:
        """d rhs / dy (n, n): the system's, or forward differences around f = rhs(t, y)."""
        self.njev += 1
        if self._jac_fn is not None:
            J = np.asarray(self._jac_fn(t, y), dtype=float)
            if J.shape != (self.n, self.n):
                raise ValueError(f"jacobian must have shape {(self.n, self.n)}, got {J.shape}")
            return J
        delta = (y + FD_REL_STEP * np.maximum(np.abs(y), FD_MIN_SCALE)) - y
        J = np.empty((self.n, self.n))
        yj = self._ys
        yj[:] = y
        for j in range(self.n):
            yj[j] = y[j] + delta[j]
            J[:, j] = self._fun(t, yj)
            yj[j] = y[j]
        J -= f[:, None]
        J /= delta
        return J

    def _factor(self, h: float) -> None:
        """LU of MU_REAL/h I - J and MU_COMPLEX/h I - J (LAPACK getrf)."""
        self._LU_real = self._lu(self._getrf_real, self.MU_REAL / h * self._I - self._J)
        self._LU_complex = self._lu(self._getrf_complex, self.MU_COMPLEX / h * self._I - self._J)
        self._lu_h = h
        self.nlu += 2

    @staticmethod
    def _lu(getrf, M: np.ndarray) -> tuple:
        lu, piv, info = getrf(M, overwrite_a=True)
        if info < 0:
            raise ValueError(f"getrf: illegal argument {-info}")
        # info > 0: exactly singular; the solves give inf/nan and the step is rejected
        return lu, piv

    def _solve(self, getrs, LU: tuple, b: np.ndarray) -> np.ndarray:
        x, info = getrs(LU[0], LU[1], b)
        return x

    def _solve_real(self, b: np.ndarray) -> np.ndarray:
        return self._solve(self._getrs_real, self._LU_real, b)

    # --- the step -------------------------------------------------------------------------------
    def _newton(self, t, y, h, Z0, scale):
        """Simplified Newton iteration for the collocation system (scipy's
        solve_collocation_system). Returns (converged, n_iter, Z (3, n), rate)."""
        F, ys = self._F, self._ys
        M_real, M_complex = self.MU_REAL / h, self.MU_COMPLEX / h
        W = self.TI @ Z0
        Z = Z0
        dW = np.empty_like(W)
        ch = h * self.C
        dW_norm_old = rate = None
        converged = False
        tol = self._newton_tol
        k = 0
        for k in range(NEWTON_MAXITER):
            for i in range(3):
                np.add(y, Z[i], out=ys)
                F[i] = self._fun(t + ch[i], ys)
            if not np.isfinite(F).all():
                self._nonfinite = _nonfinite(F)
                break
            f_real = self.TI[0] @ F - M_real * W[0]
            f_complex = self._TI_complex @ F - M_complex * (W[1] + 1j * W[2])
            dW[0] = self._solve(self._getrs_real, self._LU_real, f_real)
            dW_complex = self._solve(self._getrs_complex, self._LU_complex, f_complex)
            dW[1] = dW_complex.real
            dW[2] = dW_complex.imag
            dW_norm = _rms((dW / scale).ravel())
            if dW_norm_old is not None:
                rate = dW_norm / dW_norm_old
            if rate is not None and (
                rate >= 1 or rate ** (NEWTON_MAXITER - k) / (1 - rate) * dW_norm > tol
            ):
                break  # diverges, or will not converge within NEWTON_MAXITER
            W += dW
            Z = self.T @ W
            if dW_norm == 0 or (rate is not None and rate / (1 - rate) * dW_norm < tol):
                converged = True
                break
            dW_norm_old = dW_norm
        return converged, k + 1, Z, rate

    @staticmethod
    def _predict_factor(h_abs, h_abs_old, error_norm, error_norm_old) -> float:
        """Gustafsson's predictive step-size factor (Hairer, Wanner II, sec. IV.8)."""
        if error_norm_old is None or h_abs_old is None or error_norm == 0:
            multiplier = 1.0
        else:
            multiplier = h_abs / h_abs_old * (error_norm_old / error_norm) ** 0.25
        with np.errstate(divide="ignore"):
            return min(1.0, multiplier) * np.float64(error_norm) ** -0.25

    def _begin(self, t0: float, y: np.ndarray, t1: float) -> None:
        super()._begin(t0, y, t1)
        if self._t_end != t0 or not np.array_equal(y, self._y_end):
            # not a continuation of the previous call: no predictor, the Jacobian is old
            self._sol_Q = None
            self._current_jac = False

    def _end(self, t1: float, y: np.ndarray) -> None:
        self._t_end = t1
        self._y_end[:] = y

    def _step_impl(self, t: float, y: np.ndarray, t1: float) -> float:
        f = self._f
        min_step = self._min_step(t, t1)
        if self._h_abs > self.max_step:
            h_abs, h_abs_old, error_norm_old = self.max_step, None, None
        else:
            h_abs, h_abs_old, error_norm_old = self._h_abs, self._h_abs_old, self._error_norm_old
        if self._J is None or self._recompute_jac:
            self._J = self._jacobian(t, y, f)
            self._current_jac, self._recompute_jac = True, False
            self._LU_real = None
        self._nonfinite = ""
        rejected = False
        while True:
            if h_abs < min_step:
                raise self._collapse(t, h_abs, self._nonfinite)
            h, t_new = self._clip(t, h_abs, t1)
            if self._sol_Q is None:
                Z0 = np.zeros((3, self.n))
            else:
                x = (t + h * self.C - self._sol_t) / self._sol_h
                Z0 = (self._sol_Q @ np.array([x, x * x, x * x * x])).T + (self._sol_y - y)
            scale = self._scale(y)
            converged = False
            while not converged:
                if self._LU_real is None or abs(h - self._lu_h) > LU_REUSE_RTOL * h:
                    self._factor(h)
                converged, n_iter, Z, rate = self._newton(t, y, h, Z0, scale)
                if not converged:
                    if self._current_jac:
                        break
                    self._J = self._jacobian(t, y, f)
                    self._current_jac = True
                    self._LU_real = None
            if not converged:
                h_abs = abs(h) * RADAU_NEWTON_FAIL_FACTOR
                self._LU_real = None
                self.nrejected += 1
                continue
            y_new = self._y_new
            np.add(y, Z[-1], out=y_new)
            ZE = (self.E @ Z) / h
            error = self._solve_real(f + ZE)
            scale = self._scale(y, y_new)
            error_norm = _rms(error / scale)
            safety = SAFETY * (2 * NEWTON_MAXITER + 1) / (2 * NEWTON_MAXITER + n_iter)
            if rejected and error_norm > 1:
                error = self._solve_real(self._fun(t, y + error) + ZE)
                error_norm = _rms(error / scale)
            if not (math.isfinite(error_norm) and np.isfinite(y_new).all()):
                self._nonfinite = _nonfinite(y_new) if not np.isfinite(y_new).all() else \
                    "a non-finite error estimate"
                h_abs = abs(h) * MIN_FACTOR
                rejected = True
                self.nrejected += 1
                continue
            if error_norm > 1:
                factor = self._predict_factor(abs(h), h_abs_old, error_norm, error_norm_old)
                h_abs = abs(h) * max(MIN_FACTOR, safety * factor)
                rejected = True
                self.nrejected += 1
                continue
            break
        self._recompute_jac = n_iter > RADAU_SLOW_ITER and rate > RADAU_SLOW_RATE
        factor = self._predict_factor(abs(h), h_abs_old, error_norm, error_norm_old)
        factor = min(MAX_FACTOR, safety * factor)
        if not self._recompute_jac and factor < RADAU_KEEP_STEP:
            factor = 1.0
        # from now on J belongs to an older state (a slow Newton renews it next step)
        self._current_jac = False
        self._h_abs_old = abs(h)
        self._error_norm_old = error_norm
        self._h_abs = self._next_h(abs(h), h_abs, factor)
        self._Z = Z
        self.error_estimate = error_norm
        self.last_step = h
        return t_new

    def _accept(self, t, y, t_new, y_new, need_f: bool) -> None:
        # the collocation polynomial of this step: dense output and next Newton start
        self._sol_Q = self._Z.T @ self.P
        self._sol_t, self._sol_h = t, t_new - t
        self._sol_y[:] = y
        if need_f:
            self._rhs_at_new(t_new, y_new)

    def _dense(self, t, y, t_new, y_new, tq: np.ndarray) -> np.ndarray:
        x = (tq - t) / (t_new - t)
        return y + np.column_stack([x, x * x, x * x * x]) @ self._sol_Q.T


# =========================================================================================
# Automatic choice between the explicit and the implicit method
# =========================================================================================
# --- stiffness detection (Hairer, Norsett, Wanner I, sec. IV.10; dop853.f, "STIFFNESS DETECTION")
#: h |lambda| estimated after an accepted dop853 step above this: the step sits on the
#: method's stability boundary, not its accuracy limit. dop853.f uses 6.1, just inside the
#: boundary on the negative real axis (6.35); but on the imaginary axis, where a chain's
#: gyroscopic stiffness lies (nutation: eigenvalues +-i w_n), DOP853's boundary is 5.95, a
#: step-size controller pinned there keeps h |lambda| ~ 5.9 and 6.1 never fires (measured on
#: the stability report's fast rotor). 5.0 is inside both boundaries, and far above any
#: accuracy-limited step (h |lambda| = 5 is 1.3 steps per period of that mode).
STIFF_HLAMB = 5.0
#: that many stiff steps, not separated by NONSTIFF_RESET non-stiff steps in a row, make
#: the problem stiff (dop853.f: 15 and 6)
STIFF_STEPS = 15
NONSTIFF_RESET = 6
#: rejected steps: at least REJECT_FRACTION of the last REJECT_WINDOW step attempts of dop853
#: rejected also make it stiff (the step-size control is fighting stability)
REJECT_WINDOW = 40
REJECT_FRACTION = 0.5
#: radau hands back when h rho(J) < NONSTIFF_HRHO (an explicit step of that size is well
#: inside dop853's stability region) in this many accepted steps in a row; the count doubles
#: after every return to radau (no flip-flopping)
NONSTIFF_HRHO = 2.0
NONSTIFF_STEPS = 20
#: cost: rhs evaluations per simulated second of each method, over its last COST_WINDOW
#: steps (evaluations, not CPU time: the choice of method, hence the trajectory, must not
#: depend on the machine's load; the linear algebra of radau is not counted). Radau hands
#: back when it costs COST_MARGIN times what dop853 did (at tight tolerances radau's order 5
#: can lose to dop853 even on a stiff problem); a stiffness detected later switches to radau
#: again only if radau's last measured cost was below dop853's (between the two: no switch)
COST_WINDOW = 20
COST_MARGIN = 1.5
#: dop853's rhs evaluations per step and its stability boundary on the imaginary axis: its
#: cost on a stiff problem, never measured, is estimated as DOP853_EVALS rho / DOP853_BOUNDARY
#: evaluations per simulated second
DOP853_EVALS = 12
DOP853_BOUNDARY = 5.95
#: rho(J) from eigenvalues up to this size, above it from a few power iterations
EIG_MAX_SIZE = 200
POWER_ITERATIONS = 30


class StiffnessWarning(RuntimeWarning):
    """The "auto" integrator switched methods (the problem became stiff, or stopped being)."""


class _Switch(Exception):
    """Internal: the running method hands over at an accepted state (args: t, reason)."""


class Auto(Integrator):
    """dop853 while the problem is not stiff, radau while it is: detected, switched, reported.

    The state is advanced by one of two inner integrators on the same system: DOP853 (order
    8) and Radau IIA (order 5, L-stable, its Jacobian by finite differences). It starts with
    DOP853, which detects stiffness three ways:

    - the stiffness test of Hairer's dop853.f: after every accepted step,
      h |lambda| ~ h ||f(y1) - f(Y12)|| / ||y1 - Y12|| (Y12 the last stage, at t + h)
      estimates h times the dominant eigenvalue along the step; above STIFF_HLAMB the step
      is limited by stability, not accuracy. STIFF_STEPS such steps (not interrupted by
      NONSTIFF_RESET non-stiff ones in a row) make the problem stiff;
    - many rejected steps: REJECT_FRACTION of the last REJECT_WINDOW attempts;
    - a step-size collapse (IntegrationError): Radau retries from the last accepted state
      before the error is passed on.

    A detected stiffness switches to Radau unless Radau has already been measured to cost
    more rhs evaluations per simulated second than DOP853 on this run (then DOP853 goes
    on, and the detection starts over). Radau hands back when its steps satisfy
    h rho(J) < NONSTIFF_HRHO (rho: spectral radius of its Jacobian, refreshed with it)
    NONSTIFF_STEPS times in a row (a number that doubles after each return to Radau), or
    when it costs COST_MARGIN times more than DOP853 did (or, never measured, than DOP853
    would at its stability limit). Every switch is recorded in `switches` (time, from, to,
    reason) and issued as a :class:`StiffnessWarning` (once per kind, by the warnings
    filter). A step-size collapse of Radau, or a non-finite state, raises IntegrationError
    as the other methods do. `method` names the method in use; `error_estimate` and
    `last_step` are its; the counters add up both.

    References
    ----------
    .. [1] E. Hairer, S. P. Norsett, G. Wanner, "Solving Ordinary Differential Equations I",
           2nd ed., Springer 1993, sec. IV.10 ("Automatic stiffness detection"), and
           dop853.f (http://www.unige.ch/~hairer/software.html).
    .. [2] L. R. Petzold, "Automatic selection of methods for solving stiff and nonstiff
           systems of ordinary differential equations", SIAM J. Sci. Stat. Comput. 4 (1983)
           136-148 (LSODA: the same idea with Adams and BDF).
    """

    name = "auto"
    order = 8  # DOP853's; 5 while Radau runs
    adaptive = True
    dense_output = True

    def __init__(self, system: OdeSystem, **options):
        super().__init__(system, **options)
        inner = dict(rtol=self.rtol, atol=self.atol, step=self.step, max_step=self.max_step)
        self.explicit = DOP853(system, **inner)
        self.implicit = Radau(system, **inner)
        self._current: AdaptiveIntegrator = self.explicit
        self.reset()

    @property
    def method(self) -> str:
        """The name of the method in use."""
        return self._current.name

    def reset(self) -> None:
        super().reset()
        self.explicit.reset()
        self.implicit.reset()
        self._current = self.explicit
        #: (t, from, to, reason) of every switch since the last reset
        self.switches: list[tuple[float, str, str, str]] = []
        self._nonstiff_needed = NONSTIFF_STEPS
        self._cost: dict[str, float] = {}  # rhs evaluations per simulated s, by method
        self._new_episode()
        self._sync()

    def _new_episode(self) -> None:
        """Forget the detection state (at a reset or a switch)."""
        self._n_stiff = self._n_nonstiff = 0  # dop853.f's IASTI, NONSTI
        self._attempts: list[int] = []  # rejected attempts before each accepted step
        self._pending = None  # (t1, y1, h, Y12, f(Y12)): a test waiting for f(y1)
        self._rho: float | None = None  # spectral radius of radau's Jacobian
        self._rho_njev = -1
        self._n_easy = 0  # radau steps in a row with h rho < NONSTIFF_HRHO
        self._window: list[tuple[float, int]] = []  # (dt, nfev) per accepted step

    # --- the loop ------------------------------------------------------------------------
    def _integrate(self, t0, y, t1, te, Y) -> None:
        m = 0 if te is None else te.size
        self._j = 0  # next output time
        while self._j < m and te[self._j] <= t0:
            Y[self._j] = y
            self._j += 1
        t = t0
        try:
            while t < t1:
                try:
                    t = self._run(self._current, t, y, t1, te, Y)
                except _Switch as switch:
                    t = switch.args[0]
                    self._switch(t, switch.args[1])
                except IntegrationError as exc:
                    if self._current is not self.explicit or exc.reason != "step size collapsed":
                        raise self._own(exc) from exc
                    t = exc.t  # y is the state accepted at exc.t
                    self._switch(t, "dop853 step size collapsed")
        finally:
            self._sync()

    def _own(self, exc: IntegrationError) -> IntegrationError:
        """exc of an inner method as this integrator's, saying which method ran."""
        msg = str(exc)
        head = f"{exc.method}: {exc.reason} at t = {exc.t!r}"
        if exc.h is not None:
            head += f" (step h = {exc.h!r})"
        detail = msg[len(head) + 2:] if msg.startswith(head + ": ") else ""
        return IntegrationError(self.name, exc.reason, exc.t, exc.h,
                                f"{exc.method} running" + (f"; {detail}" if detail else ""))

    def _run(self, inner: AdaptiveIntegrator, t: float, y: np.ndarray, t1: float, te, Y) -> float:
        """AdaptiveIntegrator._integrate for `inner`, with the checks after each accepted
        step; raises _Switch(t, reason) to hand over at an accepted state."""
        m = 0 if te is None else te.size
        explicit = inner is self.explicit
        nfev = inner.nfev
        inner._begin(t, y, t1)
        if explicit and self._pending is not None:
            t_p, y_p = self._pending[:2]
            pending, self._pending = self._pending[2:], None
            if t_p == t and np.array_equal(y_p, y):  # a continuation: f(y1) is inner._f
                self._raise_if(t, self._stiffness_test(*pending, y, inner._f))
        y_new = inner._y_new
        while t < t1:
            rejected = inner.nrejected
            t_new = inner._step_impl(t, y, t1)
            inner._project(y_new)
            k = self._j
            while k < m and te[k] < t_new:
                k += 1
            need_f = t_new < t1 or k > self._j
            inner._accept(t, y, t_new, y_new, need_f)
            h = t_new - t
            if explicit:
                K12 = inner._K[_DOP_N_STAGES - 1]  # f(t + h, Y12); inner._ys holds Y12
                if need_f:
                    reason = self._stiffness_test(h, inner._ys, K12, y_new, inner._f)
                else:  # the test needs f(y1): the next call computes it
                    reason = None
                    self._pending = (t_new, y_new.copy(), h, inner._ys.copy(), K12.copy())
                reason = self._rejection_test(inner.nrejected - rejected) or reason
            else:
                reason = self._nonstiffness_test(h)
            if k > self._j:
                Yk = Y[self._j:k]
                Yk[:] = inner._dense(t, y, t_new, y_new, te[self._j:k])
                for row in Yk:
                    inner._project(row)
                self._j = k
            y[:] = y_new
            t = t_new
            inner.nsteps += 1
            while self._j < m and te[self._j] <= t:
                Y[self._j] = y
                self._j += 1
            self._measure(inner.name, h, inner.nfev - nfev)
            nfev = inner.nfev
            if explicit and reason is not None and self._costlier("radau", "dop853", 1.0):
                self._n_stiff = 0  # radau was measured slower here: keep going
                self._attempts.clear()
                reason = None
            if not explicit and reason is None:
                reason = self._cost_test()
            if reason is not None and t < t1:
                inner._end(t, y)
                raise _Switch(t, reason)
        inner._end(t1, y)
        return t

    @staticmethod
    def _raise_if(t: float, reason: str | None) -> None:
        if reason is not None:
            raise _Switch(t, reason)

    # --- detection -------------------------------------------------------------------------
    def _stiffness_test(self, h, Y12, f12, y1, f1) -> str | None:
        """dop853.f's test on one accepted step; a reason to switch, or None."""
        dy = y1 - Y12
        den = float(np.dot(dy, dy))
        if den <= 0.0:
            return None
        df = f1 - f12
        hlamb = abs(h) * math.sqrt(float(np.dot(df, df)) / den)
        if hlamb > STIFF_HLAMB:
            self._n_nonstiff = 0
            self._n_stiff += 1
            if self._n_stiff >= STIFF_STEPS:
                return f"stiff: h |lambda| > {STIFF_HLAMB:g} in {STIFF_STEPS} steps"
        else:
            self._n_nonstiff += 1
            if self._n_nonstiff >= NONSTIFF_RESET:
                self._n_stiff = 0
        return None

    def _rejection_test(self, rejected: int) -> str | None:
        self._attempts.append(rejected)
        if len(self._attempts) > REJECT_WINDOW:
            del self._attempts[0]
        n_rej = sum(self._attempts)
        n_all = n_rej + len(self._attempts)
        if n_all >= REJECT_WINDOW and n_rej >= REJECT_FRACTION * n_all:
            return f"stiff: {n_rej} of the last {n_all} step attempts rejected"
        return None

    def _nonstiffness_test(self, h: float) -> str | None:
        imp = self.implicit
        if imp.njev != self._rho_njev and imp._J is not None:
            self._rho = _spectral_radius(imp._J)
            self._rho_njev = imp.njev
        if self._rho is None or abs(h) * self._rho >= NONSTIFF_HRHO:
            self._n_easy = 0
            return None
        self._n_easy += 1
        if self._n_easy >= self._nonstiff_needed:
            return f"not stiff: h rho(J) < {NONSTIFF_HRHO:g} in {self._nonstiff_needed} steps"
        return None

    def _measure(self, method: str, dt: float, nfev: int) -> None:
        w = self._window
        w.append((dt, nfev))
        if len(w) > COST_WINDOW:
            del w[0]
        if len(w) == COST_WINDOW:
            span = sum(x[0] for x in w)
            if span > 0.0:
                self._cost[method] = sum(x[1] for x in w) / span

    def _costlier(self, candidate: str, running: str, margin: float) -> bool:
        """Is `candidate` known to cost more than `margin` times `running`?"""
        c, r = self._cost.get(candidate), self._cost.get(running)
        return c is not None and r is not None and c > margin * r

    def _cost_test(self) -> str | None:
        """Radau running: a reason to hand back if it costs more than dop853 would."""
        radau = self._cost.get("radau")
        if radau is None or len(self._window) < COST_WINDOW:
            return None
        dop = self._cost.get("dop853")
        if dop is None:
            if self._rho is None:
                return None
            dop = DOP853_EVALS * self._rho / DOP853_BOUNDARY
        if radau > COST_MARGIN * dop:
            return f"radau costs {radau:.3g} rhs evaluations per simulated s, dop853 {dop:.3g}"
        return None

    def _switch(self, t: float, reason: str) -> None:
        old = self._current
        new = self.implicit if old is self.explicit else self.explicit
        if new is self.implicit and any(s[2] == "dop853" for s in self.switches):
            self._nonstiff_needed *= 2  # stiff again after a return: wait longer next time
        self.switches.append((float(t), old.name, new.name, reason))
        kind = reason.split(":")[0]
        warnings.warn(f"auto integrator: {old.name} -> {new.name} ({kind})", StiffnessWarning,
                      stacklevel=5)
        self._sync()
        new.reset()
        self._current = new
        self._new_episode()

    def _sync(self) -> None:
        e, i = self.explicit, self.implicit
        self.nfev, self.nsteps = e.nfev + i.nfev, e.nsteps + i.nsteps
        self.nrejected, self.njev, self.nlu = e.nrejected + i.nrejected, i.njev, i.nlu
        self.error_estimate = self._current.error_estimate
        self.last_step = self._current.last_step
        self.order = self._current.order


def _spectral_radius(J: np.ndarray) -> float:
    """max |eigenvalue| of J (n, n): exact up to EIG_MAX_SIZE, else by power iterations."""
    if not np.isfinite(J).all():
        return math.inf
    if J.shape[0] <= EIG_MAX_SIZE:
        return float(np.max(np.abs(np.linalg.eigvals(J)))) if J.size else 0.0
    x = np.random.default_rng(0).standard_normal(J.shape[0])
    rho = 0.0
    for _ in range(POWER_ITERATIONS):
        x = J @ x
        rho = float(np.linalg.norm(x))
        if rho == 0.0:
            return 0.0
        x /= rho
    return rho


INTEGRATORS: dict[str, type[Integrator]] = {
    cls.name: cls for cls in (RK4, DOP853, Radau, Lie4)
}
INTEGRATORS[Auto.name] = Auto


def make_integrator(
    name: str,
    system: OdeSystem,
    *,
    rtol: float = 1e-8,
    atol: float | np.ndarray = 1e-10,
    step: float = 1e-3,
    max_step: float = np.inf,
) -> Integrator:
    """The integrator registered as `name` (see INTEGRATORS) for `system`."""
    try:
        cls = INTEGRATORS[name]
    except (KeyError, TypeError):
        valid = ", ".join(INTEGRATORS)
        raise ValueError(f"unknown integrator {name!r}; valid names: {valid}") from None
    return cls(system, rtol=rtol, atol=atol, step=step, max_step=max_step)
