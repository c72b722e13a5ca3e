"""The "auto" method: dop853 while the problem is not stiff, radau while it is."""
from __future__ import annotations

import math
import warnings
from typing import TYPE_CHECKING

import numpy as np

from gyro_sim.integrators.dop853 import loop as fast_dop853
from gyro_sim.integrators.radau import loop as fast_radau
from gyro_sim.integrators.dop853.kernels import (
    C_STIFF, COST_DOP853, COST_RADAU, COST_SIZE, COUNTERS_SIZE, DETECT_SIZE, auto_clear_attempts,
    auto_costlier, auto_measure, auto_rejection_test, auto_rejections, auto_stiffness_test,
)
from gyro_sim.integrators.radau.kernels import (
    EASY_NEEDED, EASY_RHO, EASY_SIZE, EASY_STALE, EASY_STEPS, HANDBACK_SIZE, auto_cost_test,
    auto_dop853_cost, auto_nonstiffness_test, auto_spectral_radius,
)
from gyro_sim.integrators.base import AdaptiveIntegrator, IntegrationError, Integrator
from gyro_sim.integrators.dop853.driver import DOP853
from gyro_sim.integrators.radau.driver import Radau

if TYPE_CHECKING:
    from gyro_sim.dynamics.system import OdeSystem

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
#: rho(J) from eigenvalues up to this size, above it from a few power iterations (from a
#: start drawn once, np.random.default_rng(0))
EIG_MAX_SIZE = 200
POWER_ITERATIONS = 30
#: the slot of each method in the cost array
COST_SLOT = {"dop853": COST_DOP853, "radau": COST_RADAU}


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

    The tests on DOP853's steps (h |lambda|, rejections, cost) are one implementation,
    :mod:`gyro_sim.integrators.dop853.kernels` (`dop_hlamb`, `auto_*`), on state arrays this class
    owns, with two drivers that give the same bits (decisions, switch times, states,
    counters): on a system with the compiled kernel (FastChainODE) DOP853's compiled loop
    runs a whole `advance` in its detection mode (:func:`gyro_sim.integrators.dop853.loop.dop853_advance`),
    stopping at the accepted state where a test asks for a switch; on any other system this
    class steps DOP853 by its public single step (`begin` / `take_step` / `dense`) and calls
    the tests after each accepted step. Likewise Radau's phase: the tests on its steps
    (rho(J) when its Jacobian is refreshed, h rho, cost) are one implementation,
    :mod:`gyro_sim.integrators.radau.kernels` (`auto_*`), run inside Radau's compiled loop in its
    detection mode (:func:`gyro_sim.integrators.radau.loop.radau_advance`: one compiled call per
    `advance`, stopping where a test asks for the hand-back) on a system where Radau has it
    (FastChainODE, dense mode), and after each of its public single steps otherwise (the
    matrix-free mode among them, whose rho is a Krylov estimate,
    :func:`gyro_sim.integrators.fixed.spectral_radius_estimate`).

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
        # the tests' constants and state (dop853_kernels): counts, attempts, (dt, nfev) of
        # steps, cost; the windows as long as their arrays
        self._detect = np.array([STIFF_HLAMB, STIFF_STEPS, NONSTIFF_RESET, REJECT_FRACTION])
        assert self._detect.size == DETECT_SIZE
        self._counters = np.zeros(COUNTERS_SIZE, dtype=np.int64)
        self._attempts = np.zeros(REJECT_WINDOW, dtype=np.int64)
        self._window = np.zeros((COST_WINDOW, 2))
        self._cost = np.full(COST_SIZE, math.nan)  # rhs evaluations per simulated s, by method
        self._detection = (self._detect, self._counters, self._attempts, self._window, self._cost)
        # the hand-back tests' constants and state (radau_kernels), the power iterations' start
        self._handback = np.array([NONSTIFF_HRHO, COST_MARGIN, DOP853_EVALS, DOP853_BOUNDARY,
                                   EIG_MAX_SIZE, POWER_ITERATIONS], dtype=float)
        assert self._handback.size == HANDBACK_SIZE
        self._easy = np.zeros(EASY_SIZE)
        n = self.explicit.n
        self._power = (np.random.default_rng(0).standard_normal(n) if n > EIG_MAX_SIZE
                       else np.zeros(0))
        self._handback_detection = (self._counters, self._window, self._cost, self._handback,
                                    self._easy, self._power)
        self.reset()

    def warm_up(self, t0: float, y: np.ndarray) -> None:
        """Compile (or load from numba's disk cache) now what a switch to radau runs, not at
        the first switch in the middle of a real-time run: radau's compiled loop, or the
        kernels of the hand-back tests where radau steps from Python. The state and counters
        are left as they were."""
        if self.implicit.compiled:
            self.implicit.load_loop()
        elif self.explicit.compiled:
            counters, window = np.zeros_like(self._counters), np.zeros_like(self._window)
            cost, easy = np.zeros_like(self._cost), np.zeros_like(self._easy)
            auto_measure(0.0, 0, counters, window, cost, COST_RADAU)
            auto_nonstiffness_test(0.0, easy, self._handback)
            auto_cost_test(cost, counters, window, easy, self._handback)

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
        self._easy[EASY_NEEDED] = NONSTIFF_STEPS
        self._cost[:] = math.nan
        self._new_episode()
        self._sync()

    def _new_episode(self) -> None:
        """Forget the detection state (at a reset or a switch)."""
        self._counters[:] = 0  # dop853.f's IASTI, NONSTI; the attempts and cost windows empty
        self._easy[EASY_RHO] = math.nan  # rho(J) of radau's Jacobian: none yet,
        self._easy[EASY_STALE] = 1.0  # to be computed at the first test
        self._easy[EASY_STEPS] = 0.0  # radau steps in a row with h rho < NONSTIFF_HRHO

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
                    if self._current.compiled:
                        t = self._run_compiled(t, y, t1, te, Y)
                    else:
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

    def _run_compiled(self, t: float, y: np.ndarray, t1: float, te, Y) -> float:
        """The running method's compiled loop in its detection mode advances y from t towards
        t1, filling Y at te from the next output on: `_run` in one compiled call."""
        j = self._j
        inner = self._current
        detection = self._detection if inner is self.explicit else self._handback_detection
        try:
            t, code = inner.advance_detecting(
                t, y, t1, None if te is None else te[j:], None if Y is None else Y[j:], detection)
        finally:
            self._j = j + inner.outputs_filled
        if code:
            raise _Switch(t, self._reason(code))
        return t

    def _run(self, inner: AdaptiveIntegrator, t: float, y: np.ndarray, t1: float, te, Y) -> float:
        """`inner` advances y from t towards t1 by its public single steps, as its own `advance`
        would, with the checks after each accepted step; raises _Switch(t, reason) to hand
        over at an accepted state."""
        m = 0 if te is None else te.size
        explicit = inner is self.explicit
        nfev = inner.nfev
        njev = inner.njev
        inner.begin(t, y, t1)
        if explicit and inner.hlamb is not None:  # the previous call's last step, tested now
            if auto_stiffness_test(inner.hlamb, self._counters, self._detect):
                raise _Switch(t, self._reason(fast_dop853.REASON_STIFF))
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
                code = 0
                if inner.hlamb is not None and auto_stiffness_test(inner.hlamb, self._counters,
                                                                   self._detect):
                    code = fast_dop853.REASON_STIFF
                if auto_rejection_test(inner.nrejected - rejected, self._counters, self._attempts,
                                       self._detect):
                    code = fast_dop853.REASON_REJECTED
                reason = self._reason(code) if code else None
            else:
                if inner.njev != njev:  # a Jacobian refreshed: its rho is due
                    self._easy[EASY_STALE] = 1.0
                    njev = inner.njev
                reason = self._nonstiffness_test(h)
            t = t_new
            while self._j < m and te[self._j] <= t:
                Y[self._j] = y
                self._j += 1
            auto_measure(h, inner.nfev - nfev, self._counters, self._window, self._cost,
                         COST_SLOT[inner.name])
            nfev = inner.nfev
            if explicit and reason is not None and auto_costlier(self._cost, COST_RADAU,
                                                                 COST_DOP853, 1.0):
                self._counters[C_STIFF] = 0  # radau was measured slower here: keep going
                auto_clear_attempts(self._counters)
                reason = None
            if not explicit and reason is None:
                reason = self._cost_test()
            if reason is not None and t < t1:
                inner.end(t, y)
                raise _Switch(t, reason)
        inner.end(t1, y)
        return t

    # --- detection -------------------------------------------------------------------------
    def _reason(self, code: int) -> str:
        """The reason of a switch asked for by a test (fast_dop853.REASON_*,
        fast_radau.REASON_*), read when it is asked for."""
        if code == fast_dop853.REASON_STIFF:
            return f"stiff: h |lambda| > {STIFF_HLAMB:g} in {STIFF_STEPS} steps"
        if code == fast_dop853.REASON_REJECTED:
            n_rej, n_all = auto_rejections(self._counters, self._attempts)
            return f"stiff: {n_rej} of the last {n_all} step attempts rejected"
        if code == fast_radau.REASON_NONSTIFF:
            return f"not stiff: h rho(J) < {NONSTIFF_HRHO:g} in {int(self._easy[EASY_NEEDED])} steps"
        radau = float(self._cost[COST_RADAU])
        dop = float(auto_dop853_cost(self._cost, self._easy, self._handback))
        return f"radau costs {radau:.3g} rhs evaluations per simulated s, dop853 {dop:.3g}"

    def _nonstiffness_test(self, h: float) -> str | None:
        """Radau running, after its step h: rho(J) if its Jacobian was refreshed since the last
        rho, then the test on h rho (radau_kernels.auto_nonstiffness_test)."""
        imp, easy = self.implicit, self._easy
        if easy[EASY_STALE] and imp.jacobian is not None:
            easy[EASY_RHO] = auto_spectral_radius(imp.jacobian, self._power, self._handback)
            easy[EASY_STALE] = 0.0
        elif easy[EASY_STALE] and imp.jacobian_point is not None:  # matrix-free radau
            from gyro_sim.integrators.fixed import spectral_radius_estimate

            t_j, y_j = imp.jacobian_point
            easy[EASY_RHO] = spectral_radius_estimate(self._fun, t_j, y_j)
            easy[EASY_STALE] = 0.0
        if auto_nonstiffness_test(h, easy, self._handback):
            return self._reason(fast_radau.REASON_NONSTIFF)
        return None

    def _cost_test(self) -> str | None:
        """Radau running: a reason to hand back if it costs more than dop853 would
        (radau_kernels.auto_cost_test)."""
        if auto_cost_test(self._cost, self._counters, self._window, self._easy, self._handback):
            return self._reason(fast_radau.REASON_COSTLY)
        return None

    def _switch(self, t: float, reason: str) -> None:
        old = self._current
        new = self.implicit if old is self.explicit else self.explicit
        if new is self.implicit and any(s[2] == "dop853" for s in self.switches):
            self._easy[EASY_NEEDED] *= 2  # stiff again after a return: wait longer next time
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

