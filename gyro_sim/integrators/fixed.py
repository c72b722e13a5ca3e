"""The node's fixed-step method for a scene: rk4 where it is stable at the step, gauss4s (the
Gauss method on the scene's canonical equations, a chain's or a tree's: A-stable and
symplectic, momenta kept to round-off) where the scene is stiff ; and the integrator "fixed" that
makes this choice at the start and again as the motion changes (:class:`SceneFixedStep`, the
node's default). On a system that is not a scene's (and on stateful actuators) the implicit
rung is gauss4, the same method on the system's own state. Below, "gauss4" stands
for either where the two behave alike.

RK4 is stable for h lambda inside its stability region, which reaches RK4_IMAG_LIMIT = 2 sqrt 2
along the imaginary axis (gyroscopic nutation: eigenvalues +-i w) and 2.785 along the negative
real axis (Hairer, Wanner, "Solving Ordinary Differential Equations II", 2nd ed., Springer 1996,
sec. IV.2, Fig. 2.1). The scene's largest |lambda| is estimated at the initial state, with the
commands held, from Krylov (Arnoldi) iterations on Jacobian-vector products of the rhs by
forward differences: O(size) memory, at most KRYLOV_DIM + 1 rhs evaluations, and exact (up to
the differences) when size <= KRYLOV_DIM. rk4 is chosen when h |lambda| stays below
RK4_SAFETY x RK4_IMAG_LIMIT (the margin covers the estimate and the motion moving the
eigenvalues); otherwise gauss4, A-stable, whose Newton iteration is the remaining limit.

A body that turns fast must be resolved whatever the method: on the heavy top at 1e3 rad/s
(1 rad a 1 ms step, h |lambda| = 0.61, inside rk4's region) rk4's energy grew x2.8 over 1e6
steps without leaving a finite state, and gauss4 at 1e4 rad/s (10 rad a step) kept the energy
but precessed the wrong way. So each physics step is cut into `substeps` so that no body turns
more than SPIN_RESOLVE rad in one (`body_rate_bound`: the sum of the joints' relative rates;
rotors excluded, their angles never enter the dynamics), at most MAX_SUBSTEPS, and the method
is chosen for the substep. Measured over 5 s against the exact regular precession (eq 88,
`gyro_sim.bench.spin_sweep`): the heavy top at 1e3 rad/s rk4 x4 (axis error 1.9e-5 rad, where
rk4 at 1 ms gets 5.5e-3), at 1e4 rad/s rk4 x40 (1.9e-6; CPU 0.34 s per simulated s, n = 1);
the double gyroscope at 1e3 rk4 x7 (2.8e-5), at 1e4 rk4 x64 (4.1e-6; 0.54 s per s).

    name, reason = fixed_step_method(sim, 1e-3)   # ("rk4", "rk4: h |lambda| = 0.12 ...")
    c = fixed_step_choice(sim, 1e-3)              # Choice("rk4", 40, "rk4 x40 substeps ...", 0.16)

A scene that starts soft may stiffen: a commanded moment spins a body up, and the gyroscopic
eigenvalues grow with the spin (and the commanded moments enter the Jacobian themselves,
through M(q)^-1 tau). So "fixed" re-estimates h |lambda| at the start of an `advance` (with the
commands then held) when CHECK_PERIOD of simulated time has passed since the last estimate, or,
at most every MIN_RECHECK, when the commanded values changed or the largest generalised speed
has moved by more than a factor SPEED_CHANGE (with RECHECK_DIM Krylov vectors: at most 11 rhs
evaluations, against the 80 that 20 ms of rk4 at 1 kHz take); and switches: to gauss4 above the rk4 limit, back to rk4
below
RK4_RETURN of it (hysteresis: no flapping at the boundary). A speed that grows within one call
(a huge step moment spins a link up in milliseconds: the estimate at the command saw a chain at
rest) can still take rk4 past its limit. So a call that fails is taken again from its start one
rung down: rk4 -> gauss4 -> RESCUE (dop853, adaptive at RESCUE_RTOL and RESCUE_ATOL, its
Python driver on the compiled kernels, no step longer than the physics step), which then
stays until the next scheduled check (CHECK_PERIOD); only a call dop853 cannot take either
(its step size collapses: a singular scene) is a simulation error. A call fails when its
method raises (a non-finite state, Newton not converging) or when the energy watchdog, the
`monitor` the Simulator sets where the exact motion keeps an energy (energy, or the Jacobi
integral without commands; compiled backend), finds the call's energy error (E1 - E0 - work
of the held moments) above ENERGY_WATCH x its length x the kinetic energy: a step that does
not resolve the motion no longer passes silently. The heavy tip of mass ratio 1e6 is the case
that needs every rung: when the chain straightens its light links whip (~1e8 rad/s^2 for
~0.1 ms), rk4 fails at any step down to 16 us, gauss4's Newton iteration diverges, dop853
takes ~150 steps through it; over 0.3 s "fixed" keeps the energy to 1.4 J where rk4 with the
non-finite retake alone ran away to 3.6e12 J. Every decision depends only on the simulated
states and commands, and the estimate is deterministic (a seeded start vector), so a
re-simulation makes the same switches bit for bit.

That ladder has no bound on its cost: on a violent command (moments of 1e3 x gravity torque on
the hinge chain) it takes dop853 at 7,000-20,000 evaluations a 10 ms call. So "fixed"
keeps to a real-time budget, counted in rhs evaluations (EVAL_BUDGET a physics step on
average, bursts of BURST_STEPS' worth: a credit), and tries a rung below only where the call
can pay what it is expected to cost (`_implicit_cost`, `_rescue_cost`: at most the credit and
CALL_BURST beyond the call's share). New commands choose the substeps from the rates they
reach within the call (`_rate_ahead`); rk4 in substeps that fails is taken again in
MAX_SUBSTEPS first; a stiff call the budget cannot pay the implicit rung for takes rk4 in the
substeps that make it stable (BUDGET_RK4_SAFETY), else BUDGET_RUNG
(:class:`LinearlyImplicitEuler`: L-stable, a fixed cost of size + 1 evaluations a step),
whose calls no rescue retakes; a rung that failed waits until the scene is soft again. Over
budget, the watchdog reports instead of retaking (up to OVER_BUDGET_WATCH). The calls kept and
their energy errors are counted (`budget_calls`, `budget_energy_error`: the node's
/diagnostics). docs/integrators.md states the policy, docs/performance.md its measured counts
on the violent family.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gyro_sim.integrators.base import EPS, FixedStepIntegrator, IntegrationError

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
#: most rotation of a body in one (sub)step, rad: a faster body is stepped in substeps
SPIN_RESOLVE = 0.25
#: most substeps of one physics step
MAX_SUBSTEPS = 64
#: "fixed": the method of a stiff chain or tree (symplectic: docs/integrators.md); a system
#: that is not a scene's (no `model`), or one of more than IMPLICIT_MAX_BODIES bodies, gets gauss4,
#: the same method on the package's state
IMPLICIT = "gauss4s"
IMPLICIT_PLAIN = "gauss4"
#: gauss4s's Newton-GMRES needs ~2.5x gauss4's Krylov vectors on a long swinging chain (n = 100:
#: 81 against 37 rhs evaluations a step after 2 s; median step 1.1 ms against 0.41 ms, under
#: load): the largest n holding 1 kHz measured ~77 against ~205 (`gyro-sim bench stability
#: --parts cost`). Up to this many bodies gauss4s holds it with a margin. The
#: preconditioner that would give it gauss4's conditioning costs more than it saves (each
#: Krylov vector would take ~6 field evaluations instead of 2: docs/integrators.md).
IMPLICIT_MAX_BODIES = 50


def implicit_for(model) -> str:
    """The implicit rung of "fixed" for a scene's model, a chain or a tree (None: a system that
    is not a scene's). A model whose actuators are states (friction, max_speed:
    `Model.stateful`) gets gauss4 on its own state: the canonical equations of gauss4s have no
    place for them, nor for servos (which make a model stateful)."""
    canonical = model is not None and not model.stateful
    return IMPLICIT if canonical and model.n <= IMPLICIT_MAX_BODIES else IMPLICIT_PLAIN
#: "fixed": the last resort of a call that rk4 and the implicit method both fail (adaptive,
#: error-controlled)
RESCUE = "dop853"
#: the rescue's tolerances (or the integrator's, when tighter): the calls it takes are the
#: violent ones (the step moments of 1e3 x gravity on the hinge chain drift 1.5e-5 in energy
#: at rtol 1e-8, 7.9e-8 at 1e-10, `gyro-sim bench stability --cases abrupt`)
RESCUE_RTOL = 1e-10
RESCUE_ATOL = 1e-12
#: the rescue's evaluations a step (dop853's stages, its FSAL evaluation saved) and the turn of
#: the fastest motion in one of its steps at RESCUE_RTOL: on the hinge chain through the violent
#: steps it took 4,500 steps (54,212 evaluations) for 10 ms at |lambda| = 1.5e5 (0.33 rad a
#: step), 1,470 steps (17,653) for 10 ms with links at 2.1e4 rad/s (0.14 rad a step)
RESCUE_STAGES = 12
RESCUE_TURN = 0.14
#: "fixed": the energy watchdog's limit on a call's energy error, relative to the kinetic
#: energy, per simulated second of the call (1e-5 for the node's 10 ms calls; rk4 at 1 ms on the
#: shipped scenes stays below 4.2e-7 a call, config/chain_4.yaml the highest)
ENERGY_WATCH = 1e-3
#: "fixed": the real-time budget, rhs evaluations per physics step on average. From the cost of
#: one evaluation: the hinge chain's, in rk4's compiled loop, measured 0.6-1.1 us of CPU (the
#: command in docs/integrators.md); 400 of them take at most 0.44 ms, less than half of a 1 ms
#: period, leaving the rest to the outputs, the publications and a second process on the core.
#: rk4 at MAX_SUBSTEPS (256 a step) and its re-estimates fit in it with room to pay back a burst.
EVAL_BUDGET = 400
#: "fixed": the implicit rung's evaluations a substep expected before its first call, in units of
#: size + 1 (its Jacobian's): on the hinge chain (size 19) through the violent steps gauss4s took
#: 101 a substep where it converged and up to 245 where its iteration failed; after a call,
#: taken or failed, what that call took
IMPLICIT_PRIOR = 12
#: "fixed": the burst the budget allows, in physics steps' worth of EVAL_BUDGET: a call may
#: overspend (a retake, the rescue) while the credit lasts. 150 steps = 60,000 evaluations, ~66 ms
#: of CPU at the cost above (~140 ms in the rescue's Python driver): the heavy tip's whips (up to
#: 56,000 evaluations of the rescue each) pass at full accuracy
BURST_STEPS = 150
#: "fixed", in place of an implicit rung the budget cannot pay for: rk4 in the substeps that
#: bring h |lambda| below this fraction of its limit (at most MAX_SUBSTEPS), closer to the limit
#: than RK4_SAFETY: the watchdog still sees every call
BUDGET_RK4_SAFETY = 0.9
#: ... in at most this many substeps (4 evaluations each: 384 a step, within EVAL_BUDGET)
BUDGET_MAX_SUBSTEPS = 96
#: "fixed": the most a rung below (the implicit rung, the rescue) may be expected to cost in one
#: call beyond the call's share of the budget (rhs evaluations), however much credit is left: a
#: call whose rungs below are expected to cost more keeps the budget's ways (rk4 in its most
#: substeps, its own result with its error reported, the budget's rung). About 30 ms of the
#: rescue's CPU (2.2-3.3 us an evaluation in its Python driver, the hinge chain, 2 cores), what
#: the node's pacer makes up at once (MAX_CATCH_UP: 300 ms of lateness); the heavy tip's
#: whips after its first, expected below it, pass at full accuracy
CALL_BURST = 12_000
#: "fixed", over its budget: a call whose energy error is below this (relative to the kinetic
#: energy, per simulated second) is kept and its error reported, not retaken; above it the call
#: is retaken by the budget's rung, then by the rescue within one burst, and past that the budget
#: rung's result is kept (its error reported): what a call costs has a bound
OVER_BUDGET_WATCH = 1.0
#: "fixed", over its budget: how far the calls kept with their errors reported may multiply the
#: kinetic energy, compounded (a gain err of a call's kinetic energy multiplies it by 1 / (1 -
#: err), a loss by 1 + err; a later loss pays a gain back). A kept call may overshoot: the
#: budget's rung, L-stable, damps back in the next calls what it cannot resolve (on the hinge chain
#: pushed at 1e3 x for 1.5 s, x100 then / 100). Past this factor the calls diverge, the state no
#: longer the motion's (the budget's rung on a free chain whose spun-up wheels nutate faster than
#: it follows: x100, x14, then without bound), and the run ends in a simulation error
#: (BudgetOutrun) rather than publish it. A non-finite energy ends it too.
KEEP_GROWTH = 1e4
#: "fixed", over its budget: the method of a call rk4 cannot take within the budget, and of its
#: retakes (in place of the implicit rung and the rescue, whose cost has no bound): the linearly
#: implicit Euler step (:class:`LinearlyImplicitEuler`), L-stable, size + 1 evaluations a step
BUDGET_RUNG = "rosenbrock1"
#: the methods whose compiled code this process has run (:meth:`SceneFixedStep.warm_up`): numba
#: has no public "is it compiled?", and a first call compiles, or loads from the cache, in the
#: calling thread. A guarded "fixed" (the node's) takes no other rung than rk4 and BUDGET_RUNG
#: (numpy on the compiled rhs: nothing to compile) until its method is here
WARM: set[str] = set()


class WatchdogTrip(IntegrationError):
    """A call of "fixed" broke the energy balance by more than its watchdog allows (ENERGY_WATCH
    per simulated second, relative to the kinetic energy): the state is finite, not accurate.
    `error`: the call's energy error, relative to the kinetic energy."""

    def __init__(self, method: str, error: float, t: float, h: float, span: float):
        super().__init__(method, f"energy watchdog: {error:.2g} of the kinetic energy in {span:.3g} s", t, h)
        self.error = error


class RescueOverspent(IntegrationError):
    """The rescue, taking a call over budget, spent the budget's whole burst without finishing."""


class BudgetOutrun(IntegrationError):
    """Calls no rung the budget pays for takes kept multiplying the kinetic energy past KEEP_GROWTH:
    the motion has outrun what real time can resolve, and the run ends rather than carry a state
    that is not the motion's."""


def spectral_radius_estimate(rhs, t: float, y: np.ndarray, dim: int = KRYLOV_DIM) -> float:
    """Largest |eigenvalue| of J = d rhs / dy at (t, y), y (size,): Ritz values of `dim` Arnoldi
    steps on forward-difference Jacobian-vector products (dim + 1 rhs calls, (dim, size) memory).

    The products are those of S^-1 J S, S = diag(max(1, |y_i|)), which has J's eigenvalues: each
    component is perturbed by JVP_REL_STEP of its own size, as a dense difference Jacobian does.
    One step for the whole vector, relative to |y|, would be led by the largest component: a
    rotor's angle, which grows without bound and never enters the dynamics. After a violent
    command (|y| = 3.6e5, mostly a wheel's angle) such a step perturbs the unit quaternions by
    5e-3, where the rhs is quadratic in rates of 3e4 rad/s: measured, it gives 2.0e6 against the
    4.8e4 of the dense Jacobian's eigenvalues (test/integrators/test_fixed_budget.py checks the
    agreement), which would send "fixed" from rk4 to methods 20-200 times as dear."""
    y = np.asarray(y, dtype=float)
    n = y.size
    m = min(dim, n)
    f0 = np.array(rhs(t, y), dtype=float)  # a copy: rhs may return its workspace
    scale = JVP_REL_STEP * np.maximum(1.0, np.abs(y))  # each component's perturbation of a unit vector
    V = np.zeros((m + 1, n))
    H = np.zeros((m + 1, m))
    v = np.random.default_rng(0).standard_normal(n)  # fixed seed: the same choice every time
    V[0] = v / np.linalg.norm(v)
    k = m
    for j in range(m):
        w = (np.asarray(rhs(t, y + scale * V[j]), dtype=float) - f0) / scale  # S^-1 J S V[j]
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


@dataclass(frozen=True)
class Choice:
    """A fixed-step method for a physics step h: `method` ("rk4", "gauss4s" or "gauss4") in `substeps`
    equal substeps of h, why (one line), and the estimated h |lambda| of one substep."""

    method: str
    substeps: int
    reason: str
    h_lambda: float

    @property
    def label(self) -> str:
        """"rk4", or "rk4 x4" for 4 substeps."""
        return self.method if self.substeps == 1 else f"{self.method} x{self.substeps}"


def body_rate_bound(model, y: np.ndarray) -> float:
    """An upper bound of the largest body angular speed |w^k| (rad/s) in state y, in O(n).

    w^k is the sum of the relative rates of the joints up to body k (eqs 34, 50): a spherical
    joint's relative rate is its three velocity columns (world components, model.py), a hinge's
    is phi_k' e^k. So the spherical part is summed as vectors (exact), the hinges' |phi'| are
    added to its length (their axes need the rotations: the triangle inequality instead), and
    the largest over the bodies is returned: exact on a spherical chain, where the sum of every
    joint's rate grew with the chain's length (n = 1000 links at 3 rad/s: 404 rad/s). Rotors do
    not count: an axisymmetric rotor's angle never enters the dynamics (eqs 18-19), only its
    momentum does, so its spin needs no resolving; nor does a base's translation."""
    n = model.n
    if n == 0:
        return 0.0
    u = y[model.i_vel]
    vec = np.zeros((n, 3))
    if len(model.col_sph):
        vec[model.sph_bodies] = u[model.col_sph]
    hinge = np.zeros(n)
    if len(model.col_hinge):
        hinge[model.hinge_bodies] = np.abs(u[model.col_hinge])
    if model.chain:
        w, path = np.cumsum(vec, axis=0), np.cumsum(hinge)
    else:  # a tree: summed along the path from the base to each body
        w, path = vec.copy(), hinge.copy()
        for k, q in enumerate(model.parent):
            if q >= 0:
                w[k] += w[q]
                path[k] += path[q]
    return float((np.sqrt((w * w).sum(axis=1)) + path).max())


def substeps_for(h: float, omega: float, now: int = 1) -> int:
    """Substeps of a step h so that no body turns more than SPIN_RESOLVE rad in one of them
    (at most MAX_SUBSTEPS), at body angular speeds up to `omega`; the count used `now` is kept
    while it is enough and at most twice what is needed (no flapping)."""
    if not omega > 0:
        need = 1
    elif not math.isfinite(omega):
        need = MAX_SUBSTEPS
    else:
        need = min(MAX_SUBSTEPS, max(1, math.ceil(h * omega / SPIN_RESOLVE - 1e-9)))
    return now if need <= now <= 2 * need else need


def fixed_step_choice(sim, dt: float) -> Choice:
    """The fixed-step method for the scene of `sim` (a gyro_sim.simulator.Simulator; not
    imported: the integrators know the simulator by its attributes only) at step `dt` (s).

    The substeps resolve the fastest body's rotation (`substeps_for`); the method is rk4 when
    the substep times the estimated largest |eigenvalue| of the rhs's Jacobian at the current
    state (commands held) is below RK4_SAFETY x RK4_IMAG_LIMIT, else `implicit_for` the model's
    (gauss4s up to IMPLICIT_MAX_BODIES bodies). The rhs is the Simulator's with the inputs now
    in force (`Simulator.held_rhs`); the node calls it on a Simulator just built (the scene's own
    rotor spins, no commanded moments). `sim` is not advanced.
    """
    if not (dt > 0 and math.isfinite(dt)):
        raise ValueError(f"dt must be a positive finite number, got {dt!r}")
    m = sim.model
    return _choice(sim.held_rhs(), sim.time, sim.state, dt, "rk4", omega=body_rate_bound(m, sim.state),
                   implicit=implicit_for(m))


def fixed_step_method(sim, dt: float) -> tuple[str, str]:
    """(method, one-line reason) of :func:`fixed_step_choice`, e.g. ("rk4", "rk4: h |lambda| =
    0.12 (stable below 1.4)") or ("rk4", "rk4 x40 substeps (a body turns 10 rad a step): ...")."""
    c = fixed_step_choice(sim, dt)
    return c.method, c.reason


def _choice(rhs, t: float, y: np.ndarray, h: float, now: str, dim: int = KRYLOV_DIM, omega: float = 0.0,
            k_now: int = 1, implicit: str = IMPLICIT) -> Choice:
    """The Choice at (t, y) for step h, given the method used `now` (the hysteresis of
    RK4_RETURN applies when leaving the implicit method) and its substeps `k_now`, from `dim`
    Krylov vectors, with body angular speeds up to `omega`; `implicit` names the method of a
    stiff scene."""
    k = substeps_for(h, omega, k_now)
    hl = h / k * spectral_radius_estimate(rhs, t, y, dim)
    limit = RK4_SAFETY * RK4_IMAG_LIMIT
    back = limit if now == "rk4" else RK4_RETURN * limit
    sub = f" x{k} substeps (a body turns up to {h * omega:.2g} rad a step)" if k > 1 else ""
    if hl < back:
        return Choice("rk4", k, f"rk4{sub}: h |lambda| = {hl:.2g} (stable below {limit:.2g})", hl)
    return Choice(implicit, k, f"{implicit}{sub}: h |lambda| = {hl:.2g}: stiff for rk4 "
                               f"(rk4 needs below {back:.2g} at h = {h / k:.3g} s)", hl)


class SceneFixedStep(FixedStepIntegrator):
    """"fixed": rk4 where the scene is soft at the step, gauss4s where it is stiff (gauss4 on a
    system that is not a scene's: `implicit`), re-chosen
    as the motion and the commands change (see the module docstring). Order 4 (both methods
    are), fixed step, one step per physics step.

    Attributes
    ----------
    current : the method stepping now ("rk4", `implicit` or the rescue's "dop853").
    implicit : "gauss4s" on a chain or tree of at most IMPLICIT_MAX_BODIES bodies, "gauss4" on a
        larger one, on one with stateful actuators, or on another system.
    substeps : substeps of one step now (1: none): the fastest body turns at most
        SPIN_RESOLVE rad in one.
    reason : one line: why (the substeps, h |lambda| of a substep against rk4's limit).
    h_lambda : the last estimate of h |lambda| (h: a substep).
    switches : the changes after the first choice, (t, from, to, reason) each (as "auto";
        from and to are Choice labels: "rk4", "gauss4 x4").
    over_budget : True while the calls have spent more than EVAL_BUDGET evaluations a physics
        step beyond the credit of BURST_STEPS: the watchdog then reports, not retakes.
    budget_calls, budget_energy_error : the calls kept over budget although they broke the
        watchdog's limit, and the sum of their energy errors (each relative to the kinetic
        energy): the drift the budget let through, since the start or the reset.
    credit : the evaluations the budget has left for a burst (negative: over budget).
    guard : the node sets it: a rung whose compiled code this process has not run yet (not in
        WARM: the cache fills in the background) is not taken; BUDGET_RUNG steps in its place,
        and the reason says so. Off: any rung is taken, compiled at its first call if need be.
    notes : what the guard said, once per rung.

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
        # here: gauss imports this package's base, not the reverse
        from gyro_sim.integrators.gauss4.driver import Gauss4
        from gyro_sim.integrators.gauss4.gauss4s import Gauss4S
        from gyro_sim.integrators.rk4.driver import RK4

        from gyro_sim.integrators.dop853.driver import DOP853

        #: the method of a stiff scene: gauss4s on a chain or tree of at most
        #: IMPLICIT_MAX_BODIES, gauss4 on a larger one or on a system that is not a scene's
        self.implicit = implicit_for(getattr(system, "model", None))
        symplectic = self.implicit == IMPLICIT
        implicit = Gauss4S(system, **options) if symplectic else Gauss4(system, **options)
        self._plain = _Plain(system)
        self.methods = {"rk4": RK4(system, **options), self.implicit: implicit,
                        RESCUE: DOP853(self._plain, **{**options, "max_step": self.step,
                                                           "rtol": min(RESCUE_RTOL, self.rtol),
                                                           "atol": np.minimum(RESCUE_ATOL, self.atol)})}
        #: the budget's rung, where its fixed cost (size + 1 evaluations a step) is at most half
        #: the budget; a larger system keeps the ladder over budget too
        self.budget_rung = self.n + 1 <= EVAL_BUDGET // 2
        if self.budget_rung:
            self.methods[BUDGET_RUNG] = LinearlyImplicitEuler(system, **options)
        self.current = ""
        self.substeps = 1
        self.reason = ""
        self.h_lambda = math.nan
        #: the energy watchdog: (t0, y0, t1, y1) -> relative energy error of a call, or None
        self.monitor = None
        self._hold_until = -math.inf
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
        self._model = model if hasattr(model, "col_sph") else None
        self._y0 = np.empty(self.n)
        self._reset_budget()
        self.guard = False
        self.notes: list[str] = []
        self._compiled = callable(getattr(system, "kernel_arguments", None))  # the numba backend

    def ready(self, name: str) -> bool:
        """May `name` step now? Not when guarded and its compiled code has not run in this process."""
        return not (self.guard and self._compiled) or name in ("rk4", BUDGET_RUNG) or name in WARM

    def _unready(self, name: str) -> str:
        """The reason's words for a rung the guard held back (said once in `notes`)."""
        words = f"{name} is not compiled yet (the cache fills in the background)"
        if words not in self.notes:
            self.notes.append(words)
        return words

    def _reset_budget(self) -> None:
        self.credit = float(BURST_STEPS * EVAL_BUDGET)
        self.over_budget = False
        self.budget_calls = 0
        self.budget_energy_error = 0.0
        self._kept_growth = 0.0  # log of the kinetic energy's factor from the calls kept, compounded (>= 0)
        self._retaken = False  # the method now is a rung below the last choice
        self._implicit_rate = 0.0  # the implicit rung's evaluations a substep in its last call
        self._barred: set[str] = set()  # rungs that failed (the implicit) or overspent (the rescue) since rk4
        self._ahead = (None, 0.0)  # (t0, inputs seen, inputs now) -> the body rate ahead (`_rate_ahead`)

    def reset(self) -> None:
        super().reset()
        for m in self.methods.values():
            m.reset()
        self._next_check = -math.inf
        self._last_check = -math.inf
        self._hold_until = -math.inf
        self.current = ""
        self.substeps = 1
        self._reset_budget()

    def warm_up(self, t0: float, y: np.ndarray) -> None:
        """One step of each method on a copy of y (then forgotten): every compiled path this
        integrator may switch to is compiled (or loaded from the cache) now, not at the first
        switch in the middle of a real-time run. Counters are kept as they were."""
        counts = {name: (m.nfev, m.nsteps, m.njev, m.nlu, m.nrejected) for name, m in self.methods.items()}
        try:
            for m in self.methods.values():
                if m.adaptive:
                    m.advance(t0, y, t0 + self.step)
                else:
                    m.march(t0, y.copy(), t0 + self.step)
        except IntegrationError:
            pass  # a scene a method cannot step from here: it is compiled all the same
        finally:
            for name, m in self.methods.items():
                m.nfev, m.nsteps, m.njev, m.nlu, m.nrejected = counts[name]
                m.reset()
            WARM.update(self.methods)

    def _speed(self, y: np.ndarray) -> float:
        return float(np.abs(y[self._speeds]).max()) if len(self._speeds) else 0.0

    def _due(self, t0: float, y: np.ndarray, t1: float) -> bool:
        if t0 >= self._next_check or (self.over_budget and self._retaken):
            return True  # over budget, a rung below the choice is left for a new choice
        if self.over_budget and self.current not in ("rk4", BUDGET_RUNG):
            return True  # over budget, a rung whose cost has no bound is left at once
        if t0 < self._hold_until:  # a rung down after a failure: kept until the next check
            return False
        changed = getattr(self.system, "inputs_version", 0) != self._inputs_seen
        if t0 < self._last_check + MIN_RECHECK:
            # new commands that spin a body up faster than the substeps now resolve: at once
            return changed and substeps_for(self.step, self._rate_ahead(t0, y, t1), self.substeps) > self.substeps
        if changed:
            return True
        v, seen = self._speed(y), self._speed_seen
        return v > SPEED_CHANGE * seen or v * SPEED_CHANGE < seen

    def _rate_ahead(self, t0: float, y: np.ndarray, t1: float) -> float:
        """Under new commands: the largest body rate now or by the call's end (at most
        CHECK_PERIOD ahead) at the accelerations of its start (a step moment spins a chain at
        rest up within one call: the rate now would choose no substeps). One rhs evaluation
        (none on a system that is not a chain)."""
        if self._model is None:
            return 0.0
        key = (t0, self._inputs_seen, getattr(self.system, "inputs_version", 0))
        if self._ahead[0] != key:
            f = np.asarray(self._counted_rhs(t0, y), dtype=float)
            self._ahead = (key, max(self._body_rate(y), self._body_rate(y + min(t1 - t0, CHECK_PERIOD) * f)))
        return self._ahead[1]

    def _body_rate(self, y: np.ndarray) -> float:
        return body_rate_bound(self._model, y) if self._model is not None else 0.0

    def _label(self) -> str:
        return Choice(self.current, self.substeps, "", 0.0).label

    def _switch(self, t: float, name: str, substeps: int) -> None:
        if (name, substeps) == (self.current, self.substeps):
            return
        before = self._label() if self.current else ""
        for m in self.methods.values():
            m.step = self.step / substeps
        self.current, self.substeps = name, substeps
        if before:
            self.switches.append((t, before, self._label(), self.reason))
            self.methods[name].reset()

    def _counted_rhs(self, t: float, y: np.ndarray) -> np.ndarray:
        self._check_fev += 1
        return self._rhs(t, y)

    def _choose(self, t0: float, y: np.ndarray, t1: float, left: float, income: float) -> None:
        """A new Choice at t0 for the call to t1, within the budget: `left` is what the call may
        cost (the credit and the call's share of the budget, in rk4 evaluations)."""
        omega = self._body_rate(y)
        if self.current and getattr(self.system, "inputs_version", 0) != self._inputs_seen:
            omega = self._rate_ahead(t0, y, t1)  # new commands: the rates they reach within the call
        dim = RECHECK_DIM if self.current else KRYLOV_DIM
        c = _choice(self._counted_rhs, t0, y, self.step, self.current or "rk4", dim, omega,
                    self.substeps, self.implicit)
        self.reason, self.h_lambda = c.reason, c.h_lambda
        method, substeps = c.method, c.substeps
        if method == "rk4":
            self._barred.clear()  # the scene is soft again: the ladder's rungs may be tried
        if self.over_budget:
            self.reason += f"; over the real-time budget ({EVAL_BUDGET} rhs evaluations a step)"
        if method != "rk4" and self.budget_rung:
            dear = method in self._barred or self._implicit_cost(c.substeps, t1 - t0) > min(left, CALL_BURST + income)
            if self.over_budget or dear or not self.ready(method):
                why = f" ({self._unready(method)})" if not self.ready(method) else (
                    f" ({method} failed or was beyond the budget here: not again before the scene is soft)"
                    if method in self._barred else
                    f" (its call would cost more than the budget's {max(left, 0.0):.0f} left)" if dear else "")
                # rk4 in the substeps that make it stable, where MAX_SUBSTEPS do (within the budget)
                if dear:  # not tried again before the scene is soft (the estimate chooses rk4)
                    self._barred.add(method)
                need = c.substeps * c.h_lambda / (BUDGET_RK4_SAFETY * RK4_IMAG_LIMIT)
                k = max(c.substeps, math.ceil(need)) if need <= BUDGET_MAX_SUBSTEPS else BUDGET_MAX_SUBSTEPS + 1
                method, substeps = ("rk4", k) if k <= BUDGET_MAX_SUBSTEPS else (BUDGET_RUNG, 1)
                self.reason = f"{Choice(method, substeps, '', 0.0).label} in place of {c.label}{why}: {self.reason}"
        self._switch(t0, method, substeps)
        self._retaken = False
        self._last_check = t0
        self._next_check = t0 + CHECK_PERIOD
        self._inputs_seen = getattr(self.system, "inputs_version", 0)
        self._speed_seen = self._speed(y)

    def _implicit_cost(self, substeps: int, span: float) -> float:
        """The implicit rung's expected evaluations for `span` in `substeps` a step:
        its evaluations a substep in its last call taken (IMPLICIT_PRIOR x (size + 1) before)."""
        per = self._implicit_rate if self._implicit_rate > 0 else IMPLICIT_PRIOR * (self.n + 1)
        return per * substeps * max(1, round(span / self.step))

    def _learn(self, m, before: int, t0: float, t1: float) -> None:
        """After a call of the implicit rung (taken or failed): its evaluations a substep."""
        if m is self.methods[self.implicit]:
            self._implicit_rate = (m.nfev - before) / (self.substeps * max(1, round((t1 - t0) / self.step)))

    def _rescue_cost(self, t0: float, span: float) -> float:
        """The rescue's expected evaluations for a call from t0 of `span`: at RESCUE_RTOL its steps
        turn the fastest motion (|lambda| of the last estimate, the fastest body's rate at the
        call's start or, under new commands, by its end: the largest) by about RESCUE_TURN rad
        each, RESCUE_STAGES evaluations a step."""
        lam = self.h_lambda * self.substeps / self.step if math.isfinite(self.h_lambda) else 0.0
        ahead = self._ahead[1] if self._ahead[0] and self._ahead[0][0] == t0 else 0.0
        fastest = max(lam, self._body_rate(self._y0), ahead)
        return RESCUE_STAGES * span * fastest / RESCUE_TURN

    def _march(self, t0: float, y: np.ndarray, t1: float) -> None:
        used = self.nfev
        income = (t1 - t0) / self.step * EVAL_BUDGET  # the call's share of the budget
        left = self.credit + income  # what the call may cost
        if self._due(t0, y, t1):
            self._choose(t0, y, t1, left, income)
        m = self.methods[self.current]
        self._y0[:] = y
        last = False  # the budget rung after the rescue overspent: its result is kept, its error reported
        try:
            while True:
                try:
                    if self.current == RESCUE:  # one burst of its own evaluations (a larger system has no budget rung)
                        self._plain.limit = BURST_STEPS * EVAL_BUDGET if self.budget_rung else math.inf
                    before = m.nfev
                    if m.adaptive:
                        y[:] = m.advance(t0, y, t1)
                    else:
                        m.march(t0, y, t1)
                    self._learn(m, before, t0, t1)
                    if self.monitor is not None and self.current != RESCUE:
                        if last:
                            self._report(t0, y, t1)
                        elif self.current == BUDGET_RUNG:
                            self._report(t0, y, t1, retake=True)
                        else:
                            self._watch(t0, y, t1)
                    break
                except IntegrationError as e:  # the call again from its start, one rung down
                    refused = y.copy() if isinstance(e, WatchdogTrip) else None  # a finite state, not accurate
                    y[:] = self._y0
                    if isinstance(e, BudgetOutrun):
                        raise
                    self._learn(m, before, t0, t1)
                    if self.budget_rung and (self.current == self.implicit or isinstance(e, RescueOverspent)):
                        self._barred.add(self.current)  # not again until the scene is soft (rk4 chosen)
                    if last or (self.current == RESCUE and not isinstance(e, RescueOverspent)):
                        raise
                    if isinstance(e, RescueOverspent) and self.budget_rung:  # the budget rung's result, reported
                        self.reason = f"{BUDGET_RUNG}: kept, the rescue overspent at t = {e.t:.6g} s"
                        self._switch(t0, BUDGET_RUNG, 1)
                        self._retaken = True
                        self._next_check = self._hold_until = t1
                        m, last = self.methods[BUDGET_RUNG], True
                        continue
                    what = (f"failed ({e.reason})" if self.current != "rk4" or isinstance(e, WatchdogTrip)
                            else "left a non-finite state")
                    why = ""
                    ladder = [self.implicit, RESCUE] if self.current == "rk4" else [RESCUE]
                    if self.current == BUDGET_RUNG and refused is not None:  # past OVER_BUDGET_WATCH
                        # again in 4 x its substeps, else the rescue, where the budget pays for them
                        # (as for the rungs below: the credit, at most CALL_BURST beyond the call's share)
                        k = 4 * self.substeps
                        payable = min(CALL_BURST + income, max(left, income))
                        if (self.n + 1) * k * round((t1 - t0) / self.step) <= payable:
                            after = BUDGET_RUNG
                        elif (self.ready(RESCUE) and RESCUE not in self._barred
                              and self._rescue_cost(t0, t1 - t0) <= payable):
                            after, k = RESCUE, 1  # within one burst
                        else:
                            self._keep(e.error, t0)
                            y[:] = refused
                            self.reason = (f"{self._label()}: kept, {what} at t = {e.t:.6g} s "
                                           "(more substeps beyond the budget)")
                            break
                    elif self.current == BUDGET_RUNG:  # it broke down (not its energy: that is reported)
                        after, k = RESCUE, 1  # within one burst
                    elif self.budget_rung and self.current == "rk4" and 1 < self.substeps < MAX_SUBSTEPS:
                        after, k = "rk4", MAX_SUBSTEPS  # a fast body: rk4 again in its most substeps
                    elif not self.budget_rung:
                        after, k = ladder[0], 1 if ladder[0] == RESCUE else self.substeps
                    else:
                        # the first rung below that is compiled, has not failed here since the scene
                        # was soft, and whose expected cost the call can pay (its share of the budget
                        # at least, over budget too)
                        affordable = [r for r in ladder if self.ready(r) and r not in self._barred and (
                            self._implicit_cost(self.substeps, t1 - t0) if r == self.implicit
                            else self._rescue_cost(t0, t1 - t0)) <= min(CALL_BURST + income, max(left, income))]
                        if affordable:
                            after = affordable[0]
                            k = 1 if after == RESCUE else self.substeps
                        elif self.current == "rk4" and self.substeps < MAX_SUBSTEPS:
                            after, k = "rk4", MAX_SUBSTEPS  # rk4 again in its most substeps (within the budget)
                        elif refused is not None and abs(e.error) <= OVER_BUDGET_WATCH * (t1 - t0):
                            # the rungs below cost more than the budget has: the result kept, its error reported
                            self._keep(e.error, t0)
                            y[:] = refused
                            self.reason = (f"{self._label()}: kept, {what} at t = {e.t:.6g} s "
                                           "(the rungs below beyond the budget)")
                            break
                        else:  # the budget's rung: a fixed cost, compiled nothing (the ladder's next rungs neither)
                            unready = [r for r in ladder if not self.ready(r)]
                            why = f" ({self._unready(unready[0])})" if unready else ""
                            after, k = BUDGET_RUNG, 1
                    if not self.ready(after):  # nowhere further down
                        raise
                    self.reason = (f"{Choice(after, k, '', 0.0).label}{why}: {self._label()} {what} "
                                   f"at t = {e.t:.6g} s")
                    fast = self.substeps > 1  # a body that needed substeps: the rescue's cost follows its pace
                    self._switch(t0, after, k)
                    self._retaken = True
                    # a rung down is kept until the next check; the budget's rung, and the rescue
                    # of a fast body, for this call only
                    once = after == BUDGET_RUNG or (after == RESCUE and fast)
                    self._next_check = self._hold_until = t1 if once else t0 + CHECK_PERIOD
                    m = self.methods[after]
        finally:
            ms = self.methods.values()
            self.nfev = self._check_fev + sum(x.nfev for x in ms)
            self.nsteps = sum(x.nsteps for x in ms)
            self.njev = sum(x.njev for x in ms)
            self.nlu = sum(x.nlu for x in ms)
            self.last_step = m.last_step
            self._spend(t0, t1, self.nfev - used)

    def _watch(self, t0: float, y: np.ndarray, t1: float) -> None:
        """The energy watchdog on a call just taken: raises WatchdogTrip above its limit; over
        budget, a call below OVER_BUDGET_WATCH is kept and its error counted instead."""
        err = self.monitor(t0, self._y0, t1, y)
        if abs(err) <= ENERGY_WATCH * (t1 - t0):
            return
        if self.over_budget and abs(err) <= OVER_BUDGET_WATCH * (t1 - t0):
            self._keep(err, t0)
            return
        raise WatchdogTrip(self.current, err, t0, self.step / self.substeps, t1 - t0)

    def _report(self, t0: float, y: np.ndarray, t1: float, retake: bool = False) -> None:
        """A call of the budget's rung: its energy error counted when beyond the watchdog's limit.
        No rescue retakes it (the budget chose it); `retake`: an error past OVER_BUDGET_WATCH
        raises WatchdogTrip, for the same rung in more substeps."""
        err = self.monitor(t0, self._y0, t1, y)
        if retake and not abs(err) <= OVER_BUDGET_WATCH * (t1 - t0):  # a non-finite energy too
            raise WatchdogTrip(self.current, err, t0, self.step / self.substeps, t1 - t0)
        if not abs(err) <= ENERGY_WATCH * (t1 - t0):
            self._keep(err, t0)

    def _keep(self, err: float, t: float) -> None:
        """A call kept over budget beyond the watchdog's limit: its energy error counted. Where the
        kept calls' compounded growth of the kinetic energy passes KEEP_GROWTH (or the error is
        not finite) the run ends (BudgetOutrun), the call's start state kept."""
        if not err < 1.0:  # not finite, or the whole kinetic energy gained
            grow = math.inf
        else:
            grow = -math.log1p(-err) if err > 0.0 else math.log1p(max(err, -1.0 + 1e-12))
        growth = max(0.0, self._kept_growth + grow)
        if not growth <= math.log(KEEP_GROWTH):
            raise BudgetOutrun(self.current, f"the motion outran the real-time budget ({self._label()} kept "
                               f"multiplying the kinetic energy, x{math.exp(min(growth, 700.0)):.2g} over the calls "
                               "it kept, and the methods that resolve it cost more than real time allows)", t,
                               self.step / self.substeps)
        self._kept_growth = growth
        self.budget_calls += 1
        self.budget_energy_error += err

    def _spend(self, t0: float, t1: float, evaluations: float) -> None:
        """The budget's bookkeeping of a call: EVAL_BUDGET a physics step comes in (up to the
        burst), what the call evaluated goes out. Over budget from a negative credit until the
        credit is whole again (no flapping at zero)."""
        full = BURST_STEPS * EVAL_BUDGET
        self.credit = min(full, self.credit + (t1 - t0) / self.step * EVAL_BUDGET - evaluations)
        if self.credit < 0:
            self.over_budget = True
        elif self.credit >= full:
            self.over_budget = False


class LinearlyImplicitEuler(FixedStepIntegrator):
    """The linearly implicit Euler step (the one-stage Rosenbrock method): with J the Jacobian
    of the rhs at the step's start, y1 = y0 + h (I - h J)^-1 f(t0, y0). Its stability function
    1 / (1 - z) makes it L-stable: no eigenvalue of J, however large h |lambda|, makes it grow,
    and it damps the motion it cannot resolve instead. Order 1. J by forward differences, each
    column perturbing its component by JVP_REL_STEP of its size: size + 1 rhs evaluations and
    one LU a step, whatever the state: a fixed cost, in numpy on the compiled rhs (nothing to
    compile). "fixed" steps with it only where its real-time budget cannot pay for better: the
    violent step of `gyro-sim bench realtime` pushed for 1.5 s (1.3e11 J, the wheel at 7.5e7
    rad/s, the links' nutation beyond rk4 in 64 substeps) keeps its energy balance to 1e-3
    there at one step a millisecond, where gauss4s and dop853 cost 2e4-1e5 evaluations a
    call.

    References
    ----------
    .. [1] E. Hairer, G. Wanner, "Solving Ordinary Differential Equations II", 2nd ed.,
           Springer 1996, sec. IV.7 (Rosenbrock methods; the linearly implicit Euler method).
    """

    name = BUDGET_RUNG
    order = 1

    def __init__(self, system, **options):
        super().__init__(system, **options)
        n = self.n
        self._J = np.empty((n, n))
        self._f0 = np.empty(n)
        self._yj = np.empty(n)

    def _step(self, t: float, y: np.ndarray, h: float) -> None:
        f0, J, yj = self._f0, self._J, self._yj
        f0[:] = self._fun(t, y)
        yj[:] = y
        for j in range(self.n):
            d = JVP_REL_STEP * max(1.0, abs(y[j]))
            yj[j] = y[j] + d
            J[:, j] = self._fun(t, yj)
            J[:, j] -= f0
            J[:, j] /= d
            yj[j] = y[j]
        self.njev += 1
        self.nlu += 1
        J *= -h
        J.flat[:: self.n + 1] += 1.0  # I - h J
        try:
            y += h * np.linalg.solve(J, f0)
        except np.linalg.LinAlgError as exc:
            raise IntegrationError(self.name, f"I - h J is singular ({exc})", t, h) from exc


class _Plain:
    """A system seen through its rhs only (no compiled march): the rescue's dop853 steps with
    its Python driver on the compiled dop853 kernels, so that "fixed" compiles no third loop
    for a rung most runs never take. Its evaluations of a call are counted: past `limit` the
    rhs raises RescueOverspent (over budget, the rescue has a bound)."""

    def __init__(self, system):
        self.system = system
        self.size, self.quat_index = system.size, system.quat_index
        self.project = system.project
        self._rhs = system.rhs
        self.limit = math.inf
        self.count = 0

    @property
    def limit(self) -> float:
        return self._limit

    @limit.setter
    def limit(self, value: float) -> None:
        self._limit, self.count = value, 0

    def rhs(self, t: float, y: np.ndarray, *args, **kwargs):
        self.count += 1
        if self.count > self._limit:
            raise RescueOverspent(RESCUE, f"{self.count - 1} rhs evaluations in one call, the budget's burst", t, None)
        return self._rhs(t, y, *args, **kwargs)

