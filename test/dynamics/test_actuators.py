"""Actuator limits and friction (docs/scene-format.md, "Actuator limits and friction") against
closed forms: a wheel spinning down under viscous and Coulomb friction on a free and on a
held carrier, saturation, the speed limit, a damped hinge pendulum, the energy balance with
friction, and the refusals."""
from __future__ import annotations

import copy
import math

import numpy as np
import pytest

from gyro_sim.dynamics import kernel
from gyro_sim.dynamics.actuators import ActuatorError
from gyro_sim.msgs import messages
from gyro_sim.scene.load import SceneError, load_scene
from gyro_sim.simulator import Simulator

#: the wheel and its carrier (kg m^2): A the wheel's axial inertia, C the carrier's about the axis
A, C = 0.01, 0.03
OMEGA0 = 20.0  # rad/s, the wheel's initial spin relative to its carrier
RTOL, ATOL = 1e-11, 1e-13
#: the compiled kernel where numba is installed (its absence is outside the package)
BACKENDS = ["numpy", pytest.param("numba", marks=pytest.mark.skipif(not kernel.available(), reason="numba missing"))]


def wheel_scene(carrier: str = "free", **rotor_keys) -> dict:
    """A hub on a fixed point without gravity carrying one actuated wheel on its z-axis, at rest
    with the wheel spinning at OMEGA0. carrier "free": a spherical joint (the hub turns about
    z under the wheel's reaction); "held": a hinge about x, across the wheel's axis (the
    reaction is taken by the hinge, the hub stays at rest)."""
    joint = {"type": "spherical"} if carrier == "free" else {"type": "hinge", "axis": [1.0, 0.0, 0.0]}
    rotor = {"name": "wheel", "axis": [0.0, 0.0, 1.0], "mass": 0.5, "axial_inertia": A, "transverse_inertia": 0.006,
             "mode": "torque", "spin": OMEGA0, "actuated": True, **rotor_keys}
    return {"name": "wheel", "base": {"type": "fixed", "position": [0.0, 0.0, 0.0]},
            "bodies": [{"name": "hub", "joint": joint, "mass": 2.0, "com": [0.0, 0.0, 0.0],
                        "inertia": {"axial": C, "transverse": 0.05}, "rotors": [rotor]}]}


def effective_inertia(carrier: str) -> float:
    """The inertia J_eff with which a torque pair between wheel and carrier changes their relative
    spin w = p - omega: the wheel A p' = tau, the free carrier C omega' = -tau (the same pair,
    angular momentum A p + C omega kept), so w' = tau (1/A + 1/C) = tau / J_eff,
    J_eff = A C / (A + C); a held carrier does not turn: J_eff = A."""
    return A * C / (A + C) if carrier == "free" else A


def relative_spin(sim: Simulator) -> float:
    js = sim.joint_states()
    return js.velocity[js.name.index("wheel")]


def command(sim: Simulator, torque: float) -> None:
    """Command the wheel's axial torque (a held carrier's hinge: 0)."""
    sim.set_axis_moments([torque if name == "wheel" else 0.0 for name in sim.axis_names])


def effort(sim: Simulator, name: str) -> float:
    js = sim.joint_states()
    return js.effort[js.name.index(name)]


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("carrier", ["free", "held"])
def test_viscous_spin_down_is_exponential_with_the_effective_inertia(carrier, backend):
    c = 2e-3  # N m s/rad
    sim = Simulator(wheel_scene(carrier, friction={"viscous": c}), integrator="dop853", rtol=RTOL, atol=ATOL,
                    backend=backend)
    assert sim.backend == backend
    J = effective_inertia(carrier)
    for t in (0.5, 1.0, 2.0):
        sim.advance(t - sim.time)
        expected = OMEGA0 * math.exp(-c * t / J)
        assert relative_spin(sim) == pytest.approx(expected, rel=1e-9)
        assert effort(sim, "wheel") == pytest.approx(-c * expected, rel=1e-9)  # the friction applied
    # dissipated: int c w^2 dt = J OMEGA0^2 / 2 (1 - exp(-2 c t / J))
    dissipated = 0.5 * J * OMEGA0**2 * (1.0 - math.exp(-2.0 * c * sim.time / J))
    snap = sim.snapshot()
    assert -snap.friction_work == pytest.approx(dissipated, rel=1e-9)
    assert abs(snap.energy_balance) < 1e-9 * snap.energy_scale
    assert snap.work == 0.0


@pytest.mark.filterwarnings("ignore::gyro_sim.integrators.StiffnessWarning")  # radau takes the stuck wheel
@pytest.mark.slow
def test_coulomb_spin_down_is_linear_then_stays_at_rest():
    tau_c, stick = 0.05, 1e-2
    sim = Simulator(wheel_scene("free", friction={"coulomb": tau_c, "stick_speed": stick}), integrator="auto",
                    rtol=1e-10, atol=1e-12, backend="numpy")
    J = effective_inertia("free")
    t_stop = OMEGA0 * J / tau_c  # w = OMEGA0 - tau_c t / J
    for t in (0.25 * t_stop, 0.5 * t_stop, 0.9 * t_stop):
        sim.advance(t - sim.time)
        assert relative_spin(sim) == pytest.approx(OMEGA0 - tau_c * t / J, rel=1e-8)
    # below stick_speed the friction is linear: w decays as exp(-tau_c t / (J stick)) from there
    sim.advance(t_stop + 0.2 * t_stop - sim.time)
    assert abs(relative_spin(sim)) < 1e-9
    sim.advance(t_stop)
    assert abs(relative_spin(sim)) < 1e-9
    snap = sim.snapshot()
    assert -snap.friction_work == pytest.approx(0.5 * J * OMEGA0**2, rel=1e-6)  # all the relative energy
    assert abs(snap.energy_balance) < 1e-8 * snap.energy_scale


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_command_beyond_max_torque_spins_up_at_max_torque_over_A(backend):
    limit = 0.02
    sim = Simulator(wheel_scene("held", max_torque=limit), integrator="rk4", step=1e-3, backend=backend)
    command(sim, 10 * limit)
    sim.advance(0.5)
    assert relative_spin(sim) == pytest.approx(OMEGA0 + limit / A * 0.5, rel=1e-12)
    snap = sim.snapshot()
    assert effort(sim, "wheel") == limit
    assert snap.axis_moments[sim.axis_names.index("wheel")] == 10 * limit  # the command as given
    assert snap.saturated_commands == 1
    assert snap.work == pytest.approx(limit * (OMEGA0 * 0.5 + 0.5 * limit / A * 0.25), rel=1e-10)
    assert abs(snap.energy_balance) < 1e-10 * snap.energy_scale
    command(sim, -0.5 * limit)  # within the limit: applied as commanded, not counted
    assert effort(sim, "wheel") == -0.5 * limit
    assert sim.saturated_commands == 1


@pytest.mark.parametrize("backend", BACKENDS)
def test_max_speed_stops_the_spin_up_at_max_speed(backend):
    omega_max, torque = 30.0, 0.05
    sim = Simulator(wheel_scene("held", max_speed=omega_max), integrator="dop853", rtol=RTOL, atol=ATOL,
                    backend=backend)
    command(sim, torque)
    t_reach = (omega_max - OMEGA0) * A / torque  # spin-up at torque / A until max_speed
    sim.advance(0.5 * t_reach)
    assert relative_spin(sim) == pytest.approx(OMEGA0 + torque / A * 0.5 * t_reach, rel=1e-10)
    spins = []
    for _ in range(20):
        sim.advance(0.2 * t_reach)
        spins.append(relative_spin(sim))
    assert max(spins) <= omega_max * (1.0 + 1e-12)  # to the integration error
    assert spins[-1] >= omega_max * (1.0 - 1e-3)
    assert spins[-1] - spins[-2] < 1e-9 * omega_max  # it has stopped growing
    assert abs(effort(sim, "wheel")) < 1e-6 * torque  # the motor's torque is cut
    command(sim, -torque)  # a torque that slows the wheel is never cut
    assert effort(sim, "wheel") == -torque


@pytest.mark.parametrize("backend", BACKENDS)
def test_damped_hinge_pendulum_decays_at_c_over_2I(backend):
    """I theta'' + c theta' + m g l theta = 0 for small angles: theta0 e^(-s t) (cos wd t + s/wd
    sin wd t), s = c / (2 I), wd = sqrt(m g l / I - s^2)."""
    m, l, g, I, c, theta0 = 1.0, 0.1, 9.81, 0.02, 0.01, 1e-4
    scene = {"name": "damped", "gravity": [0.0, 0.0, -g], "base": {"type": "fixed", "position": [0.0, 0.0, 0.0]},
             "bodies": [{"name": "arm", "joint": {"type": "hinge", "axis": [1.0, 0.0, 0.0], "friction": {"viscous": c}},
                         "mass": m, "com": [0.0, 0.0, -l], "inertia": {"axial": 0.01, "transverse": I},
                         "initial": {"angle": theta0}}]}
    sim = Simulator(scene, integrator="dop853", rtol=RTOL, atol=1e-16, backend=backend)
    s = c / (2 * I)
    wd = math.sqrt(m * g * l / I - s * s)
    for t in np.linspace(0.3, 3.0, 10):
        sim.advance(t - sim.time)
        js = sim.joint_states()
        expected = theta0 * math.exp(-s * t) * (math.cos(wd * t) + s / wd * math.sin(wd * t))
        assert js.position[0] == pytest.approx(expected, abs=1e-8 * theta0)  # theta0^3 nonlinearity
        assert js.effort[0] == pytest.approx(-c * js.velocity[0], rel=1e-12)
    snap = sim.snapshot()
    assert snap.friction_work < 0
    assert abs(snap.energy_balance) < 1e-9 * snap.energy_scale


def spinning_top_with_a_limited_wheel() -> dict:
    """A heavy top turning on a fixed point with a wheel under every limit and friction term."""
    scene = wheel_scene("free", max_torque=0.03, max_speed=40.0,
                        friction={"coulomb": 0.002, "viscous": 1e-4, "static": 0.004, "stribeck_speed": 0.5})
    scene["gravity"] = [0.0, 0.0, -9.81]
    scene["bodies"][0]["com"] = [0.0, 0.0, 0.05]
    scene["bodies"][0]["initial"] = {"euler": [0.0, 0.3, 0.0], "euler_rates": [0.0, 0.0, 1.0]}
    return scene


@pytest.mark.parametrize("backend", BACKENDS)
def test_energy_balance_stays_at_integration_error_with_friction_and_commands(backend):
    sim = Simulator(spinning_top_with_a_limited_wheel(), integrator="dop853", rtol=1e-10, atol=1e-12, backend=backend)
    for value in (0.1, -0.01, 0.0):
        command(sim, value)
        sim.advance(0.5)
    snap = sim.snapshot()
    assert snap.friction_work < 0 and snap.saturated_commands == 1
    assert abs(snap.energy_balance) < 1e-8 * snap.energy_scale
    # the balance without friction's work is off by it: the dissipation is not hidden in W
    assert abs(snap.energy_balance + snap.friction_work) > 1e3 * abs(snap.energy_balance)
    values = messages.dynamics_values(snap)
    assert values[messages.FRICTION_WORK_KEY] == snap.friction_work
    assert values[messages.SATURATED_KEY] == 1.0


def basilisk_friction(omega, f_coulomb, c_viscous, f_static, beta, omega_limit):
    """Basilisk's reactionWheelStateEffector friction torque (its Stribeck branch when beta > 0),
    written from its source as published, limit cycle included."""
    def force(w):
        if beta > 0:
            return (math.sqrt(2.0 * math.exp(1.0)) * (f_static - f_coulomb) * math.exp(-(w / beta) ** 2 / 2.0)
                    * w / (beta * math.sqrt(2.0)) + f_coulomb * math.tanh(w * 10.0 / beta) + c_viscous * w)
        return math.copysign(f_coulomb, w) * (w != 0) + c_viscous * w
    if abs(omega) < omega_limit:
        return -force(omega_limit) / omega_limit * omega
    return -force(omega)


@pytest.mark.parametrize("stribeck", [True, False])
def test_friction_torque_is_basilisks(stribeck):
    friction = {"coulomb": 0.002, "viscous": 3e-5, "stick_speed": 1e-3}
    if stribeck:
        friction.update(static=0.005, stribeck_speed=0.2)
    sim = Simulator(wheel_scene("held", friction=friction), integrator="rk4", backend="numpy")
    axis = sim.model.actuators.rotor
    speeds = np.array([-50.0, -0.3, -0.2, -0.01, -5e-4, 0.0, 2e-4, 0.05, 0.2, 1.0, 300.0])
    expected = [basilisk_friction(w, 0.002, 3e-5, 0.005 if stribeck else 0.0, 0.2 if stribeck else -1.0, 1e-3)
                for w in speeds]
    got = [float(axis.friction(np.array([w]))[0]) for w in speeds]
    np.testing.assert_allclose(got, expected, rtol=1e-13, atol=1e-18)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.slow
def test_an_a_stable_fixed_step_brings_a_coulomb_wheel_to_rest(backend):
    """gauss4 at a step 60 times the stick region's time constant: the wheel stops, as the
    closed form says, and rests at zero speed (an explicit step this long chatters about it)."""
    tau_c, step = 0.05, 1e-3
    sim = Simulator(wheel_scene("free", friction={"coulomb": tau_c}), integrator="gauss4", step=step, backend=backend)
    J = effective_inertia("free")
    sim.advance(1.0)
    assert relative_spin(sim) == pytest.approx(OMEGA0 - tau_c * 1.0 / J, rel=1e-9)
    sim.advance(OMEGA0 * J / tau_c)  # past the stop
    assert abs(relative_spin(sim)) < 1e-12
    snap = sim.snapshot()
    assert abs(snap.energy_balance) < 1e-12 * snap.energy_scale
    assert J * 1e-4 / tau_c < step / 50  # the stick region's time constant (default stick_speed)


# --- refusals ---------------------------------------------------------------------------------------

def scene_errors(scene: dict) -> list[str]:
    with pytest.raises(SceneError) as info:
        load_scene(scene)
    return info.value.errors


@pytest.mark.parametrize("keys, where", [
    ({"max_torque": -1.0}, "bodies[0].rotors[0].max_torque: must be >= 0"),
    ({"max_speed": 0.0}, "bodies[0].rotors[0].max_speed: must be > 0"),
    ({"max_speed": float("inf")}, "bodies[0].rotors[0].max_speed: must be finite"),
    ({"friction": {"coulomb": float("nan")}}, "bodies[0].rotors[0].friction.coulomb: must be finite"),
    ({"friction": {"viscous": -1e-3}}, "bodies[0].rotors[0].friction.viscous: must be >= 0"),
    ({"friction": {"static": 0.1}}, "bodies[0].rotors[0].friction.stribeck_speed: required with static"),
    ({"friction": {"coulomb": 0.2, "static": 0.1, "stribeck_speed": 1.0}},
     "bodies[0].rotors[0].friction.static: must be >= coulomb"),
    ({"friction": {"stick_speed": 0.0}}, "bodies[0].rotors[0].friction.stick_speed: must be > 0"),
    ({"friction": {"dry": 0.1}}, "bodies[0].rotors[0].friction.dry: unknown key"),
])
def test_bad_limits_are_refused_naming_the_key(keys, where):
    errors = scene_errors(wheel_scene("held", **keys))
    assert any(e.startswith(where) for e in errors), errors


def test_limits_where_there_is_no_commanded_torque_are_refused():
    speed = wheel_scene("held", friction={"viscous": 1e-3})
    speed["bodies"][0]["rotors"][0].update(mode="speed", actuated=False)
    assert any(e.startswith("bodies[0].rotors[0].friction: a speed rotor's rate is prescribed")
               for e in scene_errors(speed))
    spherical = copy.deepcopy(wheel_scene("free"))
    spherical["bodies"][0]["joint"]["max_torque"] = 1.0
    assert any(e.startswith("bodies[0].joint.max_torque: not allowed for a spherical joint")
               for e in scene_errors(spherical))
    hinge = wheel_scene("held")
    hinge["bodies"][0]["joint"]["max_speed"] = 1.0
    assert any(e.startswith("bodies[0].joint.max_speed: unknown key") for e in scene_errors(hinge))


@pytest.mark.skipif(not kernel.available(), reason="numba missing")
@pytest.mark.parametrize("integrator", ["rk4", "dop853", "radau", "gauss4"])
@pytest.mark.slow
def test_the_compiled_kernel_integrates_the_actuators_as_the_reference(integrator):
    """Same motion, efforts and works on both backends, to round-off."""
    runs = []
    for backend in ("numpy", "numba"):
        sim = Simulator(spinning_top_with_a_limited_wheel(), integrator=integrator, rtol=1e-10, atol=1e-12,
                        backend=backend)
        for value in (0.1, -0.01):
            command(sim, value)
            sim.advance(0.3)
        runs.append((sim.state, sim.snapshot()))
    (y_ref, ref), (y, snap) = runs
    np.testing.assert_allclose(y, y_ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(snap.effort, ref.effort, rtol=0, atol=1e-15)
    assert snap.friction_work == pytest.approx(ref.friction_work, rel=1e-12)


def test_speed_dependent_terms_refuse_the_structured_integrators():
    scene = wheel_scene("held", friction={"viscous": 1e-3})
    for name in ("gauss4s", "lie4"):
        with pytest.raises(ActuatorError, match=rf"^wheel\.friction: integrator '{name}'"):
            Simulator(scene, integrator=name, backend="numpy")


def test_a_scene_without_limits_keeps_the_held_spin_layout():
    sim = Simulator(wheel_scene("held"), integrator="rk4", backend="numpy")
    assert sim.model.actuators is None and not sim.model.stateful
    assert sim.model.size == sim.model.i_kappa.stop
    assert sim.snapshot().friction_work is None
    assert messages.FRICTION_WORK_KEY not in messages.dynamics_values(sim.snapshot())


@pytest.mark.slow
def test_the_cli_refuses_a_method_the_actuators_do_not_take_in_one_line(tmp_path):
    import subprocess
    import sys

    import yaml

    scene = tmp_path / "wheel.yaml"
    scene.write_text(yaml.safe_dump(wheel_scene("held", friction={"viscous": 1e-3})), encoding="utf-8")
    run = subprocess.run([sys.executable, "-m", "gyro_sim.cli", "run", "--scene", str(scene), "--duration", "0.1",
                          "--integrator", "gauss4s"], capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert run.returncode == 2, run.stderr
    # a cold numba cache adds the compile's lines before it (gyro_sim.warmup)
    assert "Traceback" not in run.stderr
    assert [line for line in run.stderr.splitlines() if "wheel.friction" in line] == [
        "gyro-sim run: wheel.friction: integrator 'gauss4s' does not take speed-dependent actuator terms "
        "(friction, max_speed); use one of auto, dop853, fixed, gauss4, radau, rk4"]
