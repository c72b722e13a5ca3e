"""Message definitions: the schemas of the logs, installed or shipped."""
from __future__ import annotations

import pytest

from gyro_sim.msgs import messages as M
from gyro_sim.msgs import msgdefs

TYPES = sorted(set(M.topic_types(["a"]).values()))


@pytest.mark.parametrize("msgtype", TYPES)
def test_definition_parses_with_rosbags_and_mcap_ros2(msgtype):
    from mcap_ros2._dynamic import generate_dynamic
    from rosbags.typesys.msg import get_types_from_msg

    text = msgdefs.definition(msgtype)
    assert text.startswith(msgdefs.msg_text(msgtype))
    assert msgtype in generate_dynamic(msgtype, text)
    # rosbags: each block of the concatenated text is one type
    blocks = text.split(msgdefs.SEPARATOR + "\n")
    names = [msgtype] + [msgdefs.normalize(b.split("\n", 1)[0][len("MSG: "):]) for b in blocks[1:]]
    for name, block in zip(names, blocks):
        body = block if name == msgtype else block.split("\n", 1)[1]
        assert name in get_types_from_msg(body, name)


@pytest.mark.parametrize("msgtype", TYPES)
def test_shipped_copies_cover_every_type_and_match_the_installed_ones(msgtype):
    """Offline runs need no ROS: the shipped copies define the same types as the installed files."""
    for t in msgdefs.closure([msgtype]):
        shipped = msgdefs.msg_text(t, shipped_only=True)
        try:
            installed = msgdefs.msg_text(t)
        except LookupError:
            continue
        assert shipped == installed, t
    assert msgdefs.definition(msgtype, shipped_only=True) == msgdefs.definition(msgtype) or "tf2_msgs" in msgtype


def test_tf_message_is_a_list_of_transform_stamped():
    assert "geometry_msgs/TransformStamped[] transforms" in msgdefs.msg_text("tf2_msgs/msg/TFMessage")
    assert "MSG: geometry_msgs/Transform\n" in msgdefs.definition("tf2_msgs/msg/TFMessage")


def test_unknown_type_is_refused():
    with pytest.raises(LookupError):
        msgdefs.definition("no_such_msgs/msg/Nothing")
    with pytest.raises(ValueError):
        msgdefs.normalize("JointState")
