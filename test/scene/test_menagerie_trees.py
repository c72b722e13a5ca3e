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
from gyro_sim.scene.mjcf import ModelError, import_model
from test.scene.test_model_import import write
from test.scene.test_model_sensors import READING_RTOL, deviation, gyro_readings, mujoco_readings
from test.scene.test_model_trees import FREE, POSE_ATOL, pose_deviation, probed, two_arms


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


#: a Cassie-like leg on a free pelvis: a hip, a knee, a rod on a ball joint at the hip closing a
#: loop with the heel (on a spring hinge of the shin) through a `connect`; the rod's joint {rod}
LEG = """<mujoco model="leg">
  <worldbody>
    <body name="pelvis" pos="0 0 1">
      <freejoint name="root"/>
      <inertial pos="0 0 0" mass="5" diaginertia="0.1 0.08 0.06"/>
      <body name="thigh" xyaxes="0 0 -1 0 1 0">
        <joint name="hip" axis="0 0 1"/>
        <inertial pos="0.1 0 0" mass="2" diaginertia="0.01 0.02 0.02"/>
        <body name="rod" pos="0 0 0.04" xyaxes="0.7922 -0.60599 -0.072096 0.60349 0.79547 -0.054922">
          {rod}
          <inertial pos="0.2 0 0" mass="0.15" diaginertia="1e-5 0.004 0.004"/>
        </body>
        <body name="shin" pos="0.4 0 0">
          <joint name="knee" axis="0 0 1" ref="-0.7"/>
          <inertial pos="0.2 0 0" mass="0.6" diaginertia="0.001 0.01 0.01"/>
          <body name="heel" pos="0.1 0.05 0">
            <joint name="heel_spring" axis="0 0 1" stiffness="1000"/>
            <inertial pos="0.05 0 0" mass="0.1" diaginertia="1e-5 1e-4 1e-4"/>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
  <equality>
    <connect body1="rod" body2="heel" anchor="0.45 0 0"/>
  </equality>
  <keyframe>
    <key name="home" qpos="0 0 1 1 0 0 0 0.3 0.98 0.05 -0.02 0.19 -1.1 0.02"/>
  </keyframe>
</mujoco>
"""
LOOP = ("'rod', 'knee', 'heel_spring'")


def test_a_loop_closed_by_a_connect_is_refused_naming_its_ends_and_the_joints_to_lock(tmp_path):
    """Cassie's legs close loops through `connect` equalities: the refusal names the bodies it
    ties and the joints between them (from each end up to their common ancestor), and that
    --lock (at the keyframe) makes the leg a tree whose frames carry MuJoCo's bodies held there."""
    path = write(tmp_path, "leg.xml", LEG.format(rod='<joint name="rod" type="ball"/>'))
    with pytest.raises(ModelError) as info:
        import_model(path, "home")
    assert info.value.errors == [
        f"{path}: equality #0: equality constraints are not supported (an open tree only): it closes a loop from "
        f"body 'rod' to body 'heel'; --lock the joints of the loop to weld it ({LOOP})"]
    lock = ("rod", "knee", "heel_spring")
    imported = import_model(path, "home", lock=list(lock))
    assert [b["name"] for b in imported.mapping["bodies"]] == ["pelvis", "hip"]
    assert "equality #0: left out, body 'rod' and body 'heel' are welded into one by --lock (it moves nothing)" \
        in imported.notes
    assert imported.mapping["bodies"][1]["mass"] == pytest.approx(2.85)  # the rod, shin and heel welded to the thigh
    worst, compared = pose_deviation(path, lock)
    assert compared == 2 and worst <= POSE_ATOL
    unnamed = write(tmp_path, "unnamed.xml", LEG.format(rod='<joint type="ball"/>'))
    with pytest.raises(ModelError) as info:
        import_model(unnamed, "home")
    assert info.value.errors[0].endswith("it closes a loop from body 'rod' to body 'heel'")  # no lock can weld it


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
