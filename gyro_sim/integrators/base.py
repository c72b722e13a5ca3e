"""The integrators' interface: `Integrator` (owns `advance`), fixed-step and adaptive bases.

The layout follows scipy's `integrate/_ivp/base.py`: the base class :class:`Integrator` owns
the bookkeeping in its public `advance` (counters, projection, health checks, output times);
a subclass implements one step. Adaptive methods also offer that step publicly
(:meth:`AdaptiveIntegrator.take_step`, as scipy's `OdeSolver.step`), which `advance` and the
"auto" method drive.

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
again. The system's protocol is :class:`gyro_sim.dynamics.system.OdeSystem`.
"""
from __future__ import annotations

import math
import warnings
from typing import TYPE_CHECKING

import numpy as np

from gyro_sim.errors import GyroSimError

if TYPE_CHECKING:
    from gyro_sim.dynamics.system import OdeSystem

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
H0_NEGLIGIBLE = 1e-5  # d0 or d1 below this: the scaled state or slope is negligible
H0_DEFAULT = 1e-6  # h0 then
H0_FRACTION = 0.01  # h0 = 0.01 d0 / d1; h1 = (0.01 / max(d1, d2)) ** (1 / (order + 1))
H0_GROWTH = 100.0  # the initial step is at most 100 h0
H0_TINY_DERIVATIVES = 1e-15  # d1, d2 below this: h1 = max(1e-6, 1e-3 h0)
H0_TINY_STEP = 1e-6
H0_TINY_FRACTION = 1e-3


class IntegrationError(GyroSimError, ArithmeticError):
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


def rms(x: np.ndarray) -> float:
    """Root mean square of x (n,): the weighted error norm of scipy's `norm`."""
    return math.sqrt(float(np.dot(x, x)) / x.size) if x.size else 0.0


def describe_nonfinite(y: np.ndarray) -> str:
    """Names the non-finite components of y (n,) or (k, n) (for error messages)."""
    bad = np.flatnonzero(~np.isfinite(y).reshape(y.shape[0], -1).all(axis=1)) if y.ndim > 1 \
        else np.flatnonzero(~np.isfinite(y))
    what = "stages" if y.ndim > 1 else "components"
    more = ", ..." if bad.size > MAX_REPORTED_COMPONENTS else ""
    return f"non-finite {what} {bad[:MAX_REPORTED_COMPONENTS].tolist()}{more}"


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
                                   describe_nonfinite(y))
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
                                   describe_nonfinite(out))

    def _integrate(self, t0, y, t1, te, Y) -> None:
        """Advance y (size,) in place from t0 to t1, filling Y at te (or both None)."""
        raise NotImplementedError


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

    def march(self, t0: float, y: np.ndarray, t1: float) -> None:
        """Advance y (size,) in place from t0 to t1 in equal steps of at most `step`, with no
        copy and no check of the start (for drivers of other methods, e.g. "fixed"); raises
        IntegrationError when a step leaves a non-finite state (y then holds it)."""
        self._march(t0, y, t1)

    def _march(self, t0: float, y: np.ndarray, t1: float) -> None:
        span = t1 - t0
        n = max(1, math.ceil(span / self.step - STEP_COUNT_SLACK))
        h = span / n
        done = self._march_compiled(t0, y, h, n)
        if done is not None:  # all n steps in one compiled call
            self.nsteps += done
            if done < n:
                raise IntegrationError(self.name, "state is not finite after the step", t0 + done * h,
                                       h, describe_nonfinite(y))
        else:
            for k in range(n):
                t = t0 + k * h
                self._step(t, y, h)
                self._project(y)
                if not np.isfinite(y).all():
                    raise IntegrationError(self.name, "state is not finite after the step", t, h,
                                           describe_nonfinite(y))
                self.nsteps += 1
        self.last_step = h

    def _march_compiled(self, t0: float, y: np.ndarray, h: float, n: int) -> int | None:
        """n steps of size h from (t0, y) in one compiled call, when the method and its system
        have one: y (size,) updated in place (projected after each step); returns the number
        of steps that left a finite state (n, or the index of the failing step, y then its
        non-finite result). None: no compiled loop, `_march` steps in Python with `_step`."""
        return None

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


class AdaptiveIntegrator(Integrator):
    """Steps chosen by error control, one accepted step at a time through a public call.

    As scipy's `OdeSolver.step`, the public single step owns the bookkeeping (projection,
    counters, the rhs at the new state); `advance` is this loop, and so is the "auto" method's:

        integ.begin(t0, y, t1)             # a call starts: a fresh rhs(t0, y)
        t = t0
        while t < t1:
            t = integ.take_step(t, y, t1)  # one accepted step; y (size,) is now the new state
            Y = integ.dense(tq)            # optional: states at times tq inside that step
        integ.end(t1, y)

    Subclasses implement `_step_impl` (one accepted step from (t, y) into `_y_new`), `_accept`
    (their bookkeeping of an accepted step) and `_dense` (the interpolant of the last step);
    they may extend `_rhs_at_new` (the rhs at the new state, evaluated when the next step or
    the dense output needs it), `begin` and `end`.
    """

    adaptive = True
    error_estimator_order: int = NotImplemented

    def __init__(self, system: OdeSystem, **options):
        super().__init__(system, **options)
        self._f = np.empty(self.n)  # rhs at the start of the current step
        self._y_new = np.empty(self.n)
        self._h_abs: float | None = None  # the step-size memory
        # the last accepted step: (t_old, y_old) -> (t_new, _y_new); rhs(t_new, y_new) in _f?
        self._t_old = self._t_new = 0.0
        self._y_old = np.empty(self.n)
        self._f_new = False

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
        self.begin(t0, y, t1)
        t = t0
        while t < t1:
            t = self.take_step(t, y, t1)
            k = j
            while k < m and te[k] < t:
                k += 1
            if k > j:
                Y[j:k] = self.dense(te[j:k])
                j = k
            while j < m and te[j] <= t:
                Y[j] = y
                j += 1
        self.end(t1, y)

    # --- the public single step ------------------------------------------------------------
    def begin(self, t0: float, y: np.ndarray, t1: float) -> None:
        """A call from (t0, y (size,)) towards t1 starts: a fresh rhs(t0, y) (inputs may have
        changed since the last call); on the first call after a reset, the initial step."""
        self._fresh_rhs(t0, y, self._f)
        if self._h_abs is None:
            self._h_abs = self._initial_step(t0, y, self._f, t1, self.error_estimator_order)

    def take_step(self, t: float, y: np.ndarray, t1: float) -> float:
        """Take one step from (t, y), as long as error control allows and at most to t1, and
        accept it: y (size,) becomes the new state (projected) in place; returns its time.

        Counts it in `nsteps`; sets `error_estimate` and `last_step`. Evaluates the rhs at the
        new state when a further step needs it (t_new < t1). Raises IntegrationError when the
        step size collapses or the rhs at the new state is not finite.
        """
        t_new = self._step_impl(t, y, t1)
        y_new = self._y_new
        self._project(y_new)
        self._accept(t, y, t_new, y_new)
        self._f_new = False
        if t_new < t1:
            self._rhs_at_new(t_new, y_new)
        self._t_old, self._t_new = t, t_new
        self._y_old[:] = y
        y[:] = y_new
        self.nsteps += 1
        return t_new

    def dense(self, tq: np.ndarray) -> np.ndarray:
        """States (k, size), projected, at times tq (k,) inside the step `take_step` just took.

        Evaluates the rhs at the step's end first if it is not known yet (the interpolant of
        DOP853 needs it).
        """
        if not self._f_new:
            self._rhs_at_new(self._t_new, self._y_new)
        Y = self._dense(self._t_old, self._y_old, self._t_new, self._y_new, tq)
        for row in Y:
            self._project(row)
        return Y

    def end(self, t1: float, y: np.ndarray) -> None:
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
        d0, d1 = rms(y0 / scale), rms(f0 / scale)
        h0 = H0_DEFAULT if d0 < H0_NEGLIGIBLE or d1 < H0_NEGLIGIBLE else H0_FRACTION * d0 / d1
        h0 = min(h0, span)
        if not h0 > 0.0:  # |f0| so large against |y0| that no step is representable
            raise IntegrationError(self.name, f"no starting step: the rhs is too large (weighted norm {d1:.3g})",
                                   t0, None)
        f1 = self._fun(t0 + h0, y0 + h0 * f0)
        d2 = rms((f1 - f0) / scale) / h0
        if not math.isfinite(d2):
            d2 = 0.0
        if d1 <= H0_TINY_DERIVATIVES and d2 <= H0_TINY_DERIVATIVES:
            h1 = max(H0_TINY_STEP, h0 * H0_TINY_FRACTION)
        else:
            h1 = (H0_FRACTION / max(d1, d2)) ** (1.0 / (order + 1))
        return min(H0_GROWTH * h0, h1, span, self.max_step)

    def _step_impl(self, t: float, y: np.ndarray, t1: float) -> float:
        """One accepted step from (t, y), at most to t1: fills `_y_new`, returns t_new."""
        raise NotImplementedError

    def _accept(self, t, y, t_new, y_new) -> None:
        """The subclass's bookkeeping of an accepted step (y_new projected, y still the old
        state); the rhs at the new state is not known yet."""

    def _dense(self, t, y, t_new, y_new, tq: np.ndarray) -> np.ndarray:
        """States (k, size) at times tq (k,) inside the step (t, t_new) just accepted."""
        raise NotImplementedError

    def _rhs_at_new(self, t_new: float, y_new: np.ndarray) -> None:
        """_f = rhs(t_new, y_new) of an accepted state, which must be finite."""
        self._f[:] = self._fun(t_new, y_new)
        if not np.isfinite(self._f).all():
            raise IntegrationError(self.name, "rhs is not finite at the accepted state", t_new,
                                   self.last_step, describe_nonfinite(self._f))
        self._f_new = True


class WholeAdvanceLoop:
    """Mixin: an adaptive method whose whole `advance` may run as one compiled loop, on a system
    that offers the kernel (its `_loop`, None otherwise, and `_integrate_compiled`)."""

    _loop = None

    @property
    def compiled(self) -> bool:
        """Does `advance` (and `advance_detecting`) run the compiled loop?"""
        return self._loop is not None

    def advance_detecting(self, t0: float, y: np.ndarray, t1: float, te, Y, detection: tuple) -> tuple[float, int]:
        """For "auto": the compiled loop in its detection mode (see `_integrate_compiled`):
        y advanced in place from t0 towards t1 > t0, Y filled at te; returns (time reached,
        reason code or 0)."""
        return self._integrate_compiled(t0, y, t1, te, Y, detection)
