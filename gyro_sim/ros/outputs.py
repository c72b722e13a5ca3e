"""The node's outputs: a thin serialiser from the Simulator's snapshot to DDS (and the recorder).

Message content comes from :mod:`gyro_sim.msgs.messages` only (the offline recorder uses the
same builders), as CDR bytes: the node publishes those bytes (`Publisher.publish(bytes)`) and
hands the same bytes to the recorder, so a log holds exactly what was on the wire. A state is
prepared (snapshot and bytes) as soon as it is computed, ahead of its wall deadline, and sent
at the deadline. Wrenches and poses are computed only when the parameters ask for them and
someone listens, or the node records.
"""
from __future__ import annotations

import importlib
import math
import time

from gyro_sim.simulator import SimulationError
from gyro_sim.msgs import messages as M
from gyro_sim.scene.urdf import urdf

#: wall seconds between two checks whether an optional output has subscribers
WANT_PERIOD = 0.5
#: most subscriber counts asked per publication (round robin over the optional topics): one ask
#: is an rcl call of ~2-3 us; the 100 wrench topics of n = 100 asked at once would cost the
#: physics thread ~300 us in one publication
ASKS_PER_PUBLICATION = 4


def node_topics(node) -> M.TopicNames:
    """The topic names of `node` from its fully qualified name as rclpy resolves it
    (``<namespace>/<name>``: the namespace is what comes before the name)."""
    fqn = node.get_fully_qualified_name()
    return M.TopicNames(namespace=fqn.rsplit("/", 1)[0] or "/", node=fqn)


def _qos_profile(qos: M.Qos):
    """The rclpy QoSProfile of a gyro_sim Qos."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=qos.depth,
                      reliability=ReliabilityPolicy.RELIABLE if qos.reliability == "reliable"
                      else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if qos.durability == "transient_local"
                      else DurabilityPolicy.VOLATILE)


class OutputsClosed(Exception):
    """The ROS context went away while publishing (shutdown under way): the loop ends quietly."""


def message_class(msgtype: str):
    """The rclpy message class of "pkg/msg/Type" (None when the package is not installed, e.g.
    tf2_msgs from PyPI: then the topic is only recorded)."""
    pkg, _, name = msgtype.split("/")
    try:
        return getattr(importlib.import_module(f"{pkg}.msg"), name)
    except (ImportError, AttributeError):
        return None


def _no_event_callbacks():
    """rclpy's publisher event callbacks with no handler at all, not even the default ones.

    The per-joint wrench topics are published so; the few other topics keep rclpy's defaults (a
    warning when a subscriber asks for an incompatible QoS or type). Each handler is a waitable
    that the executor adds to every wait set: the two per publisher of 100 wrench topics made
    one `spin_once` of the executor thread cost ~2.9 ms of CPU (~0.6 ms without them), ten times
    a second, holding the interpreter lock the physics thread needs at its deadlines."""
    from rclpy.event_handler import PublisherEventCallbacks

    return PublisherEventCallbacks(use_default_callbacks=False)


class Listeners:
    """Which optional topics (joint wrenches, poses, /tf) someone subscribes to.

    Every topic is asked when this is made (start-up); after that `refresh` (once per
    publication, on the physics thread) asks again each topic whose last answer is older than
    `period`, at most `per_call` of them per call, in a round robin, so no publication pays for
    all of them. `listened[topic]`: the last answer; `count[kind]`: how many topics of a kind
    are listened to.

    Parameters
    ----------
    pubs : topic -> publisher (with get_subscription_count()).
    kinds : topic -> kind (e.g. "wrench") of the optional topics; those without a publisher are left out.
    clock : time.monotonic, injectable for tests.
    """

    def __init__(self, pubs: dict, kinds: dict, clock=time.monotonic, period: float = WANT_PERIOD,
                 per_call: int = ASKS_PER_PUBLICATION):
        self._pubs, self.clock, self.period, self.per_call = pubs, clock, period, per_call
        self.topics = [t for t in kinds if t in pubs]
        self.kinds = {t: kinds[t] for t in self.topics}
        self.listened = dict.fromkeys(self.topics, False)
        self.count = dict.fromkeys(kinds.values(), 0)
        self._asked = [-math.inf] * len(self.topics)
        self._next = 0
        self.asks = 0  # subscriber counts asked so far
        self.version = 0  # counts the changes of `listened`
        self.refresh(per_call=len(self.topics))

    def _ask(self, i: int, now: float) -> None:
        topic = self.topics[i]
        on = self._pubs[topic].get_subscription_count() > 0
        self.asks += 1
        if on != self.listened[topic]:
            self.listened[topic] = on
            self.version += 1
            self.count[self.kinds[topic]] += 1 if on else -1
        self._asked[i] = now

    def refresh(self, per_call: int | None = None) -> None:
        """Ask again the topics whose answer is older than `period` (at most `per_call`)."""
        n = len(self.topics)
        if not n:
            return
        now = self.clock()
        for _ in range(min(n, self.per_call if per_call is None else per_call)):
            i = self._next
            if now - self._asked[i] <= self.period:
                break  # the round robin's oldest answer is recent: so are all the others
            self._ask(i, now)
            self._next = (i + 1) % n

    def ask_all(self) -> None:
        """Ask every topic now."""
        now = self.clock()
        for i in range(len(self.topics)):
            self._ask(i, now)


class Outputs:
    """Publishers of the node, fed with the bytes of :class:`gyro_sim.msgs.messages.Publication`.

    Parameters
    ----------
    node : rclpy Node
    sim : Simulator (for names)
    config : NodeConfig
    recorder : gyro_sim.ros.recorder.LiveRecorder or None
    qos : depth of the publishers' queues
    clock : time.monotonic, injectable for tests (when to ask the subscriber counts again)
    topics : the node's names (default: from the node, no frame prefix)

    The optional outputs (joint wrenches, poses, /tf) are computed when someone subscribes to
    them or the node records, and published only to topics someone subscribes to (`Listeners`):
    a publish without a subscriber puts nothing on the wire, yet cost the physics thread ~6 us
    per topic (~600 us per publication of n = 100 recording with nobody listening). A new
    subscriber gets them from the next ask of its topic (at most WANT_PERIOD later, as before).
    """

    def __init__(self, node, sim, config, recorder=None, qos: int = M.PUBLISHER_DEPTH, clock=time.monotonic,
                 topics: M.TopicNames | None = None):
        self.node, self.recorder = node, recorder
        self.topics = topics = topics or node_topics(node)
        self.publication = M.Publication(sim.model.names, topics=topics, hardware_id=sim.scene.name)
        self.command_topic = topics.axis_moments
        self.joint_commands_topic = topics.joint_commands
        self.events_topic = topics.events
        self.pubs: dict[str, object] = {}
        #: a URDF robot's own description, its links' frames on /tf beside the bodies' (scene.robot)
        self.robot = sim.scene.robot
        self.robot_description = urdf(sim.scene) if self.robot is None else self.robot.urdf
        self._description_pub = node.create_publisher(message_class(M.STRING_TYPE), topics.robot_description,
                                                      _qos_profile(M.LATCHED_QOS))

        def publisher(topic, msgtype, events: bool = True):
            cls = message_class(msgtype)
            if cls is not None:
                extra = {} if events else {"event_callbacks": _no_event_callbacks()}
                self.pubs[topic] = node.create_publisher(cls, topic, qos, **extra)

        publisher(topics.joint_states, M.JOINT_STATE_TYPE)
        publisher(M.CLOCK, M.CLOCK_TYPE)
        publisher(M.DIAGNOSTICS, M.DIAGNOSTICS_TYPE)
        publisher(M.TF, M.TF_TYPE)  # only where tf2_msgs is installed (an apt ROS); always recorded
        self.wrench_topics = self.publication.wrench_topics if config.publish_wrenches else ()
        for topic in self.wrench_topics:
            publisher(topic, M.WRENCH_TYPE, events=False)
        self.publish_poses = config.publish_poses
        if self.publish_poses:
            publisher(self.publication.poses_topic, M.POSE_ARRAY_TYPE)
        kinds = {t: "wrench" for t in self.wrench_topics}
        kinds[self.publication.poses_topic] = "poses"
        kinds[M.TF] = "tf"
        self.listeners = Listeners(self.pubs, kinds, clock=clock)
        self.imu_ticks, self.imu_topics = None, ()
        if sim.imu_names:  # sampled at publications: each IMU's rate must divide the publish rate
            from gyro_sim.dynamics.imu import ImuTicks, check_rates
            from gyro_sim.ros.params import ParameterError

            problem = check_rates(sim.scene, config.publish_rate)
            if problem is not None:
                raise ParameterError(problem)
            sim.set_imu_default_rate(config.publish_rate)
            self.imu_ticks = ImuTicks(sim.imu_rates)
            self.imu_topics = tuple(M.imu_topic(name, topics.node) for name in sim.imu_names)
            for topic in self.imu_topics:
                publisher(topic, M.IMU_TYPE)
        #: the publication's buffers by the parts asked (wrenches, poses, tf), once the joint
        #: names are known (from the first snapshot)
        self._frames: dict[tuple[bool, bool, bool], M.Frame] = {}
        self._joint_names: tuple[str, ...] | None = None
        self._publish_fn: dict[str, object] = {}  # topic -> the call that publishes its bytes (None: none)
        #: (layout, listeners' version, ((publish call, start, stop), ...)): what `publish` does
        #: with a FrameBatch of that layout while nobody starts or stops listening
        self._plan: tuple | None = None

    def publish_robot_description(self) -> None:
        """The URDF on ``robot_description`` (transient local: a later subscriber gets it too). Not
        recorded here: the log has it from its writer, at log time 0."""
        msg = message_class(M.STRING_TYPE)(data=self.robot_description)
        try:
            self._description_pub.publish(msg)
        except Exception as exc:  # the context went away (shutdown under way)
            raise OutputsClosed(str(exc)) from exc

    # --- called by the physics loop -------------------------------------------------------------
    def prepare_state(self, t_ns: int, sim, diagnostics_run: M.Status | None | bool = False) -> list:
        """The state's messages: [(topic, type, bytes)]. `diagnostics_run`: False for none, else the
        run's status (or None) to go with the dynamics' one. Raises SimulationError rather than
        let a non-finite value out."""
        out = self._prepare_state(t_ns, sim, diagnostics_run) if self.imu_ticks is None \
            else self._prepare_with_imus(t_ns, sim, diagnostics_run)
        if self.robot is not None and (self.recorder is not None or self.listeners.listened.get(M.TF, False)):
            out.append((M.TF, M.TF_TYPE, self._link_tf(t_ns, sim)))  # a URDF robot's links by name
        return out

    def _link_tf(self, t_ns: int, sim) -> bytes:
        """/tf of a URDF robot's links, by their names (with the frame prefix)."""
        from gyro_sim.scene.robot import link_transforms

        names, positions, quaternions = link_transforms(self.robot, sim)
        keep = [i for i, n in enumerate(names) if n != M.WORLD_FRAME]  # a root link named world is /tf's root
        names, positions, quaternions = [names[i] for i in keep], positions[keep], quaternions[keep]
        prefix = self.topics.frame_prefix
        try:
            return M.frames_tf_message([prefix + n for n in names], positions, quaternions, t_ns)
        except M.NonFiniteError as exc:
            raise SimulationError(f"t = {sim.time:.6g} s: {exc} (not published)") from exc

    def _prepare_with_imus(self, t_ns: int, sim, diagnostics_run) -> list:
        """`_prepare_state` and the IMUs due now."""
        due = self.imu_ticks.due(sim.time)
        out = self._prepare_state(t_ns, sim, diagnostics_run, accelerations=bool(due))
        if due:  # the IMUs whose sample starts now, from the accelerations the outputs just computed
            readings = sim.imus()
            try:
                messages = [(self.imu_topics[j], M.IMU_TYPE, M.imu(readings[j], t_ns)) for j in due]
            except M.NonFiniteError as exc:
                raise SimulationError(f"t = {sim.time:.6g} s: {exc} (not published)") from exc
            for item in messages:
                out.append(item)
        return out

    def _prepare_state(self, t_ns: int, sim, diagnostics_run: M.Status | None | bool = False,
                       accelerations: bool = False) -> list:
        """`prepare_state` without the IMUs; `accelerations`: have the compiled outputs compute the
        bodies' accelerations (those of the wrenches) for the IMUs."""
        listeners = self.listeners
        listeners.refresh()
        recording = self.recorder is not None
        wrenches = bool(self.wrench_topics) and (recording or listeners.count["wrench"] > 0)
        poses = self.publish_poses and (recording or listeners.listened.get(self.publication.poses_topic, False))
        tf = recording or listeners.listened.get(M.TF, False)
        frame = None
        if self._joint_names is not None:  # the numbers go straight into the messages' bytes
            key = (wrenches, poses, tf)
            frame = self._frames.get(key)
            if frame is None:
                frame = self._frames[key] = self.publication.frame(self._joint_names, wrenches=wrenches, poses=poses,
                                                                   tf=tf)
            names = sim.joint_names
            if diagnostics_run is False and (names is frame.joint_names or names == frame.joint_names):
                # no diagnostics: the numbers into the frame and their check, no snapshot
                bad = sim.write_outputs(frame.scatter, bodies=poses or tf, wrenches=wrenches or accelerations)
                if bad is not None:
                    raise SimulationError(f"t = {sim.time:.6g} s: non-finite {bad} (not published)")
                return frame.messages(t_ns)
        snap = sim.snapshot(bodies=poses or tf, wrenches=wrenches, invariants=diagnostics_run is not False,
                            into=None if frame is None else frame.scatter)
        first = frame is None or (snap.joint_names is not frame.joint_names and snap.joint_names != frame.joint_names)
        if first or diagnostics_run is False or not snap.arrays_checked:
            bad = snap.nonfinite()  # the arrays were checked as they were computed: then only the scalars
            if bad is not None:
                raise SimulationError(f"t = {sim.time:.6g} s: non-finite {bad} (not published)")
        if first:
            self._joint_names, self._frames = snap.joint_names, {}
            return self.publication.messages(snap, t_ns, poses=poses, tf=tf, diagnostics_run=diagnostics_run)
        out = frame.messages(t_ns)
        if diagnostics_run is not False:
            # the diagnostics refuse any number they would write that is not finite, and they write
            # every scalar and invariant the snapshot's check looks at (~30 us saved): it names the field
            try:
                data = M.diagnostics(snap, t_ns, self.publication.hardware_id, diagnostics_run or None,
                                     self.publication.dynamics_status)
            except M.NonFiniteError as exc:
                raise SimulationError(f"t = {sim.time:.6g} s: non-finite {snap.nonfinite() or exc} "
                                      "(not published)") from exc
            out.append((M.DIAGNOSTICS, M.DIAGNOSTICS_TYPE, data))
        return out

    def _publisher(self, topic: str):
        """The call that publishes bytes on `topic` (None: not published, only recorded).

        rclpy's `Publisher.publish(bytes)` is the binding's `publish_raw` behind a type check and
        the handle's context manager, which together cost as much again as the publish itself
        (~1.4 of ~2.8 us, bench publication): with one publisher per joint wrench topic that is
        ~140 us per publication at n = 100. The binding is called directly where rclpy has it (its
        context manager keeps a publisher from being destroyed during a publish in another
        thread; publish_raw holds the interpreter lock throughout, so nothing can destroy it
        meanwhile, and a destroyed publisher raises like publish does)."""
        fn = self._publish_fn.get(topic, False)
        if fn is False:
            pub = self.pubs.get(topic)
            raw = getattr(pub, "_Publisher__publisher", None)
            fn = None if pub is None else getattr(raw, "publish_raw", pub.publish)
            self._publish_fn[topic] = fn
        return fn

    def send(self, t_ns: int, batch: list) -> None:
        """Publish a prepared state (and hand the same bytes to the recorder, the batch itself:
        it is not changed after). An optional topic nobody subscribes to is only recorded."""
        self.publish(batch)
        if self.recorder is not None:  # one call: the recorder's sender thread takes it from there
            self.recorder.raw_batch(t_ns, batch)

    def publish(self, batch) -> None:
        """The rclpy half of `send`: each message of the batch on its topic, except optional
        topics nobody subscribes to (a FrameBatch's messages are cut from its block only for
        the topics published)."""
        get = self._publish_fn.get
        listened = self.listeners.listened.get
        layout = getattr(batch, "layout", None)
        rest = batch
        if layout is not None:
            plan = self._plan
            if plan is None or plan[0] is not layout or plan[1] != self.listeners.version:
                publishers = map(self._publisher, (x[0] for x in layout))
                calls = tuple((fn, a, b) for fn, (topic, _, a, b) in zip(publishers, layout)
                              if fn is not None and listened(topic, True))
                plan = self._plan = (layout, self.listeners.version, calls)
            block, rest = batch.block, batch.extra
            for fn, a, b in plan[2]:
                try:
                    fn(block[a:b])
                except Exception as exc:  # the context went away (shutdown under way)
                    raise OutputsClosed(str(exc)) from exc
        for topic, _, data in rest:
            fn = get(topic, False)
            if fn is False:
                fn = self._publisher(topic)
            if fn is not None and listened(topic, True):
                try:
                    fn(data)
                except Exception as exc:  # the context went away (shutdown under way)
                    raise OutputsClosed(str(exc)) from exc

    def publish_diagnostics(self, t_ns: int, sim, run: M.Status) -> None:
        """Diagnostics alone (paused, stopped): the dynamics of the state kept, and the run."""
        try:
            snap = sim.snapshot(bodies=False, wrenches=False, invariants=True)
            data = M.diagnostics(snap, t_ns, self.publication.hardware_id, run, self.publication.dynamics_status)
        except M.NonFiniteError:  # a failed state: the run's status alone says why
            data = M.diagnostic_array(t_ns, [run])
        self.send(t_ns, [(M.DIAGNOSTICS, M.DIAGNOSTICS_TYPE, data)])

    def record_commands(self, t_ns: int, raws: list) -> None:
        """The commands a step took in, in the order received (the last one applied): one hand-over."""
        if self.recorder is not None:
            self.recorder.raw_many(self.command_topic, M.COMMAND_TYPE, t_ns, raws)

    def record_joint_commands(self, t_ns: int, raws: list) -> None:
        """The joint commands a step took in (sensor_msgs/JointState), in the order received."""
        if self.recorder is not None:
            self.recorder.raw_many(self.joint_commands_topic, M.JOINT_STATE_TYPE, t_ns, raws)

    def record_event(self, t_ns: int, text: str) -> None:
        """An event for the log only (e.g. each rejected command: the console says them throttled)."""
        if self.recorder is not None:
            self.recorder.raw(self.events_topic, M.STRING_TYPE, t_ns, M.string(text))

    def event(self, t_ns: int, text: str, level: str = "info") -> None:
        """An event: one console line at `level` (info, warning, error) and the log."""
        line, logger = f"t = {t_ns * 1e-9:.6f} s: {text}", self.node.get_logger()
        # one call site per severity: rclpy refuses another severity from the same line
        if level == "error":
            logger.error(line)
        elif level == "warning":
            logger.warning(line)
        else:
            logger.info(line)
        self.record_event(t_ns, text)
