"""`gyro-sim bench accuracy`: global error against CPU time (work-precision diagrams).

For every reference scene (:func:`cases`), every method runs once per tolerance (adaptive)
or step (fixed) from the scene's initial state to the horizon, in one `advance` call, and
its final state is compared with a reference:

- exact, for the regular precessions (docs/theory.md section 4, eq 88): theta_k and psi_k' stay
  constant, so psi_k = psi_k0 + kappa t, theta_k = theta_k0, phi_k = phi_k0 + phi_k' t
  (p_k = phi_k' + psi_k' cos theta_k is constant, eq 70); rotor angles kappa_i = kappa_i' t;
- otherwise gyro_sim's dop853 at rtol REF_RTOL, whose own error is estimated by a second
  reference at CHECK_RTOL: |ref - check| bounds it (the check is the worse of the two). On
  the exact scenes the same pair is run too, which shows how good that bound is.

The error of a final state (:func:`state_error`, dimensionless) is the largest of: the
attitude error of any carrier (rad, the angle of R_ref^T R), the angular-velocity error
of any carrier relative to the largest reference angular velocity, and for a free base the
position and velocity of O^1 relative to the chain's length and speed. The error of the
invariants is the largest relative drift of those the exact motion conserves
(`gyro_sim.dynamics.invariants.conserved`; not the energy when moments are commanded).

Peers in the same run: scipy's solve_ivp (DOP853, Radau, LSODA) on gyro_sim's right-hand
side, and MuJoCo (RK4, implicitfast) on the same scene built as MJCF
(:mod:`gyro_sim.bench.peers`; scenes MuJoCo cannot represent exactly are skipped, with the
reason in the report). CPU time is `time.process_time` around the integration alone.

The report also compares the live error estimate (`Simulator.error_estimate`, the weighted
local error norm of the last step) with the true error, on the exact scenes
(:func:`error_estimate_rows`).
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from typing import Any, Callable

import numpy as np

from gyro_sim.integrators import make_integrator
from gyro_sim.dynamics.invariants import conserved
from gyro_sim.dynamics.model import Model, compile_model
from gyro_sim.dynamics.rotations import euler_rates_to_omega, euler_to_matrix, matrix_to_quat
from gyro_sim.scene.records import Scene
from gyro_sim.scene.load import load_scene
from gyro_sim.dynamics.system import make_system
from gyro_sim.simulator import SimulationError, Simulator
from gyro_sim.bench import peers
from gyro_sim.bench.extreme import load_dict
from gyro_sim.bench.peers import Frames, frames_of_state
from gyro_sim.bench.report import add_force_option, refused, write_report

#: atol = rtol * ATOL_FACTOR for every adaptive run (states are O(1) to O(100))
ATOL_FACTOR = 1e-2
#: the reference run and the check run that estimates its error
REF_RTOL, CHECK_RTOL = 1e-13, 1e-12
#: error levels of the summary table
TARGETS = (1e-6, 1e-9)
#: node-like chunks (s) of the error-estimate comparison
ESTIMATE_CHUNK = 0.01
#: a run that costs more CPU than this (s) is not repeated at finer settings
MAX_RUN_CPU = 30.0


# ------------------------------------------------------------------------------- scenes
@dataclass(frozen=True)
class Case:
    """One reference scene of the report."""

    key: str
    title: str
    scene: dict
    horizon: float  # s
    moments: tuple[float, ...] | None = None  # constant axis moments, axis order
    exact: bool = False  # a regular precession: exact solution known

    def load(self) -> Scene:
        return load_scene(self.scene)


def generic_double_gyro() -> dict:
    """double_gyro_plus.yaml thrown off its precession, with a fast wheel: generic motion."""
    sd = load_dict("double_gyro_plus")
    sd["name"] = "double Lagrange gyroscope, generic motion, fast spin"
    top1, top2 = sd["bodies"]
    top1["rotors"][0]["spin"] = -1000.0
    top1["initial"]["euler_rates"] = [-4.0, 0.8, 150.0]
    top2["initial"]["euler_rates"] = [-8.0, -1.0, 120.0]
    return sd


#: commanded axis moments of the hinge chain (wheel2, arm3, arm4), N m
HINGE_MOMENTS = (0.002, 0.1, -0.05)


def cases(quick: bool = False) -> list[Case]:
    """The reference scenes; quick: the same scenes on short horizons."""
    def T(full: float) -> float:
        return round(full / 4, 6) if quick else full

    return [
        Case("heavy_top", "heavy top, regular precession (exact)", load_dict("heavy_top"), T(2.0), exact=True),
        Case("double_gyro_plus", "double gyroscope, eps21 = +1 (exact)", load_dict("double_gyro_plus"), T(1.0),
             exact=True),
        Case("double_gyro_minus", "double gyroscope, eps21 = -1 (exact)", load_dict("double_gyro_minus"), T(1.0),
             exact=True),
        Case("generic_double_gyro", "double gyroscope, generic, fast spin", generic_double_gyro(), T(1.0)),
        Case("chain_4", "4-body chain, chaotic", load_dict("chain_4"), T(1.0)),
        Case("hinge_chain", "hinge chain, commanded moments", load_dict("hinge_chain"), T(1.0),
             moments=HINGE_MOMENTS),
        Case("free_chain_rotors", "free-floating chain with rotors", load_dict("free_chain_rotors"), T(1.0)),
    ]


# ----------------------------------------------------------------------- exact solution
def precession_exact(scene: Scene, model: Model) -> Callable[[float], np.ndarray]:
    """t -> the exact state vector y(t) (gyro_sim layout) of a regular precession scene.

    Every body is spherical with Euler-angle initial conditions, theta_k' = 0 and psi_k' =
    kappa; then psi_k(t) = psi_k0 + kappa t, theta_k const, phi_k(t) = phi_k0 + phi_k' t,
    w^k from the Euler rates (docs/theory.md section 6), and each torque rotor turns at the
    constant kappa_i' = p_i - w^k . e_i relative to its carrier (eqs 18-19).
    """
    euler0 = np.array([b.initial.euler for b in scene.bodies], dtype=float)
    rates = np.array([b.initial.euler_rates for b in scene.bodies], dtype=float)
    if np.any(rates[:, 1] != 0.0) or np.ptp(rates[:, 0]) != 0.0:
        raise ValueError(f"{scene.name}: not a regular precession (theta' != 0 or psi' not common)")
    down = model.down

    def state(t: float) -> np.ndarray:
        y = np.zeros(model.size)
        R = np.empty((model.n, 3, 3))
        w = np.empty((model.n, 3))
        for k in range(model.n):
            e = euler0[k] + np.array([rates[k, 0], 0.0, rates[k, 2]]) * t
            R[k] = euler_to_matrix(e, down)
            w[k] = euler_rates_to_omega(e, rates[k], down)
        y[model.i_quat.ravel()] = np.array([matrix_to_quat(Rk) for Rk in R]).ravel()
        wrel = np.diff(np.vstack([np.zeros(3), w]), axis=0)
        vel = np.zeros(model.N)
        vel[model.col_sph.ravel()] = wrel[model.sph_bodies].ravel()
        y[model.i_vel] = vel
        if len(model.torque_body):
            e_w = np.einsum("nij,nj->ni", R[model.torque_body], model.torque_axis)
            kdot = model.torque_p0 - np.einsum("ni,ni->n", w[model.torque_body], e_w)
            y[model.i_kappa] = kdot * t
        return y

    return state


# ------------------------------------------------------------------------- error norms
def rotation_angle(Ra: np.ndarray, Rb: np.ndarray) -> float:
    """The angle (rad) of Rb^T Ra, accurate also for tiny angles."""
    A = Rb.T @ Ra
    s = 0.5 * math.sqrt((A[2, 1] - A[1, 2]) ** 2 + (A[0, 2] - A[2, 0]) ** 2 + (A[1, 0] - A[0, 1]) ** 2)
    return math.atan2(s, 0.5 * (np.trace(A) - 1.0))


def chain_length(model: Model) -> float:
    return float(np.sum(np.linalg.norm(model.s, axis=1)) + np.max(np.linalg.norm(model.first_moment, axis=1)
                                                                  / model.mass))


def state_error(F: Frames, ref: Frames, length: float, free: bool) -> float:
    """The dimensionless error of F against ref (module docstring)."""
    err = max(rotation_angle(Ra, Rb) for Ra, Rb in zip(F.R, ref.R))
    W = max(float(np.max(np.linalg.norm(ref.w, axis=1))), 1e-300)
    err = max(err, float(np.max(np.linalg.norm(F.w - ref.w, axis=1))) / W)
    if free:
        V = max(float(np.linalg.norm(ref.v1)), W * length)
        err = max(err, float(np.linalg.norm(F.O1 - ref.O1)) / length, float(np.linalg.norm(F.v1 - ref.v1)) / V)
    return err


def invariant_names(model: Model, moments) -> tuple[str, ...]:
    names = conserved(model)
    if moments is not None and any(moments):
        names = tuple(n for n in names if n not in ("energy", "jacobi"))
    return names


def invariant_error(inv0: dict, inv1: dict, names, scales: dict) -> float | None:
    """Largest relative drift of the invariants `names` present in both dicts."""
    errs = [float(np.linalg.norm(np.asarray(inv1[n]) - np.asarray(inv0[n]))) / scales[n]
            for n in names if n in inv0 and n in inv1]
    return max(errs) if errs else None


def invariant_scales(inv0: dict, names) -> dict:
    """Energy-like: kinetic + |potential| at t = 0; momenta: their initial magnitude."""
    out = {}
    for n in names:
        if n in ("energy", "jacobi"):
            out[n] = abs(inv0["kinetic"]) + abs(inv0["potential"])
        else:
            out[n] = max(float(np.linalg.norm(inv0[n])), 1e-300)
    return out


# --------------------------------------------------------------------------------- runs
@dataclass
class Point:
    """One run: a method at one setting on one scene."""

    scene: str
    engine: str  # gyro_sim | scipy | MuJoCo
    method: str  # gyro_sim: integrator name, with " [backend]" when not the report's
    setting: float  # rtol (adaptive) or step (s)
    cpu: float  # s
    error: float | None
    inv_error: float | None
    nfev: int
    nsteps: int
    nrejected: int = 0
    failed: str | None = None

    @property
    def label(self) -> str:
        return self.method if self.engine == "gyro_sim" else f"{self.engine} {self.method}"

    @property
    def integrator(self) -> str:
        return self.method.split(" [")[0]


@dataclass(frozen=True)
class Method:
    engine: str
    name: str
    kind: str  # rtol | step
    full: tuple[float, ...]
    quick: tuple[float, ...]
    backend: str | None = None  # gyro_sim: a fixed backend instead of the report's

    @property
    def label(self) -> str:
        if self.engine != "gyro_sim":
            return f"{self.engine} {self.name}"
        return self.name if self.backend is None else f"{self.name} [{self.backend}]"


METHODS = (
    Method("gyro_sim", "dop853", "rtol", tuple(10.0 ** -k for k in range(4, 13)), (1e-5, 1e-7, 1e-9)),
    # the same on the numpy reference backend (full run only): what compiling the rhs buys
    Method("gyro_sim", "dop853", "rtol", (1e-4, 1e-6, 1e-8, 1e-10, 1e-12), (), backend="numpy"),
    Method("gyro_sim", "radau", "rtol", tuple(10.0 ** -k for k in range(3, 11)), (1e-4, 1e-6)),
    Method("gyro_sim", "auto", "rtol", (1e-4, 1e-6, 1e-8, 1e-10, 1e-12), (1e-6, 1e-9)),
    Method("gyro_sim", "rk4", "step", (1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4), (4e-3, 2e-3)),
    Method("gyro_sim", "lie4", "step", (1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4), (4e-3, 2e-3)),
    Method("scipy", "DOP853", "rtol", (1e-4, 1e-6, 1e-8, 1e-10, 1e-12), (1e-6, 1e-9)),
    Method("scipy", "Radau", "rtol", (1e-3, 1e-5, 1e-7, 1e-9), (1e-4,)),
    Method("scipy", "LSODA", "rtol", (1e-4, 1e-6, 1e-8, 1e-10, 1e-12), (1e-6,)),
    Method("MuJoCo", "RK4", "step", (1e-2, 3e-3, 1e-3, 3e-4, 1e-4, 3e-5, 1e-5), (1e-3, 3e-4, 1e-4)),
    Method("MuJoCo", "implicitfast", "step", (1e-3, 1e-4, 1e-5, 1e-6), (1e-3, 1e-4)),
)


@dataclass
class Reference:
    """What the errors of one scene are measured against."""

    frames: Frames
    kind: str  # "exact" | "dop853 rtol ..."
    est_error: float  # |ref - check|: the estimated error of the reference
    true_error: float | None  # exact scenes: the reference run's own error
    cpu: float


class Scenario:
    """A case compiled once: model, scales, reference."""

    def __init__(self, case: Case, backend: str = "auto"):
        self.case = case
        self.scene = case.load()
        self.model = compile_model(self.scene)
        self.backend = backend
        self.length = chain_length(self.model)
        self.free = self.model.free
        self.names = invariant_names(self.model, case.moments)
        sim = self.simulator("dop853", 1e-8, 1e-3)
        self.inv0 = sim.invariants()
        self.scales = invariant_scales(self.inv0, self.names)
        self.exact = precession_exact(self.scene, self.model) if case.exact else None
        self.reference = self._reference()

    def simulator(self, integrator: str, rtol: float, step: float, backend: str | None = None) -> Simulator:
        sim = Simulator(self.scene, integrator=integrator, rtol=rtol, atol=rtol * ATOL_FACTOR, step=step,
                        backend=backend or self.backend)
        if self.case.moments is not None:
            sim.set_axis_moments(self.case.moments)
        return sim

    def _tight(self, rtol: float) -> tuple[Frames, float]:
        sim = self.simulator("dop853", rtol, 1e-3)
        t0 = time.process_time()
        sim.advance(self.case.horizon)
        cpu = time.process_time() - t0
        return frames_of_state(self.model, sim.time, sim.state), cpu

    def _reference(self) -> Reference:
        T = self.case.horizon
        ref, cpu = self._tight(REF_RTOL)
        check, _ = self._tight(CHECK_RTOL)
        est = state_error(check, ref, self.length, self.free)
        if self.exact is None:
            return Reference(ref, f"dop853, rtol {REF_RTOL:g}", est, None, cpu)
        exact = frames_of_state(self.model, T, self.exact(T))
        return Reference(exact, "exact (eq 88)", est, state_error(ref, exact, self.length, self.free), cpu)

    def error(self, F: Frames) -> float:
        return state_error(F, self.reference.frames, self.length, self.free)

    # --- the runs ---------------------------------------------------------------------------
    def run(self, method: Method, setting: float) -> Point:
        c = self.case
        if method.engine == "gyro_sim":
            rtol, step = (setting, 1e-3) if method.kind == "rtol" else (1e-8, setting)
            sim = self.simulator(method.name, rtol, step, method.backend)
            name = method.label
            t0 = time.process_time()
            try:
                sim.advance(c.horizon)
            except SimulationError as exc:
                return Point(c.key, method.engine, name, setting, time.process_time() - t0, None, None,
                             sim.integrator.nfev, sim.integrator.nsteps, sim.integrator.nrejected, str(exc))
            cpu = time.process_time() - t0
            F = frames_of_state(self.model, sim.time, sim.state)
            integ = sim.integrator
            return Point(c.key, method.engine, name, setting, cpu, self.error(F),
                         invariant_error(self.inv0, sim.invariants(), self.names, self.scales),
                         integ.nfev, integ.nsteps, integ.nrejected)
        if method.engine == "scipy":
            r = peers.run_scipy(self.scene, method.name, setting, setting * ATOL_FACTOR, c.horizon, c.moments,
                                self.backend)
        else:
            r = peers.run_mujoco(self.scene, method.name, setting, c.horizon, c.moments)
        if r.failed:
            return Point(c.key, method.engine, method.name, setting, r.cpu, None, None, r.nfev, r.nsteps,
                         failed=r.failed)
        # scipy's invariants are gyro_sim's functions on its state; MuJoCo's are its own
        inv0 = r.invariants0 if method.engine == "MuJoCo" else self.inv0
        return Point(c.key, method.engine, method.name, setting, r.cpu, self.error(r.frames),
                     invariant_error(inv0, r.invariants, self.names, self.scales), r.nfev, r.nsteps)


def mujoco_skip(case: Case) -> str | None:
    try:
        import mujoco  # noqa: F401
    except ImportError:
        return "the mujoco package is not installed"
    return peers.mujoco_unsupported(case.load())


def sweep(scenario: Scenario, quick: bool, methods=METHODS, progress=None) -> list[Point]:
    """Every method at every setting on one scene (finest last; a run that costs more than
    MAX_RUN_CPU stops its method's sweep)."""
    points = []
    skip_mj = mujoco_skip(scenario.case)
    for method in methods:
        if method.engine == "MuJoCo" and skip_mj:
            continue
        for setting in (method.quick if quick else method.full):
            p = scenario.run(method, setting)
            points.append(p)
            if progress:
                progress(p)
            if p.cpu > MAX_RUN_CPU:
                break
    return points


# ------------------------------------------------------------------------------ summary
def cost_at(points: list[Point], target: float) -> float | None:
    """CPU time (s) at which this method's error first reaches `target`: log-log
    interpolation between the two runs around the crossing (runs ordered by CPU time);
    None if no run reached it."""
    pts = sorted((p for p in points if p.error is not None), key=lambda p: p.cpu)
    prev = None
    for p in pts:
        if p.error <= target:
            if prev is None or p.cpu <= 0.0 or prev.cpu <= 0.0:
                return p.cpu
            x0, x1 = math.log(prev.cpu), math.log(p.cpu)
            e0, e1 = math.log(max(prev.error, 1e-300)), math.log(max(p.error, 1e-300))
            if e1 == e0:
                return p.cpu
            return math.exp(x0 + (math.log(target) - e0) * (x1 - x0) / (e1 - e0))
        prev = p
    return None


def by_method(points: list[Point]) -> dict[str, list[Point]]:
    out: dict[str, list[Point]] = {}
    for p in points:
        out.setdefault(p.label, []).append(p)
    return out


def summary_rows(case: Case, points: list[Point]) -> list[dict]:
    """For each target: every method's cost there, cheapest first."""
    rows = []
    for target in TARGETS:
        costs = {label: cost_at(pts, target) for label, pts in by_method(points).items()}
        ranked = sorted(((c, m) for m, c in costs.items() if c is not None))
        rows.append({"scene": case.key, "target": target, "ranked": ranked,
                     "missed": sorted(m for m, c in costs.items() if c is None)})
    return rows


#: the error at which dop853 is compared with MuJoCo's RK4 (the claim: <= 0.05x its CPU)
PEER_TARGET = 1e-8


def peer_ratio_table(points: list[Point], target: float = PEER_TARGET) -> str:
    """Per scene: gyro_sim dop853's CPU and MuJoCo RK4's CPU to reach `target`, and their ratio."""
    lines = ["| scene | gyro_sim dop853 (ms) | MuJoCo RK4 (ms) | dop853 / MuJoCo RK4 |", "|---|---:|---:|---:|"]
    for scene in dict.fromkeys(p.scene for p in points):
        by = by_method([p for p in points if p.scene == scene])
        mine = cost_at(by.get("dop853", []), target)
        peer = cost_at(by.get("MuJoCo RK4", []), target)
        if mine is None and peer is None:
            continue
        ratio = f"{mine / peer:.3f}x" if mine is not None and peer is not None else "n/a"
        lines.append(f"| {scene} | {'not reached' if mine is None else _ms(mine)} | "
                     f"{'not reached' if peer is None else _ms(peer)} | {ratio} |")
    return "\n".join(lines)


def _ms(s: float) -> str:
    return f"{1e3 * s:.3g}"


GYRO_LABELS = ("dop853", "radau", "auto", "rk4", "lie4", "dop853 [numpy]")


def summary_table(rows: list[dict]) -> str:
    lines = [
        "| scene | error | cheapest (CPU ms) | runner-up | best gyro_sim | best peer |",
        "|---|---:|---|---|---|---|",
    ]
    for r in rows:
        ranked = r["ranked"]
        if not ranked:
            lines.append(f"| {r['scene']} | {r['target']:.0e} | none reached it | | | |")
            continue
        c0, m0 = ranked[0]

        def rel(entry) -> str:
            if entry is None:
                return "not reached"
            c, m = entry
            return f"{m} ({_ms(c)} ms, {c / c0:.1f}x)"

        runner = ranked[1] if len(ranked) > 1 else None
        gyro = next((e for e in ranked if e[1] in GYRO_LABELS), None)
        peer = next((e for e in ranked if e[1] not in GYRO_LABELS), None)
        lines.append(f"| {r['scene']} | {r['target']:.0e} | **{m0}** ({_ms(c0)}) | {rel(runner)} | "
                     f"{rel(gyro)} | {rel(peer)} |")
    return "\n".join(lines)


def reference_table(scenarios: list[Scenario]) -> str:
    lines = [
        "| scene | horizon (s) | reference | its error, estimated (\\|ref - check\\|) | its true error |"
        " MuJoCo |",
        "|---|---:|---|---:|---:|---|",
    ]
    for s in scenarios:
        ref = s.reference
        true = "" if ref.true_error is None else f"{ref.true_error:.1e}"
        skip = mujoco_skip(s.case)
        lines.append(f"| {s.case.key} | {s.case.horizon:g} | {ref.kind} | {ref.est_error:.1e} | {true} | "
                     f"{'skipped: ' + skip if skip else 'yes'} |")
    return "\n".join(lines)


def points_table(points: list[Point]) -> str:
    lines = ["| scene | method | rtol / step | CPU (ms) | error | invariants | rhs evals | steps | rejected |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    for p in points:
        err = "failed: " + p.failed.replace("|", "/") if p.failed else f"{p.error:.2e}"
        inv = "" if p.inv_error is None else f"{p.inv_error:.1e}"
        lines.append(f"| {p.scene} | {p.label} | {p.setting:g} | {_ms(p.cpu)} | {err} | {inv} | "
                     f"{p.nfev or ''} | {p.nsteps} | {p.nrejected} |")
    return "\n".join(lines)


# ----------------------------------------------------------------- the live error estimate
@dataclass
class EstimateRow:
    scene: str
    method: str
    rtol: float
    local_ratios: list[float] = field(default_factory=list)  # true / estimated, per step
    local_true: list[float] = field(default_factory=list)  # true local error, tolerance units
    global_error: float = math.nan  # weighted RMS of the true global error at the horizon
    estimates: list[float] = field(default_factory=list)  # reported error_estimate per chunk


def weighted_norm(err: np.ndarray, y0: np.ndarray, y1: np.ndarray, rtol: float, atol: float) -> float:
    """The integrators' weighted RMS norm: 1 is the tolerance."""
    scale = atol + rtol * np.maximum(np.abs(y0), np.abs(y1))
    return float(np.sqrt(np.mean((err / scale) ** 2)))


def _align(y_exact: np.ndarray, y: np.ndarray, model: Model) -> np.ndarray:
    """y_exact with each quaternion's sign matched to y's (q and -q are one rotation)."""
    out = y_exact.copy()
    for idx in model.i_quat:
        if np.dot(out[idx], y[idx]) < 0.0:
            out[idx] = -out[idx]
    return out


def estimate_row(scenario: Scenario, method: str, rtol: float, samples: int) -> EstimateRow:
    """Local: from exact states at `samples` times, one step (of 0.9 x the step-size memory
    the integrator has there) against the exact solution: true / estimated local error.
    Global: a node-like run in ESTIMATE_CHUNK chunks: the true global error at the horizon
    in the same norm, and the estimates reported on the way."""
    model, exact, T = scenario.model, scenario.exact, scenario.case.horizon
    atol = rtol * ATOL_FACTOR
    row = EstimateRow(scenario.case.key, method, rtol)
    system = make_system(model, scenario.backend)
    system.hold(0.0, model.torque_p0.copy() if len(model.torque_body) else None, None, None)
    integ = make_integrator(method, system, rtol=rtol, atol=atol)
    warm = min(0.05, T / 4)
    for j in range(samples):
        t = (T - 2 * warm) * j / max(samples, 1)
        integ.advance(t, exact(t), t + warm)  # the step-size memory of this region
        # the memory, not last_step: the last step of a call is often a sliver cut to land on t1
        h = 0.9 * (getattr(integ, "_h_abs", None) or integ.last_step)
        t2 = t + warm
        y0 = exact(t2)
        n0, r0 = integ.nsteps, integ.nrejected
        y1 = integ.advance(t2, y0, t2 + h)
        if integ.nsteps - n0 != 1 or integ.nrejected != r0 or not integ.error_estimate:
            continue
        true = weighted_norm(y1 - _align(exact(t2 + h), y1, model), y0, y1, rtol, atol)
        row.local_ratios.append(true / integ.error_estimate)
        row.local_true.append(true)
    sim = Simulator(scenario.scene, integrator=method, rtol=rtol, atol=atol, backend=scenario.backend)
    y_start = sim.state
    n = max(1, round(T / ESTIMATE_CHUNK))
    for _ in range(n):
        sim.advance(T / n)
        row.estimates.append(float(sim.error_estimate))
    y = sim.state
    row.global_error = weighted_norm(y - _align(exact(sim.time), y, model), y_start, y, rtol, atol)
    return row


def estimate_summary(rows: list[EstimateRow]) -> str:
    """One sentence per method: by how much the estimate under- or over-states the error."""
    out = []
    for method in sorted({r.method for r in rows}):
        mine = [r for r in rows if r.method == method and r.local_ratios]
        if not mine:
            continue
        med = [float(np.median(r.local_ratios)) for r in mine]
        top = max(max(r.local_ratios) for r in mine)
        glob = [r.global_error / max(r.estimates) for r in mine if r.estimates and max(r.estimates) > 0]
        out.append(f"{method}: one step's true local error is {min(med):.2g} to {max(med):.2g} times its "
                   f"estimate (median per scene and tolerance; worst step {top:.2g}x); after the horizon the "
                   f"true global error is {min(glob):.2g} to {max(glob):.2g} times the largest estimate reported.")
    return " ".join(out)


def estimate_table(rows: list[EstimateRow]) -> str:
    lines = [
        "| scene | method | rtol | local: true / estimated, median [min, max] (steps) | true local error |"
        " reported estimate, median [max] | true global error at the horizon | global / max reported |",
        "|---|---|---:|---|---:|---:|---:|---:|",
    ]
    for r in rows:
        if r.local_ratios:
            a = np.array(r.local_ratios)
            local = f"{np.median(a):.2g} [{a.min():.2g}, {a.max():.2g}] ({a.size})"
            true = f"{np.median(r.local_true):.2g}"
        else:
            local = true = "n/a"
        est = float(np.median(r.estimates)) if r.estimates else math.nan
        top = float(np.max(r.estimates)) if r.estimates else math.nan
        lines.append(f"| {r.scene} | {r.method} | {r.rtol:g} | {local} | {true} | {est:.2g} [{top:.2g}] | "
                     f"{r.global_error:.2g} | {r.global_error / top:.2g}x |")
    return "\n".join(lines)


# --------------------------------------------------------------------------------- plot
def plot(scenarios: list[Scenario], points: list[Point], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cols = 4
    nrow = 2 * math.ceil(len(scenarios) / cols)
    fig, axes = plt.subplots(nrow, cols, figsize=(4.2 * cols, 3.3 * nrow), squeeze=False)
    labels = [m.label for m in METHODS]
    colors = [plt.get_cmap("tab10")(i) for i in range(10)] + ["black"]
    style = {lab: (colors[i % len(colors)], "o-" if METHODS[i].engine == "gyro_sim" else
                   ("s--" if METHODS[i].engine == "scipy" else "^:")) for i, lab in enumerate(labels)}
    for i, s in enumerate(scenarios):
        r, c = 2 * (i // cols), i % cols
        ax_e, ax_i = axes[r][c], axes[r + 1][c]
        mine = by_method([p for p in points if p.scene == s.case.key])
        for lab, pts in mine.items():
            color, fmt = style[lab]
            ok = sorted((p for p in pts if p.error is not None), key=lambda p: p.cpu)
            if ok:
                ax_e.loglog([p.cpu for p in ok], [max(p.error, 1e-17) for p in ok], fmt, color=color, ms=3,
                            label=lab, lw=1)
            oki = [p for p in ok if p.inv_error is not None]
            if oki:
                ax_i.loglog([p.cpu for p in oki], [max(p.inv_error, 1e-17) for p in oki], fmt, color=color,
                            ms=3, lw=1)
        ax_e.axhline(max(s.reference.est_error, 1e-17) if s.reference.true_error is None
                     else max(s.reference.true_error, 1e-17), color="k", lw=0.8, ls="--")
        ax_e.set_title(f"{s.case.title}, T = {s.case.horizon:g} s", fontsize=8)
        ax_e.set_ylabel("final-state error")
        ax_i.set_ylabel("invariant drift (relative)")
        ax_i.set_xlabel("CPU time (s)")
        for ax in (ax_e, ax_i):
            ax.grid(True, which="both", alpha=0.3)
            ax.tick_params(labelsize=7)
    for j in range(len(scenarios), (nrow // 2) * cols):
        axes[2 * (j // cols)][j % cols].axis("off")
        axes[2 * (j // cols) + 1][j % cols].axis("off")
    handles, labs = [], []
    for ax in axes.ravel():
        for h, lab in zip(*ax.get_legend_handles_labels()):
            if lab not in labs:
                handles.append(h)
                labs.append(lab)
    fig.legend(handles, labs, loc="lower center", ncol=len(labs), fontsize=8, frameon=False)
    fig.suptitle("Work-precision: error of the final state (upper panels) and of the invariants (lower) "
                 "against CPU time; dashed: the reference's own error", fontsize=10)
    fig.tight_layout(rect=(0, 0.03, 1, 0.97))
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ------------------------------------------------------------------------------ report
@dataclass
class Report:
    scenarios: list[Scenario]
    points: list[Point]
    summary: list[dict]
    estimates: list[EstimateRow]
    cpu_total: float
    quick: bool
    backend: str = "numpy"

    def markdown(self) -> str:
        mode = "quick mode (short horizons, few settings)" if self.quick else "full run"
        skipped = sorted({f"{s.case.key}" for s in self.scenarios if mujoco_skip(s.case)})
        text = [
            "### Accuracy: error against CPU time",
            "",
            f"`gyro-sim bench accuracy{' --quick' if self.quick else ''}`, {mode}, "
            f"{self.cpu_total:.0f} s of CPU, {self.backend} backend. Error of the final state: the largest "
            "attitude error "
            "(rad) and relative angular-velocity error of any body (free base: and of O^1). One "
            "integration per point from t = 0 to the horizon; atol = 1e-2 rtol.",
            "",
            "Cheapest method to reach a final-state error of 1e-6 and 1e-9 (CPU time interpolated "
            "log-log between runs; x: times the cheapest):",
            "",
            summary_table(self.summary),
            "",
            f"gyro_sim's dop853 against MuJoCo's RK4 at a final-state error of {PEER_TARGET:g} (CPU time "
            "interpolated as above; scenes MuJoCo can express):",
            "",
            peer_ratio_table(self.points),
            "",
            "References (exact where known; otherwise dop853 at rtol 1e-13, its error estimated "
            "by a second run at rtol 1e-12):",
            "",
            reference_table(self.scenarios),
            "",
        ]
        if skipped:
            text += [f"MuJoCo cannot represent {', '.join(skipped)} exactly (see the table): no MuJoCo rows there.",
                     ""]
        text += [
            "### The live error estimate against the true error",
            "",
            "`Simulator.error_estimate` is the weighted RMS norm of the last step's local error "
            "estimate (1 = the tolerance). Local: one step from an exact state, true local error "
            "in the same norm divided by the estimate (below 1: the estimate is pessimistic), and "
            "the true local error itself (median, tolerance units). Global: a node-like run in 10 ms "
            "chunks; the true error of the state at the horizon in the same norm, against the "
            "estimates reported on the way.",
            "",
            estimate_table(self.estimates),
            "",
            estimate_summary(self.estimates),
            "",
        ]
        return "\n".join(text)

    def all_points(self) -> str:
        return "### Every run\n\n" + points_table(self.points) + "\n"


def build(quick: bool = False, keys=None, methods=METHODS, estimate: bool = True, backend: str = "auto",
          progress=None) -> Report:
    cpu0 = time.process_time()
    chosen = [c for c in cases(quick) if keys is None or c.key in keys]
    scenarios, points, summary = [], [], []
    total = sum(len(m.quick if quick else m.full) for m in methods) * len(chosen)
    done = [0]

    def tick(p: Point) -> None:
        done[0] += 1
        if progress:
            progress(done[0], total, f"{p.scene} {p.label} {p.setting:g}")

    for case in chosen:
        s = Scenario(case, backend)
        scenarios.append(s)
        pts = sweep(s, quick, methods, tick)
        points += pts
        summary += summary_rows(case, pts)
    estimates = []
    if estimate:
        samples = 3 if quick else 12
        for s in scenarios:
            if not s.case.exact:
                continue
            for method in ("dop853", "radau"):
                for rtol in ((1e-6,) if quick else (1e-6, 1e-9)):
                    estimates.append(estimate_row(s, method, rtol, samples))
    resolved = backend
    if backend == "auto":
        from gyro_sim.dynamics.kernel import available

        resolved = "numba" if available() else "numpy"
    return Report(scenarios, points, summary, estimates, time.process_time() - cpu0, quick, resolved)


def to_json(report: Report) -> dict[str, Any]:
    return {
        "quick": report.quick,
        "cpu_total": report.cpu_total,
        "references": {s.case.key: {"kind": s.reference.kind, "est_error": s.reference.est_error,
                                    "true_error": s.reference.true_error, "horizon": s.case.horizon}
                       for s in report.scenarios},
        "points": [asdict(p) for p in report.points],
        "summary": [{"scene": r["scene"], "target": r["target"], "ranked": r["ranked"], "missed": r["missed"]}
                    for r in report.summary],
        "estimates": [asdict(e) for e in report.estimates],
    }


# --------------------------------------------------------------------------------- CLI
def main(args) -> int:
    from gyro_sim.progress import Progress

    if refused(args, "accuracy"):
        return 2
    report = build(quick=args.quick, keys=args.scenes, backend=args.backend,
                   progress=Progress("accuracy"))
    text = report.markdown()
    print(text)
    write_report(args.out, "accuracy", text + "\n" + report.all_points(), to_json(report),
                 lambda png: plot(report.scenarios, report.points, png), force=args.force)
    return 0


def register(sub, bench) -> None:
    """`gyro-sim bench accuracy` (cli.PLUGINS)."""
    p = bench.add_parser("accuracy", help="work-precision diagrams: error against CPU time, with peers")
    p.add_argument("--quick", action="store_true", help="short horizons, few settings (CI)")
    p.add_argument("--out", default="out/bench", help="directory for accuracy.md, accuracy.json, accuracy.png")
    add_force_option(p)
    p.add_argument("--scenes", nargs="+", choices=[c.key for c in cases()], help="a subset of the scenes")
    p.add_argument("--backend", default="auto", choices=("auto", "numba", "numpy"),
                   help="the Simulator's dynamics backend (default auto: numba when it imports)")
    p.set_defaults(fn=main)
