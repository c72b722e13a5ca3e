"""Crafted logs are refused in one line: embedded scene, parameters, schemas,
re-simulation work, and the packages `replay` imports."""
from __future__ import annotations

import importlib
import json
import re

import pytest

from gyro_sim.log.mcap_log import LogError, iter_messages, read_info
from gyro_sim.log.resim import MAX_RESIM_STEPS, resimulate

from test.conftest import gyro_sim
from test.log.crafted import rewrite


def _params(log) -> dict:
    return dict(read_info(log).params)


def _refused_in_one_line(log, *needles):
    r = gyro_sim("replay", "--resimulate", log)
    err = r.stderr.strip()
    assert r.returncode == 2, (r.returncode, err)
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    for n in needles:
        assert n in err, err


@pytest.mark.slow
def test_a_python_object_tag_in_the_embedded_scene_is_refused_and_never_run(recorded, tmp_path):
    log, _ = recorded
    marker = tmp_path / "pwned"
    text = f"!!python/object/apply:os.system ['touch {marker}']\n"
    bad = rewrite(log, tmp_path / "tag.mcap", scene_text=text)
    with pytest.raises(LogError, match="embedded scene does not load"):
        read_info(bad).scene()
    _refused_in_one_line(bad, "embedded scene")
    assert not marker.exists()


def test_a_deeply_nested_embedded_scene_is_refused(recorded, tmp_path):
    log, _ = recorded
    bad = rewrite(log, tmp_path / "deep.mcap", scene_text="[" * 50_000 + "]" * 50_000)
    with pytest.raises(LogError, match="nested deeper than"):
        read_info(bad).scene()


@pytest.mark.parametrize("params, needle", [
    ("null", "must be a JSON object"),
    ("{not json", "is not JSON"),
])
@pytest.mark.slow
def test_unreadable_parameters_are_refused(recorded, tmp_path, params, needle):
    log, _ = recorded
    bad = rewrite(log, tmp_path / "p.mcap", params_json=params)
    with pytest.raises(LogError, match=needle):
        read_info(bad)
    _refused_in_one_line(bad, needle)


@pytest.mark.parametrize("key, value", [("step", "abc"), ("advance_dt", -0.01), ("rtol", None),
                                        ("integrator", "no_such")])
@pytest.mark.slow
def test_bad_recorded_parameters_are_refused_naming_the_key(recorded, tmp_path, key, value):
    log, _ = recorded
    p = _params(log)
    p[key] = value
    bad = rewrite(log, tmp_path / "p.mcap", params_json=json.dumps(p))
    with pytest.raises(LogError, match=f"parameter {key}"):
        resimulate(bad)
    _refused_in_one_line(bad, key)


def test_a_recursive_schema_is_refused(recorded, tmp_path):
    log, _ = recorded
    loop = ("string data\nfoo_msgs/Loop loop\n" + "=" * 80 + "\nMSG: foo_msgs/Loop\nfoo_msgs/Loop next\n")
    bad = rewrite(log, tmp_path / "loop.mcap", schemas={"std_msgs/msg/String": loop})
    with pytest.raises(LogError, match="cannot read the messages"):
        list(iter_messages(bad))


def _nothing_simulated(monkeypatch):
    """Make any Simulator built from here on fail the test: a refusal must come first."""
    import gyro_sim.simulator as simulator

    def refuse(*a, **kw):
        raise AssertionError("a Simulator was built before the log was refused")

    monkeypatch.setattr(simulator, "Simulator", refuse)


@pytest.mark.parametrize("key, value, integrator", [
    ("advance_dt", 1e-12, None),  # 4e11 steps of advance_dt over the log's 0.4 s
    ("advance_dt", 1e-9, None),  # 4e8 steps
    ("step", 1e-12, "rk4"),  # a fixed-step integrator takes span / step steps whatever advance_dt is
])
@pytest.mark.slow
def test_a_tiny_step_is_refused_before_anything_runs(recorded, tmp_path, monkeypatch, key, value, integrator):
    log, _ = recorded
    p = _params(log)
    p[key] = value
    if integrator:
        p["integrator"] = integrator
    bad = rewrite(log, tmp_path / "dt.mcap", params_json=json.dumps(p))
    span = read_info(bad).end_ns / 1e9
    assert span / value > MAX_RESIM_STEPS  # the case really is beyond the bound
    _nothing_simulated(monkeypatch)  # refused before any step: no Simulator may even be built
    with pytest.raises(LogError, match=re.escape(f"the limit is {MAX_RESIM_STEPS:.0e}")):
        resimulate(bad)
    monkeypatch.undo()
    _refused_in_one_line(bad, "limit")


@pytest.mark.slow
def test_a_joint_state_stamped_far_in_the_future_cannot_hang_resimulation(recorded, tmp_path, monkeypatch):
    log, _ = recorded
    bad = rewrite(log, tmp_path / "future.mcap",
                  retime=lambda topic, i, t: 10**18 if (topic == "/joint_states" and i == 3) else t)
    # the log's own span (its statistics) already says so: refused before any Simulator is built
    _nothing_simulated(monkeypatch)
    with pytest.raises(LogError, match=r"the log's 1e\+09 s at advance_dt = 0\.005 s would take 2e\+11 steps"):
        resimulate(bad)
    monkeypatch.undo()
    _refused_in_one_line(bad, "limit")


@pytest.mark.parametrize("topic, needle", [
    ("/clock", "carries rosgraph_msgs/msg/Clock, not std_msgs/msg/Float64MultiArray"),
    ("/joint_states", "is the topic of sensor_msgs/msg/JointState"),
    ("/gyro_sim/events", "is the topic of std_msgs/msg/String"),
    ("/robot_description", "carries std_msgs/msg/String, not std_msgs/msg/Float64MultiArray"),
])
@pytest.mark.slow
def test_a_commands_topic_of_another_type_is_refused(recorded, tmp_path, monkeypatch, topic, needle):
    log, _ = recorded
    p = _params(log)
    p["commands_topic"] = topic
    bad = rewrite(log, tmp_path / "topic.mcap", params_json=json.dumps(p))
    _nothing_simulated(monkeypatch)
    with pytest.raises(LogError, match=re.escape(needle)):
        resimulate(bad)
    monkeypatch.undo()
    _refused_in_one_line(bad, "commands_topic", needle)


@pytest.mark.slow
def test_a_schema_without_the_fields_of_its_type_is_refused_in_one_line(recorded, tmp_path):
    log, _ = recorded
    bad = rewrite(log, tmp_path / "fields.mcap", schemas={"std_msgs/msg/Float64MultiArray": "int32 other\n"})
    with pytest.raises(LogError, match="has no field data"):
        resimulate(bad)
    _refused_in_one_line(bad, "has no field data")


def test_replay_imports_only_message_packages(monkeypatch):
    from gyro_sim.ros import replay

    imported = []

    def fake_import(name, *a, **kw):
        imported.append(name)
        return type("Module", (), {"JointState": "cls", "Time": "cls", "Clock": "cls"})

    monkeypatch.setattr(importlib, "import_module", fake_import)
    for msgtype in ("os/msg/System", "subprocess/msg/Popen", "evil_msgsx/msg/X", "Sensor_msgs/msg/JointState",
                    "sensor_msgs/srv/JointState", "sensor_msgs/msg/joint_state", "a/b/c/d", "x_msgs/msg/../y"):
        with pytest.raises(ValueError):
            replay.message_class(msgtype)
    assert imported == []
    for msgtype in ("sensor_msgs/msg/JointState", "builtin_interfaces/msg/Time", "rosgraph_msgs/msg/Clock"):
        assert replay.message_class(msgtype) == "cls"
    assert imported == ["sensor_msgs.msg", "builtin_interfaces.msg", "rosgraph_msgs.msg"]
