"""The URDF every log carries on /robot_description."""
from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest

from gyro_sim import load_scene
from gyro_sim.scene.urdf import quat_z_to, rpy_z_to, urdf

from test.conftest import ROOT


@pytest.mark.parametrize("name", ["hinge_chain", "double_gyro_plus", "free_chain_rotors", "chain_4"])
def test_urdf_has_a_link_per_body_with_its_shapes(name):
    scene = load_scene(ROOT / "config" / f"{name}.yaml")
    robot = ET.fromstring(urdf(scene))
    links = {link.get("name"): link for link in robot.findall("link")}
    assert set(links) == {"world"} | {b.name for b in scene.bodies}
    for b in scene.bodies:
        cylinders = links[b.name].findall("visual/geometry/cylinder")
        assert len(cylinders) == 1 + len(b.rotors)
        assert all(float(c.get("length")) > 0 and float(c.get("radius")) > 0 for c in cylinders)
    joints = robot.findall("joint")  # each body's joint from its parent's link: a chain's previous body
    assert [j.find("child").get("link") for j in joints] == [b.name for b in scene.bodies]
    assert [j.find("parent").get("link") for j in joints] == ["world"] + [b.name for b in scene.bodies[:-1]]


@pytest.mark.parametrize("v", [[0, 0, 1], [1, 0, 0], [0, 1, 0], [0, 0, -1], [1, -2, 0.5]])
def test_shape_orientation_turns_z_onto_the_axis(v):
    from scipy.spatial.transform import Rotation

    v = np.asarray(v, float) / np.linalg.norm(v)
    assert np.allclose(Rotation.from_quat(quat_z_to(v)).apply([0, 0, 1]), v)
    assert np.allclose(Rotation.from_euler("xyz", rpy_z_to(v)).apply([0, 0, 1]), v)
