"""A tree in the views (docs/viewer.md): each body drawn from its joint point to each child's,
the lines through the joint points branching where the tree does, every joint point on the
base marked, and the live view (the URDF on robot_description, each link joined to its
parent's) drawing what the log view draws.

The log is written offline by the recorder (`record_run`) and read back by the log view
(`build_recording`); what the view drew at the last publication is checked against the /tf of
that publication and the tree written here: O^k of each child is its parent's O plus the
parent's rotation times its `joint.at` (the kinematics of the scene file, written out here).
"""
from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest

rr = pytest.importorskip("rerun")

from gyro_sim import Simulator, load_scene
from gyro_sim.dynamics.rotations import quat_to_matrix
from gyro_sim.log.mcap_log import iter_messages
from gyro_sim.log.record import record_run
from gyro_sim.msgs import messages as M
from gyro_sim.scene.urdf import urdf
from gyro_sim.viz.chain import from_scene, from_urdf
from gyro_sim.viz.rerun_view import build_recording
from test.conftest import ROOT
from test.viz.test_rerun import chunks, column

#: drawn points against the /tf (rerun keeps float32)
DRAWN_ATOL = 1e-5


def body(name: str, joint: dict, com, **more) -> dict:
    out = {"name": name, "joint": joint, "mass": 1.0, "com": com,
           "inertia_com": [[0.02, 0.0, 0.0], [0.0, 0.03, 0.0], [0.0, 0.0, 0.01]]}
    out.update(more)
    return out


#: a torso on a hinge carrying two arms (the left one two bodies long) at their own joint
#: points, and a pole on the base beside it, under gravity
TREE = {
    "name": "torso, two arms and a pole",
    "gravity": [0.0, 0.0, -9.81],
    "base": {"type": "fixed", "position": [0.0, 0.0, 1.0]},
    "bodies": [
        body("torso", {"type": "hinge", "axis": [0.0, 0.0, 1.0]}, [0.0, 0.0, 0.2],
             next_joint=[0.0, 0.3, 0.4], initial={"angle": 0.2, "rate": 1.0}),
        body("left", {"type": "hinge", "axis": [0.0, 1.0, 0.0]}, [0.0, 0.0, -0.15],
             next_joint=[0.0, 0.0, -0.3], initial={"angle": 0.5}),
        body("hand", {"type": "spherical"}, [0.05, 0.0, -0.1],
             initial={"quaternion": [0.9, 0.1, 0.3, 0.0], "angular_velocity": [1.0, -2.0, 0.5]}),
        body("right", {"type": "hinge", "axis": [1.0, 0.0, 0.0], "at": [0.0, -0.3, 0.4]}, [0.0, 0.0, -0.2],
             parent="torso", initial={"angle": -0.4}),
        body("pole", {"type": "hinge", "axis": [1.0, 0.0, 0.0], "at": [0.6, 0.0, -0.5]}, [0.0, 0.0, 0.25],
             parent="base", initial={"angle": 0.1}),
    ],
}
#: each body's parent, and the lines the view draws through the joint points: (bodies, tip)
PARENTS = [None, "torso", "left", "torso", None]
LINES = [(["torso", "left", "hand"], "hand"), (["torso", "right"], "right"), (["pole"], "pole")]


def test_both_views_know_the_tree_and_each_bodys_segments():
    scene = load_scene(TREE)
    live, log = from_urdf(urdf(scene)), from_scene(scene)
    for chain in (live, log):
        assert [b.parent for b in chain.bodies] == PARENTS
        assert chain.parents() == [-1, 0, 1, 0, -1]
    torso = [np.asarray(s) for s in (TREE["bodies"][0]["next_joint"], TREE["bodies"][3]["joint"]["at"])]
    for a, b in zip(live.bodies, log.bodies):  # the URDF's numbers through its roll-pitch-yaw (round-off)
        assert len(a.segments) == len(b.segments)
        for x, y in zip(a.segments, b.segments):
            np.testing.assert_allclose(x, y, rtol=0, atol=1e-12)
    np.testing.assert_allclose(log.bodies[0].segments, torso, rtol=0, atol=0)  # to each child's joint point
    assert [len(b.segments) for b in log.bodies] == [2, 1, 1, 1, 1]  # the leaves to twice their centre of mass
    np.testing.assert_allclose(log.bodies[2].segments[0], [0.1, 0.0, -0.2], rtol=0, atol=0)
    joints = ET.fromstring(urdf(scene)).findall("joint")  # each link joined to its parent's
    assert [(j.find("parent").get("link"), j.find("child").get("link")) for j in joints] == [
        ("world", "torso"), ("torso", "left"), ("left", "hand"), ("torso", "right"), ("world", "pole")]


def test_the_log_view_draws_the_tree_where_tf_puts_it(tmp_path):
    scene = load_scene(TREE)
    log = tmp_path / "tree.mcap"
    record_run(Simulator(scene, backend="numpy"), log, duration=0.2)
    last = [m for _, _, _, m in iter_messages(log, [M.TF])][-1]
    assert [tr.header.frame_id for tr in last.transforms] == ["world"] * 5  # every body's frame from the world
    tf = {tr.child_frame_id: (np.array([tr.transform.translation.x, tr.transform.translation.y,
                                        tr.transform.translation.z]),
                              quat_to_matrix(np.array([tr.transform.rotation.w, tr.transform.rotation.x,
                                                       tr.transform.rotation.y, tr.transform.rotation.z])))
          for tr in last.transforms}
    assert list(tf) == [b.name for b in scene.bodies]
    bodies = {b["name"]: b for b in TREE["bodies"]}
    for b, parent in zip(TREE["bodies"], PARENTS):  # O^k = O^parent + R^parent at (the scene file's kinematics)
        if parent is not None:
            O, R = tf[parent]
            at = b["joint"].get("at", bodies[parent].get("next_joint"))
            np.testing.assert_allclose(tf[b["name"]][0], O + R @ np.asarray(at), rtol=0, atol=1e-12)
    rrd = tmp_path / "tree.rrd"
    rec = rr.RecordingStream("gyro_sim_test", recording_id="tree")
    rec.save(str(rrd))
    build_recording(log, rec)
    rec.flush()
    rec.disconnect()
    got = chunks(rrd)
    strips = column(got["/world/links"], "LineStrips3D:strips")[-1]  # at the last publication
    expected = [[tf[n][0] for n in names] + [tf[tip][0] + tf[tip][1] @ (2.0 * np.asarray(bodies[tip]["com"]))]
                for names, tip in LINES]
    assert len(strips) == len(expected)
    for drawn, points in zip(strips, expected):
        np.testing.assert_allclose(np.array(drawn), np.array(points), rtol=0, atol=DRAWN_ATOL)
    base = column(got["/world/base"], "Points3D:positions")[-1]  # the joint points on the base
    np.testing.assert_allclose(np.array(base), [tf["torso"][0], tf["pole"][0]], rtol=0, atol=DRAWN_ATOL)
    lengths = column(got["/world/torso/body"], "Capsules3D:lengths")[-1]  # to each child's joint point
    np.testing.assert_allclose(lengths, [0.5, 0.5], rtol=0, atol=DRAWN_ATOL)


@pytest.mark.parametrize("name", ["spacecraft_panels"])
def test_a_shipped_tree_draws_its_bodies_from_the_hub(name):
    scene = load_scene(ROOT / "config" / f"{name}.yaml")
    chain = from_scene(scene)
    assert chain.parents() == [-1, 0, 0]
    assert [len(b.segments) for b in chain.bodies] == [2, 1, 1]
