"""Robot descriptions as people write them: ``package://`` meshes, missing meshes, MuJoCo's
warnings and names that are no ROS tokens (gyro_sim.scene.packages, gyro_sim.scene.mjcf,
docs/models.md "Meshes and package:// URIs", "Names").

The judge of "the motion does not need the mesh" is the scene itself: a model with its mesh
found and the same model with it missing must give the same scene, number for number (the
link's inertial gives its mass), and MuJoCo must refuse nothing gyro_sim accepts.
"""
from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco", reason="MuJoCo is the optional extra [models]")

from gyro_sim import Simulator
from gyro_sim.cli import main
from gyro_sim.msgs.messages import imu_topic, wrench_topic
from gyro_sim.scene.load import SceneError, load_scene
from gyro_sim.scene.mjcf import ModelError, import_model
from gyro_sim.scene.names import topic_token
from gyro_sim.scene.packages import PackageResolver

#: a tetrahedron (5 cm edges along the axes): its corners and faces, outward
CORNERS = np.array([[0, 0, 0], [0.05, 0, 0], [0, 0.05, 0], [0, 0, 0.05]], dtype=np.float32)
FACES = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]


def stl() -> bytes:
    """The tetrahedron as a binary STL (the form MuJoCo reads)."""
    out = bytearray(b"gyro_sim test tetrahedron".ljust(80) + struct.pack("<I", len(FACES)))
    for face in FACES:
        a, b, c = CORNERS[list(face)]
        normal = np.cross(b - a, c - a)
        out += struct.pack("<12fH", *normal / np.linalg.norm(normal), *a, *b, *c, 0)
    return bytes(out)


INERTIAL = ('<inertial><origin xyz="0.1 0 0"/><mass value="1.5"/>'
            '<inertia ixx="0.01" iyy="0.02" izz="0.02" ixy="0" ixz="0" iyz="0"/></inertial>')


def robot(mesh: str, inertial: str = INERTIAL, joint: str = "joint1", limit: str = "-1 1",
          second: str = "joint2") -> str:
    """A two-link URDF whose first link has a collision mesh `mesh` (and `inertial`)."""
    lower, upper = limit.split()
    return f"""<?xml version="1.0"?>
<robot name="two_link">
  <link name="base_link"/>
  <joint name="{joint}" type="revolute">
    <parent link="base_link"/><child link="link1"/>
    <origin xyz="0 0 0.5"/><axis xyz="0 1 0"/>
    <limit lower="{lower}" upper="{upper}" effort="10" velocity="3"/>
  </joint>
  <link name="link1">
    {inertial}
    <visual><geometry><mesh filename="{mesh.replace('.stl', '.dae')}"/></geometry></visual>
    <collision><geometry><mesh filename="{mesh}"/></geometry></collision>
  </link>
  <joint name="{second}" type="continuous">
    <parent link="link1"/><child link="link2"/>
    <origin xyz="0.2 0 0"/><axis xyz="0 1 0"/>
  </joint>
  <link name="link2">{INERTIAL}</link>
</robot>
"""


def package(root: Path, name: str) -> Path:
    """A ROS package NAME at `root` with meshes/link1.stl."""
    (root / "meshes").mkdir(parents=True, exist_ok=True)
    (root / "package.xml").write_text(f'<?xml version="1.0"?>\n<package format="3">\n  '
                                      f'<!-- <name>not_this</name> -->\n  <name>{name}</name>\n</package>\n')
    (root / "meshes" / "link1.stl").write_bytes(stl())
    return root


# ------------------------------------------------------------------------- package:// URIs
def test_a_package_is_found_in_the_order_ros_looks(tmp_path):
    """--package-path, the ament index, ROS_PACKAGE_PATH, the package.xml above the file: the
    first that has the package wins, and says how it was found."""
    above = package(tmp_path / "src" / "desc", "desc")
    model = above / "urdf" / "robot.urdf"
    model.parent.mkdir()
    model.write_text(robot("package://desc/meshes/link1.stl"))
    given = package(tmp_path / "given" / "desc", "desc")
    prefix = tmp_path / "install"
    package(prefix / "share" / "desc", "desc")
    marker = prefix / "share" / "ament_index" / "resource_index" / "packages" / "desc"
    marker.parent.mkdir(parents=True)
    marker.write_text("")
    ros1 = package(tmp_path / "ws" / "deep" / "down" / "desc_dir", "desc")
    env = {"AMENT_PREFIX_PATH": f"{tmp_path / 'empty'}:{prefix}", "ROS_PACKAGE_PATH": str(tmp_path / "ws")}

    def found(package_path, environ):
        return PackageResolver(str(model), package_path, environ).package("desc")

    assert found([tmp_path / "given"], env) == (str(given), "--package-path")
    assert found([], env) == (str(prefix / "share" / "desc"), "the ament index (AMENT_PREFIX_PATH)")
    assert found([], {"ROS_PACKAGE_PATH": env["ROS_PACKAGE_PATH"]}) == (str(ros1), "ROS_PACKAGE_PATH")
    assert found([], {}) == (str(above), "the package.xml above the model")
    assert PackageResolver(str(model), [], {}).package("other") is None


def test_a_package_mesh_is_read_and_its_package_noted(tmp_path):
    root = package(tmp_path / "meshes_pkg", "arm_description")
    model = tmp_path / "robot.urdf"
    model.write_text(robot("package://arm_description/meshes/link1.stl"))
    imported = import_model(model, package_path=[tmp_path])
    assert f"package 'arm_description': {root} (from --package-path)" in imported.notes
    assert not any("left out" in note for note in imported.notes)
    with pytest.raises(ModelError, match="link 'link1': its mass would come from the mesh"):
        # the same mesh where the link has no inertial: the mesh is read (MuJoCo's mass from it)
        bad = tmp_path / "no_inertial.urdf"
        bad.write_text(robot("package://arm_description/meshes/missing.stl", inertial=""))
        import_model(bad, package_path=[tmp_path])
    no_inertial = tmp_path / "no_inertial_found.urdf"
    no_inertial.write_text(robot("package://arm_description/meshes/link1.stl", inertial=""))
    scene = load_scene(no_inertial, package_path=[tmp_path])
    assert scene.bodies[0].mass > 0.0  # MuJoCo's mass of the tetrahedron


@pytest.mark.parametrize("uri", ["package://nowhere/meshes/link1.stl", "meshes/absent.stl",
                                 "package://arm_description/meshes/link1.dae"])
def test_a_missing_mesh_is_left_out_and_the_motion_is_the_same(uri, tmp_path):
    """With its mesh missing (no package, no file, a format MuJoCo cannot read) a link with an
    inertial loads to the very scene it loads to with the mesh found; one note names the URI."""
    package(tmp_path / "arm_description", "arm_description")
    (tmp_path / "arm_description" / "meshes" / "link1.dae").write_text("<COLLADA/>")
    found = tmp_path / "found.urdf"
    found.write_text(robot("package://arm_description/meshes/link1.stl"))
    missing = tmp_path / "missing.urdf"
    missing.write_text(robot(uri))
    with_mesh = import_model(found, package_path=[tmp_path])
    without = import_model(missing, package_path=[tmp_path])
    assert without.mapping["bodies"] == with_mesh.mapping["bodies"]
    left_out = [note for note in without.notes if "left out" in note]
    assert len(left_out) == 1 and left_out[0].startswith(f"mesh {uri} (on 'link1'): left out")


def test_run_takes_package_path(tmp_path, capsys):
    package(tmp_path / "pkgs" / "arm_description", "arm_description")
    model = tmp_path / "robot.urdf"
    model.write_text(robot("package://arm_description/meshes/link1.stl"))
    assert main(["run", "--scene", str(model), "--duration", "0.01",
                 "--package-path", str(tmp_path / "pkgs")]) == 0
    assert main(["import", str(model), "-o", str(tmp_path / "robot.yaml"),
                 "--package-path", str(tmp_path / "pkgs")]) == 0
    out = capsys.readouterr().out
    assert "note: package 'arm_description'" in out and "left out" not in out


# ------------------------------------------------------------------------ MuJoCo's warnings
def test_mujocos_warnings_become_notes_never_lines_on_the_terminal(tmp_path, capfd):
    model = tmp_path / "robot.urdf"
    model.write_text(robot("meshes/absent.stl", limit="0 0"))
    imported = import_model(model)
    captured = capfd.readouterr()
    assert "WARNING" not in captured.out + captured.err
    assert "MuJoCo: joint 'joint1' has equal lower and upper limits, limit ignored" in imported.notes
    assert main(["import", str(model), "-o", str(tmp_path / "robot.yaml")]) == 0
    captured = capfd.readouterr()
    assert "WARNING" not in captured.err
    assert "note: MuJoCo: joint 'joint1' has equal lower and upper limits" in captured.out
    header = (tmp_path / "robot.yaml").read_text()
    assert "#   MuJoCo: joint 'joint1' has equal lower and upper limits" in header


# ------------------------------------------------------------------------------------ names
def test_joint_names_are_kept_as_the_file_gives_them(tmp_path):
    """Joint states carry the file's names; topics take their tokens."""
    model = tmp_path / "robot.urdf"
    model.write_text(robot("meshes/absent.stl", joint="flying_arm_2__j_bl_link1", second="wrist-1"))
    sim = Simulator(load_scene(model), integrator="rk4", step=1e-3)
    assert list(sim.joint_states().name) == ["flying_arm_2__j_bl_link1", "wrist-1"]
    assert wrench_topic("flying_arm_2__j_bl_link1") == "/gyro_sim/wrench/flying_arm_2_j_bl_link1"
    assert wrench_topic("wrist-1") == "/gyro_sim/wrench/wrist_1"


@pytest.mark.parametrize("name, token", [("flying_arm_2__j1", "flying_arm_2_j1"), ("wrist-1", "wrist_1"),
                                         ("1st", "_1st"), ("a.b::c", "a_b_c"), ("ok_name", "ok_name")])
def test_topic_tokens_are_ros_name_tokens(name, token):
    rclpy_names = pytest.importorskip("rclpy.validate_full_topic_name", reason="ROS checks its names")
    assert topic_token(name) == token
    rclpy_names.validate_full_topic_name(imu_topic(name))


def test_names_making_one_topic_are_refused_naming_both(tmp_path):
    model = tmp_path / "robot.urdf"
    model.write_text(robot("meshes/absent.stl", joint="arm-1", second="arm.1"))
    with pytest.raises(SceneError) as info:
        load_scene(model)
    assert len(info.value.errors) == 1
    assert "'arm.1' and 'arm-1'" in info.value.errors[0] and "~/wrench/arm_1" in info.value.errors[0]


MJCF = """<mujoco model="mesh_arm">
  <compiler meshdir="meshes"/>
  <asset><mesh name="shell" file="{file}"/></asset>
  <worldbody>
    <body name="arm" pos="0 0 1">
      <joint name="pivot" type="hinge" axis="0 1 0"/>
      {inertial}
      <geom type="mesh" mesh="shell"/>
    </body>
  </worldbody>
</mujoco>
"""


def test_an_mjcf_mesh_is_found_under_meshdir_or_left_out_when_the_mass_is_given(tmp_path):
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "shell.stl").write_bytes(stl())
    inertial = '<inertial pos="0.1 0 0" mass="1.5" diaginertia="0.01 0.02 0.02"/>'
    found = tmp_path / "found.xml"
    found.write_text(MJCF.format(file="shell.stl", inertial=inertial))
    missing = tmp_path / "missing.xml"
    missing.write_text(MJCF.format(file="absent.stl", inertial=inertial))
    with_mesh, without = import_model(found), import_model(missing)
    assert without.mapping["bodies"] == with_mesh.mapping["bodies"]
    assert any(n.startswith("mesh absent.stl (on 'arm'): left out, no such file") for n in without.notes)
    needed = tmp_path / "needed.xml"
    needed.write_text(MJCF.format(file="absent.stl", inertial=""))
    with pytest.raises(ModelError, match="body 'arm': its mass would come from the mesh absent.stl"):
        import_model(needed)
    assert load_scene(tmp_path / "found.xml").bodies[0].mass == 1.5
