"""gyro_sim's ROS processes announce themselves every ANNOUNCE_PERIOD s through a Fast DDS
profile, unless the user configures Fast DDS or uses another middleware: the profile's
content, when it is applied and when not, and Fast DDS reading it without complaint."""
from __future__ import annotations

import os
import subprocess
import sys
import xml.etree.ElementTree as ET

import pytest

from gyro_sim.ros import discovery

NS = {"p": "http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"}
#: a generous bound for a process that creates one node and ends (s)
NODE_TIMEOUT = 120


def announcement_period(xml: str) -> float:
    root = ET.fromstring(xml)
    participant = root.find("p:participant", NS)
    assert participant.get("is_default_profile") == "true"
    period = participant.find("p:rtps/p:builtin/p:discovery_config/p:leaseAnnouncement", NS)
    nanosec = int(period.find("p:nanosec", NS).text)
    assert 0 <= nanosec < 1_000_000_000
    return int(period.find("p:sec", NS).text) + nanosec * 1e-9


@pytest.mark.parametrize("seconds", [0.2, 0.5, 1.5, 3.0])
def test_the_profile_gives_the_announcement_period(seconds):
    assert announcement_period(discovery.profile_xml(seconds)) == pytest.approx(seconds)


def test_the_shipped_profile_is_the_one_the_period_gives():
    assert discovery.PROFILE.read_text() == discovery.profile_xml(discovery.ANNOUNCE_PERIOD)
    assert announcement_period(discovery.PROFILE.read_text()) < 3.0  # Fast DDS's default


def test_it_is_applied_to_a_plain_environment(tmp_path):
    env = {"PATH": "/usr/bin"}
    assert discovery.announce_often(env, cwd=tmp_path)
    assert env["FASTRTPS_DEFAULT_PROFILES_FILE"] == str(discovery.PROFILE)
    env = {"RMW_IMPLEMENTATION": "rmw_fastrtps_cpp"}
    assert discovery.announce_often(env, cwd=tmp_path)


@pytest.mark.parametrize("setting", [{"FASTRTPS_DEFAULT_PROFILES_FILE": "/mine.xml"},
                                     {"FASTDDS_DEFAULT_PROFILES_FILE": "/mine.xml"},
                                     {"ROS_DISCOVERY_SERVER": "127.0.0.1:11811"},
                                     {"RMW_IMPLEMENTATION": "rmw_cyclonedds_cpp"}])
def test_a_users_configuration_or_another_middleware_is_left_alone(tmp_path, setting):
    env = dict(setting)
    assert not discovery.announce_often(env, cwd=tmp_path)
    assert env == setting


def test_a_profile_in_the_working_directory_is_left_alone(tmp_path):
    (tmp_path / "DEFAULT_FASTRTPS_PROFILES.xml").write_text("<profiles/>")
    env = {}
    assert not discovery.announce_often(env, cwd=tmp_path)
    assert env == {}


def test_fast_dds_reads_the_profile_without_complaint(tmp_path):
    """A node created with the profile applied: Fast DDS says nothing of it (it names an XML
    file it cannot parse or an element it does not know, on stdout)."""
    pytest.importorskip("rclpy")
    code = ("from gyro_sim.ros.discovery import announce_often\n"
            "assert announce_often()\n"
            "import rclpy\nrclpy.init()\nnode = rclpy.create_node('discovery_check')\n"
            "node.destroy_node()\nrclpy.shutdown()\nprint('ok')\n")
    env = {k: v for k, v in os.environ.items()
           if k not in discovery.PROFILE_VARIABLES + discovery.OTHER_DISCOVERY + ("RMW_IMPLEMENTATION",)}
    env.update(ROS_LOG_DIR=str(tmp_path), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    r = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True,
                       timeout=NODE_TIMEOUT)
    assert r.returncode == 0 and r.stdout.strip() == "ok", r.stdout + r.stderr
    assert "xml" not in r.stderr.lower() and "error" not in r.stderr.lower(), r.stderr


def test_a_profile_fast_dds_cannot_parse_is_said(tmp_path):
    """The check above can fail: Fast DDS reports a broken profile."""
    pytest.importorskip("rclpy")
    bad = tmp_path / "bad.xml"
    bad.write_text(discovery.profile_xml(0.5).replace("<leaseAnnouncement>", "<leaseAnnouncment>"))
    code = "import rclpy\nrclpy.init()\nnode = rclpy.create_node('discovery_check')\nprint('ok')\n"
    env = dict(os.environ, ROS_LOG_DIR=str(tmp_path), FASTRTPS_DEFAULT_PROFILES_FILE=str(bad))
    r = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True,
                       timeout=NODE_TIMEOUT)
    said = (r.stdout + r.stderr).lower()
    assert "xml" in said and "error" in said, (r.returncode, said)
