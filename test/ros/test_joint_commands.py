"""~/joint_commands without ROS: the physics loop takes a servo's control from a JointState by
joint name (position -> a position servo's control), one control period per command in
lock-step, the same states as the Simulator stepped offline with the logged commands, bit for
bit; refusals as events; joint commands and axis moments neither superseding the other."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from gyro_sim.msgs import messages as M
from gyro_sim.ros.loop import SimLoop, warm_up
from gyro_sim.ros.requests import Reset
from gyro_sim.ros.params import validate
from gyro_sim.simulator import Simulator

from .test_lockstep import run
from .test_pacing import FakeClock, Outputs

#: a pendulum (mass M at L below its hinge) held by a damped position servo; a second hinge with
#: a commanded axis moment beyond it
M_, L_, G_, KP, KV, TARGET = 1.0, 0.3, 9.81, 20.0, 3.0, 0.5


def scene_file(tmp_path, **servo) -> str:
    """The scene; `servo`: more keys of the arm's servo."""
    import yaml

    scene = {"name": "servo pendulum", "gravity": [0.0, 0.0, -G_], "base": {"type": "fixed"},
             "bodies": [{"name": "arm", "joint": {"type": "hinge", "axis": [0.0, 1.0, 0.0],
                                                  "servo": {"name": "arm_pos", "gain": KP, "bias": [0.0, -KP, -KV],
                                                            **servo}},
                         "mass": M_, "com": [0.0, 0.0, -L_], "inertia_com": [[0.01, 0, 0], [0, 0.01, 0], [0, 0, 0.005]],
                         "next_joint": [0.0, 0.0, -2 * L_]},
                        {"name": "tip", "joint": {"type": "hinge", "axis": [1.0, 0.0, 0.0]},
                         "mass": 1e-3, "com": [0.0, 0.0, 0.0],
                         "inertia_com": [[1e-6, 0, 0], [0, 1e-6, 0], [0, 0, 1e-6]]}]}
    path = tmp_path / "servo.yaml"
    path.write_text(yaml.safe_dump(scene))
    return str(path)


class JointLog(Outputs):
    """The fake outputs, with the joint commands' log; in lock-step each state is answered by a
    joint command to TARGET."""

    def __init__(self, answers: int = 0):
        super().__init__()
        self.loop, self.answers = None, answers

    def record_joint_commands(self, t, raws):
        self.log += [("joint_command", t, raw) for raw in raws]

    def send(self, t, batch):
        super().send(t, batch)
        if self.answers > 0:
            self.answers -= 1
            raw = M.joint_command(["arm"], position=[TARGET])
            assert self.loop.submit_joint_command(raw, M.decode_joint_command(raw)) is None


def make(tmp_path, out, servo: dict | None = None, **params):
    cfg = validate({"scene": scene_file(tmp_path, **(servo or {})), "physics_rate": 1000.0, "publish_rate": 100.0,
                    "thread_priority": 0, **params})
    sim = Simulator(cfg.scene, integrator=cfg.integrator, step=cfg.dt)
    warm_up(sim, cfg.dt)
    clock = FakeClock()
    loop = SimLoop(sim, cfg, out, clock=clock, sleep=clock.sleep)
    out.loop = loop
    return loop, cfg


def replay(cfg, log, periods):
    """The joint states offline: the logged commands applied in file order at their log times
    (as gyro_sim.log.resim does), a control period between states."""
    sim = Simulator(cfg.scene, integrator=cfg.integrator, step=cfg.dt)
    warm_up(sim, cfg.dt)
    states = [np.array(sim.joint_states().position)]
    for k in range(periods):
        for kind, t, raw in log:
            if t == k * 10_000_000 and kind == "joint_command":
                sim.set_controls(sim.joint_command_controls(*M.decode_joint_command(raw)))
            elif t == k * 10_000_000 and kind == "command":
                sim.set_axis_moments(M.decode_axis_moments(raw))
        for _ in range(cfg.steps_per_publish):
            sim.advance(cfg.dt)
        states.append(np.array(sim.joint_states().position))
    return states


def test_a_position_target_by_joint_name_in_lockstep_reaches_the_servos_steady_state(tmp_path):
    """The servo settles where KP (TARGET - phi) equals the gravity moment (the tip's mass at 2 L
    with the arm's) G (M L + m 2 L) sin(phi) (to 1e-6 rad after 3 s), and
    the states are those of the logged commands replayed offline, bit for bit."""
    periods = 300
    out = JointLog(answers=periods)
    loop, cfg = make(tmp_path, out, lockstep=True)
    run(loop, lambda: len(out.states) >= periods + 1)
    assert len(out.states) == periods + 1
    assert [kind for kind, _, _ in out.log if kind != "event"] == ["joint_command"] * periods
    assert loop.sim.controls.tolist() == [TARGET]
    mgl = G_ * (M_ * L_ + 1e-3 * 2 * L_)
    phi = brentq(lambda q: KP * (TARGET - q) - mgl * math.sin(q), 0.0, TARGET)
    assert abs(out.states[-1][1][0] - phi) < 1e-6
    expected = replay(cfg, out.log, periods)
    for (_, got, _), want in zip(out.states, expected):
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("names, fields, reason", [
    (["elbow"], {"position": [0.1]}, "joint 'elbow': no servo drives it"),
    (["tip"], {"effort": [0.1]}, "joint 'tip': no servo drives it"),
    (["arm"], {"velocity": [0.1]}, "joint 'arm': its servo takes a position, the command has none"),
    (["arm", "arm"], {"position": [0.1, 0.2]}, "joint 'arm': given twice"),
    (["arm"], {"position": [0.1, 0.2]}, "position: 2 values for 1 names"),
])
def test_bad_joint_commands_are_refused_as_events_and_never_logged(tmp_path, names, fields, reason):
    out = JointLog()
    loop, _ = make(tmp_path, out)
    raw = M.joint_command(names, **fields)
    assert loop.submit_joint_command(raw, M.decode_joint_command(raw)).startswith(reason)
    assert loop.commands.counters.rejected == 1 and out.log[-1][0] == "event" and reason in out.log[-1][2]


def test_non_finite_and_undecodable_joint_commands_are_refused(tmp_path):
    out = JointLog()
    loop, _ = make(tmp_path, out)
    w = M.CdrWriter()
    M._joint_state(w, ["arm"], np.array([math.nan]), np.zeros(0), np.zeros(0), 0)
    raw = bytes(w)
    assert loop.submit_joint_command(raw, M.decode_joint_command(raw)) == "position: holds NaN or inf"
    assert loop.submit_joint_command(b"\x00\x01\x00\x00", None) == "not a sensor_msgs/JointState"
    with pytest.raises(ValueError):
        M.decode_joint_command(b"\x00\x01\x00\x00\x05")


def test_joint_commands_and_axis_moments_supersede_only_their_own_kind(tmp_path):
    """Before one step: a joint command, an axis moment, another joint command: the step applies
    the last of each kind, and the log holds all three in the order received."""
    out = JointLog()
    loop, _ = make(tmp_path, out, hold="until_command", command_timeout=1e6)
    first, second = M.joint_command(["arm"], position=[0.1]), M.joint_command(["arm"], position=[0.3])
    loop.submit_joint_command(first, M.decode_joint_command(first))
    loop.submit_command(M.axis_moments([0.25]), [0.25])
    loop.submit_joint_command(second, M.decode_joint_command(second))
    loop.commands.take(loop.sim, 0, 0)
    assert loop.sim.controls.tolist() == [0.3] and loop.sim.axis_moments.tolist() == [0.25]
    assert [kind for kind, _, _ in out.log] == ["joint_command", "command", "joint_command"]
    assert loop.commands.counters.superseded == 2


def test_a_servos_initial_control_holds_from_the_start_and_after_a_reset(tmp_path):
    """A servo's `control` is its control before any command and again after ~/reset (a joint
    command applied before the reset is gone), the pendulum held at the servo's steady state."""
    out = JointLog()
    loop, _ = make(tmp_path, out, servo={"control": TARGET}, lockstep=True)
    assert loop.sim.controls.tolist() == [TARGET]
    raw = M.joint_command(["arm"], position=[0.1])
    assert loop.submit_joint_command(raw, M.decode_joint_command(raw)) is None
    run(loop, lambda: len(out.states) >= 2)
    assert loop.sim.controls.tolist() == [0.1]
    assert loop._handle(Reset()).startswith("reset")
    assert loop.sim.controls.tolist() == [TARGET]
    # the next joint command's unnamed servos keep the reset's controls
    np.testing.assert_array_equal(loop.commands._controls_submitted, [TARGET])
