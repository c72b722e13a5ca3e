"""Invalid parameters stop the node at start, with a clear message, before anything is published."""
from __future__ import annotations

import subprocess

import pytest

pytest.importorskip("rclpy", reason="the ROS 2 node needs rclpy (pip install '.[ros]')")

from sensor_msgs.msg import JointState

from .helpers import ROOT, Client, new_domain_id, node_command, ros_env

CASES = {
    "physics_rate:=-5.0": "physics_rate: must be >= 1",
    "publish_rate:=300.0": "publish_rate: physics_rate / publish_rate = 3.33333 must be a whole number",
    "integrator:=euler": "integrator: unknown 'euler'; valid: rk4",
    "scene:=no_such_scene": "scene 'no_such_scene' not found (shipped scenes:",
    "record:=/no/such/dir/x.mcap": "record: directory /no/such/dir does not exist",
    "real_time_factor:=fast": "real_time_factor: expected a number, got 'fast'",
    "command_timeout:=0.0": "command_timeout: must be >= 0.001",
    "publish_poses:=3": "publish_poses:",
    "backend:=gpu": "backend: unknown 'gpu'; valid:",
}


@pytest.mark.slow
def test_invalid_parameters_refused_before_publishing(tmp_path):
    domain = new_domain_id()
    client = Client(domain)
    try:
        client.subscribe("/joint_states", JointState)
        env = ros_env(domain, tmp_path)
        procs = {arg: subprocess.Popen(node_command(arg, "duration:=30.0"), cwd=ROOT, env=env, text=True,
                                       stdout=subprocess.PIPE, stderr=subprocess.PIPE) for arg in CASES}
        for arg, p in procs.items():
            out, err = p.communicate(timeout=60)
            assert p.returncode == 2, (arg, p.returncode, err)
            assert "invalid parameters, nothing started" in err and CASES[arg] in err, (arg, err)
            assert "simulated" not in out  # refused before the 30 s run: exit 2, not the run's end
        # a bad scene file: the scene loader's message names the key
        bad = tmp_path / "bad.yaml"
        bad.write_text("name: x\nbase: {type: fixed}\nbodies:\n"
                       "  - {name: a, joint: {type: spherical}, mass: -1, inertia: {axial: 1, transverse: 1}}\n")
        r = subprocess.run(node_command(f"scene:={bad}"), cwd=ROOT, env=env, text=True, capture_output=True,
                           timeout=60)
        assert r.returncode == 2 and "bodies[0].mass" in r.stderr, r.stderr
        assert client.messages("/joint_states") == []
    finally:
        client.close()


@pytest.mark.slow
def test_shipped_params_file_runs(tmp_path):
    """config/params.yaml starts the node (a later -p overrides it) and a bounded run exits 0."""
    domain = new_domain_id()
    r = subprocess.run(node_command("duration:=0.3", "physics_rate:=200.0", "publish_rate:=20.0",
                                    params_file=ROOT / "config" / "params.yaml"),
                       cwd=ROOT, env=ros_env(domain, tmp_path), text=True, capture_output=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert "gyro_sim_node: simulated 0.300 s" in r.stdout
    assert "scene 'hinge chain with commanded moments" in r.stderr  # the node's log line (rclpy logs to stderr)


# --- no silent overwrite: record and stats_file checked at start --------------------------
def _validate(**values):
    from gyro_sim.ros.params import validate

    return validate(values)


def test_record_and_stats_file_that_exist_are_refused_unless_overwrite(tmp_path):
    from gyro_sim.ros.params import ParameterError

    for name in ("record", "stats_file"):
        old = tmp_path / f"old_{name}"
        old.write_bytes(b"previous")
        with pytest.raises(ParameterError, match=f"{name}: {old}: exists"):
            _validate(**{name: str(old)})
        assert _validate(**{name: str(old), "overwrite": True}).overwrite is True
        assert old.read_bytes() == b"previous"  # validation writes nothing


def test_record_that_is_the_scene_file_is_refused_even_with_overwrite(tmp_path):
    from gyro_sim.ros.params import ParameterError

    scene = tmp_path / "scene.yaml"
    scene.write_bytes((ROOT / "config" / "hinge_chain.yaml").read_bytes())
    link = tmp_path / "log.mcap"
    link.hardlink_to(scene)
    for name in ("record", "stats_file"):
        with pytest.raises(ParameterError, match="is the input"):
            _validate(scene=str(scene), overwrite=True, **{name: str(link)})


@pytest.mark.parametrize("target, needle", [
    (lambda d: d, "is a directory"),
    (lambda d: d / "missing" / "x.mcap", "does not exist"),
])
def test_record_and_stats_file_into_directories_are_refused(tmp_path, target, needle):
    from gyro_sim.ros.params import ParameterError

    for name in ("record", "stats_file"):
        with pytest.raises(ParameterError, match=f"{name}: .*{needle}"):
            _validate(**{name: str(target(tmp_path))})


@pytest.mark.slow
def test_the_node_refuses_an_existing_record_file_and_leaves_it_unchanged(tmp_path):
    old = tmp_path / "previous_log.mcap"
    old.write_bytes(b"a previous log")
    r = subprocess.run(node_command(f"record:={old}", "duration:=1.0"), cwd=ROOT,
                       env=ros_env(new_domain_id(), tmp_path), text=True, capture_output=True, timeout=60)
    assert r.returncode == 2, r.stderr
    assert f"record: {old}: exists" in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert old.read_bytes() == b"a previous log"
