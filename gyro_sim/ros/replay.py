"""`gyro-sim replay`: publish a log's topics again on ROS 2 at the recorded pace (like
``ros2 bag play``, which pip-installed ROS does not have).

The stored CDR bytes are published as they are (``Publisher.publish(bytes)``), each on its
topic with the type named by its schema (transient local where the channel's
``offered_qos_profiles`` says so: the robot description); /clock is one of the logged topics, so subscribers
using simulated time follow the replay. Message i goes out at wall time
``start + (log_time_i - log_time_0) / rate``. Types whose Python package is not installed
are skipped with a note (tf2_msgs is not on PyPI, so /tf is skipped unless ROS is installed
from apt).

A log names the Python packages replay imports (``<pkg>.msg`` of each schema): only message
packages are imported, a name matching ``MSG_PACKAGE`` or listed in ``MSG_PACKAGES``; any
other schema's topic is skipped. The log is verified first (:func:`.mcap_log.verify`).
"""
from __future__ import annotations

import importlib
import os
import re
import time
from dataclasses import dataclass, field

from gyro_sim.log.mcap_log import LogError, iter_messages, verify

#: depth of each publisher's queue
QOS_DEPTH = 100
#: sleeps longer than this are split so that the replay stays responsive to Ctrl-C
SLEEP_SLICE = 0.05
#: after every publisher has seen its subscriber, the subscribers may not have seen the
#: publishers yet (discovery is not symmetric): wait this long more before the first message
MATCH_SETTLE = 0.5
#: at the end, wait at most this long for the subscribers to acknowledge the last messages
#: (a publisher destroyed at once loses what is still in flight)
ACK_TIMEOUT = 2.0
#: a ROS message package: lower-case name ending in _msgs (``sensor_msgs``, ``tf2_msgs``)
MSG_PACKAGE = re.compile(r"[a-z][a-z0-9_]*_msgs\Z")
#: message packages whose names do not end in _msgs
MSG_PACKAGES = frozenset({"builtin_interfaces", "rosgraph_msgs", "std_srvs", "rcl_interfaces",
                          "unique_identifier_msgs", "statistics_msgs"})
#: a message type name (``Type`` of ``pkg/msg/Type``)
TYPE_NAME = re.compile(r"[A-Z][A-Za-z0-9]*\Z")


@dataclass
class ReplayStats:
    published: int = 0
    per_topic: dict = field(default_factory=dict)
    skipped: dict = field(default_factory=dict)  # topic -> why
    log_span: float = 0.0  # s of log time replayed (last pass)
    wall_span: float = 0.0  # s of wall time between its first and last message
    max_late: float = 0.0  # s, the latest a message went out after its due time
    loops: int = 0

    def report(self) -> str:
        lines = [f"published {self.published} messages on {len(self.per_topic)} topics, "
                 f"{self.log_span:.3f} s of log in {self.wall_span:.3f} s of wall time"
                 f" (at most {1e3 * self.max_late:.1f} ms late)" + (f", {self.loops} passes" if self.loops > 1 else "")]
        for topic, why in self.skipped.items():
            lines.append(f"skipped {topic}: {why}")
        return "\n".join(lines)


def message_class(msgtype: str):
    """The rclpy message class of ``pkg/msg/Type`` (ImportError if its package is missing;
    ValueError, before any import, if `msgtype` does not name a message of a message package)."""
    parts = msgtype.split("/")
    if len(parts) == 2:  # pkg/Type
        parts.insert(1, "msg")
    if len(parts) != 3 or parts[1] != "msg" or not TYPE_NAME.match(parts[2]):
        raise ValueError(f"{msgtype[:80]!r} is not a message type name pkg/msg/Type")
    pkg, _, name = parts
    if not (MSG_PACKAGE.match(pkg) or pkg in MSG_PACKAGES):
        raise ValueError(f"package {pkg[:80]!r} is not a message package (*_msgs or "
                         f"{', '.join(sorted(MSG_PACKAGES))}): not imported")
    return getattr(importlib.import_module(f"{pkg}.msg"), name)


def recorded_durability(metadata) -> str:
    """The durability of the first profile of a channel's ``offered_qos_profiles`` ("" when the
    channel has none or it does not parse): a transient-local topic (the robot description) is
    replayed transient local, so that a subscriber started later still gets it."""
    import yaml

    text = (metadata or {}).get("offered_qos_profiles", "")
    try:
        profiles = yaml.safe_load(text) if text else None
    except yaml.YAMLError:
        return ""
    if isinstance(profiles, list) and profiles and isinstance(profiles[0], dict):
        return str(profiles[0].get("durability", ""))
    return ""


def replay(path: str | os.PathLike, *, rate: float = 1.0, loop: bool = False, topics=None,
           wait_for_subscribers: float = 0.0, node_name: str = "gyro_sim_replay",
           should_stop=None) -> ReplayStats:
    """Publish the log at `path` (module docstring). Needs rclpy; blocks until done.

    Parameters
    ----------
    rate : speed factor (2.0: twice as fast as recorded)
    loop : start again at the end, until interrupted
    topics : only these topics (default: all)
    wait_for_subscribers : wait up to this many seconds until every publisher has a
        subscriber before starting (discovery takes 0.1 - 4 s with Fast DDS)
    should_stop : polled between messages; True ends the replay
    """
    if not rate > 0:
        raise LogError(f"rate must be > 0, got {rate}")
    import rclpy

    stats = ReplayStats()
    summary = verify(path)  # CRCs checked; LogError naming the damaged chunk
    wanted = set(topics) if topics else None
    classes = {}
    latched = {ch.topic for ch in summary.channels.values() if recorded_durability(ch.metadata) == "transient_local"}
    for ch in summary.channels.values():
        if wanted is not None and ch.topic not in wanted:
            continue
        schema = summary.schemas.get(ch.schema_id)
        if schema is None or ch.message_encoding != "cdr":
            stats.skipped[ch.topic] = "not a CDR channel with a schema"
            continue
        try:
            classes[ch.topic] = message_class(schema.name)
        except ValueError as exc:
            stats.skipped[ch.topic] = str(exc)
        except (ImportError, AttributeError):
            stats.skipped[ch.topic] = f"message type {schema.name} is not installed"
    if wanted:
        for t in sorted(wanted - {c.topic for c in summary.channels.values()}):
            stats.skipped[t] = "not in the log"
    if not classes:
        return stats

    own_context = not rclpy.ok()
    if own_context:
        from gyro_sim.ros.discovery import announce_often

        announce_often()
        rclpy.init()
    node = rclpy.create_node(node_name)
    try:
        from rclpy.qos import DurabilityPolicy, QoSProfile

        latched_qos = QoSProfile(depth=QOS_DEPTH, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        pubs = {t: node.create_publisher(cls, t, latched_qos if t in latched else QOS_DEPTH)
                for t, cls in classes.items()}
        if wait_for_subscribers > 0:
            deadline = time.monotonic() + wait_for_subscribers
            while time.monotonic() < deadline and not all(p.get_subscription_count() > 0 for p in pubs.values()):
                time.sleep(0.02)
            time.sleep(MATCH_SETTLE)
        while True:
            stats.loops += 1
            if not _one_pass(path, pubs, rate, stats, should_stop):
                break
            if not loop:
                break
        from rclpy.duration import Duration

        for p in pubs.values():
            p.wait_for_all_acked(Duration(seconds=ACK_TIMEOUT))
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        if own_context and rclpy.ok():
            rclpy.shutdown()
    return stats


def _one_pass(path, pubs, rate: float, stats: ReplayStats, should_stop) -> bool:
    """One pass over the log; False when stopped."""
    t0 = wall0 = None
    last_wall = None
    for topic, _, log_time, data in iter_messages(path, topics=list(pubs), decode=False):
        if should_stop is not None and should_stop():
            return False
        if t0 is None:
            t0, wall0 = log_time, time.perf_counter()
        due = wall0 + (log_time - t0) / 1e9 / rate
        while True:
            wait = due - time.perf_counter()
            if wait <= 0:
                break
            time.sleep(min(wait, SLEEP_SLICE))
        now = time.perf_counter()
        stats.max_late = max(stats.max_late, now - due)
        pubs[topic].publish(data)
        last_wall = time.perf_counter()
        stats.published += 1
        stats.per_topic[topic] = stats.per_topic.get(topic, 0) + 1
        stats.log_span = (log_time - t0) / 1e9
        stats.wall_span = last_wall - wall0
    return True
