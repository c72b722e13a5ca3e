"""FastChainODE.rhs through gyro_sim.dynamics.entry (a workspace's descriptor, four arguments a
call) against the kernel called directly with the records of `fast.records` (bit for bit: same
kernel, same arrays) and against the numpy reference ChainODE.rhs (round-off), before and after
holds of new inputs.
"""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from gyro_sim import load_scene
from gyro_sim.bench.scenes import spherical_chain
from gyro_sim.dynamics import reference as dyn
from gyro_sim.dynamics import kernel as fast, entry as fast_entry
from gyro_sim.dynamics.model import compile_model, initial_state
from gyro_sim.dynamics.system import ChainODE, FastChainODE
from gyro_sim.integrators.rk4.loop import ErkMarch

from test.dynamics.chains import random_chain
from test.dynamics.test_kernel import BASES, assert_rhs_equal, chain_scene, random_state

pytestmark = pytest.mark.skipif(not fast.available(), reason="numba is not installed")

SEEDS = range(8)


def bound(model, held) -> tuple:
    """(model, data, inputs) of `model` as the kernel takes them, these inputs held."""
    chain, data, inputs = fast.records(model)
    fast.hold(inputs, model, *held)
    return chain, data, inputs


def direct(model, t, y, held) -> np.ndarray:
    """fast.rhs_kernel called directly with the records of the model and the held inputs."""
    ydot = np.empty(model.size)
    fast.rhs_kernel(float(t), y, ydot, *bound(model, held))
    return ydot


def random_hold(rng, model) -> tuple:
    """(t0, p0, hinge_tau, L_rotor) at random, None where the model has no such input."""
    nt, nh = len(model.torque_body), len(model.hinge_bodies)
    return (float(rng.uniform(-1.0, 1.0)), rng.uniform(-50.0, 50.0, nt) if nt else None,
            rng.normal(size=nh) if nh else None, rng.normal(size=nt) * 1e-2 if nt else None)


def check_case(model, rng, holds: int = 3) -> None:
    """Fresh inputs, then `holds` random holds and finally a hold of no commands: at each, two
    states, FastChainODE.rhs bit for bit the direct kernel and to round-off the reference."""
    ref, fst = ChainODE(model), FastChainODE(model)
    held = (0.0, model.torque_p0 if len(model.torque_body) else None, None, None)
    nt = len(model.torque_body)
    sequence = [None] + [random_hold(rng, model) for _ in range(holds)]
    sequence.append((0.5, rng.uniform(-50.0, 50.0, nt) if nt else None, None, None))
    for h in sequence:
        if h is not None:
            held = h
            ref.hold(*h)
            fst.hold(*h)
        for i in range(2):
            t = float(rng.uniform(-1.0, 1.0))
            y = random_state(rng, model) if i else initial_state(model)
            got = fst.rhs(t, y)
            assert np.array_equal(got, direct(model, t, y, held))
            assert_rhs_equal(model, ref.rhs(t, y), got)


@pytest.mark.parametrize("base", BASES)
@pytest.mark.parametrize("seed", SEEDS)
def test_rhs_bit_for_bit_the_kernel_and_reference_to_round_off(seed, base):
    model = compile_model(load_scene(chain_scene(seed, base)))
    check_case(model, np.random.default_rng(500 + seed))


def test_cases_cover_the_features():
    """The cases above include hinges and spherical joints, torque and speed rotors, commanded
    hinges, and every base."""
    models = [compile_model(load_scene(chain_scene(s, b))) for s in SEEDS for b in BASES]
    assert any(m.is_hinge.any() for m in models) and any((~m.is_hinge).any() for m in models)
    assert any(len(m.torque_body) for m in models) and any(m.lam_speed is not None for m in models)
    assert any(len(m.hinge_bodies) and len(m.torque_body) for m in models)
    assert {m.base_type for m in models} == set(BASES)


def _hinge_chain_without_rotors():
    scene = random_chain(3, n=4, speed_rotors=False)
    for b in scene["bodies"]:
        b.pop("rotors", None)
        b["joint"] = {"type": "hinge", "axis": [0.3, 1.0, 0.2]}
        b["initial"] = {"angle": 0.4, "rate": -0.7}
    return scene


@pytest.mark.parametrize("scene", [spherical_chain(1), spherical_chain(3, gravity=False),
                                   _hinge_chain_without_rotors()],
                         ids=["one body, no hinge", "no hinge, no gravity", "hinges only, no rotors"])
def test_records_of_models_with_empty_blocks(scene):
    """No torque rotor (empty p0, pdot, L, torque arrays) or no hinge: the records' arrays are
    C-contiguous of the kernel's dtypes, the descriptor gives their addresses and sizes, and
    rhs matches."""
    model = compile_model(load_scene(scene))
    assert len(model.torque_body) == 0 and (not model.is_hinge.any() or model.is_hinge.all())
    held = (0.25, None, np.full(len(model.hinge_bodies), 0.1) if len(model.hinge_bodies) else None, None)
    chain, data, inputs = bound(model, held)
    arrays = (*chain, data.work, *inputs)
    assert len(arrays) == len(fast.ChainModel._fields) + 1 + len(fast.HeldInputs._fields) == 27
    assert all(a.flags.c_contiguous for a in arrays)
    assert {a.dtype for a in arrays} == {np.dtype(np.float64), np.dtype(np.int64), np.dtype(np.bool_)}
    d = data.descriptor
    assert list(d[fast.D_MODEL:fast.D_N]) == [a.ctypes.data for a in arrays]
    assert (d[fast.D_N], d[fast.D_NCOL], d[fast.D_NT], d[fast.D_NWORK]) == (model.n, model.N, 0, data.work.size)
    check_case(model, np.random.default_rng(3), holds=1)


def test_hold_writes_the_inputs_in_place():
    """After a hold, the kernel's records (the same objects) hold the new inputs, and a hold of
    no commands zeroes the previous ones."""
    model = compile_model(load_scene(chain_scene(2, "fixed")))
    assert len(model.torque_body) and len(model.hinge_bodies)
    fst = FastChainODE(model)
    first = fst.kernel_arguments()
    rng = np.random.default_rng(11)
    for h in (random_hold(rng, model), (1.5, None, None, None)):
        fst.hold(*h)
        args = fst.kernel_arguments()
        assert all(a is b for a, b in zip(args, first))
        t0, p0, hinge_tau, L = h
        nt = len(model.torque_body)
        want_L = np.zeros(nt) if L is None else L
        tau = np.zeros(model.N)
        if hinge_tau is not None:
            tau[model.col_hinge] = hinge_tau
        inputs = args[2]
        assert inputs.t0[0] == t0 and np.array_equal(inputs.p0, np.zeros(nt) if p0 is None else p0)
        assert np.array_equal(inputs.L_rotor, want_L) and np.array_equal(inputs.pdot, want_L / model.torque_A)
        assert np.array_equal(inputs.tau, tau)


def test_time_as_int_or_numpy_float():
    """The entry point converts t: an int or a numpy float gives the float's result."""
    model = compile_model(load_scene(spherical_chain(2, rotors=True)))
    fst = FastChainODE(model)
    fst.hold(0.5, model.torque_p0, None, np.full(len(model.torque_body), 0.01))
    y = initial_state(model)
    want = direct(model, 2.0, y, (0.5, model.torque_p0, None, np.full(len(model.torque_body), 0.01)))
    assert np.array_equal(fst.rhs(2, y), want)
    assert np.array_equal(fst.rhs(np.float64(2.0), y), want)


def test_wrong_shape_is_refused():
    """rhs refuses a y of another shape (the kernel does not check its indices)."""
    model = compile_model(load_scene(spherical_chain(2)))
    fst = FastChainODE(model)
    y = initial_state(model)
    fst.rhs(0.0, y)
    for bad in (y[:-1], np.concatenate([y, y]), y.reshape(1, -1)):
        with pytest.raises(ValueError, match="shape"):
            fst.rhs(0.0, bad)


def test_entry_checks_length_and_stride():
    """The compiled entry refuses a y not of ydot's length, or not contiguous (whose elements
    its C-ordered type would read at the wrong places)."""
    model = compile_model(load_scene(spherical_chain(2)))
    records = fast.records(model)  # kept: the descriptor points into all three
    data = records[1]
    entry = fast_entry.entry_point()  # takes the descriptor's address
    y = initial_state(model)
    ydot = np.empty(model.size)
    entry(0.0, y, ydot, data.descriptor.ctypes.data)
    assert np.array_equal(ydot, direct(model, 0.0, y, (0.0, None, None, None)))
    strided = np.zeros(2 * model.size)
    strided[::2] = y
    for bad in (y[:-1], np.concatenate([y, y]), strided[::2]):
        with pytest.raises(ValueError, match="contiguous vector"):
            entry(0.0, bad, ydot, data.descriptor.ctypes.data)
    assert data.descriptor[fast.D_NFEV] == 1  # the refused calls not counted


def test_nfev_counts_every_evaluation():
    """FastChainODE.nfev (a word of the descriptor the compiled entry counts in): one per rhs call,
    whichever path (entry point, another dtype, outputs), plus the marches' stages; settable."""
    model = compile_model(load_scene(spherical_chain(2, rotors=True)))
    fst = FastChainODE(model)
    y = initial_state(model)
    assert fst.nfev == 0
    for _ in range(3):
        fst.rhs(0.0, y)
    strided = np.zeros(2 * model.size)
    strided[::2] = y
    fst.rhs(0.0, strided[::2])  # refused by the entry, then numba's dispatcher
    fst.rhs(0.0, y, out=dyn.Evaluation())
    assert fst.nfev == 5
    A, B, C = np.zeros((4, 4)), np.full(4, 0.25), np.zeros(4)
    assert ErkMarch(fst)(A, B, C, 0.0, y.copy(), 1e-3, 5) == 5
    assert fst.nfev == 5 + 4 * 5
    fst.nfev += 7
    assert fst.nfev == 32
    fst.nfev = 0
    fst.rhs(0.0, y)
    assert fst.nfev == 1
    with pytest.raises(ValueError):
        fst.rhs(0.0, y[:-1])
    assert fst.nfev == 2  # counted by the path that refused it (as ChainODE counts every call)


ALLOC_PROBE = r"""
import json
import numba
import numpy as np
from numba.core.runtime import rtsys
from gyro_sim import load_scene
from gyro_sim.bench.scenes import spherical_chain
from gyro_sim.dynamics import reference as dyn
from gyro_sim.dynamics import kernel as fast, entry as fast_entry
from gyro_sim.dynamics.model import compile_model, initial_state

@numba.njit
def repeat(m, t, y, ydot, buf):
    for i in range(m):
        fast_entry.rhs_entry(t + 0.001 * i, y, ydot, buf)

model = compile_model(load_scene(spherical_chain(3, rotors=True)))
y = initial_state(model)
records = fast.records(model)  # kept: the descriptor points into all three
buf = records[1].descriptor
ydot = np.empty(model.size)
repeat(1, 0.0, y, ydot, buf)  # compiled (and numba's runtime started)
counts = []
for m in (1, 1, 11):
    before = rtsys.get_allocation_stats().alloc
    repeat(m, 0.0, y, ydot, buf)
    counts.append(rtsys.get_allocation_stats().alloc - before)
print(json.dumps(counts))
"""


@pytest.mark.slow
def test_entry_views_allocate_nothing():
    """The records rhs_entry's C function rebuilds from the descriptor allocate nothing: eleven evaluations inside one
    compiled call count the same allocations as one (the arguments' unboxing at the call;
    numba's own counters, NUMBA_NRT_STATS, set before numba imports: a subprocess)."""
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    proc = subprocess.run([sys.executable, "-c", ALLOC_PROBE], env={**os.environ, "NUMBA_NRT_STATS": "1"},
                          cwd=root, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    counts = json.loads(proc.stdout.strip().splitlines()[-1])
    assert counts[0] == counts[1], counts  # the count is repeatable
    assert counts[2] == counts[1], counts
