"""`gyro-sim bench scaling`: cost per dynamics evaluation and per simulated second vs chain length.

Each row times one evaluation of the chain dynamics (eqs 48, 52-54 solved for u') on a
spherical chain of n links with both backends (the numpy reference and the numba-compiled
articulated-body recursion), each called from Python as the integrators call it
(`system.rhs(t, y)`: a new array y'); beside it the compiled kernel's own time, one
evaluation inside compiled code (:func:`kernel_time`: a compiled loop calling
`gyro_sim.dynamics.kernel.rhs_kernel` k times, divided by k), so that the difference is the cost of
the call from Python; the cost of one simulated second with RK4 at 1 kHz (the node's
real-time configuration, default backend; timed after a first, untimed run of the same
advance, which compiles or loads the compiled loop); and, in the same run, Pinocchio's `aba`
on the same chain when the `pin` package is installed (C++ O(n) articulated-body algorithm,
called from Python), with the ratio of gyro_sim's evaluation from Python to it. Every
per-call time is the fastest of many batches of about a millisecond (:func:`best_time`), so
that on a busy machine some batches run undisturbed.

A second table (:func:`fixed_step`) puts the fixed-step loop beside MuJoCo: one simulated
second of RK4 at 1 kHz on a spherical chain with a rotor on every body, CPU seconds of
gyro_sim (one `advance(1 s)`, i.e. one compiled loop; and 1000 `advance(1 ms)` calls, the
node's pattern) against MuJoCo's `mj_step` with its RK4 at the same step on the same chain
(rotors as hinge bodies, gyro_sim.bench.peers), medians of `FIXED_STEP_REPEATS` runs (one
above MUJOCO_MAX_N), each simulator after an untimed warm-up run; with the growth exponent of
each method from n = 100 to 1000 (:func:`growth_exponents`).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gyro_sim.dynamics import kernel as fast
from gyro_sim.jit import njit_with_dependencies
from gyro_sim.dynamics.model import compile_model, initial_state
from gyro_sim.scene.load import load_scene
from gyro_sim.simulator import Simulator
from gyro_sim.dynamics.system import ChainODE, make_system
from gyro_sim.bench.scenes import spherical_chain, tree_of_links

DEFAULT_SIZES = (1, 2, 5, 10, 20, 50, 100)
QUICK_SIZES = (1, 2, 5)
RK4_STEP = 1e-3  # s: 1 kHz
#: chain lengths of the fixed-step comparison with MuJoCo (rotors on every body)
FIXED_STEP_SIZES = (10, 20, 50, 100, 200, 500, 1000)
#: MuJoCo beside it up to this n (its cost grows faster than O(n) on these chains: 8 s of CPU per
#: simulated second at n = 100 already)
MUJOCO_MAX_N = 100
#: the other fixed-step methods, in the node's 10 ms advances
OTHER_FIXED = ("lie4", "gauss4", "fixed")
QUICK_FIXED_STEP_SIZES = (10,)
#: runs per entry of that comparison (the median is reported)
FIXED_STEP_REPEATS = 5


@dataclass
class Row:
    n: int
    numpy_us: float
    eval_us: float  # default backend (numba when available)
    backend: str
    sim_second_s: float
    pin_aba_us: float | None
    kernel_us: float | None = None  # one evaluation inside compiled code (None on numpy)

    @property
    def ratio(self) -> float | None:
        return None if self.pin_aba_us is None else self.eval_us / self.pin_aba_us


def best_time(fn, min_time: float = 0.2, repeats: int = 5, batch_time: float = 1e-3) -> float:
    """Best per-call time (s): the fastest of batches of about `batch_time` seconds each, run
    for about `min_time` seconds in all (at least `repeats` batches). Short batches, so that on
    a busy machine some of them run undisturbed."""
    fn()
    number = 1
    while True:
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        dt = time.perf_counter() - t0
        if dt >= batch_time or number > 1_000_000:
            break
        number *= 2
    best, spent, batches = dt / number, dt, 1
    while spent < min_time or batches < repeats:
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        dt = time.perf_counter() - t0
        best, spent, batches = min(best, dt / number), spent + dt, batches + 1
    return best


@njit_with_dependencies(*fast.DEPENDENCIES, Path(__file__))
def _kernel_loop(k, t, y, ydot, args):
    """fast.rhs_kernel at (t, y) k times, inside compiled code."""
    for _ in range(k):
        fast.rhs_kernel(t, y, ydot, *args)


def kernel_time(system, y, min_time: float) -> float:
    """The compiled kernel's own time (s) for one evaluation of `system` (a FastChainODE) at
    (0, y): the best per-call time of a compiled loop of k evaluations, divided by k; k such
    that one loop takes ~0.2 ms (shorter than best_time's batches: a busy machine
    disturbs a long loop)."""
    ydot = np.empty(system.size)
    args = system.kernel_arguments()
    _kernel_loop(1, 0.0, y, ydot, args)  # compiled or loaded
    t0 = time.perf_counter()
    _kernel_loop(100, 0.0, y, ydot, args)
    k = max(1, int(2e-4 / max((time.perf_counter() - t0) / 100, 1e-9)))
    return best_time(lambda: _kernel_loop(k, 0.0, y, ydot, args), min_time) / k


def pin_aba_time(scene_dict: dict, min_time: float) -> float | None:
    """Per-call time of pinocchio.aba on the same chain, or None without pinocchio."""
    try:
        import pinocchio as pin
    except ImportError:
        return None
    model, data, q, v, tau = pin_chain(scene_dict)
    return best_time(lambda: pin.aba(model, data, q, v, tau), min_time)


def pin_chain(scene_dict: dict):
    """The spherical chain of `scenes.spherical_chain` in pinocchio, with a state to time it at:
    (model, data, q, v, tau). ImportError without pinocchio."""
    import pinocchio as pin

    model = pin.Model()
    parent = 0
    for k, b in enumerate(scene_dict["bodies"]):
        placement = pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.0 if k == 0 else 0.2]))
        parent = model.addJoint(parent, pin.JointModelSpherical(), placement, b["name"])
        m, c = b["mass"], np.array(b["com"])
        I_O = np.diag([b["inertia"]["transverse"]] * 2 + [b["inertia"]["axial"]])
        I_c = I_O - m * (c @ c * np.eye(3) - np.outer(c, c))
        model.appendBodyToJoint(parent, pin.Inertia(m, c, I_c), pin.SE3.Identity())
    model.gravity.linear = np.array([0.0, 0.0, -9.81])
    data = model.createData()
    q = pin.randomConfiguration(model, -np.ones(model.nq), np.ones(model.nq))
    v = np.random.default_rng(0).normal(size=model.nv)
    tau = np.zeros(model.nv)
    return model, data, q, v, tau


def measure(sizes=DEFAULT_SIZES, min_time: float = 0.3, progress=None) -> list[Row]:
    rows = []
    for i, n in enumerate(sizes):
        sd = spherical_chain(n)
        scene = load_scene(sd)
        model = compile_model(scene)
        y = initial_state(model)
        reference = ChainODE(model)
        t_numpy = best_time(lambda: reference.rhs(0.0, y), min_time)
        system = make_system(model, "auto")
        backend = "numpy" if isinstance(system, ChainODE) else "numba"
        t_eval, t_kernel = float("inf"), None
        for _ in range(2):  # interleaved, the best of each: a busy machine's slow spells hit both
            t_eval = min(t_eval, best_time(lambda: system.rhs(0.0, y), min_time / 2))
            if backend == "numba":
                k = kernel_time(system, y, min_time / 2)
                t_kernel = k if t_kernel is None else min(t_kernel, k)
        sim = Simulator(scene, integrator="rk4", step=RK4_STEP)
        span = max(RK4_STEP, min(1.0, 0.05 / (4 * t_eval * 1000)))  # about 50 ms of CPU
        span = round(span / RK4_STEP) * RK4_STEP
        sim.advance(span)  # untimed: compiles (or loads) the compiled loop
        sim.reset()
        t0 = time.process_time()
        sim.advance(span)
        sim_second = (time.process_time() - t0) / span
        pin_t = pin_aba_time(sd, min_time)
        rows.append(Row(n, t_numpy * 1e6, t_eval * 1e6, backend, sim_second, None if pin_t is None else pin_t * 1e6,
                        None if t_kernel is None else t_kernel * 1e6))
        if progress:
            progress(i + 1, len(sizes))
    return rows


@dataclass
class FixedStepRow:
    n: int
    one_call_s: float  # CPU s per simulated second: one advance(1 s)
    per_step_s: float  # CPU s per simulated second: advance(1 ms) x 1000
    mujoco_s: float | None  # mj_step RK4, same step, same chain
    mujoco_note: str = ""  # "unstable" when MuJoCo warned (bad accelerations) during the runs
    others: dict = field(default_factory=dict)  # CPU s per simulated second, 10 ms advances, by method

    def ratio(self, value: float) -> float | None:
        return None if self.mujoco_s is None else value / self.mujoco_s


def _median_cpu(fn, repeats: int, setup=None) -> float:
    """Median CPU time of `fn` over `repeats` runs, `setup` (untimed) before each."""
    out = []
    for _ in range(repeats):
        if setup is not None:
            setup()
        t0 = time.process_time()
        fn()
        out.append(time.process_time() - t0)
    return float(np.median(out))


def _warm_up(sim) -> None:
    """One untimed 10 ms advance, then back to the initial state: what a run does once
    (loading compiled code, first calls) out of the timed runs."""
    sim.advance(10 * RK4_STEP)
    sim.reset()


def growth_exponents(rows: list[FixedStepRow], lo: int = 100, hi: int = 1000) -> dict[str, float]:
    """Per method, the log-log slope of CPU per simulated second between the rows n = lo and
    n = hi (1: O(n), 2: O(n^2)); empty unless both rows were run."""
    by_n = {r.n: r for r in rows}
    if lo not in by_n or hi not in by_n:
        return {}
    a, b = by_n[lo], by_n[hi]
    pairs = {"rk4 one advance": (a.one_call_s, b.one_call_s),
             "rk4 per step": (a.per_step_s, b.per_step_s)}
    pairs.update({k: (a.others[k], b.others[k]) for k in a.others if k in b.others})
    return {k: float(np.log(y / x) / np.log(hi / lo)) for k, (x, y) in pairs.items()}


def fixed_step(sizes=FIXED_STEP_SIZES, seconds: float = 1.0, repeats: int = FIXED_STEP_REPEATS,
               progress=None) -> list[FixedStepRow]:
    """CPU seconds per simulated second of RK4 at 1 kHz, gyro_sim (numba) and MuJoCo mj_step
    (up to MUJOCO_MAX_N), and of the other fixed-step methods (OTHER_FIXED) in 10 ms advances.
    Every simulator first runs one untimed 10 ms advance (compiled code loaded, first-call
    work, the chooser's start-up check), then `seconds` simulated seconds per timed run, reset
    before each: the median of `repeats` runs, one run above n = MUJOCO_MAX_N."""
    rows = []
    for i, n in enumerate(sizes):
        scene = load_scene(spherical_chain(n, rotors=True))
        sim = Simulator(scene, integrator="rk4", step=RK4_STEP, backend="numba")
        big = n > MUJOCO_MAX_N
        seconds_n, repeats_n = seconds, (1 if big else repeats)
        steps = int(round(seconds_n / RK4_STEP))
        _warm_up(sim)

        # the reset back to the initial state before each run is not timed (MuJoCo's runs are
        # timed from a model made before them, too): it cost ~0.3 ms at n = 10, 5 % of the run
        def one_call():
            sim.advance(seconds_n)

        def per_step():
            for _ in range(steps):
                sim.advance(RK4_STEP)

        one = _median_cpu(one_call, repeats_n, sim.reset) / seconds_n
        per = _median_cpu(per_step, repeats_n, sim.reset) / seconds_n
        others = {}
        for name in OTHER_FIXED:
            other = Simulator(scene, integrator=name, step=RK4_STEP, backend="numba")
            _warm_up(other)

            def chunks(other=other):
                for _ in range(max(1, steps // 10)):
                    other.advance(10 * RK4_STEP)
            others[name] = _median_cpu(chunks, repeats_n, other.reset) / (max(1, steps // 10) * 10 * RK4_STEP)
        mj, note = None, ""
        try:
            import mujoco

            from gyro_sim.bench.peers import MujocoChain
        except ImportError:
            pass
        else:
            if not big:
                warned: list[str] = []
                chains = []

                def mujoco_run():
                    chain = MujocoChain(scene, RK4_STEP, "RK4")  # from the same initial state each run
                    chains.append(chain)
                    t0 = time.process_time()
                    chain.step(steps)
                    return time.process_time() - t0

                previous = mujoco.get_mju_user_warning()
                mujoco.set_mju_user_warning(warned.append)  # MuJoCo resets an unstable run and goes on
                try:
                    mj = float(np.median([mujoco_run() for _ in range(repeats)])) / seconds
                finally:
                    mujoco.set_mju_user_warning(previous)
                bad = int(mujoco.mjtWarning.mjWARN_BADQACC)
                if warned or any(c.d.warning[bad].number for c in chains):
                    note = "unstable"
        rows.append(FixedStepRow(n, one, per, mj, note, others))
        if progress:
            progress(i + 1, len(sizes))
    return rows


def fixed_step_table(rows: list[FixedStepRow]) -> str:
    names = [k for k in OTHER_FIXED if any(k in r.others for r in rows)]
    lines = [
        "| n (rotors on every body) | gyro_sim rk4, one advance (ms) | gyro_sim rk4, advance per step (ms) "
        "| MuJoCo mj_step RK4 (ms) | one advance / MuJoCo | per step / MuJoCo | rk4 per step and body (us) | "
        + " | ".join(f"{k}, 10 ms advances (ms)" for k in names) + " |",
        "|---:|---:|---:|---:|---:|---:|---:|" + "---:|" * len(names),
    ]
    for r in rows:
        if r.mujoco_s is None:
            mj = f"not run above n = {MUJOCO_MAX_N}" if r.n > MUJOCO_MAX_N else "n/a"
        else:
            mj = f"{r.mujoco_s * 1e3:.1f}" + (f" ({r.mujoco_note})" if r.mujoco_note else "")
        a, b = r.ratio(r.one_call_s), r.ratio(r.per_step_s)
        lines.append(f"| {r.n} | {r.one_call_s * 1e3:.1f} | {r.per_step_s * 1e3:.1f} | {mj} | "
                     f"{'n/a' if a is None else f'{a:.2f}x'} | {'n/a' if b is None else f'{b:.2f}x'} | "
                     f"{r.one_call_s * 1e3 / r.n:.2f} | "
                     + " | ".join(f"{r.others[k] * 1e3:.1f}" if k in r.others else "" for k in names) + " |")
    slopes = growth_exponents(rows)
    if slopes:
        lines.append("\nGrowth exponent from n = 100 to 1000 (log-log slope of the CPU per simulated "
                     "second; 1 is O(n)): " + ", ".join(f"{k} {v:.2f}" for k, v in slopes.items()))
    return "\n".join(lines)


#: sizes of the trees' table (`trees`)
TREE_SIZES = (10, 30, 100, 300)
QUICK_TREE_SIZES = (10,)


def trees(sizes=TREE_SIZES, min_time: float = 0.3) -> list[tuple[int, float, float, float]]:
    """(n, chain, binary tree, hub with n - 1 bodies): the compiled kernel's own time (us) of one
    evaluation (`kernel_time`) on n spherical links hung as each (`tree_of_links`)."""
    rows = []
    for n in sizes:
        times = []
        for branching in (1, 2, n):
            model = compile_model(load_scene(tree_of_links(n, branching)))
            times.append(kernel_time(make_system(model, "numba"), initial_state(model), min_time) * 1e6)
        rows.append((n, *times))
    return rows


def trees_table(rows) -> str:
    lines = ["| n | chain (us) | binary tree (us) | hub with n - 1 bodies (us) | tree / chain |",
             "|---:|---:|---:|---:|---:|"]
    for n, chain, binary, hub in rows:
        lines.append(f"| {n} | {chain:.2f} | {binary:.2f} | {hub:.2f} | {max(binary, hub) / chain:.2f} |")
    return "\n".join(lines)


def table(rows: list[Row]) -> str:
    backend = rows[0].backend if rows else "numba"
    lines = [
        f"| n | numpy, one evaluation (us) | {backend}, one evaluation from Python (us) "
        f"| {backend} kernel's own time, in compiled code (us) | one simulated second, RK4 1 kHz (s) "
        f"| pinocchio aba (us) | {backend} / aba |",
        "|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        pin_s = "n/a" if r.pin_aba_us is None else f"{r.pin_aba_us:.2f}"
        ratio = "n/a" if r.ratio is None else f"{r.ratio:.2f}x"
        kernel = "n/a" if r.kernel_us is None else f"{r.kernel_us:.2f}"
        lines.append(f"| {r.n} | {r.numpy_us:.1f} | {r.eval_us:.2f} | {kernel} | {r.sim_second_s:.3f} | {pin_s} "
                     f"| {ratio} |")
    if len(rows) >= 2:
        a, b = rows[-2], rows[-1]
        slope = np.log(b.eval_us / a.eval_us) / np.log(b.n / a.n)
        lines.append("")
        lines.append(f"Growth of one {a.backend} evaluation between n = {a.n} and {b.n}: O(n^{slope:.2f}).")
    return "\n".join(lines)


def plot(rows: list[Row], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = [r.n for r in rows]
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.loglog(n, [r.numpy_us for r in rows], "o-", label="gyro_sim numpy reference")
    ax.loglog(n, [r.eval_us for r in rows], "^-", label=f"gyro_sim {rows[0].backend}")
    if all(r.pin_aba_us is not None for r in rows):
        ax.loglog(n, [r.pin_aba_us for r in rows], "s--", label="pinocchio aba")
    ax.set_xlabel("chain length n (spherical joints)")
    ax.set_ylabel("time per evaluation (us)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


FEATURE_N = 10


def features(quick: bool = False) -> list[tuple[str, float, float]]:
    """Evaluation time of a scene without a feature vs with the feature present but zero."""
    min_time = 0.05 if quick else 0.3
    out = []
    cases = [
        ("gravity", spherical_chain(FEATURE_N, gravity=False),
         _zero_gravity(spherical_chain(FEATURE_N, gravity=False))),
        ("rotors", spherical_chain(FEATURE_N), _zero_rotors(spherical_chain(FEATURE_N))),
    ]
    for name, without, with_zero in cases:
        times = []
        for sd in (without, with_zero):
            model = compile_model(load_scene(sd))
            system = ChainODE(model)  # the numpy reference: its cost follows the terms present
            y = initial_state(model)
            times.append(best_time(lambda: system.rhs(0.0, y), min_time) * 1e6)
        out.append((name, times[0], times[1]))
    return out


def _zero_gravity(sd: dict) -> dict:
    sd["gravity"] = [0.0, 0.0, 0.0]
    return sd


def _zero_rotors(sd: dict) -> dict:
    zero = spherical_chain(FEATURE_N, zero_features=True)
    for b, bz in zip(sd["bodies"], zero["bodies"]):
        b["rotors"] = bz["rotors"]
    return sd


def features_table(rows) -> str:
    lines = [
        f"| feature (n = {FEATURE_N}, numpy reference) | without (us) | present but zero (us) | saved |",
        "|---|---:|---:|---:|",
    ]
    for name, t0, t1 in rows:
        lines.append(f"| {name} | {t0:.1f} | {t1:.1f} | {100 * (1 - t0 / t1):.0f} % |")
    return "\n".join(lines)


# --- memory: long chains, every integrator --------------------------------------------------------
MEMORY_SIZES = (1000, 5000)
QUICK_MEMORY_SIZES = (300,)
MEMORY_INTEGRATORS = ("rk4", "lie4", "gauss4", "gauss4s", "fixed", "dop853", "radau", "auto")
QUICK_MEMORY_INTEGRATORS = ("rk4", "radau")
MEMORY_SECONDS = 0.1
#: wall seconds a run may take before it counts as too slow
MEMORY_TIMEOUT = 900.0
_MEMORY_RUN = r"""
import json, resource, sys, time
from gyro_sim.bench.scenes import spherical_chain
from gyro_sim.simulator import Simulator
n, name, seconds = int(sys.argv[1]), sys.argv[2], float(sys.argv[3])
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
sim = Simulator(spherical_chain(n), integrator=name, step=1e-3, rtol=1e-8, atol=1e-10)
built = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t = time.process_time()
sim.advance(seconds)
i = sim.integrator
print(json.dumps({"size": i.n, "built_mb": built / 1024,
                  "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "cpu_s": time.process_time() - t, "steps": i.nsteps, "nfev": i.nfev}))
"""


@dataclass
class MemoryRow:
    n: int
    integrator: str
    size: int = 0
    built_mb: float = float("nan")  # peak RSS after building the Simulator (MB)
    peak_mb: float = float("nan")  # peak RSS after the run (MB)
    cpu_s: float = float("nan")
    steps: int = 0
    failed: str = ""


def memory(sizes=MEMORY_SIZES, integrators=MEMORY_INTEGRATORS, seconds: float = MEMORY_SECONDS,
           progress=None) -> list[MemoryRow]:
    """Peak resident memory (ru_maxrss) of a `seconds` run of a spherical chain of n bodies with
    gravity, each integrator in a process of its own (fixed steps 1 ms, adaptive rtol 1e-8)."""
    import json
    import subprocess
    import sys

    rows, total = [], len(sizes) * len(integrators)
    for n in sizes:
        for name in integrators:
            row = MemoryRow(n, name)
            try:
                out = subprocess.run([sys.executable, "-c", _MEMORY_RUN, str(n), name, repr(seconds)],
                                     capture_output=True, text=True, timeout=MEMORY_TIMEOUT)
                if out.returncode == 0:
                    for k, v in json.loads(out.stdout.strip().splitlines()[-1]).items():
                        setattr(row, k, v)
                else:
                    row.failed = (out.stderr.strip().splitlines() or ["exit %d" % out.returncode])[-1][:120]
            except subprocess.TimeoutExpired:
                row.failed = f"over {MEMORY_TIMEOUT:g} s"
            rows.append(row)
            if progress:
                progress(len(rows), total, f"n = {n} {name}: {row.peak_mb:.0f} MB")
    return rows


def memory_table(rows: list[MemoryRow]) -> str:
    lines = ["| n (states) | integrator | peak RSS (MB) | of which the model and kernels (MB) | CPU (s) | steps |",
             "|---:|---|---:|---:|---:|---:|"]
    for r in rows:
        if r.failed:
            lines.append(f"| {r.n} | {r.integrator} | failed: {r.failed} | | | |")
        else:
            lines.append(f"| {r.n} ({r.size}) | {r.integrator} | {r.peak_mb:.0f} | {r.built_mb:.0f} | {r.cpu_s:.1f} "
                         f"| {r.steps} |")
    return "\n".join(lines)
