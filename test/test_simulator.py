"""The Simulator's outputs against its state: after an integration that fails, the state is
kept, and so are the outputs of that state (on both backends)."""
import numpy as np
import pytest

from gyro_sim.dynamics import kernel as fast
from gyro_sim.paths import find_scene
from gyro_sim.simulator import SimulationError, Simulator

BACKENDS = ["numpy"] + (["numba"] if fast.available() else [])
ARRAYS = ("position", "velocity", "effort", "body_position", "body_quaternion", "wrench_force", "wrench_moment")


def driven(backend: str) -> Simulator:
    """hinge_chain under large moments with rk4 at a step far too long: the second step
    of 0.5 s leaves the state non-finite."""
    sim = Simulator(find_scene("hinge_chain"), integrator="rk4", step=0.5, backend=backend)
    sim.set_axis_moments(np.full(len(sim.axis_names), 50.0))
    sim.advance(0.5)
    return sim


@pytest.mark.parametrize("backend", BACKENDS)
def test_outputs_after_a_failed_advance_are_those_of_the_kept_state(backend):
    sim, same = driven(backend), driven(backend)
    sim.snapshot()  # outputs computed, then the integration overwrites the workspaces and fails
    with np.errstate(all="ignore"), pytest.raises(SimulationError, match="state kept"):
        sim.advance(0.5)
    np.testing.assert_array_equal(sim.state, same.state)
    got, want = sim.snapshot(), same.snapshot()
    for name in ARRAYS:
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)
    assert got.invariants.keys() == want.invariants.keys()
    for key, v in want.invariants.items():
        np.testing.assert_array_equal(got.invariants[key], v, err_msg=key)


@pytest.mark.parametrize("backend", BACKENDS)
def test_outputs_after_the_held_rhs_is_called_elsewhere_are_those_of_the_state(backend):
    """The held rhs (the "fixed" integrator's analysis) evaluates in the workspaces the outputs
    read: outputs computed before it are computed afresh after it."""
    sim = Simulator(find_scene("hinge_chain"), backend=backend)
    sim.advance(0.05)
    want = sim.snapshot()
    rhs = sim.held_rhs()
    rhs(sim.time, sim.state + 0.3)  # somewhere else
    got = sim.snapshot()
    for name in ARRAYS:
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)


def test_a_switch_of_backend_keeps_the_run_and_repeats_bit_for_bit():
    """Simulator.switch_backend (the node's start on numpy, then on the compiled kernels): the
    time, state, commands and work are kept; the same switch at the same step gives the same
    run bit for bit; and the switched run follows the run on numba all along to round-off (the
    two backends are the same equations)."""
    from gyro_sim import Simulator

    def run(backend, switch_at=None, steps=300):
        sim = Simulator("hinge_chain", integrator="fixed", step=1e-3, backend=backend)
        sim.set_axis_moments([0.002, 0.03, -0.02])
        for i in range(steps):
            if i == switch_at:
                before = (sim.time, sim.state, sim.axis_moments, sim.work)
                sim.switch_backend("numba")
                after = (sim.time, sim.state, sim.axis_moments, sim.work)
                assert before[0] == after[0] and np.array_equal(before[1], after[1])
                assert np.array_equal(before[2], after[2]) and before[3] == after[3]
                assert sim.backend == "numba"
            sim.advance(1e-3)
        return sim

    a, b = run("numpy", 120), run("numpy", 120)
    assert np.array_equal(a.state, b.state)
    c = run("numba")
    assert not np.array_equal(a.state, c.state)  # rounding differs: the switch step matters
    assert np.allclose(a.state, c.state, rtol=0, atol=1e-10)


def test_axis_moments_are_set_by_name_in_another_order_than_the_chain():
    """An imported model's actuators in MuJoCo's order (Gymnasium's ant: hip_4, ankle_4, hip_1,
    ...) differ from the chain's: a mapping by axis name sets each where it belongs, the others
    kept; a name that is no axis is refused, naming the axes."""
    import warnings

    mujoco = pytest.importorskip("mujoco", reason="the model is MJCF: MuJoCo is the optional extra [models]")
    from gyro_sim import load_scene

    from pathlib import Path

    path = Path(__file__).parent / "scene" / "models" / "gymnasium" / "ant.xml"
    m = mujoco.MjModel.from_xml_path(str(path))
    mujoco_order = [m.joint(m.actuator_trnid[i][0]).name for i in range(m.nu)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sim = Simulator(load_scene(path), backend="numpy")
    assert sorted(mujoco_order) == sorted(sim.axis_names) and mujoco_order != list(sim.axis_names)
    action = np.arange(1.0, m.nu + 1.0)  # in MuJoCo's order
    sim.set_axis_moments(dict(zip(mujoco_order, action)))
    for name, value in zip(mujoco_order, action):
        assert sim.axis_moments[sim.axis_names.index(name)] == value
    sim.set_axis_moments({mujoco_order[0]: -5.0})
    assert sim.axis_moments[sim.axis_names.index(mujoco_order[0])] == -5.0
    assert sim.axis_moments[sim.axis_names.index(mujoco_order[1])] == action[1]  # kept
    with pytest.raises(ValueError, match="no commanded axis named 'knee'.*hip_1"):
        sim.set_axis_moments({"knee": 1.0})
