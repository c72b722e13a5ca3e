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
