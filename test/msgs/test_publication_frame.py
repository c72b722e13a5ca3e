"""The node's publication path: Simulator.snapshot(into=frame.scatter) writes the numbers
straight into the messages' bytes (io.messages.Frame). Those bytes must be the builders' bytes
of the same snapshot (the builders are checked against mcap's encoder, rosbags and rclpy in
test_cdr), on both backends, for every choice of parts; a non-finite number is never let out."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from gyro_sim.dynamics import kernel as fast
from gyro_sim.simulator import SimulationError, Simulator
from gyro_sim.msgs import messages as M

BACKENDS = ["numpy"] + (["numba"] if fast.available() else [])
#: spherical joints, hinges and an actuated torque rotor; a speed rotor; a free base with rotors;
#: a moving base
SCENES = ("hinge_chain", "speed_rotor_top", "free_chain_rotors", "vibrating_base")


def driven(scene: str, backend: str) -> Simulator:
    sim = Simulator(scene, integrator="rk4", backend=backend)
    rng = np.random.default_rng(3)
    if sim.axis_names:
        sim.set_axis_moments(rng.normal(size=len(sim.axis_names)) * 0.05)
    sim.advance(0.02)
    return sim


def builders(snap, pub: M.Publication, t: int, wrenches: bool, poses: bool, tf: bool) -> list[bytes]:
    want = [M.joint_state(snap, t), M.clock(t)]
    if wrenches:
        want += [M.wrench_stamped(t, b, f, m) for b, f, m in zip(pub.body_names, snap.wrench_force, snap.wrench_moment)]
    if poses:
        want.append(M.pose_array(snap, t))
    if tf:
        want.append(M.tf_message(snap, t))
    return want


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("scene", SCENES)
def test_frame_bytes_are_the_builders_bytes(scene, backend):
    sim = driven(scene, backend)
    pub = M.Publication(sim.model.names)
    names = sim.snapshot(bodies=False, wrenches=False, invariants=False).joint_names
    for wrenches, poses, tf in ((True, True, True), (False, False, False), (True, False, True), (False, True, False)):
        frame = pub.frame(names, wrenches=wrenches, poses=poses, tf=tf)
        for step in range(2):  # filled again: nothing left over from the last time
            sim.advance(0.01)
            t = M.time_ns(sim.time) + 2**33 * step  # past 2^32 ns: seconds and nanoseconds both change
            snap = sim.snapshot(bodies=poses or tf, wrenches=wrenches, invariants=False, into=frame.scatter)
            assert snap.nonfinite() is None
            got = frame.messages(t)
            assert [g[2] for g in got] == builders(snap, pub, t, wrenches, poses, tf)
            topics = [M.JOINT_STATES, M.CLOCK] + (list(pub.wrench_topics) if wrenches else [])
            topics += ([pub.poses_topic] if poses else []) + ([M.TF] if tf else [])
            assert [g[0] for g in got] == topics
            assert [g[1] for g in got] == [M.topic_types(pub.body_names)[x] for x in topics]
            # the block and its layout (what the recorder sends instead of the records) give the same records
            assert got.layout is frame.layout
            assert [(t, ty, got.block[a:b]) for t, ty, a, b in got.layout] == list(got)


@pytest.mark.parametrize("backend", BACKENDS)
def test_snapshot_into_gives_the_same_numbers_as_without(backend):
    sim = driven("hinge_chain", backend)
    frame = M.Publication(sim.model.names).frame(sim.snapshot().joint_names, wrenches=True, poses=True, tf=True)
    a = sim.snapshot(into=frame.scatter)
    b = sim.snapshot()
    for name in ("position", "velocity", "effort", "body_position", "body_quaternion", "wrench_force", "wrench_moment"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert a.invariants.keys() == b.invariants.keys()


@pytest.mark.parametrize("backend", BACKENDS)
def test_write_outputs_writes_the_snapshots_numbers_and_names_a_non_finite_one(backend):
    sim = driven("hinge_chain", backend)
    pub = M.Publication(sim.model.names)
    names = sim.snapshot().joint_names
    written, snapped = (pub.frame(names, wrenches=True, poses=True, tf=True) for _ in range(2))
    assert sim.write_outputs(written.scatter) is None
    sim.snapshot(into=snapped.scatter)
    assert written.scatter.dst.tobytes() == snapped.scatter.dst.tobytes()
    bad = sim.state
    bad[sim.model.i_vel.start + 1] = np.nan  # a joint rate: every output of the bodies past it
    sim._y = bad  # a state the integrator would refuse
    sim._outputs.moved(sim.time, bad, sim._p, sim._moments)
    name = sim.write_outputs(written.scatter)
    assert name in ("position", "velocity") and name == sim.snapshot(invariants=False).nonfinite()


class _Node:
    """What ros.outputs.Outputs asks of an rclpy node, without ROS: publishers nobody reads."""

    def get_fully_qualified_name(self):
        return M.NAMESPACE

    def create_publisher(self, cls, topic, qos, **kwargs):
        return SimpleNamespace(topic=topic, get_subscription_count=lambda: 1, publish=lambda data: None)


@pytest.mark.parametrize("backend", BACKENDS)
def test_node_outputs_are_the_builders_bytes_and_refuse_non_finite_numbers(backend):
    pytest.importorskip("sensor_msgs.msg")
    from gyro_sim.ros.outputs import Outputs

    sim = driven("hinge_chain", backend)
    out = Outputs(_Node(), sim, SimpleNamespace(publish_wrenches=True, publish_poses=True))
    for i in range(3):  # the first from the snapshot's arrays, then from the frame
        sim.advance(0.01)
        t = M.time_ns(sim.time)
        batch = out.prepare_state(t, sim, None if i == 2 else False)
        snap = sim.snapshot()
        tf = M.TF in out.pubs
        want = builders(snap, out.publication, t, True, True, tf)
        if i == 2:
            want.append(M.diagnostics(snap, t, out.publication.hardware_id))
        assert [b[2] for b in batch] == want
    bad = sim.state
    bad[sim.model.i_vel.start + 1] = np.nan  # a joint rate: every output of the bodies past it
    sim._y = bad  # a state the integrator would refuse
    sim._outputs.moved(sim.time, bad, sim._p, sim._moments)
    with pytest.raises(SimulationError, match="non-finite (position|velocity)"):
        out.prepare_state(M.time_ns(sim.time), sim)


class _Clock:
    def __init__(self):
        self.t = 50.0

    def __call__(self):
        return self.t


class _CountingNode(_Node):
    """Publishers that count their publish calls and the subscriber-count asks; `subscribers`
    says who listens (topic -> count)."""

    def __init__(self):
        self.subscribers, self.published, self.asks = {}, [], 0

    def create_publisher(self, cls, topic, qos, **kwargs):
        def count():
            self.asks += 1
            return self.subscribers.get(topic, 0)

        return SimpleNamespace(topic=topic, get_subscription_count=count,
                               publish=lambda data: self.published.append(topic))


class _Recorder:
    def __init__(self):
        self.batches = []

    def raw_batch(self, t_ns, batch):
        self.batches.append([topic for topic, _, _ in batch])


def test_optional_topics_nobody_subscribes_to_are_recorded_not_published():
    pytest.importorskip("sensor_msgs.msg")
    from gyro_sim.ros.outputs import ASKS_PER_PUBLICATION, WANT_PERIOD, Outputs

    sim = driven("hinge_chain", "numpy")
    node, clock, rec = _CountingNode(), _Clock(), _Recorder()
    out = Outputs(node, sim, SimpleNamespace(publish_wrenches=True, publish_poses=True), recorder=rec, clock=clock)
    optional = [*out.wrench_topics, out.publication.poses_topic]
    assert node.asks == len(optional)  # each asked once at the start

    def publish():
        node.published.clear()
        sim.advance(0.01)
        out.send(M.time_ns(sim.time), out.prepare_state(M.time_ns(sim.time), sim))
        return set(node.published)

    for _ in range(3):  # nobody listens: recorded, not published (the mandatory topics are)
        assert publish() == {M.JOINT_STATES, M.CLOCK}
        assert set(optional) <= set(rec.batches[-1])
    listened = out.wrench_topics[2]
    node.subscribers[listened] = 1
    asks = node.asks
    assert publish() == {M.JOINT_STATES, M.CLOCK}  # not asked again before WANT_PERIOD
    assert node.asks == asks
    clock.t += WANT_PERIOD * 1.01
    for _ in range(-(-len(optional) // ASKS_PER_PUBLICATION)):  # every topic asked again within these
        asks = node.asks
        got = publish()
        assert node.asks - asks <= ASKS_PER_PUBLICATION
    assert got == {M.JOINT_STATES, M.CLOCK, listened}
    assert set(optional) <= set(rec.batches[-1])


def test_without_recording_wrenches_are_computed_while_one_is_listened_to():
    pytest.importorskip("sensor_msgs.msg")
    from gyro_sim.ros.outputs import WANT_PERIOD, Outputs

    sim = driven("hinge_chain", "numpy")
    node, clock = _CountingNode(), _Clock()
    out = Outputs(node, sim, SimpleNamespace(publish_wrenches=True, publish_poses=True), clock=clock)
    batch = out.prepare_state(1, sim)
    assert [topic for topic, _, _ in batch] == [M.JOINT_STATES, M.CLOCK]
    node.subscribers[out.wrench_topics[0]] = 1
    clock.t += WANT_PERIOD * 1.01
    for _ in range(len(out.wrench_topics) + 1):
        batch = out.prepare_state(1, sim)
    topics = [topic for topic, _, _ in batch]
    assert set(out.wrench_topics) <= set(topics) and out.publication.poses_topic not in topics
    node.published.clear()
    out.send(1, batch)
    assert set(node.published) == {M.JOINT_STATES, M.CLOCK, out.wrench_topics[0]}


def test_frame_batch_is_the_sequence_of_its_messages():
    sim = driven("hinge_chain", "numpy")
    pub = M.Publication(sim.model.names)
    frame = pub.frame(sim.snapshot().joint_names, wrenches=True, poses=True, tf=True)
    sim.snapshot(bodies=True, wrenches=True, invariants=False, into=frame.scatter)
    batch = frame.messages(7)
    diag = (M.DIAGNOSTICS, M.DIAGNOSTICS_TYPE, M.diagnostic_array(7, [M.Status("run", {"i": 1})]))
    batch.append(diag)
    items = [(t, ty, batch.block[a:b]) for t, ty, a, b in frame.layout] + [diag]
    assert len(batch) == len(items) and list(batch) == items and batch == items
    assert [batch[i] for i in range(-len(items), len(items))] == items + items
    assert batch[len(frame.layout):] == [diag] and batch[1:3] == items[1:3] and batch[::-2] == items[::-2]
    with pytest.raises(IndexError):
        batch[len(items)]
    with pytest.raises(IndexError):
        batch[-len(items) - 1]


@pytest.mark.parametrize("backend", BACKENDS)
def test_node_diagnostics_refuse_a_non_finite_scalar(backend):
    pytest.importorskip("sensor_msgs.msg")
    from gyro_sim.ros.outputs import Outputs

    sim = driven("hinge_chain", backend)
    out = Outputs(_Node(), sim, SimpleNamespace(publish_wrenches=True, publish_poses=True))
    for _ in range(2):  # the frame made
        out.prepare_state(M.time_ns(sim.time), sim)
    out.prepare_state(M.time_ns(sim.time), sim, None)  # with diagnostics: all finite
    sim._work = float("nan")  # a scalar only the diagnostics carry
    out.prepare_state(M.time_ns(sim.time), sim)  # not in these messages
    with pytest.raises(SimulationError, match="non-finite work"):
        out.prepare_state(M.time_ns(sim.time), sim, None)
