"""The "auto" method: dop853 while the problem is not stiff, radau while it is."""
from __future__ import annotations

import math
import warnings
from typing import TYPE_CHECKING

import numpy as np

from .base import AdaptiveIntegrator, IntegrationError, Integrator
from .dop853 import DOP853
from .radau import Radau

if TYPE_CHECKING:
    from ..system import OdeSystem

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
        self.explicit = DOP853(system, stiffness_estimate=True, **inner)
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
        """`inner` advances y from t towards t1 by its public single steps, as its own `advance`
        would, with the checks after each accepted step; raises _Switch(t, reason) to hand
        over at an accepted state."""
        m = 0 if te is None else te.size
        explicit = inner is self.explicit
        nfev = inner.nfev
        inner.begin(t, y, t1)
        if explicit and inner.hlamb is not None:  # the previous call's last step, tested now
            self._raise_if(t, self._stiffness_test(inner.hlamb))
        while t < t1:
            rejected = inner.nrejected
            t_new = inner.take_step(t, y, t1)
            h = t_new - t
            k = self._j
            while k < m and te[k] < t_new:
                k += 1
            if k > self._j:
                Y[self._j:k] = inner.dense(te[self._j:k])
                self._j = k
            if explicit:
                # hlamb is None until f(y1) is known: then the next call tests this step
                reason = None if inner.hlamb is None else self._stiffness_test(inner.hlamb)
                reason = self._rejection_test(inner.nrejected - rejected) or reason
            else:
                reason = self._nonstiffness_test(h)
            t = t_new
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
                inner.end(t, y)
                raise _Switch(t, reason)
        inner.end(t1, y)
        return t

    @staticmethod
    def _raise_if(t: float, reason: str | None) -> None:
        if reason is not None:
            raise _Switch(t, reason)

    # --- detection -------------------------------------------------------------------------
    def _stiffness_test(self, hlamb: float) -> str | None:
        """dop853.f's test on one accepted step, given its h |lambda| (DOP853.hlamb); a reason
        to switch, or None."""
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
        if imp.njev != self._rho_njev and imp.jacobian is not None:
            self._rho = _spectral_radius(imp.jacobian)
            self._rho_njev = imp.njev
        elif imp.njev != self._rho_njev and imp.jacobian_point is not None:  # matrix-free radau
            from .choose import spectral_radius_estimate

            t_j, y_j = imp.jacobian_point
            self._rho = spectral_radius_estimate(self._fun, t_j, y_j)
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
