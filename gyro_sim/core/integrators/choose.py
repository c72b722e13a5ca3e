"""The node's fixed-step method for a scene: rk4 where it is stable at the step, gauss4 where
the scene is stiff (issue 10, item 2); and the integrator "fixed" that makes this choice at the
start and again as the motion changes (:class:`SceneFixedStep`, the node's default).

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

A scene that starts soft may stiffen: a commanded moment spins a body up, and the gyroscopic
eigenvalues grow with the spin (and the commanded moments enter the Jacobian themselves,
through M(q)^-1 tau). So "fixed" re-estimates h |lambda| at the start of an `advance` (with the
commands then held) when CHECK_PERIOD of simulated time has passed since the last estimate, or,
at most every MIN_RECHECK, when the commanded values changed or the largest generalised speed
has moved by more than a factor SPEED_CHANGE (with RECHECK_DIM Krylov vectors: at most 11 rhs
evaluations, against the 80 that 20 ms of rk4 at 1 kHz take); and switches: to gauss4 above the rk4 limit, back to rk4 below
RK4_RETURN of it (hysteresis: no flapping at the boundary). A speed that grows within one call
(a huge step moment spins a link up in milliseconds: the estimate at the command saw a chain at
rest) can still take rk4 past its limit: when rk4 leaves a non-finite state, the call is taken
again from its start with gauss4. Every decision depends only on the simulated states and
commands, and the estimate is deterministic (a seeded start vector), so a re-simulation makes
the same switches bit for bit.
"""
from __future__ import annotations

import math
import numpy as np

from .base import EPS, FixedStepIntegrator, IntegrationError

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
#: "fixed": simulated seconds between two estimates of h |lambda|
CHECK_PERIOD = 0.1
#: "fixed": back from gauss4 to rk4 only below this fraction of rk4's chosen limit
RK4_RETURN = 0.5
#: "fixed": a new estimate when the largest |generalised speed| changed by more than this factor
SPEED_CHANGE = 1.5
#: "fixed": estimates triggered by commands or speeds at most this often (simulated s)
MIN_RECHECK = 0.02
#: "fixed": Krylov vectors of the estimates after the first (the first takes KRYLOV_DIM)
RECHECK_DIM = 10


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
    name, reason, _ = _choice(sim.system.rhs, sim.time, sim.state, dt, "rk4")
    return name, reason


def _choice(rhs, t: float, y: np.ndarray, h: float, now: str, dim: int = KRYLOV_DIM) -> tuple[str, str, float]:
    """(method, reason, h |lambda|) at (t, y) for step h, given the method used `now` (the
    hysteresis of RK4_RETURN applies when leaving gauss4), from `dim` Krylov vectors."""
    hl = h * spectral_radius_estimate(rhs, t, y, dim)
    limit = RK4_SAFETY * RK4_IMAG_LIMIT
    back = limit if now == "rk4" else RK4_RETURN * limit
    if hl < back:
        return "rk4", f"rk4: h |lambda| = {hl:.2g} (stable below {limit:.2g})", hl
    return "gauss4", (f"gauss4: h |lambda| = {hl:.2g}: stiff for rk4 "
                      f"(rk4 needs below {back:.2g} at h = {h:g} s)"), hl


class SceneFixedStep(FixedStepIntegrator):
    """"fixed": rk4 where the scene is soft at the step, gauss4 where it is stiff, re-chosen
    as the motion and the commands change (see the module docstring). Order 4 (both methods
    are), fixed step, one step per physics step.

    Attributes
    ----------
    current : the method stepping now ("rk4" or "gauss4").
    reason : one line: why (h |lambda| against rk4's limit).
    h_lambda : the last estimate of h |lambda|.
    switches : the changes after the first choice, (t, from, to, reason) each (as "auto").

    References
    ----------
    .. [1] E. Hairer, G. Wanner, "Solving Ordinary Differential Equations II", 2nd ed.,
           Springer 1996, sec. IV.2 (stability regions: RK4's along the imaginary axis).
    .. [2] Y. Saad, "Numerical Methods for Large Eigenvalue Problems", 2nd ed., SIAM 2011,
           ch. 6 (Arnoldi's method: the Ritz values of the estimate).
    """

    name = "fixed"
    order = 4

    def __init__(self, system, **options):
        super().__init__(system, **options)
        from .gauss import Gauss4  # here: gauss imports this package's base, not the reverse
        from .rk4 import RK4

        self.methods = {"rk4": RK4(system, **options), "gauss4": Gauss4(system, **options)}
        self.current = ""
        self.reason = ""
        self.h_lambda = math.nan
        self.switches: list[tuple[float, str, str, str]] = []
        self._next_check = -math.inf
        self._last_check = -math.inf
        self._check_fev = 0
        self._inputs_seen = -1
        self._speed_seen = 0.0
        model = getattr(system, "model", None)
        self._speeds = getattr(model, "i_vel", None)
        if self._speeds is None:
            self._speeds = self.lin_index
        self._speeds = np.arange(self.n)[self._speeds]  # a slice or indices: indices
        self._y0 = np.empty(self.n)

    def reset(self) -> None:
        super().reset()
        for m in self.methods.values():
            m.reset()
        self._next_check = -math.inf
        self._last_check = -math.inf
        self.current = ""

    def warm_up(self, t0: float, y: np.ndarray) -> None:
        """One step of each method on a copy of y (then forgotten): every compiled path this
        integrator may switch to is compiled (or loaded from the cache) now, not at the first
        switch in the middle of a real-time run. Counters are kept as they were."""
        counts = {name: (m.nfev, m.nsteps, m.njev, m.nlu) for name, m in self.methods.items()}
        try:
            for m in self.methods.values():
                m.march(t0, y.copy(), t0 + self.step)
        except IntegrationError:
            pass  # a scene a method cannot step from here: it is compiled all the same
        finally:
            for name, m in self.methods.items():
                m.nfev, m.nsteps, m.njev, m.nlu = counts[name]
                m.reset()

    def _speed(self, y: np.ndarray) -> float:
        return float(np.abs(y[self._speeds]).max()) if len(self._speeds) else 0.0

    def _due(self, t0: float, y: np.ndarray) -> bool:
        if t0 >= self._next_check:
            return True
        if t0 < self._last_check + MIN_RECHECK:
            return False
        if getattr(self.system, "inputs_version", 0) != self._inputs_seen:
            return True
        v, seen = self._speed(y), self._speed_seen
        return v > SPEED_CHANGE * seen or v * SPEED_CHANGE < seen

    def _switch(self, t: float, name: str) -> None:
        if self.current and name != self.current:
            self.switches.append((t, self.current, name, self.reason))
            self.methods[name].reset()
        self.current = name

    def _counted_rhs(self, t: float, y: np.ndarray) -> np.ndarray:
        self._check_fev += 1
        return self._rhs(t, y)

    def _march(self, t0: float, y: np.ndarray, t1: float) -> None:
        if self._due(t0, y):
            dim = RECHECK_DIM if self.current else KRYLOV_DIM
            name, self.reason, self.h_lambda = _choice(self._counted_rhs, t0, y, self.step, self.current or "rk4", dim)
            self._switch(t0, name)
            self._last_check = t0
            self._next_check = t0 + CHECK_PERIOD
            self._inputs_seen = getattr(self.system, "inputs_version", 0)
            self._speed_seen = self._speed(y)
        m = self.methods[self.current]
        try:
            if self.current == "rk4":
                self._y0[:] = y
                try:
                    m.march(t0, y, t1)
                except IntegrationError as e:  # past rk4's limit within the call: again with gauss4
                    y[:] = self._y0
                    self.reason = f"gauss4: rk4 left a non-finite state at t = {e.t:.6g} s"
                    self._switch(t0, "gauss4")
                    self._next_check = t0 + CHECK_PERIOD
                    m = self.methods["gauss4"]
                    m.march(t0, y, t1)
            else:
                m.march(t0, y, t1)
        finally:
            ms = self.methods.values()
            self.nfev = self._check_fev + sum(x.nfev for x in ms)
            self.nsteps = sum(x.nsteps for x in ms)
            self.njev = sum(x.njev for x in ms)
            self.nlu = sum(x.nlu for x in ms)
            self.last_step = m.last_step
