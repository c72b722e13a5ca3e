"""A URDF robot drawn as itself: its links' `<visual>` elements in rerun (docs/viewer.md).

A node running a URDF model publishes the robot's own URDF on ``robot_description`` and every
link's pose on ``/tf`` by the link's name (gyro_sim.scene.robot). The view draws each link's
visuals under ``world/robot/<link>``, moved by the link's /tf: meshes through rerun's
``Asset3D`` (STL, OBJ, glTF/GLB), boxes, cylinders and spheres as rerun's shapes. A mesh whose
file is not found or is COLLADA (``.dae``, which rerun does not read) is not drawn: one note
names how many, and the link keeps its axes. ``package://`` URIs are resolved as on import
(gyro_sim.scene.packages), the shipped models' package included.
"""
from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from collections.abc import Sequence

import numpy as np

from gyro_sim.scene.gazebo import rpy_quaternion
from gyro_sim.scene.packages import PackageResolver

__all__ = ["MESH_SUFFIXES", "ROBOT_ENTITY", "is_robot_urdf", "log_robot"]

#: where the robot's links are drawn
ROBOT_ENTITY = "world/robot"
#: the mesh files rerun's Asset3D reads
MESH_SUFFIXES = (".stl", ".obj", ".glb", ".gltf")
#: colour of a link's visual without a material colour (RGBA 0-255)
LINK_RGBA = (180, 180, 190, 255)


def is_robot_urdf(text: str) -> bool:
    """Whether `text` is a robot's own URDF (some joint is not ``floating``), not the chain's
    URDF gyro_sim writes for a YAML scene (gyro_sim.scene.urdf: floating joints only)."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError:
        return False
    return root.tag == "robot" and any(j.get("type") != "floating" for j in root.findall("joint"))


def _floats(text: str | None, n: int, default: float = 0.0) -> np.ndarray:
    values = [float(v) for v in (text or "").split()]
    return np.array(values if len(values) == n else [default] * n)


def _shipped_models_dir() -> list[str]:
    from gyro_sim.paths import MODELS_DIR, config_dirs

    return [str(d / MODELS_DIR) for d in config_dirs() if (d / MODELS_DIR).is_dir()][:1]


def log_robot(rec, text: str, package_path: Sequence[str] = ()) -> tuple[set[str], list[str]]:
    """Log the robot's link visuals (static) under ROBOT_ENTITY; its link names and notes."""
    import rerun as rr

    root = ET.fromstring(text)
    resolver = PackageResolver(os.path.join(os.getcwd(), "robot.urdf"),
                               list(package_path) + _shipped_models_dir())
    links, missing, notes = set(), [], []
    for link in root.findall("link"):
        name = link.get("name", "")
        links.add(name)
        entity = f"{ROBOT_ENTITY}/{name}"
        rec.log(entity, rr.TransformAxes3D(0.05), static=True)
        for i, visual in enumerate(link.findall("visual")):
            origin = visual.find("origin")
            xyz = _floats(origin.get("xyz") if origin is not None else None, 3)
            q = rpy_quaternion(_floats(origin.get("rpy") if origin is not None else None, 3))
            geometry = visual.find("geometry")
            if geometry is None:
                continue
            shape = None
            mesh = geometry.find("mesh")
            if mesh is not None:
                path, uri = resolver.resolve(mesh.get("filename", ""))
                scale = _floats(mesh.get("scale"), 3, 1.0)
                if path is None or not os.path.isfile(path) or os.path.splitext(path)[1].lower() not in MESH_SUFFIXES:
                    missing.append(uri)
                    continue
                shape = rr.Asset3D(path=path, albedo_factor=LINK_RGBA)
            elif geometry.find("box") is not None:
                size = _floats(geometry.find("box").get("size"), 3)
                shape, scale = rr.Boxes3D(half_sizes=[0.5 * size], colors=[LINK_RGBA]), np.ones(3)
            elif geometry.find("cylinder") is not None:
                cyl = geometry.find("cylinder")
                shape = rr.Cylinders3D(lengths=[float(cyl.get("length", "0"))], radii=[float(cyl.get("radius", "0"))],
                                       colors=[LINK_RGBA])
                scale = np.ones(3)
            elif geometry.find("sphere") is not None:
                r = float(geometry.find("sphere").get("radius", "0"))
                shape, scale = rr.Ellipsoids3D(half_sizes=[[r, r, r]], colors=[LINK_RGBA]), np.ones(3)
            if shape is None:
                continue
            rec.log(f"{entity}/visual{i}", rr.Transform3D(translation=xyz, quaternion=[*q[1:], q[0]], scale=scale),
                    shape, static=True)
    if missing:
        kinds = sorted({os.path.splitext(u)[1].lower() or "(no suffix)" for u in missing})
        notes.append(f"robot meshes not drawn: {len(missing)} ({', '.join(kinds)}): not found, or a format "
                     f"rerun does not read (it reads {', '.join(MESH_SUFFIXES)}); those links show their axes")
    return links, notes


def log_link_poses(rows, names: list[str], positions: np.ndarray, quaternions_xyzw: np.ndarray, t: float) -> None:
    """The links' poses at `t` into the translator's transform rows (`rows(entity, kind)`)."""
    for name, p, q in zip(names, positions, quaternions_xyzw):
        rows(f"{ROBOT_ENTITY}/{name}", "transform").add(t, translation=p, quaternion=q)
