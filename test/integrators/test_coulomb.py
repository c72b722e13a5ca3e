"""Exact Coulomb friction of hinges and rotors (gyro_sim.integrators.coulomb.driver) against closed forms: stick and
slip are exact in the hard-friction limit, the energy dissipated is the friction's work; the
regularised law stays where a scene asks for it."""
from __future__ import annotations

import math

import numpy as np
import pytest

from gyro_sim import Simulator
from gyro_sim.integrators.coulomb.driver import box_lcp
from gyro_sim.scene.load import load_scene

#: the braked wheel: axial inertia J about a vertical hinge (gravity along it: no moment)
J, MU, W0, STEP = 0.02, 0.011, 3.0, 1e-3
#: the start of the slip-to-rest test: 1 rad/s rests at t* = 1.8181... s, inside a step (any w0 > 0
#: shows the same closed form; a shorter slip costs the numpy runs less)
W0_BRAKED = 1.0
#: the arm held against gravity: mass, centre of mass from the pivot, friction bound
M, L, G = 1.5, 0.2, 9.81
HOLD = 1.25 * M * G * L
ANGLE = 0.5 * math.pi


def wheel(coulomb: float = MU, w0: float = W0, **friction) -> dict:
    return {"name": "braked wheel", "gravity": [0.0, 0.0, -G], "base": {"type": "fixed", "position": [0.0, 0.0, 0.0]},
            "bodies": [{"name": "disc", "joint": {"type": "hinge", "axis": [0.0, 0.0, 1.0],
                                                  "friction": {"coulomb": coulomb, **friction}},
                        "mass": 2.0, "com": [0.0, 0.0, 0.0], "inertia": {"axial": J, "transverse": 0.011},
                        "initial": {"angle": 0.0, "rate": w0}}]}


def arm() -> dict:
    """A rod on a horizontal hinge (y), its centre of mass at z = L at angle 0, started at
    ANGLE = pi/2 (horizontal): gravity's moment about the hinge is +M G L there."""
    return {"name": "held arm", "gravity": [0.0, 0.0, -G], "base": {"type": "fixed", "position": [0.0, 0.0, 0.0]},
            "bodies": [{"name": "arm",
                        "joint": {"type": "hinge", "axis": [0.0, 1.0, 0.0], "friction": {"coulomb": HOLD}},
                        "mass": M, "com": [0.0, 0.0, L], "inertia": {"axial": 0.002, "transverse": 0.08},
                        "initial": {"angle": ANGLE, "rate": 0.0}}]}


@pytest.mark.parametrize("integrator, backend", [
    pytest.param("auto", "numpy", marks=pytest.mark.slow), pytest.param("rk4", "numpy", marks=pytest.mark.slow),
    ("fixed", "auto"), ("auto", "auto"), ("rk4", "auto")])
def test_a_braked_wheel_decelerates_at_mu_over_j_and_rests_from_w0_j_over_mu(integrator, backend):
    """Slip: the rate is w0 - mu t / J to round-off at every step; the wheel stops in the step
    holding t* = w0 J / mu and stays at rest exactly (rate 0, angle unchanged); the energy lost
    is the friction's work, and all of the kinetic energy."""
    sim = Simulator(wheel(w0=W0_BRAKED), integrator=integrator, step=STEP, backend=backend)
    stop = W0_BRAKED * J / MU  # 1.8181... s, inside a step
    stopped_at = None
    while sim.time < stop + 0.5:
        sim.advance(STEP)
        js = sim.joint_states()
        t, rate, angle = sim.time, js.velocity[0], js.position[0]
        if t < stop:
            assert rate == pytest.approx(W0_BRAKED - MU / J * t, abs=1e-11)
            assert angle == pytest.approx(W0_BRAKED * t - 0.5 * MU / J * t * t, abs=1e-9)
        elif stopped_at is None:
            assert rate == 0.0
            stopped_at, rest = t, angle
        else:
            assert rate == 0.0 and angle == rest
    assert stop <= stopped_at < stop + STEP
    assert abs(rest - W0_BRAKED ** 2 * J / (2 * MU)) <= W0_BRAKED * STEP  # the last step's angle, within the step
    energy = sim.invariants()["energy"] - sim.reference_invariants()["energy"]
    assert energy == pytest.approx(-0.5 * J * W0_BRAKED ** 2, rel=1e-12)
    assert sim.friction_work == pytest.approx(energy, rel=1e-9)
    snap = sim.snapshot()
    assert abs(snap.energy_balance) < 1e-9


@pytest.mark.parametrize("integrator", ["auto", "fixed"])
def test_friction_holds_against_gravity_until_a_ramped_moment_breaks_it_loose(integrator):
    """Gravity's moment M G L is below the bound: the arm stays at rest, angle and rate exactly
    0, its effort (the moment applied: command and friction) -M G L. A commanded moment ramped up
    from 0 breaks it loose in the first step where |command + M G L| > mu, and not before."""
    sim = Simulator(arm(), integrator=integrator, step=STEP, backend="auto")
    ramp = 2.0  # N m/s
    breaks = HOLD - M * G * L  # the command at which it slips
    moved_at = None
    for k in range(1, 400):
        command = ramp * k * STEP
        sim.set_axis_moments([command])
        sim.advance(STEP)
        js = sim.joint_states()
        if command + M * G * L <= HOLD:
            assert js.position[0] == ANGLE and js.velocity[0] == 0.0, command
            # what holds it is in the effort (command + friction): gravity's moment, balanced
            assert js.effort[0] == pytest.approx(-M * G * L, rel=1e-9)
        elif moved_at is None:
            moved_at = command
            assert js.velocity[0] > 0.0
    assert moved_at is not None and breaks < moved_at <= breaks + ramp * STEP
    assert sim.friction_work < 0.0


def test_the_arm_breaking_loose_accelerates_as_the_net_moment_says():
    """Once it slips (rate > 0) the arm's first step follows J_O phi'' = command + M G L cos phi -
    mu: the rate after one step against that closed form, to the step's second order."""
    sim = Simulator(load_scene(arm()), integrator="auto", step=STEP, backend="numpy")
    inertia = sim.model.inertia[0][1, 1]  # about the hinge (y) at the pivot (eq 30)
    command = HOLD - M * G * L + 0.5
    sim.set_axis_moments([command])
    sim.advance(STEP)
    accel = (command + M * G * L - HOLD) / inertia
    assert sim.joint_states().velocity[0] == pytest.approx(accel * STEP, rel=1e-3)


def test_a_stick_speed_keeps_the_regularised_law():
    """A hinge friction with stick_speed (or a Stribeck term) written is the regularised F(w) of
    docs/scene-format.md: no stick/slip stepping, the model's friction a state-dependent term."""
    sim = Simulator(wheel(stick_speed=1e-3), integrator="auto", backend="numpy")
    assert not sim.model.actuators.exact and sim.model.stateful
    exact = Simulator(wheel(), integrator="auto", backend="numpy")
    assert exact.model.actuators.exact and not exact.model.stateful
    assert list(exact.model.actuators.hinge.exact) == [MU]


def test_the_box_lcp_meets_its_complementarity_conditions():
    """Random symmetric positive definite problems: |lambda| <= c, v = b + W lambda, v = 0 where
    inside the bounds, lambda opposing v at the bounds; the guess does not change the answer."""
    rng = np.random.default_rng(7)
    for n in (1, 2, 5, 9):
        for _ in range(30):
            A = rng.normal(size=(n, n))
            W = A @ A.T + 1e-3 * np.eye(n)
            b, c = rng.normal(size=n), rng.uniform(0.01, 1.0, size=n)
            lam, stuck = box_lcp(W, b, c, rng.integers(-1, 2, size=n))
            v = b + W @ lam
            scale = np.max(np.abs(b)) + np.max(np.abs(W)) * np.max(c)
            assert np.all(np.abs(lam) <= c * (1 + 1e-12))
            assert np.all(np.abs(v[stuck]) < 1e-10 * scale)
            assert np.all(lam[~stuck] * v[~stuck] <= 1e-12 * scale)
            lam2, _ = box_lcp(W, b, c, np.zeros(n, dtype=np.int64))
            assert np.allclose(lam, lam2, atol=1e-10 * np.max(c))


def test_exact_friction_takes_no_stiff_evaluation_count():
    """The wheel sliding to rest and resting: per simulated second, "auto" takes about one
    dop853 step per friction step (12 evaluations and the start of each call) and the impulse
    steps one evaluation more each, not the millions the regularised law's stiffness costs."""
    sim = Simulator(wheel(), integrator="auto", step=STEP)
    sim.advance(8.0)
    per_second = sim.system.nfev / 8.0
    assert per_second < 20_000


def test_a_log_of_stick_and_slip_resimulates_bit_for_bit(tmp_path):
    """The arm held, then broken loose by a scheduled command: its log re-simulates with every
    joint state identical (the friction's steps depend only on the states and commands)."""
    from gyro_sim.log.record import record_run
    from gyro_sim.log.resim import resimulate

    sim = Simulator(arm(), integrator="fixed", step=STEP)
    path = tmp_path / "arm.mcap"
    record_run(sim, path, duration=0.3, schedule=[(0.0, [0.5 * (HOLD - M * G * L)]), (0.1, [1.5 * (HOLD - M * G * L)])])
    res = resimulate(path)
    assert res.compared and res.max_deviation == 0.0
    assert sim.state[sim.model.i_phi][0] != ANGLE  # it broke loose


def test_friction_inside_a_free_chain_keeps_its_momenta():
    """A hub on a free base and an arm on a hinge with exact friction, no gravity: friction is
    internal, so the linear momentum and the angular momentum about the centre of mass stay
    those of the start (to the impulse step's first order at the slip reversals: the positions
    move by half a step of the velocity change); the energy lost is the friction's work."""
    scene = {"name": "free pair", "base": {"type": "free", "position": [0.0, 0.0, 0.0], "velocity": [0.1, 0.0, 0.0]},
             "bodies": [{"name": "hub", "joint": {"type": "spherical"}, "mass": 2.0, "com": [0.0, 0.0, 0.1],
                         "inertia": {"axial": 0.02, "transverse": 0.05}, "next_joint": [0.0, 0.0, 0.3],
                         "initial": {"euler": [0.0, 0.3, 0.0], "euler_rates": [0.5, 0.0, 0.2]}},
                        {"name": "arm",
                         "joint": {"type": "hinge", "axis": [0.0, 1.0, 0.0], "friction": {"coulomb": 0.02}},
                         "mass": 1.0, "com": [0.0, 0.0, 0.2], "inertia": {"axial": 0.003, "transverse": 0.05},
                         "initial": {"angle": 0.2, "rate": 3.0}}]}
    sim = Simulator(scene, integrator="fixed", step=STEP)
    start = sim.invariants()
    rates = []
    for _ in range(3000):
        sim.advance(STEP)
        rates.append(sim.state[sim.model.i_vel][sim.model.col_hinge[0]])
    now = sim.invariants()
    assert min(rates) < 0.0 < max(rates)  # the arm's slip reversed
    for name in ("linear_momentum", "angular_momentum"):
        assert np.max(np.abs(now[name] - start[name])) < 1e-6 * np.max(np.abs(start[name])), name
    lost = now["energy"] - start["energy"]
    assert lost < -0.01 and abs(lost - sim.friction_work) < 1e-5 * abs(lost)


@pytest.mark.parametrize("carrier", ["held", "free"])
@pytest.mark.parametrize("integrator", ["fixed", "auto"])
def test_a_wheel_braked_on_its_bearing_rests_from_w0_jeff_over_mu(carrier, integrator):
    """A torque rotor's exact Coulomb friction: its spin relative to the carrier falls at
    mu / J_eff (J_eff = A on a held carrier; A C / (A + C) on a free one, whose angular momentum
    is kept), it stops in the step holding w0 J_eff / mu and stays at rest; the energy lost is
    the friction's work, on a free carrier the kinetic energy of the relative spin."""
    from test.dynamics.test_actuators import OMEGA0, effective_inertia, relative_spin, wheel_scene

    mu = 0.11
    sim = Simulator(wheel_scene(carrier, friction={"coulomb": mu}), integrator=integrator, step=STEP)
    J = effective_inertia(carrier)
    stop = OMEGA0 * J / mu
    start = sim.invariants()
    stopped_at = None
    while sim.time < stop + 0.2:
        sim.advance(STEP)
        w = relative_spin(sim)
        if sim.time < stop:
            assert w == pytest.approx(OMEGA0 - mu / J * sim.time, abs=1e-9)
        elif stopped_at is None:
            stopped_at = sim.time
        else:
            assert abs(w) < 1e-12
    assert stop <= stopped_at < stop + STEP
    now = sim.invariants()
    lost = now["energy"] - start["energy"]
    assert lost == pytest.approx(sim.friction_work, rel=1e-9)
    if carrier == "free":
        assert lost == pytest.approx(-0.5 * J * OMEGA0 ** 2, rel=1e-9)
        assert np.allclose(now["angular_momentum_O1"], start["angular_momentum_O1"], rtol=0, atol=1e-12)


@pytest.mark.parametrize("backend", ["numpy", "auto"])
def test_held_moments_work_counts_the_impulse_steps_with_viscous_friction_beside(backend):
    """With a viscous term beside the exact friction the works are states (integrated along each
    smooth step), and an impulse step's correction moves the angle after them: the motor work
    is still moment x change of the angle exactly for held moments (to round-off), and the
    energy balance E - E0 - W - W_f closes to 1e-8 of the work over stick and slip."""
    scene = arm()
    scene["bodies"][0]["joint"]["friction"] = {"coulomb": 1.0, "viscous": 0.05}
    sim = Simulator(load_scene(scene), integrator="dop853", rtol=1e-11, atol=1e-11, step=STEP, backend=backend)
    assert sim.model.stateful
    e0 = sim.invariants()["energy"]
    held = worst = 0.0
    for k in range(300):
        command = 2.5 * math.sin(3.0 * k * 0.01) - M * G * L  # about gravity's moment: stick and slip
        before = sim.joint_states().position[0]
        sim.set_axis_moments([command])
        sim.advance(0.01)
        held += command * (sim.joint_states().position[0] - before)
        worst = max(worst, abs(sim.invariants()["energy"] - e0 - sim.work - sim.friction_work))
    assert sim._coulomb.impulse_steps > 10  # stick and slip both happened
    assert abs(sim.work - held) < 1e-12 * abs(held) + 1e-14, (sim.work, held)
    assert worst < 1e-8 * abs(held), (worst, held)
