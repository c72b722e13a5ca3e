"""The live view draws what the log view draws, and a URDF robot as itself (gyro_sim.viz.robot,
gyro_sim.viz.chain, docs/viewer.md).

The log view's chain comes from the log's scene, the live view's from the node's
robot_description: for every shipped scene both must be the same chain (bodies, rotors by
name, gravity, base) and draw the same entities. A URDF robot's description draws its links'
visuals, moved by its links' /tf.
"""
from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

rr = pytest.importorskip("rerun")

from gyro_sim import Simulator, load_scene
from gyro_sim.msgs import messages as M
from gyro_sim.paths import find_scene, shipped_scenes
from gyro_sim.scene.urdf import urdf
from gyro_sim.viz.chain import from_scene, from_urdf
from gyro_sim.viz.translate import Translator

ERD = Path(__file__).parents[1] / "scene" / "models" / "example_robot_data"


def entities(rrd: Path) -> set[str]:
    from rerun.chunk import RrdReader

    return {c.entity_path for c in RrdReader(str(rrd)).stream()}


def recording(tmp_path: Path, name: str):
    rec = rr.RecordingStream("gyro_sim_test", recording_id=name)
    rec.save(str(tmp_path / f"{name}.rrd"))
    return rec


@pytest.mark.parametrize("scene_path", shipped_scenes(), ids=lambda p: p.stem)
def test_the_live_view_draws_the_log_views_entities(scene_path, tmp_path):
    scene = load_scene(scene_path)
    live, log = from_urdf(urdf(scene)), from_scene(scene)
    assert live.body_names == log.body_names
    assert [[r.name for r in b.rotors] for b in live.bodies] == [[r.name for r in b.rotors] for b in log.bodies]
    assert (live.gravity is None) == (log.gravity is None)
    a, b = live, log
    numbers = [(np.r_[a.length, a.base, a.gravity if a.gravity is not None else []],
                np.r_[b.length, b.base, b.gravity if b.gravity is not None else []])]
    for x, y in zip(live.bodies, log.bodies):
        numbers.append((np.r_[x.extent, x.radius], np.r_[y.extent, y.radius]))
        for r, q in zip(x.rotors, y.rotors):
            numbers.append((np.r_[r.position, r.axis, r.radius, r.thickness],
                            np.r_[q.position, q.axis, q.radius, q.thickness]))
    for a, b in numbers:  # the URDF's numbers are the scene's, through its roll-pitch-yaw (round-off)
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)
    drawn = {}
    for name, feed in (("log", lambda tr: None),
                       ("live", lambda tr: tr.message(M.ROBOT_DESCRIPTION, 0.0, SimpleNamespace(data=urdf(scene))))):
        rec = recording(tmp_path, name)
        tr = Translator(rec, from_scene(scene) if name == "log" else None)
        feed(tr)
        tr.flush()
        rec.flush()
        rec.disconnect()
        drawn[name] = entities(tmp_path / f"{name}.rrd") - {"/world/legend", "/__properties"}
    assert drawn["live"] == drawn["log"]
    if scene.gravity is not None:
        assert "/world/gravity" in drawn["live"]
    for b in scene.bodies:
        for r in b.rotors:
            assert f"/world/{b.name}/{r.name}/spin/disc" in drawn["live"]


def tf_message(names, positions, quaternions):
    """A TFMessage-like object (as rclpy or the log reader gives it)."""
    def vec(v):
        return SimpleNamespace(x=v[0], y=v[1], z=v[2])

    return SimpleNamespace(transforms=[
        SimpleNamespace(child_frame_id=n, transform=SimpleNamespace(
            translation=vec(p), rotation=SimpleNamespace(x=q[1], y=q[2], z=q[3], w=q[0])))
        for n, p, q in zip(names, positions, quaternions)])


def test_a_urdf_robot_is_drawn_with_its_meshes_where_its_links_are(tmp_path):
    from gyro_sim.scene.robot import link_transforms

    scene = load_scene(find_scene("ur5.urdf"))
    sim = Simulator(scene, integrator="rk4", step=1e-3, backend="numpy")
    sim.advance(0.2)
    names, positions, quaternions = link_transforms(scene.robot, sim)
    rec = recording(tmp_path, "ur5")
    tr = Translator(rec)
    tr.message(M.ROBOT_DESCRIPTION, 0.0, SimpleNamespace(data=scene.robot.urdf))
    tr.message(M.TF, 0.2, tf_message(names, positions, quaternions))
    tr.flush()
    rec.flush()
    rec.disconnect()
    got = entities(tmp_path / "ur5.rrd")
    for link in ("shoulder_link", "upper_arm_link", "forearm_link", "wrist_3_link"):
        assert f"/world/robot/{link}" in got and f"/world/robot/{link}/visual0" in got
    assert tr.notes == []  # every mesh found (the shipped package)
    assert tr.last_pose is None  # link frames move the robot, not the chain's bodies
    assert np.isfinite(positions).all()


def test_a_robot_with_colladas_is_drawn_as_its_frames_with_one_note(tmp_path):
    text = (ERD / "panda.urdf").read_text()
    rec = recording(tmp_path, "panda")
    tr = Translator(rec)
    tr.message(M.ROBOT_DESCRIPTION, 0.0, SimpleNamespace(data=text))
    tr.flush()
    rec.flush()
    rec.disconnect()
    assert len(tr.notes) == 1 and tr.notes[0].startswith("robot meshes not drawn: ")
    assert ".dae" in tr.notes[0]
    assert "/world/robot/panda_link3" in entities(tmp_path / "panda.rrd")
