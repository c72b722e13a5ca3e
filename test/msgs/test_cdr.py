"""gyro_sim's CDR bytes against three independent implementations: the generic encoder of
mcap-ros2-support (byte for byte), rosbags' decoder and rclpy's (field for field)."""
from __future__ import annotations

import numpy as np
import pytest

from gyro_sim.snapshot import Snapshot
from gyro_sim.msgs import messages as M
from gyro_sim.msgs import msgdefs


def encoder(msgtype):
    from mcap_ros2._dynamic import serialize_dynamic

    return serialize_dynamic(msgtype, msgdefs.definition(msgtype))[msgtype]


def snapshot(suffix: str, n: int = 3) -> Snapshot:
    """A snapshot with names of every length modulo 4 (every string alignment)."""
    rng = np.random.default_rng(len(suffix))
    names = tuple(f"b{k}{suffix}" for k in range(n))
    q = rng.normal(size=(n, 4))
    return Snapshot(
        time=1.25, joint_names=tuple(f"j{k}{suffix * k}" for k in range(2 * n)), position=rng.normal(size=2 * n),
        velocity=rng.normal(size=2 * n), effort=np.zeros(2 * n), axis_names=("a" + suffix,),
        axis_moments=np.array([0.5]),
        integrator="rk4", error_estimate=None, body_names=names, body_position=rng.normal(size=(n, 3)),
        body_quaternion=q / np.linalg.norm(q, axis=1, keepdims=True), wrench_force=rng.normal(size=(n, 3)),
        wrench_moment=rng.normal(size=(n, 3)),
        invariants={"energy": 1.5, "kinetic": 1.0, "potential": 0.5, "angular_momentum_O1": np.array([0.1, 0.2, 0.3]),
                    "vertical_momentum": 0.3}, drift={"energy": 1e-12}, work=0.25, energy_balance=-1e-13,
        energy_scale=1.5)


def expected(snap, t_ns):
    """The messages as dicts, written from the snapshot's fields and the message definitions."""
    st = {"sec": t_ns // 10**9, "nanosec": t_ns % 10**9}
    world = {"stamp": st, "frame_id": "world"}
    poses = [{"position": dict(zip("xyz", p)), "orientation": dict(zip("wxyz", q))}
             for p, q in zip(snap.body_position.tolist(), snap.body_quaternion.tolist())]
    out = {
        M.JOINT_STATES: {"header": {"stamp": st, "frame_id": ""}, "name": list(snap.joint_names),
                         "position": snap.position.tolist(), "velocity": snap.velocity.tolist(),
                         "effort": snap.effort.tolist()},
        M.CLOCK: {"clock": st},
        M.POSES: {"header": world, "poses": poses},
        M.TF: {"transforms": [{"header": world, "child_frame_id": b,
                               "transform": {"translation": p["position"], "rotation": p["orientation"]}}
                              for b, p in zip(snap.body_names, poses)]},
    }
    for b, f, m in zip(snap.body_names, snap.wrench_force.tolist(), snap.wrench_moment.tolist()):
        out[M.wrench_topic(b)] = {"header": {"stamp": st, "frame_id": b},
                                  "wrench": {"force": dict(zip("xyz", f)), "torque": dict(zip("xyz", m))}}
    return out


@pytest.mark.parametrize("suffix", ["", "a", "ab", "abc"])
def test_bytes_equal_the_generic_encoder(suffix):
    snap = snapshot(suffix)
    t_ns = 1_500_000_123
    msgs = M.Publication(snap.body_names).messages(snap, t_ns, diagnostics_run=M.Status(M.RUN_STATUS, {"state": "x"}))
    exp = expected(snap, t_ns)
    checked = 0
    for topic, msgtype, data in msgs:
        if topic in exp:
            assert data == bytes(encoder(msgtype)(exp[topic])), topic
            checked += 1
    assert checked == len(exp)
    cmd = [0.5, -1.0, 2.0 ** -30]
    assert M.axis_moments(cmd) == bytes(encoder(M.COMMAND_TYPE)({"layout": {"dim": [], "data_offset": 0}, "data": cmd}))
    assert M.string("reset" + suffix) == bytes(encoder(M.STRING_TYPE)({"data": "reset" + suffix}))


@pytest.mark.parametrize("suffix", ["", "ab"])
def test_rosbags_and_rclpy_decode_every_message(suffix):
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    snap = snapshot(suffix)
    msgs = M.Publication(snap.body_names, hardware_id="h").messages(
        snap, 7, diagnostics_run=M.Status(M.RUN_STATUS, {"state": "running", "deadline_misses": 3}))
    for topic, msgtype, data in msgs:
        msg = store.deserialize_cdr(data, msgtype)  # rosbags refuses a size mismatch: no stray bytes
        if topic == M.DIAGNOSTICS:
            dyn, run = msg.status
            assert (dyn.name, run.name, dyn.hardware_id) == (M.DYNAMICS_STATUS, M.RUN_STATUS, "h")
            values = {kv.key: kv.value for kv in dyn.values}
            assert float(values["energy_J"]) == 1.5 and float(values["angular_momentum_O1_y_Nms"]) == 0.2
            assert float(values[M.BALANCE_REL_KEY]) == -1e-13 / 1.5 and values["integrator"] == "rk4"
            assert {kv.key: kv.value for kv in run.values} == {"state": "running", "deadline_misses": "3"}
    rclpy_ser = pytest.importorskip("rclpy.serialization", reason="rclpy is the third reader (pip install '.[ros]')")
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import JointState

    by_topic = {t: d for t, _, d in msgs}
    js = rclpy_ser.deserialize_message(by_topic[M.JOINT_STATES], JointState)
    assert list(js.name) == list(snap.joint_names) and np.array_equal(js.position, snap.position)
    diag = rclpy_ser.deserialize_message(by_topic[M.DIAGNOSTICS], DiagnosticArray)
    assert M.diagnostic_numbers(diag)["deadline_misses"] == 3.0


def test_non_finite_values_and_text_in_numeric_keys_are_refused():
    snap = snapshot("")
    bad = Snapshot(**{**snap.__dict__, "position": np.array([np.nan] * len(snap.position))})
    assert bad.nonfinite() == "position"
    with pytest.raises(M.NonFiniteError):
        M.joint_state(bad, 0)
    with pytest.raises(M.NonFiniteError):
        M.diagnostic_array(0, [M.Status(M.RUN_STATUS, {"deadline_misses": "many"})])
    with pytest.raises(M.NonFiniteError):
        M.diagnostic_array(0, [M.Status(M.RUN_STATUS, {"step_time_p50_us": float("nan")})])
