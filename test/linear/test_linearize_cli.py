"""`gyro-sim linearize`: the report, its JSON, and bad input refused in one line with exit 2."""
import json
import math

import pytest

from gyro_sim.cli import main


def test_upright_reaction_wheel_pendulum_is_unstable_and_controllable(tmp_path, capsys):
    state = tmp_path / "up.yaml"
    state.write_text(f"pendulum: {{angle: {math.pi!r}, rate: 0.0}}\n")
    assert main(["linearize", "imu_pendulum", "--state", str(state), "--discrete", "0.01", "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["state_names"] == ["pendulum", "pendulum_rate", "wheel_spin"]
    assert r["input_names"] == ["pendulum", "wheel"]
    assert r["is_equilibrium"] and r["verdict"] == "unstable" and r["controllability_rank"] == 3
    top = r["eigenvalues"][0]
    assert top["real"] > 0 and top["time_constant_s"] == pytest.approx(1 / top["real"])
    assert r["discrete"]["spectral_radius"] == pytest.approx(math.exp(0.01 * top["real"]), rel=1e-9)


def test_text_report_names_the_verdict_and_the_time(capsys):
    assert main(["linearize", "imu_pendulum"]) == 0
    out = capsys.readouterr().out
    assert "verdict: none, not an equilibrium" in out and "controllability rank: 3 of 3" in out
    assert "took" in out and "frequency Hz" in out


@pytest.mark.parametrize("content, words", [
    ("pend: {angle: 1.0}\n", "no body named 'pend'"),
    ("pendulum: {angle: .nan}\n", "angle"),
    ("- 1\n- 2\n", "must map body names"),
])
def test_a_bad_state_file_is_refused_in_one_line(tmp_path, capsys, content, words):
    f = tmp_path / "s.yaml"
    f.write_text(content)
    assert main(["linearize", "imu_pendulum", "--state", str(f)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and words in err and err.startswith("gyro-sim linearize:")


def test_a_missing_scene_and_a_bad_step_are_refused_in_one_line(capsys):
    assert main(["linearize", "no_such_scene"]) == 2
    assert main(["linearize", "imu_pendulum", "--discrete", "-1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "no_such_scene" in err[0] and "--discrete" in err[1]


def test_a_chain_too_long_for_a_dense_model_is_refused_in_one_line(tmp_path, capsys):
    import yaml

    from gyro_sim.bench.scenes import spherical_chain

    f = tmp_path / "long.yaml"
    f.write_text(yaml.safe_dump(spherical_chain(501)))  # 6 states per body: 3006
    assert main(["linearize", str(f)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "3006 states" in err


def test_the_frame_chart_needs_its_rate(capsys):
    assert main(["linearize", "heavy_top", "--chart", "frame"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "frame_rate" in err
    assert main(["linearize", "heavy_top", "--chart", "frame", "--frame-rate", "0", "0", "-3", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["chart"] == "frame"


SERVO_ARM = """<mujoco><option gravity="0 0 -9.81"/><worldbody>
<body name="upper"><joint name="shoulder" type="hinge" axis="0 1 0"/>
<geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03" mass="1"/>
<body name="lower" pos="0.3 0 0"><joint name="elbow" type="hinge" axis="0 1 0"/>
<geom type="capsule" fromto="0 0 0 0.25 0 0" size="0.03" mass="0.6"/>
<body name="tip" pos="0.25 0 0"><joint name="finger" type="slide" axis="1 0 0"/>
<geom type="sphere" size="0.02" mass="0.05"/></body></body></body></worldbody>
<actuator><position name="a_shoulder" joint="shoulder" kp="200" kv="20"/>
<position name="a_elbow" joint="elbow" kp="100" kv="10"/></actuator>
<tendon><fixed name="bad"><joint joint="finger" coef="1"/></fixed></tendon>
<keyframe><key name="home" qpos="0.4 -0.7 0" ctrl="0.4 -0.7"/></keyframe></mujoco>"""


@pytest.mark.slow
def test_a_models_keyframe_controls_and_locks_are_those_of_the_simulator(tmp_path, capsys):
    """A servo arm linearised at its keyframe: the servos hold their controls (the keyframe's
    ctrl), as `Simulator.linearize()` of the same scene does; `--lock` takes its finger; the
    eigenvalues are the simulator's, every one damped, and the residual is gravity's sag only."""
    pytest.importorskip("mujoco", reason="MJCF import needs MuJoCo (the [models] extra)")
    from gyro_sim import Simulator, load_scene

    path = tmp_path / "arm.xml"
    path.write_text(SERVO_ARM)
    assert main(["linearize", str(path), "--keyframe", "home", "--lock", "finger", "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    sim = Simulator(load_scene(path, keyframe="home", lock=["finger"]), backend="numpy")
    ev = sorted(sim.linearize().eigenvalues(), key=lambda e: (e.real, e.imag))
    got = sorted((complex(e["real"], e["imag"]) for e in r["eigenvalues"]), key=lambda e: (e.real, e.imag))
    assert got == pytest.approx(ev, rel=1e-9, abs=1e-9) and r["largest_real_part"] < 0
    # away from equilibrium by gravity's sag only: at zero controls the servos would pull too
    held = sim.linearize().equilibrium_residual
    assert r["equilibrium_residual"] == pytest.approx(held, rel=1e-9)
    sim.set_controls({"shoulder": 0.0, "elbow": 0.0})
    assert sim.linearize().equilibrium_residual > 2 * held


def test_every_problem_of_a_refused_model_is_listed(tmp_path, capsys):
    """A model refused for several reasons lists them all, as `gyro-sim run` does."""
    pytest.importorskip("mujoco", reason="MJCF import needs MuJoCo (the [models] extra)")
    path = tmp_path / "arm.xml"
    path.write_text(SERVO_ARM.replace('<key name="home"', '<key name="home2" qpos="0 0 0"/><key name="home"'))
    assert main(["linearize", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("gyro-sim linearize:") and "tendon 'bad'" in err
