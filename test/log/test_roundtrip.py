"""Round trip: messages written to a log read back equal with rosbags and mcap-ros2-support."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from gyro_sim import Simulator, load_scene
from gyro_sim.msgs import messages as M
from gyro_sim.log.mcap_log import LogError, LogWriter, iter_messages, read_info
from gyro_sim.log.record import LogRecorder, run_params
from gyro_sim.scene.urdf import urdf

from test.conftest import SCENE

TYPES = sorted(set(M.topic_types(["a"]).values()))


def plain(x):
    """A decoded message (rosbags dataclass / mcap_ros2 object / numpy) as dicts and lists."""
    if isinstance(x, (str, bytes, bool, int, float)) or x is None:
        return x
    if isinstance(x, np.ndarray):
        return [plain(v) for v in x.tolist()]
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, (list, tuple)):
        return [plain(v) for v in x]
    if isinstance(x, dict):
        return {k: plain(v) for k, v in x.items()}
    if hasattr(x, "__dataclass_fields__"):
        return {k: plain(getattr(x, k)) for k in x.__dataclass_fields__ if not k.startswith("__")}
    if hasattr(x, "__slots__"):
        return {k: plain(getattr(x, k)) for k in x.__slots__}
    raise TypeError(type(x))


def same(a, b, path="msg"):
    """Exact equality of written and read (floats bit for bit), with the place of a difference."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and set(a) <= set(b), f"{path}: {a} vs {b}"
        for k in a:
            same(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), f"{path}: {a} vs {b}"
        for i, (x, y) in enumerate(zip(a, b)):
            same(x, y, f"{path}[{i}]")
    elif isinstance(a, float):
        assert isinstance(b, float) and (a == b or (math.isnan(a) and math.isnan(b))), f"{path}: {a!r} vs {b!r}"
    else:
        assert a == b, f"{path}: {a!r} vs {b!r}"


def _stamp(t_ns: int) -> dict:
    return {"sec": t_ns // 1_000_000_000, "nanosec": t_ns % 1_000_000_000}


def _xyz(v) -> dict:
    return dict(zip("xyz", (float(c) for c in v)))


def _quat(q_wxyz) -> dict:
    w, x, y, z = (float(c) for c in q_wxyz)
    return {"x": x, "y": y, "z": z, "w": w}


def expected_messages(sim, t_ns: int) -> dict:
    """What each message must hold, written here from the Simulator's public API (README),
    independently of gyro_sim.msgs.messages."""
    hdr = {"stamp": _stamp(t_ns), "frame_id": ""}
    js = sim.joint_states()
    out = {M.JOINT_STATES: {"header": hdr, "name": list(js.name), "position": list(js.position),
                            "velocity": list(js.velocity), "effort": list(js.effort)},
           M.CLOCK: {"clock": _stamp(t_ns)}}
    for w in sim.wrenches():
        out[f"/gyro_sim/wrench/{w.joint}"] = {"header": {"stamp": _stamp(t_ns), "frame_id": w.joint},
                                              "wrench": {"force": _xyz(w.force), "torque": _xyz(w.moment)}}
    bodies = sim.body_states()
    world = {"stamp": _stamp(t_ns), "frame_id": "world"}
    out["/gyro_sim/poses"] = {"header": world,
                              "poses": [{"position": _xyz(b.position), "orientation": _quat(b.quaternion)}
                                        for b in bodies]}
    out["/tf"] = {"transforms": [{"header": world, "child_frame_id": b.name,
                                  "transform": {"translation": _xyz(b.position), "rotation": _quat(b.quaternion)}}
                                 for b in bodies]}
    return out


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    """A log holding every message type: outputs, commands, a reset event. Returns
    (path, {topic: [(t_ns, expected dict)]}, the scene); diagnostics are checked apart."""
    path = tmp_path_factory.mktemp("rt") / "all.mcap"
    scene = load_scene(SCENE)
    sim = Simulator(scene)
    written: dict[str, list] = {M.ROBOT_DESCRIPTION: [(0, {"data": urdf(scene)})]}
    with LogWriter(path, scene=scene, params=run_params(sim, advance_dt=0.01, publish_rate=100, source="test")) as w:
        r = LogRecorder(w, sim, diagnostics_period=0.03)
        for i in range(12):
            t_ns = r.time.ns
            r.publish()
            for topic, msg in expected_messages(sim, t_ns).items():
                written.setdefault(topic, []).append((t_ns, msg))
            if i in (0, 3, 6, 9, 10):  # every 0.03 s, and at once after the reset
                written.setdefault(M.DIAGNOSTICS, []).append((t_ns, None))
            if i in (2, 7):
                cmd = [0.01 * i, -0.02, 0.003]
                r.command(cmd)
                sim.set_axis_moments(cmd)
                written.setdefault(M.AXIS_MOMENTS, []).append(
                    (r.time.ns, {"layout": {"dim": [], "data_offset": 0}, "data": cmd}))
            if i == 9:
                t = r.time.ns
                r.reset()
                written.setdefault(M.EVENTS, []).append((t, {"data": "reset"}))
            sim.advance(0.01)
    return path, written, scene


def test_every_type_is_in_the_log(log):
    path, written, scene = log
    info = read_info(path)
    assert set(info.topics.values()) == set(TYPES)
    expected = M.topic_types([b.name for b in scene.bodies]) | {M.ROBOT_DESCRIPTION: "std_msgs/msg/String"}
    assert info.topics == expected
    assert info.message_count == sum(len(v) for v in written.values())
    assert info.params["integrator"] == "auto" and info.params["advance_dt"] == 0.01  # the default
    assert load_scene(info.scene_source()).name == scene.name


@pytest.mark.parametrize("msgtype", TYPES)
def test_rosbags_reads_back_what_was_written(log, msgtype):
    from rosbags.highlevel import AnyReader

    path, written, _ = log
    all_topics = M.topic_types(["arm1", "arm2", "arm3", "arm4"]) | {M.ROBOT_DESCRIPTION: "std_msgs/msg/String"}
    topics = [t for t, ty in all_topics.items() if ty == msgtype]
    with AnyReader([Path(path)]) as reader:
        cons = [c for c in reader.connections if c.topic in topics]
        assert cons and all(c.msgtype == msgtype for c in cons)
        got: dict[str, list] = {}
        for con, t, raw in reader.messages(connections=cons):
            got.setdefault(con.topic, []).append((t, plain(reader.deserialize(raw, con.msgtype))))
    for topic in topics:
        exp = written[topic]
        assert len(got[topic]) == len(exp), topic
        for (t0, m0), (t1, m1) in zip(exp, got[topic]):
            assert t0 == t1
            if m0 is not None:
                same(m0, m1, topic)


@pytest.mark.parametrize("msgtype", TYPES)
def test_mcap_ros2_decoder_reads_back_what_was_written(log, msgtype):
    path, written, _ = log
    got: dict[str, list] = {}
    for topic, ty, t, msg in iter_messages(path):
        if ty == msgtype:
            got.setdefault(topic, []).append((t, plain(msg)))
    assert got
    for topic, items in got.items():
        exp = written[topic]
        assert [t for t, _ in exp] == [t for t, _ in items]
        for (_, m0), (_, m1) in zip(exp, items):
            if m0 is not None:
                same(m0, m1, topic)


def test_diagnostics_are_numbers_with_units(log):
    """Every diagnostics value is a number (strings only under the text keys), vectors by
    component, and the momentum vector agrees with the vertical momentum (eq 79)."""
    path, _, _ = log
    diags = [msg for topic, _, _, msg in iter_messages(path, [M.DIAGNOSTICS])]
    assert len(diags) == 5
    for msg in diags:
        assert [st.name for st in msg.status] == [M.DYNAMICS_STATUS]
        for kv in msg.status[0].values:
            if kv.key not in M.STRING_KEYS:
                assert math.isfinite(float(kv.value)), kv
    d = M.diagnostic_numbers(diags[-1])
    assert {"energy_J", "energy_drift_rel", "vertical_momentum_drift_rel", "angular_momentum_O1_z_Nms",
            "work_by_commands_J", "energy_balance_J", "energy_balance_rel"} <= set(d)
    assert math.isclose(d["angular_momentum_O1_z_Nms"], d["vertical_momentum_Nms"], rel_tol=1e-12, abs_tol=1e-15)


def test_write_raw_stores_the_bytes_exactly(tmp_path):
    scene = load_scene(SCENE)
    data = [bytes([0, 1, 0, 0]) + b"\x05\x00\x00\x00hello\x00" + bytes(k) for k in range(4)]
    with LogWriter(tmp_path / "raw.mcap", scene=scene, params={}) as w:
        ch = w.add_channel("/chatter", "std_msgs/msg/String")
        for i, d in enumerate(data):
            w.write_raw(ch, 1000 * i, d, publish_time_ns=7 + i)
    got = [m for topic, _, _, m in iter_messages(tmp_path / "raw.mcap", ["/chatter"], decode=False)]
    assert got == data


def test_non_finite_values_never_reach_a_log(tmp_path):
    scene = load_scene(SCENE)
    with pytest.raises(M.NonFiniteError):
        M.axis_moments([0.0, float("nan")])
    with pytest.raises(M.NonFiniteError):
        M.diagnostic_array(0, [M.Status(M.DYNAMICS_STATUS, {"energy_J": float("inf")})])
    with pytest.raises(M.NonFiniteError):
        M.time_ns(float("nan"))
    with LogWriter(tmp_path / "nan.mcap", scene=scene, params={}) as w:
        ch = w.add_channel("/joint_states", "sensor_msgs/JointState")
        with pytest.raises(LogError, match="non-finite"):
            w.write(ch, 0, {"name": ["a"], "position": [float("nan")]})
        with pytest.raises(LogError):
            LogWriter(tmp_path / "p.mcap", scene=scene, params={"rtol": float("nan")})
    assert read_info(tmp_path / "nan.mcap").message_count == 1  # the URDF only


def test_channels_are_idempotent_and_typed(tmp_path):
    scene = load_scene(SCENE)
    w = LogWriter(tmp_path / "c.mcap", scene=scene, params={})
    a = w.add_channel("/joint_states", "sensor_msgs/msg/JointState")
    assert w.add_channel("/joint_states", "sensor_msgs/JointState") == a
    with pytest.raises(LogError, match="already has type"):
        w.add_channel("/joint_states", "std_msgs/msg/String")
    with pytest.raises(LogError):
        w.add_channel("/x", "no_such_msgs/msg/X")
    w.close()
    w.close()
    with pytest.raises(LogError, match="closed"):
        w.write(a, 0, {})


def test_log_is_chunked_compressed_and_indexed(log):
    from mcap.reader import make_reader

    path, _, _ = log
    with open(path, "rb") as f:
        reader = make_reader(f)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
    assert summary.chunk_indexes and all(c.compression in ("zstd", "lz4") for c in summary.chunk_indexes)
    assert all(c.message_index_offsets for c in summary.chunk_indexes)
    assert all(ch.message_encoding == "cdr" for ch in summary.channels.values())
    assert all(s.encoding == "ros2msg" for s in summary.schemas.values())


def test_flush_period_puts_the_data_in_the_file(tmp_path):
    """Written messages are in the file (a complete chunk) within the flush period, writes or not."""
    import time

    from mcap.stream_reader import StreamReader
    from mcap.records import Message

    scene = load_scene(SCENE)
    path = tmp_path / "f.mcap"
    w = LogWriter(path, scene=scene, params={}, flush_period=0.1)
    ch = w.add_channel("/s", "std_msgs/msg/String")
    for i in range(5):
        w.write(ch, i, {"data": str(i)})
    time.sleep(0.35)  # no more writes: the background timer flushes

    def readable():
        n = 0
        try:
            with open(path, "rb") as f:
                for rec in StreamReader(f).records:
                    n += isinstance(rec, Message)
        except Exception:  # noqa: BLE001 - the file ends in the middle: what came before counts
            pass
        return n

    assert readable() == 5 + 1  # and the URDF
    w.close()


def test_rclpy_serialized_bytes_are_stored_canonical_on_request(tmp_path):
    """serialize_message may pad (a JointState without efforts); canonical=True stores what rosbags accepts."""
    rclpy_ser = pytest.importorskip("rclpy.serialization")
    from rosbags.highlevel import AnyReader
    from sensor_msgs.msg import JointState

    msg = JointState(name=["a", "b"], position=[1.0, 2.0], velocity=[0.5, -0.5])  # effort empty
    msg.header.frame_id = "x"
    data = rclpy_ser.serialize_message(msg)
    scene = load_scene(SCENE)
    with LogWriter(tmp_path / "rclpy.mcap", scene=scene, params={}) as w:
        ch = w.add_channel("/joint_states", "sensor_msgs/msg/JointState")
        w.write_raw(ch, 0, data, canonical=True)
    with AnyReader([tmp_path / "rclpy.mcap"]) as reader:
        con = [c for c in reader.connections if c.topic == "/joint_states"]
        (_, _, raw), = list(reader.messages(connections=con))
        got = reader.deserialize(raw, "sensor_msgs/msg/JointState")
    assert list(got.name) == ["a", "b"] and list(got.position) == [1.0, 2.0] and got.header.frame_id == "x"
    assert len(raw) <= len(data)
