"""DOP853's compiled advance (gyro_sim.integrators.dop853.loop) and its Python driver (both on the
arithmetic of gyro_sim.integrators.dop853.kernels) against independent references: scipy's
`scipy.integrate.DOP853` on the same right-hand side and tolerances, and each other.

How close to scipy, and why:

- scipy forms its sums (stage states, the step, the error estimates, the dense coefficients)
  with BLAS dot products, whose order of summation and fused multiply-adds are the
  library's; the kernels add one product at a time in increasing order. Where no sum is
  involved the operations are scipy's, in scipy's order: the dense output evaluated from the
  same coefficients is scipy's bit for bit.
- A step of a given size: the same result to a few ulps (SAME_STEP_RTOL after many steps).
- The error norm sums E5_j K_j over stages that agree to O(h): the sum cancels to the local
  error, ~1e-9 of |K| at rtol 1e-9, so its relative round-off is ~1e-16 / 1e-9 and
  h_new ~ err^(-1/8) inherits an eighth of it: the accepted step sequence is scipy's (the
  same steps accepted and rejected) with times that agree to STEP_TIME_RTOL, and the states
  at those times agree to round-off (STATE_RTOL) once the time offset is accounted for
  (y(t + dt) = y(t) + f dt + O(dt^2), dt ~ 1e-11). With the step size pinned by max_step
  the times are scipy's bit for bit and the states agree to round-off directly.

Reached here (scipy 1.17, OpenBLAS): 145 steps (40 rejected) at rtol 1e-9 of a chaotic
pendulum, step times within 7e-10 relative, states within 2e-12 of max |y| once shifted; 41
pinned steps: the final state within 8 ulps of max |y|, the dense output within 1.3e-15.
The bounds below leave ~10-100x for other BLAS builds.

The compiled loop and the Python driver run the same kernels between the same rhs
evaluations: identical bits, counters included (and so are two runs of either).
"""
import glob
import math
import os

import numpy as np
import pytest

from gyro_sim.integrators.dop853 import kernels as dk
from gyro_sim.dynamics import kernel as fast
from gyro_sim.integrators.dop853 import loop as fast_dop853
from gyro_sim import jit
from gyro_sim.integrators import IntegrationError
from gyro_sim.integrators.dop853.driver import DOP853
from gyro_sim.dynamics.model import compile_model, initial_state
from gyro_sim.scene.load import load_scene
from gyro_sim.simulator import Simulator
from gyro_sim.dynamics.system import FastChainODE
from test.core.package_paths import in_package

from .chains import random_chain

pytestmark = pytest.mark.skipif(not fast.available(), reason="numba is not installed")

#: a step of the same size as scipy's, after up to ~100 steps of a chaotic pendulum
SAME_STEP_RTOL = 1e-13
#: accepted step times against scipy's (the error norm's cancellation, see the docstring)
STEP_TIME_RTOL = 1e-8
#: states against scipy's at the same step, corrected for the time offset, relative to max |y|
STATE_RTOL = 1e-11
#: dense output against scipy's on the same steps, relative to max |y|
DENSE_RTOL = 1e-13
SCENES = sorted(os.path.basename(p)[:-5] for p in glob.glob(
    os.path.join(os.path.dirname(__file__), "..", "..", "config", "*.yaml")) if not p.endswith("params.yaml"))


def hinge_pendulum() -> dict:
    """Three hinges with non-parallel axes and an actuated wheel: no quaternion in the state
    (nothing projected, as in scipy), chaotic enough to have rejected steps."""
    def body(name, axis, angle, rate, last=False):
        b = {"name": name, "joint": {"type": "hinge", "axis": axis}, "mass": 0.4,
             "com": [0.02, 0.01, 0.08],
             "inertia_com": [[3e-3, 1e-4, 0.0], [1e-4, 2.5e-3, 2e-4], [0.0, 2e-4, 1.2e-3]],
             "initial": {"angle": angle, "rate": rate}}
        if not last:
            b["next_joint"] = [0.0, 0.0, 0.16]
        return b

    bodies = [body("a", [1, 0, 0], 2.0, 0.5), body("b", [0, 1, 0.2], -0.7, 1.0),
              body("c", [1, 0, 0.5], 0.4, -2.0, last=True)]
    bodies[1]["rotors"] = [{"name": "wheel", "axis": [0.3, 0.0, 1.0], "position": [0.0, 0.0, 0.1],
                            "mass": 0.1, "axial_inertia": 4.5e-5, "transverse_inertia": 2.4e-5,
                            "mode": "torque", "spin": 80.0, "actuated": True}]
    return {"name": "hinge pendulum", "gravity": [0.0, 0.0, -9.81], "base": {"type": "fixed"},
            "bodies": bodies}


def held_system(scene, seed=0):
    """FastChainODE of `scene` with random held inputs, and a perturbed initial state."""
    model = compile_model(load_scene(scene))
    system = FastChainODE(model)
    rng = np.random.default_rng(seed)
    nt, nh = len(model.torque_body), len(model.hinge_bodies)
    system.hold(0.1, rng.uniform(-50, 50, nt) if nt else None,
                rng.normal(size=nh) * 0.05 if nh else None, rng.normal(size=nt) * 1e-3 if nt else None)
    y = initial_state(model)
    y[model.i_vel] += rng.normal(size=model.N) * 0.3
    return system, y


def python_driver(system, **options) -> DOP853:
    """DOP853 stepping in Python on a system that has the compiled loop."""
    integ = DOP853(system, **options)
    integ._loop = None  # noqa: SLF001 - the Python driver on the same system
    return integ


def counters(integ):
    return (integ.nfev, integ.nsteps, integ.nrejected, integ.error_estimate, integ.last_step,
            integ._h_abs)  # noqa: SLF001


def scipy_run(system, y0, t0, t1, rtol, atol, dense=False, **options):
    """scipy's DOP853 stepped to t1: its solver, the accepted times, states and, if `dense`,
    interpolants (3 more rhs evaluations a step)."""
    si = pytest.importorskip("scipy.integrate")
    ref = si.DOP853(system.rhs, t0, y0, t1, rtol=rtol, atol=atol, **options)
    ts, ys, interpolants = [], [], []
    while ref.status == "running":
        assert ref.step() is None
        ts.append(ref.t)
        ys.append(ref.y.copy())
        if dense:
            interpolants.append(ref.dense_output())
    assert ref.status == "finished"
    return ref, np.array(ts), np.array(ys), interpolants


# ------------------------------------------------------------------ against scipy
def test_initial_step_is_scipys():
    """The first step (HNW I, sec. II.4) as scipy selects it, to round-off (its norms are
    BLAS dot products)."""
    si = pytest.importorskip("scipy.integrate")
    system, y0 = held_system(hinge_pendulum())
    integ = DOP853(system, rtol=1e-9, atol=1e-11)
    integ.begin(0.1, y0.copy(), 3.0)
    ref = si.DOP853(system.rhs, 0.1, y0, 3.0, rtol=1e-9, atol=1e-11)
    assert integ._h_abs == pytest.approx(ref.h_abs, rel=1e-14)  # noqa: SLF001


@pytest.mark.parametrize("compiled", (False, True))
def test_accepted_steps_are_scipys(compiled):
    """From the same first step: scipy's steps (the same number accepted and tried), at
    times equal to STEP_TIME_RTOL, states equal to round-off at those times."""
    rtol, atol, t0, t1 = 1e-9, 1e-11, 0.1, 3.1
    system, y0 = held_system(hinge_pendulum())
    assert system.quaternion_block()[1] == 0  # nothing projected: scipy's problem exactly
    integ = DOP853(system, rtol=rtol, atol=atol) if compiled else python_driver(system, rtol=rtol, atol=atol)
    integ.begin(t0, y0.copy(), t1)  # the first step, here, to hand to scipy
    h0 = integ._h_abs  # noqa: SLF001
    integ.reset()
    ref, ts_ref, ys_ref, _ = scipy_run(system, y0, t0, t1, rtol, atol, first_step=h0)
    if compiled:
        integ._trace = np.zeros(len(ts_ref) + 5)  # noqa: SLF001 - the ends of the steps
        ys = integ.advance(t0, y0, t1)[None, :]
        ts = integ._trace[:integ._status[fast_dop853.S_TRACED]]  # noqa: SLF001
    else:
        y, ts, ys, t = y0.copy(), [], [], t0
        integ.begin(t0, y, t1)
        while t < t1:
            t = integ.take_step(t, y, t1)
            ts.append(t)
            ys.append(y.copy())
        ts, ys = np.array(ts), np.array(ys)
    # the same steps: as many accepted, as many tried (scipy: 12 rhs a trial, 1 at the start)
    assert integ.nsteps == len(ts) == len(ts_ref) > 50
    assert integ.nsteps + integ.nrejected == (ref.nfev - 1) // 12 and integ.nrejected > 5
    np.testing.assert_allclose(ts, ts_ref, rtol=STEP_TIME_RTOL, atol=0)
    assert ts[-1] == ts_ref[-1] == t1
    if compiled:  # the same time t1 at the end: no offset to correct
        assert np.abs(ys[-1] - ys_ref[-1]).max() <= STATE_RTOL * np.abs(ys_ref).max()
        return
    scale = np.abs(ys_ref).max()
    for k in range(len(ts)):  # y(t) = y_ref(t_ref) + f (t - t_ref) + O((t - t_ref)^2)
        f = system.rhs(ts_ref[k], ys_ref[k])
        shifted = ys_ref[k] + f * (ts[k] - ts_ref[k])
        assert np.abs(ys[k] - shifted).max() <= STATE_RTOL * scale, k


@pytest.mark.parametrize("compiled", (False, True))
def test_pinned_steps_and_dense_output_are_scipys(compiled):
    """Steps pinned by max_step (always accepted): scipy's times bit for bit, its states to
    round-off; the dense output at requested times is scipy's interpolant on the same steps."""
    rtol, atol, h, t0 = 1e-6, 1e-8, 0.01, 0.1
    t1 = t0 + 40.5 * h  # the last step is half a step: no stretch (ours) nor sliver (scipy)
    system, y0 = held_system(hinge_pendulum(), seed=1)
    ref, ts_ref, ys_ref, dense = scipy_run(system, y0, t0, t1, rtol, atol, dense=True, first_step=h, max_step=h)
    te = np.sort(np.concatenate([np.linspace(t0, t1, 97), ts_ref[:-1]]))
    integ = DOP853(system, rtol=rtol, atol=atol, max_step=h) if compiled else \
        python_driver(system, rtol=rtol, atol=atol, max_step=h)
    integ._h_abs = h  # noqa: SLF001 - scipy's first step
    n_steps = len(ts_ref)
    if compiled:
        integ._trace = np.zeros(n_steps)  # noqa: SLF001
    y1, Y = integ.advance(t0, y0, t1, t_eval=te)
    assert integ.nsteps == n_steps and integ.nrejected == 0
    if compiled:
        np.testing.assert_array_equal(integ._trace, ts_ref)  # noqa: SLF001
    scale = np.abs(ys_ref).max()
    assert np.abs(y1 - ys_ref[-1]).max() <= SAME_STEP_RTOL * scale
    starts = np.concatenate([[t0], ts_ref])
    for j, t in enumerate(te):
        k = np.searchsorted(ts_ref, t)  # the step that holds t: (starts[k], ts_ref[k]]
        if t in ts_ref or t == t0:  # a step's end: the state itself
            want = y0 if t == t0 else ys_ref[k]
        else:
            assert starts[k] < t < ts_ref[k]
            want = dense[k](t)
        assert np.abs(Y[j] - want).max() <= DENSE_RTOL * scale, (j, t)


def test_dense_evaluation_is_scipys_bit_for_bit():
    """From the same coefficients, the dense output is scipy's Dop853DenseOutput's: the same
    operations in the same order (HNW I, sec. II.6)."""
    rk = pytest.importorskip("scipy.integrate._ivp.rk")
    rng = np.random.default_rng(4)
    F, y_old = rng.normal(size=(7, 9)), rng.normal(size=9)
    t_old, t_new = 0.37, 0.37 + 0.0123
    tq = np.sort(rng.uniform(t_old, t_new, 13))
    Y = np.empty((13, 9))
    dk.dop_dense_eval(F, y_old, t_old, t_new - t_old, tq, Y)
    np.testing.assert_array_equal(Y, rk.Dop853DenseOutput(t_old, t_new, y_old, F)(tq).T)


def test_step_and_error_norm_are_scipys():
    """One step of the kernels against scipy's rk_step and DOP853._estimate_error_norm from the
    same state and step: the state to round-off, the error norm to its cancellation (here
    e5 ~ 1e-9 |K|: ~1e-8 relative)."""
    rk = pytest.importorskip("scipy.integrate._ivp.rk")
    system, y = held_system(hinge_pendulum(), seed=2)
    rtol, atol, t, h = 1e-9, 1e-11, 0.1, 0.02
    f = system.rhs(t, y)
    K = np.zeros((16, y.size))
    K[0] = f
    ys, y_new = np.empty(y.size), np.empty(y.size)
    for s in range(1, 12):
        dk.dop_stage_state(y, K, DOP853.A_ALL, s, h, ys)
        K[s] = system.rhs(t + DOP853.C_ALL[s] * h, ys)
    dk.dop_update(y, K, DOP853.B, h, y_new)
    err = dk.dop_error_norm(K, DOP853.E5, DOP853.E3, h, y, y_new, rtol, np.full(y.size, atol))
    K_ref = np.empty((13, y.size))
    y_ref, f_ref = rk.rk_step(system.rhs, t, y, f, h, DOP853.A, DOP853.B, DOP853.C, K_ref)
    np.testing.assert_allclose(K[:12], K_ref[:12], rtol=1e-13, atol=1e-13)
    assert np.abs(y_new - y_ref).max() <= 4 * np.finfo(float).eps * np.abs(y_ref).max()
    scale = atol + np.maximum(np.abs(y), np.abs(y_ref)) * rtol
    solver = rk.DOP853(system.rhs, t, y, t + 1.0, rtol=rtol, atol=atol)
    err_ref = solver._estimate_error_norm(K_ref, h, scale)  # noqa: SLF001
    assert err == pytest.approx(err_ref, rel=1e-6) and err > 1e-3


# ------------------------------------------------------------------ compiled == Python driver
@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("base", ("fixed", "free"))
def test_compiled_advance_is_the_python_driver_bit_for_bit(seed, base):
    """10 ms calls with output times: the same bits, the same counters, the same memory
    (a scalar atol with a fixed base, one per component with a free one)."""
    system, y0 = held_system(random_chain(seed, base=base), seed)
    kw = dict(rtol=1e-8, atol=1e-10 if base == "fixed" else np.geomspace(1e-11, 1e-9, system.size))
    compiled, python = DOP853(system, **kw), python_driver(system, **kw)
    assert compiled._loop is not None  # noqa: SLF001
    ya, yb = y0.copy(), y0.copy()
    for k in range(6):
        t0, t1 = 0.1 + 0.01 * k, 0.1 + 0.01 * (k + 1)
        te = np.linspace(t0, t1, 4)[1:] if k % 2 else None
        ra, rb = compiled.advance(t0, ya, t1, t_eval=te), python.advance(t0, yb, t1, t_eval=te)
        if te is not None:
            (ya, Ya), (yb, Yb) = ra, rb
            np.testing.assert_array_equal(Ya, Yb)
        else:
            ya, yb = ra, rb
        np.testing.assert_array_equal(ya, yb)
        assert counters(compiled) == counters(python)
    assert not np.array_equal(ya, y0)


@pytest.mark.parametrize("scene", SCENES)
def test_every_scene_compiled_equals_python_driver(scene):
    """Every shipped scene, 0.5 s in 10 ms calls of Simulator.advance: the same state, bit
    for bit (quaternions projected after every step, held inputs, moving bases, rotors)."""
    states = []
    for compiled in (True, False):
        sim = Simulator(load_scene(scene), integrator="dop853", rtol=1e-8, atol=1e-10, backend="numba")
        if not compiled:
            sim.integrator._loop = None  # noqa: SLF001
        for _ in range(50):
            sim.advance(0.01)
        states.append((sim.state.copy(), counters(sim.integrator)))
    np.testing.assert_array_equal(states[0][0], states[1][0])
    assert states[0][1] == states[1][1]


@pytest.mark.parametrize("scene", ("hinge_chain", "free_chain_rotors", "vibrating_base"))
def test_python_driver_on_the_numpy_reference_agrees(scene):
    """The Python driver on the numpy reference (ChainODE: another implementation of the rhs,
    equal to round-off) and the compiled loop: the same steps, the state after 0.5 s equal to
    round-off as the error control amplifies it (1e-15 to 3e-11 on the shipped scenes)."""
    runs = []
    for backend in ("numba", "numpy"):
        sim = Simulator(load_scene(scene), integrator="dop853", rtol=1e-8, atol=1e-10, backend=backend)
        for _ in range(50):
            sim.advance(0.01)
        runs.append((sim.state.copy(), sim.integrator.nsteps, sim.integrator.nrejected))
    (a, na, ra), (b, nb, rb) = runs
    assert (na, ra) == (nb, rb)
    assert np.abs(a - b).max() <= 1e-10 * np.abs(a).max()


def test_two_runs_are_identical():
    """Determinism (logs are re-simulated): fresh integrators, and after a reset."""
    system, y0 = held_system("chain_4", seed=3)
    te = np.linspace(0.1, 0.4, 31)[::3]  # not contiguous
    runs = []
    for _ in range(2):
        integ = DOP853(system, rtol=1e-9, atol=1e-11)
        runs.append(integ.advance(0.1, y0, 0.4, t_eval=te))
        integ.reset()
        runs.append(integ.advance(0.1, y0, 0.4, t_eval=te))
    for y, Y in runs[1:]:
        np.testing.assert_array_equal(y, runs[0][0])
        np.testing.assert_array_equal(Y, runs[0][1])
    assert np.abs(np.linalg.norm(runs[0][1][:, system.model.i_quat], axis=-1) - 1).max() < 1e-15


def test_a_recorded_dop853_run_resimulates_bit_for_bit(tmp_path):
    """A log recorded with dop853 (compiled) and commands, re-simulated: deviation 0."""
    pytest.importorskip("mcap")
    from gyro_sim.log.record import record_run
    from gyro_sim.log.resim import resimulate

    sim = Simulator(load_scene("hinge_chain"), integrator="dop853", backend="numba")
    schedule = [(0.0, [0.001, 0.0, 0.0]), (0.05, [0.0, 0.02, -0.01])]
    rec = record_run(sim, tmp_path / "run.mcap", duration=0.1, chunk=0.005, publish_rate=100.0,
                     schedule=schedule)
    res = resimulate(tmp_path / "run.mcap")
    assert res.compared == rec.publications > 5 and res.max_deviation == 0.0, res.report()


def test_stiffness_estimate_steps_in_python_with_the_same_bits():
    """The "auto" method's DOP853 (stiffness_estimate) steps in Python: same steps and bits."""
    system, y0 = held_system("fast_rotor", seed=5)
    a = DOP853(system, rtol=1e-8, atol=1e-10)
    b = DOP853(system, rtol=1e-8, atol=1e-10, stiffness_estimate=True)
    np.testing.assert_array_equal(a.advance(0.1, y0, 0.3), b.advance(0.1, y0, 0.3))
    assert counters(a) == counters(b) and b.hlamb is None and a.hlamb is None


# ------------------------------------------------------------------ failures
def _failure(integ, y0, t1, h=None):
    """The IntegrationError of advance from (0.1, y0) to t1 (h: the step-size memory of an
    earlier call; None: the first call selects it) and the counters after it."""
    integ._h_abs = h  # noqa: SLF001
    with pytest.raises(IntegrationError) as info:
        integ.advance(0.1, y0, t1)
    return str(info.value), info.value.t, info.value.h, counters(integ)


@pytest.mark.parametrize("scene, speed", [("chain_4", 1e150), ("heavy_top", 1e30)])
def test_collapse_reports_the_non_finite_stages_as_in_python(scene, speed):
    """A state whose stages overflow: the step keeps failing with non-finite trials until its
    size collapses; the same error (message naming the stages, time, step) and counters from
    both drivers."""
    system, y0 = held_system(scene)
    y0[system.model.i_vel.start] = speed  # finite rhs at y0, overflow in the stages
    got = _failure(DOP853(system, rtol=1e-6, atol=1e-8), y0, 0.2, h=1e-3)
    assert got == _failure(python_driver(system, rtol=1e-6, atol=1e-8), y0, 0.2, h=1e-3)
    assert "step size collapsed" in got[0] and "non-finite stages" in got[0]


def test_non_finite_initial_rhs_fails_as_in_python():
    system, y0 = held_system("chain_4")
    y0[system.model.i_vel.start] = 1e200  # squares overflow: rhs(t0, y0) is not finite
    got = _failure(DOP853(system), y0, 0.2)
    assert got == _failure(python_driver(system), y0, 0.2)
    assert "rhs is not finite at the initial state" in got[0]


# ------------------------------------------------------------------ the loop's cache


def test_loop_cache_is_keyed_on_every_file_it_compiles_in():
    names = {in_package(p) for p in fast_dop853.DEPENDENCIES}
    assert names == {"dynamics/kernel.py", "dynamics/actuators.py", "integrators/dop853/kernels.py",
                     "integrators/adaptive_kernels.py", "integrators/dop853/loop.py"}
    assert jit.cache_directory(fast_dop853.DEPENDENCIES).name.startswith("fast_loop-")


def test_one_compiled_loop_per_process_and_argument_types():
    """New integrators (new Simulators) share the entry point of the first call: numba's type
    dispatch is paid once per process; other argument types get a loop of their own."""
    a, _ = held_system("chain_4")
    b, _ = held_system("heavy_top", seed=1)
    loop = DOP853(a)._loop  # noqa: SLF001
    assert DOP853(b)._loop is loop and fast_dop853.loop_for(b.kernel_arguments()) is loop  # noqa: SLF001
    model, data, inputs = a.kernel_arguments()
    work = data.work.copy()
    work.flags.writeable = False  # another type of one array of a record
    assert fast_dop853.loop_for((model, data._replace(work=work), inputs)) is not loop


def test_controller_constants_are_the_bases():
    from gyro_sim.integrators import base

    assert DOP853.CONTROL.tolist() == [base.SAFETY, base.MIN_FACTOR, base.MAX_FACTOR, -1.0 / 8,
                                       base.MIN_STEP_RELATIVE, base.LAST_STEP_STRETCH]
    assert math.isclose(DOP853.CONTROL[3], -1.0 / (DOP853.error_estimator_order + 1))
    assert DOP853.INITIAL.tolist() == [base.H0_NEGLIGIBLE, base.H0_DEFAULT, base.H0_FRACTION,
                                       base.H0_GROWTH, base.H0_TINY_DERIVATIVES,
                                       base.H0_TINY_STEP, base.H0_TINY_FRACTION]
    assert fast_dop853.ORDER_OF_ESTIMATOR == DOP853.error_estimator_order
