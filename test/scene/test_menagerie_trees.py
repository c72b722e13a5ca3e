"""Menagerie's legged robots and humanoids (docs/models.md, "Menagerie's legged robots and
humanoids"): what they needed of the importer, on small models written here and judged by
MuJoCo as test/scene/test_model_trees.py judges trees; and, given a checkout of MuJoCo Menagerie
in the environment variable MENAGERIE (it is not part of the repository), the robots themselves
(test/scene/menagerie_trees.py).
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco", reason="MuJoCo is the optional extra [models]")

from gyro_sim.scene.load import load_scene
from gyro_sim.scene.mjcf import import_model
from test.scene.test_model_sensors import READING_RTOL, deviation, gyro_readings, mujoco_readings
from test.scene.test_model_trees import FREE, probed, two_arms


def test_a_free_body_named_base_takes_another_scene_name(tmp_path):
    """Go2's and ANYmal's trunk is a free body named `base`, the name a scene's `parent` gives
    the base: the scene names it `base_` (the free joint has no name), its children hang from it,
    and it moves as MuJoCo's."""
    path = two_arms(tmp_path, FREE.replace(' name="root"', "")).rename(tmp_path / "trunk.xml")
    path.write_text(path.read_text().replace('name="torso"', 'name="base"'))
    bodies = import_model(path).mapping["bodies"]
    assert [(b["name"], b.get("parent")) for b in bodies] == [
        ("base_", None), ("l_upper", None), ("l_elbow_x", None), ("l_elbow_y", None), ("l_slide", None),
        ("r_shoulder", "base_"), ("r_elbow", None), ("r_wrist", None), ("tail", "base_")]
    assert [b.parent for b in load_scene(path).bodies] == [-1, 0, 1, 2, 3, 0, 5, 6, 0]
    probe, sites = probed(path, tmp_path)
    ctrl = np.zeros(mujoco.MjModel.from_xml_path(str(probe)).nu)
    worst = max(deviation(mujoco_readings(probe, ctrl, key=k), gyro_readings(probe, k, ctrl), sites)
                for k in ("probe0", "probe1"))
    print(f"free body named base: {len(sites)} IMUs within {worst:.2g} (relative) of MuJoCo's sensors")
    assert worst <= READING_RTOL


def test_a_hinge_named_base_takes_its_bodys_name_or_base_(tmp_path):
    """A hinge joint named `base` is named after its body; unnamed, `base_`, with `_` added while
    that is a name of the model's."""
    text = two_arms(tmp_path).read_text().replace('name="waist"', 'name="base"')
    path = tmp_path / "hinged_base.xml"
    path.write_text(text)
    assert import_model(path).mapping["bodies"][0]["name"] == "torso"
    path.write_text(text.replace('<body name="torso" ', '<body ').replace('<body name="tail"', '<body name="base_"'))
    assert import_model(path).mapping["bodies"][0]["name"] == "base__"
    assert [b.name for b in load_scene(path).bodies][0] == "base__"


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("MENAGERIE"), reason="MENAGERIE names no checkout of MuJoCo Menagerie")
def test_menageries_robots_move_as_in_mujoco(tmp_path):
    """Every robot of menagerie_trees.MODELS that imports accelerates and moves as MuJoCo's;
    the others are refused naming their element."""
    from test.scene.menagerie_trees import MODELS, judge

    root = Path(os.environ["MENAGERIE"])
    for name, (file, keyframe, lock) in MODELS.items():
        if not (root / file).is_file():
            continue
        row = judge(root / file, keyframe, lock, tmp_path)
        print(name, row)
        if row["refused"]:
            assert "'" in row["refused"]  # an element named
        elif "qacc" in row:
            assert row["qacc"] <= 1e-12 and row["imu"] <= READING_RTOL and row["motion"] <= 1e-8
