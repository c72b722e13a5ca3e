"""The recorder's own /tf encoder against the generic CDR encoder and rosbags (no rclpy needed)."""
from __future__ import annotations

import pytest

from gyro_sim.ros.recorder import encode_tf


@pytest.mark.parametrize("suffix", ["", "a", "ab", "abc"])  # every string alignment
def test_encode_tf_matches_the_generic_encoder(suffix):
    mcap_dynamic = pytest.importorskip("mcap_ros2._dynamic")
    from gyro_sim.io import msgdefs

    name = "tf2_msgs/msg/TFMessage"
    enc = mcap_dynamic.serialize_dynamic(name, msgdefs.definition(name))[name]
    tr = [(f"link{k}{suffix}", (0.1 * k, -0.2, 1.0 + k), (0.5, -0.5, 0.5, 0.5)) for k in range(3)]
    mine = encode_tf(1_500_000_123, "world" + suffix, tr)
    ref = enc({"transforms": [
        {"header": {"stamp": {"sec": 1, "nanosec": 500_000_123}, "frame_id": "world" + suffix}, "child_frame_id": c,
         "transform": {"translation": dict(zip("xyz", p)), "rotation": dict(zip("xyzw", q))}} for c, p, q in tr]})
    assert mine[4:] == bytes(ref)[4:]
    rosbags = pytest.importorskip("rosbags.typesys")
    msg = rosbags.get_typestore(rosbags.Stores.ROS2_JAZZY).deserialize_cdr(mine, name)
    assert [t.child_frame_id for t in msg.transforms] == [c for c, _, _ in tr]
    assert msg.transforms[2].transform.translation.z == 3.0 and msg.transforms[0].header.stamp.nanosec == 500_000_123
