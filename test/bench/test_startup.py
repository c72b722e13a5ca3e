"""`gyro-sim bench startup`: its refusals, and its measuring functions against fake processes
whose wall and CPU time are known (a fake node that burns a known CPU time before it publishes,
a command that does): no venv is installed here."""
from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest

from gyro_sim.bench import startup
from gyro_sim.bench.procs import running
from gyro_sim.cli import main

#: CPU seconds the fake processes burn before they publish or end
BURN = 0.6
#: generous bound for a fake process on a busy machine (s)
TIMEOUT = 120.0
#: a node command that refuses its scene at once (exit 2)
NO_SCENE = [sys.executable, "-c", "import sys; print('no scene', file=sys.stderr); sys.exit(2)"]

BURN_CODE = f"""
import time
t0 = time.process_time()
while time.process_time() - t0 < {BURN}:
    pass
"""

#: a fake node: burns BURN s of CPU, then publishes JointState on /joint_states until killed
FAKE_NODE = BURN_CODE + """
import rclpy
from rclpy.node import Node
from sensor_msgs.msg import JointState

rclpy.init()
node = Node("fake_gyro_sim")
pub = node.create_publisher(JointState, "/joint_states", 10)
while rclpy.ok():
    pub.publish(JointState(name=["a"], position=[0.0]))
    rclpy.spin_once(node, timeout_sec=0.02)
"""


def test_a_directory_that_is_not_a_source_tree_is_refused_in_one_line(tmp_path, capsys):
    assert main(["bench", "startup", "--source", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a gyro_sim source tree" in err[0], err
    assert not any(tmp_path.iterdir())


def test_a_venv_without_python_is_refused_in_one_line(tmp_path, capsys):
    assert main(["bench", "startup", "--venv", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a virtual environment" in err[0], err


def test_an_existing_json_is_kept_without_force(tmp_path, capsys):
    out = tmp_path / "startup.json"
    out.write_text("mine")
    assert main(["bench", "startup", "--venv", str(tmp_path), "--json", str(out)]) == 2
    assert out.read_text() == "mine"
    assert "--force" in capsys.readouterr().err


def test_a_non_empty_keep_venv_directory_is_refused(tmp_path, capsys):
    (tmp_path / "something").write_text("x")
    assert main(["bench", "startup", "--keep-venv", str(tmp_path)]) == 2
    assert (tmp_path / "something").read_text() == "x"
    assert "not empty" in capsys.readouterr().err


def test_the_source_tree_is_found_from_the_package():
    root = startup.source_tree(None)
    if root is None:
        pytest.skip("gyro_sim is installed without its source tree")
    assert (root / "setup.py").is_file() and (root / "gyro_sim" / "bench" / "startup.py").is_file()


@pytest.mark.slow
def test_a_run_is_timed_to_its_end_with_its_cpu():
    t = startup.timed_run([sys.executable, "-c", BURN_CODE], dict(os.environ), timeout=TIMEOUT)
    assert t.cpu >= BURN
    assert t.wall >= BURN


def test_a_failing_run_is_an_error_with_its_last_line():
    with pytest.raises(startup.StartupError, match="exited 3: bad luck"):
        startup.timed_run([sys.executable, "-c", "import sys; print('bad luck', file=sys.stderr); sys.exit(3)"],
                          dict(os.environ), timeout=TIMEOUT)


def test_what_a_measured_process_leaves_running_is_ended(tmp_path):
    """A helper the measured process started (and left behind) does not run into the next case."""
    pid_file = tmp_path / "pid"
    code = ("import subprocess, sys\n"
            f"p = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(600)'])\n"
            f"open({str(pid_file)!r}, 'w').write(str(p.pid))\n")
    startup.timed_run([sys.executable, "-c", code], dict(os.environ), timeout=TIMEOUT)
    left = int(pid_file.read_text())
    end = time.monotonic() + TIMEOUT
    while running(left) and time.monotonic() < end:
        time.sleep(0.05)
    assert not running(left)


@pytest.mark.slow
def test_the_first_message_of_a_fake_node_is_timed_with_its_cpu(tmp_path):
    pytest.importorskip("rclpy")
    pytest.importorskip("sensor_msgs.msg")
    script = tmp_path / "fake_node.py"
    script.write_text(FAKE_NODE)
    env = startup.child_env(tmp_path / "venv", tmp_path / "cache", tmp_path)
    env["PATH"] = os.environ.get("PATH", "")
    env["PYTHONPATH"] = os.environ.get("PYTHONPATH", "")
    env["AMENT_PREFIX_PATH"] = os.environ.get("AMENT_PREFIX_PATH", sys.prefix)
    t = startup.first_message(sys.executable, [sys.executable, str(script)], env, timeout=TIMEOUT, settle=0)
    assert t.cpu >= BURN  # it published only after burning that much
    assert t.wall >= BURN


def test_the_minimal_rclpy_node_is_timed_as_the_node_is(tmp_path):
    pytest.importorskip("rclpy")
    pytest.importorskip("sensor_msgs.msg")
    env = dict(os.environ, ROS_DOMAIN_ID=str(startup.DOMAIN_BASE + os.getpid() % startup.DOMAIN_SPAN),
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_LOG_DIR=str(tmp_path))
    t = startup.first_message(sys.executable, [sys.executable, "-c", startup.MINIMAL_NODE], env, timeout=TIMEOUT,
                              settle=0)
    assert 0 < t.cpu and 0 < t.wall < TIMEOUT


@pytest.mark.slow
def test_a_subscriber_started_after_a_node_is_timed_from_its_subscription(tmp_path):
    pytest.importorskip("rclpy")
    pytest.importorskip("sensor_msgs.msg")
    script = tmp_path / "fake_node.py"
    script.write_text(FAKE_NODE.replace("while rclpy.ok():",
                                        f"import sys\nprint({startup.NODE_READY!r}, file=sys.stderr, flush=True)\n"
                                        "while rclpy.ok():"))
    env = dict(os.environ, ROS_DOMAIN_ID=str(startup.DOMAIN_BASE + os.getpid() % startup.DOMAIN_SPAN),
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_LOG_DIR=str(tmp_path))
    t = startup.late_subscriber(sys.executable, [sys.executable, str(script)], env, timeout=TIMEOUT, settle=0)
    assert 0 < t.wall < TIMEOUT and t.cpu != t.cpu  # no CPU time: NaN


def test_a_node_that_never_says_it_runs_is_an_error_for_the_late_subscriber(tmp_path):
    env = dict(os.environ, ROS_LOG_DIR=str(tmp_path))
    with pytest.raises(startup.StartupError, match=r"did not start \(exit 2\): no scene"):
        startup.late_subscriber(sys.executable, NO_SCENE, env, timeout=TIMEOUT, settle=0)


@pytest.mark.slow
def test_a_node_that_never_publishes_is_an_error(tmp_path):
    pytest.importorskip("rclpy")
    env = dict(os.environ, ROS_DOMAIN_ID=str(startup.DOMAIN_BASE + os.getpid() % startup.DOMAIN_SPAN),
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_LOG_DIR=str(tmp_path))
    with pytest.raises(startup.StartupError, match="no /joint_states message within 3 s"):
        startup.first_message(sys.executable, [sys.executable, "-c", "import time; time.sleep(600)"], env,
                              timeout=3.0, settle=0)


def test_a_node_that_ends_before_publishing_is_an_error_with_its_last_line(tmp_path):
    pytest.importorskip("rclpy")
    env = dict(os.environ, ROS_DOMAIN_ID=str(startup.DOMAIN_BASE + os.getpid() % startup.DOMAIN_SPAN),
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_LOG_DIR=str(tmp_path))
    with pytest.raises(startup.StartupError, match=r"ended \(exit 2\) before its first /joint_states: no scene"):
        startup.first_message(sys.executable, NO_SCENE, env, timeout=TIMEOUT, settle=0)


def test_the_table_shows_every_figure_with_the_machine():
    results = {"node": {"cold": {"wall": 18.25, "cpu": 15.5, "extra": {}},
                        "warm": {"wall": 1.21, "cpu": 0.9, "extra": {}}},
               "worker": {"cold": {"wall": 4.0, "cpu": 2.5, "extra": {"sweep_wall": 21.0, "client_cpu": 16.0}},
                          "warm": {"wall": 3.0, "cpu": 2.0, "extra": {"sweep_wall": 5.0, "client_cpu": 1.0}}}}
    text = startup.table(results, {"cores": 2, "load": 1.5}, "gyro-sim bench startup",
                         "2026-11-26")
    lines = text.splitlines()
    assert lines[0] == "2026-11-26, `gyro-sim bench startup`; 2 cores."
    node = next(x for x in lines if x.startswith("| `gyro_sim_node`"))
    assert node.split("|")[2:6] == [" 18.2 ", " 15.5 ", " 1.2 ", " 0.9 "]
    assert not any(x.startswith("| `gyro-sim run") for x in lines)  # not measured: not shown
    assert "21.0 s cold" in text and "16.0 s CPU" in text
    assert f"announced itself every {startup.ANNOUNCE_PERIOD:g} s" in text


def test_repeated_warm_starts_show_their_median_and_range_and_the_subscribers_period():
    results = {"node": {"cold": {"wall": 18.25, "cpu": 15.5, "extra": {}},
                        "warm": {"wall": 1.0, "cpu": 0.9, "extra": {"walls": [1.0, 3.31, 0.94]}}}}
    text = startup.table(results, {"cores": 2, "load": 1.5}, "c", "2026-11-26", 0.0)
    node = next(x for x in text.splitlines() if x.startswith("| `gyro_sim_node`"))
    assert node.split("|")[4] == " 1.0 (median of 3: 0.9 to 3.3) "
    assert "every 3 s (Fast DDS's default)" in text


def test_the_command_line_is_given_back(tmp_path):
    class Args:
        source, keep_venv, venv, parts = None, None, str(tmp_path), ["node"]
        warm_starts, announce_period = 1, startup.ANNOUNCE_PERIOD

    assert startup.command_of(Args) == f"gyro-sim bench startup --venv {tmp_path} --parts node"
    Args.warm_starts, Args.announce_period = 16, 0.0
    assert startup.command_of(Args).endswith("--parts node --warm-starts 16 --announce-period 0")


def test_a_process_stopped_with_sigint_is_gone():
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"], start_new_session=True)
    startup.stop(proc)
    assert proc.returncode is not None


def test_the_command_prints_the_table_and_writes_the_json(tmp_path, monkeypatch, capsys):
    """The command's flow on a venv already there, with the measurement replaced by known
    figures: the table printed, the same figures in --json, exit 0."""
    import json

    venv = tmp_path / "venv"
    (venv / "bin").mkdir(parents=True)
    (venv / "bin" / "python").write_text("")
    figures = {"run": {"cold": {"wall": 17.5, "cpu": 14.25, "extra": {}},
                       "warm": {"wall": 1.5, "cpu": 1.0, "extra": {}}}}
    asked = []
    monkeypatch.setattr(startup, "measure",
                        lambda v, parts, say, timeout, **kw: asked.append((v, parts, kw)) or figures)
    out = tmp_path / "startup.json"
    assert main(["bench", "startup", "--venv", str(venv), "--parts", "run", "--json", str(out)]) == 0
    assert asked == [(venv, ["run"], {"warm_starts": 1, "announce_period": startup.ANNOUNCE_PERIOD, "source": None})]
    printed = capsys.readouterr().out
    assert "| `gyro-sim run --scene hinge_chain --duration 2`, to its end | 17.5 | 14.2 | 1.5 | 1.0 |" in printed
    data = json.loads(out.read_text())
    assert data["results"] == figures and data["command"] == f"gyro-sim bench startup --venv {venv} --parts run"
    assert main(["bench", "startup", "--venv", str(venv), "--json", str(out)]) == 2  # kept without --force


def test_the_node_starts_show_their_real_time_factor_with_and_without_a_terminal():
    results = {"node": {"cold": {"wall": 3.25, "cpu": 2.0, "extra": {"rtf": 0.9991, "rtf_window": 10.0}},
                        "warm": {"wall": 1.0, "cpu": 0.9, "extra": {"rtf": 1.0004, "rtf_window": 10.0}}},
               "node_tty": {"cold": {"wall": 3.5, "cpu": 2.0, "extra": {"rtf": 0.995, "rtf_window": 10.0}},
                            "warm": {"wall": 1.1, "cpu": 0.9, "extra": {"rtf": 1.0, "rtf_window": 10.0}}}}
    text = startup.table(results, {"cores": 2, "load": 1.5}, "c", "2026-11-29")
    lines = text.splitlines()
    assert "| without a terminal | 3.2 | 0.999 | 1.0 | 1.000 |" in lines
    assert "| from a terminal | 3.5 | 0.995 | 1.1 | 1.000 |" in lines
    assert "over the 10 s after it" in text


def test_a_source_tree_is_measured_with_the_entry_points_its_setup_names(tmp_path):
    (tmp_path / "setup.py").write_text('"gyro_sim_node = pkg.start:main",\n"gyro-sim = pkg.cli:main",\n')
    run = startup.scripts(tmp_path / "venv", tmp_path)
    assert run["gyro_sim_node"][0] == str(tmp_path / "venv" / "bin" / "python")
    assert run["gyro_sim_node"][1:] == ["-c", "import sys; sys.argv[0] = 'gyro_sim_node'; from pkg.start import main; "
                                              "sys.exit(main())"]
    assert "from pkg.cli import main" in run["gyro-sim"][2]
    (tmp_path / "setup.py").write_text("")
    with pytest.raises(startup.StartupError, match="names no console script gyro_sim_node"):
        startup.scripts(tmp_path / "venv", tmp_path)


@pytest.mark.slow
def test_a_start_from_a_terminal_has_one_and_a_start_without_has_none(tmp_path):
    """The two starts the bench times: on a pseudo-terminal that is the process's controlling
    terminal, and with stdin /dev/null in a session of its own."""
    pytest.importorskip("rclpy")
    pytest.importorskip("sensor_msgs.msg")
    script = tmp_path / "fake_node.py"
    said = tmp_path / "tty"
    script.write_text(f"import os, sys\nopen({str(said)!r}, 'a').write(str(sys.stdin.isatty()) + "
                      f"str(os.isatty(0) and os.tcgetpgrp(0) == os.getpgrp()) + '\\n')\n" + FAKE_NODE)
    env = dict(os.environ, ROS_DOMAIN_ID=str(startup.DOMAIN_BASE + os.getpid() % startup.DOMAIN_SPAN),
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_LOG_DIR=str(tmp_path))
    for terminal in (True, False):
        startup.first_message(sys.executable, [sys.executable, str(script)], env, timeout=TIMEOUT, settle=0,
                              terminal=terminal)
    assert said.read_text().splitlines() == ["TrueTrue", "FalseFalse"]
