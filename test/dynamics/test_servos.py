"""A hinge's servo (docs/models.md, "Servo actuators"): the compiled kernel against the numpy
reference (both eliminations, with friction and springs), closed forms (the steady state
against gravity, a critically damped servo, the ranges' clips, the linearisation's
eigenvalues), the scene's refusals, and scenes without servos unchanged."""
import copy
import re
import math

import numpy as np
import pytest
from scipy.optimize import brentq

from gyro_sim import Simulator, load_scene
from gyro_sim.dynamics import kernel as fast
from gyro_sim.dynamics.model import compile_model, initial_state
from gyro_sim.dynamics.system import ChainODE, FastChainODE
from gyro_sim.scene.load import SceneError

from test.dynamics.test_joint_terms import with_joint_terms
from test.dynamics.test_kernel import assert_rhs_equal, chain_scene

needs_numba = pytest.mark.skipif(not fast.available(), reason="numba is not installed")

#: the pendulum: mass M at L below its hinge (about y), its own inertia I_COM about the axis
M, L, I_COM, G = 1.3, 0.4, 0.01, 9.81
I_HINGE = I_COM + M * L * L


def pendulum(servo: dict, gravity: bool = True, angle: float = 0.0, rate: float = 0.0) -> dict:
    return {"name": "servo pendulum", "base": {"type": "fixed"},
            "gravity": [0.0, 0.0, -G] if gravity else None,
            "bodies": [{"name": "rod", "joint": {"type": "hinge", "axis": [0.0, 1.0, 0.0], "servo": servo},
                        "mass": M, "com": [0.0, 0.0, -L],
                        "inertia_com": [[0.02, 0, 0], [0, I_COM, 0], [0, 0, 0.015]],
                        "initial": {"angle": angle, "rate": rate}}]}


def position_servo(kp: float, kv: float, gear: float = 1.0, **ranges) -> dict:
    """MuJoCo's <position kp kv gear>: gain kp, bias (0, -kp, -kv) (on the actuator's length
    gear phi)."""
    return {"gain": kp, "bias": [0.0, -kp, -kv], "gear": gear, **ranges}


def with_servos(scene: dict, seed: int) -> dict:
    """`scene` with a random servo on every hinge (and `with_joint_terms`' armature and spring)."""
    scene = with_joint_terms(scene, seed)
    rng = np.random.default_rng(seed + 100)
    for b in scene["bodies"]:
        if b["joint"]["type"] == "hinge":
            b["joint"]["servo"] = {"gain": float(rng.uniform(0.5, 5)), "bias": rng.normal(size=3).tolist(),
                                   "gear": float(rng.uniform(0.5, 2)), "force_range": [-1.0, 1.5]}
    return scene


@needs_numba
@pytest.mark.parametrize("base", ["fixed", "free"])
@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("heavy", [False, True])
@pytest.mark.parametrize("friction", [False, True])
def test_kernel_equals_reference(seed, base, heavy, friction):
    """The servos' moments in both eliminations (a 1e3 x heavier tip takes the square-root
    form), with friction on the hinges or not, random drives and states
    (clipped by the force range or not)."""
    scene = with_servos(chain_scene(seed, base, n=5), seed)
    for b in scene["bodies"]:
        if friction and b["joint"]["type"] == "hinge":
            b["joint"]["friction"] = {"viscous": 0.1}
    if heavy:
        tip = scene["bodies"][-1]
        tip["mass"] *= 1e3
        tip["inertia_com"] = (np.asarray(tip["inertia_com"]) * 1e3).tolist()
    model = compile_model(load_scene(scene))
    assert model.servo is not None and model.stateful  # a servo's work is a state
    rng = np.random.default_rng(seed)
    ref, comp = ChainODE(model), FastChainODE(model)
    drive = rng.normal(size=len(model.hinge_bodies))
    for ode in (ref, comp):
        ode.hold(0.1, ref.spins(0.1), drive, None)
    for _ in range(3):
        y = initial_state(model) + rng.normal(size=model.size) * 0.3
        assert_rhs_equal(model, ref.rhs(0.4, y), comp.rhs(0.4, y), rtol=1e-9 if heavy else 1e-12)


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_position_servo_settles_against_gravity(backend):
    """A damped position servo holding the pendulum out settles where kp (ctrl - phi) equals
    the gravity moment M G L sin(phi) (to 1e-9), and publishes that moment as its effort."""
    kp, kv, ctrl = 20.0, 4.0, 0.8
    sim = Simulator(pendulum(position_servo(kp, kv)), integrator="radau", backend=backend, rtol=1e-12,
                    atol=1e-12)
    sim.set_controls([ctrl])
    sim.advance(30.0)
    phi = brentq(lambda q: kp * (ctrl - q) - M * G * L * math.sin(q), 0.0, ctrl)
    state = sim.joint_states()
    assert abs(state.position[0] - phi) < 1e-9 and abs(state.velocity[0]) < 1e-9
    assert abs(state.effort[0] - M * G * L * math.sin(phi)) < 1e-8


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_critically_damped_servo_follows_the_closed_form(backend):
    """In zero gravity, g^2 kv = 2 sqrt(g^2 kp I) (a gear g: the joint sees g^2 kp, g^2 kv):
    phi(t) = c + (e0 + (v0 + w e0) t) exp(-w t), w = g sqrt(kp / I), e0 = phi0 - c, to 1e-10."""
    kp, gear, ctrl, phi0, v0 = 5.0, 1.5, 0.6, -0.4, 1.2
    kv = 2.0 * math.sqrt(kp * I_HINGE) / gear
    sim = Simulator(pendulum(position_servo(kp, kv, gear), gravity=False, angle=phi0, rate=v0),
                    backend=backend, rtol=1e-12, atol=1e-12)
    # the servo's target on the joint is ctrl / gear: its length gear phi follows ctrl
    sim.set_controls({"rod": ctrl})
    w, c = gear * math.sqrt(kp / I_HINGE), ctrl / gear
    e0 = phi0 - c
    for t in (0.1, 0.3, 0.7, 1.5):
        sim.advance(t - sim.time)
        exact = c + (e0 + (v0 + w * e0) * t) * math.exp(-w * t)
        assert abs(sim.joint_states().position[0] - exact) < 1e-10


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_ranges_clip_the_control_and_the_force(backend):
    """A control beyond ctrl_range acts as its bound (the servo settles there in zero gravity);
    a force beyond force_range is clipped: the acceleration from rest is gear F_max / I exactly,
    and the effort gear F_max."""
    servo = position_servo(10.0, 2.0, ctrl_range=[-0.5, 0.5])
    sim = Simulator(pendulum(servo, gravity=False), backend=backend, rtol=1e-12, atol=1e-12)
    sim.set_controls([2.0])
    assert sim.controls[0] == 2.0  # as set; the servo clips it
    sim.advance(20.0)
    assert abs(sim.joint_states().position[0] - 0.5) < 1e-9
    gear, f_max = 2.0, 0.3
    servo = position_servo(100.0, 0.0, gear, force_range=[-0.1, f_max])
    sim = Simulator(pendulum(servo, gravity=False), backend=backend)
    sim.set_controls([1.0])
    udot = sim.held_rhs()(0.0, sim.state)[sim.model.i_vel]
    assert udot[0] == pytest.approx(gear * f_max / I_HINGE, rel=1e-14)
    assert sim.joint_states().effort[0] == pytest.approx(gear * f_max, rel=1e-15)
    sim.set_controls([-1.0])
    assert sim.joint_states().effort[0] == pytest.approx(-gear * 0.1, rel=1e-15)


@pytest.mark.parametrize("gear", [1.0, 2.0])
def test_linearized_servo_pendulum_has_the_closed_form_eigenvalues(gear):
    """Hanging at rest: I s^2 + g^2 kv s + g^2 kp + M G L = 0, and B's column on the control
    is (0, g kp / I), named after the servo."""
    kp, kv = 6.0, 0.5
    sim = Simulator(pendulum(position_servo(kp, kv, gear)), backend="numpy")
    lin = sim.linearize()
    assert lin.input_names == ("rod",)
    expected = np.sort_complex(np.roots([I_HINGE, gear ** 2 * kv, gear ** 2 * kp + M * G * L]))
    np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(lin.A)), expected, rtol=1e-12)
    np.testing.assert_allclose(lin.B[:, 0], [0.0, gear * kp / I_HINGE], rtol=1e-12, atol=1e-15)


def test_linearize_takes_the_control_clip_one_sided():
    """A control beyond its range, or a force beyond its range: the column of B is zero (the
    clip's flat side), and the notes say so."""
    sim = Simulator(pendulum(position_servo(6.0, 0.5, ctrl_range=[-0.2, 0.2])), backend="numpy")
    sim.set_controls([0.5])
    lin = sim.linearize()
    assert np.all(lin.B == 0.0)
    assert any("control 0.5 beyond its ctrl_range [-0.2, 0.2]" in note for note in lin.notes)
    sim = Simulator(pendulum(position_servo(6.0, 0.5, force_range=[-0.1, 0.1])), backend="numpy")
    sim.set_controls([0.5])
    lin = sim.linearize()
    assert np.all(lin.B == 0.0) and any("force 3 at or beyond its force_range" in note for note in lin.notes)


def test_set_controls_by_name_and_refusals():
    scene = pendulum(position_servo(1.0, 0.1))
    scene["bodies"][0]["joint"]["servo"]["name"] = "lift"
    sim = Simulator(scene, backend="numpy")
    assert sim.control_names == ("lift",) and sim.axis_names == []
    sim.set_controls({"rod": 0.25})  # by joint name
    assert sim.controls.tolist() == [0.25]
    sim.set_controls({"lift": -0.5})
    assert sim.controls.tolist() == [-0.5]
    with pytest.raises(ValueError, match="no servo named 'elbow'"):
        sim.set_controls({"elbow": 1.0})
    with pytest.raises(ValueError, match="finite"):
        sim.set_controls([math.nan])
    with pytest.raises(ValueError, match="expected 1 controls"):
        sim.set_controls([1.0, 2.0])
    sim.reset()
    assert sim.controls.tolist() == [0.0]
    with pytest.raises(ValueError, match="does not take servos"):
        Simulator(scene, integrator="gauss4s", backend="numpy")


@pytest.mark.parametrize("servo, where", [
    ({"gain": 1.0, "gear": 0.0}, "servo.gear: must not be zero"),
    ({"gain": 1.0, "ctrl_range": [1.0, -1.0]}, "servo.ctrl_range: must be [low, high]"),
    ({"gain": 1.0, "bias": [1.0, 2.0]}, "servo.bias: must have 3 components"),
    ({"gain": 1.0, "kp": 3.0}, "servo.kp: unknown key"),
])
def test_bad_servos_are_refused_naming_the_key(servo, where):
    with pytest.raises(SceneError, match=re.escape(where)):
        load_scene(pendulum(servo))


def test_servo_with_max_torque_on_a_spherical_joint_or_twice_named_is_refused():
    scene = pendulum(position_servo(1.0, 0.1))
    scene["bodies"][0]["joint"]["max_torque"] = 2.0
    with pytest.raises(SceneError, match="max_torque: not allowed with a servo"):
        load_scene(scene)
    scene = pendulum(position_servo(1.0, 0.1))
    scene["bodies"][0]["joint"] = {"type": "spherical", "servo": {"gain": 1.0}}
    with pytest.raises(SceneError, match="servo: not allowed for a spherical joint"):
        load_scene(scene)
    scene = chain_scene(0, "fixed", n=4)
    hinges = [b for b in scene["bodies"] if b["joint"]["type"] == "hinge"]
    for b in hinges[:2]:
        b["joint"]["servo"] = {"name": "same"}
    if len(hinges) >= 2:
        with pytest.raises(SceneError, match="duplicate servo name 'same'"):
            load_scene(scene)


def test_scene_without_servos_takes_no_servo_path():
    """Without servos the model has none and the kernel's flag is off: the kernel reads no
    servo term and the held moments are the axes' as before."""
    plain = chain_scene(3, "free", n=4)
    model = compile_model(load_scene(copy.deepcopy(plain)))
    assert model.servo is None and fast.chain_model(model).flags[fast.FLAG_SERVOS] == 0


def pendulum_energy(phi: float, rate: float) -> float:
    """The pendulum's energy in closed form: 1/2 I phi'^2 - M G L cos(phi) (its centre of mass
    at -L (sin phi, 0, cos phi) turned about y)."""
    return 0.5 * I_HINGE * rate * rate - M * G * L * math.cos(phi)


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_a_servos_work_closes_the_energy_balance(backend):
    """A damped, geared position servo with a force range tracking a moving target: the energy
    in closed form changes by the work `Simulator.work` integrates (the servo's force x the
    joint rate) to 1e-9 of the work done, and the snapshot's balance E - E0 - W says the same;
    without the servo's work the balance would miss by that work, which is large."""
    kp, kv, gear = 12.0, 0.8, 1.5
    sim = Simulator(pendulum(position_servo(kp, kv, gear, force_range=[-3.0, 3.0]), angle=0.2),
                    integrator="dop853", rtol=1e-12, atol=1e-12, backend=backend)
    e0 = pendulum_energy(0.2, 0.0)
    worst = swing = 0.0
    clipped = False
    for _ in range(300):  # 3 s in 10 ms holds of the target 1.2 sin(2 t)
        sim.set_controls([1.2 * math.sin(2.0 * sim.time)])
        sim.advance(0.01)
        state = sim.joint_states()
        clipped |= abs(state.effort[0]) == 3.0 * gear
        change = pendulum_energy(state.position[0], state.velocity[0]) - e0
        worst = max(worst, abs(change - sim.work))
        swing = max(swing, abs(sim.work))
    snap = sim.snapshot(bodies=False, wrenches=False)
    assert swing > 1.0 and worst < 1e-9 * swing, (worst, swing)
    assert abs(snap.energy_balance) < 1e-9 * swing and snap.energy_scale > 0.0
    assert clipped  # the force range was reached
    assert "energy" not in snap.drift  # not conserved: the servo works on the chain


def test_a_servo_arms_energy_error_is_watched_by_the_fixed_integrator():
    """The node's default integrator at 1 kHz on the servo pendulum: the balance is reported
    and small against the work done (the watchdog's energy error is the servo's too)."""
    sim = Simulator(pendulum(position_servo(12.0, 0.8, 1.5)), integrator="fixed", step=1e-3)
    worst = swing = 0.0
    for _ in range(200):
        sim.set_controls([1.2 * math.sin(2.0 * sim.time)])
        sim.advance(0.01)
        snap = sim.snapshot(bodies=False, wrenches=False)
        state = sim.joint_states()
        change = pendulum_energy(state.position[0], state.velocity[0]) - pendulum_energy(0.0, 0.0)
        worst = max(worst, abs(change - snap.work), abs(snap.energy_balance))
        swing = max(swing, abs(snap.work))
    assert swing > 1.0 and worst < 1e-6 * swing, (worst, swing)
