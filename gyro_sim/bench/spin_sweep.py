"""The spin sweep of the stability report: fast tops at the node's 1 kHz, with MuJoCo beside.

Two scenes, each spun at SPINS rad/s and started in its *slow regular precession*, so that
the exact motion is known (the paper's closing result, docs/theory.md section 4: eq 88, with the
general-n conditions before it; :func:`gyro_sim.analytic.lagrange.regular_precession_state`):
theta_k and psi_k' = kappa stay constant, phi_k' is constant
(:func:`gyro_sim.bench.accuracy.precession_exact` gives the state at any t):

- :func:`heavy_top` -- config/heavy_top.yaml (theta = 0.6) with proper rotation phi' = spin;
  for n = 1, eq 88 reads A phi' = (B - A) kappa cos th - m c g / kappa - lambda, whose slow
  root is kappa ~ -m c g / (A phi'): the precession slows as the spin grows (-2.4, -0.24,
  -0.024 rad/s at 1e2, 1e3, 1e4 rad/s). It is the fast heavy top of test/integrators/test_fixed.py
  (heavy_top.yaml spun at `spin` with psi' = 0 at the start) without the nutation that start
  excites: the same stiffness (rk4 at 1 ms is unstable past h |lambda| = 2 sqrt 2), a known
  solution.
- :func:`double_gyro` -- config/double_gyro_plus.yaml (thetas 0.6, 0.9, eps21 = +1, its
  wheel at -300 rad/s) with top 1's proper rotation phi_1' = spin (the slow root kappa of
  eq 88; top 2's phi_2' follows from it: ~0.5 x spin).

Every method (gyro_sim rk4, lie4, gauss4, gauss4s, fixed at h = 1 ms, `advance` in 10 ms calls as the
node; MuJoCo RK4 and implicitfast at the same step, peers.MujocoChain) runs `steps` steps
(1e6 in the full report, 1e4 in quick mode), sampled SAMPLES times:

- the slow motion: at every sample the axis eps^k of every carrier against the exact one
  (the largest angle between them, rad) and the precession angle of each axis (its azimuth
  about the vertical, against psi_k0 + kappa t), the largest over the run and bodies;
- the invariants: relative energy drift (E - E0) / (T0 + |V0|) and vertical angular
  momentum drift (K - K0) / |K0| (the engine's own: MuJoCo's energy and subtree momenta),
  their growth classified as the long-horizon item does (`budget.growth`: bounded,
  random walk ~ t^1/2, linear ~ t);
- the cost (CPU s of the run), or the failure message (SimulationError, MuJoCo's
  instability warnings), or "too slow" when the run's CPU budget is spent.
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from gyro_sim.analytic import lagrange as lg
from gyro_sim.dynamics.model import compile_model
from gyro_sim.scene.load import load_scene
from gyro_sim.simulator import SimulationError, Simulator
from gyro_sim.bench.accuracy import precession_exact
from gyro_sim.bench.budget import OverBudget, cpu_limit, growth
from gyro_sim.bench.extreme import load_dict
from gyro_sim.bench.peers import frames_of_state

#: spin rates (rad/s) of the sweep, the node's step, its call length, samples per run
SPINS = (1e2, 1e3, 1e4)
STEP = 1e-3
CHUNK = 0.01
SAMPLES = 200
#: the methods: gyro_sim integrators, then MuJoCo's (label -> MuJoCo integrator)
GYRO_METHODS = ("rk4", "lie4", "gauss4", "gauss4s", "fixed")
MUJOCO_METHODS = {"mujoco RK4": "RK4", "mujoco implicitfast": "implicitfast"}
METHODS = (*GYRO_METHODS, *MUJOCO_METHODS)
#: the scenes: key -> (title, builder)
SCENES = ("heavy_top", "double_gyro")


# ------------------------------------------------------------------------------- scenes
def _slow_kappa(chain: lg.LagrangeChain, thetas, spin: float, eps21: float = 1.0) -> float:
    """The slow root kappa (< 0, smallest |kappa|) of phi_1'(kappa) = spin, eq 88.

    phi_1'(kappa) -> +inf as kappa -> 0- (the -m c g / kappa term of the hanging chain); the
    first sign change of phi_1' - spin from there (on a log grid) brackets the slow root.
    """
    from scipy.optimize import brentq

    def f(kappa: float) -> float:
        return float(lg.regular_precession_spins(chain, thetas, kappa, eps21)[0]) - spin

    grid = -np.logspace(-9, 3, 1201)
    prev = grid[0]
    if not f(prev) > 0.0:
        raise ValueError(f"spin {spin:g}: phi_1' is not above it as kappa -> 0-")
    for k in grid[1:]:
        if f(k) <= 0.0:
            return float(brentq(f, k, prev, xtol=1e-300, rtol=1e-15, maxiter=500))
        prev = k
    raise ValueError(f"spin {spin:g}: no slow regular precession with kappa in [-1e3, 0)")


def _precessing(sd: dict, thetas, spin: float, eps21: float = 1.0) -> dict:
    chain = lg.LagrangeChain.from_scene(load_scene(sd))
    kappa = _slow_kappa(chain, thetas, spin, eps21)
    euler, rates = lg.regular_precession_state(chain, thetas, kappa, eps21)
    for b, e, r in zip(sd["bodies"], euler, rates):
        b["initial"] = {"euler": [float(x) for x in e], "euler_rates": [float(x) for x in r]}
    return sd


def heavy_top(spin: float) -> dict:
    """config/heavy_top.yaml in its slow regular precession with phi' = `spin` (eq 88, n = 1)."""
    sd = _precessing(load_dict("heavy_top"), [0.6], spin)
    kappa = sd["bodies"][0]["initial"]["euler_rates"][0]
    sd["name"] = f"heavy top spun at {spin:g} rad/s, slow regular precession kappa = {kappa:.4g} rad/s"
    return sd


def double_gyro(spin: float) -> dict:
    """config/double_gyro_plus.yaml in its slow regular precession with phi_1' = `spin` (eq 88)."""
    sd = _precessing(load_dict("double_gyro_plus"), [0.6, 0.9], spin, 1.0)
    kappa = sd["bodies"][0]["initial"]["euler_rates"][0]
    sd["name"] = f"double gyroscope, top 1 spun at {spin:g} rad/s, slow regular precession kappa = {kappa:.4g} rad/s"
    return sd


BUILDERS = {"heavy_top": heavy_top, "double_gyro": double_gyro}


# --------------------------------------------------------------------------------- runs
@dataclass
class SpinRun:
    scene: str
    spin: float
    method: str
    kappa: float  # the exact precession rate (rad/s)
    steps: int  # asked for
    steps_done: int = 0
    t: list[float] = field(default_factory=list)
    energy: list[float] = field(default_factory=list)  # (E - E0) / (T0 + |V0|)
    momentum: list[float] = field(default_factory=list)  # (K - K0) / |K0|
    axis_error: list[float] = field(default_factory=list)  # rad, largest over the bodies
    precession_error: list[float] = field(default_factory=list)  # rad, largest over the bodies
    energy_growth: str = ""
    energy_slope: float = math.nan
    momentum_growth: str = ""
    momentum_slope: float = math.nan
    cpu: float = 0.0
    failed: str | None = None
    too_slow: str | None = None

    @property
    def max_axis_error(self) -> float:
        return max(self.axis_error) if self.axis_error else math.nan

    @property
    def max_precession_error(self) -> float:
        return max(self.precession_error) if self.precession_error else math.nan


def _axes(R: np.ndarray) -> np.ndarray:
    """The body axes eps^k (world frame, (n, 3)) of carriers' attitudes R (n, 3, 3)."""
    return R[:, :, 2]


def _azimuth(axes: np.ndarray, up: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Azimuth of each axis about the vertical `up`, measured from the horizontal `ref`."""
    h = axes - np.outer(axes @ up, up)
    other = np.cross(up, ref)
    return np.arctan2(h @ other, h @ ref)


class _Exact:
    """The exact regular precession of a scene: axes and their azimuths at any t."""

    def __init__(self, scene, model):
        self.model = model
        self.state = precession_exact(scene, model)
        self.up = -model.down[:, 2]
        self.ref = np.cross(self.up, [0.0, 0.0, 1.0] if abs(self.up[2]) < 0.9 else [1.0, 0.0, 0.0])
        self.ref /= np.linalg.norm(self.ref)

    def errors(self, t: float, R: np.ndarray) -> tuple[float, float]:
        """(largest angle between numerical and exact axes, largest precession-angle error)."""
        Re = frames_of_state(self.model, t, self.state(t)).R
        a, e = _axes(R), _axes(Re)
        axis = float(np.max(np.arctan2(np.linalg.norm(np.cross(a, e), axis=1), np.sum(a * e, axis=1))))
        d = _azimuth(a, self.up, self.ref) - _azimuth(e, self.up, self.ref)
        prec = float(np.max(np.abs((d + math.pi) % (2 * math.pi) - math.pi)))
        return axis, prec


def _finish(run: SpinRun) -> None:
    for series, key in ((run.energy, "energy"), (run.momentum, "momentum")):
        words, slope, _ = growth(run.t, series)
        setattr(run, f"{key}_growth", words)
        setattr(run, f"{key}_slope", slope)


def run_gyro(key: str, spin: float, method: str, steps: int, budget: float, backend: str = "auto") -> SpinRun:
    scene = load_scene(BUILDERS[key](spin))
    model = compile_model(scene)
    exact = _Exact(scene, model)
    # one step of a throwaway simulator first: a method's compiled loop is compiled (or loaded
    # from the cache) at its first call, which is not the run's cost
    Simulator(scene, integrator=method, step=STEP, backend=backend).advance(STEP)
    sim = Simulator(scene, integrator=method, step=STEP, backend=backend)
    inv0 = sim.invariants()
    E_scale = abs(inv0["kinetic"]) + abs(inv0["potential"])
    K0 = inv0["vertical_momentum"]
    run = SpinRun(key, spin, method, scene.bodies[0].initial.euler_rates[0], steps)
    per_call = round(CHUNK / STEP)
    per_sample = max(per_call, steps // SAMPLES // per_call * per_call)
    cpu0 = time.process_time()
    with np.errstate(all="ignore"):
        try:
            with cpu_limit(budget):
                while run.steps_done < steps:
                    k = min(per_sample, steps - run.steps_done)
                    done = 0
                    while done < k:
                        c = min(per_call, k - done)
                        sim.advance(c * STEP)
                        done += c
                    run.steps_done += k
                    inv = sim.invariants()
                    run.t.append(sim.time)
                    run.energy.append((inv["energy"] - inv0["energy"]) / E_scale)
                    run.momentum.append((inv["vertical_momentum"] - K0) / abs(K0))
                    R = frames_of_state(model, sim.time, sim.state).R
                    a, p = exact.errors(sim.time, R)
                    run.axis_error.append(a)
                    run.precession_error.append(p)
        except SimulationError as exc:
            run.failed = str(exc)
        except OverBudget:
            run.too_slow = f"budget {budget:g} s CPU spent at t = {sim.time:.4g} s of {steps * STEP:g} s"
    run.cpu = time.process_time() - cpu0
    run.t.insert(0, 0.0)  # the initial state, also of a run stopped before its first sample
    run.energy.insert(0, 0.0)
    run.momentum.insert(0, 0.0)
    _finish(run)
    return run


def run_mujoco(key: str, spin: float, label: str, steps: int, budget: float) -> SpinRun:
    from gyro_sim.bench.peers import MujocoChain, mujoco_failure, mujoco_warnings
    scene = load_scene(BUILDERS[key](spin))
    model = compile_model(scene)
    exact = _Exact(scene, model)
    integrator = MUJOCO_METHODS[label]
    chain = MujocoChain(scene, STEP, integrator)
    inv0 = Simulator(scene).invariants()  # gyro_sim's T0 + |V0|: the energy's scale
    E_scale = abs(inv0["kinetic"]) + abs(inv0["potential"])
    mj0 = chain.invariants()
    K0 = mj0["vertical_momentum"]
    run = SpinRun(key, spin, label, scene.bodies[0].initial.euler_rates[0], steps)
    per_sample = max(1, steps // SAMPLES)
    cpu0 = time.process_time()
    with np.errstate(all="ignore"), mujoco_warnings() as messages:
        try:
            with cpu_limit(budget):
                while run.steps_done < steps:
                    k = min(per_sample, steps - run.steps_done)
                    chain.step(k)
                    run.steps_done += k
                    what = mujoco_failure(chain, messages)
                    if what:  # (MuJoCo has reset its state and time: the last good sample is kept)
                        last = run.t[-1] if run.t else 0.0
                        run.failed = f"MuJoCo {integrator}: {what} (in the {k} steps after t = {last:.4g} s)"
                        break
                    inv = chain.invariants()
                    run.t.append(chain.time)
                    run.energy.append((inv["energy"] - mj0["energy"]) / E_scale)
                    run.momentum.append((inv["vertical_momentum"] - K0) / abs(K0))
                    a, p = exact.errors(chain.time, chain.frames().R)
                    run.axis_error.append(a)
                    run.precession_error.append(p)
        except OverBudget:
            run.too_slow = f"budget {budget:g} s CPU spent at t = {chain.time:.4g} s of {steps * STEP:g} s"
    run.cpu = time.process_time() - cpu0
    run.t.insert(0, 0.0)  # the initial state, also of a run stopped before its first sample
    run.energy.insert(0, 0.0)
    run.momentum.insert(0, 0.0)
    _finish(run)
    return run


def mujoco_available() -> bool:
    try:
        import mujoco  # noqa: F401
    except ImportError:
        return False
    return True


def sweep(steps: int, budget: float, spins=SPINS, scenes=SCENES, methods=METHODS, progress=None,
          backend: str = "auto") -> list[SpinRun]:
    """Every scene x spin x method (MuJoCo's only where the package imports)."""
    out = []
    mj = mujoco_available()
    total = len(scenes) * len(spins) * len([m for m in methods if mj or m not in MUJOCO_METHODS])
    for key in scenes:
        for spin in spins:
            for m in methods:
                if m in MUJOCO_METHODS:
                    if not mj:
                        continue
                    run = run_mujoco(key, spin, m, steps, budget)
                else:
                    run = run_gyro(key, spin, m, steps, budget, backend)
                out.append(run)
                if progress:
                    progress(len(out), total, run)
    return out


# ------------------------------------------------------------------------------- tables
def _e(x: float) -> str:
    return "" if x is None or not math.isfinite(x) else f"{x:.1e}"


#: a drift whose largest value stays below this is round-off (its growth is still shown)
ROUND_OFF = 1e-12


def _growth(label: str, slope: float, series=None) -> str:
    if not label or label == "n/a":
        return label
    out = f"{label.split(' ')[0]} ({slope:.2f})" if math.isfinite(slope) else label
    if series is not None and len(series) and float(np.max(np.abs(series))) < ROUND_OFF:
        out += f", round-off (< {ROUND_OFF:g})"
    return out


def table(runs: list[SpinRun]) -> str:
    lines = [
        "| scene | spin (rad/s) | kappa (rad/s) | method | outcome | simulated (s) | axis error (rad) |"
        " precession angle error (rad) | energy drift, final [max] | growth (slope) |"
        " K drift, final [max] | growth (slope) | CPU (s) |",
        "|---|---:|---:|---|---|---:|---:|---:|---:|---|---:|---|---:|",
    ]
    for r in runs:
        if r.failed:
            outcome = "fails: " + r.failed.replace("|", "/")
            if len(outcome) > 170:
                outcome = outcome[:167] + "..."
        elif r.too_slow:
            outcome = "too slow: " + r.too_slow
        else:
            outcome = "finished"
        t_end = r.t[-1] if r.t else 0.0
        if r.failed:  # what it did before failing is not shown (as the verdict table)
            lines.append(f"| {r.scene} | {r.spin:.0e} | {r.kappa:.4g} | {r.method} | {outcome} | {t_end:.4g} | "
                         f"| | | | | | {r.cpu:.1f} |")
            continue
        if r.t and len(r.t) > 1:
            e = f"{r.energy[-1]:.1e} [{np.max(np.abs(r.energy)):.1e}]"
            k = f"{r.momentum[-1]:.1e} [{np.max(np.abs(r.momentum)):.1e}]"
        else:
            e = k = ""
        lines.append(f"| {r.scene} | {r.spin:.0e} | {r.kappa:.4g} | {r.method} | {outcome} | {t_end:.4g} | "
                     f"{_e(r.max_axis_error)} | {_e(r.max_precession_error)} | {e} | "
                     f"{_growth(r.energy_growth, r.energy_slope, r.energy)} | {k} | "
                     f"{_growth(r.momentum_growth, r.momentum_slope, r.momentum)} | {r.cpu:.1f} |")
    return "\n".join(lines)


def summary_table(runs: list[SpinRun]) -> str:
    """scene x spin rows, a cell per method: the largest axis error, the energy drift's growth
    (round-off: below ROUND_OFF throughout) and the CPU time, or the outcome."""
    methods = [m for m in METHODS if any(r.method == m for r in runs)]
    lines = ["| scene | spin (rad/s) | " + " | ".join(methods) + " |", "|---|---:|" + "---|" * len(methods)]
    keys = []
    for r in runs:
        if (r.scene, r.spin) not in keys:
            keys.append((r.scene, r.spin))
    for scene, spin in keys:
        cells = []
        for m in methods:
            r = next((x for x in runs if x.scene == scene and x.spin == spin and x.method == m), None)
            if r is None:
                cells.append("")
            elif r.failed:
                cells.append("fails")
            elif r.too_slow:
                cells.append(f"too slow (t = {r.t[-1] if r.t else 0:.3g} s)")
            else:
                e = "round-off" if r.energy and float(np.max(np.abs(r.energy))) < ROUND_OFF else \
                    r.energy_growth.split(' ')[0]
                cells.append(f"axis {r.max_axis_error:.0e}, E {e}, {r.cpu:.0f} s")
        lines.append(f"| {scene} | {spin:.0e} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def plot(axes, runs: list[SpinRun]) -> None:
    """Two panels: largest axis error and largest |energy drift| against the spin, per method
    (solid: heavy top, dashed: double gyroscope; a failed run is not drawn)."""
    import matplotlib.pyplot as plt

    ax_a, ax_e = axes
    colors = {m: plt.get_cmap("tab10")(i) for i, m in enumerate(METHODS)}
    for scene, style in (("heavy_top", "o-"), ("double_gyro", "s--")):
        for m in METHODS:
            pts = [r for r in runs if r.scene == scene and r.method == m and not r.failed and len(r.t) > 1]
            if not pts:
                continue
            s = [r.spin for r in pts]
            ax_a.loglog(s, [max(r.max_axis_error, 1e-17) for r in pts], style, color=colors[m], ms=4,
                        label=f"{m} ({scene})")
            ax_e.loglog(s, [max(float(np.max(np.abs(r.energy))), 1e-17) for r in pts], style, color=colors[m],
                        ms=4)
    ax_a.set_ylabel("largest axis error (rad)")
    ax_e.set_ylabel("largest |E - E0| / (T0 + |V0|)")
    for ax in axes:
        ax.set_xlabel("spin (rad/s)")
        ax.grid(True, which="both", alpha=0.3)
    ax_a.set_title("spin sweep: slow motion vs exact regular precession (eq 88)", fontsize=9)
    ax_e.set_title("spin sweep: energy drift (solid: heavy top, dashed: double gyro)", fontsize=9)
    ax_a.legend(fontsize=5, ncol=2)


def to_json(runs: list[SpinRun]) -> list[dict[str, Any]]:
    return [asdict(r) for r in runs]


