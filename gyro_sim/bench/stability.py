"""`gyro-sim bench stability`: stiff and extreme cases, a verdict per integrator.

Every case (:func:`items`, scenes from :mod:`gyro_sim.bench.extreme`) runs with every
integrator at the settings of :data:`SETTINGS` (the fixed-step methods at the node's 1 kHz,
the adaptive ones at rtol 1e-8), node-like: `Simulator.advance` in CHUNK-second calls,
commands set between calls. A run gets one verdict:

- **fails**: `Simulator.advance` raised SimulationError (divergence, NaN, step-size
  collapse); the message is shown, no number of that run is;
- **too slow**: its CPU time passed the case's budget before the horizon (how far it got
  is shown);
- **drifts**: it finished, but an invariant the exact motion keeps drifted by more than
  DRIFT_TOL (relative), or its final state is further than ERROR_TOL from the reference
  (exact where known, else dop853 at REF_RTOL in the same chunks, checked by a run at
  CHECK_RTOL: if the two differ by more than REF_AGREE the final state is not reproducible
  and no error is judged), or (Kapitza) the rod did the opposite of what the classical
  condition predicts;
- **stable**: it finished within all of these.

The long-horizon item is separate: RK4 and Lie4 for 1e6 steps (1e4 in quick mode) on a
small scene, the energy recorded on the way; the growth of |E(t) - E(0)| is classified as
bounded, random-walk (t^1/2), linear (t^1) or superlinear (slope 1.5 and more: an
instability) by its log-log slope over the last two decades of time, and its rate fitted.

Beside them (:mod:`gyro_sim.bench.spin_sweep`, :mod:`gyro_sim.bench.heavy_tips`): MuJoCo's
implicitfast and RK4 at the same 1 ms step as rows of the verdict tables wherever MuJoCo can
express the case (:func:`peers.mujoco_unsupported` says why not), a spin sweep of fast tops
against the exact regular precession (eq 88), and the heavy/light-tip accelerations against
80 digits.
"""
from __future__ import annotations

import math
import time
import warnings
from dataclasses import asdict, dataclass, field
from typing import Any, Callable

import numpy as np

from gyro_sim.dynamics.invariants import conserved
from gyro_sim.dynamics.model import compile_model
from gyro_sim.scene.load import load_scene
from gyro_sim.simulator import SimulationError, Simulator
from gyro_sim.bench import extreme as ex
from gyro_sim.bench.accuracy import (
    ATOL_FACTOR, chain_length, invariant_error, invariant_scales, precession_exact, state_error,
)
from gyro_sim.bench.peers import frames_of_state, mujoco_unsupported
from gyro_sim.bench.scenes import spherical_chain
from gyro_sim.bench.budget import OverBudget, cpu_limit, growth
from gyro_sim.bench.report import add_force_option, refused, write_report

#: seconds of simulated time per `advance` call (a node publishing at 100 Hz)
CHUNK = 0.01
#: the integrators and their settings (fixed steps: the node's 1 kHz physics rate)
SETTINGS: dict[str, dict[str, float]] = {
    "rk4": {"step": 1e-3},
    "lie4": {"step": 1e-3},
    "gauss4": {"step": 1e-3},
    "gauss4s": {"step": 1e-3},
    "fixed": {"step": 1e-3},
    "dop853": {"rtol": 1e-8},
    "radau": {"rtol": 1e-8},
    "auto": {"rtol": 1e-8},
}
#: MuJoCo's rows (peers.MujocoChain), at the node's step, in the same chunks: row -> integrator
MUJOCO_ROWS = {"mujoco implicitfast": "implicitfast", "mujoco RK4": "RK4"}
MUJOCO_STEP = 1e-3
#: every row of the verdict tables, in order
ROWS = (*SETTINGS, *MUJOCO_ROWS)
#: verdict thresholds: relative drift of a conserved invariant, final-state error
DRIFT_TOL = 1e-5
ERROR_TOL = 1e-3
#: the reference of cases without an exact solution, and the check run that estimates its
#: error: if they differ by more than REF_AGREE, the final state is not reproducible (the
#: motion amplifies round-off) and errors are not judged
REF_RTOL, CHECK_RTOL = 1e-11, 1e-10
REF_AGREE = 0.1 * 1e-3
NO_REF_HEAVY = ("no reference: the motion amplifies round-off (rhs exact to 1e-14 relative on the compiled "
                "path, 6e-8 on the numpy one: test/dynamics/test_heavy_tip.py), a tight run cannot be had")
#: Kapitza: the upright rod "falls" once its tilt from the upward vertical passes FALLEN
#: (below the horizontal), else it "stays up" (Kapitza's effective potential
#: cos(tilt) + (margin / 2) sin(tilt)^2 keeps a margin > 1 rod below its barrier at
#: cos(tilt) = 1 / margin: 0.64 rad at margin 1.25)
FALLEN = math.pi / 2
#: long horizon: scene, step and how often the energy is recorded
LONG_STEP = 1e-3
LONG_SAMPLES = 200


@dataclass(frozen=True)
class Item:
    """One stability case."""

    key: str
    title: str
    build: Callable[[], dict]
    horizon: float  # s
    budget: float  # CPU s per run
    moments: tuple[float, ...] | None = None
    moments_at: float = 0.0  # the step time of the moments
    exact: bool = False
    kapitza_margin: float | None = None
    integrators: tuple[str, ...] = tuple(SETTINGS)
    why: str = ""
    backend: str | None = None  # overrides the report's backend
    no_reference: str = ""  # why there is no reference run (then errors are not judged)


def items(quick: bool = False) -> list[Item]:
    """The suite. Quick mode: shorter horizons, small budgets, no n = 200, two Kapitza margins."""
    q = quick
    budget = 2.0 if q else 60.0
    abrupt_scene, abrupt_moments = ex.abrupt_commands()
    ratio = 1e4
    w_n, w_p = ex.fast_rotor_frequencies(ex.fast_rotor_spin(ratio))
    out = [
        Item("fast_rotor", f"fast rotor, nutation {w_n:.0f} rad/s = {ratio:.0e} x precession {w_p:.3f} rad/s",
             lambda: ex.fast_rotor_precession(ratio), 0.2 if q else 2.0, budget, exact=True,
             why="gyroscopic stiffness (eigenvalues +-1080i); exact regular precession"),
        Item("light_tip", "light tip, mass ratio 1e-6", lambda: ex.mass_ratio_chain(1e-6), 0.2 if q else 1.0,
             budget, why="the tip is 1e-6 of its neighbour: cond(M) ~ 2e9"),
        Item("heavy_tip", "heavy tip, mass ratio 1e6", lambda: ex.mass_ratio_chain(1e6), 0.02 if q else 0.1,
             budget / 2, no_reference=NO_REF_HEAVY,
             why="two light links carry a 3e5 kg tip: cond(M) ~ 4e9, the links whip when the chain straightens"),
    ]
    if _default_backend() == "numba":
        out.append(Item("heavy_tip_numpy", "heavy tip, mass ratio 1e6, numpy backend", lambda: ex.mass_ratio_chain(1e6),
                        0.02 if q else 0.1, budget / 2, backend="numpy", no_reference=NO_REF_HEAVY,
                        why="the same with the numpy backend (composite-inertia matrix and a dense solve)"))
    out.append(Item("chain_100", "long chain, n = 100", lambda: spherical_chain(100), 0.01 if q else 0.05, budget,
                    why="700 states: radau's finite-difference Jacobian costs 700 evaluations"))
    if not q:
        out.append(Item("chain_200", "long chain, n = 200", lambda: spherical_chain(200), 0.05, 3 * budget,
                        why="1400 states"))
    for margin in ((0.5, 3.77) if q else (0.5, 0.8, 1.25, 2.0, 3.77)):
        f = ex.kapitza_threshold_frequency() * math.sqrt(margin)
        out.append(Item(f"kapitza_{margin:g}", f"Kapitza, base at {f:.1f} Hz, (a W)^2 = {margin:g} x 2 g I / (m c)",
                        (lambda m=margin: ex.kapitza(m)), 1.0 if q else 3.0, budget, kapitza_margin=margin,
                        why=f"inverted rod, base vibrating at {f:.1f} Hz; Kapitza: "
                            f"{'stable' if margin > 1 else 'unstable'}"))
    out += [
        Item("looping_top", "axis through theta = 0 and pi (looping top)", ex.looping_top, 0.3 if q else 2.0,
             budget, why="starts at theta = 0 exactly, loops over theta = pi (Euler-angle singularities)"),
        Item("near_spherical", "near-degenerate inertia, A = B (1 + 1e-9)", ex.near_spherical_top,
             0.3 if q else 2.0, budget, why="spherical inertia to 1e-9: undefined principal axes"),
        Item("thin_rod", "very thin body, A = 1e-8 B", ex.thin_rod_top, 0.3 if q else 2.0, budget,
             why="axial inertia 1e-8 of the transverse: cond(M) 1e8"),
        Item("flat_disc", "very flat body, A_c = 2 B_c (1 - 1e-9)", ex.flat_disc_top, 0.3 if q else 2.0, budget,
             why="at the triangle-inequality limit"),
        Item("abrupt", f"step moments {ex.ABRUPT_FACTOR:g} x gravity torque (hinge chain)",
             lambda: abrupt_scene, 0.02 if q else 0.05, budget, moments=tuple(abrupt_moments), moments_at=0.01,
             why=f"at t = 0.01 s the hinge chain's axes get {ex.ABRUPT_FACTOR:g} x their gravity torque "
                 f"({', '.join(f'{m:.0f}' for m in abrupt_moments)} N m)"),
    ]
    return out


def _default_backend() -> str:
    """The backend "auto" resolves to: numba when it imports, else numpy."""
    from gyro_sim.dynamics.kernel import available

    return "numba" if available() else "numpy"


# ---------------------------------------------------------------------------------- runs
@dataclass
class Run:
    item: str
    integrator: str
    verdict: str = ""
    t_reached: float = 0.0
    drift: float | None = None  # largest relative drift of the conserved invariants
    energy_drift: float | None = None
    error: float | None = None
    nsteps: int = 0
    nrejected: int = 0
    nfev: int = 0
    cpu: float = 0.0
    note: str = ""
    max_tilt: float | None = None  # Kapitza
    switches: list = field(default_factory=list)


def _names(model, moments) -> tuple[str, ...]:
    names = conserved(model)
    if moments is not None:
        names = tuple(n for n in names if n not in ("energy", "jacobi"))
    return names


def _tilt(sim: Simulator) -> float:
    """Angle (rad) between the first body's axis and the upward vertical."""
    axis = sim.body_states()[0].rotation[:, 2]
    up = -sim.model.down[:, 2]
    return float(np.arccos(np.clip(axis @ up, -1.0, 1.0)))


def simulate(item: Item, scene, integrator: str, settings: dict, budget: float,
             backend: str = "auto") -> tuple[Run, Simulator]:
    """One node-like run of `item` (see the module docstring); the run and the simulator."""
    rtol = settings.get("rtol", 1e-8)
    sim = Simulator(scene, integrator=integrator, rtol=rtol, atol=rtol * ATOL_FACTOR,
                    step=settings.get("step", 1e-3), backend=item.backend or backend)
    run = Run(item.key, integrator)
    n = max(1, round(item.horizon / CHUNK))
    dt = item.horizon / n
    tilt = _tilt(sim) if item.kapitza_margin is not None else None
    cpu0 = time.process_time()
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the auto integrator's switches are read from it
        try:
            with cpu_limit(budget):
                for i in range(n):
                    if item.moments is not None and i * dt >= item.moments_at - 1e-12 and \
                            not np.any(sim.axis_moments):
                        sim.set_axis_moments(item.moments)
                    try:
                        sim.advance(dt)
                    except SimulationError as exc:
                        run.verdict = "fails"
                        run.note = str(exc)
                        break
                    if tilt is not None:
                        tilt = max(tilt, _tilt(sim))
                    if time.process_time() - cpu0 > budget and i < n - 1:
                        raise OverBudget()
        except OverBudget:
            pass
        if run.verdict == "" and sim.time < item.horizon * (1 - 1e-9):
            run.verdict = "too slow"
            run.note = f"budget {budget:g} s CPU spent at t = {sim.time:.3g} s of {item.horizon:g} s"
    run.cpu = time.process_time() - cpu0
    run.t_reached = sim.time
    integ = sim.integrator
    run.nsteps, run.nrejected, run.nfev = integ.nsteps, integ.nrejected, integ.nfev
    run.max_tilt = tilt
    run.switches = [(round(t, 6), a, b, why) for t, a, b, why in getattr(integ, "switches", [])]
    return run, sim


@dataclass
class ItemResult:
    item: Item
    runs: list[Run]
    reference: str  # what the errors are against
    predicted: str | None = None  # Kapitza: "stays up" / "falls"
    mujoco_skipped: str | None = None  # why there are no MuJoCo rows


def mujoco_skip(scene) -> str | None:
    """Why MuJoCo gets no row on `scene` (package missing, scene not expressible), or None."""
    try:
        import mujoco  # noqa: F401
    except ImportError:
        return "the mujoco package is not installed"
    return mujoco_unsupported(scene)


def simulate_mujoco(item: Item, scene, row: str, budget: float) -> tuple[Run, Any]:
    """`item` in MuJoCo (peers.MujocoChain, integrator MUJOCO_ROWS[row]) at MUJOCO_STEP, as
    :func:`simulate` does it: CHUNK-second calls, the step moments set between calls from
    `item.moments_at` on (generalised forces on the hinge and rotor joints, as the accuracy
    report's peers); the run and the chain."""
    from gyro_sim.bench.peers import MujocoChain, mujoco_failure, mujoco_warnings

    run = Run(item.key, row)
    n = max(1, round(item.horizon / CHUNK))
    per = max(1, round(item.horizon / n / MUJOCO_STEP))
    chain = MujocoChain(scene, item.horizon / n / per, MUJOCO_ROWS[row])
    chain.invariants0 = chain.invariants()
    applied = False
    cpu0 = time.process_time()
    with np.errstate(all="ignore"), mujoco_warnings() as messages:
        try:
            with cpu_limit(budget):
                for i in range(n):
                    if item.moments is not None and not applied and i * item.horizon / n >= item.moments_at - 1e-12:
                        chain.set_moments(item.moments)
                        applied = True
                    chain.step(per)
                    run.nsteps += per
                    what = mujoco_failure(chain, messages)
                    if what:  # MuJoCo has reset its state and time to the model's rest
                        run.verdict = "fails"
                        run.t_reached = i * item.horizon / n
                        run.note = f"MuJoCo {MUJOCO_ROWS[row]}: {what} (in the call from t = {run.t_reached:.3g} s)"
                        break
        except OverBudget:
            pass
    run.cpu = time.process_time() - cpu0
    if run.verdict != "fails":
        run.t_reached = chain.time
    if run.verdict == "" and chain.time < item.horizon * (1 - 1e-9):
        run.verdict = "too slow"
        run.note = f"budget {budget:g} s CPU spent at t = {chain.time:.3g} s of {item.horizon:g} s"
    return run, chain


def run_item(item: Item, integrators=None, progress=None, backend: str = "auto",
             mujoco: bool = True) -> ItemResult:
    scene = load_scene(item.build())
    model = compile_model(scene)
    names = _names(model, item.moments)
    sim0 = Simulator(scene)
    inv0 = sim0.invariants()
    scales = invariant_scales(inv0, names)
    length, free = chain_length(model), model.free
    # the reference: exact, or a tight dop853 run in the same chunks, checked by a second one
    ref_frames, ref_kind = None, "none"
    if item.exact:
        exact = precession_exact(scene, model)
        ref_frames = frames_of_state(model, item.horizon, exact(item.horizon))
        ref_kind = "exact"
    elif item.no_reference:
        ref_kind = item.no_reference
    else:
        runs = [simulate(item, scene, "dop853", {"rtol": r}, item.budget, backend) for r in (REF_RTOL, CHECK_RTOL)]
        if all(r.verdict == "" for r, _ in runs):
            ref_frames, check = (frames_of_state(model, sim.time, sim.state) for _, sim in runs)
            agree = state_error(check, ref_frames, length, free)
            ref_kind = f"dop853 rtol {REF_RTOL:g}, within {agree:.0e} of rtol {CHECK_RTOL:g}"
            if agree > REF_AGREE:
                ref_kind = (f"none: dop853 at rtol {REF_RTOL:g} and {CHECK_RTOL:g} differ by {agree:.1g} "
                            "(the final state is not reproducible)")
                ref_frames = None
        else:
            ref_kind = f"none (dop853 rtol {REF_RTOL:g}: {runs[0][0].verdict or runs[1][0].verdict})"
    result = ItemResult(item, [], ref_kind)
    if item.kapitza_margin is not None:
        result.predicted = "stays up" if item.kapitza_margin > 1.0 else "falls"
    for name in integrators or item.integrators:
        run, sim = simulate(item, scene, name, SETTINGS[name], item.budget, backend)
        if run.verdict == "":
            _judge(run, inv0, sim.invariants(), frames_of_state(model, sim.time, sim.state), names, scales,
                   ref_frames, length, free, result.predicted)
        if progress:
            progress(run)
        result.runs.append(run)
    if mujoco:
        result.mujoco_skipped = mujoco_skip(scene)
        for row in (() if result.mujoco_skipped else MUJOCO_ROWS):
            run, chain = simulate_mujoco(item, scene, row, item.budget)
            if run.verdict == "":
                # MuJoCo's own energy and momenta, against its own at t = 0 (as the accuracy report)
                _judge(run, chain.invariants0, chain.invariants(), chain.frames(), names, scales, ref_frames,
                       length, free, result.predicted)
            if progress:
                progress(run)
            result.runs.append(run)
    return result


def _judge(run: Run, inv0: dict, inv1: dict, frames, names, scales, ref_frames, length, free,
           predicted) -> None:
    """The verdict of a finished run from its invariants and final frames."""
    run.drift = invariant_error(inv0, inv1, names, scales)
    if "energy" in names:
        run.energy_drift = invariant_error(inv0, inv1, ("energy",), scales)
    if ref_frames is not None:
        run.error = state_error(frames, ref_frames, length, free)
    run.verdict, run.note = _verdict(run, predicted)


def _verdict(run: Run, predicted: str | None) -> tuple[str, str]:
    notes = []
    if run.switches:
        notes.append("; ".join(f"{a} -> {b} at t = {t:.3g} s" for t, a, b, _ in run.switches))
    bad = []
    if run.drift is not None and not run.drift <= DRIFT_TOL:
        bad.append(f"invariant drift {run.drift:.1e}")
    if run.error is not None and not run.error <= ERROR_TOL:
        bad.append(f"error {run.error:.1e}")
    if predicted is not None and run.max_tilt is not None:
        outcome = kapitza_outcome(run.max_tilt)
        notes.append(f"{outcome} (max tilt {run.max_tilt:.3f} rad)")
        if outcome != predicted:
            bad.append(f"Kapitza predicts: {predicted}")
    return ("drifts" if bad else "stable"), "; ".join(bad + notes)


def kapitza_outcome(max_tilt: float) -> str:
    return "falls" if max_tilt > FALLEN else "stays up"


# -------------------------------------------------------------------------- long horizon
@dataclass
class LongRun:
    integrator: str
    steps: int
    step: float
    t: list[float]
    drift: list[float]  # (E(t) - E(0)) / (T0 + |V0|)
    cpu: float
    growth: str = ""
    slope: float = math.nan  # log-log slope of max |drift| over the last two decades
    rate: float = math.nan  # fitted d(drift)/dt, per second
    failed: str | None = None


def long_horizon(steps: int, integrators=("rk4", "lie4"), progress=None, backend: str = "auto") -> list[LongRun]:
    """`steps` fixed steps of LONG_STEP on :func:`extreme.nutating_top`, energy sampled."""
    scene = load_scene(ex.nutating_top())
    out = []
    for name in integrators:
        sim = Simulator(scene, integrator=name, step=LONG_STEP, backend=backend)
        inv0 = sim.invariants()
        scale = abs(inv0["kinetic"]) + abs(inv0["potential"])
        per = max(1, steps // LONG_SAMPLES)
        run = LongRun(name, steps, LONG_STEP, [0.0], [0.0], 0.0)
        cpu0 = time.process_time()
        done = 0
        try:
            while done < steps:
                k = min(per, steps - done)
                sim.advance(k * LONG_STEP)
                done += k
                run.t.append(sim.time)
                run.drift.append((sim.invariants()["energy"] - inv0["energy"]) / scale)
                if progress:
                    progress(name, done, steps)
        except SimulationError as exc:
            run.failed = str(exc)
        run.cpu = time.process_time() - cpu0
        run.growth, run.slope, run.rate = growth(run.t, run.drift)
        out.append(run)
    return out


# ------------------------------------------------------------------------------- tables
def _g(x: float | None, fmt: str = ".1e") -> str:
    return "" if x is None or (isinstance(x, float) and math.isnan(x)) else format(x, fmt)


def verdict_table(results: list[ItemResult]) -> str:
    lines = [
        "| case | integrator | verdict | energy drift | invariant drift | error | steps | rejected | CPU (s) | note |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|---|",
    ]
    for res in results:
        for r in res.runs:
            note = r.note.replace("|", "/")
            if r.verdict == "fails" and len(note) > 160:
                note = note[:157] + "..."
            lines.append(f"| {res.item.key} | {r.integrator} | **{r.verdict}** | {_g(r.energy_drift)} | "
                         f"{_g(r.drift)} | {_g(r.error)} | {r.nsteps} | {r.nrejected} | {r.cpu:.2f} | {note} |")
    return "\n".join(lines)


def overview_table(results: list[ItemResult]) -> str:
    names = list(ROWS)
    lines = ["| case | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    for res in results:
        v = {r.integrator: r.verdict for r in res.runs}
        lines.append(f"| {res.item.title} | " + " | ".join(v.get(n, "") for n in names) + " |")
    return "\n".join(lines)


def cases_table(results: list[ItemResult]) -> str:
    lines = ["| case | horizon (s) | reference | what makes it hard | MuJoCo |", "|---|---:|---|---|---|"]
    for res in results:
        mj = "yes" if any(r.integrator in MUJOCO_ROWS for r in res.runs) else \
            ("skipped: " + res.mujoco_skipped if res.mujoco_skipped else "not run")
        lines.append(f"| {res.item.key} | {res.item.horizon:g} | {res.reference} | {res.item.why or res.item.title} "
                     f"| {mj} |")
    return "\n".join(lines)


def mujoco_skipped_text(results: list[ItemResult]) -> str:
    """One sentence: the cases MuJoCo cannot express, each with the reason."""
    skipped = [f"{r.item.key} ({r.mujoco_skipped})" for r in results if r.mujoco_skipped]
    return ("No MuJoCo rows for " + "; ".join(skipped) + ".") if skipped else ""



def kapitza_table(results: list[ItemResult]) -> str:
    lines = ["| (a W)^2 / (2 g I / (m c)) | base frequency (Hz) | Kapitza predicts | "
             + " | ".join(SETTINGS) + " |", "|---:|---:|---|" + "---|" * len(SETTINGS)]
    for res in results:
        if res.item.kapitza_margin is None:
            continue
        m = res.item.kapitza_margin
        cells = []
        for n in SETTINGS:
            r = next((r for r in res.runs if r.integrator == n), None)
            if r is None or r.max_tilt is None or r.verdict in ("fails", "too slow"):
                cells.append(r.verdict if r else "")
            else:
                o = kapitza_outcome(r.max_tilt)
                cells.append(f"{o} ({r.max_tilt:.2f})" + ("" if o == res.predicted else " WRONG"))
        f = ex.kapitza_threshold_frequency() * math.sqrt(m)
        lines.append(f"| {m:g} | {f:.1f} | {res.predicted} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def long_table(runs: list[LongRun]) -> str:
    lines = ["| integrator | steps (h = 1 ms) | simulated (s) | final energy drift | growth | log-log slope |"
             " rate (per s) | rate (per hour) | CPU (s) |",
             "|---|---:|---:|---:|---|---:|---:|---:|---:|"]
    for r in runs:
        if r.failed:
            lines.append(f"| {r.integrator} | {r.steps} | {r.t[-1]:.3g} | failed: {r.failed[:80]} | | | | | "
                         f"{r.cpu:.1f} |")
            continue
        lines.append(f"| {r.integrator} | {r.steps:.0e} | {r.t[-1]:.4g} | {r.drift[-1]:.2e} | {r.growth} | "
                     f"{_g(r.slope, '.2f')} | {_g(r.rate, '.2e')} | {_g(r.rate * 3600, '.2e')} | {r.cpu:.1f} |")
    return "\n".join(lines)


# --------------------------------------------------------------------------------- plot
def plot(results: list[ItemResult], long_runs: list[LongRun], path: str, spin_runs=()) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if spin_runs:
        from gyro_sim.bench import spin_sweep as ss

        fig, axes = plt.subplots(2, 2, figsize=(14, 10), gridspec_kw={"width_ratios": [1.6, 1]})
        (ax0, ax1), bottom = axes
        ss.plot(bottom, spin_runs)
    else:
        fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(14, 5), gridspec_kw={"width_ratios": [1.6, 1]})
    names = list(ROWS)
    colors = {"stable": "#4caf50", "drifts": "#ffb300", "fails": "#e53935", "too slow": "#8e8e8e"}
    keys = [r.item.key for r in results]
    for i, res in enumerate(results):
        for r in res.runs:
            j = names.index(r.integrator)
            ax0.add_patch(plt.Rectangle((j, i), 1, 1, color=colors.get(r.verdict, "white")))
            ax0.text(j + 0.5, i + 0.5, f"{r.verdict}\n{r.cpu:.2g} s", ha="center", va="center", fontsize=6)
    ax0.set_xlim(0, len(names))
    ax0.set_ylim(len(keys), 0)
    ax0.set_xticks(np.arange(len(names)) + 0.5, [n.replace("mujoco ", "MuJoCo\n") for n in names], fontsize=7)
    ax0.set_yticks(np.arange(len(keys)) + 0.5, keys, fontsize=7)
    ax0.set_title("verdict and CPU time per case and integrator")
    for r in long_runs:
        if len(r.t) > 1:
            t, d = np.array(r.t[1:]), np.abs(np.array(r.drift[1:]))
            ax1.loglog(t, np.maximum(d, 1e-17), label=f"{r.integrator}: {r.growth}")
    ax1.set_xlabel("simulated time (s)")
    ax1.set_ylabel("|E(t) - E(0)| / (T + |V|)")
    ax1.set_title(f"long horizon, h = {LONG_STEP * 1e3:g} ms, nutating top")
    ax1.grid(True, which="both", alpha=0.3)
    ax1.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ------------------------------------------------------------------------------- report
@dataclass
class Report:
    results: list[ItemResult]
    long_runs: list[LongRun]
    cpu_total: float
    quick: bool
    backend: str = "numpy"
    spin_runs: list = field(default_factory=list)  # spin_sweep.SpinRun
    sweep_steps: int = 0
    tips: list = field(default_factory=list)  # heavy_tips.TipRow
    wall: float = 0.0  # s
    costs: list = field(default_factory=list)  # step_cost.CostRow
    holding: dict = field(default_factory=dict)  # method -> (largest n measured holding 1 kHz, crossing)

    def markdown(self) -> str:
        mode = "quick mode (short horizons, small budgets)" if self.quick else "full run"
        settings = ", ".join(f"{k} " + ", ".join(f"{a} {b:g}" for a, b in v.items()) for k, v in SETTINGS.items())
        return "\n".join([
            "### Stability: stiff and extreme cases",
            "",
            f"`gyro-sim bench stability{' --quick' if self.quick else ''}`, {mode}, {self.cpu_total:.0f} s of CPU, "
            f"{self.backend} backend. "
            f"Settings: {settings} (atol = 1e-2 rtol); `advance` in {CHUNK * 1e3:g} ms calls. Verdicts: "
            f"*stable* (finished, conserved invariants within {DRIFT_TOL:g} relative, final state within "
            f"{ERROR_TOL:g} of the reference), *drifts* (finished outside those), *fails* (SimulationError: "
            "the run stopped, nothing of it reaches an output), *too slow* (CPU budget spent before the "
            "horizon).",
            "",
            overview_table(self.results),
            "",
            f"Kapitza's pendulum, inverted, tilted {ex.KAPITZA_TILT:g} rad: the classical condition "
            "(a W)^2 > 2 g I / (m c) "
            "against what each integrator shows (max tilt from the upward vertical in rad; falls: past "
            "the horizontal):",
            "",
            kapitza_table(self.results),
            "",
            "Long horizon: energy drift of the fixed-step methods (growth from the log-log slope of "
            "max |drift| over the last two decades of time):",
            "",
            long_table(self.long_runs),
            "",
            *self._spin_section(),
            *self._tips_section(),
            *self._cost_section(),
            "The numbers behind the verdicts:",
            "",
            verdict_table(self.results),
            "",
            "The cases:",
            "",
            cases_table(self.results),
            "",
            mujoco_skipped_text(self.results),
            "",
        ])

    def _spin_section(self) -> list[str]:
        from gyro_sim.bench import spin_sweep as ss

        if not self.spin_runs:
            return []
        return [
            f"### Spin sweep: fast tops at h = {ss.STEP * 1e3:g} ms",
            "",
            "The heavy top (config/heavy_top.yaml) and the double gyroscope (config/double_gyro_plus.yaml), "
            "top 1 spun at 1e2, 1e3, 1e4 rad/s and started in its slow regular precession (the paper's "
            "eq 88, `lagrange.regular_precession_state`; slow root kappa of phi_1'(kappa) = spin), so "
            "the exact motion is known (theta_k, psi_k' = kappa, phi_k' constant: "
            "`accuracy.precession_exact`). "
            f"{self.sweep_steps:.0e} steps each"
            f"{' (quick mode)' if self.quick else ''}, gyro_sim in {ss.CHUNK * 1e3:g} ms `advance` calls, MuJoCo "
            f"in its own steps; {ss.SAMPLES} samples. Axis error: the largest angle between a "
            "carrier's axis and the exact one over the run; precession angle error: the largest error "
            "of an axis's azimuth about the vertical; energy drift (E - E0) / (T0 + |V0|) and vertical "
            "angular momentum drift (K - K0) / |K0| (MuJoCo: its own), final and [largest], growth "
            "classified as in the long-horizon item (log-log slope of the running max over the last two "
            "decades). A run that fails shows its message and how far it got, nothing else.",
            "",
            ss.summary_table(self.spin_runs),
            "",
            ss.table(self.spin_runs),
            "",
        ]

    def _cost_section(self) -> list[str]:
        from gyro_sim.bench import step_cost as sc

        if not self.costs:
            return []
        hold = []
        for method, (best, crossing) in self.holding.items():
            if best is None:
                hold.append(f"{method}: no measured n")
            else:
                hold.append(f"{method}: n = {best} measured"
                            + (f", about {crossing:.0f} interpolated" if crossing else ""))
        steps = max(r.steps for r in self.costs)
        return [
            "### The cost of one physics step: gauss4s and gauss4 beside rk4",
            "",
            f"`Simulator.advance({sc.STEP:g})` called {steps} times, as the node calls it, on the spherical chain "
            "with a torque rotor on every body, under gravity; CPU time of the calling thread in each call "
            "(the method's own cost, whatever else the machine runs), after a warm-up call. "
            "The Gauss methods' own worst case in work: the most Newton iterations of a (sub)step and the most "
            "right-hand-side evaluations of a step (their caps bound them: gauss.py).",
            "",
            sc.table(self.costs),
            "",
            f"Largest n holding 1 kHz (median step within {sc.HOLD_FRACTION:g} of the 1 ms period): "
            + ("; ".join(hold) if hold else "not searched (quick mode)") + ".",
            "",
        ]

    def _tips_section(self) -> list[str]:
        from gyro_sim.bench import heavy_tips as ht

        if not self.tips:
            return []
        return [
            "### Heavy and light tips: accelerations against 80 digits",
            "",
            "`extreme.mass_ratio_chain(ratio)` at its initial state: the largest difference of the "
            "accelerations u', relative to the largest 80-digit acceleration, between the compiled "
            "(numba) kernel, the numpy reference (dense solve of the composite-inertia matrix) and the "
            "same equations in 80-digit arithmetic (the kernel run as Python on decimal numbers: "
            "`gyro_sim.bench.heavy_tips`, as test/dynamics/extended_precision.py).",
            "",
            ht.table(self.tips),
            "",
        ]


#: the report's parts (--parts)
PARTS = ("verdicts", "long", "sweep", "tips", "cost")
#: CPU budget (s) of one spin-sweep run: quick, full
SWEEP_BUDGET = (20.0, 600.0)


def build(quick: bool = False, keys=None, integrators=None, long_steps: int | None = None,
          progress=None, backend: str = "auto", mujoco: bool = True, sweep_steps: int | None = None,
          parts=PARTS) -> Report:
    cpu0, wall0 = time.process_time(), time.time()
    chosen = [it for it in items(quick) if keys is None or it.key in keys]
    total = sum(len(integrators or it.integrators) + (len(MUJOCO_ROWS) if mujoco else 0) for it in chosen)
    done = [0]

    def tick(run: Run) -> None:
        done[0] += 1
        if progress:
            progress(done[0], total, f"{run.item} {run.integrator}: {run.verdict}")

    results = [run_item(it, integrators, tick, backend, mujoco) for it in chosen] if "verdicts" in parts else []
    steps = long_steps if long_steps is not None else (10_000 if quick else 1_000_000)
    long_runs = long_horizon(steps, backend=backend) if steps > 0 and "long" in parts else []
    spin_runs = []
    s_steps = sweep_steps if sweep_steps is not None else (10_000 if quick else 1_000_000)
    if "sweep" in parts and s_steps > 0:
        from gyro_sim.bench import spin_sweep as ss

        methods = ss.METHODS if mujoco else ss.GYRO_METHODS
        spin_runs = ss.sweep(s_steps, SWEEP_BUDGET[0 if quick else 1], methods=methods, backend=backend,
                             progress=(lambda i, n, r: progress(i, n, f"spin sweep: {r.scene} {r.spin:g} {r.method}"))
                             if progress else None)
    tips = []
    if "tips" in parts:
        from gyro_sim.bench import heavy_tips as ht

        tips = ht.rows()
    costs, holding = [], {}
    if "cost" in parts:
        costs, holding = step_costs(quick, backend, progress)
    resolved = _default_backend() if backend == "auto" else backend
    return Report(results, long_runs, time.process_time() - cpu0, quick, resolved, spin_runs, s_steps, tips,
                  time.time() - wall0, costs, holding)


def step_costs(quick: bool, backend: str, progress=None):
    """The cost part: step_cost rows at its SIZES for its METHODS, and for each the largest
    n holding 1 kHz (measured by doubling n; not in quick mode)."""
    from gyro_sim.bench import step_cost as sc

    sizes, steps = (sc.QUICK_SIZES, sc.QUICK_STEPS) if quick else (sc.SIZES, sc.STEPS)
    rows, holding = [], {}
    total = len(sizes) * len(sc.METHODS)
    for n in sizes:
        for method in sc.METHODS:
            rows.append(sc.measure(n, method, steps, backend))
            if progress:
                progress(len(rows), total, f"step cost: n = {n} {method}")
    if not quick:
        for method in sc.METHODS:
            best, crossing, extra = sc.largest_holding(
                rows, method, steps, backend,
                (lambda r: progress(len(rows), total, f"step cost: n = {r.n} {r.method}")) if progress else None)
            rows.extend(extra)
            holding[method] = (best, crossing)
    return rows, holding


def to_json(report: Report) -> dict[str, Any]:
    return {
        "quick": report.quick,
        "cpu_total": report.cpu_total,
        "items": [{"key": r.item.key, "title": r.item.title, "horizon": r.item.horizon, "reference": r.reference,
                   "kapitza_margin": r.item.kapitza_margin, "predicted": r.predicted,
                   "runs": [asdict(x) for x in r.runs]} for r in report.results],
        "long_horizon": [asdict(r) for r in report.long_runs],
        "mujoco_skipped": {r.item.key: r.mujoco_skipped for r in report.results if r.mujoco_skipped},
        "spin_sweep": {"steps": report.sweep_steps, "runs": [asdict(r) for r in report.spin_runs]},
        "heavy_tips": [asdict(r) for r in report.tips],
        "step_cost": {"rows": [asdict(r) for r in report.costs],
                      "holding_1kHz": {k: {"largest_n_measured": v[0], "interpolated_n": v[1]}
                                       for k, v in report.holding.items()}},
        "wall": report.wall,
    }


def main(args) -> int:
    from gyro_sim.progress import Progress

    if refused(args, "stability"):
        return 2
    bar = Progress("stability")
    report = build(quick=args.quick, keys=args.cases, long_steps=args.long_steps, progress=bar,
                   backend=args.backend, mujoco=not args.no_mujoco, sweep_steps=args.sweep_steps,
                   parts=tuple(args.parts))
    text = report.markdown()
    print(text)
    write_report(args.out, "stability", text + "\n", to_json(report),
                 lambda png: plot(report.results, report.long_runs, png, report.spin_runs), force=args.force)
    return 0


def register(sub, bench) -> None:
    """`gyro-sim bench stability` (cli.PLUGINS)."""
    p = bench.add_parser("stability", help="stiff and extreme cases: a verdict per integrator")
    p.add_argument("--quick", action="store_true", help="short horizons, small budgets, 1e4 long steps (CI)")
    p.add_argument("--out", default="out/bench", help="directory for stability.md, stability.json, stability.png")
    add_force_option(p)
    p.add_argument("--cases", nargs="+", choices=[it.key for it in items()], help="a subset of the cases")
    p.add_argument("--long-steps", type=int, default=None,
                   help="steps of the long-horizon runs (default 1e6, quick 1e4; 0: skip)")
    p.add_argument("--backend", default="auto", choices=("auto", "numba", "numpy"),
                   help="the Simulator's dynamics backend (default auto: numba when it imports)")
    p.add_argument("--sweep-steps", type=int, default=None,
                   help="steps of each spin-sweep run (default 1e6, quick 1e4; 0: skip)")
    p.add_argument("--parts", nargs="+", choices=PARTS, default=list(PARTS),
                   help="the parts of the report to run (default all): verdicts, long (the long-horizon item), "
                        "sweep (spin sweep), tips (heavy-tip table), cost (gauss4s, gauss4 and rk4 per step at 1 kHz)")
    p.add_argument("--no-mujoco", action="store_true", help="no MuJoCo rows (verdicts and spin sweep)")
    p.set_defaults(fn=main)
