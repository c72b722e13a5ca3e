"""The node's fixed-step method (gyro_sim.core.integrators.choose): rk4 where it is stable at
the step, gauss4 where the scene is stiff, and the choice checked against a 1 s run."""
import numpy as np
import pytest

from gyro_sim.bench.extreme import load_dict
from gyro_sim.core.integrators.choose import spectral_radius_estimate, fixed_step_method
from gyro_sim.core.simulator import SimulationError, Simulator

STEP = 1e-3  # the node's physics step
CALL = 0.01  # the node's advance calls
FAST_SPIN = 1e4  # rad/s, the fast heavy top


def fast_heavy_top(spin=FAST_SPIN):
    """config/heavy_top.yaml spun about its axis at `spin` rad/s."""
    sd = load_dict("heavy_top")
    sd["bodies"][0]["initial"]["euler_rates"] = [0.0, 0.0, spin]
    return sd


def survives(scene, name, seconds=1.0):
    sim = Simulator(scene, integrator=name, step=STEP)
    try:
        for _ in range(round(seconds / CALL)):
            sim.advance(CALL)
    except SimulationError:
        return False
    return True


def test_spectral_radius_exact_on_a_small_matrix():
    J = np.array([[0.0, 50.0, 0.0], [-50.0, 0.0, 0.0], [0.0, 0.0, -3.0]])  # +-50 i, -3
    rho = spectral_radius_estimate(lambda t, y: J @ y, 0.0, np.array([1.0, 2.0, 3.0]))
    assert rho == pytest.approx(50.0, rel=1e-6)


@pytest.mark.parametrize("scene", ["hinge_chain", "stiff_fast_rotor"])
def test_rk4_where_stable_and_it_survives(scene):
    name, why = fixed_step_method(Simulator(scene, integrator="rk4", step=STEP), STEP)
    assert name == "rk4" and why.startswith("rk4: h |lambda| = "), why
    assert survives(scene, "rk4")


def test_gauss4_on_the_fast_heavy_top_where_rk4_fails():
    scene = fast_heavy_top()
    name, why = fixed_step_method(Simulator(scene, integrator="rk4", step=STEP), STEP)
    assert name == "gauss4" and "stiff for rk4" in why, why
    assert not survives(scene, "rk4")  # the choice matters: rk4 goes non-finite


# --- "fixed": the choice made at the start and again as the motion changes -------------------

class Rotation:
    """y' = w J y in the plane (eigenvalues +-i w): rk4 is unstable for h w > 2 sqrt 2, Gauss
    collocation keeps |y| exactly (a quadratic invariant)."""

    def __init__(self, w):
        self.w, self.size, self.quat_index, self.nfev = w, 2, np.zeros((0, 4), dtype=int), 0

    def rhs(self, t, y):
        self.nfev += 1
        with np.errstate(over="ignore", invalid="ignore"):  # rk4 past its limit overflows, by design here
            return self.w * np.array([-y[1], y[0]])

    def project(self, y):
        pass


def test_fixed_is_rk4_bit_for_bit_on_a_soft_scene():
    a = Simulator("hinge_chain", integrator="fixed", step=STEP)
    b = Simulator("hinge_chain", integrator="rk4", step=STEP)
    for _ in range(30):
        a.advance(CALL)
        b.advance(CALL)
    assert a.integrator.current == "rk4" and a.integrator.switches == []
    assert np.array_equal(a.state, b.state)


def test_fixed_switches_when_a_command_stiffens_the_scene_and_back():
    """A rotation whose rate is the command: soft, then past rk4's limit, then soft again."""
    from gyro_sim.core.integrators.choose import SceneFixedStep

    sys_ = Rotation(100.0)
    sys_.inputs_version = 0
    integ = SceneFixedStep(sys_, step=STEP)
    y = np.array([1.0, 0.0])
    t = 0.0
    for w, expect in ((100.0, "rk4"), (5000.0, "gauss4"), (100.0, "rk4")):
        sys_.w = w
        sys_.inputs_version += 1  # as ChainODE.hold does when the commanded values change
        for _ in range(50):
            y = integ.advance(t, y, t + CALL)
            t += CALL
        assert integ.current == expect, (w, integ.reason)
    assert [s[1:3] for s in integ.switches] == [("rk4", "gauss4"), ("gauss4", "rk4")]
    assert np.hypot(*y) == pytest.approx(1.0, abs=1e-5)  # neither let it grow (rk4 damps ~7e-9 a step)


def test_fixed_takes_a_call_again_with_gauss4_when_rk4_blows_up(monkeypatch):
    """The estimate said rk4 (forced here), rk4 overflowed within the call: the call is taken
    again from its start with gauss4, which keeps |y| = 1 to round-off (h w = 5)."""
    from gyro_sim.core.integrators import choose

    monkeypatch.setattr(choose, "_choice", lambda rhs, t, y, h, now, dim=0: ("rk4", "forced", 0.0))
    integ = choose.SceneFixedStep(Rotation(5000.0), step=STEP)
    y = integ.advance(0.0, np.array([1.0, 0.0]), 1.0)  # 1000 steps: rk4 grows ~21x a step
    assert integ.current == "gauss4" and "non-finite" in integ.reason
    assert len(integ.switches) == 1 and integ.switches[0][0] == 0.0
    assert np.hypot(*y) == pytest.approx(1.0, abs=1e-12)
def test_fixed_takes_gauss4_on_the_fast_heavy_top():
    sim = Simulator(fast_heavy_top(1e3 * 3), integrator="fixed", step=STEP)  # h w ~ 3: past rk4's limit
    sim.advance(CALL)
    assert sim.integrator.current == "gauss4" and "stiff for rk4" in sim.integrator.reason


def test_fixed_re_simulates_bit_for_bit_with_its_switches():
    """Two runs with the same commands: the same switches and the same states."""
    def run():
        sim = Simulator(fast_heavy_top(3e3), integrator="fixed", step=STEP)
        out = []
        for _ in range(20):
            sim.advance(CALL)
            out.append(sim.state.copy())
        return out, list(sim.integrator.switches), sim.integrator.current
    a, b = run(), run()
    assert a[1:] == b[1:] and all(np.array_equal(x, y) for x, y in zip(a[0], b[0]))


def test_warm_up_runs_both_methods_and_leaves_no_trace():
    """The node calls it before real time starts: gauss4's path is compiled (or loaded) then,
    not at the first switch; state, counters and the choice are as before."""
    sim = Simulator("hinge_chain", integrator="fixed", step=STEP)
    integ, y0 = sim.integrator, sim.state
    calls = []
    for name, m in integ.methods.items():
        march = m.march
        m.march = lambda t0, y, t1, march=march, name=name: (calls.append(name), march(t0, y, t1))
    integ.warm_up(sim.time, y0)
    assert sorted(calls) == ["gauss4", "rk4"]
    assert all(m.nsteps == 0 and m.nfev == 0 for m in integ.methods.values())
    assert np.array_equal(sim.state, y0) and integ.current == "" and integ.switches == []
