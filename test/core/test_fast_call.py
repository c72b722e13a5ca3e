"""The compiled code calls the dynamics through compiled C functions (gyro_sim.dynamics.kernel):

- the heavy-subtree elimination (`_aba_heavy`) through flags[FLAG_HEAVY], which
  `chain_model` fills only for a model whose kernel takes that path;
- the kernel itself (`rhs_call`) through flags[FLAG_KERNEL], from every compiled loop;
- FastChainODE.outputs and the Simulator's publications share one specialization of the
  publication kernel;
- "fixed" builds its gauss4s without compiling it (the first march does).
"""
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from gyro_sim.bench import scenes
from gyro_sim.bench.extreme import mass_ratio_chain
from gyro_sim.dynamics import kernel as fast
from gyro_sim.dynamics.model import compile_model, initial_state
from gyro_sim.scene.load import load_scene
from gyro_sim.dynamics.system import ChainODE, FastChainODE, heavy_subtree_ratio

pytestmark = pytest.mark.skipif(not fast.available(), reason="needs numba")

ROOT = Path(__file__).resolve().parents[2]
#: mass ratios of the tip against its neighbour, away from STABLE_ABA_RATIO on both sides
RATIOS = (1e-6, 1.0, 30.0, 1e3, 1e6)
#: the numpy reference against the compiled kernel (round-off, conditioning of the heavy tips)
RTOL = 1e-9


def _models():
    yield "hinge_chain", compile_model(load_scene("hinge_chain"))
    yield "spherical_chain(150)", compile_model(load_scene(scenes.spherical_chain(150)))  # 149x at the root
    for r in RATIOS:
        yield f"mass ratio {r:g}", compile_model(load_scene(mass_ratio_chain(r)))


def _kernel(model, flags=None):
    """y' at the model's initial state, the inputs held as ChainODE holds them at its start."""
    ref = ChainODE(model)
    chain, data, inputs = fast.records(model)
    fast.hold(inputs, model, ref.t0, ref.p0, None, None)
    if flags is not None:
        chain = chain._replace(flags=flags)
    args = (chain, data, inputs)
    y = initial_state(model)
    ydot = np.empty_like(y)
    fast.rhs_kernel(0.0, y, ydot, *args)
    return ydot


@pytest.mark.parametrize("name,model", list(_models()))
def test_heavy_path_is_there_exactly_where_the_kernel_takes_it(name, model):
    """flags[FLAG_HEAVY] is set where a subtree outweighs its carrier STABLE_ABA_RATIO times
    (system.heavy_subtree_ratio, numpy); there the kernel without it gives no number (the path
    was taken), elsewhere the same y' bit for bit (it was not). With it, y' is finite (its
    accuracy against 80 digits: test_heavy_tip), and the numpy reference's to round-off where
    the classic elimination runs."""
    flags = fast.chain_model(model).flags
    heavy = heavy_subtree_ratio(model) > fast.STABLE_ABA_RATIO
    assert (flags[fast.FLAG_HEAVY] != 0) == heavy == fast.heavy_subtrees(model.mass)
    ydot = _kernel(model)
    assert np.isfinite(ydot).all(), name
    if not heavy:
        ref = ChainODE(model).rhs(0.0, initial_state(model))
        assert np.abs(ydot - ref).max() <= RTOL * np.abs(ref).max(), name
    without = flags.copy()
    without[fast.FLAG_HEAVY] = 0
    other = _kernel(model, without)
    if heavy:
        assert np.isnan(other[model.i_vel]).all(), name
    else:
        assert np.array_equal(other, ydot), name


def _via_call():
    import numba

    @numba.njit
    def call(t, y, ydot, *args):
        fast.rhs_call(t, y, ydot, *args)

    return call


def test_the_kernel_through_its_c_function_is_the_kernel_bit_for_bit():
    call = _via_call()
    for name, model in _models():
        args = fast.records(model)
        fast.hold(args[2], model, 0.1, None, None, None)
        y = initial_state(model) + 0.01 * np.random.default_rng(1).standard_normal(model.size)
        direct, through = np.empty_like(y), np.empty_like(y)
        fast.rhs_kernel(0.3, y, direct, *args)
        call(0.3, y, through, *args)
        assert np.array_equal(direct, through), name


def test_a_strided_array_does_not_compile_into_a_c_call():
    """The C functions read items consecutively: a strided array is refused when the caller is
    compiled, never read with the wrong strides."""
    from numba.core.errors import TypingError

    model = compile_model(load_scene("hinge_chain"))
    args = fast.records(model)
    y = np.repeat(initial_state(model), 2)[::2]  # the state, every other item of a longer vector
    with pytest.raises(TypingError):
        _via_call()(0.0, y, np.empty(model.size), *args)


def test_the_null_kernel_only_zeroes_the_rate():
    model = compile_model(load_scene("hinge_chain"))
    chain, data, inputs = fast.records(model)
    flags = chain.flags.copy()
    flags[fast.FLAG_KERNEL] = fast.null_kernel_address()
    args = (chain._replace(flags=flags), data, inputs)
    y = initial_state(model)
    ydot = np.full_like(y, 7.0)
    _via_call()(0.0, y, ydot, *args)
    assert not ydot.any()


def test_outputs_and_publications_share_one_specialization():
    code = ("import numpy as np\nfrom gyro_sim.simulator import Simulator\n"
            "from gyro_sim.dynamics import outputs as fast_outputs\n"
            "sim = Simulator('hinge_chain', integrator='rk4', backend='numba')\n"
            "sim.snapshot(); sim.system.outputs(0.0, sim.state)\n"
            "print(len(fast_outputs.publication_kernel.overloads))\n")
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0 and r.stdout.strip() == "1", (r.stdout, r.stderr)


def test_fixed_builds_its_implicit_method_without_compiling_it():
    from gyro_sim.dynamics.canonical_kernel import CFLAG_KERNEL
    from gyro_sim.integrators.fixed import SceneFixedStep

    system = FastChainODE(compile_model(load_scene("hinge_chain")))
    integ = SceneFixedStep(system, step=1e-3)
    gauss4s = integ.methods["gauss4s"]
    cflags = gauss4s.canonical._extra[1]
    assert gauss4s.inner._compiled._march.entry is None and cflags[CFLAG_KERNEL] == 0
    y = initial_state(system.model)
    gauss4s.march(0.0, y, 2e-3)
    assert gauss4s.inner._compiled._march.entry is not None and cflags[CFLAG_KERNEL] != 0
