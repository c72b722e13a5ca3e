"""What a model needs and what it is refused for (docs/models.md): inertias outside the
triangle inequality (refused naming the body, or MuJoCo's balanced inertia with
--balance-inertia, judged against MuJoCo doing the same), what does not move needs no mass
(a missing mesh there, a missing texture: notes), and one refusal listing every problem of a
file, never suggesting a --lock that would then be refused."""
from __future__ import annotations

import re

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco", reason="MuJoCo is the optional extra [models]")

from gyro_sim import Simulator
from gyro_sim.cli import main
from gyro_sim.dynamics.model import initial_state
from gyro_sim.scene.load import SceneError, load_scene
from gyro_sim.scene.mjcf import ModelError, import_model
from test.scene.test_model_import import write

#: the inertia of pybullet_data's xArm6 link3 (its principal moments 0.00202, 0.00430, 0.00731
#: break A + B >= C), on the base and on the moving link of a two-link arm
XARM_LINK3 = ('<inertia ixx="0.0053694" ixy="0.0014185" ixz="-0.00092094" iyy="0.0032423" '
              'iyz="-0.00169178" izz="0.00501731"/>')
TRIANGLE_URDF = f"""<robot name="lopsided">
  <link name="world"/>
  <joint name="mount" type="fixed"><parent link="world"/><child link="base"/></joint>
  <link name="base"><inertial><mass value="2.7"/>{XARM_LINK3}</inertial></link>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="upper"/><origin xyz="0 0 0.3"/><axis xyz="0 1 0"/>
    <limit effort="10" lower="-3" upper="3" velocity="3"/>
  </joint>
  <link name="upper"><inertial><origin xyz="0.07 0.1 0.01"/><mass value="1.384"/>{XARM_LINK3}</inertial></link>
  <joint name="elbow" type="revolute">
    <parent link="upper"/><child link="fore"/><origin xyz="0.3 0 0" rpy="0.3 0 0"/><axis xyz="0 0 1"/>
    <limit effort="10" lower="-3" upper="3" velocity="3"/>
  </joint>
  <link name="fore"><inertial><origin xyz="0.1 0 0"/><mass value="0.8"/>
    <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.004" iyz="0" izz="0.0045"/></inertial></link>
</robot>
"""


def test_an_inertia_outside_the_triangle_inequality_is_refused_naming_the_link(tmp_path):
    path = write(tmp_path, "lopsided.urdf", TRIANGLE_URDF)
    with pytest.raises(SceneError) as info:
        load_scene(path)
    (error,) = info.value.errors  # the base's is a note: it moves nothing
    assert error.startswith(f"{path}: link 'upper': principal moments of inertia (0.00202307, 0.00429974, "
                            "0.0073062) break the triangle inequality A + B >= C")
    assert "--balance-inertia" in error


def test_balance_inertia_takes_mujocos_balanced_inertia_and_moves_as_mujoco(tmp_path):
    path = write(tmp_path, "lopsided.urdf", TRIANGLE_URDF)
    imported = import_model(path, balance_inertia=True)
    assert any(n.startswith("link 'upper': principal moments") and "(--balance-inertia)" in n for n in imported.notes)
    assert any(n.startswith("link 'base': principal moments") and "welded to the world" in n for n in imported.notes)
    spec = mujoco.MjSpec.from_file(str(path))
    spec.compiler.balanceinertia = True
    m = spec.compile()
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT) | int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    d = mujoco.MjData(m)
    sim = Simulator(load_scene(path, balance_inertia=True), backend="numpy")
    model = sim.model
    rng = np.random.default_rng(4)
    for _ in range(4):
        d.qpos[:], d.qvel[:] = rng.uniform(-2, 2, 2), rng.normal(size=2)
        mujoco.mj_forward(m, d)
        y = initial_state(model)
        y[model.i_phi], y[model.i_vel] = d.qpos, d.qvel
        udot = sim.held_rhs()(0.0, y)[model.i_vel]
        assert np.max(np.abs(udot - d.qacc)) <= 1e-9 * np.max(np.abs(d.qacc))


def test_the_command_line_takes_balance_inertia(tmp_path, capsys):
    path = write(tmp_path, "lopsided.urdf", TRIANGLE_URDF)
    assert main(["import", str(path), "-o", str(tmp_path / "a.yaml")]) == 2
    assert "--balance-inertia sets them to their mean" in capsys.readouterr().err
    assert main(["import", str(path), "-o", str(tmp_path / "a.yaml"), "--balance-inertia"]) == 0
    assert "set to their mean" in (tmp_path / "a.yaml").read_text()
    with pytest.raises(SceneError, match="balance_inertia: only an MJCF or URDF model"):
        load_scene("hinge_chain", balance_inertia=True)


#: a base whose mass would come from a missing mesh, a moving link with an inertial, a
#: material with a texture whose file is missing
STATIC_MESH = """<mujoco model="stand">
  <asset>
    <mesh name="pedestal" file="missing/pedestal.stl"/>
    <texture name="wood" type="2d" file="missing/wood.png"/>
    <material name="varnish" texture="wood"/>
  </asset>
  <worldbody>
    <body name="stand">
      <geom type="mesh" mesh="pedestal" material="varnish"/>
      <body name="arm" pos="0 0 1">
        <joint name="pivot" type="hinge" axis="1 0 0"/>
        <inertial pos="0 0 -0.2" mass="1" diaginertia="0.01 0.01 0.001"/>
        {arm_mesh}
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def test_what_does_not_move_needs_no_mesh_or_texture(tmp_path):
    path = write(tmp_path, "stand.xml", STATIC_MESH.format(arm_mesh=""))
    imported = import_model(path)
    notes = "\n".join(imported.notes)
    assert "mesh missing/pedestal.stl (on 'stand'): left out" in notes
    assert "'stand' welded to the world needs no mass" in notes
    assert "texture missing/wood.png: left out" in notes
    assert len(imported.mapping["bodies"]) == 1


def test_a_moving_body_whose_mass_is_its_missing_mesh_is_refused(tmp_path):
    text = STATIC_MESH.format(arm_mesh='<body name="tool" pos="0 0 -0.4"><joint name="wrist" type="hinge" '
                                       'axis="0 1 0"/><geom type="mesh" mesh="pedestal"/></body>')
    path = write(tmp_path, "stand.xml", text)
    with pytest.raises(ModelError) as info:
        import_model(path)
    (error,) = info.value.errors
    assert error.startswith(f"{path}: body 'tool': its mass would come from the mesh missing/pedestal.stl")
    # locked, the tool is part of the arm, whose mass is given: still refused (it moves)
    with pytest.raises(ModelError):
        import_model(path, lock=["wrist"])
    # locking the pivot as well welds everything to the world: nothing needs the mesh, but
    # then nothing moves
    with pytest.raises(ModelError, match="no body has a joint: nothing moves"):
        import_model(path, lock=["pivot", "wrist"])


#: every stage has a problem: a moving body's missing mesh, a bad lock, a tendon, a slide joint
#: sharing its body with a ball joint (its sibling on a ball joint, 'side', is a branch of the tree: no problem)
EVERYTHING = """<mujoco model="everything">
  <asset><mesh name="blob" file="missing/blob.stl"/></asset>
  <worldbody>
    <body name="upper" pos="0 0 1">
      <joint name="shoulder" type="hinge" axis="1 0 0"/>
      <geom type="mesh" mesh="blob"/>
      <body name="carriage" pos="0 0 -0.3">
        <joint name="rail" type="slide" axis="1 0 0"/>
        <joint name="swivel" type="ball"/>
        <inertial pos="0 0 -0.05" mass="0.5" diaginertia="0.001 0.001 0.0005"/>
      </body>
      <body name="side" pos="0.1 0 -0.3">
        <joint name="knob" type="ball"/>
        <inertial pos="0 0 -0.05" mass="0.2" diaginertia="0.001 0.001 0.0005"/>
      </body>
    </body>
  </worldbody>
  <tendon><fixed name="cable"><joint joint="shoulder" coef="1"/><joint joint="rail" coef="1"/></fixed></tendon>
</mujoco>
"""


def test_one_refusal_lists_every_problem_and_suggests_no_refused_lock(tmp_path):
    path = write(tmp_path, "everything.xml", EVERYTHING)
    with pytest.raises(ModelError) as info:
        import_model(path, lock=["nope"])
    errors = [e.removeprefix(f"{path}: ") for e in info.value.errors]
    expected = [
        "body 'upper': its mass would come from the mesh missing/blob.stl",
        "lock: no joint named 'nope'",
        "tendon 'cable': tendons are not supported",
        "body 'carriage': 2 joints, a ball or free joint among them; several joints in one body are hinge and "
        "slide joints only",
    ]
    for said in expected:
        assert any(e.startswith(said) for e in errors), (said, errors)
    assert len(errors) == len(expected), errors
    # no error suggests a --lock that the lock would refuse; the tendon's joints are welded
    suggestion = r"--lock its joints \(([^)]*)\)|--lock (\w+)"
    suggested = sorted({name for e in errors for listed, single in re.findall(suggestion, e)
                        for name in (re.findall(r"'(\w+)'", listed) or [single]) if name != "cannot"})
    assert suggested == ["rail", "shoulder"], errors
    # the locks suggested are taken, and the model is then two balls on the world (a tree)
    bodies = import_model(path, lock=suggested).mapping["bodies"]
    assert [(b["name"], b.get("parent")) for b in bodies] == [("carriage", None), ("side", "base")]
