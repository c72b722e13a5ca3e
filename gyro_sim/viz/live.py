"""`gyro-sim view --live`: a running gyro_sim node drawn in rerun as it runs.

A process of its own (the node stays as it is): an rclpy node subscribes to the gyro_sim
node's topics under a namespace and feeds every message to the translator of the log view
(gyro_sim.viz.translate), which sends the same entities and plots to rerun a few times a
second (:data:`FLUSH_PERIOD`).

- The chain's shapes come from ``<ns>/robot_description`` (reliable, transient local: the
  last description is received whenever the viewer starts); until then the viewer says
  "waiting for <ns>/robot_description" once and draws what /tf or the poses give.
- A reset (the "reset" event and a new description) is followed; so is a node that stops and
  starts again (one line each; the viewer keeps waiting). A restarted node counts its
  simulated time from 0 again: the view's ``sim_time`` goes on from where it was (the event
  "node restarted at ..." marks the place), so the plots do not draw over each other.
- SIGINT or SIGTERM end it with exit 0, the .rrd of ``--save`` complete.
- At the end one line gives how far the drawn messages were behind the node (LagStats).
"""
from __future__ import annotations

import math
import signal
import socket
import sys
import threading
import time
from dataclasses import dataclass, field
from urllib.parse import quote

from gyro_sim.errors import GyroSimError
from gyro_sim.msgs import messages as M
from gyro_sim.viz.translate import Translator

#: messages drawn per topic and wall second at most (the node publishes 100 by default; a
#: chain of n bodies has n wrench topics): what keeps the viewer's CPU bounded
DRAW_RATE = 30.0
#: the joint wrenches of at most this many bodies are drawn (one topic each)
MAX_WRENCH_BODIES = 12
#: wall seconds between two sends to rerun (what the picture lags at most behind a message)
FLUSH_PERIOD = 0.1
#: wall seconds between two looks for new wrench topics and for the node's presence
GRAPH_PERIOD = 1.0
#: the plots of the live view show this many simulated seconds before the time cursor
LIVE_WINDOW = 30.0
#: wall seconds at least between two updates of the layout (new plots, wider y ranges)
BLUEPRINT_PERIOD = 2.0
#: a node whose time goes back by more than this (s) has restarted
RESTART_BACKSTEP = 0.5
#: the live camera frames this many chain lengths about O^1 (the chain reaches one)
EYE_SPAN = 1.5
#: wall seconds without a message (and no publisher in the graph) after which the node has stopped
SILENCE = 1.0
#: wall seconds between two renewals of the subscriptions while a listed node stays silent
RESUBSCRIBE_PERIOD = 3.0
#: rerun's default ports: its gRPC server and its web viewer
GRPC_PORT = 9876
WEB_PORT = 9090
#: queue depth of the subscriptions
DEPTH = 50
SPIN_TIMEOUT = 0.05


@dataclass
class LagStats:
    """How far the drawn messages are behind the node (at real_time_factor 1).

    For each joint state: its receipt (wall clock) minus its stamp (simulated time), less the
    smallest such difference of the node's run: the delay beyond that of the quickest
    message (which is the node's own publication and transport time, not the viewer's).
    """

    runs: list = field(default_factory=lambda: [[]])  # one list per node run (a restart: a new one)
    #: wall seconds from the receipt of the oldest message of a send to the send
    delays: list = field(default_factory=list)

    def line(self) -> str:
        def stats(values):
            s = sorted(values)
            return (f"median {1e3 * s[len(s) // 2]:.1f} ms, 95th percentile "
                    f"{1e3 * s[int(0.95 * (len(s) - 1))]:.1f} ms, max {1e3 * s[-1]:.1f} ms")

        behind = [x - min(run) for run in self.runs if run for x in run]
        clock = f"received behind the quickest message {stats(behind)}" if behind else "no joint state received"
        sent = f"; received to sent to rerun {stats(self.delays)} (wall time)" if self.delays else ""
        return f"lag: {clock}{sent}"


def _topic(ns: str, name: str) -> str:
    return f"{ns}/{name}" if ns else f"/{name}"


def _say(line: str) -> None:
    print(f"gyro-sim view --live: {line}", file=sys.stderr, flush=True)


class LiveView:
    """The subscriptions and the translator (callbacks and flushes in one executor thread)."""

    def __init__(self, node, rec, namespace: str, publish_blueprint, rate: float = DRAW_RATE):
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

        self.node, self.rec, self.ns = node, rec, namespace
        self.publish_blueprint = publish_blueprint
        self.tr = Translator(rec, source=f"live: `{namespace or '/'}`")
        self.offset = 0.0  # added to the node's time after a restart
        self.last_stamp = None  # the newest stamp of the node's run (its own time, s)
        self.lag = LagStats()
        self._subs: dict[str, tuple] = {}  # topic -> (type, key, suffix, subscription)
        self._resubscribed = -math.inf
        self.found: dict[str, object] = {}  # subscriptions to the topics found
        self._said_wrenches = False
        self._receiving = False
        self._last_message = -math.inf  # wall time of the newest stamped message
        self._bad: set[str] = set()  # topics whose messages could not be drawn (said once)
        self.description = False
        self.received = 0
        self.skipped = 0  # messages left out by the rate limit
        self.min_gap = 1.0 / rate if rate > 0 else 0.0
        self._drawn_at: dict[str, float] = {}
        self.eye = None
        self._gone = False  # the node went away since its last joint state
        self._oldest = None  # when the oldest message not yet sent was received
        self._bp_sent = None
        self._bp_at = -math.inf
        msgs = _message_classes()
        self.prefix = _topic(namespace, "gyro_sim")
        plan = [
            ("joint_states", M.JOINT_STATES, "JointState"),
            ("gyro_sim/poses", M.POSES, "PoseArray"),
            ("gyro_sim/events", M.EVENTS, "String"),
        ]
        for rel, key, cls in plan:
            self._sub(msgs[cls], _topic(namespace, rel), key)
        for topic, key, cls in ((M.TF, M.TF, "TFMessage"), (M.DIAGNOSTICS, M.DIAGNOSTICS, "DiagnosticArray")):
            if msgs.get(cls) is not None:  # tf2_msgs is not on PyPI: poses then
                self._sub(msgs[cls], topic, key)
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.description_topic = _topic(namespace, "robot_description")
        node.create_subscription(msgs["String"], self.description_topic, self._on_description, latched)
        # topics found as they appear: one per joint, one per IMU (prefix -> translator key, type)
        self.per_topic = {f"{self.prefix}/wrench/": (M.WRENCH_PREFIX, msgs["WrenchStamped"]),
                          f"{self.prefix}/imu/": (M.IMU_PREFIX, msgs["Imu"])}
        node.create_timer(FLUSH_PERIOD, self.flush)
        node.create_timer(GRAPH_PERIOD, self.look)
        _say(f"waiting for {self.description_topic} (the chain is drawn from the poses meanwhile)")
        self.look()

    # --- input ---------------------------------------------------------------------------------------
    def _sub(self, cls, topic: str, key: str, suffix: str = ""):
        sub = self._make_sub(cls, topic, key, suffix)
        self._subs[topic] = (cls, key, suffix, sub)
        return sub

    def resubscribe(self) -> None:
        """Every subscription made again (a new run's publishers are matched afresh)."""
        for topic, (cls, key, suffix, sub) in list(self._subs.items()):
            self.node.destroy_subscription(sub)
            self._subs[topic] = (cls, key, suffix, self._make_sub(cls, topic, key, suffix))
        self._resubscribed = time.monotonic()

    def _make_sub(self, cls, topic: str, key: str, suffix: str = ""):
        """A subscription to `topic`; stamped messages arrive as bytes and are decoded only
        when drawn (the rate limit first: decoding a long chain's poses is most of the cost)."""
        if not hasattr(cls, "header"):
            return self.node.create_subscription(cls, topic, lambda msg: self._on(key, msg, suffix), DEPTH)
        from rclpy.serialization import deserialize_message

        def on_bytes(data: bytes) -> None:
            if self._gate(key + suffix):
                self._on(key, deserialize_message(data, cls), suffix)

        return self.node.create_subscription(cls, topic, on_bytes, DEPTH, raw=True)

    def _gate(self, topic: str) -> bool:
        """Whether a message of `topic` is drawn: at most `rate` a wall second per topic."""
        if self.min_gap <= 0:
            return True
        now = time.monotonic()
        if now - self._drawn_at.get(topic, -math.inf) < self.min_gap:
            self.skipped += 1
            return False
        self._drawn_at[topic] = now
        return True

    def _on(self, key: str, msg, suffix: str = "") -> None:
        header = getattr(msg, "header", None)
        t = (M.stamp_ns(header.stamp) / 1e9) if header is not None else None
        if t is not None:
            if self._gone:
                _say("the node is back: following it")
            restarted = self._gone and t + self.offset < self.tr.last_t  # a new run, seen go and come back
            restarted = self.last_stamp is not None and (t < self.last_stamp - RESTART_BACKSTEP or restarted)
            if restarted:
                self.offset = self.tr.last_t + FLUSH_PERIOD
                self.tr.message(M.EVENTS, self.offset, _Text(f"node restarted at sim_time {self.offset:.3f} s"))
                _say(f"the node restarted: its time 0 is drawn at sim_time {self.offset:.3f} s")
                self.lag.runs.append([])
            self.last_stamp = t if self.last_stamp is None or restarted else max(self.last_stamp, t)
            self._gone = False
            if key == M.JOINT_STATES:
                self.lag.runs[-1].append(time.monotonic() - t)
        if t is None:
            t = self.tr.last_t
        else:
            t += self.offset
        self.received += 1
        if header is not None:  # the node's own (a description may be another's)
            self._last_message = time.monotonic()
            if not self._receiving:
                self._receiving = True
                _say("receiving from the node")
        if self._oldest is None:
            self._oldest = time.monotonic()
        try:
            self.tr.message(key + suffix, t, msg)
        except (ValueError, TypeError, AttributeError, IndexError, KeyError) as exc:  # not one of gyro_sim's
            if key + suffix not in self._bad:
                self._bad.add(key + suffix)
                _say(f"messages of {key + suffix} not drawn: {type(exc).__name__}: {str(exc)[:200]}")

    def _on_description(self, msg) -> None:
        before = self.tr.chain
        self._on(M.ROBOT_DESCRIPTION, msg)
        if self.tr.notes:
            for line in self.tr.notes:
                _say(line)
            self.tr.notes.clear()
        if self.tr.chain is not None and self.tr.chain is not before:
            _say(f"robot description received: {len(self.tr.chain.bodies)} bodies")
            self.description = True
            self.look()  # its wrench topics now

    def look(self) -> None:
        """Subscribe to new wrench and IMU topics; say when the node goes away or comes back."""
        wanted = self._wanted_wrenches()
        for topic, _types in self.node.get_topic_names_and_types():
            for prefix, (key, cls) in self.per_topic.items():
                if topic.startswith(prefix) and topic not in self.found:
                    name = topic[len(prefix):]
                    if key == M.WRENCH_PREFIX and name not in wanted:
                        continue
                    self.found[topic] = self._sub(cls, topic, key, name)
        # gone: silent for SILENCE s and no longer in the graph (the graph alone lags behind
        # or ahead of the messages; a paused node is silent but still there)
        now = time.monotonic()
        silent = now - self._last_message > SILENCE
        listed = self.node.count_publishers(_topic(self.ns, "joint_states")) > 0
        if self._receiving and not self._gone and silent and not listed:
            _say("the node stopped: waiting for it to start again (Ctrl-C to end)")
            self._gone = True
        elif self._gone and listed and now - self._resubscribed > RESUBSCRIBE_PERIOD:
            # a node in the graph again whose messages do not come: its publishers matched
            # afresh (DDS can keep a stopped node's endpoints for a while)
            self.resubscribe()

    def _wanted_wrenches(self) -> set[str]:
        """The bodies whose wrenches are drawn: all of them up to MAX_WRENCH_BODIES, else that
        many spread evenly along the chain, first and last included (each is a topic at the
        publish rate: a long chain's would take the viewer's CPU); none before the chain is
        known (the arrows are drawn in the body frames it names)."""
        chain = self.tr.chain
        if chain is None:
            return set()
        names = [M.topic_token(b) for b in chain.body_names]
        if len(names) <= MAX_WRENCH_BODIES:
            return set(names)
        picked = {names[round(i * (len(names) - 1) / (MAX_WRENCH_BODIES - 1))] for i in range(MAX_WRENCH_BODIES)}
        if not self._said_wrenches:
            _say(f"drawing the joint wrenches of {len(picked)} of the {len(names)} bodies, spread along the chain")
            self._said_wrenches = True
        return picked

    # --- output --------------------------------------------------------------------------------------
    def flush(self) -> None:
        from gyro_sim.viz.rerun_view import drawn

        self.tr.flush()
        if self._oldest is not None:
            self.lag.delays.append(time.monotonic() - self._oldest)
            self._oldest = None
        got = drawn(self.tr)
        if self.tr.chain is not None and self.tr.last_pose is not None:
            if self.eye is None:  # the chain reaches at most its length from O^1: a camera for all
                self.eye = _eye(self.tr.last_pose[0][0], self.tr.chain.length)
            got["eye"] = self.eye
        now = time.monotonic()
        key = (tuple(got["views"]), tuple(sorted((k, _rounded(v)) for k, v in got["ranges"].items())),
               got["eye"] is not None, _filling(got.get("t_range")))
        if key != self._bp_sent and now - self._bp_at >= BLUEPRINT_PERIOD:
            self.publish_blueprint(got)
            self._bp_sent, self._bp_at = key, now


class _Text:
    """A std_msgs/String made here (an event of the viewer's own)."""

    def __init__(self, data: str):
        self.data = data


def _eye(base, length: float):
    """(position, target) of a camera that sees a chain of `length` about O^1 at `base`."""
    from gyro_sim.viz.translate import EYE_DIRECTION, EYE_DISTANCE

    return base + EYE_DIRECTION * EYE_DISTANCE * EYE_SPAN * length, base


def _filling(t_range) -> float | None:
    """The first time of the plots while they fill their window (None once they scroll)."""
    if t_range is None or t_range[1] - t_range[0] >= LIVE_WINDOW:
        return None
    return t_range[0]


def _rounded(r):
    if r is None:
        return None
    from gyro_sim.viz.rerun_view import y_range

    return y_range(r[0], r[1], 1)


def _message_classes() -> dict:
    import importlib

    out = {}
    for pkg, name in (("sensor_msgs", "JointState"), ("geometry_msgs", "PoseArray"), ("geometry_msgs", "WrenchStamped"),
                      ("sensor_msgs", "Imu"),
                      ("std_msgs", "String"), ("tf2_msgs", "TFMessage"),
                      ("diagnostic_msgs", "DiagnosticArray")):
        try:
            out[name] = getattr(importlib.import_module(f"{pkg}.msg"), name)
        except ImportError:
            if name in ("TFMessage", "DiagnosticArray"):
                out[name] = None
            else:
                raise
    return out


class LiveError(GyroSimError, RuntimeError):
    """The viewer could not be reached or served (a port in use, no viewer to spawn)."""


def port_free(port: int) -> bool:
    """Whether a server can listen on `port` (all interfaces, as rerun's servers do)."""
    with socket.socket() as s:
        try:
            s.bind(("0.0.0.0", port))
        except OSError:
            return False
    return True


def run(namespace: str = "", *, mode: str = "spawn", save: str | None = None, seconds: float | None = None,
        domain_id: int | None = None, grpc_port: int = GRPC_PORT, web_port: int = WEB_PORT,
        rate: float = DRAW_RATE, out=print) -> int:
    """Follow the node until `seconds` have passed (None: until SIGINT/SIGTERM); 0 when done.

    `mode`: "spawn" (a viewer window), "serve" (rerun's gRPC server on `grpc_port` and web
    viewer on `web_port`; the URL is printed), "save" (to the .rrd file `save`, complete
    when this returns). `rate`: messages drawn per topic and wall second at most (0: all).
    Raises LiveError when the viewer cannot be started or served.
    """
    if mode == "serve":
        for port, what in ((grpc_port, "--grpc-port"), (web_port, "--web-port")):
            if not port_free(port):
                raise LiveError(f"port {port} is in use (another viewer serving?): choose another with {what}")
    import rclpy
    import rerun as rr
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    from gyro_sim.viz.rerun_view import APP_ID, blueprint

    namespace = namespace.rstrip("/")
    if namespace and not namespace.startswith("/"):
        namespace = "/" + namespace
    stop = threading.Event()
    previous = {s: signal.signal(s, lambda *_: stop.set()) for s in (signal.SIGINT, signal.SIGTERM)}
    from gyro_sim.ros.discovery import announce_often

    announce_often()
    context = rclpy.Context()
    rec = rr.RecordingStream(APP_ID, recording_id=f"gyro_sim:live:{namespace or '/'}:{time.time_ns()}")
    live = None
    try:
        rclpy.init(context=context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
        node = rclpy.create_node("gyro_sim_view", context=context)

        def bp(got=None):
            got = got or {"views": ["world"], "scene": "", "eye": None, "ranges": {}, "series": {}}
            return blueprint(got["views"], got["scene"], eye=got["eye"], play_state="following",
                             window=LIVE_WINDOW, t_range=got.get("t_range"), ranges=got["ranges"],
                             series=got["series"])

        try:
            if mode == "save":
                rec.save(save, default_blueprint=bp())
            elif mode == "serve":
                uri = rec.serve_grpc(grpc_port=grpc_port, default_blueprint=bp())
                rr.serve_web_viewer(web_port=web_port, open_browser=False, connect_to=uri)
                out(f"serving: open http://localhost:{web_port}/?url={quote(uri, safe='')} in a browser "
                    f"(or: rerun {uri})")
            else:
                rec.spawn(default_blueprint=bp())
        except (RuntimeError, OSError) as exc:
            raise LiveError(f"the viewer could not be started ({mode}): "
                            f"{str(exc).splitlines()[0] if str(exc) else exc}") from None

        live = LiveView(node, rec, namespace, lambda got: rec.send_blueprint(bp(got), make_active=True), rate)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        end = None if seconds is None else time.monotonic() + seconds
        while not stop.is_set() and (end is None or time.monotonic() < end):
            executor.spin_once(timeout_sec=SPIN_TIMEOUT)
        live.flush()
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
        try:
            rec.flush()
            if mode == "save":
                rec.disconnect()  # the file's footer written: complete
        except RuntimeError:  # a sink that never started: its error is the one reported
            pass
        for s, h in previous.items():
            signal.signal(s, h)
    if live is not None:
        _say(f"{live.received} messages drawn ({live.skipped} left out by --rate); {live.lag.line()}")
    return 0
